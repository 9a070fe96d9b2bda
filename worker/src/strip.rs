//! A strip from request to events: the request is checked into a [`StripOrder`] (its frame decoded once, with
//! the size limit), queued for the render slot, its job found in the cache of decoded jobs or made from the
//! blobs, the block rendered on the worker's pool, and its fixed-point sums sent as chunks of rows and a summary.

use crate::Worker;
use crate::cache::BlobCache;
use crate::config::Limits;
use photon_core::method::Unit;
use photon_core::photon::PhotonMapError;
use photon_core::prepare::Prepared;
use photon_core::prepare::blobs::{Frame, FrameError, decode_textures};
use photon_core::prepare::budget::MemoryEstimate;
use photon_core::render::sums::MAX_BLOCK_UNITS;
use photon_core::render::{Block, render_block};
use photon_core::run::{Cancel, Guard, RunError};
use photon_core::scene::RenderSettings;
use photon_proto::pb::{self, strip_event::Event};
use photon_proto::{MAX_CHUNK, quote};
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

/// One message of a strip's response stream: an event, or the status that ends the stream.
pub(crate) type EventOrStatus = Result<pb::StripEvent, Status>;

/// The most texture images one request may name.
pub const MAX_TEXTURES: usize = 4096;

/// The longest frame blob accepted (a camera and render settings take a few hundred bytes).
pub const MAX_FRAME_BYTES: usize = 64 << 10;

/// Decoded jobs kept (the most recently used); an older job is decoded again from its blobs when asked for.
const JOBS_KEPT: usize = 2;

/// A strip request that passed [`check_strip_request`]: what the render needs, with its frame decoded.
#[derive(Clone, Debug)]
pub struct StripOrder {
    scene_blob: String,
    photons_blob: String,
    texture_blobs: Vec<String>,
    /// The frame blob's id: decoded jobs are kept by their blobs' ids.
    frame_id: String,
    frame: Frame,
    trace_photons: bool,
    strip: u32,
    attempt: u32,
    rows: Range<u32>,
    units: Range<u32>,
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

/// The decoded scene of one job.
struct Job {
    key: [String; 4],
    prep: Prepared,
    /// What making the job cost and no finished strip has reported yet: the strip that made it may be
    /// cancelled (a tail copy that lost), and its cost then goes with the next strip of the job.
    unreported: Mutex<Load>,
}

/// What making a job cost this worker: decoding its blobs, and tracing its photon maps when it traced them.
#[derive(Clone, Copy, Debug, Default)]
struct Load {
    /// Seconds spent decoding the blobs (and rebuilding received photon maps' trees).
    seconds: f64,
    /// Photon paths traced for the job's maps (0 when they were received).
    photon_paths: u64,
    /// Seconds spent tracing those paths and building their maps.
    photon_seconds: f64,
}

impl Job {
    /// Adds what making the job cost and no strip has reported yet to `summary`, and forgets it.
    fn report_load(&self, summary: &mut pb::StripSummary) {
        let load = std::mem::take(&mut *self.unreported.lock().unwrap_or_else(std::sync::PoisonError::into_inner));
        summary.load_seconds = load.seconds;
        summary.photon_paths += load.photon_paths;
        summary.photon_seconds += load.photon_seconds;
    }
}

/// The most recently used decoded jobs (at most [`JOBS_KEPT`]), most recent last.
#[derive(Default)]
pub(crate) struct JobCache {
    jobs: Mutex<Vec<Arc<Job>>>,
}

impl JobCache {
    /// Forgets what making the jobs cost and no strip reported: a new session's report is not charged with an
    /// earlier session's work (whose report was complete without it).
    pub(crate) fn forget_unreported(&self) {
        for job in self.jobs.lock().unwrap_or_else(std::sync::PoisonError::into_inner).iter() {
            *job.unreported.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Load::default();
        }
    }

