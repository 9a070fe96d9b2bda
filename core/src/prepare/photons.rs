//! Photon emission and tracing (Jensen's first pass), and the photon maps of a job built from it.
//!
//! Photons leave the lights in proportion to their power: light `l` emits `round(N · Φ_l / Φ)` of the `N`
//! paths (at least one if it has power), each carrying `Φ_l / N_l`, so the emitted power adds up to the
//! lights' power exactly. A point light emits isotropically (Φ = 4πI); a diffuse area light from a uniform
//! point with a cosine-weighted direction (Φ = πLA per side). At every surface with a non-delta component a
//! photon is stored; the BSDF is sampled in importance (flux) mode and Russian roulette on the sampled weight
//! `w = f·|cos θ|/pdf` keeps the path with probability `q = min(1, max(w))`, dividing its power by `q`: a
//! photon's power never grows where `w ≤ 1` (every material here but the Phong lobe near grazing angles).
//!
//! Shading normals (Veach 1997, §5.3): a photon scatters with the adjoint BSDF, its weight multiplied by
//! `|wo·ns|·|wi·ng| / (|wo·ng|·|wi·ns|)` ([`crate::material::bsdf::Bsdf::adjoint_correction`]), and a stored
//! photon's flux by `|wo·ns| / |wo·ng|` ([`crate::material::bsdf::Bsdf::arrival_correction`]); both are 1 where
//! the shading normal is the geometric one. Progressive photon mapping traces its passes here too.
//! Photon `i` of pass `p` draws from the stream `(seed, p, i)`; paths are traced in parallel in fixed chunks and
//! concatenated in order, so the maps are bit-identical whatever the thread count.

use super::Prepared;
use crate::Rgb;
use crate::geometry::NONE;
use crate::material::Material;
use crate::material::bsdf::TransportMode;
use crate::math::Ray;
use crate::math::rng::Sampler;
use crate::medium::HenyeyGreenstein;
use crate::method::StaticMaps;
use crate::photon::{Photon, PhotonMap, PhotonMapError, PhotonMaps, precompute_irradiance};
use crate::prepare::budget::BYTES_PER_PHOTON;
use crate::prepare::tracer::Tracer;
use crate::run::{Cancel, Guard, Meter, NEVER, RunError};
use crate::scene::SceneError;
use rayon::prelude::*;

/// Paths traced per parallel chunk (fixed, so results do not depend on the thread pool).
const CHUNK: u64 = 4096;

/// Which photons a tracing run keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PhotonKind {
    /// Every photon at a non-delta surface (light → anything → diffuse).
    Global,
    /// Only photons whose path from the light was specular until this diffuse hit (light → specular⁺ →
    /// diffuse); the path ends there.
    Caustic,
    /// Photons that have bounced at least once (light → anything⁺ → diffuse): indirect light, for methods
    /// that compute direct light by shadow rays.
    Indirect,
}

/// The photons of one tracing run and how many paths were emitted.
#[derive(Clone, Debug, Default)]
pub struct Traced {
    /// Stored photons, in path order.
    pub photons: Vec<Photon>,
    /// Photons scattered in media (scenes with media only), in path order.
    pub volume: Vec<Photon>,
    /// Paths emitted.
    pub paths: u64,
    /// Power emitted (W) per channel, summed over all paths.
    pub emitted: [f64; 3],
}

/// How many of `n` paths each light emits: proportional to the luminance of its power, every powered light at
/// least one path, the counts summing to `max(n, number of powered lights)`.
pub fn paths_per_light(prep: &Prepared, n: u64) -> Vec<u64> {
    let lum: Vec<f64> =
        prep.lights.lights.iter().map(|l| f64::from(crate::math::luminance(l.power()).max(0.0))).collect();
    let total: f64 = lum.iter().sum();
    if total <= 0.0 || n == 0 {
        return vec![0; lum.len()];
    }
    // Largest-remainder apportionment: deterministic, exact total.
    let raw: Vec<f64> = lum.iter().map(|&w| n as f64 * w / total).collect();
    let mut counts: Vec<u64> = raw.iter().map(|&r| r.floor() as u64).collect();
    let mut left = n.saturating_sub(counts.iter().sum());
    let mut order: Vec<usize> = (0..raw.len()).collect();
    order.sort_by(|&a, &b| (raw[b] - raw[b].floor()).total_cmp(&(raw[a] - raw[a].floor())).then(a.cmp(&b)));
    for &i in &order {
        if left == 0 {
            break;
        }
        if lum[i] > 0.0 {
            counts[i] += 1;
            left -= 1;
        }
    }
    for (c, &w) in counts.iter_mut().zip(&lum) {
        if w > 0.0 && *c == 0 {
            *c = 1;
        }
    }
    counts
}

