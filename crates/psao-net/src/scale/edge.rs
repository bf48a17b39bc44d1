//! An edge (`psao edge`): joins from the latest snapshot chunks and the batches after them
//! ([`super::join`]; from the first frame when there is no snapshot), then reads every
//! partition's record batches that follow from the records stream, rebuilds the whole
//! published state in a replica [`Server`] ([`Server::restore_replica`],
//! [`Server::step_replica`]), and serves viewers with [`crate::serve`], publishing their
//! views for the trace nodes.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use async_nats::jetstream::consumer::pull;
use futures_util::StreamExt;
use psao_server::{PointRecord, Server, StepStats, View};
use serde::Serialize;
use tokio::sync::{mpsc, Notify};

use super::join::{join, last_sequence, records_from, Joiner};
use super::lost::Received;
use super::parts::{Reassembled, Reassembler};
use super::wire::{Batch, ViewSet};
use super::{connect, records_stream, Names, NatsAuth, ServerErrors, LEASE_TTL};
use crate::http::Health;
use crate::serve::Stepper;
use crate::NetError;

/// Batches buffered between the stream and the simulation.
const INBOX: usize = 1024;
/// The window of frames an edge takes batches for: `applied + 1 ..= applied +
/// MAX_PENDING_FRAMES` (9 minutes at 30 Hz; a partition that never publishes again, or a
/// publisher of far-future frames, cannot grow the pending frames past it, and the next
/// frames always fit).
pub const MAX_PENDING_FRAMES: usize = 1 << 14;
/// How long a lockstep edge waits for a frame's batches before publishing its views again.
const VIEWS_AGAIN: Duration = Duration::from_secs(1);

/// How an edge follows the trace nodes.
#[derive(Clone, Debug)]
pub struct EdgeConfig {
    /// NATS server URL.
    pub nats: String,
    /// Credentials and TLS for it.
    pub auth: NatsAuth,
    /// Scene name (names the subjects and stream; see [`Names`]).
    pub scene: String,
    /// This edge's name on its views subject.
    pub edge_id: String,
    /// The session's number of partitions (the trace nodes' `--partition k/N`): batches and
    /// snapshots that claim another count are dropped, whatever the bus says.
    pub partitions: u32,
    /// Lockstep: each server frame waits for every partition's batch of that frame.
    pub lockstep: bool,
    /// Longest wait for a frame's batches in lockstep.
    pub frame_timeout: Duration,
}

/// What an edge counted (shared with the stream task; read with [`EdgeCounters::snapshot`]).
#[derive(Default)]
pub struct EdgeCounters {
    batches: AtomicU64,
    bytes: AtomicU64,
    malformed: AtomicU64,
    duplicates: AtomicU64,
    sequence_gaps: AtomicU64,
    rewinds: AtomicU64,
    frames: AtomicU64,
    snapshot_bytes: AtomicU64,
    snapshot_frame: AtomicU64,
}

/// [`EdgeCounters`] at one moment (`psao edge --json` writes it beside the serve figures).
#[derive(Clone, Debug, Default, Serialize)]
pub struct EdgeStats {
    /// Record batch messages (parts, [`super::parts`]) received from the stream, and their
    /// bytes.
    pub batches: u64,
    pub batch_bytes: u64,
    /// Batches or messages that did not parse or named points that do not exist: dropped.
    pub malformed: u64,
    /// Second copies of a (frame, partition) batch, and batches of frames already applied:
    /// dropped.
    pub duplicates: u64,
    /// Stream sequence numbers that did not follow the previous one.
    pub sequence_gaps: u64,
    /// Times the NATS server was found to have lost records this edge had received (it
    /// read again after the last one still held).
    pub rewinds: u64,
    /// Server frames applied.
    pub frames: u64,
    /// Bytes of the snapshot chunks and marks read when the edge joined.
    pub snapshot_bytes: u64,
    /// The frame the edge started from (0: no snapshot, the stream from its start).
    pub snapshot_frame: u64,
}

