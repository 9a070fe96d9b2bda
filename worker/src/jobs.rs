//! The decoded jobs a worker keeps ([`JobCache`]): a job's scene, photon maps and textures decoded from its
//! blobs once, with what that cost until a strip reports it; and the status of a run that stopped.

use crate::cache::BlobCache;
use crate::order::StripOrder;
use photon_core::photon::PhotonMapError;
use photon_core::prepare::Prepared;
use photon_core::prepare::blobs::{Frame, FrameError, decode_textures};
use photon_core::run::{Guard, RunError};
use photon_proto::pb;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tonic::Status;

/// Decoded jobs kept (the most recently used); an older job is decoded again from its blobs when asked for.
const JOBS_KEPT: usize = 2;

/// The decoded scene of one job.
pub(crate) struct Job {
    key: [String; 4],
    pub(crate) prep: Prepared,
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
    pub(crate) fn report_load(&self, summary: &mut pb::StripSummary) {
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
    pub(crate) fn get_or_make(
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
pub(crate) fn run_status(e: RunError) -> Status {
    match e {
        RunError::Cancelled => Status::cancelled("the strip's call ended (the coordinator cancelled it or left)"),
        RunError::Storage(e) => Status::failed_precondition(format!("this worker cannot render the strip: {e}")),
    }
}
