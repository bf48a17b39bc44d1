//! Joining a running session (docs/SCALE-OUT.md), shared by edges and trace nodes: read the
//! latest message of every snapshot subject (each chunk's points as of some frame, each
//! partition's mark), then the record batches that follow them, and fold both into every
//! point's latest published record.
//!
//! A chunk's latest message is the state of its points at its own frame, or at its
//! partition's latest mark's frame when that is later (a mark says that every chunk that
//! changed was published again before it). That frame is the chunk's *validity*. A batch's
//! record of a point is folded in when the batch's frame is after the validity of the
//! point's chunk; older ones are already in the chunk. The first batch of a (partition,
//! frame) wins, as on an edge.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Duration;

use async_nats::jetstream::consumer::{pull, DeliverPolicy};
use futures_util::StreamExt;
use psao_server::{Owners, PointRecord, PointState, Server};

use super::lost::stored;
use super::parts::{Reassembled, Reassembler};
use super::wire::{Batch, BatchPart, Snapshot, SnapshotMark, CHUNK_POINTS};
use super::{records_stream, snapshot_stream, Names};
use crate::NetError;

/// Longest wait for the next message while joining.
const JOIN_WAIT: Duration = Duration::from_secs(10);

/// The latest snapshot chunk and mark of each subject.
#[derive(Clone, Default)]
pub struct Published {
    marks: BTreeMap<u32, SnapshotMark>,
    chunks: BTreeMap<(u32, u32), Snapshot>,
}

impl Published {
    /// Keep `chunk` unless a later one of its subject is kept.
    pub fn add_chunk(&mut self, chunk: Snapshot) {
        let key = (chunk.partition, chunk.chunk);
        if self.chunks.get(&key).is_none_or(|c| c.frame <= chunk.frame) {
            self.chunks.insert(key, chunk);
        }
    }

    /// Keep `mark` unless a later one of its partition is kept.
    pub fn add_mark(&mut self, mark: SnapshotMark) {
        if self
            .marks
            .get(&mark.partition)
            .is_none_or(|m| m.frame <= mark.frame)
        {
            self.marks.insert(mark.partition, mark);
        }
    }
}

/// Where a join starts from the snapshots.
#[derive(Debug, PartialEq)]
pub struct Plan {
    /// Number of partitions.
    pub partitions: u32,
    /// The latest validity of any chunk, and its scene time: the earliest frame at which
    /// the whole state can be rebuilt.
    pub frame: u64,
    pub seconds: f64,
    /// The first records-stream sequence number to read: after the batch of the earliest
    /// validity.
    pub first: u64,
    /// Per (partition, chunk): its validity.
    pub valid: BTreeMap<(u32, u32), u64>,
    /// Per (partition, frame) of a validity: the records-stream sequence number of the
    /// partition's batch of that frame.
    pub sequences: BTreeMap<(u32, u64), u64>,
    /// Every chunk's points.
    pub points: Vec<PointState>,
}

/// The plan of a join from `published` for a session of `n` partitions (the joiner's own
/// setting, never a message's); `None` when some partition has no mark or misses a chunk
/// (no complete snapshot yet: read the records stream from its start). Messages of another
/// partition count are ignored.
pub fn plan(published: Published, n: u32) -> Option<Plan> {
    // (frame, records sequence, scene time) of the validity of each chunk.
    let mut valid = BTreeMap::new();
    let mut sequences = BTreeMap::new();
    let mut at = Vec::new();
    for k in 0..n {
        let mark = published.marks.get(&k).filter(|m| m.partitions == n)?;
        for c in 0..mark.chunks {
            let chunk = published
                .chunks
                .get(&(k, c))
                .filter(|s| s.partitions == n && s.chunks == mark.chunks)?;
            let v = if chunk.frame > mark.frame {
                (chunk.frame, chunk.sequence, chunk.seconds)
            } else {
                (mark.frame, mark.sequence, mark.seconds)
            };
            valid.insert((k, c), v.0);
            sequences.insert((k, v.0), v.1);
            at.push(v);
        }
    }
    let &(frame, _, seconds) = at.iter().max_by_key(|v| v.0)?;
    let first = at.iter().map(|v| v.1).min()? + 1;
    let mut chunks = published.chunks;
    let points = valid
        .keys()
        .flat_map(|key| chunks.remove(key).map(|c| c.points).unwrap_or_default())
        .collect();
    Some(Plan {
        partitions: n,
        frame,
        seconds,
        first,
        valid,
        sequences,
        points,
    })
}

