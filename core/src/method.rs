//! `Method`: a rendering method, and every question the rest of the renderer asks about one.
//!
//! A scene file names its method (`render.integrator = "vcm"`); this module is the only place that matches on
//! it. Each question below is one exhaustive `match`, so a new method is one estimator file plus the arms the
//! compiler demands here; everything else (the block renderer, the photon tracer, the memory budget, the
//! farm's unit of work, the report) asks these questions and matches on their small answers.
//!
//! | method | unit | static maps | block technique | radius | bias |
//! |---|---|---|---|---|---|
//! | `path` | samples | none | camera samples, full paths | none | none |
//! | `direct` | samples | none | camera samples, direct light | none | none |
//! | `photon-map` | samples | global | camera samples, global map seen | photon | fixed |
//! | `final-gather` | samples | global, caustic | camera samples, final gathering | photon | fixed |
//! | `progressive` | passes | none | photon passes | photon | shrinking |
//! | `vcm` | passes | none | light and camera subpaths, merges | merge | shrinking |
//! | `bdpt` | passes | none | light and camera subpaths | none | none |
//! | `lt` | passes | none | light subpaths to the camera | none | none |
//!
//! `method` comes before `scene` in core's layers: the scene file names a method, so the scene's types use
//! this one, and the questions take the settings they need as arguments rather than the scene's types.

use crate::photon::kernel::Kernel;
use serde::{Deserialize, Serialize};

/// How pixels are computed: the method, in the scene file (`render.integrator`) and on the command line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Unbiased path tracing with next-event estimation, MIS and Russian roulette (the reference).
    #[default]
    Path,
    /// Direct lighting at the first non-specular hit, following mirror and glass.
    Direct,
    /// Direct visualisation of the global photon map at the first non-specular hit (what the origin did).
    PhotonMap,
    /// Jensen's two passes: direct light by shadow rays, caustics from the caustic map, indirect light from
    /// the global map through final gathering.
    FinalGather,
    /// Probabilistic progressive photon mapping (Knaus & Zwicker 2011): independent passes of fresh photons,
    /// each gathering with a radius that shrinks with the pass index; consistent, it converges to the path
    /// tracer's answer, and its passes spread over the farm.
    Progressive,
    /// Vertex connection and merging (Georgiev et al. 2012): bidirectional path tracing whose connections and
    /// photon merges are weighted by multiple importance sampling; iterations of fresh light subpaths with a
    /// shrinking merging radius, spread over the farm like progressive passes.
    Vcm,
    /// Bidirectional path tracing: [`Method::Vcm`] without merging (unbiased).
    Bdpt,
    /// Light tracing: [`Method::Vcm`]'s light subpaths connected to the camera only (unbiased; sees no
    /// light through mirror or glass in front of the camera).
    Lt,
}

/// What one unit of a method's work is: the axis a render bounded by time or error grows along, and the
/// numbering of a block's units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// One camera sample of each pixel (`render.spp` of them): pixels are independent, so the farm may cut the
    /// image into strips of rows.
    Samples,
    /// One whole-image pass (`render.photons.passes` of them): each pass traces its own light paths, which may
    /// reach any pixel, so the farm hands out blocks of passes over the whole image.
    Passes,
}

/// The photon maps traced once, before rendering, and shipped to (or traced by) every worker.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StaticMaps {
    /// None.
    None,
    /// The global map (with its volume map in a scene with media).
    Global,
    /// The global map, and a caustic map and precomputed irradiance for final gathering.
    GlobalAndCaustic,
}

/// The estimator of one camera sample, for the methods that render samples (and for those whose passes fall
/// back to samples in a scene with media).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraEstimator {
    /// Full paths with next-event estimation and MIS.
    Path,
    /// Direct light at the first non-delta surface.
    Direct,
    /// The global photon map at the first non-delta surface.
    PhotonMap,
    /// Shadow rays, the caustic map and final gathering of the global map.
    FinalGather,
}

/// Which techniques a subpath iteration (vcm, bdpt, lt) uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Techniques {
    /// Vertex connection: next-event estimation, connections between subpaths, and light tracing.
    pub connect: bool,
    /// Vertex merging.
    pub merge: bool,
    /// Light tracing only: light subpaths connected to the camera, plus emission seen directly; nothing else.
    pub light_tracing_only: bool,
}