/// Traces `n` photon paths of pass `pass` and keeps the photons of `kind`, with no bound on their storage and
/// no way to cancel: for runs of known size (tests, benchmarks, a sample of paths). The farm's runs go through
/// [`trace_photons_guarded`].
pub fn trace_photons(prep: &Prepared, n: u64, pass: u64, kind: PhotonKind) -> Traced {
    let unbounded = Guard::unbounded();
    let meter = unbounded.meter("photon", "render.photons.global", prep.settings.max_depth);
    // Neither cancelled nor bounded: it cannot fail.
    trace_photons_guarded(prep, n, pass, kind, &NEVER, &meter).unwrap_or_default()
}

/// [`trace_photons`], stopping when `cancel` is set ([`RunError::Cancelled`], checked before every path) or when
/// the photons stored, [`BYTES_PER_PHOTON`] each, pass `meter`'s bound ([`RunError::Storage`], checked after
/// every path). The storage is one count over all paths, so the run fails on it exactly when all its paths
/// together would store more, whatever the threads.
pub fn trace_photons_guarded(
    prep: &Prepared,
    n: u64,
    pass: u64,
    kind: PhotonKind,
    cancel: &Cancel,
    meter: &Meter,
) -> Result<Traced, RunError> {
    let counts = paths_per_light(prep, n);
    let total: u64 = counts.iter().sum();
    // Light of path i: by ranges of the path index.
    let mut starts = Vec::with_capacity(counts.len());
    let mut acc = 0u64;
    for &c in &counts {
        starts.push(acc);
        acc += c;
    }
    let chunks: Vec<(Vec<Photon>, Vec<Photon>, [f64; 3])> = (0..total.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut out = Vec::new();
            let mut volume = Vec::new();
            let mut emitted = [0.0f64; 3];
            for i in c * CHUNK..((c + 1) * CHUNK).min(total) {
                cancel.check()?;
                meter.check()?;
                let l = starts.partition_point(|&s| s <= i) - 1;
                let phi = prep.lights.lights[l].power() / counts[l] as f32;
                for (e, v) in emitted.iter_mut().zip(phi.to_array()) {
                    *e += f64::from(v);
                }
                let s = Sampler::for_light_path(prep.settings.seed, pass, l as u64, i - starts[l]);
                let before = out.len() + volume.len();
                trace_path(&mut Tracer::new(prep, s), l, phi, kind, &mut out, &mut volume);
                meter.add((out.len() + volume.len() - before) as u64 * BYTES_PER_PHOTON)?;
            }
            Ok((out, volume, emitted))
        })
        .collect::<Result<_, RunError>>()?;
    let mut traced = Traced { paths: total, ..Default::default() };
    for (photons, volume, e) in chunks {
        traced.photons.extend(photons);
        traced.volume.extend(volume);
        for (t, v) in traced.emitted.iter_mut().zip(e) {
            *t += v;
        }
    }
    Ok(traced)
}

