//! A strip request checked into a [`StripOrder`]: its blob ids, its frame (decoded once, with the size limit),
//! rows, units, work and memory, each refusal naming the field ([`check_strip_request`]).

use crate::config::Limits;
use photon_core::method::Unit;
use photon_core::prepare::blobs::Frame;
use photon_core::prepare::budget::MemoryEstimate;
use photon_core::render::sums::MAX_BLOCK_UNITS;
use photon_core::scene::RenderSettings;
use photon_proto::pb;
use photon_proto::quote;
use std::ops::Range;
use tonic::Status;

/// The most texture images one request may name.
pub const MAX_TEXTURES: usize = 4096;

/// The longest frame blob accepted (a camera and render settings take a few hundred bytes).
pub const MAX_FRAME_BYTES: usize = 64 << 10;

/// A strip request that passed [`check_strip_request`]: what the render needs, with its frame decoded.
#[derive(Clone, Debug)]
pub struct StripOrder {
    pub(crate) scene_blob: String,
    pub(crate) photons_blob: String,
    pub(crate) texture_blobs: Vec<String>,
    /// The frame blob's id: decoded jobs are kept by their blobs' ids.
    pub(crate) frame_id: String,
    pub(crate) frame: Frame,
    pub(crate) trace_photons: bool,
    pub(crate) strip: u32,
    pub(crate) attempt: u32,
    pub(crate) rows: Range<u32>,
    pub(crate) units: Range<u32>,
}

impl StripOrder {
    /// The decoded and checked frame: camera and render settings.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// The rows to render, within the frame's image.
    pub fn rows(&self) -> Range<u32> {
        self.rows.clone()
    }

    /// The units (samples per pixel, or passes) to render, within the job's.
    pub fn units(&self) -> Range<u32> {
        self.units.clone()
    }
}

/// Checks a strip request before anything is looked up or allocated from it: blob ids, the frame (decoded with
/// at most [`MAX_FRAME_BYTES`] and checked as the scene's validation checks a scene: sizes, finite camera,
/// settings in range), the rows against the frame's image, the method against the blobs present, and the strip's
/// memory against `limits`. Returns the order the render takes, with the decoded frame. A refusal names the
/// field and quotes at most a short prefix of a received value.
pub fn check_strip_request(r: pb::StripRequest, limits: &Limits) -> Result<StripOrder, Status> {
    check_blob_ids(&r)?;
    if r.row_start >= r.row_end {
        return Err(Status::out_of_range(format!("empty or reversed rows {}..{}", r.row_start, r.row_end)));
    }
    let frame = Frame::decode(&r.frame, MAX_FRAME_BYTES).map_err(|e| Status::invalid_argument(e.to_string()))?;
    let height = frame.camera.height;
    if r.row_end > height {
        return Err(Status::out_of_range(format!(
            "rows {}..{} are outside the image's {height} rows",
            r.row_start, r.row_end
        )));
    }
    check_photon_maps(&r, &frame.settings)?;
    check_units(&r, &frame.settings)?;
    check_work(&r, &frame, limits)?;
    check_memory(&r, &frame, limits)?;
    Ok(StripOrder {
        frame_id: photon_proto::blob_id(&r.frame),
        scene_blob: r.scene_blob,
        photons_blob: r.photons_blob,
        texture_blobs: r.texture_blobs,
        frame,
        trace_photons: r.trace_photons,
        strip: r.strip,
        attempt: r.attempt,
        rows: r.row_start..r.row_end,
        units: r.unit_start..r.unit_end,
    })
}

/// Refuses a request whose scene, photons or texture ids are not blob ids, or that names too many textures.
fn check_blob_ids(r: &pb::StripRequest) -> Result<(), Status> {
    if !photon_proto::is_blob_id(&r.scene_blob) {
        return Err(Status::invalid_argument(format!(
            "scene_blob: {} is not a blob id (64 lowercase hex digits)",
            quote(&r.scene_blob)
        )));
    }
    if !r.photons_blob.is_empty() && !photon_proto::is_blob_id(&r.photons_blob) {
        return Err(Status::invalid_argument(format!(
            "photons_blob: {} is not a blob id (64 lowercase hex digits, or empty)",
            quote(&r.photons_blob)
        )));
    }
    if r.texture_blobs.len() > MAX_TEXTURES {
        return Err(Status::invalid_argument(format!(
            "texture_blobs: {} ids, at most {MAX_TEXTURES} expected",
            r.texture_blobs.len()
        )));
    }
    if let Some((i, id)) = r.texture_blobs.iter().enumerate().find(|(_, id)| !photon_proto::is_blob_id(id)) {
        return Err(Status::invalid_argument(format!(
            "texture_blobs[{i}]: {} is not a blob id (64 lowercase hex digits)",
            quote(id)
        )));
    }
    // Each texture is decoded once per job: the same id twice would decode (and hold) a copy per name.
    let mut seen = std::collections::HashMap::with_capacity(r.texture_blobs.len());
    for (i, id) in r.texture_blobs.iter().enumerate() {
        if let Some(first) = seen.insert(id.as_str(), i) {
            return Err(Status::invalid_argument(format!(
                "texture_blobs[{i}]: blob {id} is named already at texture_blobs[{first}]; each texture once expected"
            )));
        }
    }
    Ok(())
}