/// How a block of a method's units is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// Independent camera samples through a per-ray estimator.
    Samples(CameraEstimator),
    /// Passes of fresh photons gathered at a shrinking radius (progressive photon mapping).
    PhotonPasses,
    /// Passes of light subpaths joined to camera subpaths.
    Subpaths(Techniques),
}

/// The scene setting that holds a method's gather or merge radius.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RadiusSetting {
    /// The method gathers nothing.
    None,
    /// `render.photons.radius`: the photon maps' gather radius (progressive's first pass).
    Photon,
    /// `render.photons.merge_radius`: vcm's first merge radius.
    Merge,
}

impl RadiusSetting {
    /// The field's name in the scene file, for errors; `None` for [`RadiusSetting::None`].
    pub fn field(self) -> Option<&'static str> {
        match self {
            RadiusSetting::None => None,
            RadiusSetting::Photon => Some("render.photons.radius"),
            RadiusSetting::Merge => Some("render.photons.merge_radius"),
        }
    }
}

/// The bias of a method's estimate, as a bounded render models it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bias {
    /// Unbiased: the error is the variance, which falls as 1/N.
    None,
    /// Biased by photon maps whose size is fixed before the render: no number of samples lowers it, so no
    /// error target can be reached by rendering longer.
    Fixed,
    /// Biased by a radius that shrinks with the passes as `r_i² ∝ Π (k + α)/(k + 1)` (Knaus & Zwicker 2011,
    /// eq. 15): consistent, with a bias that falls as the radius does.
    Shrinking,
}

/// The setting a budget (a sweep's multiplier, a reference's size) grows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSetting {
    /// `render.spp`.
    Spp,
    /// The photon maps' paths: `render.photons.global`, and `caustic` too when `caustic` is set.
    Photons {
        /// Whether the caustic map grows with the global map.
        caustic: bool,
    },
    /// `render.photons.passes`.
    Passes,
}

/// What a pass holds while it renders, besides the image's sums: for the memory budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassStorage {
    /// Nothing: the unit is a sample.
    None,
    /// A photon map of `render.photons.pass_photons` paths, traced for the pass.
    PhotonMap,
    /// One light subpath per pixel: its vertices when the camera connects to them, indexed in a kd-tree when
    /// it merges, and the light-tracing splats.
    LightSubpaths(Techniques),
}

impl Method {
    /// Every method, in the order the documentation lists them.
    pub const ALL: [Method; 8] = [
        Method::Path,
        Method::Direct,
        Method::PhotonMap,
        Method::FinalGather,
        Method::Progressive,
        Method::Vcm,
        Method::Bdpt,
        Method::Lt,
    ];