impl EdgeCounters {
    /// The counts now.
    pub fn snapshot(&self) -> EdgeStats {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        EdgeStats {
            batches: get(&self.batches),
            batch_bytes: get(&self.bytes),
            malformed: get(&self.malformed),
            duplicates: get(&self.duplicates),
            sequence_gaps: get(&self.sequence_gaps),
            rewinds: get(&self.rewinds),
            frames: get(&self.frames),
            snapshot_bytes: get(&self.snapshot_bytes),
            snapshot_frame: get(&self.snapshot_frame),
        }
    }
}

/// One frame's batches as they arrive.
struct Parts {
    seconds: f64,
    partitions: BTreeSet<u32>,
    records: Vec<PointRecord>,
}

/// What [`Assembler::add`] did with a batch.
#[derive(Debug, PartialEq, Eq)]
pub enum Added {
    /// Kept.
    Kept,
    /// Dropped: its frame was applied already or its partition sent that frame before.
    Duplicate,
    /// Dropped: its partition count is not the edge's, or too many frames are incomplete.
    Refused,
}

/// Gathers the batches of each frame until every partition's is there.
pub struct Assembler {
    /// The session's partition count (the edge's own setting: a batch never sets it).
    partitions: u32,
    frames: BTreeMap<u64, Parts>,
    /// Per partition, the frame of the first batch taken in (0 for the partitions whose
    /// state the edge's join knew). A partition first heard of at frame g had no node
    /// before (a clocked node that started late steps on from the others' frame), so the
    /// frames before g do not wait for it.
    first: BTreeMap<u32, u64>,
}

impl Assembler {
    /// An assembler for a session of `partitions` partitions.
    pub fn new(partitions: u32) -> Self {
        Self {
            partitions,
            frames: BTreeMap::new(),
            first: BTreeMap::new(),
        }
    }

    /// Partition `k`'s state is known from the join: every later frame waits for it.
    pub fn known(&mut self, k: u32) {
        self.first.insert(k, 0);
    }

    /// Take in `batch`; frames up to `applied` are done.
    pub fn add(&mut self, batch: Batch, applied: u64) -> Added {
        if batch.partitions != self.partitions || batch.partition >= self.partitions {
            return Added::Refused;
        }
        if batch.frame <= applied {
            return Added::Duplicate;
        }
        if batch.frame > applied + MAX_PENDING_FRAMES as u64 {
            return Added::Refused;
        }
        // Frames the edge moved past without taking (a join) free their place.
        while self
            .frames
            .first_key_value()
            .is_some_and(|(&f, _)| f <= applied)
        {
            self.frames.pop_first();
        }
        if !self.frames.contains_key(&batch.frame) && self.frames.len() >= MAX_PENDING_FRAMES {
            return Added::Refused;
        }
        let parts = self.frames.entry(batch.frame).or_insert_with(|| Parts {
            seconds: batch.seconds,
            partitions: BTreeSet::new(),
            records: Vec::new(),
        });
        if !parts.partitions.insert(batch.partition) {
            return Added::Duplicate;
        }
        parts.records.extend(batch.records);
        self.first.entry(batch.partition).or_insert(batch.frame);
        Added::Kept
    }

    /// The partitions whose batch of `frame` is awaited.
    pub fn missing(&self, frame: u64) -> Vec<u32> {
        let parts = self.frames.get(&frame);
        (0..self.partitions)
            .filter(|k| !parts.is_some_and(|p| p.partitions.contains(k)))
            .filter(|k| self.first.get(k).is_none_or(|&g| frame >= g))
            .collect()
    }

    /// Whether every partition's batch of `frame` is in (or the partition started later).
    pub fn ready(&self, frame: u64) -> bool {
        self.frames.get(&frame).is_some_and(|parts| {
            let started_later = self
                .first
                .iter()
                .filter(|&(k, &g)| frame < g && !parts.partitions.contains(k))
                .count();
            parts.partitions.len() + started_later >= self.partitions as usize
        })
    }

