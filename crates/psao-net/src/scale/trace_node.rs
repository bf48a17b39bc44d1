//! A trace node (`psao trace-node`): steps the whole scene's selection each server frame,
//! traces the points of the partitions it holds, and publishes their new records as one
//! batch per held partition into the records stream, and every `--snapshot-every` frames
//! the snapshot chunks of its partitions that changed. Partitions are held by leases in a
//! key-value bucket; a node adopts partitions whose lease expired (docs/SCALE-OUT.md). A
//! node starts from the published state ([`super::join`]), not from zero.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use async_nats::jetstream::kv;
use futures_util::{FutureExt, StreamExt};
use psao_server::{Partition, PointRecord, PointState, Server, View};
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, Notify};

use super::join::{join, Joiner};
use super::lost::{lost, Sent};
use super::parts::{split, Reassembled, Reassembler, NATS_HEADROOM};
use super::wire::{Batch, PayloadError, Snapshot, SnapshotMark, ViewSet, CHUNK_POINTS};
use super::{
    connect, max_payload, records_stream, snapshot_stream, Names, NatsAuth, ServerErrors,
    LEASE_CHECK, LEASE_TTL,
};
use crate::cpu_time::cpu_seconds;
use crate::NetError;

/// Messages buffered per subscription; more are dropped (and counted).
const INBOX: usize = 4096;
/// Frames whose scene time a node remembers.
const RECENT_FRAMES: usize = 4096;
/// How long a trace node keeps retrying to store a batch while the NATS server is away
/// (a restart) before it gives up with an error.
const OUTAGE: Duration = Duration::from_secs(60);
/// Pause between attempts to store a batch.
const RETRY: Duration = Duration::from_millis(200);
/// Longest wait for the NATS server's answer (a store's acknowledgement, a lease update):
/// well under [`LEASE_TTL`], so that a message published into a restart is sent again,
/// and the leases refreshed, before they expire.
const ACK_WAIT: Duration = Duration::from_secs(1);
/// Batch messages a node keeps to publish again should the NATS server lose them
/// ([`super::lost`]): a hard kill loses the messages of the last moments, far fewer.
const SENT_WINDOW: usize = 512;

/// Most edges whose views a trace node keeps (per frame in lockstep, latest when clocked);
/// views of further edge names are dropped, so forged names cannot grow the tables.
pub const MAX_EDGES: usize = 256;
/// Frames ahead of the node's own whose lockstep views are kept (edges send the views of
/// frame f + 1 only once they have f).
const MAX_VIEW_FRAMES_AHEAD: u64 = 64;

/// How a trace node runs.
#[derive(Clone, Debug)]
pub struct TraceNodeConfig {
    /// NATS server URL.
    pub nats: String,
    /// Credentials and TLS for it.
    pub auth: NatsAuth,
    /// Scene name (names the subjects, stream and bucket; see [`Names`]).
    pub scene: String,
    /// The partition this node starts with.
    pub partition: Partition,
    /// Server frames per second of scene time.
    pub hz: u32,
    /// Lockstep: step frame `f` once this many edges sent their views for it (their scene
    /// time is used). `None`: step on the shared clock with the latest views.
    pub lockstep_edges: Option<usize>,
    /// Stop after this many server frames.
    pub frames: Option<u64>,
    /// This node's name in the leases.
    pub node_id: String,
    /// Publish a snapshot of every held partition every this many frames (0: never).
    pub snapshot_every: u64,
}

/// A partition adopted from a node that stopped refreshing its lease.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Adoption {
    /// The partition.
    pub partition: u32,
    /// This node's server frame when it adopted it.
    pub frame: u64,
    /// Seconds from the last batch of the partition seen to the adoption.
    pub after_s: f64,
    /// Points restarted from their published AO.
    pub points: usize,
}

/// What a trace node did (`psao trace-node --json`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TraceNodeStats {
    /// Server frames stepped.
    pub frames: u64,
    /// Rays traced by this node.
    pub rays: u64,
    /// Mean wall time of a step, ms.
    pub mean_step_ms: f64,
    /// Mean wall time of the step's selection, tracing and accumulation, ms.
    pub mean_trace_ms: f64,
    /// Rays per second of step time.
    pub rays_per_s: f64,
    /// CPU time of the process per server frame, ms.
    pub cpu_ms: f64,
    /// Records published, the bytes of their batches as published (compressed, in parts),
    /// and the bytes the batches would have cost uncompressed.
    pub records: u64,
    pub batch_bytes: u64,
    pub batch_raw_bytes: u64,
    /// Bytes of the largest batch uncompressed.
    pub largest_batch_raw_bytes: u64,
    /// Messages the batches took (more than one per batch when one would not fit the NATS
    /// server's `max_payload`).
    pub batch_messages: u64,
    /// Bytes of the snapshot chunks and marks published, and the chunks published (only
    /// those whose points changed since their previous message).
    pub snapshot_bytes: u64,
    pub snapshot_chunks: u64,
    /// Bytes the snapshot rounds would have cost had every chunk been published.
    pub snapshot_full_bytes: u64,
    /// Bytes of the chunks published although their records had not changed (only their
    /// points' sample counts).
    pub snapshot_samples_only_bytes: u64,
    /// The published state the node started from.
    pub restored: Restored,
    /// Messages that did not parse (or named points that do not exist): dropped.
    pub malformed: u64,
    /// Messages dropped because the inbox was full.
    pub dropped: u64,
    /// Batches published again because the NATS server lost them.
    pub republished: u64,
    /// Partitions held at the end.
    pub partitions: Vec<u32>,
    /// Partitions adopted from dead nodes.
    pub adopted: Vec<Adoption>,
}

