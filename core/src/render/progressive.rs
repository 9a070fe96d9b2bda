//! `progressive`: probabilistic progressive photon mapping (Knaus & Zwicker 2011, "Progressive Photon Mapping:
//! A Probabilistic Approach", ACM TOG 30(3)).
//!
//! Pass `p` (0-based, numbered over the whole render) traces its own photons from the streams `(seed, p + 2, i)`
//! (0 and 1 belong to the static global and caustic maps), takes camera sample `p` of each pixel, and estimates
//! that pixel's radiance with a box kernel of a radius that depends only on the pass index:
//!
//! `r_{i+1}² = r_i² · (i + α) / (i + 1)` (1-based `i`; Knaus & Zwicker, eq. 15), `r_1 = render.photons.radius`.
//!
//! The passes are independent estimates, and averaging them makes both the variance (`O(1/N^α)`) and the bias
//! (`O(1/N^(1−α))`) vanish (their §4), so the method is consistent. No state is carried from pass to pass, so
//! passes can be rendered anywhere: the farm hands out whole-image **pass blocks**, and each pass is traced
//! exactly once in the whole farm.
//!
//! Direct light comes from light sampling at the visible point; photons carry indirect light only
//! (light → anything⁺ → diffuse), so each light path is counted once.
//!
//! # Exact sums, so the farm's cut never changes a pixel
//! Each pass's estimate of a pixel channel is rounded to fixed point and added as an integer ([`super::sums`]):
//! the image depends only on (scene, seed, passes).

use super::radius::RadiusSequence;
use super::samples::{camera_sample, for_each_pixel};
use super::sums::{BlockSums, add_fixed, finite_or_zero};
use crate::Rgb;
use crate::integrator::volume::{Strategy, in_scattering, segment_point};
use crate::integrator::{Segment, photon_vertex_direct, visible_point, visible_point_in};
use crate::math::Ray;
use crate::method::Method;
use crate::photon::{Estimator, Gather, PhotonMap, photon_flux, volume_radiance};
use crate::prepare::Prepared;
use crate::prepare::budget::{BYTES_PER_PHOTON, passes_at_once};
use crate::prepare::photons::{PhotonKind, trace_photons_guarded, volume_map};
use crate::prepare::tracer::Tracer;
use crate::run::{Cancel, Guard, Meter, RunError};
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

/// Renders progressive photon mapping's passes `passes` over rows `rows`: each pixel channel's sum over those
/// passes of its fixed-point estimate. `progress` gets the passes finished so far; `guard` stops the render
/// (checked before every photon path and every pixel) and bounds each pass's photons.
///
/// Several passes trace their photons and build their maps side by side (as many as the threads, within a
/// memory bound), and each pass's gather then runs over the rows in parallel, while the next group of passes
/// traces its photons: the tail of either keeps no core idle. The passes traced side by side share the
/// storage bound, and a group traced ahead has what the group being gathered leaves of it. A group that does
/// not fit is traced again without the other beside it, and then one pass at a time, so that a pass fails on
/// its storage only when it alone passes the bound, whatever the threads.
pub(super) fn render_passes(
    prep: &Prepared,
    rows: Range<u32>,
    passes: Range<u32>,
    progress: &(dyn Fn(u32) + Sync),
    guard: &Guard,
) -> Result<BlockSums, RunError> {
    let ph = &prep.settings.photons;
    let width = prep.camera.width as usize;
    let mut sums = vec![0i64; 3 * width * rows.len()];
    let (mut rays, mut photon_paths, mut photon_seconds) = (0u64, 0u64, 0.0f64);
    // How many passes trace side by side changes the speed and the memory, never a pixel.
    let mut group = passes_at_once(ph.pass_photons, rayon::current_num_threads());
    let mut done = 0u32;
    let mut radius = RadiusSequence::at(prep.photon_radius(), ph.alpha, passes.start);
    let mut start = passes.start;
    let mut ahead: Option<TracedGroup> = None;
    while start < passes.end {
        let end = start.saturating_add(group).min(passes.end);
        let traced = match ahead.take() {
            Some(traced) if traced.passes == (start..end) && traced.maps.is_ok() => traced,
            _ => trace_group(prep, start..end, guard),
        };
        photon_seconds += traced.seconds;
        let maps = match traced.maps {
            Ok(maps) => maps,
            Err(RunError::Storage(_)) if group > 1 => {
                group = 1;
                continue;
            }
            Err(e) => return Err(e),
        };
        let used = maps.iter().map(|m| m.bytes).sum::<u64>();
        let beside = Guard { cancel: guard.cancel, storage_bytes: guard.storage_bytes.saturating_sub(used) };
        let next = end..end.saturating_add(group).min(passes.end);
        let gather = || -> Result<(), RunError> {
            for (pass, maps) in (start..end).zip(&maps) {
                photon_paths += maps.paths;
                debug_assert_eq!(radius.pass, pass);
                rays += render_pass(prep, &rows, pass, radius.r2(), maps, &mut sums, guard.cancel)?;
                radius = radius.next();
                done += 1;
                progress(done);
            }
            Ok(())
        };
        let (gathered, traced_ahead) =
            rayon::join(gather, || (!next.is_empty()).then(|| trace_group(prep, next.clone(), &beside)));
        gathered?;
        ahead = traced_ahead;
        start = end;
    }
    Ok(BlockSums { rows, units: passes, sums, rays, photon_paths, photon_seconds })
}

