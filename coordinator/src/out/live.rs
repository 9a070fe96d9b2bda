//! The live page of a render (`render --serve`): a small HTTP server that shows the render while it runs.
//!
//! The farm's loop publishes a [`LiveStatus`] snapshot to a shared [`Board`] (at most every [`PUBLISH_EVERY`],
//! and once more at the end), with the image so far when it changed. The server reads the board and answers:
//!
//! - `/`: the page ([`PAGE`], plain HTML and JavaScript built into the binary, nothing fetched from elsewhere). It
//!   polls the two routes below every second and shows the image as it fills in, which strips (or pass blocks)
//!   are done, in flight or duplicated, the workers, progress, the time left and the photon statistics.
//! - `/api/status`: the [`LiveStatus`] as JSON, for scripts.
//! - `/preview.png`: the image so far, tone-mapped as the output's 8-bit formats are
//!   ([`photon_core::image_io::Image::to_srgb8`]). It is encoded on the first request after a publish and
//!   cached, so at most once per published state and never when nobody looks.
//!
//! With a farm token every route wants `Authorization: Bearer <token>` (compared in constant time,
//! [`photon_proto::tokens_match`]) and answers 401 without it. The 401 of `/` carries the page itself, which holds
//! no render state: it asks the user for the token, keeps it in the tab's `sessionStorage` and sends it with
//! its fetches (the preview is fetched and shown through a blob URL, since an `<img src>` cannot carry a header).

use crate::farm::scheduler::{Scheduler, StripId, WorkerState, WorkerStats};
use axum::Router;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use photon_core::image_io::Image;
use serde::Serialize;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// Where `--serve` with no address serves the page.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8080";

/// The shortest interval between two publishes that are not forced.
pub const PUBLISH_EVERY: Duration = Duration::from_millis(500);

/// How long after the last request for `/preview.png` the farm still hands its image over.
pub const PREVIEW_IDLE: Duration = Duration::from_secs(10);

/// How long a request for `/preview.png` waits for the farm's image when there is none yet: a little more than
/// [`PUBLISH_EVERY`] and the farm loop's 250 ms tick.
pub const PREVIEW_WAIT: Duration = Duration::from_millis(1500);

/// The page, built into the binary.
pub const PAGE: &str = include_str!("live.html");

/// One render's state as the page and `/api/status` show it.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LiveStatus {
    /// Seconds since the render started (connecting to the workers and shipping the job included).
    pub elapsed_s: f64,
    /// Estimated seconds until the last unit is done, from the rate of the units finished so far since the first
    /// worker was ready; `None` until one is done (and 0 once the render is finished).
    pub eta_s: Option<f64>,
    /// What the render is cut into: `strips` (of rows) or `pass blocks` (of progressive photon-mapping passes,
    /// each over the whole image).
    pub units: String,
    /// Units finished (accepted, or resumed from a partial file).
    pub done: usize,
    /// Units in all.
    pub total: usize,
    /// Each unit's state, in order (strip 0 at the top of the image, or pass block 0 first).
    pub unit_states: Vec<LiveUnit>,
    /// One entry per worker, in the order they were given.
    pub workers: Vec<LiveWorker>,
    /// Photon paths traced so far by the accepted units (progressive passes, or the maps workers trace
    /// themselves); maps traced here when the job was prepared are not counted.
    pub photon_paths: u64,
    /// Size of the job's photon-map blob in bytes (0 when the method has none, or each worker traces its own).
    pub photon_blob_bytes: u64,
    /// The relative MSE the render estimated of itself over time (a render bounded by time or error,
    /// [`crate::farm::bounded`], after each round; [`Board::push_error`]); empty otherwise.
    pub error: Vec<ErrorPoint>,
    /// `--integrator auto`: each candidate's pilot, its prediction and the choice ([`Board::set_candidates`]);
    /// empty otherwise.
    pub candidates: Vec<LiveCandidate>,
    /// The render is over (finished, failed or interrupted): nothing more will change.
    pub finished: bool,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Count of states published so far (0 before the first); set by the board.
    pub version: u64,
    /// Units finished in the image `/preview.png` shows (set by the board; the page shows it under the image).
    pub preview_done: usize,
}

