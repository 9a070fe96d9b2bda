//! A discrete-event model of a render farm: the real [`Scheduler`] state machine driven by a simulated clock and
//! network, to answer what a 50-machine lab would do with a job before renting one.
//!
//! What is modelled:
//! - the coordinator prepares the job (serially, [`SimJob::prepare_s`]), then uploads the blobs to every
//!   worker at once, the uploads sharing its link fairly (each at most its worker's link: with N workers behind
//!   one link every worker holds them after N blob times, as measured on namespaced hosts), or, with
//!   [`SimJob::relay`], to one worker at a time while every worker holding them sends them on to one more
//!   ([`crate::fleet::swarm`]); a worker decodes them
//!   ([`SimJob::load_core_s`]) and is ready;
//! - a worker renders one unit at a time on all its cores, at `cores × core_speed × thread_efficiency`
//!   reference cores, and holds up to the policy's `max_in_flight` units;
//! - a result crosses the worker's link and the coordinator's downlink, which results share first come, first
//!   served; the scheduler sees it when it has arrived;
//! - a worker may die at a given time: the coordinator sees the connection drop after a detection delay
//!   ([`Network::detect_s`]) and the scheduler requeues its units;
//! - deadlines, speculative copies and cancellations are the scheduler's own.
//!
//! What is not: request latency beyond one round trip per unit, memory, and the variance of unit costs (every
//! unit of a job costs the same per row or pass).

use crate::farm::scheduler::{Completion, Policy, Scheduler, StripFailure, StripId, WorkerId};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, VecDeque};
use std::time::Duration;

/// A simulated worker machine.
#[derive(Clone, Debug, PartialEq)]
pub struct SimWorker {
    /// Cores it renders with.
    pub cores: u32,
    /// Speed of one of its cores relative to the reference core of [`SimJob`]'s costs.
    pub core_speed: f64,
    /// When it dies (seconds from the start), if it does.
    pub dies_at: Option<f64>,
}

/// The links, in bytes per second.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    /// The coordinator's link (each direction).
    pub coordinator_bps: f64,
    /// Each worker's link.
    pub worker_bps: f64,
    /// One round trip, seconds (a unit's request and its first byte back).
    pub rtt_s: f64,
    /// Seconds from a worker's death to the coordinator's noticing (a reset connection: about a round trip; a
    /// machine that vanishes: the keepalive timeout).
    pub detect_s: f64,
}

impl Network {
    /// 1 Gbit/s everywhere, 0.2 ms round trips, deaths seen after 1 s.
    pub fn gigabit() -> Self {
        Self { coordinator_bps: 125e6, worker_bps: 125e6, rtt_s: 2e-4, detect_s: 1.0 }
    }
}

/// A job as the model sees it: units (rows, or passes) cut into strips, and what each costs.
#[derive(Clone, Debug, PartialEq)]
pub struct SimJob {
    /// Units in the job: image rows, or progressive passes.
    pub units: u32,
    /// Units per strip (rows per strip, or passes per block).
    pub units_per_strip: u32,
    /// Reference-core seconds to render one unit.
    pub core_s_per_unit: f64,
    /// Bytes a strip sends back: a fixed part (a pass block's whole image) plus a part per unit (a row).
    pub result_bytes_fixed: f64,
    /// See [`SimJob::result_bytes_fixed`].
    pub result_bytes_per_unit: f64,
    /// Bytes of blobs shipped to each worker.
    pub blob_bytes: f64,
    /// Seconds the coordinator prepares the job before shipping (scene, BVH, photon maps).
    pub prepare_s: f64,
    /// Reference-core seconds a worker spends decoding the blobs (rebuilding trees), on all its cores.
    pub load_core_s: f64,
    /// Fraction of linear speed-up within one worker (0..=1]: measured thread scaling.
    pub thread_efficiency: f64,
    /// The workers pass the blobs on among themselves (`--photon-maps peers`): the holders double with each
    /// transfer time, so the i-th worker (from 0) holds them after ⌊log₂(i+1)⌋ + 1 transfers.
    pub relay: bool,
}

/// Where the time went.
#[derive(Clone, Debug, PartialEq)]
pub struct SimReport {
    /// Seconds from the start to the last result.
    pub makespan_s: f64,
    /// The time a perfect farm would need: the job's work over the farm's total speed (no prepare, no shipping,
    /// no tail).
    pub ideal_s: f64,
    /// `ideal_s / makespan_s`.
    pub efficiency: f64,
    /// Seconds preparing.
    pub prepare_s: f64,
    /// Seconds from the end of preparing until the last live worker was ready.
    pub ship_s: f64,
    /// Seconds from the moment no unit was waiting any more until the last result (the tail).
    pub tail_s: f64,
    /// Speculative copies issued.
    pub speculative: u32,
    /// Strips whose first copy was lost or failed.
    pub failures: u32,
    /// Whether every strip was done (false when no worker was left).
    pub complete: bool,
    /// Strips accepted from each worker, in order.
    pub strips: Vec<u32>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Ready(usize),
    Computed { worker: usize, generation: u64 },
    Arrived { worker: usize, strip: StripId, attempt: u32 },
    Dies(usize),
    Noticed(usize),
    Tick,
}