    /// The job of an order: from the cache, or decoded from its blobs (with its photon maps traced here when
    /// the order says so) on `pool`; what that cost is kept in [`Job::unreported`].
    fn get_or_make(
        &self,
        order: &StripOrder,
        pool: &rayon::ThreadPool,
        blobs: &BlobCache,
        guard: &Guard,
    ) -> Result<Arc<Job>, Status> {
        // A traced map and a received one are the same bits, but keep the jobs apart all the same.
        let photons = if order.trace_photons { "traced".to_owned() } else { order.photons_blob.clone() };
        let key = [order.scene_blob.clone(), photons, order.frame_id.clone(), order.texture_blobs.join(",")];
        // A panic while the lock was held (a bug, caught by `render_guarded`) leaves a list of whole jobs.
        let mut jobs = self.jobs.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(i) = jobs.iter().position(|j| j.key == key) {
            let job = jobs.remove(i);
            jobs.push(job.clone());
            return Ok(job);
        }
        let t0 = Instant::now();
        let blob = |id: &str| {
            blobs.get(id).ok_or_else(|| Status::not_found(format!("blob {id} was evicted; upload it again")))
        };
        let scene = blob(&order.scene_blob)?;
        let photons = if order.photons_blob.is_empty() { None } else { Some(blob(&order.photons_blob)?) };
        let photons = photons.as_deref().map(Vec::as_slice);
        let textures = order.texture_blobs.iter().map(|id| blob(id)).collect::<Result<Vec<_>, _>>()?;
        let textures: Vec<&[u8]> = textures.iter().map(|b| b.as_slice()).collect();
        let mut prep = pool
            .install(|| prepare(&scene, photons, &textures, &order.frame))
            .map_err(|e| Status::invalid_argument(format!("the job's blobs do not decode: {e}")))?;
        let mut load = Load { seconds: t0.elapsed().as_secs_f64(), ..Load::default() };
        if order.trace_photons {
            let t1 = Instant::now();
            // Deterministic streams: the same maps as the coordinator would have traced and shipped.
            let maps = pool.install(|| prep.build_photon_maps(guard)).map_err(|e| match e {
                PhotonMapError::Run(e) => run_status(e),
                e => Status::invalid_argument(format!("the job's photon maps cannot be built: {e}")),
            })?;
            load.photon_paths = prep.photon_map_paths();
            load.photon_seconds = t1.elapsed().as_secs_f64();
            prep.photons = Some(maps);
        }
        if prep.settings.integrator.needs_photon_maps() && prep.photons.is_none() {
            return Err(Status::invalid_argument(format!(
                "the method `{}` needs photon maps and the photons blob holds none",
                prep.settings.integrator
            )));
        }
        let job = Arc::new(Job { key, prep, unreported: Mutex::new(load) });
        jobs.push(job.clone());
        if jobs.len() > JOBS_KEPT {
            jobs.remove(0);
        }
        Ok(job)
    }
}

/// A prepared scene from a job's blobs and its frame, which [`check_strip_request`] decoded already. The blobs
/// were bounded by the blob size limit on upload and hashed to their ids, so they are decoded without a further
/// limit; the texture images first, as the scene's materials are checked against their slots.
fn prepare(scene: &[u8], photons: Option<&[u8]>, textures: &[&[u8]], frame: &Frame) -> Result<Prepared, FrameError> {
    let textures = Arc::new(decode_textures(textures, usize::MAX)?);
    let mut prep = Prepared::from_scene_blob(scene, textures, frame.camera, frame.settings.clone(), usize::MAX)?;
    prep.photons = photons.map(|p| photon_core::codec::decode(p, usize::MAX)).transpose()?;
    Ok(prep)
}

/// The status of a run that stopped: its call ended (cancelled, dropped or past its deadline), or it would
/// store more than this worker's memory allows (`FAILED_PRECONDITION`: the same strip fails the same way on
/// this worker however often it is sent).
fn run_status(e: RunError) -> Status {
    match e {
        RunError::Cancelled => Status::cancelled("the strip's call ended (the coordinator cancelled it or left)"),
        RunError::Storage(e) => Status::failed_precondition(format!("this worker cannot render the strip: {e}")),
    }
}

/// What a strip's blocking render needs from the worker.
struct StripContext {
    pool: Arc<rayon::ThreadPool>,
    blobs: Arc<BlobCache>,
    jobs: Arc<JobCache>,
    /// Set when the strip's call ends: the render stops soon after.
    cancel: Arc<Cancel>,
    /// Bytes one run's photons or light vertices may take ([`crate::Config::strip_memory_bytes`]).
    storage_bytes: u64,
    #[cfg(feature = "fault-injection")]
    faults: Arc<crate::fault::Injector>,
}

impl StripContext {
    /// [`StripContext::render`], with a panic (a bug: every request was checked before) turned into an
    /// `INTERNAL` status for this strip, so the worker keeps serving the others.
    fn render_guarded(
        &self,
        order: &StripOrder,
        tx: &mpsc::Sender<EventOrStatus>,
    ) -> Result<Vec<EventOrStatus>, Status> {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.render(order, tx))).unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            tracing::error!(strip = order.strip, "the render panicked: {what}");
            Err(Status::internal(format!(
                "strip {} (rows {}..{}) panicked on this worker: {}; this is a bug in photon",
                order.strip,
                order.rows.start,
                order.rows.end,
                quote(&what)
            )))
        })
    }

    /// Renders the strip, sending progress on `tx` as it goes; returns the sums and summary events.
    fn render(&self, order: &StripOrder, tx: &mpsc::Sender<EventOrStatus>) -> Result<Vec<EventOrStatus>, Status> {
        // The rows and units were checked against this frame by `check_strip_request` before the call started.
        let guard = Guard { cancel: &self.cancel, storage_bytes: self.storage_bytes };
        let job = self.jobs.get_or_make(order, &self.pool, &self.blobs, &guard)?;
        tracing::info!(strip = order.strip, attempt = order.attempt, rows = ?order.rows, "rendering strip");
        #[cfg(feature = "fault-injection")]
        self.faults.before_render(order.strip, &|| tx.is_closed())?;
        let t0 = Instant::now();
        let progress = |units: u32| {
            // A full channel only delays a progress report (a closed one has set the cancel flag already).
            let _ = tx.try_send(Ok(pb::StripEvent { event: Some(Event::UnitsDone(units)) }));
        };
        let block = Block { rows: order.rows(), units: order.units() };
        let block = self.pool.install(|| render_block(&job.prep, &block, &progress, &guard)).map_err(run_status)?;
        let sums = block.sums;
        #[cfg(feature = "fault-injection")]
        let sums = self.faults.before_checksum(order.strip, sums);
        let bytes = photon_proto::sums_to_bytes(&sums);
        let mut summary = pb::StripSummary {
            rays: block.rays,
            photon_paths: block.photon_paths,
            photon_seconds: block.photon_seconds,
            render_seconds: t0.elapsed().as_secs_f64(),
            checksum: photon_proto::checksum(&bytes).to_vec(),
            ..Default::default()
        };
        job.report_load(&mut summary);
        #[cfg(feature = "fault-injection")]
        let bytes = self.faults.after_checksum(order.strip, bytes);
        Ok(strip_events(&bytes, job.prep.camera.width, order.rows.start, summary))
    }
}