/// One candidate of `--integrator auto` ([`crate::auto`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LiveCandidate {
    /// The method, with its radius when scaled (`progressive (radius ×0.5)`).
    pub method: String,
    /// Passes (or samples per pixel) its pilot rendered.
    pub passes: u32,
    /// Seconds its pilot's rounds took.
    pub pilot_s: f64,
    /// The relative MSE its pilot estimated of itself; `None` when it gave no estimate.
    pub rel_mse: Option<f64>,
    /// The relative MSE predicted at the deadline (`--time`), or the seconds predicted to the target
    /// (`--target-error`); `None` without a prediction.
    pub predicted: Option<f64>,
    /// Whether `predicted` is in seconds (to the target) rather than a relative MSE.
    pub predicted_seconds: bool,
    /// The one chosen.
    pub chosen: bool,
}

/// One strip or pass block.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct LiveUnit {
    /// Where it stands.
    pub state: UnitState,
    /// Its first row (strips) or pass (pass blocks).
    pub start: u32,
    /// One past its last row or pass.
    pub end: u32,
}

/// Where a strip or pass block stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UnitState {
    /// Finished.
    Done,
    /// One copy in flight.
    Running,
    /// More than one copy in flight (a tail copy beside the original).
    Duplicated,
    /// Waiting in the queue.
    Pending,
}

/// One worker's line.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LiveWorker {
    /// Its name (the address it was given as).
    pub address: String,
    /// Architecture and OS (`x86_64 linux`), empty until it answered.
    pub platform: String,
    /// Render threads it announced (0 until it answered).
    pub threads: u32,
    /// `connecting`, `ok`, `stalled`, `lost`, `refused: REASON` or `dropped: REASON` ([`worker_state`]).
    pub state: String,
    /// Units accepted from it.
    pub strips: u32,
    /// Units it holds now.
    pub in_flight: usize,
    /// Megapixels of its accepted units per second since the first worker was ready (a pass block counts its
    /// passes times the image's pixels).
    pub mpix_per_s: f64,
    /// Blob bytes shipped to it from the coordinator.
    pub shipped_bytes: u64,
    /// Blob bytes it fetched from other workers.
    pub fetched_bytes: u64,
}

/// One estimate of the render's error, without a reference ([`crate::farm::bounded`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorPoint {
    /// Seconds since the render started.
    pub elapsed_s: f64,
    /// Relative mean squared error (dimensionless).
    pub rel_mse: f64,
}

/// The image so far, as the farm hands it over.
#[derive(Clone, Debug)]
pub struct Preview {
    /// Linear RGB.
    pub image: Image,
    /// Factor the pixels are multiplied by before tone mapping: 1 for strips; for pass blocks the passes in all
    /// over the passes summed so far (the accumulator divides by all of them).
    pub gain: f32,
}

/// The preview as `/preview.png` serves it.
#[derive(Clone, Debug)]
pub struct Png {
    /// The PNG file's bytes (shared: a clone does not copy them).
    pub bytes: Bytes,
    /// Units finished in the image.
    pub done: usize,
}

/// The latest state of a render, shared by the farm (which publishes) and the server (which reads).
#[derive(Debug)]
pub struct Board {
    /// Exposure in stops of the preview, as for the 8-bit outputs.
    exposure: f32,
    inner: Mutex<Inner>,
    /// Held while the preview is encoded, so that two requests for one state encode it once.
    encoding: Mutex<()>,
}

#[derive(Debug, Default)]
struct Inner {
    status: LiveStatus,
    /// The image of the latest publish that carried one, and the units done in it.
    image: Option<Arc<(Preview, usize)>>,
    /// The PNG of `image`, once a request asked for it.
    png: Option<Bytes>,
    last_publish: Option<Instant>,
    /// When `/preview.png` was last asked for.
    last_asked: Option<Instant>,
}