#[derive(Clone, Copy, Debug)]
struct Event {
    t: f64,
    seq: u64,
    kind: Kind,
}

impl PartialEq for Event {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Event {}
impl PartialOrd for Event {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Event {
    /// Earliest first in a max-heap; ties in the order they were scheduled.
    fn cmp(&self, o: &Self) -> Ordering {
        o.t.total_cmp(&self.t).then(o.seq.cmp(&self.seq))
    }
}

#[derive(Clone, Debug, Default)]
struct Machine {
    /// Units assigned and not started: (strip, attempt).
    queue: VecDeque<(StripId, u32)>,
    /// The unit rendering now, and the generation that tells its completion from a cancelled one's.
    current: Option<(StripId, u32)>,
    generation: u64,
    ready: bool,
    dead: bool,
}

struct Sim<'a> {
    job: &'a SimJob,
    workers: &'a [SimWorker],
    net: &'a Network,
    sched: Scheduler,
    machines: Vec<Machine>,
    events: BinaryHeap<Event>,
    seq: u64,
    downlink_free: f64,
    queue_empty_at: Option<f64>,
    failures: u32,
    /// When the last live worker became ready.
    last_ready: f64,
    /// When the last accepted result arrived.
    end: f64,
}

/// Runs `job` on `workers` over `net` with `policy`; returns where the time went.
pub fn simulate(job: &SimJob, workers: &[SimWorker], net: &Network, policy: Policy) -> SimReport {
    let mut sim = Sim::new(job, workers, net, policy);
    sim.run();
    sim.report()
}

fn at(t: f64) -> Duration {
    Duration::from_secs_f64(t.max(0.0))
}

impl<'a> Sim<'a> {
    /// The farm before the start: every worker's readiness (after its upload and decode) and death scheduled.
    fn new(job: &'a SimJob, workers: &'a [SimWorker], net: &'a Network, policy: Policy) -> Self {
        let mut sim = Sim {
            job,
            workers,
            net,
            sched: Scheduler::with_policy(job.units, job.units_per_strip, policy),
            machines: vec![Machine::default(); workers.len()],
            events: BinaryHeap::new(),
            seq: 0,
            downlink_free: job.prepare_s,
            queue_empty_at: None,
            failures: 0,
            last_ready: job.prepare_s,
            end: job.prepare_s,
        };
        // Uploads all at once, sharing the coordinator's link fairly (TCP's share; measured in docs/RESULTS.md,
        // "The farm on a network"), or passed on in rounds of one transfer each.
        let upload = job.blob_bytes / net.coordinator_bps.min(net.worker_bps);
        let shared = job.blob_bytes / net.worker_bps.min(net.coordinator_bps / workers.len().max(1) as f64);
        for (i, w) in workers.iter().enumerate() {
            let moving = if job.relay { f64::from((i + 1).ilog2() + 1) * upload } else { shared };
            let held = job.prepare_s + moving;
            sim.push(held + net.rtt_s + job.load_core_s / sim.speed(i), Kind::Ready(i));
            if let Some(t) = w.dies_at {
                sim.push(t, Kind::Dies(i));
            }
        }
        sim
    }

    /// Takes events in time order until every strip is done, or no worker is left.
    fn run(&mut self) {
        while let Some(Event { t, kind, .. }) = self.events.pop() {
            if self.sched.is_done() {
                break;
            }
            self.handle(kind, t);
            for (w, s) in self.sched.expired(at(t)) {
                self.withdraw(w.0 as usize, s, t);
                let deadline = self.sched.deadline(w, s).unwrap_or_default();
                self.sched.failed(w, s, StripFailure::timed_out(at(t), deadline), at(t));
                self.failures += 1;
            }
            self.fill(t);
            if let Some(d) = self.sched.next_deadline() {
                let d = d.as_secs_f64();
                if d > t && self.events.peek().is_none_or(|e| e.t > d) {
                    self.push(d + 1e-6, Kind::Tick);
                }
            }
            if self.sched.all_workers_gone() && self.machines.iter().all(|m| m.ready || m.dead) {
                break;
            }
        }
    }

