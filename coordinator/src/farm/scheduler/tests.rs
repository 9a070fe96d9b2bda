//! Tests of the scheduler: policy cases by hand, and randomised runs that check its invariants.

use super::*;

const W0: WorkerId = WorkerId(0);
const W1: WorkerId = WorkerId(1);
const W2: WorkerId = WorkerId(2);

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s)
}

fn is_accepted(c: &Completion) -> bool {
    matches!(c, Completion::Accepted { .. })
}

/// A tiny portable generator (splitmix64) so the random tests replay exactly.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

#[test]
fn strips_cover_every_row_once() {
    let s = Scheduler::new(10, 4);
    let rows: Vec<_> = (0..3).map(|i| s.strip_rows(StripId(i)).unwrap()).collect();
    assert_eq!(rows, vec![0..4, 4..8, 8..10]);
    assert_eq!(s.strip_rows(StripId(3)), None);
    assert_eq!(Scheduler::new(5, 0).strip_count(), 5);
    let empty = Scheduler::new(0, 8);
    assert!(empty.is_done());
    assert_eq!(empty.progress(), (0, 0));
}

#[test]
fn rows_per_strip_gives_many_more_strips_than_workers() {
    for (height, workers) in [(1080, 1), (1080, 8), (2160, 52), (100, 4), (7, 3)] {
        let rows = rows_per_strip_for(height, workers);
        assert!((1..=64).contains(&rows));
        let strips = height.div_ceil(rows);
        assert!(strips >= (8 * workers).min(height), "{height} rows over {workers} workers: {strips} strips");
    }
    assert_eq!(rows_per_strip_for(1080, 0), rows_per_strip_for(1080, 1));
}

#[test]
fn pulls_serve_pending_strips_in_order_up_to_the_in_flight_limit() {
    let mut s = Scheduler::new(40, 4);
    assert!(s.add_worker(W0, 8));
    assert!(s.add_worker(W1, 8));
    assert!(!s.add_worker(W1, 4), "an id is registered once");
    let t = Duration::ZERO;
    let a = s.assign(W0, t).unwrap();
    assert_eq!((a.strip, a.rows.clone(), a.attempt, a.speculative), (StripId(0), 0..4, 1, false));
    assert_eq!(s.assign(W1, t).unwrap().strip, StripId(1));
    assert_eq!(s.assign(W0, t).unwrap().strip, StripId(2));
    assert_eq!(s.assign(W0, t), None, "two in flight is the limit");
    assert_eq!(s.assign(WorkerId(9), t), None, "unknown worker");
    assert!(is_accepted(&s.complete(W0, StripId(0), 1, secs(1.0))));
    assert_eq!(s.assign(W0, secs(1.0)).unwrap().strip, StripId(3), "a freed slot pulls the next strip");
    assert_eq!(s.in_flight(W0), vec![StripId(2), StripId(3)]);
}

/// A discrete-event simulation: each worker renders its strips one after the other at `seconds_per_row`,
/// results arrive at their finish times on a fake clock, and every free slot pulls after every event.
struct Sim {
    sched: Scheduler,
    clock: Duration,
    speed: BTreeMap<WorkerId, f64>,
    free_at: BTreeMap<WorkerId, Duration>,
    events: BTreeMap<(Duration, u64), (WorkerId, Assignment)>,
    seq: u64,
    accepted: Vec<u32>,
    duplicates: u32,
}

impl Sim {
    fn new(sched: Scheduler, workers: &[(WorkerId, u32, f64)]) -> Self {
        let mut sim = Sim {
            accepted: vec![0; sched.strip_count()],
            sched,
            clock: Duration::ZERO,
            speed: BTreeMap::new(),
            free_at: BTreeMap::new(),
            events: BTreeMap::new(),
            seq: 0,
            duplicates: 0,
        };
        for &(id, cores, seconds_per_row) in workers {
            assert!(sim.sched.add_worker(id, cores));
            sim.speed.insert(id, seconds_per_row);
            sim.free_at.insert(id, Duration::ZERO);
        }
        sim
    }

    fn fill(&mut self) {
        let ids: Vec<WorkerId> = self.speed.keys().copied().collect();
        for w in ids {
            while let Some(a) = self.sched.assign(w, self.clock) {
                let start = self.free_at[&w].max(self.clock);
                let finish = start + secs(self.speed[&w] * a.rows.len() as f64);
                self.free_at.insert(w, finish);
                self.events.insert((finish, self.seq), (w, a));
                self.seq += 1;
            }
        }
    }

    fn run(&mut self) {
        self.fill();
        while let Some(((t, _), (w, a))) = self.events.pop_first() {
            self.clock = t;
            assert!(self.sched.expired(t).is_empty(), "no deadline should pass in a healthy run");
            match self.sched.complete(w, a.strip, a.attempt, t) {
                Completion::Accepted { .. } => self.accepted[a.strip.0 as usize] += 1,
                Completion::Duplicate => self.duplicates += 1,
                Completion::Unknown => panic!("{w} {a:?}: no assignment was withdrawn"),
            }
            self.fill();
        }
    }
}

