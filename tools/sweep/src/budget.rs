//! A sweep's budgets and its measured renders: how a budget multiplier becomes a method's setting ([`budget`], as
//! `--set` pairs through [`photon_coordinator::cli::overrides`]), and the rows of `sweep.csv` ([`Row`], [`csv`]).

use anyhow::{Context, Result};
use photon_coordinator::cli::overrides::Setting;
use photon_core::method::{BudgetSetting, Method};
use std::fmt::Write as _;

/// Samples per pixel of `path` and `direct` at budget 1.
pub const BASE_SPP: u32 = 4;
/// Global photon paths of `photon-map` and global and caustic photon paths of `final-gather` at budget 1.
pub const BASE_PHOTONS: u32 = 25_000;
/// Passes of `progressive`, `vcm`, `bdpt` and `lt` at budget 1.
pub const BASE_PASSES: u32 = 4;
/// Samples per pixel of the photon-map methods, fixed across budgets: they only anti-alias the first hit, so the
/// budget grows the photon count alone.
pub const PHOTON_METHOD_SPP: u32 = 2;

/// What a budget multiplier set: the setting's name and value, for the CSV.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Budget {
    /// The setting that grows with the budget: `spp`, `photons` or `passes`.
    pub parameter: &'static str,
    /// Its value.
    pub value: u64,
}

/// The settings that render with `method` at budget multiplier `b`: `path`/`direct` at `BASE_SPP·b` spp,
/// `photon-map` with `BASE_PHOTONS·b` global photons (k unchanged), `final-gather` with `BASE_PHOTONS·b` global
/// and caustic photons, `progressive`, `vcm`, `bdpt` and `lt` with `BASE_PASSES·b` passes. The photon-map
/// methods render [`PHOTON_METHOD_SPP`] samples per pixel at every budget. Fails when a value overflows `u32`.
pub fn budget(method: Method, b: u32) -> Result<(Vec<Setting>, Budget)> {
    let times = |base: u32| base.checked_mul(b).with_context(|| format!("budget {b} × {base} overflows for {method}"));
    let grown = |parameter, value: u32| Budget { parameter, value: u64::from(value) };
    let (settings, budget) = match method.budget_setting() {
        BudgetSetting::Spp => {
            let spp = times(BASE_SPP)?;
            (vec![Setting::Spp(spp)], grown("spp", spp))
        }
        BudgetSetting::Photons { caustic } => {
            let n = times(BASE_PHOTONS)?;
            let mut settings = vec![Setting::Spp(PHOTON_METHOD_SPP), Setting::GlobalPhotons(n)];
            if caustic {
                settings.push(Setting::CausticPhotons(n));
            }
            (settings, grown("photons", n))
        }
        BudgetSetting::Passes => {
            let passes = times(BASE_PASSES)?;
            (vec![Setting::Passes(passes)], grown("passes", passes))
        }
    };
    Ok(([vec![Setting::Integrator(method)], settings].concat(), budget))
}

/// One measured render of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The method.
    pub method: Method,
    /// The budget multiplier.
    pub budget: u32,
    /// What the multiplier set.
    pub setting: Budget,
    /// Wall seconds, prepare plus render.
    pub seconds: f64,
    /// RMSE against the reference.
    pub rmse: f64,
    /// Relative MSE against the reference.
    pub rel_mse: f64,
    /// The relative MSE the render estimated without the reference, for the methods that estimate it.
    pub estimated_rel_mse: Option<f64>,
}

/// The CSV header of [`csv`].
pub const CSV_HEADER: &str = "method,budget,parameter,value,seconds,rmse,rel_mse,estimated_rel_mse";

/// The rows as CSV with a header line.
pub fn csv(rows: &[Row]) -> String {
    let mut s = format!("{CSV_HEADER}\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{:.6},{:.6e},{:.6e},{}",
            r.method,
            r.budget,
            r.setting.parameter,
            r.setting.value,
            r.seconds,
            r.rmse,
            r.rel_mse,
            r.estimated_rel_mse.map(|e| format!("{e:.6e}")).unwrap_or_default()
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use photon_core::scene::{RenderSettings, Scene};
    use std::path::Path;

    /// A scene file with default render settings, loaded with the pairs of `method` at budget `b`.
    fn with_budget(dir: &Path, method: Method, b: u32) -> (RenderSettings, Budget) {
        let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 8\nheight = 8\n\
                    [materials.white]\ntype = \"lambert\"\n\
                    [[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = 0.5\nmaterial = \"white\"\n\
                    [[lights]]\ntype = \"point\"\nposition = [0.0, 2.0, 0.0]\npower = [10.0, 10.0, 10.0]\n";
        std::fs::write(dir.join("s.toml"), text).unwrap();
        let (settings, budget) = super::budget(method, b).unwrap();
        let scene =
            Scene::load_with(&dir.join("s.toml"), &photon_coordinator::cli::overrides::pairs(&[], &settings)).unwrap();
        (scene.render, budget)
    }

    #[test]
    fn budgets_grow_the_right_setting() {
        let dir = std::env::temp_dir().join(format!("photon-sweep-budget-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let k = RenderSettings::default().photons.k;
        let (s, b) = with_budget(&dir, Method::Path, 8);
        assert_eq!(b, Budget { parameter: "spp", value: 32 });
        assert_eq!(s.spp, 32);
        let (s, b) = with_budget(&dir, Method::PhotonMap, 4);
        assert_eq!((b.value, s.photons.global, s.photons.k, s.spp), (100_000, 100_000, k, PHOTON_METHOD_SPP));
        let (s, _) = with_budget(&dir, Method::FinalGather, 2);
        assert_eq!((s.photons.global, s.photons.caustic), (50_000, 50_000));
        let (s, b) = with_budget(&dir, Method::Progressive, 16);
        assert_eq!((b.value, s.photons.passes), (64, 64));
        assert_eq!(s.integrator, Method::Progressive);
        for method in [Method::Vcm, Method::Bdpt, Method::Lt] {
            let (s, b) = with_budget(&dir, method, 2);
            assert_eq!(b, Budget { parameter: "passes", value: 8 }, "{method}");
            assert_eq!((s.integrator, s.photons.passes), (method, 8));
        }
        assert!(super::budget(Method::Path, u32::MAX).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn csv_has_a_row_per_render() {
        let row = Row {
            method: Method::Progressive,
            budget: 2,
            setting: Budget { parameter: "passes", value: 8 },
            seconds: 1.5,
            rmse: 0.25,
            rel_mse: 0.125,
            estimated_rel_mse: Some(0.1),
        };
        let s = csv(&[row.clone(), row]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(lines.len(), 3);
        assert!(lines[1].starts_with("progressive,2,passes,8,1.5"), "{}", lines[1]);
        assert!(lines[1].ends_with(",1.000000e-1"), "{}", lines[1]);
    }
}