impl Board {
    /// An empty board for a render tone-mapped at `exposure` stops.
    pub fn new(exposure: f32) -> Self {
        Self { exposure, inner: Mutex::new(Inner::default()), encoding: Mutex::new(()) }
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic elsewhere while the lock was held leaves a snapshot that is still whole: keep serving it.
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Whether a publish is due now: always when `force`, else when [`PUBLISH_EVERY`] has passed since the last.
    pub fn due(&self, force: bool) -> bool {
        force || self.lock().last_publish.is_none_or(|t| t.elapsed() >= PUBLISH_EVERY)
    }

    /// Whether a publish of a state with `done` units finished should carry the image: when the preview is older
    /// (or there is none yet), and either `force` (the final state) or someone asked for the preview in the last
    /// [`PREVIEW_IDLE`]. Copying a large image twice a second costs the farm's loop milliseconds: not for nobody.
    pub fn wants_preview(&self, done: usize, force: bool) -> bool {
        let inner = self.lock();
        let stale = inner.image.as_ref().is_none_or(|i| i.1 != done);
        stale && (force || inner.last_asked.is_some_and(|t| t.elapsed() < PREVIEW_IDLE))
    }

    /// Publishes a new state, with the image so far when it changed (`None` keeps the last one). The error
    /// points pushed so far are kept, and the state's `version` and `preview_done` are the board's; nothing is
    /// published after [`Board::finish`].
    pub fn publish(&self, mut status: LiveStatus, preview: Option<Preview>) {
        let mut inner = self.lock();
        if inner.status.finished {
            return;
        }
        status.error = std::mem::take(&mut inner.status.error);
        status.candidates = std::mem::take(&mut inner.status.candidates);
        status.version = inner.status.version + 1;
        if let Some(p) = preview {
            inner.image = Some(Arc::new((p, status.done)));
            inner.png = None;
        }
        status.preview_done = inner.image.as_ref().map_or(0, |i| i.1);
        inner.status = status;
        inner.last_publish = Some(Instant::now());
    }

    /// Adds a point to the error-against-time list (seconds since the start, relative MSE).
    pub fn push_error(&self, elapsed_s: f64, rel_mse: f64) {
        self.lock().status.error.push(ErrorPoint { elapsed_s, rel_mse });
    }

    /// Sets the candidates of `--integrator auto` and its choice, kept by every later publish.
    pub fn set_candidates(&self, candidates: Vec<LiveCandidate>) {
        let mut inner = self.lock();
        inner.status.candidates = candidates;
        inner.status.version += 1;
    }

    /// Marks the render over: the estimate of the time left becomes 0 (when every unit is done) and nothing
    /// more is published.
    pub fn finish(&self) {
        let mut inner = self.lock();
        let s = &mut inner.status;
        s.finished = true;
        s.version += 1;
        if s.done == s.total {
            s.eta_s = Some(0.0);
        }
    }

    /// The latest state.
    pub fn status(&self) -> LiveStatus {
        self.lock().status.clone()
    }

    /// The preview as PNG bytes, with the units finished in it; `None` before the first image (the farm hands one
    /// over at its next publish, now that it was asked for). Encodes (outside the board's lock, so the farm is
    /// never held up) only when the image changed since the last call.
    pub fn preview_png(&self) -> Result<Option<Png>, image::ImageError> {
        let _one_at_a_time = self.encoding.lock().unwrap_or_else(PoisonError::into_inner);
        let image = {
            let mut inner = self.lock();
            inner.last_asked = Some(Instant::now());
            match (&inner.image, &inner.png) {
                (None, _) => return Ok(None),
                (Some(i), Some(png)) => return Ok(Some(Png { bytes: png.clone(), done: i.1 })),
                (Some(i), None) => i.clone(),
            }
        };
        let (preview, done) = (&image.0, image.1);
        let png = Bytes::from(encode_png(&preview.image, self.exposure, preview.gain)?);
        let mut inner = self.lock();
        // Keep it only if no newer image arrived meanwhile.
        if inner.image.as_ref().is_some_and(|i| Arc::ptr_eq(i, &image)) {
            inner.png = Some(png.clone());
        }
        Ok(Some(Png { bytes: png, done }))
    }
}

/// Tone-maps linear pixels as the 8-bit outputs are (`exposure` stops, times `gain`) and encodes them as PNG.
fn encode_png(image: &Image, exposure: f32, gain: f32) -> Result<Vec<u8>, image::ImageError> {
    use image::ImageEncoder;
    let stops = if gain.is_finite() && gain > 0.0 { exposure + gain.log2() } else { exposure };
    let rgb = image.to_srgb8(stops);
    let mut png = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut png);
    encoder.write_image(&rgb, image.width, image.height, image::ExtendedColorType::Rgb8)?;
    Ok(png)
}

