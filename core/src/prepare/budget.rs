//! The memory a job needs, estimated from its settings before anything is allocated, so that a job that cannot
//! fit is refused with the setting to change instead of aborting the process halfway (a 65536 × 65536 image
//! alone is 51 GB of f32 pixels).
//!
//! The estimates are upper bounds of the large buffers only (the scene's geometry is already loaded when they
//! are made): the coordinator checks a whole job ([`MemoryEstimate::job`]) against its machine, a worker checks
//! each strip request ([`MemoryEstimate::strip`]) against its own.

use crate::method::{PassStorage, StaticMaps};
pub use crate::run::{gib, machine_memory};
use crate::scene::RenderSettings;

/// Bytes per pixel of an assembled image: the whole render's fixed-point sums (3 × i128 = 48), the f32 RGB
/// pixels divided from them (12), and the encoder's copy when the image is written (12).
pub const IMAGE_BYTES_PER_PIXEL: u64 = 72;

/// Bytes per pixel of one block on a worker, or of a block as it arrives at the coordinator: its fixed-point
/// sums (3 × i64 = 24), their wire bytes (24) and the chunked events that carry them (24).
pub const STRIP_BYTES_PER_PIXEL: u64 = 72;

/// Bytes per pixel of the copy of one pass's sums that vcm, bdpt and lt keep apart before adding them in
/// (3 × i64).
pub const PASS_COPY_BYTES_PER_PIXEL: u64 = 24;

/// Photon-map bytes a worker may hold at once while it traces progressive passes side by side.
pub const PASS_MAPS_AT_ONCE_BYTES: u64 = 1 << 29;

/// How many progressive passes a worker traces side by side with `threads` threads: as many as the threads,
/// while their maps (about 96 bytes per photon path) stay within [`PASS_MAPS_AT_ONCE_BYTES`], and at least one.
/// The next group is traced while this one gathers, within what this group leaves of the run's storage bound
/// ([`crate::run::Guard`]).
/// For progressive photon mapping only: its passes hold `pass_photons` paths each, while vcm, bdpt and lt trace
/// one pass at a time, one light subpath per pixel ([`MemoryEstimate::light_paths`]).
pub fn passes_at_once(pass_photons: u32, threads: usize) -> u32 {
    let per_map = (u64::from(pass_photons) * 96).max(1);
    (PASS_MAPS_AT_ONCE_BYTES / per_map).clamp(1, threads.max(1) as u64) as u32
}

/// Bytes of one stored light-subpath vertex of vcm and bdpt (a point and its error bound, the BSDF there, the
/// direction, the throughput and the MIS quantities: 240 bytes, since a conductor's BSDF carries a complex
/// index per channel).
pub const LIGHT_VERTEX_BYTES: u64 = 240;

/// Bytes of one light-tracing contribution of vcm, bdpt and lt (a pixel index and a colour, aligned: 32 bytes).
pub const SPLAT_BYTES: u64 = 32;

/// Bytes per vertex of vcm's merge index (a kd-tree of the vertices' positions and indices).
pub const MERGE_TREE_BYTES_PER_VERTEX: u64 = 24;

/// Photons stored per emitted path, an upper bound for scenes of usual albedo (Russian roulette ends a path
/// after 1/(1 − albedo) bounces on average: 3.3 at albedo 0.7).
pub const PHOTONS_PER_PATH: u64 = 4;

/// Bytes per stored photon: the photon (36) and its share of the kd-tree, and of the encoded blob.
pub const BYTES_PER_PHOTON: u64 = 128;

/// Bytes per candidate of a k-nearest query buffer (index and squared distance, with slack).
pub const BYTES_PER_NEIGHBOUR: u64 = 16;

/// The large buffers of a job, in bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryEstimate {
    /// Pixels: the image being assembled, or one strip's.
    pub image: u64,
    /// The global and caustic photon maps.
    pub photon_maps: u64,
    /// The progressive passes' photon maps traced side by side while a block renders ([`passes_at_once`]).
    pub pass_map: u64,
    /// vcm, bdpt and lt: what one pass's light subpaths hold, one subpath per pixel of the whole image
    /// ([`MemoryEstimate::light_paths`]).
    pub light_paths: u64,
    /// vcm, bdpt and lt: the copy of one pass's sums kept apart before it joins the block's.
    pub pass_copy: u64,
    /// The k-nearest buffers of every render thread.
    pub k_nearest: u64,
    /// The decoded texture images (about their blobs' size, each distinct image once); set by the caller that
    /// knows the images ([`MemoryEstimate::strip`] leaves it 0).
    pub textures: u64,
}

