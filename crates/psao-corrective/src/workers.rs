//! The threaded runtime of corrections (paper §4.4): one pool of tracing workers on their own
//! threads serves the region queues ([`Planner`]) of every viewer, each in its own [`Lane`],
//! taking jobs from the lanes in turn (round-robin), and pushes each job's samples into its
//! lane's sample queue, which that viewer's frame loop drains within its per-frame time
//! budget. Per lane, the analyzer (at its own rate) replaces the queue's regions with
//! [`Lane::analyze`], the frame loop gives the current view with [`Lane::set_view`] and the
//! sample budget with [`Lane::grant`]: every position a worker examines costs one sample of
//! the budget, whether it gives a sample or misses the job's object (its primary ray is
//! traced either way), so workers examine at most as many positions as were granted, and
//! never more than the lane's `max_outstanding` are granted but not yet drained. A region of
//! an object that is nowhere on screen thus costs its lane's budget, not unbounded work.
//! A lane may also have a time budget per grant ([`Lane::set_time_budget`], the paper's
//! per-frame 1/f): each grant refills it, each job's tracing time is taken from it, and no
//! job of the lane starts once it is spent, so a lane examines at most its granted positions
//! and starts no job after its time is used up (the job running then may overrun it).
//!
//! Plain `std` threads rather than rayon: the workers block on a condition variable between
//! jobs and run for the pool's lifetime, which rayon's task pool is not made for.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::attention::ObjectRegion;
use crate::schedule::Job;
use crate::session::Planner;

/// What the workers trace with.
pub trait JobTracer: Send + Sync + 'static {
    /// What a job is traced for (e.g. a camera, the image size and the camera age).
    type View: Send + Sync + 'static;
    /// One traced sample.
    type Sample: Send + 'static;
    /// Trace the positions of `job` (pixel centres in iteration order) for `view`; positions
    /// not on the job's object give no sample (and cost their share of the budget all the
    /// same).
    fn trace_job(
        &self,
        view: &Self::View,
        job: &Job,
        positions: &[(i32, i32)],
    ) -> Vec<Self::Sample>;
}

/// Counters of a lane since it was opened.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolStats {
    /// Samples granted (each pays for one examined position).
    pub granted: u64,
    /// Jobs traced.
    pub jobs: u64,
    /// Positions examined (at most `granted`).
    pub examined: u64,
    /// Samples traced (pushed into the sample queue).
    pub traced: u64,
    /// Samples drained.
    pub drained: u64,
    /// Wall-clock time the workers spent tracing the lane's jobs (summed over workers).
    pub trace_time: Duration,
}

impl PoolStats {
    /// Samples traced per second of tracing time (0 before any job).
    pub fn samples_per_second(&self) -> f64 {
        let s = self.trace_time.as_secs_f64();
        if s > 0.0 {
            self.traced as f64 / s
        } else {
            0.0
        }
    }
}

/// One viewer's region queue, view, allowance and sample queue.
struct LaneState<T: JobTracer> {
    planner: Planner,
    view: Option<Arc<T::View>>,
    max_outstanding: u64,
    /// Positions the workers may still examine.
    allowance: u64,
    /// Tracing time each grant allows (`None`: no time limit).
    time_per_grant: Option<Duration>,
    /// Tracing time left of the latest grant.
    time_left: Option<Duration>,
    /// Positions of jobs in flight (their samples not yet queued).
    reserved: u64,
    /// Jobs in flight.
    busy: usize,
    samples: VecDeque<T::Sample>,
    stats: PoolStats,
}

impl<T: JobTracer> LaneState<T> {
    fn can_work(&self) -> bool {
        self.allowance > 0
            && self.time_left.is_none_or(|t| !t.is_zero())
            && self.view.is_some()
            && self.planner.has_work()
    }
}

struct State<T: JobTracer> {
    lanes: BTreeMap<u64, LaneState<T>>,
    next_id: u64,
    /// The lane served next if it has work (round-robin over lane ids).
    cursor: u64,
    shutdown: bool,
}

impl<T: JobTracer> State<T> {
    /// The lane with work that is next in turn from the cursor, cyclically.
    fn next_lane(&self) -> Option<u64> {
        let after = self.lanes.range(self.cursor..);
        let before = self.lanes.range(..self.cursor);
        after
            .chain(before)
            .find(|(_, l)| l.can_work())
            .map(|(&id, _)| id)
    }
}