/// The published state a trace node started from ([`join`]).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Restored {
    /// The server frame the node started at (0: a new session), and the frame of the
    /// snapshots it started from (0: none).
    pub frame: u64,
    pub snapshot_frame: u64,
    /// Published records restored (every partition's points), and points whose sample
    /// counts came from the snapshots.
    pub records: u64,
    pub samples: u64,
    /// Bytes of snapshot messages and of record batches read to start.
    pub snapshot_bytes: u64,
    pub batch_bytes: u64,
}

/// Counters the subscription tasks share with the node.
#[derive(Default)]
struct Counters {
    malformed: AtomicU64,
    dropped: AtomicU64,
}

/// The leases this node holds: partition → revision of its key.
struct Leases {
    kv: kv::Store,
    node: String,
    held: BTreeMap<u32, u64>,
    count: u32,
}

fn lease_key(k: u32) -> String {
    format!("p{k}")
}

impl Leases {
    /// Take the lease of partition `k` when nobody holds it.
    async fn try_take(&mut self, k: u32) -> bool {
        match self.kv.create(lease_key(k), self.node.clone().into()).await {
            Ok(revision) => {
                self.held.insert(k, revision);
                true
            }
            Err(_) => false,
        }
    }

    /// Refresh every held lease. A refresh that fails is settled by the key's holder: this
    /// node (an answer lost in a NATS restart: its revision is taken), nobody (the key
    /// expired while the NATS server was away: it is created again) or another node (an
    /// error: that node traces the partition now). Returns false when the NATS server
    /// could not be asked (try again later).
    async fn refresh(&mut self) -> Result<bool, NetError> {
        let mut reached = true;
        for (k, revision) in self.held.iter_mut() {
            let key = lease_key(*k);
            let mine = self.node.as_bytes();
            if let Ok(r) = self.kv.update(&key, mine.to_vec().into(), *revision).await {
                *revision = r;
                continue;
            }
            match self.kv.entry(key.clone()).await {
                Err(_) => reached = false,
                Ok(Some(e)) if e.operation == kv::Operation::Put && e.value != mine => {
                    return Err(NetError::Nats(format!(
                        "lost the lease of partition {k}: node {} traces it now",
                        String::from_utf8_lossy(&e.value)
                    )))
                }
                Ok(Some(e)) if e.operation == kv::Operation::Put => *revision = e.revision,
                _ => match self.kv.create(&key, mine.to_vec().into()).await {
                    Ok(r) => {
                        tracing::info!("lease of partition {k} taken again");
                        *revision = r;
                    }
                    // Taken in between (the next refresh says by whom) or not delivered.
                    Err(_) => reached = false,
                },
            }
        }
        Ok(reached)
    }

    /// Take every partition of `candidates` whose lease is free; returns them.
    async fn adopt_free(&mut self, candidates: impl Iterator<Item = u32>) -> Vec<u32> {
        let mut adopted = Vec::new();
        for k in candidates {
            if k < self.count && !self.held.contains_key(&k) && self.try_take(k).await {
                adopted.push(k);
            }
        }
        adopted
    }
}

/// The leases bucket of `names`, created when missing. The bucket's stream is made here
/// with the key-value conventions (`KV_<bucket>` over `$KV.<bucket>.>`, one message per
/// key, roll-ups allowed) because `create_key_value` first queries the account, whose
/// answer from Debian's nats-server 2.9 async-nats 0.42 does not parse.
async fn leases_bucket(
    js: &async_nats::jetstream::Context,
    names: &Names,
) -> Result<kv::Store, NetError> {
    use async_nats::jetstream::stream;
    let bucket = names.leases();
    js.get_or_create_stream(stream::Config {
        name: format!("KV_{bucket}"),
        subjects: vec![format!("$KV.{bucket}.>")],
        max_messages_per_subject: 1,
        max_age: LEASE_TTL,
        allow_rollup: true,
        deny_delete: true,
        allow_direct: true,
        discard: stream::DiscardPolicy::New,
        // On disk, so that leases survive a restart of the NATS server.
        storage: stream::StorageType::File,
        ..Default::default()
    })
    .await
    .map_err(|e| NetError::Nats(format!("cannot open bucket {bucket}: {e}")))?;
    js.get_key_value(bucket.clone())
        .await
        .map_err(|e| NetError::Nats(format!("cannot open bucket {bucket}: {e}")))
}

