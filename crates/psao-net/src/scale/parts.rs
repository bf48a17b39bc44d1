//! Record batches as messages that always fit the NATS server's payload limit
//! (docs/SCALE-OUT.md, "Record batches"): a batch's payload ([`Batch::encode`]) is
//! compressed with zstd and cut into as many [`BatchPart`]s as its size needs under the
//! server's `max_payload`, each naming its partition, frame, and part k of m. A
//! [`Reassembler`] gives the batch back once every part of it arrived, in any order,
//! holding a bounded number of bytes meanwhile.

use std::collections::{BTreeMap, BTreeSet};

use super::wire::{fail, Batch, BatchPart, PayloadError, MAX_PARTS, PART_HEADER};

/// Bytes kept free in every message for its NATS headers (the server counts them against
/// `max_payload`): the message id, tens of bytes.
pub const NATS_HEADROOM: usize = 512;
/// Smallest `max_payload` a trace node works with: room for a part of 1 KiB.
pub const MIN_MAX_PAYLOAD: usize = PART_HEADER + NATS_HEADROOM + 1024;
/// zstd level of the batches (that of the viewer wire's compact codec).
const LEVEL: i32 = psao_delta::COMPACT_LEVEL;
/// Most records in one batch: a partition's records of one frame are at most all the
/// scene's points (Sponza at 1024 points/m² has some 1.5 M).
pub const MAX_BATCH_RECORDS: usize = 1 << 23;
/// Most bytes of parts a [`Reassembler`] holds for incomplete batches (beyond the largest
/// legitimate batch, [`MAX_BATCH_RECORDS`] records, compressed or not).
pub const MAX_PENDING_BYTES: usize = 256 << 20;
/// Most incomplete batches a [`Reassembler`] holds.
pub const MAX_PENDING_BATCHES: usize = 4096;
/// Completed batches a [`Reassembler`] remembers, to drop their late copies' parts.
const DONE_WINDOW: usize = 4096;

/// Why a batch cannot be published.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SplitError {
    /// The server's `max_payload` is too small for any part.
    #[error(
        "the NATS server's max_payload of {0} bytes is too small (a trace node needs {MIN_MAX_PAYLOAD})"
    )]
    PayloadLimit(usize),
    /// The batch has more records than an edge accepts.
    #[error("a batch of {0} records is more than the {MAX_BATCH_RECORDS} an edge accepts")]
    TooManyRecords(usize),
    /// The batch needs more parts than an edge accepts.
    #[error(
        "a batch of {bytes} bytes compressed needs {parts} parts under the NATS server's \
         max_payload of {max_payload} bytes, more than {MAX_PARTS}"
    )]
    TooManyParts {
        bytes: usize,
        parts: usize,
        max_payload: usize,
    },
}

/// A batch as the payloads of its parts.
#[derive(Debug)]
pub struct Split {
    /// The parts' payloads, in order.
    pub parts: Vec<Vec<u8>>,
    /// Bytes of the batch's payload uncompressed.
    pub raw_bytes: usize,
}

/// Compress `batch` and cut it into parts whose messages fit `max_payload` bytes (headers
/// included).
pub fn split(batch: &Batch, max_payload: usize) -> Result<Split, SplitError> {
    if max_payload < MIN_MAX_PAYLOAD {
        return Err(SplitError::PayloadLimit(max_payload));
    }
    if batch.records.len() > MAX_BATCH_RECORDS {
        return Err(SplitError::TooManyRecords(batch.records.len()));
    }
    let raw = batch.encode();
    let packed = psao_delta::zstd_io::compress(&raw, LEVEL);
    let room = max_payload - PART_HEADER - NATS_HEADROOM;
    let parts = packed.len().div_ceil(room).max(1);
    if parts > MAX_PARTS as usize {
        return Err(SplitError::TooManyParts {
            bytes: packed.len(),
            parts,
            max_payload,
        });
    }
    let parts = packed
        .chunks(room)
        .enumerate()
        .map(|(k, data)| {
            BatchPart {
                partition: batch.partition,
                partitions: batch.partitions,
                frame: batch.frame,
                part: k as u32,
                parts: parts as u32,
                data: data.to_vec(),
            }
            .encode()
        })
        .collect();
    Ok(Split {
        parts,
        raw_bytes: raw.len(),
    })
}