struct Shared<T: JobTracer> {
    state: Mutex<State<T>>,
    /// Signalled when work may be available or on shutdown.
    work: Condvar,
    /// Signalled when a job ends.
    done: Condvar,
}

impl<T: JobTracer> Shared<T> {
    /// The state; a worker that panicked while holding the lock leaves it usable (every
    /// update keeps the counters consistent before anything that can panic).
    fn lock(&self) -> MutexGuard<'_, State<T>> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Tracing workers shared by every lane opened on them.
pub struct WorkerPool<T: JobTracer> {
    shared: Arc<Shared<T>>,
    threads: Vec<JoinHandle<()>>,
}

impl<T: JobTracer> WorkerPool<T> {
    /// `workers` threads (at least 1) tracing with `tracer`, without lanes yet.
    pub fn new(tracer: T, workers: usize) -> Self {
        Self::with_thread_start(tracer, workers, || {})
    }

    /// As [`WorkerPool::new`], each worker thread first running `start` (e.g. to lower its
    /// scheduling priority below the server step's: the caller's business, not this crate's).
    pub fn with_thread_start(
        tracer: T,
        workers: usize,
        start: impl Fn() + Send + Sync + 'static,
    ) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                lanes: BTreeMap::new(),
                next_id: 0,
                cursor: 0,
                shutdown: false,
            }),
            work: Condvar::new(),
            done: Condvar::new(),
        });
        let tracer = Arc::new(tracer);
        let start = Arc::new(start);
        let threads = (0..workers.max(1))
            .filter_map(|i| {
                let (shared, tracer, start) = (shared.clone(), tracer.clone(), start.clone());
                std::thread::Builder::new()
                    .name(format!("psao-corrective-{i}"))
                    .spawn(move || {
                        start();
                        work(&shared, &*tracer)
                    })
                    .ok()
            })
            .collect();
        Self { shared, threads }
    }

    /// Worker threads running.
    pub fn workers(&self) -> usize {
        self.threads.len()
    }

    /// Open a lane over `planner`'s queue, with at most `max_outstanding` samples granted and
    /// not yet drained at any time; dropping the lane closes it.
    pub fn lane(&self, planner: Planner, max_outstanding: u64) -> Lane<T> {
        let mut s = self.shared.lock();
        let id = s.next_id;
        s.next_id += 1;
        s.lanes.insert(
            id,
            LaneState {
                planner,
                view: None,
                max_outstanding,
                allowance: 0,
                time_per_grant: None,
                time_left: None,
                reserved: 0,
                busy: 0,
                samples: VecDeque::new(),
                stats: PoolStats::default(),
            },
        );
        Lane {
            shared: self.shared.clone(),
            id,
        }
    }

    /// Lanes open.
    pub fn lanes(&self) -> usize {
        self.shared.lock().lanes.len()
    }
}

impl<T: JobTracer> Drop for WorkerPool<T> {
    /// Stop the workers (each finishes its job in flight) and join them; lanes still open
    /// get no more samples.
    fn drop(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.work.notify_all();
        for t in self.threads.drain(..) {
            // A worker that panicked has had its panic message printed; nothing to add.
            let _ = t.join();
        }
    }
}

/// One viewer's share of a [`WorkerPool`]: its region queue and sample queue.
pub struct Lane<T: JobTracer> {
    shared: Arc<Shared<T>>,
    id: u64,
}

impl<T: JobTracer> Lane<T> {
    /// Runs `f` on this lane's state.
    fn with<R>(&self, f: impl FnOnce(&mut LaneState<T>) -> R) -> R {
        let mut s = self.shared.lock();
        let lane = s
            .lanes
            .get_mut(&self.id)
            .expect("a lane is open while its handle lives");
        f(lane)
    }

    /// A new analysis of a frame seen at `camera_age` (see [`Planner::analyze`]).
    pub fn analyze(&self, regions: &[ObjectRegion], camera_age: u32) {
        self.with(|l| l.planner.analyze(regions, camera_age));
        self.shared.work.notify_all();
    }

    /// The viewer's camera age now (see [`Planner::set_camera_age`]).
    pub fn set_camera_age(&self, camera_age: u32) {
        self.with(|l| l.planner.set_camera_age(camera_age));
        self.shared.work.notify_all();
    }

    /// Replace the queue (e.g. for a new image size).
    pub fn replace_planner(&self, planner: Planner) {
        self.with(|l| l.planner = planner);
        self.shared.work.notify_all();
    }