/// The shared clock's epoch (Unix ms) kept in the bucket: the first node's start. The
/// epoch key is refreshed by whoever holds partition 0, so it outlives the lease TTL.
async fn shared_epoch(store: &kv::Store) -> Result<u64, NetError> {
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64);
    let _ = store.create("epoch", now.to_string().into()).await;
    let value = store
        .get("epoch")
        .await
        .map_err(|e| NetError::Nats(format!("cannot read the clock's epoch: {e}")))?;
    Ok(value
        .and_then(|v| std::str::from_utf8(&v).ok()?.parse().ok())
        .unwrap_or(now))
}

/// What the node's loop keeps between frames.
struct Node {
    server: Server,
    config: TraceNodeConfig,
    rt: tokio::runtime::Runtime,
    client: async_nats::Client,
    js: async_nats::jetstream::Context,
    /// The NATS server's latest error (a refused publish).
    errors: ServerErrors,
    names: Names,
    leases: Leases,
    views: mpsc::Receiver<(String, ViewSet)>,
    /// Every partition's batches, with the time each arrived.
    batches: mpsc::Receiver<(Instant, Batch)>,
    counters: Arc<Counters>,
    /// Lockstep: view sets by frame and edge. Clocked: the latest of each edge.
    pending_views: BTreeMap<u64, BTreeMap<String, Vec<View>>>,
    latest_views: BTreeMap<String, (u64, Vec<View>)>,
    /// Lockstep: the scene time of frames whose views are pending.
    pending_seconds: BTreeMap<u64, f64>,
    /// Scene time of this node's recent frames (for the batches of adopted partitions).
    recent_seconds: BTreeMap<u64, f64>,
    /// Per partition: the last frame a batch was seen for it, and when.
    last_seen: BTreeMap<u32, (u64, Instant)>,
    /// Per partition: the last frame whose records are in this node's published state.
    noted: BTreeMap<u32, u64>,
    /// The points of every snapshot chunk this node published last, per (partition, chunk).
    published_chunks: BTreeMap<(u32, u32), Vec<PointState>>,
    /// The last batch messages stored, in the order they were stored.
    sent: VecDeque<Sent>,
    /// Notified at every reconnection to the NATS server.
    connected: Arc<Notify>,
    /// Whether the stream is still to be checked for lost batches (after a reconnection).
    check_lost: bool,
    last_upkeep: Instant,
    /// No partition is adopted before this: after the NATS server was away, the other
    /// nodes get a lease's lifetime to refresh theirs.
    adopt_after: Instant,
    stats: TraceNodeStats,
}