#[test]
fn simulated_workers_complete_every_strip_once_and_faster_ones_take_more() {
    // Worker 0 is 4× faster than worker 1; worker 2 sits in between.
    let workers = [(W0, 16, 0.025), (W1, 4, 0.1), (W2, 8, 0.05)];
    let mut sim = Sim::new(Scheduler::new(480, 4), &workers);
    sim.run();
    assert!(sim.sched.is_done());
    assert_eq!(sim.sched.progress(), (120, 120));
    assert!(sim.accepted.iter().all(|&n| n == 1), "{:?}", sim.accepted);
    assert_eq!(sim.sched.done_strips().len(), 120);
    let strips = |w| sim.sched.worker_stats(w).unwrap().strips;
    let (fast, mid, slow) = (strips(W0), strips(W2), strips(W1));
    assert_eq!(fast + mid + slow, 120);
    assert!(fast >= 3 * slow, "fast {fast}, slow {slow}");
    assert!(fast > mid && mid > slow, "{fast} {mid} {slow}");
    eprintln!("strips taken: 4x {fast}, 2x {mid}, 1x {slow}; {} duplicates", sim.duplicates);
    let stats = sim.sched.worker_stats(W0).unwrap();
    assert_eq!(stats.rows, u64::from(fast) * 4);
    assert!(stats.busy > Duration::ZERO && stats.busy <= sim.clock);
    // The measured latency per row includes the wait behind the other in-flight strip: about 2× the speed.
    let spr = sim.sched.seconds_per_row(W0).unwrap();
    assert!((0.025..=0.06).contains(&spr), "{spr}");
}

#[test]
fn a_single_worker_sees_no_speculation_and_no_duplicates() {
    let mut sim = Sim::new(Scheduler::new(64, 4), &[(W0, 4, 0.1)]);
    sim.run();
    assert_eq!(sim.duplicates, 0);
    assert_eq!(sim.sched.worker_stats(W0).unwrap().speculative, 0);
    assert_eq!(sim.sched.worker_stats(W0).unwrap().strips, 16);
    assert!(sim.accepted.iter().all(|&n| n == 1));
}

#[test]
fn a_lost_workers_strips_requeue_at_the_front_and_complete_elsewhere() {
    let mut s = Scheduler::new(40, 4);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let t0 = Duration::ZERO;
    let a0 = s.assign(W0, t0).unwrap();
    let a1 = s.assign(W0, t0).unwrap();
    let b0 = s.assign(W1, t0).unwrap();
    assert_eq!((a0.strip, a1.strip, b0.strip), (StripId(0), StripId(1), StripId(2)));
    assert_eq!(s.worker_lost(W0, secs(2.0)), vec![StripId(0), StripId(1)]);
    assert_eq!(s.worker_lost(W0, secs(2.0)), vec![], "lost once");
    assert_eq!(s.pending_strips()[..3], [StripId(0), StripId(1), StripId(3)]);
    assert_eq!(s.assign(W0, secs(2.0)), None, "a lost worker takes nothing");
    assert_eq!(s.worker_stats(W0).unwrap().state, WorkerState::Lost);
    assert_eq!(s.worker_stats(W0).unwrap().busy, secs(2.0));
    assert!(is_accepted(&s.complete(W1, b0.strip, b0.attempt, secs(3.0))));
    let r = s.assign(W1, secs(3.0)).unwrap();
    assert_eq!((r.strip, r.attempt), (StripId(0), 2), "the requeued strip comes first, as a new attempt");
    // The lost worker's late result is not accepted while the re-issue runs...
    assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(3.5)), Completion::Unknown);
    assert!(is_accepted(&s.complete(W1, r.strip, r.attempt, secs(4.0))));
    // ...and is a duplicate once the strip is done.
    assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(4.5)), Completion::Duplicate);
    let mut t = 5.0;
    while let Some(a) = s.assign(W1, secs(t)) {
        assert!(is_accepted(&s.complete(W1, a.strip, a.attempt, secs(t + 0.5))));
        t += 1.0;
    }
    assert!(s.is_done());
    assert_eq!(s.worker_stats(W1).unwrap().strips, 10);
    assert_eq!(s.worker_stats(W0).unwrap().strips, 0);
    assert_eq!(s.worker_stats(W0).unwrap().duplicates, 1);
}

#[test]
fn late_results_after_a_timeout_are_never_counted_twice() {
    let mut s = Scheduler::new(8, 4);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let a = s.assign(W0, Duration::ZERO).unwrap();
    let f = StripFailure::timed_out(secs(700.0), secs(600.0));
    assert_eq!(s.failed(W0, a.strip, f.clone(), secs(700.0)), FailureOutcome::Retrying);
    assert_eq!(s.failed(W0, a.strip, f, secs(700.0)), FailureOutcome::Ignored, "reported once");
    // The same worker may pull the strip again: the old attempt still does not match.
    let again = s.assign(W0, secs(700.0)).unwrap();
    assert_eq!((again.strip, again.attempt), (a.strip, 2));
    assert_eq!(s.complete(W0, a.strip, a.attempt, secs(701.0)), Completion::Unknown);
    assert!(is_accepted(&s.complete(W0, again.strip, again.attempt, secs(702.0))));
    assert_eq!(s.complete(W0, again.strip, again.attempt, secs(703.0)), Completion::Duplicate);
    assert_eq!(s.complete(W0, StripId(99), 1, secs(703.0)), Completion::Unknown);
    assert_eq!(s.progress(), (1, 2));
    assert_eq!(s.worker_stats(W0).unwrap().strips, 1);
}

