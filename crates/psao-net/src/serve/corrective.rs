//! The serving side of corrective splatting: each client that asked for corrections
//! ([`capabilities::CORRECTIVE`]) and whose server has them ([`Serve::with_corrections`])
//! gets a correction state ([`SessionCorrections`]); its regions and cameras update it.
//!
//! - **Lockstep** (deterministic, for tests): at every round, before the round's answer, the
//!   simulation thread traces the client's samples within its budget ([`RemoteCorrections`])
//!   and sends them.
//! - **Threaded** (the real-time server): one pool of tracing workers on their own threads
//!   ([`WorkerPool`], [`Corrections::new`]'s `workers`, made with the first threaded client)
//!   serves every client: each client's regions go into its own region queue (a [`Lane`]),
//!   which the workers take jobs from in turn, pushing samples into the lane's sample queue.
//!   Each server frame grants each client's budget for one tick and drains its samples that
//!   are ready within a wall-clock share of the frame ([`DRAIN_SHARE`]), sent as `Samples`
//!   messages: the simulation thread never traces corrections, so they cannot delay the AO
//!   step, and more clients share the same cores instead of adding threads. The workers
//!   run at a lower scheduling priority than the step ([`CORRECTION_NICE`]), so on busy
//!   cores the step goes first and corrections take what is left.
//!
//! Either way every position examined costs one sample of the client's budget, whether or
//! not it shows the region's object, and regions of objects the scene does not have are
//! dropped on arrival ([`crate::corrective::object_regions`], counted in [`ClientStats`]):
//! what a client's regions make the server trace is bounded by its budget.

use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use psao_corrective::schedule::Job;
use psao_corrective::workers::{JobTracer, Lane, WorkerPool};
use psao_scene::Camera;
use psao_wire::{
    capabilities, encode_frame, CameraMsg, Message, RegionsMsg, SampleMsg, SamplesMsg,
};

use super::{ClientStats, Serve, Session, Simulation};
use crate::corrective::{
    budget_of_tick, new_planner, object_regions, sample_msg, ClientCamera, CorrectionCounters,
    CorrectionEngine, RemoteCorrections,
};
use crate::pipeline::client_time;

/// The nice value of the correction workers' threads: below the server step (0), so they
/// never take its cores from it, but not the lowest (19) either, so other idle-priority work
/// on the machine does not starve corrections.
pub const CORRECTION_NICE: i32 = 10;

/// Default tracing workers of a server, shared by all its clients (both cores of the
/// reference machine).
pub const DEFAULT_WORKERS: usize = 2;
/// Share of a server frame the simulation thread spends at most draining one client's
/// sample queue.
pub const DRAIN_SHARE: f64 = 0.1;

/// The server's corrections: the tracing engine, every client's sample budget and the
/// workers all threaded clients share.
#[derive(Clone)]
pub struct Corrections {
    engine: Arc<CorrectionEngine>,
    samples_per_second: u32,
    /// Tracing time per server frame per client (`None`: only the sample budget limits).
    time_per_frame: Option<Duration>,
    workers: usize,
    /// The shared workers, started with the first threaded client.
    pool: Arc<OnceLock<WorkerPool<EngineJobs>>>,
}

impl Corrections {
    /// Corrections traced with `engine`, `samples_per_second` per client, by `workers`
    /// threads (at least 1) shared by every client not in lockstep.
    pub fn new(engine: Arc<CorrectionEngine>, samples_per_second: u32, workers: usize) -> Self {
        Self {
            engine,
            samples_per_second,
            time_per_frame: None,
            workers,
            pool: Arc::new(OnceLock::new()),
        }
    }

    /// The same corrections with at most `time` of worker tracing per server frame per
    /// threaded client (the paper's per-frame budget 1/f; `None`: no time limit). The sample
    /// budget still bounds every client: each examined position costs one sample of it.
    pub fn with_time_budget(mut self, time: Option<Duration>) -> Self {
        self.time_per_frame = time;
        self
    }

    /// The shared workers (started on first use; stopped when the last copy is dropped).
    fn pool(&self) -> &WorkerPool<EngineJobs> {
        self.pool.get_or_init(|| {
            // Below the server step: whatever the clients ask, corrections take the cores
            // only when the step leaves them free (docs/SECURITY.md, "Corrections").
            WorkerPool::with_thread_start(EngineJobs(self.engine.clone()), self.workers, || {
                crate::priority::lower_this_thread(CORRECTION_NICE)
            })
        })
    }
}

impl Serve {
    /// Serve corrections to the clients that ask for them.
    pub fn with_corrections(mut self, corrections: Corrections) -> Self {
        self.corrections = Some(corrections);
        self
    }
}

