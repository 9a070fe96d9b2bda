//! The farm's state fed events by hand: which calls it starts and cancels, what it tells the user, and what
//! joins the image, for results that come late, twice or broken, and for a worker that is lost.
#![allow(clippy::unwrap_used)]

use super::Options;
use super::scheduler::{Policy, StripId, WorkerId, WorkerState};
use super::state::{Action, Farm, Stop};
use crate::fleet::session::{Delivered, StripError, StripResult, WorkerAddr};
use crate::job::Job;
use crate::out::report::Warning;
use photon_proto::pb;
use std::time::Duration;

/// The image of every test: 2×4 pixels, 4 units (samples or passes) per pixel.
const WIDTH: u32 = 2;
const HEIGHT: u32 = 4;
const UNITS: u32 = 4;

/// A job of the test image whose blobs are never read: cut in strips of rows, or in pass blocks of `passes`.
fn job(passes: Option<u32>) -> Job {
    let settings = photon_core::scene::RenderSettings::default();
    let mut job = Job::new(b"scene".to_vec(), None, Vec::new(), b"frame".to_vec(), (WIDTH, HEIGHT), &settings);
    // The counts of photon paths then follow the accepted copies only.
    (job.passes, job.units, job.trace_photons) = (passes, UNITS, false);
    job
}

fn workers(n: u32) -> Vec<WorkerAddr> {
    (0..n).map(|i| WorkerAddr::new(&format!("w{i}:7878"), None)).collect()
}

/// One strip (or block) covering the whole job, with the policy `policy`.
fn options(policy: Policy) -> Options {
    Options { rows_per_strip: Some(HEIGHT), policy, ..Options::default() }
}

fn ms(t: u64) -> Duration {
    Duration::from_millis(t)
}

fn w(i: u32) -> WorkerId {
    WorkerId(i)
}

/// `worker`'s session is open, with one thread.
fn ready(farm: &mut Farm, worker: WorkerId, now: Duration) {
    let hello = pb::HelloReply { threads: 1, math_mode: "strict".into(), ..pb::HelloReply::default() };
    farm.on_ready(worker, hello, Delivered::default(), 0.0, now);
}

/// A valid result of the whole image: every sum `value`, with `rays` rays.
fn result(value: i64, rays: u64) -> Result<StripResult, StripError> {
    let sums = vec![value; 3 * (WIDTH * HEIGHT) as usize];
    Ok(StripResult { sums, summary: pb::StripSummary { rays, photon_paths: 1, ..pb::StripSummary::default() } })
}

/// The calls started by `actions`: (worker, strip, attempt).
fn spawned(actions: &[Action]) -> Vec<(WorkerId, StripId, u32)> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Spawn(worker, a) => Some((*worker, a.strip, a.attempt)),
            _ => None,
        })
        .collect()
}

/// The state's actions after it filled the free slots at `now`.
fn fill(farm: &mut Farm, now: Duration) -> Vec<Action> {
    farm.fill_slots(now);
    farm.take_actions()
}

fn image_is(farm: &Farm, value: i128) -> bool {
    farm.image.sums().iter().all(|&s| s == value)
}

#[test]
fn a_late_result_of_a_strip_reissued_and_finished_elsewhere_is_ignored() {
    let job = job(None);
    let policy = Policy { max_copies: 1, first_deadline: Duration::from_secs(1), ..Policy::default() };
    let mut farm = Farm::new(&job, &workers(2), &options(policy)).unwrap();
    // Worker 1 is ready first and takes the only strip; worker 0 gets no copy (one copy at most).
    ready(&mut farm, w(1), ms(0));
    assert_eq!(spawned(&fill(&mut farm, ms(0))), [(w(1), StripId(0), 1)]);
    ready(&mut farm, w(0), ms(10));
    assert!(fill(&mut farm, ms(10)).is_empty());
    // Worker 1 said nothing past its silence limit and misses its deadline: the user hears it stalled, its call
    // is cancelled, and the strip goes to worker 0.
    farm.on_tick(ms(1500));
    let actions = fill(&mut farm, ms(1500));
    assert!(matches!(&actions[0], Action::Warn(Warning::Stalled { worker, .. }) if worker == "w1:7878"));
    assert_eq!(actions[1], Action::Cancel(w(1), StripId(0)));
    assert_eq!(spawned(&actions), [(w(0), StripId(0), 2)]);
    // Worker 1's result of the withdrawn attempt arrives while worker 0 renders: it matches no assignment.
    farm.on_strip(w(1), StripId(0), 1, result(7, 100), ms(1600));
    assert!(image_is(&farm, 0) && farm.rays == 0);
    farm.on_strip(w(0), StripId(0), 2, result(5, 10), ms(1700));
    assert!(image_is(&farm, 5) && farm.rays == 10);
    // The same late result once the strip is done: a duplicate, dropped.
    farm.on_strip(w(1), StripId(0), 1, result(7, 100), ms(1800));
    assert!(image_is(&farm, 5));
    assert!(fill(&mut farm, ms(1800)).is_empty());
    assert_eq!(farm.end(ms(1800)), Some(Ok(())));
    let outcome = farm.finish(Ok(()), ms(1900)).unwrap();
    // Counted once: the rays and photon paths of the accepted copy, one strip for worker 0 and none for 1.
    assert_eq!((outcome.rays, outcome.photon_paths), (10, 1));
    let strips: Vec<(u32, u32, u32)> = outcome.workers.iter().map(|r| (r.strips, r.duplicates, r.failures)).collect();
    assert_eq!(strips, [(1, 0, 0), (0, 1, 1)]);
}

