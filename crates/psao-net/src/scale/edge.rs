//! An edge (`psao edge`): reads every partition's record batches from the records stream
//! (from its first message: the snapshot, then the live frames), rebuilds the whole
//! published state in a replica [`Server`] ([`Server::step_replica`]), and serves viewers
//! with [`crate::serve`], publishing their views for the trace nodes.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use async_nats::jetstream::consumer::{pull, DeliverPolicy};
use futures_util::StreamExt;
use psao_server::{PointRecord, Server, StepStats, View};
use serde::Serialize;
use tokio::sync::mpsc;

use super::wire::{Batch, ViewSet};
use super::{connect, records_stream, Names};
use crate::serve::Stepper;
use crate::NetError;

/// Batches buffered between the stream and the simulation.
const INBOX: usize = 1024;
/// Frames an edge keeps incomplete before it refuses more (a partition that never
/// publishes again would otherwise grow this without bound).
pub const MAX_PENDING_FRAMES: usize = 1 << 16;

/// How an edge follows the trace nodes.
#[derive(Clone, Debug)]
pub struct EdgeConfig {
    /// NATS server URL.
    pub nats: String,
    /// Scene name (names the subjects and stream; see [`Names`]).
    pub scene: String,
    /// This edge's name on its views subject.
    pub edge_id: String,
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
    frames: AtomicU64,
}

/// [`EdgeCounters`] at one moment (`psao edge --json` writes it beside the serve figures).
#[derive(Clone, Debug, Default, Serialize)]
pub struct EdgeStats {
    /// Record batches received from the stream, and their bytes.
    pub batches: u64,
    pub batch_bytes: u64,
    /// Batches or messages that did not parse or named points that do not exist: dropped.
    pub malformed: u64,
    /// Second copies of a (frame, partition) batch, and batches of frames already applied:
    /// dropped.
    pub duplicates: u64,
    /// Stream sequence numbers that did not follow the previous one.
    pub sequence_gaps: u64,
    /// Server frames applied.
    pub frames: u64,
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
            frames: get(&self.frames),
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
    /// Dropped: its partition count disagrees with the earlier batches', or too many frames
    /// are incomplete.
    Refused,
}

/// Gathers the batches of each frame until every partition's is there.
#[derive(Default)]
pub struct Assembler {
    partitions: Option<u32>,
    frames: BTreeMap<u64, Parts>,
}