    /// The name used in scene files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Path => "path",
            Method::Direct => "direct",
            Method::PhotonMap => "photon-map",
            Method::FinalGather => "final-gather",
            Method::Progressive => "progressive",
            Method::Vcm => "vcm",
            Method::Bdpt => "bdpt",
            Method::Lt => "lt",
        }
    }

    /// The unit of the method's work.
    pub fn unit(self) -> Unit {
        match self {
            Method::Path | Method::Direct | Method::PhotonMap | Method::FinalGather => Unit::Samples,
            Method::Progressive | Method::Vcm | Method::Bdpt | Method::Lt => Unit::Passes,
        }
    }

    /// Whether the method renders in whole-image passes ([`Unit::Passes`]) rather than pixel samples.
    pub fn renders_passes(self) -> bool {
        self.unit() == Unit::Passes
    }

    /// The photon maps traced before rendering.
    pub fn static_maps(self) -> StaticMaps {
        match self {
            Method::PhotonMap => StaticMaps::Global,
            Method::FinalGather => StaticMaps::GlobalAndCaustic,
            Method::Path | Method::Direct | Method::Progressive | Method::Vcm | Method::Bdpt | Method::Lt => {
                StaticMaps::None
            }
        }
    }

    /// Whether the method reads photon maps traced before rendering.
    pub fn needs_photon_maps(self) -> bool {
        self.static_maps() != StaticMaps::None
    }

    /// How a block of the method's units is computed, in a scene with participating media (`media`) or
    /// without. vcm, bdpt and lt have no volumetric version: in a scene with media their passes are the
    /// volumetric path tracer's samples. The photon-map methods fall back to direct light when their maps are
    /// missing (`maps`: a job prepared without them).
    pub fn technique(self, media: bool, maps: bool) -> Technique {
        let subpaths = |t| if media { Technique::Samples(CameraEstimator::Path) } else { Technique::Subpaths(t) };
        match self {
            Method::Path => Technique::Samples(CameraEstimator::Path),
            Method::Direct => Technique::Samples(CameraEstimator::Direct),
            Method::PhotonMap if maps => Technique::Samples(CameraEstimator::PhotonMap),
            Method::FinalGather if maps => Technique::Samples(CameraEstimator::FinalGather),
            Method::PhotonMap | Method::FinalGather => Technique::Samples(CameraEstimator::Direct),
            Method::Progressive => Technique::PhotonPasses,
            Method::Vcm => subpaths(Techniques::VCM),
            Method::Bdpt => subpaths(Techniques::BDPT),
            Method::Lt => subpaths(Techniques::LT),
        }
    }

    /// The techniques of a subpath method (`vcm`, `bdpt`, `lt`); `None` for the other methods.
    pub fn techniques(self) -> Option<Techniques> {
        match self {
            Method::Vcm => Some(Techniques::VCM),
            Method::Bdpt => Some(Techniques::BDPT),
            Method::Lt => Some(Techniques::LT),
            Method::Path | Method::Direct | Method::PhotonMap | Method::FinalGather | Method::Progressive => None,
        }
    }

    /// Whether subpaths of the method cross participating media. None does: [`Method::technique`] falls back.
    pub fn warns_in_media(self) -> bool {
        match self {
            Method::Vcm | Method::Bdpt | Method::Lt => true,
            Method::Path | Method::Direct | Method::PhotonMap | Method::FinalGather | Method::Progressive => false,
        }
    }

    /// The setting of the radius the method gathers or merges within.
    pub fn radius(self) -> RadiusSetting {
        match self {
            Method::PhotonMap | Method::FinalGather | Method::Progressive => RadiusSetting::Photon,
            Method::Vcm => RadiusSetting::Merge,
            Method::Path | Method::Direct | Method::Bdpt | Method::Lt => RadiusSetting::None,
        }
    }

    /// The kernel the method's density estimates weight photons with, given the scene's
    /// `render.photons.kernel`: progressive photon mapping's flat disc whatever it says (its estimate is the
    /// photons' flux over `π r²`, Hachisuka, Ogaki & Jensen 2008), the configured one for the others that gather
    /// or merge.
    pub fn kernel(self, configured: Kernel) -> Kernel {
        match self {
            Method::Progressive => Kernel::Box,
            _ => configured,
        }
    }

    /// The bias of the method's estimate.
    pub fn bias(self) -> Bias {
        match self {
            Method::Path | Method::Direct | Method::Bdpt | Method::Lt => Bias::None,
            Method::PhotonMap | Method::FinalGather => Bias::Fixed,
            Method::Progressive | Method::Vcm => Bias::Shrinking,
        }
    }

    /// The `α` of a shrinking radius ([`Bias::Shrinking`]) for the bounded render's bias model, from the
    /// scene's `render.photons.alpha`; `None` for the other methods.
    pub fn bias_alpha(self, alpha: f32) -> Option<f32> {
        (self.bias() == Bias::Shrinking).then_some(alpha)
    }

    /// Whether rendering longer lowers the method's error, so that a render can estimate it and stop at a
    /// target.
    pub fn error_falls_with_units(self) -> bool {
        match self.bias() {
            Bias::None | Bias::Shrinking => true,
            Bias::Fixed => false,
        }
    }

    /// The setting a budget grows.
    pub fn budget_setting(self) -> BudgetSetting {
        match self {
            Method::Path | Method::Direct => BudgetSetting::Spp,
            Method::PhotonMap => BudgetSetting::Photons { caustic: false },
            Method::FinalGather => BudgetSetting::Photons { caustic: true },
            Method::Progressive | Method::Vcm | Method::Bdpt | Method::Lt => BudgetSetting::Passes,
        }
    }

    /// What one pass holds while it renders (the memory budget).
    pub fn pass_storage(self) -> PassStorage {
        match self {
            Method::Path | Method::Direct | Method::PhotonMap | Method::FinalGather => PassStorage::None,
            Method::Progressive => PassStorage::PhotonMap,
            Method::Vcm => PassStorage::LightSubpaths(Techniques::VCM),
            Method::Bdpt => PassStorage::LightSubpaths(Techniques::BDPT),
            Method::Lt => PassStorage::LightSubpaths(Techniques::LT),
        }
    }

    /// Whether the method gathers photons k-nearest or within a radius per pixel (the memory of the gather
    /// buffers); vcm merges within a fixed radius without them.
    pub fn gathers_photons(self) -> bool {
        match self {
            Method::PhotonMap | Method::FinalGather | Method::Progressive => true,
            Method::Path | Method::Direct | Method::Vcm | Method::Bdpt | Method::Lt => false,
        }
    }

    /// The report's words for the work of `units` units (samples per pixel or passes) of an image of `pixels`
    /// pixels, given the scene's photon settings: `pass_photons` per progressive pass, `global` photon-map paths.
    /// `media` says that a subpath method's passes fell back to path-traced samples. Photon-map delivery is
    /// the report's to add (it knows how the maps travelled).
    pub fn work_words(self, units: u32, pixels: u64, pass_photons: u32, media: bool) -> String {
        match self {
            Method::Path | Method::Direct | Method::PhotonMap | Method::FinalGather => format!("{units} spp"),
            Method::Progressive => format!("{units} passes of {pass_photons} photon paths"),
            Method::Vcm | Method::Bdpt | Method::Lt if media => {
                format!("{units} passes of path-traced samples (the scene has participating media)")
            }
            Method::Vcm | Method::Bdpt | Method::Lt => format!("{units} passes of {pixels} light paths"),
        }
    }
}