#[test]
fn tail_speculation_copies_the_oldest_strip_and_the_first_result_wins() {
    let mut s = Scheduler::new(12, 4);
    for w in [W0, W1, W2] {
        s.add_worker(w, 4);
    }
    let a0 = s.assign(W0, secs(0.0)).unwrap();
    let a1 = s.assign(W0, secs(1.0)).unwrap();
    let b = s.assign(W1, secs(2.0)).unwrap();
    assert!(!a0.speculative && !a1.speculative && !b.speculative);
    // The queue is empty: W1's free slot takes a copy of the oldest outstanding strip it does not hold.
    let spec = s.assign(W1, secs(3.0)).unwrap();
    assert_eq!((spec.strip, spec.attempt, spec.speculative), (StripId(0), 2, true));
    // W2 cannot take strip 0 (two copies in flight): it gets the next oldest, strip 1.
    let spec2 = s.assign(W2, secs(3.0)).unwrap();
    assert_eq!(spec2.strip, StripId(1));
    let spec3 = s.assign(W2, secs(3.0)).unwrap();
    assert_eq!(spec3.strip, StripId(2), "strip 2 has one copy, on W1");
    assert_eq!(s.assign(WorkerId(7), secs(3.0)), None);
    // The copy finishes first and wins; the original is cancelled and its late result is a duplicate.
    assert_eq!(
        s.complete(W1, spec.strip, spec.attempt, secs(4.0)),
        Completion::Accepted { cancel: vec![(W0, StripId(0))] }
    );
    assert_eq!(s.in_flight(W0), vec![StripId(1)]);
    assert_eq!(s.complete(W0, a0.strip, a0.attempt, secs(5.0)), Completion::Duplicate);
    assert!(is_accepted(&s.complete(W0, a1.strip, a1.attempt, secs(5.0))));
    assert_eq!(s.complete(W2, spec2.strip, spec2.attempt, secs(6.0)), Completion::Duplicate);
    assert!(is_accepted(&s.complete(W1, b.strip, b.attempt, secs(6.0))));
    assert_eq!(s.complete(W2, spec3.strip, spec3.attempt, secs(6.0)), Completion::Duplicate);
    assert!(s.is_done());
    assert_eq!(s.assign(W0, secs(7.0)), None, "nothing left to copy");
    let total: u32 = s.workers().map(|(_, st)| st.strips).sum();
    assert_eq!(total, 3);
    assert_eq!(s.worker_stats(W2).unwrap().speculative, 2);
    assert_eq!(s.worker_stats(W2).unwrap().duplicates, 2);
}

#[test]
fn speculation_can_be_disabled() {
    let policy = Policy { max_copies: 1, ..Policy::default() };
    let mut s = Scheduler::with_policy(4, 4, policy);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    assert!(s.assign(W0, Duration::ZERO).is_some());
    assert_eq!(s.assign(W1, Duration::ZERO), None);
}

#[test]
fn a_failed_copy_leaves_the_other_copy_running_without_requeueing() {
    let mut s = Scheduler::new(4, 4);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let a = s.assign(W0, secs(0.0)).unwrap();
    let b = s.assign(W1, secs(1.0)).unwrap();
    assert!(b.speculative);
    assert_eq!(s.failed(W1, b.strip, StripFailure::transient("reset"), secs(2.0)), FailureOutcome::Retrying);
    assert!(s.pending_strips().is_empty(), "the original still runs");
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(3.0))));
    assert!(s.is_done());
}

#[test]
fn repeated_counted_failures_block_the_worker_and_requeue_its_strips() {
    let mut s = Scheduler::new(40, 4);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let mut t = 0.0;
    for n in 1..=2 {
        let a = s.assign(W0, secs(t)).unwrap();
        let out = s.failed(W0, a.strip, StripFailure::counted(format!("crash {n}")), secs(t + 1.0));
        assert_eq!(out, FailureOutcome::Retrying);
        assert_eq!(s.pending_strips()[0], a.strip, "requeued at the front");
        t += 2.0;
    }
    let a = s.assign(W0, secs(t)).unwrap();
    let other = s.assign(W0, secs(t)).unwrap();
    assert_eq!((a.strip, a.attempt, other.strip), (StripId(0), 3, StripId(1)));
    match s.failed(W0, a.strip, StripFailure::counted("crash 3"), secs(t + 1.0)) {
        FailureOutcome::WorkerBlocked { reason, cancel } => {
            assert!(reason.contains("3 failed units (limit 3)") && reason.contains("crash 3"), "{reason}");
            assert_eq!(cancel, vec![StripId(1)]);
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(s.worker_stats(W0).unwrap().state, WorkerState::Blocked(_)));
    assert_eq!(s.worker_stats(W0).unwrap().counted_failures, 3);
    assert_eq!(s.pending_strips()[..3], [StripId(0), StripId(1), StripId(2)]);
    assert_eq!(s.assign(W0, secs(t + 1.0)), None);
    assert_eq!(s.complete(W0, other.strip, other.attempt, secs(t + 2.0)), Completion::Unknown);
    assert!(!s.all_workers_gone());
    let mut now = t + 2.0;
    while let Some(a) = s.assign(W1, secs(now)) {
        assert!(is_accepted(&s.complete(W1, a.strip, a.attempt, secs(now + 0.5))));
        now += 1.0;
    }
    assert!(s.is_done());
}

#[test]
fn uncounted_failures_do_not_count_toward_the_limit() {
    let mut s = Scheduler::new(8, 4);
    s.add_worker(W0, 4);
    for i in 0..10 {
        let a = s.assign(W0, secs(f64::from(i))).unwrap();
        let out = s.failed(W0, a.strip, StripFailure::transient("connection reset"), secs(f64::from(i) + 0.5));
        assert_eq!(out, FailureOutcome::Retrying);
    }
    let stats = s.worker_stats(W0).unwrap();
    assert_eq!((stats.failures, stats.counted_failures, stats.state.clone()), (10, 0, WorkerState::Active));
    let a = s.assign(W0, secs(20.0)).unwrap();
    assert_eq!(a.attempt, 11);
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(21.0))));
}

#[test]
fn a_fatal_failure_stops_the_render() {
    let mut s = Scheduler::new(8, 4);
    s.add_worker(W0, 4);
    let a = s.assign(W0, Duration::ZERO).unwrap();
    assert_eq!(s.failed(W0, a.strip, StripFailure::fatal("bad scene"), secs(1.0)), FailureOutcome::Fatal);
    assert_eq!(s.fatal().map(|(strip, f)| (*strip, f.reason.as_str())), Some((StripId(0), "bad scene")));
    assert_eq!(s.assign(W0, secs(1.0)), None);
    assert!(!s.is_done());
}