/// A job or strip that does not fit the memory it may use.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{setting}: the job needs about {} ({what} {}), more than the {} available; {fits}",
    gib(*needed), gib(*part), gib(*budget)
)]
pub struct BudgetError {
    /// The setting that decides the largest part, e.g. `camera.width × camera.height`.
    pub setting: &'static str,
    /// What the largest part is.
    pub what: &'static str,
    /// Bytes of the largest part.
    pub part: u64,
    /// Bytes of the whole estimate.
    pub needed: u64,
    /// Bytes available.
    pub budget: u64,
    /// What would fit, in the setting's terms.
    pub fits: String,
}

impl MemoryEstimate {
    /// A whole render on one machine: the image, the photon maps, and the strips of its in-process workers
    /// (`strip_rows` rows at a time on `threads` threads).
    pub fn job(width: u32, height: u32, strip_rows: u32, settings: &RenderSettings, threads: usize) -> Self {
        let strip = Self::strip(width, strip_rows.min(height), settings, threads);
        // The coordinator adds the blocks' sums into its own (a block as it arrives is counted in `strip`).
        Self {
            image: pixels(width, height).saturating_mul(IMAGE_BYTES_PER_PIXEL).saturating_add(strip.image),
            photon_maps: Self::photon_maps(settings),
            light_paths: Self::light_paths(width, height, settings),
            ..strip
        }
    }

    /// The bytes of the static photon maps the method reads (none for the others): what the coordinator holds
    /// when it traces them, and what a worker that traces them itself (`StripRequest.trace_photons`) holds.
    pub fn photon_maps(settings: &RenderSettings) -> u64 {
        let paths = match settings.integrator.static_maps() {
            StaticMaps::None => 0,
            StaticMaps::Global => u64::from(settings.photons.global),
            StaticMaps::GlobalAndCaustic => u64::from(settings.photons.global) + u64::from(settings.photons.caustic),
        };
        paths.saturating_mul(PHOTONS_PER_PATH * BYTES_PER_PHOTON)
    }

    /// The bytes one pass of vcm, bdpt or lt holds for its light subpaths, one per pixel of a `width` × `height`
    /// image (0 for the other methods). Each pass traces the subpaths of the whole image whatever rows it
    /// renders. The next pass's subpaths are traced while this pass's camera subpaths run, within what this
    /// pass leaves of the run's storage bound ([`crate::run::Guard`]): the bound, not this estimate of one
    /// pass, caps the two together. Per subpath, [`PHOTONS_PER_PATH`] vertices: vcm and bdpt store each
    /// vertex for the camera subpaths to connect to (vcm also indexes them for merging), and every vertex may
    /// leave a light-tracing splat; vertices and splats are gathered in parallel chunks and then joined, so
    /// they are counted twice. lt stores no vertex, only its splats.
    pub fn light_paths(width: u32, height: u32, settings: &RenderSettings) -> u64 {
        let PassStorage::LightSubpaths(t) = settings.integrator.pass_storage() else { return 0 };
        // Vertices are stored when the camera connects to them (or merges with them), and indexed to merge.
        let vertex = if t.connect || t.merge { LIGHT_VERTEX_BYTES } else { 0 };
        let tree = if t.merge { MERGE_TREE_BYTES_PER_VERTEX } else { 0 };
        let per_vertex = 2 * (vertex + SPLAT_BYTES) + tree;
        // Each subpath's end index (4 bytes), also joined from the chunks.
        pixels(width, height).saturating_mul(PHOTONS_PER_PATH * per_vertex + 8)
    }

