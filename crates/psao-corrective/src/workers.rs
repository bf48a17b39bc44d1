//! The threaded runtime of corrections (paper §4.4): tracing workers on their own threads
//! take jobs from one viewer's region queue ([`Planner`]) and push their samples into a sample
//! queue, which the frame loop drains within its per-frame time budget. The analyzer (at its
//! own rate) replaces the queue's regions with [`WorkerPool::analyze`], the frame loop gives
//! the current view with [`WorkerPool::set_view`] and the sample budget with
//! [`WorkerPool::grant`]: workers trace at most as many samples as were granted, and never
//! more than `max_outstanding` are granted but not yet drained.
//!
//! Plain `std` threads rather than rayon: the workers block on a condition variable between
//! jobs and run for the pool's lifetime, which rayon's task pool is not made for.

use std::collections::VecDeque;
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
    /// not on the job's object give no sample.
    fn trace_job(
        &self,
        view: &Self::View,
        job: &Job,
        positions: &[(i32, i32)],
    ) -> Vec<Self::Sample>;
}

/// Counters of a pool since it started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolStats {
    /// Samples granted.
    pub granted: u64,
    /// Jobs traced.
    pub jobs: u64,
    /// Samples traced (pushed into the sample queue).
    pub traced: u64,
    /// Samples drained.
    pub drained: u64,
}

struct State<T: JobTracer> {
    planner: Planner,
    view: Option<Arc<T::View>>,
    /// Samples the workers may still trace.
    allowance: u64,
    /// Samples reserved by jobs in flight.
    reserved: u64,
    /// Jobs in flight.
    busy: usize,
    samples: VecDeque<T::Sample>,
    stats: PoolStats,
    shutdown: bool,
}

impl<T: JobTracer> State<T> {
    fn can_work(&self) -> bool {
        self.allowance > 0 && self.view.is_some() && self.planner.has_work()
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

/// Tracing workers over one region queue, with the sample queue they fill.
pub struct WorkerPool<T: JobTracer> {
    shared: Arc<Shared<T>>,
    tracer: Arc<T>,
    max_outstanding: u64,
    threads: Vec<JoinHandle<()>>,
}

impl<T: JobTracer> WorkerPool<T> {
    /// `workers` threads (at least 1) tracing with `tracer` from `planner`'s queue; at most
    /// `max_outstanding` samples granted and not yet drained at any time.
    pub fn new(tracer: T, planner: Planner, workers: usize, max_outstanding: u64) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                planner,
                view: None,
                allowance: 0,
                reserved: 0,
                busy: 0,
                samples: VecDeque::new(),
                stats: PoolStats::default(),
                shutdown: false,
            }),
            work: Condvar::new(),
            done: Condvar::new(),
        });
        let tracer = Arc::new(tracer);
        let threads = (0..workers.max(1))
            .filter_map(|i| {
                let (shared, tracer) = (shared.clone(), tracer.clone());
                std::thread::Builder::new()
                    .name(format!("psao-corrective-{i}"))
                    .spawn(move || work(&shared, &*tracer))
                    .ok()
            })
            .collect();
        Self {
            shared,
            tracer,
            max_outstanding,
            threads,
        }
    }

    /// Worker threads running.
    pub fn workers(&self) -> usize {
        self.threads.len()
    }

    /// The tracer.
    pub fn tracer(&self) -> &T {
        &self.tracer
    }

    /// A new analysis of a frame seen at `camera_age` (see [`Planner::analyze`]).
    pub fn analyze(&self, regions: &[ObjectRegion], camera_age: u32) {
        self.shared.lock().planner.analyze(regions, camera_age);
        self.shared.work.notify_all();
    }

    /// Replace the queue (e.g. for a new image size).
    pub fn replace_planner(&self, planner: Planner) {
        self.shared.lock().planner = planner;
        self.shared.work.notify_all();
    }

    /// Trace the next jobs for `view` (jobs in flight finish with the view they took).
    pub fn set_view(&self, view: T::View) {
        self.shared.lock().view = Some(Arc::new(view));
        self.shared.work.notify_all();
    }

    /// Allow `samples` more samples, as far as `max_outstanding` leaves room (granted, in
    /// flight and queued samples count); returns the samples actually granted.
    pub fn grant(&self, samples: u64) -> u64 {
        let mut s = self.shared.lock();
        let outstanding = s.allowance + s.reserved + s.samples.len() as u64;
        let granted = samples.min(self.max_outstanding.saturating_sub(outstanding));
        s.allowance += granted;
        s.stats.granted += granted;
        drop(s);
        if granted > 0 {
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
            let mut s = self.shared.lock();
            let n = BATCH.min(max - out.len()).min(s.samples.len());
            out.extend(s.samples.drain(..n));
            s.stats.drained += n as u64;
            let more = !s.samples.is_empty();
            drop(s);
            if n == 0 || !more || out.len() >= max || Instant::now() >= deadline {
                return out;
            }
        }
    }

    /// Wait up to `timeout` until no job is in flight and none can start (allowance spent,
    /// queue dry or no view); true when idle.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        let mut s = self.shared.lock();
        loop {
            if s.busy == 0 && !s.can_work() {
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
        self.shared.lock().stats
    }

    /// Samples waiting in the sample queue.
    pub fn queued(&self) -> usize {
        self.shared.lock().samples.len()
    }
}