    /// Trace the next jobs for `view` (jobs in flight finish with the view they took).
    pub fn set_view(&self, view: T::View) {
        self.with(|l| l.view = Some(Arc::new(view)));
        self.shared.work.notify_all();
    }

    /// Give every later grant `time` of tracing (`None`: no time limit, the default); until
    /// the next grant the time left is at most `time`. The sample allowance applies all the
    /// same.
    pub fn set_time_budget(&self, time: Option<Duration>) {
        self.with(|l| {
            l.time_per_grant = time;
            l.time_left = match (l.time_left, time) {
                (Some(left), Some(t)) => Some(left.min(t)),
                (_, t) => t,
            };
        });
        self.shared.work.notify_all();
    }

    /// Allow `samples` more samples, as far as `max_outstanding` leaves room (granted, in
    /// flight and queued samples count), and refill the time budget; returns the samples
    /// actually granted. Each pays for one examined position, which gives at most one sample.
    pub fn grant(&self, samples: u64) -> u64 {
        let (granted, refilled) = self.with(|l| {
            l.time_left = l.time_per_grant;
            let outstanding = l.allowance + l.reserved + l.samples.len() as u64;
            let granted = samples.min(l.max_outstanding.saturating_sub(outstanding));
            l.allowance += granted;
            l.stats.granted += granted;
            (granted, l.time_per_grant.is_some())
        });
        if granted > 0 || refilled {
            self.shared.work.notify_all();
        }
        granted
    }

    /// Take up to `max` queued samples, stopping early once `deadline` has passed (checked
    /// every 256 samples; at least one batch is taken).
    pub fn drain(&self, max: usize, deadline: Instant) -> Vec<T::Sample> {
        const BATCH: usize = 256;
        let mut out = Vec::new();
        loop {
            let (n, more) = self.with(|l| {
                let n = BATCH.min(max - out.len()).min(l.samples.len());
                out.extend(l.samples.drain(..n));
                l.stats.drained += n as u64;
                (n, !l.samples.is_empty())
            });
            if n == 0 || !more || out.len() >= max || Instant::now() >= deadline {
                return out;
            }
        }
    }

