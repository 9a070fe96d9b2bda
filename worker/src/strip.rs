//! A strip from request to events: the request is checked into a [`StripOrder`] (`order.rs`), queued for the
//! render slot, its job found in the cache of decoded jobs or made from the blobs (`jobs.rs`), the block
//! rendered on the worker's pool, and its fixed-point sums sent as chunks of rows and a summary.

use crate::cache::BlobCache;
use crate::config::Limits;
use crate::jobs::{JobCache, run_status};
use crate::order::{StripOrder, check_strip_request};
use crate::service::{EventOrStatus, Worker};
use photon_core::render::{Block, render_block};
use photon_core::run::{Cancel, Guard};
use photon_proto::pb::{self, strip_event::Event};
use photon_proto::{MAX_CHUNK, quote};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

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
        tracing::info!(strip = order.strip, attempt = order.attempt, bytes = bytes.len(), "strip rendered, sending it");
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