/// What [`Fold::add`] did with a batch.
#[derive(Debug, PartialEq)]
pub enum Folded {
    /// Folded in.
    Kept,
    /// Its frame is after the fold's end: handed back.
    Later(Batch),
    /// A second copy of a (partition, frame): dropped.
    Duplicate,
    /// Its records name points that do not exist, or another partition count: dropped.
    Malformed,
}

/// Every point's latest published record, from a [`Plan`]'s chunks and the batches after
/// them.
pub struct Fold {
    plan: Option<Plan>,
    /// The session's partition count: batches of another are malformed.
    partitions: u32,
    /// The snapshot chunk of every point (when there is a plan).
    chunk_of: Vec<Vec<u32>>,
    owners: Option<Owners>,
    /// Point → (frame, record).
    published: HashMap<(u32, u32), (u64, u32)>,
    seen: HashSet<(u32, u64)>,
    /// Per partition: the latest frame folded and its scene time.
    latest: BTreeMap<u32, (u64, f64)>,
}

impl Fold {
    /// A fold of a session of `partitions` partitions starting from `plan`'s chunks (or
    /// from nothing); `server` has the scene.
    pub fn new(plan: Option<Plan>, partitions: u32, server: &Server) -> Fold {
        let mut published = HashMap::new();
        let (mut chunk_of, mut owners) = (Vec::new(), None);
        if let Some(p) = &plan {
            let o = server.owners(p.partitions);
            chunk_of = o.chunks(CHUNK_POINTS);
            owners = Some(o);
            for s in &p.points {
                let r = s.record;
                let chunk = chunk_of
                    .get(r.instance as usize)
                    .and_then(|c| c.get(r.index as usize));
                let Some(&chunk) = chunk else { continue };
                let k = owners.as_ref().map_or(0, |o| o.owner(r.instance, r.index));
                let v = p.valid.get(&(k, chunk)).copied().unwrap_or(0);
                published.insert((r.instance, r.index), (v, r.bits));
            }
        }
        Fold {
            plan,
            partitions,
            chunk_of,
            owners,
            published,
            seen: HashSet::new(),
            latest: BTreeMap::new(),
        }
    }

    /// The frame the snapshots allow rebuilding the state at (0: no snapshot).
    pub fn snapshot_frame(&self) -> u64 {
        self.plan.as_ref().map_or(0, |p| p.frame)
    }

    /// The scene time of [`Fold::snapshot_frame`].
    pub fn snapshot_seconds(&self) -> f64 {
        self.plan.as_ref().map_or(0.0, |p| p.seconds)
    }

    /// Take in `batch` if its frame is at most `upto`; `server` checks its records.
    pub fn add(&mut self, batch: Batch, upto: u64, server: &Server) -> Folded {
        if batch.partitions != self.partitions {
            return Folded::Malformed;
        }
        if self.seen.contains(&(batch.partition, batch.frame)) {
            return Folded::Duplicate;
        }
        if batch.frame > upto {
            return Folded::Later(batch);
        }
        if server.check_records(&batch.records).is_err() {
            return Folded::Malformed;
        }
        self.seen.insert((batch.partition, batch.frame));
        let latest = self.latest.entry(batch.partition).or_insert((0, 0.0));
        if batch.frame >= latest.0 {
            *latest = (batch.frame, batch.seconds);
        }
        for r in &batch.records {
            if batch.frame <= self.validity(batch.partition, r) {
                continue;
            }
            let entry = self
                .published
                .entry((r.instance, r.index))
                .or_insert((0, r.bits));
            if entry.0 <= batch.frame {
                *entry = (batch.frame, r.bits);
            }
        }
        Folded::Kept
    }