    /// One event at time `t`.
    fn handle(&mut self, kind: Kind, t: f64) {
        match kind {
            Kind::Ready(i) if !self.machines[i].dead => {
                self.sched.add_worker(WorkerId(i as u32), self.workers[i].cores);
                self.machines[i].ready = true;
                self.last_ready = self.last_ready.max(t);
            }
            Kind::Ready(_) => {}
            Kind::Computed { worker, generation } => self.computed(worker, generation, t),
            Kind::Arrived { worker, strip, attempt } => {
                if let Completion::Accepted { cancel } =
                    self.sched.complete(WorkerId(worker as u32), strip, attempt, at(t))
                {
                    self.end = t;
                    for (w, s) in cancel {
                        self.withdraw(w.0 as usize, s, t);
                    }
                }
            }
            Kind::Dies(i) => {
                let m = &mut self.machines[i];
                m.dead = true;
                m.generation += 1;
                self.push(t + self.net.detect_s, Kind::Noticed(i));
            }
            Kind::Noticed(i) => {
                let lost = self.sched.worker_lost(WorkerId(i as u32), at(t));
                self.failures += lost.len() as u32;
            }
            Kind::Tick => {}
        }
    }

    /// Where the time went, once the run is over.
    fn report(&self) -> SimReport {
        let (job, workers, end) = (self.job, self.workers, self.end);
        let speed: f64 = (0..workers.len()).map(|i| self.speed(i)).sum();
        let ideal_s = f64::from(job.units) * job.core_s_per_unit / speed.max(f64::MIN_POSITIVE);
        let speculative = self.sched.workers().map(|(_, s)| s.speculative).sum();
        let complete = self.sched.is_done();
        let strips =
            (0..workers.len()).map(|i| self.sched.worker_stats(WorkerId(i as u32)).map_or(0, |s| s.strips)).collect();
        SimReport {
            makespan_s: end,
            ideal_s,
            efficiency: if complete { ideal_s / end } else { 0.0 },
            prepare_s: job.prepare_s,
            ship_s: self.last_ready - job.prepare_s,
            tail_s: self.queue_empty_at.map_or(0.0, |q| (end - q).max(0.0)),
            speculative,
            failures: self.failures,
            complete,
            strips,
        }
    }

    fn push(&mut self, t: f64, kind: Kind) {
        self.seq += 1;
        self.events.push(Event { t, seq: self.seq, kind });
    }

    /// Reference cores' worth of speed of worker `i`.
    fn speed(&self, i: usize) -> f64 {
        let w = &self.workers[i];
        f64::from(w.cores.max(1)) * w.core_speed * self.job.thread_efficiency
    }

    /// Gives every ready, live worker units up to its slots, and starts the idle ones.
    fn fill(&mut self, t: f64) {
        for i in 0..self.machines.len() {
            if !self.machines[i].ready || self.machines[i].dead {
                continue;
            }
            while let Some(a) = self.sched.assign(WorkerId(i as u32), at(t)) {
                self.machines[i].queue.push_back((a.strip, a.attempt));
            }
            self.start_next(i, t);
        }
        if self.queue_empty_at.is_none() && self.sched.pending_strips().is_empty() {
            self.queue_empty_at = Some(t);
        }
    }

    /// Starts worker `i`'s next queued unit if it is idle.
    fn start_next(&mut self, i: usize, t: f64) {
        if self.machines[i].current.is_some() {
            return;
        }
        let Some((strip, attempt)) = self.machines[i].queue.pop_front() else { return };
        let units = self.sched.strip_rows(strip).map_or(0, |r| r.len());
        let compute = units as f64 * self.job.core_s_per_unit / self.speed(i);
        let m = &mut self.machines[i];
        m.current = Some((strip, attempt));
        m.generation += 1;
        let generation = m.generation;
        self.push(t + self.net.rtt_s + compute, Kind::Computed { worker: i, generation });
    }

    /// Worker `i` finished computing: its result goes over the coordinator's downlink.
    fn computed(&mut self, i: usize, generation: u64, t: f64) {
        let m = &mut self.machines[i];
        if m.dead || m.generation != generation {
            return;
        }
        let Some((strip, attempt)) = m.current.take() else { return };
        let units = self.sched.strip_rows(strip).map_or(0, |r| r.len()) as f64;
        let bytes = self.job.result_bytes_fixed + units * self.job.result_bytes_per_unit;
        let start = t.max(self.downlink_free);
        let done = start + bytes / self.net.coordinator_bps.min(self.net.worker_bps);
        self.downlink_free = done;
        self.push(done, Kind::Arrived { worker: i, strip, attempt });
        self.start_next(i, t);
    }