/// Each unit's state, from the scheduler (strips, or pass blocks whose "rows" are passes).
pub fn unit_states(sched: &Scheduler) -> Vec<LiveUnit> {
    let done = sched.done_strips();
    sched
        .copies_in_flight()
        .into_iter()
        .enumerate()
        .map(|(i, copies)| {
            let id = StripId(i as u32);
            let rows = sched.strip_rows(id).unwrap_or_default();
            let state = match copies {
                _ if done.binary_search(&id).is_ok() => UnitState::Done,
                0 => UnitState::Pending,
                1 => UnitState::Running,
                _ => UnitState::Duplicated,
            };
            LiveUnit { state, start: rows.start, end: rows.end }
        })
        .collect()
}

/// A worker's state word: `connecting` before its session answered, `refused: REASON` when it refused (`out` is
/// the farm's reason), else the scheduler's view: `ok`, `stalled`, `lost` or `dropped: REASON`.
pub fn worker_state(out: Option<&str>, stats: Option<&WorkerStats>) -> String {
    match (stats, out) {
        (None, None) => "connecting".into(),
        (None, Some(why)) => format!("refused: {why}"),
        (Some(s), _) => match &s.state {
            WorkerState::Lost => "lost".into(),
            WorkerState::Blocked(why) => format!("blocked: {why}"),
            WorkerState::Active if s.stalled => "stalled".into(),
            WorkerState::Active => "ok".into(),
        },
    }
}

/// Seconds left at the rate so far: `render_s` seconds since the first worker was ready rendered `rendered`
/// units, and `left` remain. `None` before anything was rendered.
pub fn eta_s(render_s: f64, rendered: usize, left: usize) -> Option<f64> {
    (rendered > 0 && render_s > 0.0).then(|| render_s / rendered as f64 * left as f64)
}

/// Why the live page cannot be served.
#[derive(Debug, thiserror::Error)]
#[error("cannot serve the live page on {addr}: {cause}")]
pub struct ServeError {
    /// The address asked for.
    pub addr: SocketAddr,
    /// Why it cannot be listened on (in use, not an address of this machine, a privileged port).
    #[source]
    pub cause: std::io::Error,
}

/// What the routes share.
#[derive(Clone)]
struct App {
    board: Arc<Board>,
    /// `Bearer <token>`, when the farm has a token.
    bearer: Option<Arc<str>>,
}

impl App {
    /// Whether the request carries the token (always, when there is none to carry).
    fn authorized(&self, headers: &HeaderMap) -> bool {
        let Some(want) = &self.bearer else { return true };
        let got = headers.get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()).unwrap_or("");
        photon_proto::tokens_match(got, want)
    }
}

/// The page's routes over `board`; with `token`, each wants `Authorization: Bearer <token>`.
pub fn router(board: Arc<Board>, token: Option<&str>) -> Router {
    let app = App { board, bearer: token.map(|t| Arc::from(photon_proto::bearer(t))) };
    Router::new()
        .route("/", get(page))
        .route("/api/status", get(status))
        .route("/preview.png", get(preview))
        .with_state(app)
}

const NO_STORE: (header::HeaderName, HeaderValue) = (header::CACHE_CONTROL, HeaderValue::from_static("no-store"));

fn unauthorized() -> Response {
    (StatusCode::UNAUTHORIZED, [NO_STORE], "this page wants the farm's token: Authorization: Bearer <token>\n")
        .into_response()
}

async fn page(State(app): State<App>, headers: HeaderMap) -> Response {
    // Without the token the page still comes (it holds no render state), as a 401: it asks for the token.
    let code = if app.authorized(&headers) { StatusCode::OK } else { StatusCode::UNAUTHORIZED };
    let html = HeaderValue::from_static("text/html; charset=utf-8");
    (code, [(header::CONTENT_TYPE, html), NO_STORE], PAGE).into_response()
}