/// Emits one photon from light `light` (an index into the light set) with power `phi` (W per channel; its share of the
/// light's power, scaled as [`crate::light::Light::emits_as_sampled`] says), drawing
/// from the tracer's stream, and follows it, appending the surface photons it stores to `out` and, in a scene
/// with media, the photons it scatters in a medium to `volume`.
///
/// In a medium the photon samples a free flight ([`crate::medium::Medium::sample_distance`]); where it scatters
/// it stores its scattered power `w·Φ` (`w = σs·T/p`, the albedo in a grey medium) as a volume photon, then
/// survives Russian roulette with probability `min(1, max(w))`, so its power never grows in a grey medium, and
/// leaves along a Henyey–Greenstein direction. A photon that crosses the segment carries `T/P(pass)` (1 in a
/// grey medium, the transmittance in one that only absorbs).
pub fn trace_path(
    tracer: &mut Tracer,
    light: usize,
    phi: Rgb,
    kind: PhotonKind,
    out: &mut Vec<Photon>,
    volume: &mut Vec<Photon>,
) {
    let prep = tracer.prep;
    let Some(l) = prep.lights.lights.get(light) else { return };
    let media = prep.media.as_ref();
    let mut medium = media.and_then(|m| m.lights.get(light).copied().flatten());
    // The light's choice is the caller's (photons per light in proportion to power): its densities are unused.
    let Some(e) = l.sample_le(&prep.light_scene(), 1.0, &mut tracer.sampler) else { return };
    if let (Some(media), Some((object, n))) = (media, e.surface) {
        medium = media.leaving(object, n, e.ray.d, medium);
    }
    let mut ray = e.ray;
    // A light that emits in proportion to its sampling density gives every photon the same share `phi`; a spot
    // light's falloff and an environment image's colours make the sample's weight vary about its mean, the
    // light's power: the photon carries its share scaled by that ratio.
    let mut power = if l.emits_as_sampled() { phi } else { phi * e.beta / l.power() };
    let mut specular_only = true;
    let (mut depth, mut crossings) = (0u32, 0u32);
    while depth < prep.settings.max_depth {
        // Photon tracing counts paths, not rays (see `Tracer::rays`).
        let found = prep.geometry.intersect(&ray, f32::INFINITY);
        if let Some(m) = medium.filter(|m| !m.is_vacuum()) {
            let t_max = found.as_ref().map_or(f32::INFINITY, |h| h.t);
            let flight = m.sample_distance(&ray, t_max, &mut tracer.sampler);
            if flight.scattered {
                let x = ray.at(flight.t);
                if keeps(kind, specular_only, depth) {
                    volume.push(Photon::new(x, -ray.d, -ray.d, power * flight.weight, NONE));
                }
                // Past a scattering in a medium no photon of this path is a caustic one.
                if !survives(&mut power, flight.weight, &mut tracer.sampler) || kind == PhotonKind::Caustic {
                    return;
                }
                specular_only = false;
                let wi = HenyeyGreenstein { g: m.g }.sample(ray.d, tracer.sampler.next_2d()).wi;
                ray = Ray::new(x, wi);
                (depth, crossings) = (depth + 1, 0);
                continue;
            }
            power *= flight.weight;
            if !power.is_finite() || power == Rgb::ZERO {
                return;
            }
        }
        let Some(hit) = found else { return };
        let Some(material) = prep.materials.get(hit.material as usize) else { return };
        if let Some(media) = media
            && material.is_interface()
        {
            // Not a bounce: the photon goes on in the medium on the other side.
            crossings += 1;
            if crossings > crate::medium::MAX_CROSSINGS {
                return;
            }
            medium = media.after(&hit, ray.d, medium);
            ray = hit.spawn_ray(ray.d);
            continue;
        }
        let bsdf = material.bsdf(&hit, &prep.textures);
        let wo = -ray.d;
        if bsdf.black_from(wo) {
            // The back of a one-sided surface absorbs the photon; it is not stored.
            return;
        }
        let stores = bsdf.stores_photons(prep.settings.photons.min_roughness);
        if stores && keeps(kind, specular_only, depth) {
            // Store the normal on the side the photon arrived from, and the flux as the shading normal sees it
            // (`Bsdf::arrival_correction`), so that density estimates match the path tracer on smooth-shaded
            // surfaces.
            let n = hit.normal_towards(wo);
            out.push(Photon::new(hit.p, wo, n, power * bsdf.arrival_correction(wo), hit.object));
        }
        // A zero BSDF value, which `sample_bsdf` refuses, would have ended the path in `survives` (q = 0).
        let Some(bs) = tracer.sample_bsdf(&bsdf, wo, TransportMode::Importance) else { return };
        // Photons carry flux: the adjoint of the shading-normal BSDF (Veach 1997, eq. 5.17).
        let w = bsdf.sample_weight(wo, &bs, bs.pdf, TransportMode::Importance);
        if !survives(&mut power, w, &mut tracer.sampler) {
            return;
        }
        // A bounce off a lobe too glossy to store photons is specular for the maps: the light it sends to a
        // diffuse surface is a caustic, and the camera paths walk through it to find it there.
        specular_only &= bs.delta || !stores;
        if kind == PhotonKind::Caustic && !specular_only {
            // Past a diffuse bounce no photon of this path can be a caustic one.
            return;
        }
        if let Some(media) = media {
            medium = media.after(&hit, bs.wi, medium);
        }
        ray = hit.spawn_ray(bs.wi);
        (depth, crossings) = (depth + 1, 0);
    }
}

/// Whether a photon of `kind` is stored at bounce `depth` (0: straight from the light) of a path whose bounces
/// so far were all specular (`specular_only`).
#[inline]
fn keeps(kind: PhotonKind, specular_only: bool, depth: u32) -> bool {
    match kind {
        PhotonKind::Global => true,
        PhotonKind::Caustic => specular_only && depth > 0,
        PhotonKind::Indirect => depth > 0,
    }
}