#[test]
fn when_all_workers_are_gone_the_remaining_strips_stay_pending() {
    let mut s = Scheduler::new(20, 4);
    assert!(s.all_workers_gone(), "no worker yet");
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let a = s.assign(W0, Duration::ZERO).unwrap();
    s.assign(W1, Duration::ZERO).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(1.0))));
    s.worker_lost(W0, secs(2.0));
    assert!(!s.all_workers_gone());
    s.worker_lost(W1, secs(2.0));
    assert!(s.all_workers_gone());
    assert_eq!(s.done_strips(), vec![StripId(0)]);
    assert_eq!(s.pending_strips(), (1..5).map(StripId).collect::<Vec<_>>());
    assert_eq!(s.progress(), (1, 5));
}

#[test]
fn a_stalled_worker_is_reported_past_its_deadline() {
    let policy = Policy { deadline_floor: secs(1.0), first_deadline: secs(100.0), ..Policy::default() };
    let mut s = Scheduler::with_policy(40, 4, policy);
    s.add_worker(W0, 4);
    s.add_worker(W1, 8);
    // Nothing measured yet: the first deadline applies.
    let a = s.assign(W0, Duration::ZERO).unwrap();
    assert_eq!(s.deadline(W0, a.strip), Some(secs(100.0)));
    assert!(s.expired(secs(100.0)).is_empty());
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(2.0))));
    // W0 measured 0.5 s per row: a 4-row strip is due after max(4 × 2 s, 1 s) = 8 s.
    assert_eq!(s.seconds_per_row(W0), Some(0.5));
    let b = s.assign(W0, secs(10.0)).unwrap();
    assert_eq!(s.deadline(W0, b.strip), Some(secs(18.0)));
    // W1 has measured nothing: it borrows W0's core-seconds per row, halved for its 8 cores.
    let c = s.assign(W1, secs(10.0)).unwrap();
    assert_eq!(s.deadline(W1, c.strip), Some(secs(14.0)));
    assert_eq!(s.next_deadline(), Some(secs(14.0)));
    assert!(s.expired(secs(14.0)).is_empty());
    assert_eq!(s.expired(secs(15.0)), vec![(W1, c.strip)]);
    assert_eq!(s.expired(secs(19.0)), vec![(W0, b.strip), (W1, c.strip)]);
    // The caller cancels and reports: the strips requeue at the front in order.
    for (w, strip) in s.expired(secs(19.0)) {
        let f = StripFailure::timed_out(secs(9.0), secs(8.0));
        assert_eq!(s.failed(w, strip, f, secs(19.0)), FailureOutcome::Retrying);
    }
    assert!(s.expired(secs(1000.0)).is_empty());
    assert_eq!(s.pending_strips()[..2], [b.strip, c.strip]);
    assert_eq!(s.worker_stats(W1).unwrap().counted_failures, 1);
}

#[test]
fn the_speed_estimate_is_a_moving_average() {
    let policy = Policy { speed_smoothing: 0.5, ..Policy::default() };
    let mut s = Scheduler::with_policy(8, 4, policy);
    s.add_worker(W0, 4);
    let a = s.assign(W0, secs(0.0)).unwrap();
    s.complete(W0, a.strip, a.attempt, secs(4.0));
    let b = s.assign(W0, secs(4.0)).unwrap();
    s.complete(W0, b.strip, b.attempt, secs(12.0));
    assert_eq!(s.seconds_per_row(W0), Some(1.5));
    assert_eq!(s.worker_stats(W0).unwrap().busy, secs(12.0));
}

#[test]
fn strips_marked_done_are_never_assigned() {
    let mut s = Scheduler::new(40, 4);
    for i in [0, 3, 4, 9] {
        assert!(s.mark_done(StripId(i)));
    }
    assert!(!s.mark_done(StripId(3)), "already done");
    assert!(!s.mark_done(StripId(10)), "out of range");
    assert_eq!(s.progress(), (4, 10));
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let mut seen = Vec::new();
    let mut t = 0.0;
    loop {
        let mut any = false;
        for w in [W0, W1] {
            if let Some(a) = s.assign(w, secs(t)) {
                seen.push(a.strip.0);
                assert!(is_accepted(&s.complete(w, a.strip, a.attempt, secs(t + 1.0))));
                any = true;
            }
        }
        t += 1.0;
        if !any {
            break;
        }
    }
    assert_eq!(seen, vec![1, 2, 5, 6, 7, 8]);
    assert!(s.is_done());
    assert_eq!(s.done_strips().len(), 10);
}

#[test]
fn marking_a_running_strip_done_turns_its_result_into_a_duplicate() {
    let mut s = Scheduler::new(8, 4);
    s.add_worker(W0, 4);
    let a = s.assign(W0, Duration::ZERO).unwrap();
    assert!(s.mark_done(a.strip));
    assert_eq!(s.complete(W0, a.strip, a.attempt, secs(1.0)), Completion::Duplicate);
    assert!(s.in_flight(W0).is_empty());
    assert_eq!(s.progress(), (1, 2));
}