/// The photon maps of a group of passes traced side by side, or why they could not be, and the seconds it took.
struct TracedGroup {
    passes: Range<u32>,
    maps: Result<Vec<PassMaps>, RunError>,
    seconds: f64,
}

/// Traces the photon maps of passes `passes` side by side, their photons counted against one bound, `guard`'s.
fn trace_group(prep: &Prepared, passes: Range<u32>, guard: &Guard) -> TracedGroup {
    let t0 = Instant::now();
    let meter = guard.meter("photon", "render.photons.pass_photons", prep.settings.max_depth);
    let maps = passes.clone().into_par_iter().map(|p| pass_map(prep, p, guard.cancel, &meter)).collect();
    TracedGroup { passes, maps, seconds: t0.elapsed().as_secs_f64() }
}

/// The photon maps of one pass: surfaces, and media in a scene that has them.
struct PassMaps {
    surface: Option<PhotonMap>,
    volume: Option<PhotonMap>,
    paths: u64,
    /// What the photons took of the storage bound, [`BYTES_PER_PHOTON`] each.
    bytes: u64,
}

/// The photon maps of pass `pass` and the paths traced for it, its photons counted by `meter`. A map that
/// cannot be built (no photon was stored) contributes nothing.
fn pass_map(prep: &Prepared, pass: u32, cancel: &Cancel, meter: &Meter) -> Result<PassMaps, RunError> {
    let n = u64::from(prep.settings.photons.pass_photons);
    let traced = trace_photons_guarded(prep, n, u64::from(pass) + 2, PhotonKind::Indirect, cancel, meter)?;
    let bytes = (traced.photons.len() + traced.volume.len()) as u64 * BYTES_PER_PHOTON;
    let surface = PhotonMap::build(traced.photons).map_err(|e| tracing::warn!("pass {pass}: {e}")).ok();
    let volume = volume_map(traced.volume).map_err(|e| tracing::warn!("pass {pass}, volume: {e}")).ok().flatten();
    Ok(PassMaps { surface, volume, paths: traced.paths, bytes })
}