    /// One strip of `rows` rows of an image `width` pixels wide on a worker with `threads` render threads (the
    /// photon maps are not counted: they arrived as a blob whose size the worker already limits). For vcm, bdpt
    /// and lt, `light_paths` counts the subpaths of `width` × `rows` pixels, those of a whole-image pass block;
    /// a caller with a block of fewer rows sets it from the image's size ([`MemoryEstimate::light_paths`]).
    pub fn strip(width: u32, rows: u32, settings: &RenderSettings, threads: usize) -> Self {
        let px = pixels(width, rows);
        let storage = settings.integrator.pass_storage();
        let progressive = storage == PassStorage::PhotonMap;
        // vcm merges within a fixed radius: no k-nearest buffers.
        let gathers = settings.integrator.gathers_photons();
        // vcm, bdpt and lt also keep each pass's sums apart before adding them in.
        let pass_copy = if matches!(storage, PassStorage::LightSubpaths(_)) { PASS_COPY_BYTES_PER_PIXEL } else { 0 };
        Self {
            image: px.saturating_mul(STRIP_BYTES_PER_PIXEL),
            photon_maps: 0,
            pass_map: if progressive {
                u64::from(settings.photons.pass_photons)
                    .saturating_mul(PHOTONS_PER_PATH * BYTES_PER_PHOTON)
                    .saturating_mul(u64::from(passes_at_once(settings.photons.pass_photons, threads)))
            } else {
                0
            },
            light_paths: Self::light_paths(width, rows, settings),
            pass_copy: px.saturating_mul(pass_copy),
            k_nearest: if gathers {
                u64::from(settings.photons.k).saturating_mul(BYTES_PER_NEIGHBOUR).saturating_mul(threads as u64)
            } else {
                0
            },
            textures: 0,
        }
    }

    /// The sum of the parts.
    pub fn total(&self) -> u64 {
        [self.image, self.photon_maps, self.pass_map, self.light_paths, self.pass_copy, self.k_nearest, self.textures]
            .iter()
            .fold(0u64, |a, &b| a.saturating_add(b))
    }

    /// `Ok` when the estimate fits `budget` bytes; otherwise the largest part, its setting, and the value of that
    /// setting that would fit with the other parts as they are. `width`, `height` and `settings` are the job's.
    pub fn check(&self, budget: u64, width: u32, height: u32, settings: &RenderSettings) -> Result<(), BudgetError> {
        let needed = self.total();
        if needed <= budget {
            return Ok(());
        }
        let parts = [
            (self.image, Part::Image),
            (self.photon_maps, Part::PhotonMaps),
            (self.pass_map, Part::PassMap),
            (self.light_paths, Part::LightPaths),
            (self.pass_copy, Part::PassCopy),
            (self.k_nearest, Part::KNearest),
            (self.textures, Part::Textures),
        ];
        let (part, largest) = parts.iter().copied().max_by_key(|p| p.0).unwrap_or(parts[0]);
        // The share of the budget the largest part may have, the others staying as they are.
        let room = budget.saturating_sub(needed - part);
        let fits = if room == 0 {
            "the other parts alone do not fit".to_owned()
        } else {
            largest.fits(room as f64 / part.max(1) as f64, width, height, settings)
        };
        let (setting, what) = (largest.setting(), largest.what());
        Err(BudgetError { setting, what, part, needed, budget, fits })
    }
}

/// The parts of an estimate, each decided by one setting.
#[derive(Clone, Copy, Debug)]
enum Part {
    Image,
    PhotonMaps,
    PassMap,
    LightPaths,
    PassCopy,
    KNearest,
    Textures,
}

impl Part {
    fn setting(self) -> &'static str {
        match self {
            Part::Image => "camera.width × camera.height",
            Part::PhotonMaps => "render.photons.global",
            Part::PassMap => "render.photons.pass_photons",
            Part::LightPaths => "camera.width × camera.height",
            Part::PassCopy => "camera.width",
            Part::KNearest => "render.photons.k",
            Part::Textures => "the scene's texture images",
        }
    }

    fn what(self) -> &'static str {
        match self {
            Part::Image => "pixels",
            Part::PhotonMaps => "photon maps",
            Part::PassMap => "progressive passes' photons",
            Part::LightPaths => "a pass's light subpaths",
            Part::PassCopy => "a pass's sums",
            Part::KNearest => "k-nearest buffers",
            Part::Textures => "texture images",
        }
    }

    /// The value of this part's setting that would fit when the part may be `scale` times its size (each part
    /// grows in proportion to its setting; the image with the square of its scale along each side).
    fn fits(self, scale: f64, width: u32, height: u32, settings: &RenderSettings) -> String {
        let times = |v: u32| (f64::from(v) * scale) as u64;
        match self {
            Part::Image | Part::LightPaths => {
                // 1 % short of the square root: the strips in flight, part of `image`, do not shrink with it.
                let s = 0.99 * scale.sqrt();
                let (w, h) = ((f64::from(width) * s) as u32, (f64::from(height) * s) as u32);
                format!("an image of about {w} × {h} pixels would fit")
            }
            Part::PhotonMaps => {
                format!("about {} photon paths (global and caustic together) would fit", times(settings.photons.global))
            }
            Part::PassMap => format!("about {} photon paths per pass would fit", times(settings.photons.pass_photons)),
            Part::PassCopy => format!("an image about {} pixels wide would fit", times(width)),
            Part::KNearest => format!("k = {} would fit", times(settings.photons.k)),
            Part::Textures => format!("textures of {:.0} % of their size would fit", 100.0 * scale),
        }
    }
}