/// Checks that the scheduler's books agree with what the test knows is on the wire, and that no strip is lost.
fn check_books(s: &Scheduler, outstanding: &[(WorkerId, Assignment)], accepted: &[u32]) {
    let done = accepted.iter().filter(|&&n| n == 1).count();
    assert!(accepted.iter().all(|&n| n <= 1), "a strip was accepted twice");
    assert_eq!(s.progress(), (done, accepted.len()));
    let mut by_worker: BTreeMap<WorkerId, Vec<StripId>> = BTreeMap::new();
    for (w, a) in outstanding {
        by_worker.entry(*w).or_default().push(a.strip);
    }
    for (id, stats) in s.workers() {
        let mut expect = by_worker.remove(&id).unwrap_or_default();
        expect.sort_unstable();
        assert_eq!(s.in_flight(id), expect, "{id}");
        assert!(expect.len() <= s.policy().max_in_flight);
        if stats.state != WorkerState::Active {
            assert!(expect.is_empty());
        }
    }
    assert!(by_worker.is_empty());
    let pending = s.pending_strips();
    for strip in 0..accepted.len() as u32 {
        let strip = StripId(strip);
        let queued = pending.iter().filter(|&&p| p == strip).count();
        let copies = outstanding.iter().filter(|(_, a)| a.strip == strip).count();
        // A stalled copy is issued again beside itself, whatever the copy limit.
        let stalled = s.copies(strip).filter(|(_, f)| f.stalled).count();
        assert!(copies <= s.policy().max_copies + stalled);
        if accepted[strip.0 as usize] == 1 {
            assert_eq!((queued, copies), (0, 0), "{strip} is done");
        } else {
            assert!((queued == 1) != (copies > 0), "{strip}: queued {queued} times, {copies} copies in flight");
        }
    }
}

/// A blocked worker `w`'s strips in flight: they must be the ones the scheduler cancels, and become stale.
fn withdraw(
    w: WorkerId,
    mut cancel: Vec<StripId>,
    outstanding: &mut Vec<(WorkerId, Assignment)>,
    stale: &mut Vec<(WorkerId, Assignment)>,
    seed: u64,
) {
    let mut theirs: Vec<StripId> = outstanding.iter().filter(|(o, _)| *o == w).map(|(_, a)| a.strip).collect();
    theirs.sort_unstable();
    cancel.sort_unstable();
    assert_eq!(cancel, theirs, "seed {seed}");
    stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
    outstanding.retain(|(o, _)| *o != w);
}

#[test]
fn random_event_orders_accept_every_strip_exactly_once() {
    // How often the interesting paths were taken over all seeds, to show the test reaches them.
    let (mut drops, mut losses, mut expiries, mut late, mut speculative, mut stalls) = (0, 0, 0, 0, 0, 0);
    for seed in 0..200u64 {
        let mut rng = SplitMix64(seed);
        let height = 1 + rng.below(60) as u32;
        let rows = 1 + rng.below(6) as u32;
        let policy = Policy {
            max_in_flight: 1 + rng.below(3),
            max_copies: 1 + rng.below(3),
            block_after: 1 + rng.below(4) as u32,
            deadline_floor: secs(1.0),
            first_deadline: secs(20.0),
            silence_floor: secs(0.5),
            ..Policy::default()
        };
        let mut s = Scheduler::with_policy(height, rows, policy);
        let mut accepted = vec![0u32; s.strip_count()];
        // What is on the wire, and results that are no longer current (for late replays).
        let mut outstanding: Vec<(WorkerId, Assignment)> = Vec::new();
        let mut stale: Vec<(WorkerId, Assignment)> = Vec::new();
        let mut next_worker = 0u32;
        let mut now = Duration::ZERO;
        let accept = |strip: StripId, accepted: &mut Vec<u32>| {
            accepted[strip.0 as usize] += 1;
            assert_eq!(accepted[strip.0 as usize], 1, "seed {seed}: {strip} accepted twice");
        };
        for _ in 0..400 {
            now += secs(rng.below(1000) as f64 / 1000.0);
            match rng.below(10) {
                0 if next_worker < 6 => {
                    assert!(s.add_worker(WorkerId(next_worker), 1 + rng.below(16) as u32));
                    next_worker += 1;
                }
                1 | 2 => {
                    let w = WorkerId(rng.below(next_worker as usize + 1) as u32);
                    if let Some(a) = s.assign(w, now) {
                        speculative += u32::from(a.speculative);
                        outstanding.push((w, a));
                    }
                }
                3 | 4 if !outstanding.is_empty() => {
                    let (w, a) = outstanding.swap_remove(rng.below(outstanding.len()));
                    match s.complete(w, a.strip, a.attempt, now) {
                        Completion::Accepted { cancel } => {
                            accept(a.strip, &mut accepted);
                            for c in cancel {
                                let i = outstanding.iter().position(|(w, a)| (*w, a.strip) == c).unwrap();
                                stale.push(outstanding.swap_remove(i));
                            }
                        }
                        other => panic!("seed {seed}: a current assignment was {other:?}"),
                    }
                    stale.push((w, a));
                }
                5 if !stale.is_empty() => {
                    let (w, a) = stale[rng.below(stale.len())].clone();
                    let c = s.complete(w, a.strip, a.attempt, now);
                    late += 1;
                    assert!(!is_accepted(&c), "seed {seed}: a stale result {a:?} from {w} was accepted");
                }
                6 if !outstanding.is_empty() => {
                    let (w, a) = outstanding.swap_remove(rng.below(outstanding.len()));
                    let failure = if rng.below(2) == 0 {
                        StripFailure::counted("crash")
                    } else {
                        StripFailure::transient("reset")
                    };
                    match s.failed(w, a.strip, failure, now) {
                        FailureOutcome::Retrying => {}
                        FailureOutcome::WorkerBlocked { cancel, .. } => {
                            drops += 1;
                            withdraw(w, cancel, &mut outstanding, &mut stale, seed);
                        }
                        other => panic!("seed {seed}: {other:?}"),
                    }
                    stale.push((w, a));
                }
                7 if next_worker > 0 && rng.below(4) == 0 => {
                    let w = WorkerId(rng.below(next_worker as usize) as u32);
                    let mut lost = s.worker_lost(w, now);
                    losses += 1;
                    let mut theirs: Vec<StripId> =
                        outstanding.iter().filter(|(o, _)| *o == w).map(|(_, a)| a.strip).collect();
                    theirs.sort_unstable();
                    lost.sort_unstable();
                    assert_eq!(lost, theirs, "seed {seed}");
                    stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
                    outstanding.retain(|(o, _)| *o != w);
                }
                8 => {
                    for (w, strip) in s.expired(now) {
                        let Some(i) = outstanding.iter().position(|(o, a)| (*o, a.strip) == (w, strip)) else {
                            let f = StripFailure::timed_out(now, now);
                            assert_eq!(s.failed(w, strip, f, now), FailureOutcome::Ignored, "seed {seed}");
                            continue;
                        };
                        let (w, a) = outstanding.swap_remove(i);
                        expiries += 1;
                        match s.failed(w, strip, StripFailure::timed_out(now, now), now) {
                            FailureOutcome::Retrying => {}
                            FailureOutcome::WorkerBlocked { .. } => {
                                stale.extend(outstanding.iter().filter(|(o, _)| *o == w).cloned());
                                outstanding.retain(|(o, _)| *o != w);
                            }
                            other => panic!("seed {seed}: {other:?}"),
                        }
                        stale.push((w, a));
                    }
                }
                9 => {
                    for stall in s.check_stalls(now) {
                        stalls += 1;
                        if rng.below(3) == 0 {
                            s.heard_from(stall.worker, now);
                        }
                        if let Some((_, cancel)) = stall.blocked {
                            drops += 1;
                            withdraw(stall.worker, cancel, &mut outstanding, &mut stale, seed);
                        }
                    }
                }
                _ => {}
            }
            check_books(&s, &outstanding, &accepted);
        }
        // Drain: a reliable worker joins and every result is delivered, oldest first.
        assert!(s.add_worker(WorkerId(100), 8));
        let ids: Vec<WorkerId> = s.workers().map(|(id, _)| id).collect();
        while !s.is_done() {
            for &w in &ids {
                while let Some(a) = s.assign(w, now) {
                    outstanding.push((w, a));
                }
            }
            assert!(!outstanding.is_empty(), "seed {seed}: strips left but nothing to run");
            now += secs(1.0);
            while !outstanding.is_empty() {
                let (w, a) = outstanding.remove(0);
                match s.complete(w, a.strip, a.attempt, now) {
                    Completion::Accepted { cancel } => {
                        accept(a.strip, &mut accepted);
                        outstanding.retain(|(o, b)| !cancel.contains(&(*o, b.strip)));
                    }
                    other => panic!("seed {seed}: {other:?}"),
                }
            }
            check_books(&s, &outstanding, &accepted);
        }
        assert!(accepted.iter().all(|&n| n == 1), "seed {seed}: {accepted:?}");
        let total: u32 = s.workers().map(|(_, st)| st.strips).sum();
        assert_eq!(total as usize, accepted.len(), "seed {seed}: per-worker counts add up");
        for (w, a) in &stale {
            assert_eq!(s.complete(*w, a.strip, a.attempt, now), Completion::Duplicate, "seed {seed}");
        }
    }
    let counts = [drops, losses, expiries, late, speculative, stalls];
    assert!(
        counts.iter().all(|&n| n >= 20),
        "blocks, losses, expiries, late results, speculative copies, stalls: {counts:?}"
    );
}