async fn status(State(app): State<App>, headers: HeaderMap) -> Response {
    if !app.authorized(&headers) {
        return unauthorized();
    }
    match serde_json::to_vec(&app.board.status()) {
        Ok(json) => {
            let kind = HeaderValue::from_static("application/json");
            (StatusCode::OK, [(header::CONTENT_TYPE, kind), NO_STORE], json).into_response()
        }
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot encode the status: {e}\n")).into_response(),
    }
}

async fn preview(State(app): State<App>, headers: HeaderMap) -> Response {
    if !app.authorized(&headers) {
        return unauthorized();
    }
    // Encoding takes milliseconds to a few hundred for a large image: off the async threads. The first ask may
    // find no image (the farm hands it over at its next publish, once asked): wait for it a little.
    let deadline = Instant::now() + PREVIEW_WAIT;
    let png = loop {
        let board = app.board.clone();
        match tokio::task::spawn_blocking(move || board.preview_png()).await {
            Ok(Ok(None)) if Instant::now() < deadline => tokio::time::sleep(Duration::from_millis(50)).await,
            other => break other,
        }
    };
    match png {
        Ok(Ok(Some(Png { bytes, done }))) => {
            let kind = HeaderValue::from_static("image/png");
            let done = (header::HeaderName::from_static("x-photon-done"), HeaderValue::from(done));
            (StatusCode::OK, [(header::CONTENT_TYPE, kind), NO_STORE, done], bytes).into_response()
        }
        Ok(Ok(None)) => (StatusCode::SERVICE_UNAVAILABLE, [NO_STORE], "no image yet\n").into_response(),
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot encode the preview: {e}\n")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("the preview task failed: {e}\n")).into_response(),
    }
}