fn pixels(width: u32, rows: u32) -> u64 {
    u64::from(width) * u64::from(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::Method;

    #[test]
    fn a_huge_image_is_refused_with_what_fits() {
        let settings = RenderSettings::default();
        let e = MemoryEstimate::job(65_536, 65_536, 16, &settings, 8);
        assert!(e.image > 140 << 30, "{e:?}");
        let err = e.check(16 << 30, 65_536, 65_536, &settings).unwrap_err();
        assert_eq!(err.setting, "camera.width × camera.height");
        let msg = err.to_string();
        assert!(msg.contains("would fit") && msg.contains("16.0 GiB"), "{msg}");
        // The suggested size does fit.
        let side: u32 = msg.split("image of about ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
        let fits = MemoryEstimate::job(side, side, 16, &settings, 8);
        assert!(fits.check(16 << 30, side, side, &settings).is_ok(), "{msg}: {fits:?}");
        assert!(side > 10_000, "{msg}");
        assert!(MemoryEstimate::job(512, 512, 16, &settings, 8).check(1 << 30, 512, 512, &settings).is_ok());
    }

    #[test]
    fn photon_budgets_name_their_setting() {
        let mut settings = RenderSettings { integrator: Method::PhotonMap, ..Default::default() };
        settings.photons.global = u32::MAX;
        let err = MemoryEstimate::job(64, 64, 64, &settings, 8).check(8 << 30, 64, 64, &settings).unwrap_err();
        assert_eq!(err.setting, "render.photons.global");
        settings.integrator = Method::Progressive;
        settings.photons.pass_photons = u32::MAX;
        let err = MemoryEstimate::strip(64, 1, &settings, 8).check(8 << 30, 64, 1, &settings).unwrap_err();
        assert_eq!(err.setting, "render.photons.pass_photons");
    }

    #[test]
    fn every_block_counts_its_sums_and_subpath_methods_their_light_subpaths() {
        for integrator in Method::ALL {
            let settings = RenderSettings { integrator, ..Default::default() };
            let e = MemoryEstimate::strip(64, 48, &settings, 8);
            assert_eq!(e.image, 64 * 48 * STRIP_BYTES_PER_PIXEL, "{integrator}");
            let light = matches!(integrator, Method::Vcm | Method::Bdpt | Method::Lt);
            assert_eq!(e.pass_copy > 0, light, "{integrator}");
            assert_eq!(e.light_paths > 0, light, "{integrator}");
            assert_eq!(e.pass_map > 0, integrator == Method::Progressive, "{integrator}");
        }
        // One light subpath per pixel: the image size is the setting to change.
        let settings = RenderSettings { integrator: Method::Vcm, ..Default::default() };
        let e = MemoryEstimate::strip(8192, 8192, &settings, 8);
        let err = e.check(8 << 30, 8192, 8192, &settings).unwrap_err();
        assert_eq!(err.setting, "camera.width × camera.height", "{err}");
        assert!(err.to_string().contains("light subpaths"), "{err}");
    }

    #[test]
    fn passes_side_by_side_are_bounded_by_threads_and_memory() {
        assert_eq!(passes_at_once(100_000, 16), 16);
        assert_eq!(passes_at_once(100_000, 0), 1);
        // 2 M paths of about 96 bytes: 2 maps fit 512 MiB.
        assert_eq!(passes_at_once(2_000_000, 16), 2);
        assert_eq!(passes_at_once(u32::MAX, 16), 1);
    }
}