impl Techniques {
    /// vcm's techniques: connections and merges.
    pub const VCM: Techniques = Techniques { connect: true, merge: true, light_tracing_only: false };
    /// bdpt's techniques: connections, no merges.
    pub const BDPT: Techniques = Techniques { connect: true, merge: false, light_tracing_only: false };
    /// Light tracing's techniques.
    pub const LT: Techniques = Techniques { connect: false, merge: false, light_tracing_only: true };
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A method name that is none of [`Method::ALL`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownMethod(pub String);

impl std::fmt::Display for UnknownMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = Method::ALL.iter().map(|i| i.name()).collect();
        write!(f, "unknown integrator `{}`: expected one of {}", self.0, names.join(", "))
    }
}

impl std::error::Error for UnknownMethod {}

impl std::str::FromStr for Method {
    type Err = UnknownMethod;
    fn from_str(s: &str) -> Result<Self, UnknownMethod> {
        Self::ALL.into_iter().find(|i| i.name() == s).ok_or_else(|| UnknownMethod(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>(), Ok(m));
        }
        assert_eq!("pathtracer".parse::<Method>(), Err(UnknownMethod("pathtracer".into())));
    }

    #[test]
    fn answers_agree() {
        for m in Method::ALL {
            // A method with a radius gathers, or merges (vcm); a fixed bias means static maps.
            assert_eq!(m.bias() == Bias::Fixed, m.needs_photon_maps(), "{m}");
            assert_eq!(m.techniques().is_some(), matches!(m.technique(false, true), Technique::Subpaths(_)), "{m}");
            assert_eq!(m.budget_setting() == BudgetSetting::Passes, m.renders_passes(), "{m}");
            assert_eq!(m.pass_storage() != PassStorage::None, m.renders_passes(), "{m}");
            if m.gathers_photons() {
                assert_eq!(m.radius(), RadiusSetting::Photon, "{m}");
            }
            // In a scene with media every pass method but progressive falls back to samples.
            let media = m.technique(true, true);
            assert!(!matches!(media, Technique::Subpaths(_)), "{m}");
            assert_eq!(m.warns_in_media(), m.renders_passes() && media != Technique::PhotonPasses, "{m}");
        }
    }
}