/// A running live-page server; [`LiveServer::stop`] ends it (dropping it does too, without waiting).
#[derive(Debug)]
pub struct LiveServer {
    addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl LiveServer {
    /// The address it listens on (the port chosen when port 0 was asked for).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops taking connections, lets the requests under way finish (at most 2 s), and returns.
    pub async fn stop(mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if tokio::time::timeout(Duration::from_secs(2), &mut self.task).await.is_err() {
            self.task.abort();
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Listens on `addr` and serves the page of `board` (call it inside the runtime); with `token`, every route
/// wants it.
pub async fn serve(addr: SocketAddr, board: Arc<Board>, token: Option<&str>) -> Result<LiveServer, ServeError> {
    let listener = tokio::net::TcpListener::bind(addr).await.map_err(|cause| ServeError { addr, cause })?;
    let bound = listener.local_addr().map_err(|cause| ServeError { addr, cause })?;
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let app = router(board, token);
    let task = tokio::spawn(async move {
        let shutdown = async move {
            let _ = rx.await;
        };
        if let Err(e) = axum::serve(listener, app).with_graceful_shutdown(shutdown).await {
            tracing::warn!("the live page on {bound} stopped: {e}");
        }
    });
    Ok(LiveServer { addr: bound, stop: Some(tx), task })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use axum::body::Body;
    use axum::http::Request;
    use tower::ServiceExt;

    /// A farm state as `Farm::publish` builds it: two workers, one of them lost, 4 strips of 2 rows.
    fn farm_state() -> (Board, Scheduler) {
        let mut sched = Scheduler::new(8, 2);
        let (w0, w1) = (crate::farm::scheduler::WorkerId(0), crate::farm::scheduler::WorkerId(1));
        sched.add_worker(w0, 4);
        sched.add_worker(w1, 2);
        let a = sched.assign(w0, Duration::ZERO).unwrap();
        sched.assign(w0, Duration::ZERO).unwrap();
        sched.assign(w1, Duration::ZERO).unwrap();
        sched.complete(w0, a.strip, a.attempt, Duration::from_secs(1));
        sched.worker_lost(w1, Duration::from_secs(2));
        let workers = [(w0, "127.0.0.1:7001"), (w1, "127.0.0.1:7002")]
            .into_iter()
            .map(|(id, address)| LiveWorker {
                address: address.into(),
                platform: "x86_64 linux".into(),
                threads: 4,
                state: worker_state(None, sched.worker_stats(id)),
                strips: sched.worker_stats(id).unwrap().strips,
                in_flight: sched.in_flight(id).len(),
                mpix_per_s: 0.5,
                shipped_bytes: 1 << 20,
                fetched_bytes: 0,
            })
            .collect();
        let (done, total) = sched.progress();
        let status = LiveStatus {
            elapsed_s: 2.5,
            eta_s: eta_s(2.0, done, total - done),
            units: "strips".into(),
            done,
            total,
            unit_states: unit_states(&sched),
            workers,
            photon_paths: 1000,
            photon_blob_bytes: 4096,
            width: 4,
            height: 8,
            ..LiveStatus::default()
        };
        let board = Board::new(0.0);
        board.publish(
            status,
            Some(Preview { image: Image { width: 4, height: 8, pixels: vec![0.5; 3 * 4 * 8] }, gain: 1.0 }),
        );
        board.push_error(2.0, 0.25);
        (board, sched)
    }

    async fn get(router: Router, path: &str, token: Option<&str>) -> (StatusCode, HeaderMap, Vec<u8>) {
        let mut request = Request::builder().uri(path);
        if let Some(t) = token {
            request = request.header(header::AUTHORIZATION, photon_proto::bearer(t));
        }
        let response = router.oneshot(request.body(Body::empty()).unwrap()).await.unwrap();
        let (parts, body) = response.into_parts();
        (parts.status, parts.headers, axum::body::to_bytes(body, usize::MAX).await.unwrap().to_vec())
    }

    #[tokio::test]
    async fn live_status_is_the_published_farm_state_as_json() {
        let (board, _) = farm_state();
        let (code, headers, body) = get(router(Arc::new(board), None), "/api/status", None).await;
        assert_eq!(code, StatusCode::OK);
        assert_eq!(headers[header::CONTENT_TYPE], "application/json");
        let json: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(json["units"], "strips");
        assert_eq!((json["done"].as_u64(), json["total"].as_u64()), (Some(1), Some(4)));
        // Strip 0 done, strip 1 running on worker 0, strip 2 back in the queue after worker 1 was lost.
        let states: Vec<&str> =
            json["unit_states"].as_array().unwrap().iter().map(|u| u["state"].as_str().unwrap()).collect();
        assert_eq!(states, ["done", "running", "pending", "pending"]);
        assert_eq!(
            (json["unit_states"][1]["start"].as_u64(), json["unit_states"][1]["end"].as_u64()),
            (Some(2), Some(4))
        );
        let workers = json["workers"].as_array().unwrap();
        assert_eq!(workers.len(), 2);
        assert_eq!(
            (workers[0]["address"].as_str(), workers[0]["state"].as_str()),
            (Some("127.0.0.1:7001"), Some("ok"))
        );
        assert_eq!(
            (workers[1]["address"].as_str(), workers[1]["state"].as_str()),
            (Some("127.0.0.1:7002"), Some("lost"))
        );
        assert_eq!(workers[0]["in_flight"].as_u64(), Some(1));
        assert_eq!(json["photon_paths"].as_u64(), Some(1000));
        assert_eq!(json["photon_blob_bytes"].as_u64(), Some(4096));
        // 1 strip in 2 s, 3 left.
        assert_eq!(json["eta_s"].as_f64(), Some(6.0));
        assert_eq!(json["error"][0]["rel_mse"].as_f64(), Some(0.25));
        assert_eq!(json["finished"], false);
        assert_eq!(
            (json["width"].as_u64(), json["height"].as_u64(), json["version"].as_u64()),
            (Some(4), Some(8), Some(1))
        );
    }

    #[tokio::test]
    async fn the_auto_choice_survives_later_publishes_and_reaches_the_json() {
        let (board, _) = farm_state();
        let candidate = |method: &str, chosen| LiveCandidate {
            method: method.into(),
            passes: 4,
            pilot_s: 0.4,
            rel_mse: Some(0.1),
            predicted: Some(0.01),
            predicted_seconds: false,
            chosen,
        };
        board.set_candidates(vec![candidate("path", false), candidate("bdpt", true)]);
        board.publish(LiveStatus { units: "pass blocks".into(), ..LiveStatus::default() }, None);
        let (_, _, body) = get(router(Arc::new(board), None), "/api/status", None).await;
        let json: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(json["units"], "pass blocks");
        let cands = json["candidates"].as_array().unwrap();
        assert_eq!(cands.len(), 2);
        assert_eq!((cands[1]["method"].as_str(), cands[1]["chosen"].as_bool()), (Some("bdpt"), Some(true)));
        assert_eq!(cands[0]["predicted"].as_f64(), Some(0.01));
    }

    #[tokio::test]
    async fn a_board_with_a_token_answers_401_without_it_and_200_with_it() {
        let (board, _) = farm_state();
        let router = router(Arc::new(board), Some("s3cret"));
        for path in ["/", "/api/status", "/preview.png"] {
            assert_eq!(get(router.clone(), path, None).await.0, StatusCode::UNAUTHORIZED, "{path}");
            assert_eq!(get(router.clone(), path, Some("s3cre7")).await.0, StatusCode::UNAUTHORIZED, "{path}");
            assert_eq!(get(router.clone(), path, Some("s3cret")).await.0, StatusCode::OK, "{path}");
        }
        // The 401 of the page is the page, which asks for the token.
        let (_, _, body) = get(router, "/", None).await;
        assert!(String::from_utf8(body).unwrap().contains("id=\"token-form\""));
    }

    #[tokio::test]
    async fn the_preview_is_a_png_of_the_image_encoded_once_per_state() {
        let (board, _) = farm_state();
        let board = Arc::new(board);
        let (code, headers, png) = get(router(board.clone(), None), "/preview.png", None).await;
        assert_eq!(code, StatusCode::OK);
        assert_eq!(
            (&headers[header::CONTENT_TYPE], &headers["x-photon-done"]),
            (&"image/png".parse::<HeaderValue>().unwrap(), &HeaderValue::from(1))
        );
        let decoded = image::load_from_memory(&png).unwrap().into_rgb8();
        assert_eq!(decoded.dimensions(), (4, 8));
        // 0.5 linear is 188 in sRGB.
        assert_eq!(decoded.get_pixel(0, 0).0, [188, 188, 188]);
        // Nobody asked for the preview since this board was made with an image... until now.
        let fresh = Board::new(0.0);
        assert!(!fresh.wants_preview(1, false) && fresh.wants_preview(1, true));
        assert!(fresh.preview_png().unwrap().is_none());
        assert!(fresh.wants_preview(1, false), "asked for: the next publish carries the image");
        assert!(!board.wants_preview(1, false) && board.wants_preview(2, false), "the image of 1 unit is there");
        let first = board.preview_png().unwrap().unwrap().bytes;
        let again = board.preview_png().unwrap().unwrap().bytes;
        assert_eq!(first.as_ptr(), again.as_ptr(), "encoded again for the same state");
        // A publish without an image keeps the cached PNG; one with an image replaces it.
        board.publish(board.status(), None);
        assert_eq!(first.as_ptr(), board.preview_png().unwrap().unwrap().bytes.as_ptr());
        board.publish(board.status(), Some(Preview { image: Image::new(4, 8), gain: 1.0 }));
        assert_ne!(first.as_ptr(), board.preview_png().unwrap().unwrap().bytes.as_ptr());
    }

    #[tokio::test]
    async fn serve_names_the_address_it_cannot_listen_on() {
        let board = Arc::new(Board::new(0.0));
        let server = serve("127.0.0.1:0".parse().unwrap(), board.clone(), None).await.unwrap();
        let taken = server.addr();
        let e = serve(taken, board, None).await.unwrap_err();
        assert!(e.to_string().starts_with(&format!("cannot serve the live page on {taken}: ")), "{e}");
        server.stop().await;
    }

    #[test]
    fn finish_freezes_the_state_and_keeps_the_error_points() {
        let (board, _) = farm_state();
        board.finish();
        let before = board.status();
        assert!(before.finished);
        board.publish(LiveStatus::default(), None);
        assert_eq!(board.status(), before);
        assert_eq!(before.error, vec![ErrorPoint { elapsed_s: 2.0, rel_mse: 0.25 }]);
    }
}
