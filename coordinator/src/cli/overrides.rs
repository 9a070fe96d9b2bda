//! Settings that a command-line flag or a sweep's budget overrides, as the `KEY=VALUE` pairs of `--set`.
//!
//! `--spp 64` is shorthand for `--set render.spp=64`: every flag becomes pairs appended after the user's
//! `--set` pairs (a later pair wins, so the flag does), and the scene is loaded once with all of them
//! ([`photon_core::scene::Scene::load_with`]), so the scene file's parser and validation are the one source of
//! truth for what a setting may be. The sweep's budgets become pairs the same way.

use photon_core::method::Method;

/// One overridden setting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Setting {
    /// `--spp N`: `render.spp`.
    Spp(u32),
    /// `--integrator M`: `render.integrator`, by its scene-file name (`photon-map`).
    Integrator(Method),
    /// `--seed N`: `render.seed`.
    Seed(u64),
    /// `--size WxH`: `camera.width` and `camera.height`.
    Size(u32, u32),
    /// `--photons N`: `render.photons.global`, `.caustic` and `.pass_photons`.
    Photons(u32),
    /// `render.photons.global` alone (the sweep's photon-map budget).
    GlobalPhotons(u32),
    /// `render.photons.caustic` alone (the sweep's final-gather budget, with the global one).
    CausticPhotons(u32),
    /// `--passes N`: `render.photons.passes`.
    Passes(u32),
    /// `--exposure E`: `render.exposure`, in stops.
    Exposure(f32),
}

impl Setting {
    /// The `KEY=VALUE` pairs of this setting, in the syntax of `--set` (values are TOML).
    pub fn pairs(self) -> Vec<String> {
        match self {
            Self::Spp(n) => vec![format!("render.spp={n}")],
            Self::Integrator(m) => vec![format!("render.integrator=\"{}\"", m.name())],
            Self::Seed(n) => vec![format!("render.seed={n}")],
            Self::Size(w, h) => vec![format!("camera.width={w}"), format!("camera.height={h}")],
            Self::Photons(n) => vec![
                format!("render.photons.global={n}"),
                format!("render.photons.caustic={n}"),
                format!("render.photons.pass_photons={n}"),
            ],
            Self::GlobalPhotons(n) => vec![format!("render.photons.global={n}")],
            Self::CausticPhotons(n) => vec![format!("render.photons.caustic={n}")],
            Self::Passes(n) => vec![format!("render.photons.passes={n}")],
            Self::Exposure(e) => vec![format!("render.exposure={}", toml_float(e))],
        }
    }
}

/// The user's `--set` pairs followed by the pairs of `settings`, which therefore win.
pub fn pairs(set: &[String], settings: &[Setting]) -> Vec<String> {
    set.iter().cloned().chain(settings.iter().flat_map(|s| s.pairs())).collect()
}

/// `x` as a TOML float that reads back as exactly `x`: the shortest decimal when it round-trips through the
/// f64 the parser makes (it nearly always does), else the exact f64 value; TOML's `inf` and `nan` spellings
/// for the others, so that validation rejects them with the field's name.
fn toml_float(x: f32) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let short = format!("{x:?}");
    if short.parse::<f64>().is_ok_and(|d| d as f32 == x) { short } else { format!("{:?}", f64::from(x)) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_become_set_pairs_after_the_users() {
        let set = vec!["render.spp=2".to_owned()];
        let got = pairs(&set, &[Setting::Spp(64), Setting::Integrator(Method::PhotonMap), Setting::Size(4, 3)]);
        assert_eq!(
            got,
            ["render.spp=2", "render.spp=64", "render.integrator=\"photon-map\"", "camera.width=4", "camera.height=3"]
        );
        assert_eq!(Setting::Photons(7).pairs().len(), 3);
    }

    #[test]
    fn floats_read_back_exactly() {
        for x in [1.0f32, -2.5, 0.1, 1e-7, 3.4e38, f32::MIN_POSITIVE, 16_777_217.0] {
            let s = toml_float(x);
            let v: toml::Table = toml::from_str(&format!("v = {s}")).unwrap();
            assert_eq!(v["v"].as_float().map(|d| d as f32), Some(x), "{x} as {s}");
        }
        assert_eq!(toml_float(f32::INFINITY), "inf");
        assert_eq!(toml_float(f32::NAN), "nan");
    }
}