    /// The scene time and records of `frame` once every partition's batch of it is in.
    pub fn take(&mut self, frame: u64) -> Option<(f64, Vec<PointRecord>)> {
        if !self.ready(frame) {
            return None;
        }
        let parts = self.frames.remove(&frame)?;
        Some((parts.seconds, parts.records))
    }
}

/// The [`Stepper`] of an edge.
pub struct EdgeStepper {
    config: EdgeConfig,
    rt: tokio::runtime::Runtime,
    client: async_nats::Client,
    names: Names,
    /// The stream's batches with their sequence numbers.
    batches: mpsc::Receiver<(u64, Batch)>,
    /// The stream's last sequence number when the edge connected, and the first one read.
    backlog: u64,
    first: u64,
    assembler: Assembler,
    counters: Arc<EdgeCounters>,
    /// The frame waited for, since when (monotonic and wall clock), and whether the stall
    /// was reported.
    waiting: Option<Waiting>,
    /// Where stalls are reported (`/health`).
    health: Option<Arc<Health>>,
}

/// The frame an edge waits for.
struct Waiting {
    frame: u64,
    since: Instant,
    since_unix_ms: u64,
    /// What the viewers are told once the stall is reported.
    reported: Option<String>,
}

/// A stall as `/health` reports it (key `stalled`).
#[derive(Clone, Debug, Serialize)]
pub struct Stall {
    /// The frame waited for.
    pub frame: u64,
    /// The partitions whose batches of it are missing.
    pub partitions: Vec<u32>,
    /// Since when (Unix ms), and for how long, seconds.
    pub since_unix_ms: u64,
    pub seconds: f64,
}