/// One client's correction state on the server.
pub(super) enum SessionCorrections {
    /// Traced in the simulation thread at each lockstep round.
    Lockstep(RemoteCorrections),
    /// Traced by worker threads, drained by the server frames.
    Threaded(ThreadedCorrections),
}

impl SessionCorrections {
    /// The client's camera.
    pub(super) fn camera(&mut self, msg: &CameraMsg) {
        match self {
            Self::Lockstep(r) => r.camera(msg),
            Self::Threaded(t) => t.camera(msg),
        }
    }

    /// The client's new analysis of the scene `engine` traces.
    fn regions(&mut self, msg: &RegionsMsg, engine: &CorrectionEngine) {
        match self {
            Self::Lockstep(r) => r.regions(msg, engine),
            Self::Threaded(t) => t.regions(msg, engine),
        }
    }

    /// What the client's corrections cost so far.
    pub(super) fn counters(&self) -> CorrectionCounters {
        match self {
            Self::Lockstep(r) => r.counters,
            Self::Threaded(t) => {
                let stats = t.lane.stats();
                CorrectionCounters {
                    budget: stats.granted,
                    examined: stats.examined,
                    regions_dropped: t.regions_dropped,
                }
            }
        }
    }
}

/// `stats` with the costs of `corrections`.
pub(super) fn record(corrections: Option<&SessionCorrections>, stats: &mut ClientStats) {
    if let Some(c) = corrections {
        let counters = c.counters();
        stats.correction_budget = counters.budget;
        stats.correction_examined = counters.examined;
        stats.regions_dropped = counters.regions_dropped;
        if let SessionCorrections::Threaded(t) = c {
            stats.correction_samples_per_s = t.lane.stats().samples_per_second();
        }
    }
}

/// A new session's correction state, when both ends want corrections.
pub(super) fn session_state(
    corrections: Option<&Corrections>,
    client_capabilities: u32,
    lockstep: bool,
) -> Option<SessionCorrections> {
    let c = corrections?;
    if client_capabilities & capabilities::CORRECTIVE == 0 {
        return None;
    }
    Some(if lockstep {
        SessionCorrections::Lockstep(RemoteCorrections::new(c.samples_per_second))
    } else {
        SessionCorrections::Threaded(ThreadedCorrections::new(c))
    })
}

/// A client's regions (ignored when the session has no corrections).
pub(super) fn regions(session: &mut Session, msg: &RegionsMsg, corrections: Option<&Corrections>) {
    match (&mut session.corrective, corrections) {
        (Some(state), Some(c)) => state.regions(msg, &c.engine),
        _ => tracing::debug!("client {} sent regions without corrections", session.id.0),
    }
}

/// What a worker traces a job for: the client's camera, its frame's scene time, image size and
/// camera age.
pub(super) struct TraceView {
    camera: Camera,
    time: f32,
    width: u32,
    height: u32,
    age: u32,
}

/// The engine as the workers use it: positions whose primary ray shows the job's object are
/// traced in the scene at the view's time ([`CorrectionTracer::camera_sample`] gives nothing
/// for the others); a sample carries the camera age it was traced at. A scene that cannot be
/// posed gives no samples (logged).
///
/// [`CorrectionTracer::camera_sample`]: psao_corrective::trace::CorrectionTracer::camera_sample
pub(super) struct EngineJobs(Arc<CorrectionEngine>);

impl JobTracer for EngineJobs {
    type View = TraceView;
    type Sample = (u32, SampleMsg);

    fn trace_job(
        &self,
        v: &TraceView,
        job: &Job,
        positions: &[(i32, i32)],
    ) -> Vec<(u32, SampleMsg)> {
        let traced = self.0.with_tracer(v.time, |tracer| {
            positions
                .iter()
                .filter_map(|&(x, y)| {
                    tracer.camera_sample(
                        &v.camera, v.width, v.height, x, y, job.object, job.level, v.age,
                    )
                })
                .map(|s| (v.age, sample_msg(&s)))
                .collect()
        });
        traced.unwrap_or_else(|e| {
            tracing::warn!("no corrections traced: {e}");
            Vec::new()
        })
    }
}

/// A client's threaded correction state: its lane of the shared workers (region queue and
/// sample queue), its camera and camera age, the image size of its analyses, its budget
/// clock and the regions dropped so far.
pub(super) struct ThreadedCorrections {
    lane: Lane<EngineJobs>,
    samples_per_second: u32,
    camera: ClientCamera,
    size: Option<(u32, u32)>,
    ticks: u64,
    regions_dropped: u64,
}