/// Adds pass `pass`'s fixed-point estimates of rows `rows`, gathered at squared radius `r2`, to `sums`; returns
/// the rays traced; stops when `cancel` is set.
fn render_pass(
    prep: &Prepared,
    rows: &Range<u32>,
    pass: u32,
    r2: f32,
    maps: &PassMaps,
    sums: &mut [i64],
    cancel: &Cancel,
) -> Result<u64, RunError> {
    let ph = &prep.settings.photons;
    let est = Estimator {
        gather: Gather::Radius { radius: r2.sqrt() },
        kernel: Method::Progressive.kernel(ph.kernel),
        disc: ph.disc,
        same_object: ph.same_object,
    };
    // The volume radius shrinks so that r³ follows the sequence r² follows (the variance of a 3D estimate grows
    // as 1/r³ where a surface's grows as 1/r²; Knaus & Zwicker 2011, §4.3, with dimension 3).
    let r0 = prep.photon_radius();
    let ratio = if r0 > 0.0 { r2 / (r0 * r0) } else { 1.0 };
    let volume = maps.volume.as_ref().map(|v| (v, prep.volume_radius() * crate::math::fmath::cbrt(ratio)));
    let width = prep.camera.width as usize;
    let pixel = |x, y, px: &mut [i64], rays: &mut u64| {
        let (ray, s) = camera_sample(prep, prep.settings.seed, x, y, pass);
        let mut tracer = Tracer::new(prep, s);
        add_fixed(px, pixel_estimate(&mut tracer, ray, maps.surface.as_ref(), volume, &est, r2));
        *rays += tracer.rays;
    };
    for_each_pixel(width, rows, sums, cancel, pixel)
}

/// A pass's radiance estimate along the camera ray `ray` of one pixel sample: emission and light sampling at
/// the visible point, plus the box-kernel photon estimate `β · Σ f·Φ / (π r²)` of `map` at squared radius `r2`
/// there (Knaus & Zwicker 2011, eq. 4). In a scene with media, each medium segment of the camera walk adds
/// single scattering ([`in_scattering`]) and the volume map's box estimate at radius `volume.1` at one point of
/// the segment ([`segment_point`]). Non-finite parts count as zero.
fn pixel_estimate(
    tracer: &mut Tracer,
    ray: Ray,
    map: Option<&PhotonMap>,
    volume: Option<(&PhotonMap, f32)>,
    est: &Estimator,
    r2: f32,
) -> Rgb {
    let prep = tracer.prep;
    let max_depth = prep.settings.max_depth;
    let vp = match &prep.media {
        None => visible_point(tracer, max_depth, ray),
        Some(media) => {
            let mut along = |tracer: &mut Tracer, segment: &Segment| -> Rgb {
                let Some((t, pdf, w)) = segment_point(segment, &mut tracer.sampler) else { return Rgb::ZERO };
                let (r, m) = (segment.ray, segment.medium);
                let mass = m.segment_mass(r, segment.t_max);
                let density = |x: f32| m.distance_pdf(r, x) / mass;
                let direct = in_scattering(tracer, segment, Some((t, pdf)), &density, Strategy::Mis, false);
                let indirect = match volume {
                    Some((v, radius)) => w * volume_radiance(v, r.at(t), r.d, m.g, Gather::Radius { radius }),
                    None => Rgb::ZERO,
                };
                finite_or_zero(direct) + finite_or_zero(indirect)
            };
            visible_point_in(tracer, max_depth, ray, media.camera, &mut along)
        }
    };
    let Some((beta, hit, bsdf, wo)) = vp.vertex else { return finite_or_zero(vp.le) + finite_or_zero(vp.volume) };
    let ld = vp.le + beta * photon_vertex_direct(tracer, &hit, &bsdf, wo, vp.medium);
    let ld = finite_or_zero(ld) + finite_or_zero(vp.volume);
    let Some(map) = map else { return finite_or_zero(ld) };
    let (phi, m) = photon_flux(map, est, &hit, &bsdf, wo);
    let area = std::f32::consts::PI * r2;
    let indirect = if m > 0 && area > 0.0 { beta * phi / area } else { Rgb::ZERO };
    finite_or_zero(ld) + finite_or_zero(indirect)
}