impl EdgeStepper {
    /// Connects; starts `server` (a fresh replica) from the latest snapshot chunks and the
    /// batches after them when there is a complete snapshot ([`join`]), else from the
    /// records stream's first message.
    pub fn connect(config: EdgeConfig, server: &mut Server) -> Result<Self, NetError> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .map_err(NetError::io("cannot start the async runtime"))?;
        let names = Names::new(&config.scene);
        let counters = Arc::new(EdgeCounters::default());
        let (client, batches, backlog, joined) = rt.block_on(async {
            let connected = Arc::new(Notify::new());
            let client = connect(
                &config.nats,
                &config.auth,
                connected.clone(),
                ServerErrors::default(),
            )
            .await?;
            let js = async_nats::jetstream::new(client.clone());
            let mut stream = records_stream(&js, &names).await?;
            let mut joined = join(&js, &names, server, Joiner::Replica, config.partitions).await?;
            let backlog = last_sequence(&mut stream, "the records stream").await?;
            let messages = records_from(&stream, &names, joined.next)
                .await
                .map_err(|e| NetError::Nats(format!("cannot read the records stream: {e}")))?;
            let (tx, rx) = mpsc::channel(INBOX);
            let reader = StreamReader {
                stream,
                names: names.clone(),
                connected,
                tx,
                counters: counters.clone(),
            };
            let mut received = Received::default();
            if let Some((seq, nanos)) = joined.last_read {
                received.note(seq, nanos);
            }
            let parts = std::mem::take(&mut joined.parts);
            tokio::spawn(reader.run(messages, received, joined.next, parts));
            Ok::<_, NetError>((client, rx, backlog, joined))
        })?;
        let c = joined.counts;
        let add = |a: &AtomicU64, v: u64| a.fetch_add(v, Ordering::Relaxed);
        add(&counters.snapshot_bytes, c.snapshot_bytes);
        add(&counters.batches, c.batches);
        add(&counters.bytes, c.batch_bytes);
        add(&counters.malformed, c.malformed);
        add(&counters.duplicates, c.duplicates);
        add(&counters.sequence_gaps, c.sequence_gaps);
        let mut assembler = Assembler::new(config.partitions);
        for &k in joined.fold.latest_frames().keys() {
            assembler.known(k);
        }
        let frame = joined.fold.snapshot_frame();
        if frame > 0 {
            let records = joined.fold.records();
            let seconds = joined.fold.snapshot_seconds();
            server.restore_replica(frame, seconds as f32, &records)?;
            tracing::info!(
                "started from the snapshots of frame {frame} ({} records)",
                records.len()
            );
            counters.snapshot_frame.store(frame, Ordering::Relaxed);
        }
        let mut edge = Self {
            config,
            rt,
            client,
            names,
            batches,
            backlog,
            first: joined.next,
            assembler,
            counters,
            waiting: None,
            health: None,
        };
        for batch in joined.later {
            edge.add(batch, server);
        }
        Ok(edge)
    }

    /// The edge's counters.
    pub fn counters(&self) -> Arc<EdgeCounters> {
        self.counters.clone()
    }

    /// Report stalls in `health` (`/health`'s `stalled`).
    pub fn report_to(&mut self, health: Arc<Health>) {
        self.health = Some(health);
    }

    /// Note whether frame `next` is `ready`: a frame waited for longer than a lease
    /// ([`LEASE_TTL`]: its trace node would have been replaced by then) is a stall, logged
    /// once and reported in `/health` until the frame completes.
    fn watch(&mut self, next: u64, ready: bool) {
        if ready {
            if let Some(w) = self.waiting.take().filter(|w| w.reported.is_some()) {
                tracing::info!(
                    "frame {}: every partition's batch arrived after {:.1} s",
                    w.frame,
                    w.since.elapsed().as_secs_f64()
                );
                self.set_stall(None);
            }
            return;
        }
        if self.waiting.as_ref().is_none_or(|w| w.frame != next) {
            if self.waiting.as_ref().is_some_and(|w| w.reported.is_some()) {
                self.set_stall(None);
            }
            let since_unix_ms = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as u64);
            self.waiting = Some(Waiting {
                frame: next,
                since: Instant::now(),
                since_unix_ms,
                reported: None,
            });
        }
        let w = self.waiting.as_mut().expect("set above");
        let seconds = w.since.elapsed().as_secs_f64();
        if seconds < LEASE_TTL.as_secs_f64() {
            return;
        }
        let stall = Stall {
            frame: w.frame,
            partitions: self.assembler.missing(w.frame),
            since_unix_ms: w.since_unix_ms,
            seconds,
        };
        if w.reported.is_none() {
            let text = if stall.partitions.len() == self.config.partitions as usize {
                format!(
                    "frame {}: no record batch of it arrived from any trace node",
                    stall.frame
                )
            } else {
                format!(
                    "frame {}: the record batches of partitions {:?} are missing (their trace \
                     nodes may be down)",
                    stall.frame, stall.partitions
                )
            };
            tracing::warn!("{text} for {seconds:.1} s");
            w.reported = Some(text);
        }
        self.set_stall(Some(stall));
    }

    fn set_stall(&self, stall: Option<Stall>) {
        let Some(health) = &self.health else { return };
        if let Ok(mut stalled) = health.stalled.lock() {
            *stalled = stall.and_then(|s| serde_json::to_value(s).ok());
        }
    }

    /// Apply every complete frame that was in the stream when the edge connected (a joining
    /// edge's snapshot), giving up when nothing arrives for `quiet`; returns the frames
    /// applied.
    pub fn catch_up(&mut self, server: &mut Server, quiet: Duration) -> Result<u64, NetError> {
        let start = server.frame();
        // Frames the join read past its snapshot.
        self.apply_ready(server)?;
        if self.backlog < self.first {
            return Ok(server.frame() - start);
        }
        loop {
            let got = self
                .rt
                .block_on(async { tokio::time::timeout(quiet, self.batches.recv()).await });
            match got {
                Ok(Some((seq, batch))) => {
                    self.add(batch, server);
                    self.apply_ready(server)?;
                    if seq >= self.backlog {
                        return Ok(server.frame() - start);
                    }
                }
                Ok(None) => return Err(NetError::Nats("the records stream ended".into())),
                Err(_) => return Ok(server.frame() - start),
            }
        }
    }

    fn add(&mut self, batch: Batch, server: &Server) {
        if let Err(e) = server.check_records(&batch.records) {
            tracing::warn!("batch of partition {} refused: {e}", batch.partition);
            self.counters.malformed.fetch_add(1, Ordering::Relaxed);
            return;
        }
        match self.assembler.add(batch, server.frame()) {
            Added::Kept => {}
            Added::Duplicate => {
                self.counters.duplicates.fetch_add(1, Ordering::Relaxed);
            }
            Added::Refused => {
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Apply the complete frames that follow the server's, in order.
    fn apply_ready(&mut self, server: &mut Server) -> Result<StepStats, NetError> {
        let mut total = StepStats::default();
        while let Some((seconds, records)) = self.assembler.take(server.frame() + 1) {
            let step = match server.step_replica(seconds as f32, &records) {
                Ok(step) => step,
                Err(e) => {
                    // Batches that are valid alone but not together (a point in two).
                    tracing::warn!("frame {} dropped: {e}", server.frame() + 1);
                    self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                    server.step_replica(seconds as f32, &[])?
                }
            };
            self.counters.frames.fetch_add(1, Ordering::Relaxed);
            total.published_points += step.published_points;
            total.publish_ms += step.publish_ms;
            total.ms += step.ms;
        }
        Ok(total)
    }
}

/// Forwards the records stream's batches to the edge, checking that sequence numbers
/// follow one another. The consumer lives in the NATS server, which forgets it when it
/// restarts: at every reconnection, and when the consumer fails, a new one resumes after
/// the last message received that the stream still holds ([`Received::last_held`]; a NATS
/// server killed hard can lose the newest messages and reuse their sequence numbers).
struct StreamReader {
    stream: async_nats::jetstream::stream::Stream,
    names: Names,
    connected: Arc<Notify>,
    tx: mpsc::Sender<(u64, Batch)>,
    counters: Arc<EdgeCounters>,
}

impl StreamReader {
    /// Forward from `messages`, whole batches once all their parts arrived (`parts` holds
    /// those the join read); `received` holds the last message the join read.
    async fn run(
        self,
        mut messages: pull::Ordered,
        mut received: Received,
        first: u64,
        mut parts: Reassembler,
    ) {
        let mut last: Option<u64> = first.checked_sub(1).filter(|&l| l > 0);
        loop {
            let message = tokio::select! {
                m = messages.next() => m,
                () = self.connected.notified() => {
                    tracing::info!("reconnected: reading the records stream again");
                    None
                }
            };
            let message = match message {
                Some(Ok(m)) => m,
                failed => {
                    if let Some(Err(e)) = failed {
                        tracing::warn!("records stream: {e}");
                    }
                    let (resume, m) = self.read_again(&mut received, last).await;
                    (last, messages) = (resume, m);
                    continue;
                }
            };
            let mut seq = 0;
            if let Ok(info) = message.info() {
                seq = info.stream_sequence;
                if let Some(prev) = last {
                    if seq <= prev {
                        self.counters.duplicates.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    if seq != prev + 1 {
                        tracing::warn!("records stream jumped from {prev} to {seq}");
                        self.counters.sequence_gaps.fetch_add(1, Ordering::Relaxed);
                    }
                }
                last = Some(seq);
                received.note(seq, info.published.unix_timestamp_nanos());
            }
            self.counters.batches.fetch_add(1, Ordering::Relaxed);
            self.counters
                .bytes
                .fetch_add(message.payload.len() as u64, Ordering::Relaxed);
            let subject = self.names.records_partition(&message.subject);
            match parts.add_payload(subject, &message.payload) {
                Reassembled::Complete(batch) => {
                    if self.tx.send((seq, batch)).await.is_err() {
                        return;
                    }
                }
                Reassembled::Incomplete => {}
                Reassembled::Duplicate => {
                    self.counters.duplicates.fetch_add(1, Ordering::Relaxed);
                }
                Reassembled::Malformed(e) => {
                    tracing::debug!("{e}");
                    self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// A new consumer after the last message received that the stream still holds (from
    /// the stream's start when it holds none of those remembered), and that message's
    /// sequence number; retries until the NATS server answers.
    async fn read_again(
        &self,
        received: &mut Received,
        last: Option<u64>,
    ) -> (Option<u64>, pull::Ordered) {
        loop {
            // Nothing received since the join, which read nothing: nothing to check.
            let checked = if received.is_empty() {
                Ok(last)
            } else {
                received.last_held(&self.stream).await
            };
            match checked {
                Ok(held) => {
                    if held != last {
                        tracing::warn!(
                            "the NATS server lost records after message {}: reading them again",
                            held.unwrap_or(0)
                        );
                        self.counters.rewinds.fetch_add(1, Ordering::Relaxed);
                    }
                    let from = held.map_or(1, |l| l + 1);
                    match records_from(&self.stream, &self.names, from).await {
                        Ok(m) => return (held, m),
                        Err(e) => tracing::warn!("cannot read the records stream again: {e}"),
                    }
                }
                Err(e) => tracing::warn!("{e}"),
            }
            tokio::time::sleep(VIEWS_AGAIN).await;
        }
    }
}

impl EdgeStepper {
    /// Publish a view set on this edge's subject. Views are sent again and again, so one
    /// that cannot be sent (the NATS server is away) is only logged; the wait is bounded.
    fn publish_views(&mut self, payload: &[u8]) {
        let subject = self.names.views(&self.config.edge_id);
        let payload = bytes::Bytes::copy_from_slice(payload);
        let sent = self.rt.block_on(async {
            let send = async {
                self.client.publish(subject, payload).await.ok()?;
                self.client.flush().await.ok()
            };
            tokio::time::timeout(VIEWS_AGAIN, send).await.ok().flatten()
        });
        if sent.is_none() {
            tracing::warn!("cannot publish views: is the NATS server away?");
        }
    }
}

impl Stepper for EdgeStepper {
    /// The stall reported, if any (a frame overdue longer than a lease).
    fn stalled(&self) -> Option<String> {
        self.waiting.as_ref()?.reported.clone()
    }

    /// Publish the viewers' views for the next frame; lockstep: wait until every
    /// partition's batch of it arrived and apply it; clocked: apply the complete frames
    /// that arrived.
    fn step(
        &mut self,
        server: &mut Server,
        views: &[View],
        seconds: f32,
    ) -> Result<StepStats, NetError> {
        let next = server.frame() + 1;
        let set = ViewSet {
            frame: next,
            seconds: f64::from(seconds),
            views: views.to_vec(),
        };
        let payload = set.encode();
        self.publish_views(&payload);
        if !self.config.lockstep {
            while let Ok((_, batch)) = self.batches.try_recv() {
                self.add(batch, server);
            }
            let step = self.apply_ready(server);
            self.watch(next, server.frame() >= next);
            return step;
        }
        let deadline = Instant::now() + self.config.frame_timeout;
        loop {
            let ready = self.assembler.ready(next);
            self.watch(next, ready);
            if ready {
                return self.apply_ready(server);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(NetError::Nats(format!(
                    "frame {next}: not every partition's batch arrived within {:.0} s",
                    self.config.frame_timeout.as_secs_f64()
                )));
            }
            let slice = left.min(VIEWS_AGAIN);
            let got = self
                .rt
                .block_on(async { tokio::time::timeout(slice, self.batches.recv()).await });
            match got {
                Ok(Some((_, batch))) => self.add(batch, server),
                Ok(None) => return Err(NetError::Nats("the records stream ended".into())),
                // A trace node that subscribed late missed them: say them again.
                Err(_) => self.publish_views(&payload),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch(partition: u32, frame: u64, index: u32) -> Batch {
        Batch {
            partition,
            partitions: 2,
            frame,
            seconds: frame as f64 / 30.0,
            records: vec![PointRecord {
                instance: 0,
                index,
                bits: 7,
            }],
        }
    }

    #[test]
    fn frames_complete_once_every_partition_sent_them() {
        let mut a = Assembler::new(2);
        let forged = Batch {
            partitions: 1,
            ..batch(0, 1, 1)
        };
        assert_eq!(
            a.add(forged, 0),
            Added::Refused,
            "a first batch sets nothing"
        );
        assert_eq!(a.missing(1), [0, 1]);
        assert_eq!(a.add(batch(0, 1, 1), 0), Added::Kept);
        assert!(!a.ready(1));
        assert_eq!(a.take(1), None);
        assert_eq!(a.add(batch(0, 1, 9), 0), Added::Duplicate, "second copy");
        assert_eq!(a.add(batch(1, 2, 3), 0), Added::Kept, "a later frame first");
        assert_eq!(a.add(batch(1, 1, 2), 0), Added::Kept);
        let (seconds, records) = a.take(1).unwrap();
        assert_eq!(seconds, 1.0 / 30.0);
        assert_eq!(records.iter().map(|r| r.index).collect::<Vec<_>>(), [1, 2]);
        assert_eq!(a.add(batch(1, 1, 2), 1), Added::Duplicate, "frame applied");
        let other = Batch {
            partitions: 3,
            ..batch(2, 2, 4)
        };
        assert_eq!(a.add(other, 1), Added::Refused, "another partition count");
        let beyond = Batch {
            partition: 2,
            ..batch(0, 2, 4)
        };
        assert_eq!(
            a.add(beyond, 1),
            Added::Refused,
            "a partition past the count"
        );
        assert!(!a.ready(2));
        assert_eq!(a.add(batch(0, 2, 5), 1), Added::Kept);
        assert!(a.ready(2));
    }

    #[test]
    fn frames_before_a_partitions_first_batch_do_not_wait_for_it() {
        let mut a = Assembler::new(2);
        for f in 1..=3 {
            assert_eq!(a.add(batch(0, f, f as u32), 0), Added::Kept);
        }
        assert!(!a.ready(1), "partition 1 not heard of yet");
        assert_eq!(
            a.add(batch(1, 3, 9), 0),
            Added::Kept,
            "its node started late"
        );
        assert!(a.ready(1) && a.ready(2) && a.ready(3));
        let (_, records) = a.take(3).unwrap();
        assert_eq!(records.iter().map(|r| r.index).collect::<Vec<_>>(), [3, 9]);
        assert_eq!(a.add(batch(0, 4, 4), 3), Added::Kept);
        assert!(!a.ready(4), "started: later frames wait for it");

        // A partition the join knew waits, whatever frame its next batch has.
        let mut a = Assembler::new(2);
        a.known(1);
        assert_eq!(a.add(batch(0, 5, 0), 4), Added::Kept);
        assert_eq!(a.add(batch(1, 6, 0), 4), Added::Kept);
        assert!(!a.ready(5));
    }

    #[test]
    fn far_future_batches_are_refused_and_the_next_frames_still_fit() {
        let mut a = Assembler::new(2);
        let window = MAX_PENDING_FRAMES as u64;
        for f in (window + 1..window + 70_000).step_by(7) {
            assert_eq!(a.add(batch(0, f, 0), 0), Added::Refused);
        }
        assert_eq!(a.add(batch(0, 1, 0), 0), Added::Kept);
        assert_eq!(a.add(batch(1, 1, 1), 0), Added::Kept);
        assert!(a.take(1).is_some());
        // The window moves with the frames applied.
        assert_eq!(a.add(batch(0, window + 1, 0), 1), Added::Kept);
    }

    #[test]
    fn incomplete_frames_are_bounded() {
        let mut a = Assembler::new(2);
        for f in 1..=MAX_PENDING_FRAMES as u64 {
            assert_eq!(a.add(batch(0, f, 0), 0), Added::Kept);
        }
        let over = MAX_PENDING_FRAMES as u64 + 1;
        assert_eq!(a.add(batch(0, over, 0), 0), Added::Refused);
        assert_eq!(
            a.add(batch(1, 1, 0), 0),
            Added::Kept,
            "known frames still fill"
        );
        assert!(a.take(1).is_some());
    }
}