#[test]
fn a_result_delivered_twice_joins_the_image_once() {
    // The same for a strip of rows and for a block of passes.
    for passes in [None, Some(UNITS)] {
        let job = job(passes);
        let mut farm = Farm::new(&job, &workers(2), &options(Policy::default())).unwrap();
        ready(&mut farm, w(0), ms(0));
        assert_eq!(spawned(&fill(&mut farm, ms(0))), [(w(0), StripId(0), 1)], "{passes:?}");
        // Worker 1 has nothing left to take but a speculative copy.
        ready(&mut farm, w(1), ms(10));
        assert_eq!(spawned(&fill(&mut farm, ms(10))), [(w(1), StripId(0), 2)], "{passes:?}");
        // Worker 0's copy wins: worker 1's is cancelled.
        farm.on_strip(w(0), StripId(0), 1, result(3, 10), ms(100));
        assert_eq!(farm.take_actions(), [Action::Cancel(w(1), StripId(0))], "{passes:?}");
        assert!(image_is(&farm, 3), "{passes:?}");
        // The same result again, and the cancelled copy's, which was already on its way.
        farm.on_strip(w(0), StripId(0), 1, result(3, 10), ms(110));
        farm.on_strip(w(1), StripId(0), 2, result(3, 10), ms(120));
        assert!(image_is(&farm, 3) && farm.rays == 10, "{passes:?}");
        assert!(farm.take_actions().is_empty(), "{passes:?}");
        assert_eq!(farm.sched.progress(), (1, 1), "{passes:?}");
        let stats = |i| farm.sched.worker_stats(w(i)).map(|s| (s.strips, s.duplicates)).unwrap();
        assert_eq!((stats(0), stats(1)), ((1, 1), (0, 1)), "{passes:?}");
    }
}

#[test]
fn a_corrupt_result_is_reissued_and_counted_against_its_worker() {
    let job = job(None);
    let mut farm = Farm::new(&job, &workers(1), &options(Policy::default())).unwrap();
    ready(&mut farm, w(0), ms(0));
    assert_eq!(spawned(&fill(&mut farm, ms(0))), [(w(0), StripId(0), 1)]);
    // Bytes that do not hash to the worker's checksum: the strip is issued again, the failure counts.
    farm.on_strip(w(0), StripId(0), 1, Err(StripError::ChecksumMismatch), ms(100));
    assert_eq!(spawned(&fill(&mut farm, ms(100))), [(w(0), StripId(0), 2)]);
    let failures = |farm: &Farm| farm.sched.worker_stats(w(0)).map(|s| (s.failures, s.counted_failures)).unwrap();
    assert_eq!(failures(&farm), (1, 1));
    assert!(image_is(&farm, 0));
    assert_eq!(farm.end(ms(100)), None);
    // A sum no block of this build can add up to is the renderer's, not the worker's: the render cannot finish,
    // nothing is issued again, and the worker is not blamed.
    let bad = StripError::NotASum { x: 1, y: 2, value: -5, units: UNITS };
    farm.on_strip(w(0), StripId(0), 2, Err(bad), ms(200));
    assert!(fill(&mut farm, ms(200)).is_empty());
    assert_eq!(failures(&farm), (2, 1));
    let fatal = "strip 0: pixel (1, 2) holds the sum -5: not the sum of 4 units".to_owned();
    assert_eq!(farm.end(ms(200)), Some(Err(Stop::Fatal(fatal))));
    assert!(image_is(&farm, 0));
}

#[test]
fn a_lost_worker_is_called_back_and_its_strip_goes_to_another() {
    let job = job(None);
    let policy = Policy { max_copies: 1, ..Policy::default() };
    let mut farm = Farm::new(&job, &workers(2), &options(policy)).unwrap();
    ready(&mut farm, w(0), ms(0));
    ready(&mut farm, w(1), ms(0));
    assert_eq!(spawned(&fill(&mut farm, ms(0))), [(w(0), StripId(0), 1)]);
    farm.on_strip(w(0), StripId(0), 1, Err(StripError::StreamEnded), ms(100));
    let actions = fill(&mut farm, ms(100));
    let lost = Warning::Lost { worker: "w0:7878".into(), reason: StripError::StreamEnded.to_string() };
    assert_eq!(actions[0], Action::Warn(lost));
    assert!(actions.contains(&Action::CallBack(w(0))));
    assert_eq!(spawned(&actions), [(w(1), StripId(0), 2)]);
    assert_eq!(farm.sched.worker_stats(w(0)).map(|s| s.state.clone()), Some(WorkerState::Lost));
    // It answers again: it rejoins, and the user hears of it.
    ready(&mut farm, w(0), ms(200));
    let rejoined = Warning::Rejoined { worker: "w0:7878".into(), shipped: 0 };
    assert_eq!(farm.take_actions(), [Action::Warn(rejoined)]);
    farm.on_strip(w(1), StripId(0), 2, result(2, 10), ms(300));
    assert!(image_is(&farm, 2));
    assert_eq!(farm.end(ms(300)), Some(Ok(())));
}