/// What [`Reassembler::add`] did with a part.
#[derive(Debug, PartialEq)]
pub enum Reassembled {
    /// The part completed its batch.
    Complete(Batch),
    /// Kept until the batch's other parts arrive.
    Incomplete,
    /// A second copy of a part, or a part of a batch completed already: dropped.
    Duplicate,
    /// Its counts disagree with its batch's earlier parts', or the whole batch does not
    /// decode (or names another partition or frame than its parts): dropped, with the
    /// batch's parts received so far.
    Malformed(PayloadError),
}

/// The parts of one batch received so far.
struct Pending {
    partitions: u32,
    parts: u32,
    got: BTreeMap<u32, Vec<u8>>,
}

/// Gathers the parts of batches until each batch is whole. Holds at most
/// [`MAX_PENDING_BATCHES`] incomplete batches and [`MAX_PENDING_BYTES`] bytes: beyond them
/// the incomplete batches of the oldest frames are dropped (counted by
/// [`Reassembler::evicted`]).
#[derive(Default)]
pub struct Reassembler {
    /// Incomplete batches by (frame, partition).
    pending: BTreeMap<(u64, u32), Pending>,
    /// Bytes of the parts in `pending`.
    bytes: usize,
    /// The last [`DONE_WINDOW`] batches completed, by (frame, partition).
    done: BTreeSet<(u64, u32)>,
    evicted: u64,
}

impl Reassembler {
    /// Take in the part `payload`, which arrived on the subject of partition `subject` (a
    /// part claiming another partition is refused: a publisher allowed one partition's
    /// subject cannot forge another's); its batch when it was the last part missing.
    pub fn add_payload(&mut self, subject: Option<u32>, payload: &[u8]) -> Reassembled {
        match BatchPart::decode(payload) {
            Ok(part) if subject != Some(part.partition) => Reassembled::Malformed(fail(
                "record batch part",
                format!(
                    "claims partition {} on the subject of partition {subject:?}",
                    part.partition
                ),
            )),
            Ok(part) => self.add(part),
            Err(e) => Reassembled::Malformed(e),
        }
    }

    /// Take in `part`; its batch when it was the last part missing.
    pub fn add(&mut self, part: BatchPart) -> Reassembled {
        let key = (part.frame, part.partition);
        if self.done.contains(&key) {
            return Reassembled::Duplicate;
        }
        let what = "record batch part";
        let pending = self.pending.entry(key).or_insert_with(|| Pending {
            partitions: part.partitions,
            parts: part.parts,
            got: BTreeMap::new(),
        });
        if (pending.partitions, pending.parts) != (part.partitions, part.parts) {
            let reason = format!(
                "part {} of {} of {} partitions, after parts of {} of {} partitions",
                part.part, part.parts, part.partitions, pending.parts, pending.partitions
            );
            self.drop_pending(key);
            return Reassembled::Malformed(fail(what, reason));
        }
        if pending.got.contains_key(&part.part) {
            return Reassembled::Duplicate;
        }
        self.bytes += part.data.len();
        pending.got.insert(part.part, part.data);
        if pending.got.len() < pending.parts as usize {
            self.bound(key);
            return Reassembled::Incomplete;
        }
        let pending = self.drop_pending(key).expect("the batch is pending");
        self.done.insert(key);
        if self.done.len() > DONE_WINDOW {
            self.done.pop_first();
        }
        let packed: Vec<u8> = pending.got.into_values().flatten().collect();
        match unpack(&packed) {
            Ok(b) if (b.frame, b.partition, b.partitions) == (key.0, key.1, pending.partitions) => {
                Reassembled::Complete(b)
            }
            Ok(b) => Reassembled::Malformed(fail(
                what,
                format!(
                    "parts of partition {} frame {} hold partition {} frame {}",
                    key.1, key.0, b.partition, b.frame
                ),
            )),
            Err(e) => Reassembled::Malformed(e),
        }
    }

    /// Incomplete batches dropped to stay within the bounds.
    pub fn evicted(&self) -> u64 {
        self.evicted
    }