#[test]
fn a_lost_worker_rejoins_with_its_numbers_and_takes_strips_again() {
    let mut s = Scheduler::new(40, 4);
    s.add_worker(W0, 4);
    s.add_worker(W1, 4);
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(1.0))));
    let held = s.assign(W0, secs(1.0)).unwrap();
    assert_eq!(s.worker_lost(W0, secs(2.0)), vec![held.strip]);
    assert_eq!(s.assign(W0, secs(2.0)), None, "a lost worker takes nothing");
    // Only a lost worker rejoins; an active or blocked one, or an unknown id, does not.
    assert!(!s.rejoin(W1, 4));
    assert!(!s.rejoin(W2, 4));
    assert!(s.rejoin(W0, 8));
    assert!(!s.rejoin(W0, 8), "already back");
    let stats = s.worker_stats(W0).unwrap();
    assert_eq!((stats.state.clone(), stats.cores, stats.strips, stats.rejoins), (WorkerState::Active, 8, 1, 1));
    assert_eq!(s.seconds_per_row(W0), None, "measured afresh");
    // It takes the strip it held when it was lost (requeued at the front), with a new attempt number; a late
    // result of the old attempt is not accepted.
    let again = s.assign(W0, secs(3.0)).unwrap();
    assert_eq!(again.strip, held.strip);
    assert!(again.attempt > held.attempt);
    assert_eq!(s.complete(W0, held.strip, held.attempt, secs(3.5)), Completion::Unknown);
    assert!(is_accepted(&s.complete(W0, again.strip, again.attempt, secs(4.0))));
    assert_eq!(s.worker_stats(W0).unwrap().strips, 2);
    // A blocked worker stays out.
    let policy = Policy { block_after: 1, ..Policy::default() };
    let mut s = Scheduler::with_policy(8, 4, policy);
    s.add_worker(W0, 1);
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(matches!(
        s.failed(W0, a.strip, StripFailure::counted("bad"), secs(1.0)),
        FailureOutcome::WorkerBlocked { .. }
    ));
    assert!(!s.rejoin(W0, 1));
}