    /// The validity of the chunk of `r`'s point (0 without a plan).
    fn validity(&self, k: u32, r: &PointRecord) -> u64 {
        let Some(plan) = &self.plan else { return 0 };
        let chunk = self.chunk_of[r.instance as usize][r.index as usize];
        let owner = self
            .owners
            .as_ref()
            .map_or(k, |o| o.owner(r.instance, r.index));
        plan.valid.get(&(owner, chunk)).copied().unwrap_or(0)
    }

    /// Whether every partition's state is known at [`Fold::snapshot_frame`]: its batches
    /// reached that frame or all its chunks are valid there.
    pub fn complete(&self) -> bool {
        let Some(plan) = &self.plan else { return true };
        (0..plan.partitions).all(|k| {
            self.latest.get(&k).is_some_and(|l| l.0 >= plan.frame)
                || plan
                    .valid
                    .range((k, 0)..=(k, u32::MAX))
                    .all(|(_, &v)| v >= plan.frame)
        })
    }

    /// Per partition, the latest frame its state is known at (its last batch folded, or
    /// its chunks' validity).
    pub fn latest_frames(&self) -> BTreeMap<u32, (u64, f64)> {
        let mut out = self.latest.clone();
        if let Some(plan) = &self.plan {
            for (&(k, _), &v) in &plan.valid {
                let e = out.entry(k).or_insert((0, 0.0));
                if v > e.0 {
                    *e = (v, plan.seconds);
                }
            }
        }
        out
    }

    /// The latest frame anything is known at, and its scene time.
    pub fn last_frame(&self) -> (u64, f64) {
        let mut best = (
            self.snapshot_frame(),
            self.plan.as_ref().map_or(0.0, |p| p.seconds),
        );
        for &(f, s) in self.latest.values() {
            if f > best.0 {
                best = (f, s);
            }
        }
        best
    }

    /// Every point's latest record, in (instance, index) order.
    pub fn records(&self) -> Vec<PointRecord> {
        let mut out: Vec<PointRecord> = self
            .published
            .iter()
            .map(|(&(instance, index), &(_, bits))| PointRecord {
                instance,
                index,
                bits,
            })
            .collect();
        out.sort_unstable();
        out
    }

    /// The snapshots' points (records and sample counts).
    pub fn snapshot_points(&self) -> &[PointState] {
        self.plan.as_ref().map_or(&[], |p| &p.points)
    }
}

/// What reading while joining counted.
#[derive(Clone, Copy, Debug, Default)]
pub struct JoinCounts {
    /// Bytes of snapshot chunks and marks read.
    pub snapshot_bytes: u64,
    /// Record batches read, and their bytes.
    pub batches: u64,
    pub batch_bytes: u64,
    /// Messages that did not parse or were refused, dropped.
    pub malformed: u64,
    /// Second copies, dropped.
    pub duplicates: u64,
    /// Records-stream sequence numbers that did not follow the previous one.
    pub sequence_gaps: u64,
}

/// Who joins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Joiner {
    /// An edge: the state at the snapshots' frame (waiting for every partition's batches
    /// up to it); later batches are handed back. Without a snapshot nothing is read: the
    /// edge replays the records stream from its start.
    Replica,
    /// A trace node: everything published until now, whatever the frame.
    TraceNode,
}

/// The outcome of [`join`].
pub struct Joined {
    /// The folded state.
    pub fold: Fold,
    /// Batches of frames after the snapshots' frame (an edge's first live frames).
    pub later: Vec<Batch>,
    /// The records-stream sequence number to continue reading from.
    pub next: u64,
    /// The last records message read: its sequence number and the time the stream stored
    /// it (Unix ns), to notice a NATS server that lost it ([`super::lost`]).
    pub last_read: Option<(u64, i128)>,
    /// The parts of the batches not whole yet (their other parts come after `next`).
    pub parts: Reassembler,
    /// What was read.
    pub counts: JoinCounts,
}