/// Runs a trace node until `stop` is set (also by Ctrl-C) or its frames are done.
pub fn run(
    server: Server,
    config: TraceNodeConfig,
    stop: Arc<AtomicBool>,
) -> Result<TraceNodeStats, NetError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(NetError::io("cannot start the async runtime"))?;
    let stop_signal = stop.clone();
    rt.spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            tracing::info!("Ctrl-C: stopping");
            stop_signal.store(true, Ordering::SeqCst);
        }
    });
    let names = Names::new(&config.scene);
    let connected = Arc::new(Notify::new());
    let errors = ServerErrors::default();
    let client = rt.block_on(connect(
        &config.nats,
        &config.auth,
        connected.clone(),
        errors.clone(),
    ))?;
    max_payload(&client)?;
    let mut js = async_nats::jetstream::new(client.clone());
    js.set_timeout(ACK_WAIT);
    rt.block_on(records_stream(&js, &names))?;
    rt.block_on(snapshot_stream(&js, &names))?;
    let store = rt.block_on(leases_bucket(&js, &names))?;
    let counters = Arc::new(Counters::default());
    let views = rt.block_on(subscribe(
        &client,
        names.views_wildcard(),
        counters.clone(),
        |subject, payload| {
            let edge = subject.rsplit('.').next().unwrap_or("").to_string();
            ViewSet::decode(payload).map(|v| Some((edge, v)))
        },
    ))?;
    let mut parts = Reassembler::default();
    let subject_names = names.clone();
    let batches = rt.block_on(subscribe(
        &client,
        names.records_wildcard(),
        counters.clone(),
        move |subject, payload| match parts
            .add_payload(subject_names.records_partition(subject), payload)
        {
            Reassembled::Complete(b) => Ok(Some((Instant::now(), b))),
            Reassembled::Incomplete | Reassembled::Duplicate => Ok(None),
            Reassembled::Malformed(e) => Err(e),
        },
    ))?;
    let partition = config.partition;
    let mut leases = Leases {
        kv: store,
        node: config.node_id.clone(),
        held: BTreeMap::new(),
        count: partition.count,
    };
    let mut waited = false;
    while !rt.block_on(leases.try_take(partition.index)) {
        if !waited {
            tracing::info!("partition {partition} is leased by another node: waiting");
            waited = true;
        }
        if stop.load(Ordering::SeqCst) {
            return Ok(TraceNodeStats::default());
        }
        std::thread::sleep(LEASE_CHECK);
    }
    // Start from the published state: every partition's records, and the sample counts
    // of the snapshots.
    let mut server = server;
    let joined = rt.block_on(join(
        &js,
        &names,
        &server,
        Joiner::TraceNode,
        partition.count,
    ))?;
    let (last, seconds) = joined.fold.last_frame();
    let latest = joined.fold.latest_frames();
    let own = latest.get(&partition.index).map(|&(f, _)| f);
    let frame = start_frame(last, own, config.lockstep_edges.is_some());
    let records = joined.fold.records();
    let mut restored = Restored {
        frame,
        snapshot_frame: joined.fold.snapshot_frame(),
        records: records.len() as u64,
        snapshot_bytes: joined.counts.snapshot_bytes,
        batch_bytes: joined.counts.batch_bytes,
        ..Restored::default()
    };
    if last > 0 {
        // In the pose of the latest frame: a lockstep node one frame behind steps that one.
        server.restore_replica(frame, seconds as f32, &records)?;
        restored.samples = server.restore_samples(joined.fold.snapshot_points())? as u64;
        tracing::info!(
            "starting at frame {frame} from the published state ({} records, snapshots of frame {})",
            records.len(),
            restored.snapshot_frame
        );
    }
    let now = Instant::now();
    let last_seen = latest.iter().map(|(&k, &(f, _))| (k, (f, now))).collect();
    let noted = latest.iter().map(|(&k, &(f, _))| (k, f)).collect();
    let recent_seconds = latest.values().copied().collect();
    let owners = server.owners(partition.count);
    server.hold_partitions(owners, &[partition.index]);
    tracing::info!("tracing partition {partition} as {}", config.node_id);
    let mut node = Node {
        server,
        config,
        rt,
        client,
        js,
        errors,
        names,
        leases,
        views,
        batches,
        counters,
        pending_views: BTreeMap::new(),
        latest_views: BTreeMap::new(),
        pending_seconds: BTreeMap::new(),
        recent_seconds,
        last_seen,
        noted,
        published_chunks: BTreeMap::new(),
        sent: VecDeque::new(),
        connected,
        check_lost: false,
        last_upkeep: Instant::now(),
        adopt_after: Instant::now(),
        stats: TraceNodeStats {
            restored,
            ..TraceNodeStats::default()
        },
    };
    // Clocked, the frames this partition missed while it had no node are published empty
    // (the edges wait for them).
    if let Some(own) = own.filter(|&own| own < frame) {
        node.fill(partition.index, own, frame)?;
    }
    // Adopt at once the partitions nobody holds (their nodes died before this one started).
    node.upkeep(true)?;
    node.run(&stop)
}

/// The frame a node starts after, given the latest frame any partition published (`last`)
/// and its own partition's latest (`own`, `None` when it never published). Lockstep edges
/// wait for the node's partition before they send the views of a later frame, so the others
/// are at most one frame ahead: the node steps on from its own frame. Clocked, it steps
/// the clock's frames from the latest on, and the frames its partition missed are published
/// empty (or, when it never published, edges take it to have started there).
fn start_frame(last: u64, own: Option<u64>, lockstep: bool) -> u64 {
    if lockstep {
        own.unwrap_or(0).min(last)
    } else {
        last
    }
}