/// Refuses a request whose photon maps come both ways, or that brings them (a photons blob, or `trace_photons`)
/// when the frame's method reads none or omits them when it reads them.
fn check_photon_maps(r: &pb::StripRequest, settings: &RenderSettings) -> Result<(), Status> {
    let method = settings.integrator;
    if r.trace_photons && !r.photons_blob.is_empty() {
        return Err(Status::invalid_argument(
            "trace_photons: the worker is asked to trace the photon maps and is sent them too; expected one or the \
             other",
        ));
    }
    let maps_given = !r.photons_blob.is_empty() || r.trace_photons;
    if method.needs_photon_maps() != maps_given {
        let (needs, sent) = if maps_given {
            ("needs no", "a photons blob or trace_photons was sent")
        } else {
            ("needs", "neither a photons blob nor trace_photons was sent")
        };
        return Err(Status::invalid_argument(format!(
            "photons_blob: the frame's method `{method}` {needs} photon maps, and {sent}"
        )));
    }
    Ok(())
}

/// Checks a request's units against its frame: a non-empty block of at most [`MAX_BLOCK_UNITS`] within the
/// job's units ([`RenderSettings::units`]: samples per pixel, or passes).
fn check_units(r: &pb::StripRequest, settings: &RenderSettings) -> Result<(), Status> {
    let (start, end, total) = (r.unit_start, r.unit_end, settings.units());
    let what = match settings.integrator.unit() {
        Unit::Samples => "samples per pixel",
        Unit::Passes => "passes",
    };
    if start >= end || end > total {
        return Err(Status::out_of_range(format!(
            "unit_start/unit_end {start}..{end}: expected a non-empty block within the job's {total} {what}"
        )));
    }
    if end - start > MAX_BLOCK_UNITS {
        return Err(Status::invalid_argument(format!(
            "unit_start/unit_end {start}..{end}: expected at most {MAX_BLOCK_UNITS} units in one block"
        )));
    }
    Ok(())
}

/// Refuses a strip that asks for more than `limits.max_strip_work` path vertices: pixels × units ×
/// `render.max_depth` (a bound on the bounces, not the work a scene will take, which roulette usually ends
/// sooner).
fn check_work(r: &pb::StripRequest, frame: &Frame, limits: &Limits) -> Result<(), Status> {
    let pixels = u64::from(frame.camera.width) * u64::from(r.row_end - r.row_start);
    let units = u64::from(r.unit_end.saturating_sub(r.unit_start));
    let work = pixels.saturating_mul(units).saturating_mul(u64::from(frame.settings.max_depth.max(1)));
    if work > limits.max_strip_work {
        return Err(Status::invalid_argument(format!(
            "the strip asks for {work} path vertices ({pixels} pixels × {units} units × render.max_depth {}), \
             more than this worker's limit of {} (photon-worker --max-strip-work)",
            frame.settings.max_depth, limits.max_strip_work
        )));
    }
    Ok(())
}

/// Refuses a strip whose buffers would not fit the worker's strip memory (`limits`), the texture images it
/// decodes (`limits.texture_bytes`: the named blobs' sizes; a texture named twice is refused first) included.
fn check_memory(r: &pb::StripRequest, frame: &Frame, limits: &Limits) -> Result<(), Status> {
    let (width, height, rows) = (frame.camera.width, frame.camera.height, r.row_end - r.row_start);
    let mut estimate = MemoryEstimate::strip(width, rows, &frame.settings, limits.threads);
    estimate.textures = limits.texture_bytes;
    // A pass of vcm, bdpt or lt traces the light subpaths of the whole image, whatever rows it renders.
    estimate.light_paths = MemoryEstimate::light_paths(width, height, &frame.settings);
    if r.trace_photons {
        // Maps traced here are held here (received ones were bounded by the blob size limit on upload).
        estimate.photon_maps = MemoryEstimate::photon_maps(&frame.settings);
    }
    estimate
        .check(limits.strip_memory_bytes, width, rows, &frame.settings)
        .map_err(|e| Status::resource_exhausted(format!("this worker cannot render the strip: {e}")))
}