#[test]
fn a_busy_worker_silent_past_its_limit_is_stalled_until_it_speaks() {
    let policy = Policy { silence_floor: secs(2.0), first_deadline: secs(100.0), ..Policy::default() };
    let mut s = Scheduler::with_policy(40, 4, policy);
    s.add_worker(W0, 1);
    s.add_worker(W1, 1);
    // Before its speed is known, a worker may be silent for the first deadline (its first strip may load the
    // scene).
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert_eq!(s.silence_limit(W0), secs(100.0));
    assert!(s.check_stalls(secs(99.0)).is_empty());
    s.heard_from(W0, secs(0.5));
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(4.0))));
    s.heard_from(W0, secs(4.0));
    // 1 s a row: the limit is max(4 × 1 s, 2 s) = 4 s of silence while it holds strips.
    assert_eq!(s.silence_limit(W0), secs(4.0));
    // Idle workers are never stalled, however long they are silent; W1 holds nothing.
    assert!(s.check_stalls(secs(50.0)).is_empty());
    // Busy from 50 s: counted from then, not from when it last spoke (4 s).
    s.assign(W0, secs(50.0)).unwrap();
    assert!(s.check_stalls(secs(54.0)).is_empty());
    s.heard_from(W0, secs(53.0));
    assert!(s.check_stalls(secs(57.0)).is_empty());
    let stalls = s.check_stalls(secs(57.5));
    assert_eq!(stalls.len(), 1);
    assert_eq!((stalls[0].worker, stalls[0].newly, &stalls[0].strips[..]), (W0, true, &[StripId(1)][..]));
    assert!(s.worker_stats(W0).unwrap().stalled);
    assert!(s.check_stalls(secs(60.0)).is_empty(), "reported once");
    // It stays stalled until it is heard from, then it is not.
    s.heard_from(W0, secs(61.0));
    assert!(!s.worker_stats(W0).unwrap().stalled);
    assert!(!s.worker_stats(W1).unwrap().stalled);
    // The floor holds for a fast worker: 0.01 s a row still allows 2 s.
    let mut s = Scheduler::with_policy(40, 4, Policy { silence_floor: secs(2.0), ..Policy::default() });
    s.add_worker(W0, 1);
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(0.04))));
    assert_eq!(s.silence_limit(W0), secs(2.0));
}

#[test]
fn a_bounded_render_appends_rounds_served_after_what_is_queued() {
    // Round 1: passes 0..4 in blocks of 2; round 2 appends 4..9 in blocks of 3 (the last one shorter).
    let mut s = Scheduler::new(4, 2);
    s.add_worker(W0, 1);
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(1.0))));
    let b = s.assign(W0, secs(1.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, b.strip, b.attempt, secs(2.0))));
    assert!(s.is_done());
    let ids = s.extend(5, 3);
    assert_eq!(ids, 2..4);
    assert!(!s.is_done());
    assert_eq!((s.strip_rows(StripId(2)), s.strip_rows(StripId(3))), (Some(4..7), Some(7..9)));
    assert_eq!(s.progress(), (2, 4));
    let c = s.assign(W0, secs(2.0)).unwrap();
    assert_eq!((c.strip, c.rows.clone()), (StripId(2), 4..7));
    assert!(is_accepted(&s.complete(W0, c.strip, c.attempt, secs(3.0))));
    let d = s.assign(W0, secs(3.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, d.strip, d.attempt, secs(4.0))));
    assert!(s.is_done());
    // Nothing appended: no strip, still done.
    assert_eq!(s.extend(0, 3), 4..4);
    assert!(s.is_done());
}

#[test]
fn copies_in_flight_count_the_originals_and_their_tail_copies() {
    let mut s = Scheduler::new(16, 4);
    for w in [W0, W1] {
        s.add_worker(w, 4);
    }
    assert_eq!(s.copies_in_flight(), vec![0, 0, 0, 0]);
    let a0 = s.assign(W0, secs(0.0)).unwrap();
    let a1 = s.assign(W0, secs(0.0)).unwrap();
    let b = s.assign(W1, secs(1.0)).unwrap();
    assert_eq!(s.copies_in_flight(), vec![1, 1, 1, 0]);
    assert!(is_accepted(&s.complete(W1, b.strip, b.attempt, secs(2.0))));
    let c = s.assign(W1, secs(2.0)).unwrap();
    // The queue is empty: W1's free slot copies strip 0, now in flight twice.
    let spec = s.assign(W1, secs(2.0)).unwrap();
    assert_eq!((c.strip, spec.strip, spec.speculative), (StripId(3), StripId(0), true));
    assert_eq!(s.copies_in_flight(), vec![2, 1, 0, 1]);
    // The first result wins and cancels the other copy: no copy of strip 0 is left in flight.
    assert!(is_accepted(&s.complete(W0, a0.strip, a0.attempt, secs(3.0))));
    assert_eq!(s.copies_in_flight(), vec![0, 1, 0, 1]);
    assert_eq!(s.done_strips(), vec![StripId(0), StripId(2)]);
    assert!(is_accepted(&s.complete(W0, a1.strip, a1.attempt, secs(3.0))));
}