/// Join the session of `names`, cut into `partitions` partitions: read the snapshots, then
/// the records stream after them (see [`Joiner`]); `server` has the scene.
pub async fn join(
    js: &async_nats::jetstream::Context,
    names: &Names,
    server: &Server,
    joiner: Joiner,
    partitions: u32,
) -> Result<Joined, NetError> {
    let mut counts = JoinCounts::default();
    let published = read_published(js, names, partitions, &mut counts).await?;
    let plan = plan(published, partitions);
    let mut stream = records_stream(js, names).await?;
    let mut first = plan.as_ref().map_or(1, |p| p.first);
    if let Some(p) = &plan {
        if !batches_held(&stream, &p.sequences).await? {
            tracing::warn!(
                "the snapshots name batches the records stream no longer holds (the NATS \
                 server lost messages): reading the records stream from its start"
            );
            first = 1;
        }
    }
    let mut fold = Fold::new(plan, partitions, server);
    let mut later = Vec::new();
    if joiner == Joiner::Replica && fold.snapshot_frame() == 0 {
        return Ok(Joined {
            fold,
            later,
            next: 1,
            last_read: None,
            parts: Reassembler::default(),
            counts,
        });
    }
    let upto = match joiner {
        Joiner::Replica => fold.snapshot_frame(),
        Joiner::TraceNode => u64::MAX,
    };
    let failed = |e: &dyn std::fmt::Display| {
        NetError::Nats(format!("cannot read the records stream while joining: {e}"))
    };
    let last = last_sequence(&mut stream, "the records stream while joining").await?;
    let done = |fold: &Fold| joiner == Joiner::TraceNode || fold.complete();
    if last < first && done(&fold) {
        return Ok(Joined {
            fold,
            later,
            next: first,
            last_read: None,
            parts: Reassembler::default(),
            counts,
        });
    }
    let mut messages = records_from(&stream, names, first)
        .await
        .map_err(|e| failed(&e))?;
    let mut prev = first - 1;
    let mut parts = Reassembler::default();
    loop {
        let message = match tokio::time::timeout(JOIN_WAIT, messages.next()).await {
            Err(_) => return Err(failed(&"nothing arrived for 10 s")),
            Ok(None) => return Err(failed(&"the stream ended")),
            Ok(Some(Err(e))) => {
                tracing::warn!("records stream while joining: {e}");
                continue;
            }
            Ok(Some(Ok(m))) => m,
        };
        let info = message.info().ok();
        let seq = info.as_ref().map_or(prev + 1, |i| i.stream_sequence);
        let stored = info.map(|i| i.published.unix_timestamp_nanos());
        if seq <= prev {
            counts.duplicates += 1;
            continue;
        }
        if seq != prev + 1 && prev > 0 {
            tracing::warn!("records stream jumped from {prev} to {seq} while joining");
            counts.sequence_gaps += 1;
        }
        prev = seq;
        counts.batches += 1;
        counts.batch_bytes += message.payload.len() as u64;
        match parts.add_payload(names.records_partition(&message.subject), &message.payload) {
            Reassembled::Complete(batch) => match fold.add(batch, upto, server) {
                Folded::Kept => {}
                Folded::Later(b) => later.push(b),
                Folded::Duplicate => counts.duplicates += 1,
                Folded::Malformed => counts.malformed += 1,
            },
            Reassembled::Incomplete => {}
            Reassembled::Duplicate => counts.duplicates += 1,
            Reassembled::Malformed(e) => {
                tracing::debug!("{e}");
                counts.malformed += 1;
            }
        }
        if seq >= last && done(&fold) {
            return Ok(Joined {
                fold,
                later,
                next: seq + 1,
                last_read: stored.map(|t| (seq, t)),
                parts,
                counts,
            });
        }
    }
}