    /// Worker `i` drops its copy of `strip` (cancelled or overdue).
    fn withdraw(&mut self, i: usize, strip: StripId, t: f64) {
        let m = &mut self.machines[i];
        m.queue.retain(|&(s, _)| s != strip);
        if m.current.is_some_and(|(s, _)| s == strip) {
            m.current = None;
            m.generation += 1;
            self.start_next(i, t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(units: u32, per_strip: u32) -> SimJob {
        SimJob {
            units,
            units_per_strip: per_strip,
            core_s_per_unit: 1.0,
            result_bytes_fixed: 0.0,
            result_bytes_per_unit: 1000.0,
            blob_bytes: 1e6,
            prepare_s: 2.0,
            load_core_s: 0.5,
            thread_efficiency: 1.0,
            relay: false,
        }
    }

    fn same(n: usize, cores: u32) -> Vec<SimWorker> {
        vec![SimWorker { cores, core_speed: 1.0, dies_at: None }; n]
    }

    #[test]
    fn one_worker_takes_the_serial_time() {
        let j = job(400, 4);
        let net = Network::gigabit();
        let r = simulate(&j, &same(1, 4), &net, Policy::default());
        assert!(r.complete);
        // prepare + upload + decode + the work on 4 cores; a round trip for the hello and for each of the 100
        // strips, and the transfer of the last result (the others cross while the next strip renders).
        let serial = 2.0 + 1e6 / 125e6 + 0.5 / 4.0 + 400.0 / 4.0;
        let overhead = 101.0 * net.rtt_s + 4000.0 / 125e6;
        assert!((r.makespan_s - serial - overhead).abs() < 1e-6, "{} against {}", r.makespan_s, serial + overhead);
        assert!((r.ideal_s - 100.0).abs() < 1e-9);
    }

    #[test]
    fn doubling_identical_workers_halves_the_time_until_the_tail_dominates() {
        let j = SimJob { prepare_s: 0.0, blob_bytes: 0.0, load_core_s: 0.0, ..job(4096, 4) };
        let net = Network::gigabit();
        let mut last: Option<f64> = None;
        for n in [1, 2, 4, 8, 16] {
            let r = simulate(&j, &same(n, 1), &net, Policy::default());
            assert!(r.complete);
            if let Some(prev) = last {
                let ratio = r.makespan_s / prev;
                assert!((ratio - 0.5).abs() < 0.02, "{n} workers: {ratio}");
            }
            last = Some(r.makespan_s);
        }
        // Four strips for 16 single-core workers of 4 s each: the tail is one strip's time, whatever the farm.
        let few = simulate(&SimJob { units: 16, ..j.clone() }, &same(16, 1), &net, Policy::default());
        let more = simulate(&SimJob { units: 16, ..j }, &same(32, 1), &net, Policy::default());
        assert!((few.makespan_s - more.makespan_s).abs() < 0.01, "{} {}", few.makespan_s, more.makespan_s);
    }

    #[test]
    fn faster_workers_take_more_and_a_dead_one_loses_nothing() {
        let j = job(2000, 4);
        let mut ws = same(4, 4);
        ws[0].core_speed = 3.0;
        ws[3].dies_at = Some(50.0);
        let r = simulate(&j, &ws, &Network::gigabit(), Policy::default());
        assert!(r.complete);
        assert!(r.failures >= 1);
        assert!(r.strips[0] > 2 * r.strips[1], "{:?}", r.strips);
        assert_eq!(r.strips.iter().sum::<u32>(), 500);
        let healthy = simulate(&j, &same(4, 4), &Network::gigabit(), Policy::default());
        assert!(healthy.efficiency > 0.95, "{healthy:?}");
        // Speeds 3 + 1 + 1 (+ 1 until t = 50): about 2000 / (4 × 5) = 100 s of work after the first 50 s.
        assert!(r.makespan_s > 50.0 && r.makespan_s < 2.0 + 2000.0 / 20.0 + 20.0, "{r:?}");
    }

    #[test]
    fn a_slow_link_shows_as_shipping_time() {
        let j = SimJob { blob_bytes: 250e6, ..job(400, 4) };
        let net = Network { coordinator_bps: 125e6, ..Network::gigabit() };
        let r = simulate(&j, &same(4, 4), &net, Policy::default());
        // Four 2 s uploads sharing one link: every worker is ready 8 s (and its decode) after preparing.
        assert!((r.ship_s - (8.0 + net.rtt_s + 0.5 / 4.0)).abs() < 1e-6, "{r:?}");
        // Passed on among the workers: 1 + 2 + 4 hold them after three transfers, the 8th after four.
        let relayed = SimJob { relay: true, ..j };
        for (n, transfers) in [(1, 1.0), (3, 2.0), (4, 3.0), (7, 3.0), (8, 4.0)] {
            let r = simulate(&relayed, &same(n, 4), &net, Policy::default());
            assert!((r.ship_s - (2.0 * transfers + net.rtt_s + 0.5 / 4.0)).abs() < 1e-6, "{n}: {r:?}");
        }
    }
}