/// A worker silent past its limit has its units issued again, to the next free worker before anything else,
/// while its own copy runs on: whichever copy finishes first is the one accepted, once. The stalled worker gets
/// nothing new until it speaks; once it has, its copy counts as running again and is not re-issued twice.
#[test]
fn a_stalled_unit_is_issued_again_before_its_deadline_and_the_first_result_wins() {
    let policy = Policy { silence_floor: secs(2.0), max_copies: 1, block_after: 10, ..Policy::default() };
    let mut s = Scheduler::with_policy(40, 4, policy);
    s.add_worker(W0, 1);
    s.add_worker(W1, 1);
    // W0 measures 1 s a row (a 4-row strip in 4 s): silent for 4 s, it has stalled; its deadline is 16 s.
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(4.0))));
    let b = s.assign(W0, secs(4.0)).unwrap();
    let c = s.assign(W0, secs(4.0)).unwrap();
    assert_eq!(s.deadline(W0, b.strip), Some(secs(20.0)));
    assert!(s.check_stalls(secs(8.0)).is_empty());
    let stalls = s.check_stalls(secs(8.5));
    assert_eq!(stalls.len(), 1);
    assert_eq!((stalls[0].worker, stalls[0].newly, stalls[0].blocked.clone()), (W0, true, None));
    assert_eq!(stalls[0].strips, vec![b.strip, c.strip]);
    assert_eq!(s.worker_stats(W0).unwrap().counted_failures, 2, "each unit is charged");
    // W1 takes the stalled units first (copies beside the stalled ones, whatever max_copies), then fresh ones.
    assert_eq!(s.assign(W0, secs(8.5)), None, "a stalled worker gets nothing new");
    let b1 = s.assign(W1, secs(8.5)).unwrap();
    let c1 = s.assign(W1, secs(8.5)).unwrap();
    assert_eq!((b1.strip, c1.strip, b1.speculative), (b.strip, c.strip, false));
    assert!(b1.attempt > b.attempt);
    assert_eq!(s.copies_in_flight()[b.strip.0 as usize], 2);
    // W1 finishes strip b first: W0's copy is cancelled. W0 comes back and finishes strip c before W1: W1's
    // copy is cancelled, and W1's late result is not accepted.
    assert_eq!(s.complete(W1, b1.strip, b1.attempt, secs(9.0)), Completion::Accepted { cancel: vec![(W0, b.strip)] });
    s.heard_from(W0, secs(9.5));
    assert!(!s.worker_stats(W0).unwrap().stalled);
    assert!(s.check_stalls(secs(9.9)).is_empty(), "W0 spoke at 9.5 s, W1 is busy since 8.5 s (limit 2 s)");
    assert_eq!(s.complete(W0, c.strip, c.attempt, secs(10.0)), Completion::Accepted { cancel: vec![(W1, c.strip)] });
    assert_eq!(s.complete(W1, c1.strip, c1.attempt, secs(10.5)), Completion::Duplicate);
    assert_eq!(s.done_strips(), vec![a.strip, b.strip, c.strip]);
    // A unit is charged once: stalled, then past its deadline, it still counts one failed unit.
    let d = s.assign(W0, secs(10.0)).unwrap();
    assert_eq!(s.check_stalls(secs(20.0)).len(), 1);
    assert_eq!(s.worker_stats(W0).unwrap().counted_failures, 3, "two before, one now");
    let deadline = s.deadline(W0, d.strip).unwrap();
    assert_eq!(s.expired(deadline + secs(1.0)), vec![(W0, d.strip)]);
    let f = StripFailure::timed_out(secs(30.0), secs(16.0));
    assert_eq!(s.failed(W0, d.strip, f, deadline + secs(1.0)), FailureOutcome::Retrying);
    assert_eq!(s.worker_stats(W0).unwrap().counted_failures, 3, "charged once");
}

/// Three failed units of one job block a worker whatever their cause: a corrupt result, a stall and a lost
/// connection here. A blocked worker takes nothing, is not taken back as a lost one would be, and its strips
/// go to the others; the render finishes without it.
#[test]
fn a_worker_that_fails_three_units_whatever_the_cause_is_blocked() {
    let policy = Policy { silence_floor: secs(2.0), block_after: 3, ..Policy::default() };
    let mut s = Scheduler::with_policy(40, 4, policy);
    s.add_worker(W0, 1);
    s.add_worker(W1, 1);
    let a = s.assign(W0, secs(0.0)).unwrap();
    assert!(is_accepted(&s.complete(W0, a.strip, a.attempt, secs(1.0))));
    // 1: a corrupt result.
    let b = s.assign(W0, secs(1.0)).unwrap();
    assert_eq!(s.failed(W0, b.strip, StripFailure::counted("checksum mismatch"), secs(2.0)), FailureOutcome::Retrying);
    // 2: a stall on one unit (it takes the requeued strip again, and holds only that).
    let c = s.assign(W0, secs(2.0)).unwrap();
    assert_eq!(c.strip, b.strip);
    let stalls = s.check_stalls(secs(10.0));
    assert_eq!((stalls.len(), s.worker_stats(W0).unwrap().counted_failures), (1, 2));
    // W1 takes the stalled unit; W0's copy ends when W1's result lands.
    let c1 = s.assign(W1, secs(10.0)).unwrap();
    assert_eq!(c1.strip, c.strip);
    assert!(is_accepted(&s.complete(W1, c1.strip, c1.attempt, secs(11.0))));
    // 3: lost while holding a unit (it took new units once it held nothing).
    let d = s.assign(W0, secs(11.0)).unwrap();
    let e = s.assign(W0, secs(11.0)).unwrap();
    assert_eq!(s.worker_lost(W0, secs(12.0)), vec![d.strip, e.strip]);
    let stats = s.worker_stats(W0).unwrap();
    assert_eq!(stats.counted_failures, 3);
    match &stats.state {
        WorkerState::Blocked(why) => {
            assert!(why.starts_with("3 failed units (limit 3)") && why.contains("lost"), "{why}")
        }
        other => panic!("{other:?}"),
    }
    assert!(!s.rejoin(W0, 1), "a blocked worker is not taken back");
    assert_eq!(s.assign(W0, secs(12.0)), None);
    assert_eq!(s.pending_strips()[..2], [d.strip, e.strip], "requeued at the front");
    let mut now = 12.0;
    while let Some(a) = s.assign(W1, secs(now)) {
        assert!(is_accepted(&s.complete(W1, a.strip, a.attempt, secs(now + 0.5))));
        now += 1.0;
    }
    assert!(s.is_done());
}