impl Assembler {
    /// Take in `batch`; frames up to `applied` are done.
    pub fn add(&mut self, batch: Batch, applied: u64) -> Added {
        if *self.partitions.get_or_insert(batch.partitions) != batch.partitions {
            return Added::Refused;
        }
        if batch.frame <= applied {
            return Added::Duplicate;
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
        Added::Kept
    }

    /// Whether every partition's batch of `frame` is in.
    pub fn ready(&self, frame: u64) -> bool {
        match (self.partitions, self.frames.get(&frame)) {
            (Some(n), Some(parts)) => parts.partitions.len() >= n as usize,
            _ => false,
        }
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
    batches: mpsc::Receiver<Batch>,
    assembler: Assembler,
    counters: Arc<EdgeCounters>,
}

impl EdgeStepper {
    /// Connects and starts reading the records stream from its first message.
    pub fn connect(config: EdgeConfig) -> Result<Self, NetError> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .map_err(NetError::io("cannot start the async runtime"))?;
        let names = Names::new(&config.scene);
        let counters = Arc::new(EdgeCounters::default());
        let (client, batches) = rt.block_on(async {
            let client = connect(&config.nats).await?;
            let js = async_nats::jetstream::new(client.clone());
            let stream = records_stream(&js, &names).await?;
            let consumer = stream
                .create_consumer(pull::OrderedConfig {
                    deliver_policy: DeliverPolicy::All,
                    filter_subject: names.records_wildcard(),
                    ..Default::default()
                })
                .await
                .map_err(|e| NetError::Nats(format!("cannot read the records stream: {e}")))?;
            let messages = consumer
                .messages()
                .await
                .map_err(|e| NetError::Nats(format!("cannot read the records stream: {e}")))?;
            let (tx, rx) = mpsc::channel(INBOX);
            tokio::spawn(read_stream(messages, tx, counters.clone()));
            Ok::<_, NetError>((client, rx))
        })?;
        Ok(Self {
            config,
            rt,
            client,
            names,
            batches,
            assembler: Assembler::default(),
            counters,
        })
    }

    /// The edge's counters.
    pub fn counters(&self) -> Arc<EdgeCounters> {
        self.counters.clone()
    }

    /// Apply every complete frame already in the stream, until none arrives for `quiet`
    /// (a joining edge's snapshot); returns the frames applied.
    pub fn catch_up(&mut self, server: &mut Server, quiet: Duration) -> Result<u64, NetError> {
        let start = server.frame();
        loop {
            let got = self
                .rt
                .block_on(async { tokio::time::timeout(quiet, self.batches.recv()).await });
            match got {
                Ok(Some(batch)) => {
                    self.add(batch, server);
                    self.apply_ready(server)?;
                }
                Ok(None) => return Err(NetError::Nats("the records stream ended".into())),
                Err(_) => return Ok(server.frame() - start),
            }
        }
    }

    fn add(&mut self, batch: Batch, server: &Server) {
        if server.validate_records(&batch.records).is_err() {
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

/// Forwards the stream's batches, checking that sequence numbers follow one another.
async fn read_stream(
    mut messages: pull::Ordered,
    tx: mpsc::Sender<Batch>,
    counters: Arc<EdgeCounters>,
) {
    let mut last: Option<u64> = None;
    while let Some(message) = messages.next().await {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!("records stream: {e}");
                continue;
            }
        };
        if let Ok(info) = message.info() {
            let seq = info.stream_sequence;
            if let Some(prev) = last {
                if seq <= prev {
                    counters.duplicates.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                if seq != prev + 1 {
                    tracing::warn!("records stream jumped from {prev} to {seq}");
                    counters.sequence_gaps.fetch_add(1, Ordering::Relaxed);
                }
            }
            last = Some(seq);
        }
        counters.batches.fetch_add(1, Ordering::Relaxed);
        counters
            .bytes
            .fetch_add(message.payload.len() as u64, Ordering::Relaxed);
        match Batch::decode(&message.payload) {
            Ok(batch) => {
                if tx.send(batch).await.is_err() {
                    return;
                }
            }
            Err(e) => {
                tracing::debug!("{e}");
                counters.malformed.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

impl Stepper for EdgeStepper {
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
        let subject = self.names.views(&self.config.edge_id);
        self.rt.block_on(async {
            self.client
                .publish(subject, set.encode().into())
                .await
                .map_err(|e| NetError::Nats(format!("cannot publish views: {e}")))?;
            self.client
                .flush()
                .await
                .map_err(|e| NetError::Nats(format!("cannot publish views: {e}")))
        })?;
        if !self.config.lockstep {
            while let Ok(batch) = self.batches.try_recv() {
                self.add(batch, server);
            }
            return self.apply_ready(server);
        }
        let deadline = Instant::now() + self.config.frame_timeout;
        loop {
            if self.assembler.ready(next) {
                return self.apply_ready(server);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(NetError::Nats(format!(
                    "frame {next}: not every partition's batch arrived within {:.0} s",
                    self.config.frame_timeout.as_secs_f64()
                )));
            }
            let got = self
                .rt
                .block_on(async { tokio::time::timeout(left, self.batches.recv()).await });
            match got {
                Ok(Some(batch)) => self.add(batch, server),
                Ok(None) => return Err(NetError::Nats("the records stream ended".into())),
                Err(_) => {}
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
        let mut a = Assembler::default();
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
        assert!(!a.ready(2));
        assert_eq!(a.add(batch(0, 2, 5), 1), Added::Kept);
        assert!(a.ready(2));
    }

    #[test]
    fn incomplete_frames_are_bounded() {
        let mut a = Assembler::default();
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