/// A strip's events: its sums' bytes (`3 × 8` per pixel of a `width`-pixel row, from row `first_row`) in chunks
/// of whole rows of at most [`MAX_CHUNK`] bytes (one row when a row is larger), then the summary.
fn strip_events(bytes: &[u8], width: u32, first_row: u32, summary: pb::StripSummary) -> Vec<EventOrStatus> {
    let row_bytes = 3 * 8 * width as usize;
    let rows_per_chunk = (MAX_CHUNK / row_bytes.max(1)).max(1);
    let mut events: Vec<EventOrStatus> = bytes
        .chunks(rows_per_chunk * row_bytes)
        .enumerate()
        .map(|(i, c)| {
            let rows = pb::PixelRows { first_row: first_row + (i * rows_per_chunk) as u32, data: c.to_vec() };
            Ok(pb::StripEvent { event: Some(Event::Sums(rows)) })
        })
        .collect();
    events.push(Ok(pb::StripEvent { event: Some(Event::Done(summary)) }));
    events
}

impl Worker {
    /// `RenderStrip`: checks the request, queues it for the render slot (refused beyond [`crate::Config::max_queue`])
    /// and streams the strip's events as the render on the pool produces them.
    pub(crate) async fn start_strip(
        &self,
        request: Request<pb::StripRequest>,
    ) -> Result<Response<ReceiverStream<EventOrStatus>>, Status> {
        // Held until the strip's last event is sent (or it is cancelled).
        let call = self.peers.admit(request.remote_addr())?;
        let r = request.into_inner();
        for id in [&r.scene_blob, &r.photons_blob].into_iter().chain(&r.texture_blobs) {
            if photon_proto::is_blob_id(id) && !self.blobs.contains(id) {
                return Err(Status::not_found(format!("blob {id} is unknown here: upload it with PutBlob first")));
            }
        }
        // The texture images this strip decodes, from their blobs' sizes (not read here); a request that names
        // one twice is refused by the check before its memory is.
        let texture_bytes = r.texture_blobs.iter().filter_map(|id| self.blobs.size(id)).fold(0u64, u64::saturating_add);
        let order = check_strip_request(r, &Limits { texture_bytes, ..self.limits() })?;
        if self.waiting.load(Ordering::Relaxed) >= self.config.max_queue {
            return Err(Status::resource_exhausted(format!(
                "{} strips already queued here; send fewer at once",
                self.config.max_queue
            )));
        }
        self.waiting.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = mpsc::channel(32);
        let cancel = Arc::new(Cancel::new());
        let ctx = StripContext {
            pool: self.pool.clone(),
            blobs: self.blobs.clone(),
            jobs: self.jobs.clone(),
            cancel: cancel.clone(),
            storage_bytes: self.config.strip_memory_bytes,
            #[cfg(feature = "fault-injection")]
            faults: self.faults.clone(),
        };
        let slot = self.render_slot.clone();
        let waiting = self.waiting.clone();
        tokio::spawn(async move {
            let _call = call;
            // A strip whose caller leaves (cancels, drops the call, or passes its deadline) while it waits gives
            // up its place in the queue at once.
            let permit = tokio::select! {
                permit = slot.acquire_owned() => permit,
                () = tx.closed() => {
                    waiting.fetch_sub(1, Ordering::Relaxed);
                    return;
                }
            };
            waiting.fetch_sub(1, Ordering::Relaxed);
            let Ok(_permit) = permit else { return };
            if tx.is_closed() {
                return;
            }
            // The render reads the flag before every sample, pixel and path: the slot is free soon after.
            let watch = {
                let tx = tx.clone();
                tokio::spawn(async move {
                    tx.closed().await;
                    cancel.cancel();
                })
            };
            let render_tx = tx.clone();
            let outcome = tokio::task::spawn_blocking(move || ctx.render_guarded(&order, &render_tx)).await;
            watch.abort();
            let events = match outcome {
                Ok(Ok(events)) => events,
                Ok(Err(status)) => vec![Err(status)],
                Err(e) => vec![Err(Status::internal(format!("the render failed: {e}")))],
            };
            for e in events {
                if tx.send(e).await.is_err() {
                    break;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }
}