/// Subscribes to `subject`, forwarding what `parse` makes of the messages (nothing yet: a
/// part of a batch; counting what it refuses).
async fn subscribe<T: Send + 'static>(
    client: &async_nats::Client,
    subject: String,
    counters: Arc<Counters>,
    mut parse: impl FnMut(&str, &[u8]) -> Result<Option<T>, PayloadError> + Send + 'static,
) -> Result<mpsc::Receiver<T>, NetError> {
    let mut sub = client
        .subscribe(subject.clone())
        .await
        .map_err(|e| NetError::Nats(format!("cannot subscribe to {subject}: {e}")))?;
    let (tx, rx) = mpsc::channel(INBOX);
    tokio::spawn(async move {
        while let Some(m) = sub.next().await {
            match parse(m.subject.as_str(), &m.payload) {
                Ok(None) => {}
                Ok(Some(item)) => {
                    if tx.try_send(item).is_err() {
                        if tx.is_closed() {
                            return;
                        }
                        counters.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(e) => {
                    tracing::debug!("malformed message on {}: {e}", m.subject);
                    counters.malformed.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    });
    Ok(rx)
}

impl Node {
    fn run(&mut self, stop: &AtomicBool) -> Result<TraceNodeStats, NetError> {
        let cpu_start = cpu_seconds();
        let (mut step_ms, mut trace_ms) = (0.0, 0.0);
        let clock = match self.config.lockstep_edges {
            Some(_) => None,
            None => Some(self.clock_origin()?),
        };
        loop {
            if stop.load(Ordering::SeqCst)
                || self.config.frames.is_some_and(|n| self.server.frame() >= n)
            {
                break;
            }
            let frame = self.server.frame() + 1;
            let Some((views, seconds)) = self.views_for(frame, clock, stop)? else {
                break;
            };
            self.note_batches();
            let step = self.server.step_at(&views, seconds as f32)?;
            step_ms += step.ms;
            trace_ms += step.trace_ms;
            self.stats.rays += step.rays;
            self.recent_seconds.insert(frame, seconds);
            if self.recent_seconds.len() > RECENT_FRAMES {
                self.recent_seconds.pop_first();
            }
            let records = self.server.take_records();
            self.publish(frame, seconds, records)?;
            // A node done with its frames adopts nothing (the others stop there too).
            if self.config.frames != Some(frame) {
                self.upkeep(false)?;
            }
        }
        let frames = self.server.frame();
        let n = (frames.max(1)) as f64;
        self.stats.frames = frames;
        self.stats.mean_step_ms = step_ms / n;
        self.stats.mean_trace_ms = trace_ms / n;
        self.stats.rays_per_s = self.stats.rays as f64 / (step_ms / 1e3).max(1e-9);
        if let (Some(a), Some(b)) = (cpu_start, cpu_seconds()) {
            self.stats.cpu_ms = (b - a) * 1e3 / n;
        }
        self.stats.malformed = self.counters.malformed.load(Ordering::Relaxed);
        self.stats.dropped = self.counters.dropped.load(Ordering::Relaxed);
        self.stats.partitions = self.server.held_partitions();
        // Let the leases expire for the other nodes at once.
        let held: Vec<u32> = self.leases.held.keys().copied().collect();
        for k in held {
            let _ = self.rt.block_on(self.leases.kv.purge(lease_key(k)));
        }
        Ok(std::mem::take(&mut self.stats))
    }

    /// The instant of frame 0 on the shared clock.
    fn clock_origin(&mut self) -> Result<Instant, NetError> {
        let epoch_ms = self.rt.block_on(shared_epoch(&self.leases.kv))?;
        let now_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let behind = Duration::from_millis(now_ms.saturating_sub(epoch_ms));
        Ok(Instant::now()
            .checked_sub(behind)
            .unwrap_or_else(Instant::now))
    }

    /// The views and scene time of `frame` (lockstep: once every edge sent them; clocked:
    /// at the frame's time on the shared clock). `None` when stopped while waiting.
    fn views_for(
        &mut self,
        frame: u64,
        clock: Option<Instant>,
        stop: &AtomicBool,
    ) -> Result<Option<(Vec<View>, f64)>, NetError> {
        let hz = f64::from(self.config.hz.max(1));
        loop {
            if stop.load(Ordering::SeqCst) {
                return Ok(None);
            }
            while let Ok((edge, set)) = self.views.try_recv() {
                match clock {
                    // Lockstep edges are at most a frame ahead: views further ahead, or from
                    // more edges than a session has, are not kept (bounded tables).
                    None if set.frame >= frame && set.frame <= frame + MAX_VIEW_FRAMES_AHEAD => {
                        let edges = self.pending_views.entry(set.frame).or_default();
                        if edges.len() >= MAX_EDGES && !edges.contains_key(&edge) {
                            continue;
                        }
                        edges.insert(edge, set.views);
                        if set.frame == frame {
                            self.pending_seconds.insert(frame, set.seconds);
                        }
                    }
                    None => {}
                    Some(_) => {
                        let full = self.latest_views.len() >= MAX_EDGES;
                        if !full || self.latest_views.contains_key(&edge) {
                            self.latest_views.insert(edge, (set.frame, set.views));
                        }
                    }
                }
            }
            match clock {
                None => {
                    let want = self.config.lockstep_edges.unwrap_or(1);
                    if self
                        .pending_views
                        .get(&frame)
                        .is_some_and(|e| e.len() >= want)
                    {
                        let edges = self.pending_views.remove(&frame).unwrap_or_default();
                        let seconds = self.pending_seconds.remove(&frame).unwrap_or(0.0);
                        return Ok(Some((union(edges.into_values()), seconds)));
                    }
                }
                Some(origin) => {
                    let due = origin + Duration::from_secs_f64(frame as f64 / hz);
                    if Instant::now() >= due {
                        // Views of edges silent for 2 s of frames are forgotten.
                        let horizon = frame.saturating_sub(2 * self.config.hz as u64);
                        self.latest_views.retain(|_, (f, _)| *f >= horizon);
                        let views = union(self.latest_views.values().map(|(_, v)| v.clone()));
                        return Ok(Some((views, frame as f64 / hz)));
                    }
                }
            }
            self.upkeep(false)?;
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Take in the other partitions' batches: their records become this node's published
    /// state (to adopt from), and their frames are noted. Batches of another partition
    /// count than this node's, or of a partition past it, are dropped.
    fn note_batches(&mut self) {
        while let Ok((arrived, batch)) = self.batches.try_recv() {
            let count = self.leases.count;
            if batch.partitions != count || batch.partition >= count {
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let seen = self
                .last_seen
                .entry(batch.partition)
                .or_insert((0, arrived));
            if batch.frame >= seen.0 {
                *seen = (batch.frame, arrived);
            }
            if self.leases.held.contains_key(&batch.partition) {
                continue;
            }
            // Frames this node has the records of already (read when it started).
            let noted = self.noted.entry(batch.partition).or_insert(0);
            if batch.frame <= *noted {
                continue;
            }
            *noted = batch.frame;
            if self.server.note_records(&batch.records).is_err() {
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Publish this frame's records, one batch per held partition, and wait for the stream
    /// to store them; on snapshot frames, then publish every held partition's snapshot.
    fn publish(
        &mut self,
        frame: u64,
        seconds: f64,
        records: Vec<PointRecord>,
    ) -> Result<(), NetError> {
        let owners = self
            .server
            .partition_owners()
            .expect("a trace node holds partitions")
            .clone();
        let mut per: BTreeMap<u32, Vec<PointRecord>> =
            self.leases.held.keys().map(|&k| (k, Vec::new())).collect();
        for r in records {
            per.entry(owners.owner(r.instance, r.index))
                .or_default()
                .push(r);
        }
        let batches: Vec<Batch> = per
            .into_iter()
            .map(|(partition, records)| Batch {
                partition,
                partitions: owners.count(),
                frame,
                seconds,
                records,
            })
            .collect();
        let sequences = self.send(&batches)?;
        let every = self.config.snapshot_every;
        if every > 0 && frame.is_multiple_of(every) {
            for (b, sequence) in batches.iter().zip(sequences) {
                self.snapshot(b.partition, frame, seconds, sequence)?;
            }
        }
        Ok(())
    }

    /// Publish the snapshot of partition `k` at `frame`, whose batch has stream sequence
    /// number `sequence`: the chunks whose points changed (records or sample counts) since
    /// this node last published them (all of them the first time), then the partition's
    /// mark, once they are stored.
    fn snapshot(
        &mut self,
        k: u32,
        frame: u64,
        seconds: f64,
        sequence: u64,
    ) -> Result<(), NetError> {
        let chunks = self.server.partition_records(k, CHUNK_POINTS);
        let partitions = self.server.partition_owners().map_or(1, |o| o.count());
        let count = chunks.len() as u32;
        let mut changed = Vec::new();
        let mut messages: Vec<(String, String, bytes::Bytes)> = Vec::new();
        for (c, points) in chunks.into_iter().enumerate() {
            self.stats.snapshot_full_bytes += Snapshot::encoded_len(points.len()) as u64;
            let key = (k, c as u32);
            let last = self.published_chunks.get(&key);
            if last == Some(&points) {
                continue;
            }
            let same_records = last.is_some_and(|l| {
                l.len() == points.len() && l.iter().zip(&points).all(|(a, b)| a.record == b.record)
            });
            if same_records {
                self.stats.snapshot_samples_only_bytes +=
                    Snapshot::encoded_len(points.len()) as u64;
            }
            let chunk = Snapshot {
                partition: k,
                partitions,
                chunk: c as u32,
                chunks: count,
                frame,
                seconds,
                sequence,
                points,
            };
            let id = format!("{}.snap.{k}.{c}.{frame}", self.config.node_id);
            messages.push((self.names.snapshot(k, c as u32), id, chunk.encode().into()));
            changed.push((key, chunk.points));
        }
        self.store_retrying(&messages)?;
        let mark = SnapshotMark {
            partition: k,
            partitions,
            chunks: count,
            frame,
            seconds,
            sequence,
        };
        let id = format!("{}.mark.{k}.{frame}", self.config.node_id);
        let mark = [(self.names.snapshot_mark(k), id, mark.encode().into())];
        // Only after the chunks are stored: a mark vouches for them.
        self.store_retrying(&mark)?;
        self.stats.snapshot_chunks += messages.len() as u64;
        self.stats.snapshot_bytes += messages
            .iter()
            .chain(&mark)
            .map(|m| m.2.len() as u64)
            .sum::<u64>();
        self.published_chunks.extend(changed);
        Ok(())
    }

    /// Publish `batches` into the records stream ([`Node::store_retrying`]), each
    /// compressed and in as many parts as the NATS server's `max_payload` needs
    /// ([`split`]); returns the stream sequence number of each one's last part.
    fn send(&mut self, batches: &[Batch]) -> Result<Vec<u64>, NetError> {
        let max_payload = max_payload(&self.client)?;
        let mut messages: Vec<(String, String, bytes::Bytes)> = Vec::new();
        let mut ends = Vec::with_capacity(batches.len());
        for b in batches {
            let split = split(b, max_payload).map_err(|e| {
                NetError::Nats(format!(
                    "cannot publish partition {}'s batch of frame {}: {e}",
                    b.partition, b.frame
                ))
            })?;
            self.stats.batch_raw_bytes += split.raw_bytes as u64;
            self.stats.largest_batch_raw_bytes =
                (self.stats.largest_batch_raw_bytes).max(split.raw_bytes as u64);
            for (k, payload) in split.parts.into_iter().enumerate() {
                let id = format!("{}.{}.{}.{k}", self.config.node_id, b.partition, b.frame);
                messages.push((self.names.records(b.partition), id, payload.into()));
            }
            ends.push(messages.len() - 1);
        }
        let sequences = self.store_retrying(&messages)?;
        self.stats.batch_bytes += messages.iter().map(|m| m.2.len() as u64).sum::<u64>();
        self.stats.batch_messages += messages.len() as u64;
        self.stats.records += batches.iter().map(|b| b.records.len() as u64).sum::<u64>();
        let ends = ends.into_iter().map(|i| sequences[i]).collect();
        self.remember(messages, &sequences);
        Ok(ends)
    }

    /// Keep the last [`SENT_WINDOW`] batch messages stored, with their sequence numbers.
    fn remember(&mut self, messages: Vec<(String, String, bytes::Bytes)>, sequences: &[u64]) {
        for ((subject, id, payload), &sequence) in messages.into_iter().zip(sequences) {
            if self.sent.len() == SENT_WINDOW {
                self.sent.pop_front();
            }
            self.sent.push_back(Sent {
                sequence,
                subject,
                id,
                payload,
            });
        }
    }

    /// After a reconnection: publish again the batches the NATS server lost (it may have
    /// been killed hard), and every snapshot chunk at the next round (lost chunks would
    /// otherwise be vouched for by later marks). Returns false when the NATS server could
    /// not be asked (try again later).
    fn republish_lost(&mut self) -> Result<bool, NetError> {
        let found = self.rt.block_on(async {
            let stream = records_stream(&self.js, &self.names).await?;
            lost(&stream, &self.sent).await
        });
        let lost = match found {
            Ok(lost) => lost,
            Err(e) => {
                tracing::warn!("{e}: checking again later");
                return Ok(false);
            }
        };
        self.published_chunks.clear();
        if lost.is_empty() {
            return Ok(true);
        }
        if lost[0] == 0 && self.sent.len() == SENT_WINDOW {
            tracing::error!(
                "the NATS server lost the oldest batch this node remembers: edges that \
                 missed older ones stall"
            );
        }
        tracing::warn!(
            "the NATS server lost {} batches: publishing them again",
            lost.len()
        );
        let mut messages = Vec::with_capacity(lost.len());
        let mut kept = VecDeque::with_capacity(self.sent.len());
        for (i, s) in std::mem::take(&mut self.sent).into_iter().enumerate() {
            if lost.binary_search(&i).is_ok() {
                messages.push((s.subject, s.id, s.payload));
            } else {
                kept.push_back(s);
            }
        }
        self.sent = kept;
        let sequences = self.store_retrying(&messages)?;
        self.remember(messages, &sequences);
        self.stats.republished += lost.len() as u64;
        Ok(true)
    }

    /// Publish `messages` (subject, message id, payload) and wait for the streams to store
    /// them, retrying for up to [`OUTAGE`] while the NATS server is away; the message ids
    /// make a stream store a retried message once. A publish the server refuses (too
    /// large, not permitted) is an error at once. Returns their stream sequence numbers.
    fn store_retrying(
        &mut self,
        messages: &[(String, String, bytes::Bytes)],
    ) -> Result<Vec<u64>, NetError> {
        let max = max_payload(&self.client)?;
        if let Some(m) = messages.iter().find(|m| m.2.len() + NATS_HEADROOM > max) {
            return Err(NetError::Nats(format!(
                "a message of {} bytes to {} does not fit the NATS server's max_payload of {max} bytes",
                m.2.len(),
                m.0
            )));
        }
        let deadline = Instant::now() + OUTAGE;
        loop {
            let attempt = Instant::now();
            match self.rt.block_on(store(&self.js, messages)) {
                Ok(sequences) => return Ok(sequences),
                Err(e) => {
                    if let Some(reason) = self.errors.refusal_since(attempt) {
                        let subjects: BTreeSet<&str> =
                            messages.iter().map(|m| m.0.as_str()).collect();
                        return Err(NetError::Nats(format!(
                            "the NATS server refused a message to {}: {reason} ({e})",
                            subjects.into_iter().collect::<Vec<_>>().join(", ")
                        )));
                    }
                    if Instant::now() >= deadline {
                        return Err(e);
                    }
                    tracing::warn!("{e}: retrying");
                    // The other nodes may miss refreshing their leases meanwhile.
                    self.adopt_after = Instant::now() + LEASE_TTL;
                    // This node's may expire while the server answers leases but not
                    // stores.
                    self.rt.block_on(self.leases.refresh())?;
                    std::thread::sleep(RETRY);
                }
            }
        }
    }

    /// Every [`LEASE_CHECK`] (or now with `force`): refresh the held leases, and adopt free
    /// partitions, restarting their points from the published state and publishing empty
    /// batches for the frames their dead node did not.
    fn upkeep(&mut self, force: bool) -> Result<(), NetError> {
        if !force && self.last_upkeep.elapsed() < LEASE_CHECK {
            return Ok(());
        }
        self.last_upkeep = Instant::now();
        if !self.rt.block_on(self.leases.refresh())? {
            tracing::warn!("cannot refresh the leases: is the NATS server away?");
            self.adopt_after = Instant::now() + LEASE_TTL;
            return Ok(());
        }
        if self.connected.notified().now_or_never().is_some() {
            self.check_lost = true;
        }
        if self.check_lost && self.republish_lost()? {
            self.check_lost = false;
        }
        if Instant::now() < self.adopt_after {
            return Ok(());
        }
        if self.leases.held.contains_key(&0) {
            // Keep the clock's epoch alive past the bucket's TTL.
            if let Ok(Some(epoch)) = self.rt.block_on(self.leases.kv.get("epoch")) {
                let _ = self.rt.block_on(self.leases.kv.put("epoch", epoch));
            }
        }
        // Only partitions that published and then went quiet are adopted (a node still
        // starting up has not published yet).
        self.note_batches();
        let seen: Vec<u32> = self.last_seen.keys().copied().collect();
        let adopted = self.rt.block_on(self.leases.adopt_free(seen.into_iter()));
        if adopted.is_empty() {
            return Ok(());
        }
        let frame = self.server.frame();
        for k in adopted {
            let (last, at) = self
                .last_seen
                .get(&k)
                .copied()
                .unwrap_or((0, Instant::now()));
            let points = self.server.adopt_partition(k);
            tracing::warn!(
                "adopted partition {k} at frame {frame} ({points} points, {:.2} s after its last batch)",
                at.elapsed().as_secs_f64()
            );
            self.stats.adopted.push(Adoption {
                partition: k,
                frame,
                after_s: at.elapsed().as_secs_f64(),
                points,
            });
            self.fill(k, last, frame)?;
        }
        Ok(())
    }

    /// Publish empty batches of partition `k` for the frames after `last` up to `frame`.
    fn fill(&mut self, k: u32, last: u64, frame: u64) -> Result<(), NetError> {
        let partitions = self.server.partition_owners().map_or(1, |o| o.count());
        let fill: Vec<Batch> = (last + 1..=frame)
            .map(|f| Batch {
                partition: k,
                partitions,
                frame: f,
                seconds: self
                    .recent_seconds
                    .get(&f)
                    .copied()
                    .unwrap_or(f as f64 / f64::from(self.config.hz.max(1))),
                records: Vec::new(),
            })
            .collect();
        self.send(&fill)?;
        Ok(())
    }
}

/// Publish `messages` (subject, message id, payload) and wait for the streams to store
/// them; returns their stream sequence numbers.
async fn store(
    js: &async_nats::jetstream::Context,
    messages: &[(String, String, bytes::Bytes)],
) -> Result<Vec<u64>, NetError> {
    use async_nats::jetstream::context::Publish;
    let mut acks = Vec::with_capacity(messages.len());
    for (subject, id, payload) in messages {
        let message = Publish::build().payload(payload.clone()).message_id(id);
        let ack = js
            .send_publish(subject.clone(), message)
            .await
            .map_err(|e| NetError::Nats(format!("cannot publish to {subject}: {e}")))?;
        acks.push(ack);
    }
    let mut sequences = Vec::with_capacity(acks.len());
    for ack in acks {
        let ack = ack
            .await
            .map_err(|e| NetError::Nats(format!("message not stored: {e}")))?;
        sequences.push(ack.sequence);
    }
    Ok(sequences)
}

/// The distinct views of several edges, in the order given.
fn union(sets: impl Iterator<Item = Vec<View>>) -> Vec<View> {
    let mut out: Vec<View> = Vec::new();
    for v in sets.flatten() {
        if !out.contains(&v) {
            out.push(v);
        }
    }
    out
}