/// Photon tracing's Russian roulette on a scattering of weight `w` (`f·|cos|/pdf` at a surface, `σs·T/p` in a
/// medium): the photon survives with probability `q = min(1, max(w))` and its power becomes `power·w/q`, so it
/// never grows where `w ≤ 1`. Whether the photon goes on: it survived and its power is finite. Draws one
/// sample, unless `q` is not positive (or NaN).
#[inline]
fn survives(power: &mut Rgb, w: Rgb, s: &mut Sampler) -> bool {
    let q = w.max_element().min(1.0);
    if q.is_nan() || q <= 0.0 || s.next_f32() >= q {
        return false;
    }
    *power *= w / q;
    power.is_finite()
}

impl Prepared {
    /// The prepared scene with the photon maps its method needs (`photons` is `None` for methods without maps,
    /// and for progressive photon mapping, which traces its own photons pass by pass). `scene_path` names the
    /// scene in errors.
    ///
    /// The maps are traced under this machine's guard ([`Guard::machine`]): their photons may take up to half
    /// its memory.
    ///
    /// # Errors
    /// [`SceneError::Photons`] when a map cannot be built (a stored photon that is not finite, or more photons
    /// than the guard allows).
    pub fn with_photon_maps(mut self, scene_path: &std::path::Path) -> Result<Self, SceneError> {
        self.photons = self
            .photon_maps_if_needed(&Guard::machine(&NEVER))
            .map_err(|source| SceneError::Photons { path: scene_path.into(), source })?;
        Ok(self)
    }

    /// The photon maps the method needs, or `None` when it needs none ([`Prepared::build_photon_maps`]).
    pub fn photon_maps_if_needed(&self, guard: &Guard) -> Result<Option<PhotonMaps>, PhotonMapError> {
        if self.settings.integrator.needs_photon_maps() { self.build_photon_maps(guard).map(Some) } else { Ok(None) }
    }

    /// Whether the method reads a caustic map: `final-gather` on a scene with a mirror or glass.
    fn needs_caustic_map(&self) -> bool {
        self.settings.integrator.static_maps() == StaticMaps::GlobalAndCaustic
            && self.materials.iter().any(Material::has_specular)
    }

    /// The photon paths [`Prepared::build_photon_maps`] traces: the global map's, and the caustic map's when the
    /// method has one (each at least one per powered light, [`paths_per_light`]).
    pub fn photon_map_paths(&self) -> u64 {
        let ph = &self.settings.photons;
        let paths = |n: u32| paths_per_light(self, u64::from(n)).iter().sum::<u64>();
        paths(ph.global) + if self.needs_caustic_map() { paths(ph.caustic) } else { 0 }
    }

    /// Traces and builds the photon maps of the method: the global map, and the caustic map for
    /// `final-gather` when some material has a delta (mirror or glass) component. Both maps' photons count
    /// against one bound, `guard.storage_bytes`, and the tracing stops when `guard.cancel` is set.
    ///
    /// # Errors
    /// [`PhotonMapError::Run`] when cancelled or over the storage bound; the others when a map cannot be built.
    pub fn build_photon_maps(&self, guard: &Guard) -> Result<PhotonMaps, PhotonMapError> {
        let ph = &self.settings.photons;
        let setting = if self.needs_caustic_map() {
            "render.photons.global or render.photons.caustic"
        } else {
            "render.photons.global"
        };
        let meter = guard.meter("photon", setting, self.settings.max_depth);
        let global = trace_photons_guarded(self, u64::from(ph.global), 0, PhotonKind::Global, guard.cancel, &meter)?;
        tracing::info!(
            paths = global.paths,
            photons = global.photons.len(),
            volume = global.volume.len(),
            "global photon map traced"
        );
        let volume = volume_map(global.volume)?;
        let global = PhotonMap::build(global.photons)?;
        let caustic = if self.needs_caustic_map() {
            // Pass index 1 keeps the caustic streams apart from the global ones.
            let c = trace_photons_guarded(self, u64::from(ph.caustic), 1, PhotonKind::Caustic, guard.cancel, &meter)?;
            tracing::info!(paths = c.paths, photons = c.photons.len(), "caustic photon map traced");
            Some(PhotonMap::build(c.photons)?)
        } else {
            None
        };
        let estimator = self.estimator();
        let irradiance = if self.settings.integrator.static_maps() == StaticMaps::GlobalAndCaustic {
            guard.cancel.check()?;
            let entries = precompute_irradiance(&global, &estimator, 4);
            Some(PhotonMap::build(entries)?)
        } else {
            None
        };
        Ok(PhotonMaps { global, caustic, estimator, irradiance, volume, volume_gather: self.volume_gather() })
    }
}

/// The volume photon map of some photons: `None` when there are none (a scene without media, or whose media
/// no photon reached).
pub fn volume_map(photons: Vec<Photon>) -> Result<Option<PhotonMap>, PhotonMapError> {
    if photons.is_empty() { Ok(None) } else { PhotonMap::build(photons).map(Some) }
}