/// Whether the records stream still holds, under each of `sequences`, (the last part of)
/// the batch of the (partition, frame) naming it. A NATS server that lost acknowledged messages reuses
/// their sequence numbers, and the snapshots may name some of them.
async fn batches_held(
    stream: &async_nats::jetstream::stream::Stream,
    sequences: &BTreeMap<(u32, u64), u64>,
) -> Result<bool, NetError> {
    for (&(k, frame), &seq) in sequences {
        let held = stored(stream, seq)
            .await?
            .and_then(|m| BatchPart::decode(&m.payload).ok())
            .is_some_and(|b| b.partition == k && b.frame == frame);
        if !held {
            return Ok(false);
        }
    }
    Ok(true)
}

/// The latest message of every snapshot subject (chunks and marks); messages that do not
/// parse, name another partition count than `n` or another subject than the one they were
/// published on are counted as malformed and dropped.
async fn read_published(
    js: &async_nats::jetstream::Context,
    names: &Names,
    n: u32,
    counts: &mut JoinCounts,
) -> Result<Published, NetError> {
    let failed =
        |e: &dyn std::fmt::Display| NetError::Nats(format!("cannot read the snapshots: {e}"));
    let mut stream = snapshot_stream(js, names).await?;
    let last = last_sequence(&mut stream, "the snapshots").await?;
    let mut published = Published::default();
    if last == 0 {
        return Ok(published);
    }
    let mut messages = ordered(
        &stream,
        DeliverPolicy::LastPerSubject,
        names.snapshots_wildcard(),
    )
    .await
    .map_err(|e| failed(&e))?;
    loop {
        let next = tokio::time::timeout(JOIN_WAIT, messages.next())
            .await
            .map_err(|_| failed(&"nothing arrived for 10 s"))?;
        let message = match next {
            Some(Ok(m)) => m,
            Some(Err(e)) => {
                tracing::warn!("snapshots stream: {e}");
                continue;
            }
            None => break,
        };
        counts.snapshot_bytes += message.payload.len() as u64;
        let subject = message.subject.as_str();
        let kept = if subject.ends_with(".mark") {
            SnapshotMark::decode(&message.payload)
                .map_err(|e| e.to_string())
                .and_then(|m| {
                    let ok = m.partitions == n && subject == names.snapshot_mark(m.partition);
                    ok.then(|| published.add_mark(m))
                        .ok_or_else(|| format!("{subject}: a mark of another partition or count"))
                })
        } else {
            Snapshot::decode(&message.payload)
                .map_err(|e| e.to_string())
                .and_then(|c| {
                    let ok = c.partitions == n && subject == names.snapshot(c.partition, c.chunk);
                    ok.then(|| published.add_chunk(c))
                        .ok_or_else(|| format!("{subject}: a chunk of another partition or count"))
                })
        };
        if let Err(e) = kept {
            tracing::debug!("{e}");
            counts.malformed += 1;
        }
        if message.info().map_or(true, |i| i.stream_sequence >= last) {
            break;
        }
    }
    Ok(published)
}

/// The sequence number of `stream`'s last message (0 when it never held one); an error
/// names `what` could not be read.
pub(super) async fn last_sequence(
    stream: &mut async_nats::jetstream::stream::Stream,
    what: &str,
) -> Result<u64, NetError> {
    let info =
        (stream.info().await).map_err(|e| NetError::Nats(format!("cannot read {what}: {e}")))?;
    Ok(info.state.last_sequence)
}

/// An ordered consumer of the records stream from sequence number `first`.
pub(super) async fn records_from(
    stream: &async_nats::jetstream::stream::Stream,
    names: &Names,
    first: u64,
) -> Result<pull::Ordered, String> {
    let from = DeliverPolicy::ByStartSequence {
        start_sequence: first,
    };
    ordered(stream, from, names.records_wildcard()).await
}