impl ThreadedCorrections {
    fn new(c: &Corrections) -> Self {
        // Samples granted and not yet sent: a quarter second of budget (at least a job).
        let outstanding =
            (u64::from(c.samples_per_second) / 4).max(psao_corrective::schedule::DEFAULT_JOB_SIZE);
        let lane = c.pool().lane(new_planner(1, 1), outstanding);
        lane.set_time_budget(c.time_per_frame);
        Self {
            lane,
            samples_per_second: c.samples_per_second,
            camera: ClientCamera::default(),
            size: None,
            ticks: 0,
            regions_dropped: 0,
        }
    }

    fn camera(&mut self, msg: &CameraMsg) {
        self.camera.update(msg);
        self.set_view();
    }

    fn regions(&mut self, msg: &RegionsMsg, engine: &CorrectionEngine) {
        let size = (msg.width, msg.height);
        if self.size != Some(size) {
            self.lane
                .replace_planner(new_planner(msg.width, msg.height));
            self.size = Some(size);
            self.set_view();
        }
        let (regions, dropped) = object_regions(msg, engine);
        self.regions_dropped += dropped;
        self.lane.analyze(&regions, self.camera.age);
    }

    /// The workers' view, once both a camera and an image size are known.
    fn set_view(&self) {
        self.lane.set_camera_age(self.camera.age);
        if let (Some((camera, frame)), Some((width, height))) = (self.camera.latest, self.size) {
            self.lane.set_view(TraceView {
                camera,
                time: client_time(frame),
                width,
                height,
                age: self.camera.age,
            });
        }
    }

    /// One server frame of a clock at `hz`: grant the tick's budget, then take the samples
    /// that are ready (within `drain` of wall-clock time), as messages of one camera age each.
    fn frame(&mut self, hz: u32, drain: Duration) -> Vec<SamplesMsg> {
        let budget = budget_of_tick(self.samples_per_second, hz, &mut self.ticks);
        self.lane.grant(budget as u64);
        let ready = self
            .lane
            .drain(psao_wire::MAX_SAMPLES, Instant::now() + drain);
        messages_by_age(ready)
    }
}

/// Consecutive samples of the same camera age, one message each.
fn messages_by_age(samples: Vec<(u32, SampleMsg)>) -> Vec<SamplesMsg> {
    let mut out: Vec<SamplesMsg> = Vec::new();
    for (age, s) in samples {
        match out.last_mut() {
            Some(m) if m.camera_age == age => m.samples.push(s),
            _ => out.push(SamplesMsg {
                client_frame: None,
                camera_age: age,
                samples: vec![s],
            }),
        }
    }
    out
}

impl Simulation {
    /// Every corrective session's samples for one tick of a clock at `hz`. Lockstep: traced
    /// here for the sessions with a camera awaiting its answer (the round's budget is spent
    /// either way), each message carrying that camera's frame and sent waiting for room. Threaded: drained from the session's workers
    /// and sent when there is room; a session without room gets no budget this tick (it is
    /// not carried over) and keeps its traced samples for the next.
    pub(super) fn corrections(&mut self, hz: u32, lockstep: bool) {
        let Some(c) = self.corrections.clone() else {
            return;
        };
        let drain = Duration::from_secs_f64(DRAIN_SHARE / f64::from(hz.max(1)));
        for s in self.sessions.values_mut() {
            let messages = match &mut s.corrective {
                None => continue,
                Some(SessionCorrections::Lockstep(state)) => {
                    let budget = state.next_budget(hz);
                    if s.pending.is_none() {
                        continue;
                    }
                    state
                        .trace(&c.engine, budget, s.pending)
                        .into_iter()
                        .collect()
                }
                Some(SessionCorrections::Threaded(state)) => {
                    if s.out.capacity() == 0 {
                        state.ticks += 1;
                        continue;
                    }
                    state.frame(hz, drain)
                }
            };
            for msg in messages {
                let samples = msg.samples.len() as u64;
                let Ok(bytes) = encode_frame(&Message::Samples(msg)) else {
                    continue;
                };
                let size = bytes.len() as u64;
                let sent = if lockstep {
                    self.rt.block_on(s.out.send(bytes)).is_ok()
                } else {
                    s.out.try_send(bytes).is_ok()
                };
                if sent {
                    s.stats.samples += samples;
                    s.stats.bytes += size;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_split_at_camera_age_changes() {
        let s = |object| SampleMsg {
            object,
            level: 1,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            ndotv: 1.0,
            color: [0.5; 3],
        };
        let m = messages_by_age(vec![(3, s(1)), (3, s(2)), (4, s(3)), (3, s(4))]);
        let shape: Vec<(u32, Vec<u32>)> = m
            .iter()
            .map(|m| (m.camera_age, m.samples.iter().map(|s| s.object).collect()))
            .collect();
        assert_eq!(shape, [(3, vec![1, 2]), (4, vec![3]), (3, vec![4])]);
        assert!(messages_by_age(Vec::new()).is_empty());
    }
}