    /// Wait up to `timeout` until no job of this lane is in flight and none can start
    /// (allowance spent, queue dry, no view, or the pool stopped); true when idle.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        let mut s = self.shared.lock();
        loop {
            let stopped = s.shutdown;
            let lane = s
                .lanes
                .get(&self.id)
                .expect("a lane is open while its handle lives");
            if lane.busy == 0 && (stopped || !lane.can_work()) {
                return true;
            }
            let now = Instant::now();
            if now >= end {
                return false;
            }
            s = self
                .shared
                .done
                .wait_timeout(s, end - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> PoolStats {
        self.with(|l| l.stats)
    }

    /// Samples waiting in the sample queue.
    pub fn queued(&self) -> usize {
        self.with(|l| l.samples.len())
    }
}

impl<T: JobTracer> Drop for Lane<T> {
    /// Close the lane: its jobs in flight finish and their samples are dropped.
    fn drop(&mut self) {
        self.shared.lock().lanes.remove(&self.id);
    }
}

/// A worker's loop: wait for work, take a job of at most the allowance of the lane next in
/// turn (each of its positions spent from the allowance, on the object or not), trace it
/// without the lock and queue its samples in its lane (if still open).
fn work<T: JobTracer>(shared: &Shared<T>, tracer: &T) {
    let mut s = shared.lock();
    loop {
        if s.shutdown {
            return;
        }
        let Some(id) = s.next_lane() else {
            s = shared.work.wait(s).unwrap_or_else(|e| e.into_inner());
            continue;
        };
        s.cursor = id + 1;
        let Some(lane) = s.lanes.get_mut(&id) else {
            continue;
        };
        let allowance = lane.allowance;
        let Some(job) = lane.planner.take_job(allowance) else {
            continue;
        };
        let Some(view) = lane.view.clone() else {
            continue;
        };
        let mut positions = lane.planner.positions(&job);
        positions.truncate(allowance.try_into().unwrap_or(usize::MAX));
        let cost = positions.len() as u64;
        lane.allowance -= cost;
        lane.reserved += cost;
        lane.busy += 1;
        drop(s);
        let started = Instant::now();
        let mut samples = tracer.trace_job(&view, &job, &positions);
        let took = started.elapsed();
        samples.truncate(positions.len());
        s = shared.lock();
        if let Some(lane) = s.lanes.get_mut(&id) {
            lane.time_left = lane.time_left.map(|t| t.saturating_sub(took));
            lane.stats.trace_time += took;
            lane.reserved -= cost;
            lane.busy -= 1;
            lane.stats.jobs += 1;
            lane.stats.examined += cost;
            lane.stats.traced += samples.len() as u64;
            lane.samples.extend(samples);
        }
        shared.done.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sqrt5::{Hierarchy, PixelRect};
    use std::collections::HashSet;

    /// Object 1 covers the even columns of its rectangle; a sample is its position and view.
    struct Stripes;

    impl JobTracer for Stripes {
        type View = u32;
        type Sample = (i32, i32, u32);
        fn trace_job(&self, view: &u32, job: &Job, positions: &[(i32, i32)]) -> Vec<Self::Sample> {
            assert_eq!(job.object, 1);
            positions
                .iter()
                .filter(|(x, _)| x % 2 == 0)
                .map(|&(x, y)| (x, y, *view))
                .collect()
        }
    }

    const RECT: PixelRect = PixelRect {
        x0: 3,
        y0: 2,
        x1: 43,
        y1: 30,
    };

    fn region() -> ObjectRegion {
        ObjectRegion {
            id: 1,
            rect: RECT,
            pixels: 0,
            saliency: 0.0,
            importance: 0.0,
            priority: 1.0,
        }
    }

    fn pool(workers: usize, max_outstanding: u64) -> (WorkerPool<Stripes>, Lane<Stripes>) {
        let pool = WorkerPool::new(Stripes, workers);
        let lane = pool.lane(planner(), max_outstanding);
        lane.analyze(&[region()], 0);
        lane.set_view(7);
        (pool, lane)
    }

    fn planner() -> Planner {
        Planner::new(Hierarchy::new(4).unwrap(), 16, 0.8)
    }

    fn on_object() -> usize {
        (RECT.x0..RECT.x1).filter(|x| x % 2 == 0).count() * (RECT.y1 - RECT.y0) as usize
    }

    const WAIT: Duration = Duration::from_secs(30);

    #[test]
    fn every_sample_arrives_exactly_once_with_one_and_two_workers() {
        for workers in [1, 2] {
            let (pool, p) = pool(workers, u64::MAX);
            assert_eq!(pool.workers(), workers);
            let mut seen = HashSet::new();
            // The frame loop: grant a frame's budget, drain what is ready, until every sample
            // arrived (bounded by time, not by a count of rounds: a loaded machine runs the
            // workers rarely, and a drain with nothing ready returns at once).
            let end = Instant::now() + WAIT;
            while Instant::now() < end {
                p.grant(37);
                for s in p.drain(usize::MAX, Instant::now() + Duration::from_millis(2)) {
                    assert!(seen.insert(s), "{s:?} twice");
                }
                if seen.len() == on_object() {
                    break;
                }
                std::thread::yield_now();
            }
            assert!(p.wait_idle(WAIT));
            assert!(p.drain(usize::MAX, Instant::now()).is_empty());
            assert_eq!(seen.len(), on_object(), "{workers} workers");
            let stats = p.stats();
            assert_eq!(stats.traced, on_object() as u64);
            assert_eq!(stats.drained, stats.traced);
        }
    }

    #[test]
    fn a_spent_time_budget_starts_no_job_and_each_grant_refills_it() {
        for workers in [1, 2] {
            let (_pool, p) = pool(workers, u64::MAX);
            // No time at all: the allowance stays unspent.
            p.set_time_budget(Some(Duration::ZERO));
            assert_eq!(p.grant(500), 500);
            assert!(p.wait_idle(WAIT));
            assert_eq!(p.stats().examined, 0);
            // A nanosecond per grant (from the next grant on): each worker starts at most one
            // job (16 positions) before the first job ends and spends it, far below the 500
            // allowed, and at least one.
            p.set_time_budget(Some(Duration::from_nanos(1)));
            let mut before = 0;
            for _ in 0..3 {
                p.grant(0);
                assert!(p.wait_idle(WAIT));
                let examined = p.stats().examined;
                assert!(examined > before, "{workers} workers");
                assert!(
                    examined - before <= 16 * workers as u64,
                    "{workers} workers"
                );
                before = examined;
            }
            let stats = p.stats();
            assert!(stats.trace_time > Duration::ZERO && stats.samples_per_second() > 0.0);
            // Without a time limit the rest of the allowance is examined.
            p.set_time_budget(None);
            p.grant(0);
            assert!(p.wait_idle(WAIT));
            assert_eq!(p.stats().examined, 500);
        }
    }

    #[test]
    fn workers_examine_exactly_the_positions_granted() {
        for workers in [1, 2] {
            let (_pool, p) = pool(workers, u64::MAX);
            let mut granted = 0;
            for budget in [1, 5, 40, 3, 100] {
                granted += p.grant(budget);
                assert!(p.wait_idle(WAIT));
                let stats = p.stats();
                assert_eq!(stats.examined, granted, "{workers} workers");
                // Positions off the object (odd columns) cost their share too.
                assert!(stats.traced < stats.examined, "{stats:?}");
            }
            let traced = p.stats().traced;
            assert_eq!(p.queued() as u64, traced);
            // The drain takes at most what it is asked for.
            assert_eq!(p.drain(10, Instant::now() + WAIT).len(), 10);
            assert_eq!(p.queued() as u64, traced - 10);
        }
    }

    #[test]
    fn grants_stop_at_the_outstanding_limit_until_drained() {
        // No view yet, so no worker can start a job between the two grants (a job finished
        // in between would free the allowance of its misses and let the second grant give
        // more: the test used to race the workers there).
        let pool = WorkerPool::new(Stripes, 2);
        let p = pool.lane(planner(), 50);
        p.analyze(&[region()], 0);
        assert_eq!(p.grant(40), 40);
        assert_eq!(p.grant(40), 10);
        p.set_view(7);
        assert!(p.wait_idle(WAIT));
        assert_eq!(p.stats().examined, 50);
        // The spent allowance is free again; the queued samples still count.
        let queued = p.queued() as u64;
        assert!(queued > 0 && queued < 50, "{queued}");
        assert_eq!(p.grant(100), 50 - queued);
        assert!(p.wait_idle(WAIT));
        let queued = p.queued() as u64;
        assert_eq!(
            p.drain(usize::MAX, Instant::now() + WAIT).len() as u64,
            queued
        );
        assert_eq!(p.grant(100), 50);
    }

    #[test]
    fn jobs_take_the_latest_view_and_queue_changes_wake_the_workers() {
        let (_pool, p) = pool(2, u64::MAX);
        p.grant(10);
        assert!(p.wait_idle(WAIT));
        let first = p.stats().traced as usize;
        p.set_view(8);
        p.grant(10);
        assert!(p.wait_idle(WAIT));
        let views: Vec<u32> = p
            .drain(usize::MAX, Instant::now() + WAIT)
            .iter()
            .map(|s| s.2)
            .collect();
        assert_eq!(views.len() as u64, p.stats().traced);
        assert!(first > 0 && views.len() > first, "{views:?}");
        assert!(views[..first].iter().all(|&v| v == 7) && views[first..].iter().all(|&v| v == 8));
        // A dry queue idles with allowance left; a new camera age restarts the regions.
        p.grant(u64::MAX / 2);
        assert!(p.wait_idle(WAIT));
        let before = p.stats().traced;
        assert_eq!(before, on_object() as u64);
        p.analyze(&[region()], 1);
        assert!(p.wait_idle(WAIT));
        assert_eq!(p.stats().traced, 2 * before);
    }

    #[test]
    fn dropping_a_busy_pool_stops_its_workers() {
        for workers in [1, 2] {
            let (pool, p) = pool(workers, u64::MAX);
            p.grant(u64::MAX / 2);
            drop(pool);
            // The lane outlives the pool: idle, nothing more traced.
            assert!(p.wait_idle(WAIT));
            let traced = p.stats().traced;
            p.grant(100);
            assert!(p.wait_idle(WAIT));
            assert_eq!(p.stats().traced, traced);
        }
        // Without a view nothing is traced, and the pool still shuts down.
        let pool = WorkerPool::new(Stripes, 2);
        let p = pool.lane(Planner::new(Hierarchy::new(2).unwrap(), 16, 0.8), 100);
        p.grant(100);
        assert!(p.wait_idle(WAIT));
        assert_eq!(p.stats().traced, 0);
    }

    /// The job's object is nowhere on screen: no position gives a sample; counts the
    /// positions it was asked to trace.
    struct Nowhere(Arc<std::sync::atomic::AtomicU64>);

    impl JobTracer for Nowhere {
        type View = u32;
        type Sample = ();
        fn trace_job(&self, _: &u32, _: &Job, positions: &[(i32, i32)]) -> Vec<()> {
            (self.0).fetch_add(positions.len() as u64, std::sync::atomic::Ordering::Relaxed);
            Vec::new()
        }
    }

    #[test]
    fn a_region_of_a_missing_object_costs_the_positions_it_examines() {
        // The largest region a client may send (a 16384² image, psao-wire's
        // MAX_REGION_IMAGE_SIDE), of an object that does not exist: 2.7·10⁸ positions that
        // all miss. The work done is the budget granted, not the region.
        const SIDE: i32 = 16_384;
        let region = ObjectRegion {
            id: 99,
            rect: PixelRect {
                x0: 0,
                y0: 0,
                x1: SIDE,
                y1: SIDE,
            },
            ..region()
        };
        for workers in [1, 2] {
            let examined = Arc::new(std::sync::atomic::AtomicU64::new(0));
            let pool = WorkerPool::new(Nowhere(examined.clone()), workers);
            let hierarchy = Hierarchy::for_spacing(SIDE as f32 / 4.0);
            let p = pool.lane(Planner::new(hierarchy, 64, 0.8), 1500);
            p.analyze(std::slice::from_ref(&region), 0);
            p.set_view(0);
            let mut granted = 0;
            for frame in 0..10 {
                granted += p.grant(1000);
                assert!(p.wait_idle(WAIT), "frame {frame}: still tracing");
                let traced = examined.load(std::sync::atomic::Ordering::Relaxed);
                assert_eq!(traced, granted, "frame {frame}, {workers} workers");
            }
            assert_eq!(granted, 10_000);
            let stats = p.stats();
            assert_eq!((stats.examined, stats.traced), (granted, 0));
        }
    }

    /// Logs the view of every job; the first job waits until the gate opens.
    struct Gated(Arc<Gate>);

    #[derive(Default)]
    struct Gate {
        open: Mutex<bool>,
        opened: Condvar,
        views: Mutex<Vec<u32>>,
    }

    impl JobTracer for Gated {
        type View = u32;
        type Sample = u32;
        fn trace_job(&self, view: &u32, job: &Job, positions: &[(i32, i32)]) -> Vec<u32> {
            let mut open = self.0.open.lock().unwrap();
            while !*open {
                open = self.0.opened.wait(open).unwrap();
            }
            drop(open);
            self.0.views.lock().unwrap().push(*view);
            Stripes
                .trace_job(view, job, positions)
                .iter()
                .map(|s| s.2)
                .collect()
        }
    }

    #[test]
    fn one_pool_serves_its_lanes_in_turn_and_closed_lanes_get_nothing() {
        let gate = Arc::new(Gate::default());
        let pool = WorkerPool::new(Gated(gate.clone()), 1);
        let lanes: Vec<_> = (0..3).map(|_| pool.lane(planner(), u64::MAX)).collect();
        assert_eq!(pool.lanes(), 3);
        for lane in &lanes {
            lane.analyze(&[region()], 0);
            lane.grant(u64::MAX / 2);
        }
        // Lane 0 is first; its job waits at the gate until every lane has a view.
        for (view, lane) in lanes.iter().enumerate() {
            lane.set_view(view as u32);
        }
        // Closing lane 2 while a job is in flight leaves the others served.
        let mut lanes = lanes;
        drop(lanes.pop());
        assert_eq!(pool.lanes(), 2);
        *gate.open.lock().unwrap() = true;
        gate.opened.notify_all();
        for lane in &lanes {
            assert!(lane.wait_idle(WAIT));
            assert_eq!(lane.stats().traced, on_object() as u64);
        }
        let views = gate.views.lock().unwrap().clone();
        assert!(!views.contains(&2), "{views:?}");
        // Round-robin: the two lanes alternate, job for job.
        let jobs = views.len() / 2;
        assert!(jobs > 4, "{views:?}");
        let alternating: Vec<u32> = (0..2 * jobs as u32).map(|i| i % 2).collect();
        assert_eq!(views, alternating);
        let drained: Vec<u32> = lanes[1].drain(usize::MAX, Instant::now() + WAIT);
        assert!(drained.iter().all(|&v| v == 1));
    }
}