/// The messages of an ordered consumer of `stream` on `subject`, delivered from `from`.
pub(super) async fn ordered(
    stream: &async_nats::jetstream::stream::Stream,
    from: DeliverPolicy,
    subject: String,
) -> Result<pull::Ordered, String> {
    stream
        .create_consumer(pull::OrderedConfig {
            deliver_policy: from,
            filter_subject: subject,
            ..Default::default()
        })
        .await
        .map_err(|e| e.to_string())?
        .messages()
        .await
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(instance: u32, index: u32, bits: u32) -> PointState {
        PointState {
            record: PointRecord {
                instance,
                index,
                bits,
            },
            samples: 4,
        }
    }

    fn chunk(partition: u32, chunk: u32, frame: u64) -> Snapshot {
        Snapshot {
            partition,
            partitions: 2,
            chunk,
            chunks: 2,
            frame,
            seconds: frame as f64 / 30.0,
            sequence: frame * 10 + u64::from(partition),
            points: vec![point(partition, chunk, frame as u32)],
        }
    }

    fn mark(partition: u32, frame: u64) -> SnapshotMark {
        SnapshotMark {
            partition,
            partitions: 2,
            chunks: 2,
            frame,
            seconds: frame as f64 / 30.0,
            sequence: frame * 10 + u64::from(partition),
        }
    }

    #[test]
    fn a_join_starts_from_each_chunks_latest_message() {
        let mut p = Published::default();
        assert_eq!(plan(Published::default(), 2), None, "nothing published");
        for k in 0..2 {
            p.add_chunk(chunk(k, 0, 4));
            p.add_chunk(chunk(k, 1, 4));
            p.add_mark(mark(k, 4));
        }
        // Partition 1's round of frame 8 published chunk 0 (chunk 1 did not change) and
        // its mark; partition 0's round of frame 8 is under way: chunk 1 only, no mark.
        p.add_chunk(chunk(1, 0, 8));
        p.add_mark(mark(1, 8));
        p.add_chunk(chunk(0, 1, 8));
        // An older copy arriving late does not replace the newer one.
        p.add_chunk(chunk(0, 1, 4));
        assert_eq!(
            plan(p.clone(), 3),
            None,
            "a session of 3 has no marks of its own"
        );
        let got = plan(p, 2).unwrap();
        assert_eq!(got.partitions, 2);
        let valid: Vec<u64> = got.valid.values().copied().collect();
        assert_eq!(
            valid,
            [4, 8, 8, 8],
            "(0,0) valid at 4, (0,1) at 8, partition 1 at 8"
        );
        assert_eq!(
            (got.frame, got.first),
            (8, 41),
            "after partition 0's batch of 4"
        );
        let sequences: Vec<_> = got.sequences.into_iter().collect();
        assert_eq!(
            sequences,
            [((0, 4), 40), ((0, 8), 80), ((1, 8), 81)],
            "the batches a joiner checks the records stream still holds"
        );
        assert_eq!(got.points.len(), 4);

        let mut missing = Published::default();
        missing.add_chunk(chunk(0, 0, 4));
        missing.add_chunk(chunk(0, 1, 4));
        missing.add_mark(mark(0, 4));
        missing.add_mark(mark(1, 4));
        missing.add_chunk(chunk(1, 0, 4));
        assert_eq!(plan(missing, 2), None, "chunk 1 of partition 1 missing");
        let mut other = Published::default();
        for k in 0..2 {
            other.add_chunk(chunk(k, 0, 4));
            other.add_chunk(chunk(k, 1, 4));
            other.add_mark(mark(k, 4));
        }
        other.add_mark(SnapshotMark {
            partitions: 3,
            ..mark(2, 12)
        });
        assert_eq!(
            plan(other, 2).map(|p| p.frame),
            Some(4),
            "a later mark of another partition count is ignored"
        );
    }
}