impl<T: JobTracer> Drop for WorkerPool<T> {
    /// Stop the workers (each finishes its job in flight) and join them.
    fn drop(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.work.notify_all();
        for t in self.threads.drain(..) {
            // A worker that panicked has had its panic message printed; nothing to add.
            let _ = t.join();
        }
    }
}

/// A worker's loop: wait for work, take a job within the allowance, trace it without the
/// lock, queue its samples and give back the unused allowance.
fn work<T: JobTracer>(shared: &Shared<T>, tracer: &T) {
    let mut s = shared.lock();
    loop {
        if s.shutdown {
            return;
        }
        if !s.can_work() {
            s = shared.work.wait(s).unwrap_or_else(|e| e.into_inner());
            continue;
        }
        let allowance = s.allowance;
        let Some(job) = s.planner.take_job(allowance) else {
            continue;
        };
        let Some(view) = s.view.clone() else {
            continue;
        };
        let positions = s.planner.positions(&job);
        let reserve = job.len.min(allowance);
        s.allowance -= reserve;
        s.reserved += reserve;
        s.busy += 1;
        drop(s);
        let mut samples = tracer.trace_job(&view, &job, &positions);
        samples.truncate(reserve as usize);
        s = shared.lock();
        let n = samples.len() as u64;
        s.reserved -= reserve;
        s.allowance += reserve - n;
        s.busy -= 1;
        s.stats.jobs += 1;
        s.stats.traced += n;
        s.samples.extend(samples);
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

    fn pool(workers: usize, max_outstanding: u64) -> WorkerPool<Stripes> {
        let planner = Planner::new(Hierarchy::new(4).unwrap(), 16, 0.8);
        let p = WorkerPool::new(Stripes, planner, workers, max_outstanding);
        p.analyze(&[region()], 0);
        p.set_view(7);
        p
    }

    fn on_object() -> usize {
        (RECT.x0..RECT.x1).filter(|x| x % 2 == 0).count() * (RECT.y1 - RECT.y0) as usize
    }

    const WAIT: Duration = Duration::from_secs(30);

    #[test]
    fn every_sample_arrives_exactly_once_with_one_and_two_workers() {
        for workers in [1, 2] {
            let p = pool(workers, u64::MAX);
            assert_eq!(p.workers(), workers);
            let mut seen = HashSet::new();
            // The frame loop: grant a frame's budget, drain what is ready.
            for _ in 0..10_000 {
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
    fn workers_trace_no_more_samples_than_granted() {
        for workers in [1, 2] {
            let p = pool(workers, u64::MAX);
            let mut granted = 0;
            for budget in [1, 5, 40, 3, 100] {
                granted += p.grant(budget);
                assert!(p.wait_idle(WAIT));
                assert_eq!(p.stats().traced, granted, "{workers} workers");
            }
            assert_eq!(p.queued() as u64, granted);
            // The drain takes at most what it is asked for.
            assert_eq!(p.drain(10, Instant::now() + WAIT).len(), 10);
            assert_eq!(p.queued() as u64, granted - 10);
        }
    }

    #[test]
    fn grants_stop_at_the_outstanding_limit_until_drained() {
        let p = pool(2, 50);
        assert_eq!(p.grant(40), 40);
        assert_eq!(p.grant(40), 10);
        assert!(p.wait_idle(WAIT));
        assert_eq!(p.queued(), 50);
        assert_eq!(p.grant(1), 0);
        assert_eq!(p.drain(30, Instant::now() + WAIT).len(), 30);
        assert_eq!(p.grant(100), 30);
    }

    #[test]
    fn jobs_take_the_latest_view_and_queue_changes_wake_the_workers() {
        let p = pool(2, u64::MAX);
        p.grant(10);
        assert!(p.wait_idle(WAIT));
        p.set_view(8);
        p.grant(10);
        assert!(p.wait_idle(WAIT));
        let views: Vec<u32> = p
            .drain(usize::MAX, Instant::now() + WAIT)
            .iter()
            .map(|s| s.2)
            .collect();
        assert_eq!(views.len(), 20);
        assert!(views[..10].iter().all(|&v| v == 7) && views[10..].iter().all(|&v| v == 8));
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
            let p = pool(workers, u64::MAX);
            p.grant(u64::MAX / 2);
            drop(p);
        }
        // Without a view nothing is traced, and the pool still shuts down.
        let planner = Planner::new(Hierarchy::new(2).unwrap(), 16, 0.8);
        let p = WorkerPool::new(Stripes, planner, 2, 100);
        p.grant(100);
        assert!(p.wait_idle(WAIT));
        assert_eq!(p.stats().traced, 0);
    }
}