    /// Incomplete batches held, and the bytes of their parts.
    pub fn pending(&self) -> (usize, usize) {
        (self.pending.len(), self.bytes)
    }

    fn drop_pending(&mut self, key: (u64, u32)) -> Option<Pending> {
        let pending = self.pending.remove(&key)?;
        self.bytes -= pending.got.values().map(Vec::len).sum::<usize>();
        Some(pending)
    }

    /// Drop the oldest incomplete batches while over the bounds (`key`'s last, which just
    /// grew).
    fn bound(&mut self, key: (u64, u32)) {
        while self.pending.len() > MAX_PENDING_BATCHES || self.bytes > MAX_PENDING_BYTES {
            let oldest = self
                .pending
                .keys()
                .find(|&&k| k != key)
                .copied()
                .unwrap_or(key);
            self.drop_pending(oldest);
            self.evicted += 1;
        }
    }
}

/// The batch of a whole compressed payload (at most [`MAX_BATCH_RECORDS`] records).
fn unpack(packed: &[u8]) -> Result<Batch, PayloadError> {
    let limit = Batch::encoded_len(MAX_BATCH_RECORDS) as u64;
    let raw = psao_delta::zstd_io::decompress(packed, limit)
        .map_err(|e| fail("record batch", e.to_string()))?;
    Batch::decode(&raw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_server::PointRecord;

    /// A batch of `n` records that compress like traced ones (ordered points, AO bits that
    /// vary).
    fn batch(partition: u32, frame: u64, n: usize) -> Batch {
        let mut x = 0x9e37_79b9_u32 ^ frame as u32;
        Batch {
            partition,
            partitions: 2,
            frame,
            seconds: frame as f64 / 30.0,
            records: (0..n as u32)
                .map(|i| {
                    x ^= x << 13;
                    x ^= x >> 17;
                    x ^= x << 5;
                    PointRecord {
                        instance: i / 50_000,
                        index: i * 3,
                        bits: x,
                    }
                })
                .collect(),
        }
    }

    fn parts(b: &Batch, max_payload: usize) -> Vec<BatchPart> {
        let s = split(b, max_payload).unwrap();
        assert_eq!(s.raw_bytes, Batch::encoded_len(b.records.len()));
        let parts: Vec<BatchPart> = s
            .parts
            .iter()
            .map(|p| {
                assert!(p.len() + NATS_HEADROOM <= max_payload, "fits the limit");
                BatchPart::decode(p).unwrap()
            })
            .collect();
        for (k, p) in parts.iter().enumerate() {
            assert_eq!((p.part, p.parts), (k as u32, parts.len() as u32));
            assert_eq!((p.partition, p.frame), (b.partition, b.frame));
        }
        parts
    }

    #[test]
    fn a_default_budget_batch_fits_one_mib_and_comes_back_whole() {
        // 125 000 records: one partition's frame at the default ray budget (1.5 MB raw).
        let b = batch(1, 9, 125_000);
        let parts = parts(&b, 1 << 20);
        let mut r = Reassembler::default();
        let mut got = None;
        for p in parts {
            if let Reassembled::Complete(done) = r.add(p) {
                got = Some(done);
            }
        }
        assert_eq!(got, Some(b));
        assert_eq!(r.pending(), (0, 0));
    }

    #[test]
    fn parts_reassemble_in_any_order_and_duplicates_are_dropped() {
        let b = batch(0, 4, 20_000);
        let mut parts = parts(&b, 16 << 10);
        assert!(parts.len() > 3, "{} parts", parts.len());
        parts.reverse();
        parts.swap(0, 2);
        let mut r = Reassembler::default();
        let last = parts.pop().unwrap();
        for p in &parts {
            assert_eq!(r.add(p.clone()), Reassembled::Incomplete);
            assert_eq!(r.add(p.clone()), Reassembled::Duplicate, "second copy");
        }
        assert_eq!(r.add(last.clone()), Reassembled::Complete(b));
        assert_eq!(r.add(last), Reassembled::Duplicate, "batch done");
        assert_eq!(r.add(parts[0].clone()), Reassembled::Duplicate);
        assert_eq!(r.pending(), (0, 0));
    }

    #[test]
    fn a_batch_missing_a_part_is_never_given_and_other_batches_are_not_held_up() {
        let (a, b) = (batch(0, 1, 20_000), batch(1, 1, 20_000));
        let (pa, pb) = (parts(&a, 16 << 10), parts(&b, 16 << 10));
        let mut r = Reassembler::default();
        for p in pa.iter().skip(1) {
            assert_eq!(r.add(p.clone()), Reassembled::Incomplete);
        }
        let mut got = Vec::new();
        for p in pb {
            if let Reassembled::Complete(done) = r.add(p) {
                got.push(done);
            }
        }
        assert_eq!(got, [b]);
        assert_eq!(r.pending().0, 1, "partition 0 waits for its part 0");
        assert_eq!(r.add(pa[0].clone()), Reassembled::Complete(a));
    }

    #[test]
    fn forged_part_counts_are_refused_and_memory_stays_bounded() {
        let b = batch(0, 3, 20_000);
        let ps = parts(&b, 16 << 10);
        let mut r = Reassembler::default();
        assert_eq!(r.add(ps[0].clone()), Reassembled::Incomplete);
        let forged = BatchPart {
            parts: MAX_PARTS,
            ..ps[1].clone()
        };
        assert!(
            matches!(r.add(forged), Reassembled::Malformed(e) if e.to_string().contains("after parts of"))
        );
        assert_eq!(r.pending(), (0, 0), "the batch's parts are dropped");

        // Parts whose counts agree but whose whole is no batch.
        let junk = |part| BatchPart {
            partition: 0,
            partitions: 2,
            frame: 8,
            part,
            parts: 2,
            data: vec![7; 100],
        };
        assert_eq!(r.add(junk(0)), Reassembled::Incomplete);
        assert!(matches!(r.add(junk(1)), Reassembled::Malformed(_)));
        // A whole batch under another batch's name.
        let mut renamed = parts(&batch(1, 5, 10), 1 << 20);
        renamed[0].frame = 6;
        assert!(
            matches!(r.add(renamed.remove(0)), Reassembled::Malformed(e) if e.to_string().contains("hold partition 1 frame 5"))
        );

        // Many batches that never complete, each claiming the most parts: the oldest go.
        let data = vec![0; 64 << 10];
        for frame in 0..(MAX_PENDING_BATCHES as u64 + 100) {
            let p = BatchPart {
                partition: 0,
                partitions: 2,
                frame: 100 + frame,
                part: 0,
                parts: MAX_PARTS,
                data: data.clone(),
            };
            assert_eq!(r.add(p), Reassembled::Incomplete);
            let (batches, bytes) = r.pending();
            assert!(batches <= MAX_PENDING_BATCHES && bytes <= MAX_PENDING_BYTES);
        }
        assert!(r.evicted() >= 100);
        assert_eq!(
            r.add(ps[1].clone()),
            Reassembled::Incomplete,
            "a real batch still gathers"
        );
    }

    #[test]
    fn the_largest_batch_splits_and_comes_back_and_one_more_record_is_refused() {
        let mut b = batch(0, 2, 1000);
        b.records = (0..MAX_BATCH_RECORDS as u32)
            .map(|i| PointRecord {
                instance: 0,
                index: i,
                bits: i.wrapping_mul(2_654_435_761),
            })
            .collect();
        let mut r = Reassembler::default();
        let mut got = None;
        for p in parts(&b, 1 << 20) {
            if let Reassembled::Complete(done) = r.add(p) {
                got = Some(done);
            }
        }
        assert_eq!(got.as_ref(), Some(&b));
        b.records.push(b.records[0]);
        assert_eq!(
            split(&b, 1 << 20).unwrap_err(),
            SplitError::TooManyRecords(MAX_BATCH_RECORDS + 1)
        );
    }

    #[test]
    fn a_tiny_payload_limit_is_an_error_not_a_part_that_cannot_fit() {
        let b = batch(0, 1, 400_000);
        assert_eq!(split(&b, 1000).unwrap_err(), SplitError::PayloadLimit(1000));
        assert!(matches!(
            split(&b, MIN_MAX_PAYLOAD),
            Err(SplitError::TooManyParts { .. })
        ));
    }
}
