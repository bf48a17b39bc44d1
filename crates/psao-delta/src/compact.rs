//! The `compact` codec (DESIGN §4, our default): every record is XORed against the state last
//! sent for the same slot, indices are delta-coded varints in their own stream, payload words
//! are split into byte planes per record kind, and the whole is compressed with zstd at a low
//! level.
//!
//! Payload before compression (integers little-endian):
//! ```text
//! tag "PSC1" · flags u32 (bit 0 snapshot) · frame u64 · index stream length u32 ·
//! cell word count u32
//! index stream (LEB128 varints, zigzag for deltas):
//!     transform count · per transform: instance − previous instance (previous starts at −1)
//!     instance count · per instance: instance − previous, bucket count, cell count,
//!         bucket index − previous (from −1) per bucket, cell slot − previous (from −1) per cell
//! cell lengths: one byte per cell (in index order), its number of points (0..=7)
//! planes, four groups in this order, each stored as its 4 byte planes (byte 0 of every
//! word, then byte 1, …):
//!     transforms: 12 words each (Affine3A columns, f32 bits)
//!     bucket keys: 16 words each (8 keys, low word then high word)
//!     bucket slots: 8 words each
//!     cells: per cell the first max(new length, reference length) words
//! ```
//! Every word is XORed with the word at the same position of the same slot (instance +
//! bucket index, instance + cell slot, or instance for transforms) as last sent in this
//! session, or with 0 if never sent; a snapshot starts from an empty state. Buckets and cells
//! are compacted (empty entries last) first, so they decode exactly as the `paper` codec
//! does. Cell words past both the new and the reference length are zero after XOR and are
//! not stored. Both ends must see the same sequence of updates; after a decoding error the
//! decoder's state is undefined and the session must start again (with a snapshot).

use glam::Affine3A;
use psao_points::{Bucket, BucketEntry, Cell, KeyMap, BUCKET_ENTRIES, CELL_POINTS};

use crate::model::{compact_bucket, compact_cell, InstanceDelta, Update};
use crate::{Codec, DeltaError, MAX_DECODED_BYTES};

/// zstd level of the compact codec.
pub const COMPACT_LEVEL: i32 = 3;

const TAG: u32 = u32::from_le_bytes(*b"PSC1");
const FLAG_SNAPSHOT: u32 = 1;
const HEADER_BYTES: usize = 24;
const TRANSFORM_WORDS: usize = 12;
const KEY_WORDS: usize = 2 * BUCKET_ENTRIES;
const SLOT_WORDS: usize = BUCKET_ENTRIES;

fn key(instance: u32, index: u32) -> u64 {
    (u64::from(instance) << 32) | u64::from(index)
}

/// What was last sent, per slot: the XOR reference of both ends.
#[derive(Default, Clone)]
struct Reference {
    transforms: KeyMap<[u32; TRANSFORM_WORDS]>,
    keys: KeyMap<[u32; KEY_WORDS]>,
    slots: KeyMap<[u32; SLOT_WORDS]>,
    cells: KeyMap<[u32; CELL_POINTS]>,
}

impl Reference {
    fn clear(&mut self) {
        *self = Self::default();
    }
}

/// XOR `words` with the reference stored under `k` and store `words` as the new reference.
fn xor_encode<const N: usize>(
    map: &mut KeyMap<[u32; N]>,
    k: u64,
    words: [u32; N],
    out: &mut Vec<u32>,
) {
    let prev = map.insert(k, words).unwrap_or([0; N]);
    out.extend(words.iter().zip(prev).map(|(w, p)| w ^ p));
}

/// Undo [`xor_encode`]: the words after XOR with the reference, stored as the new reference.
fn xor_decode<const N: usize>(map: &mut KeyMap<[u32; N]>, k: u64, coded: &[u32]) -> [u32; N] {
    let prev = map.get(&k).copied().unwrap_or([0; N]);
    let mut words = [0u32; N];
    for ((w, c), p) in words.iter_mut().zip(coded).zip(prev) {
        *w = c ^ p;
    }
    map.insert(k, words);
    words
}

fn bucket_words(bucket: &Bucket) -> ([u32; KEY_WORDS], [u32; SLOT_WORDS]) {
    let b = compact_bucket(bucket);
    let mut keys = [0u32; KEY_WORDS];
    let mut slots = [0u32; SLOT_WORDS];
    for (i, e) in b.entries.iter().enumerate() {
        keys[2 * i] = e.key as u32;
        keys[2 * i + 1] = (e.key >> 32) as u32;
        slots[i] = e.slot;
    }
    (keys, slots)
}

/// The compact codec. Stateful: one instance per sending or receiving end of a session.
#[derive(Clone)]
pub struct CompactCodec {
    reference: Reference,
    level: i32,
    decode_limit: u64,
}

impl Default for CompactCodec {
    fn default() -> Self {
        Self::new()
    }
}

impl std::fmt::Debug for CompactCodec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CompactCodec")
            .field("level", &self.level)
            .field("decode_limit", &self.decode_limit)
            .field("reference_cells", &self.reference.cells.len())
            .finish()
    }
}

impl CompactCodec {
    /// A codec with an empty reference state, [`COMPACT_LEVEL`] and the
    /// [`MAX_DECODED_BYTES`] decoding limit.
    pub fn new() -> Self {
        Self {
            reference: Reference::default(),
            level: COMPACT_LEVEL,
            decode_limit: MAX_DECODED_BYTES,
        }
    }
}

/// Word groups of one update, XORed, before byte-plane shuffling.
#[derive(Default)]
struct Groups {
    transforms: Vec<u32>,
    keys: Vec<u32>,
    slots: Vec<u32>,
    cells: Vec<u32>,
    cell_lengths: Vec<u8>,
}

/// Words of a cell up to its last non-zero one.
fn cell_len(words: &[u32; CELL_POINTS]) -> usize {
    words.iter().rposition(|&w| w != 0).map_or(0, |i| i + 1)
}

impl Codec for CompactCodec {
    fn name(&self) -> &'static str {
        "compact"
    }

    fn encode(&mut self, update: &Update) -> Vec<u8> {
        if update.snapshot {
            self.reference.clear();
        }
        let r = &mut self.reference;
        let mut index = Vec::new();
        let mut g = Groups::default();
        put_varint(&mut index, update.transforms.len() as u64);
        let mut prev = -1i64;
        for (instance, t) in &update.transforms {
            put_delta(&mut index, &mut prev, *instance);
            let words = t.to_cols_array().map(f32::to_bits);
            xor_encode(
                &mut r.transforms,
                u64::from(*instance),
                words,
                &mut g.transforms,
            );
        }
        put_varint(&mut index, update.instances.len() as u64);
        let mut prev_instance = -1i64;
        for d in &update.instances {
            put_delta(&mut index, &mut prev_instance, d.instance);
            put_varint(&mut index, d.buckets.len() as u64);
            put_varint(&mut index, d.cells.len() as u64);
            let mut prev = -1i64;
            for (b, bucket) in &d.buckets {
                put_delta(&mut index, &mut prev, *b);
                let (keys, slots) = bucket_words(bucket);
                xor_encode(&mut r.keys, key(d.instance, *b), keys, &mut g.keys);
                xor_encode(&mut r.slots, key(d.instance, *b), slots, &mut g.slots);
            }
            let mut prev = -1i64;
            for (s, cell) in &d.cells {
                put_delta(&mut index, &mut prev, *s);
                let words = compact_cell(cell).points;
                let prev = r
                    .cells
                    .insert(key(d.instance, *s), words)
                    .unwrap_or_default();
                let n = cell_len(&words);
                g.cell_lengths.push(n as u8);
                let m = n.max(cell_len(&prev));
                g.cells
                    .extend(words[..m].iter().zip(&prev[..m]).map(|(w, p)| w ^ p));
            }
        }
        let words = g.transforms.len() + g.keys.len() + g.slots.len() + g.cells.len();
        let mut payload =
            Vec::with_capacity(HEADER_BYTES + index.len() + g.cell_lengths.len() + 4 * words);
        payload.extend_from_slice(&TAG.to_le_bytes());
        let flags = if update.snapshot { FLAG_SNAPSHOT } else { 0 };
        payload.extend_from_slice(&flags.to_le_bytes());
        payload.extend_from_slice(&update.frame.to_le_bytes());
        payload.extend_from_slice(&(index.len() as u32).to_le_bytes());
        payload.extend_from_slice(&(g.cells.len() as u32).to_le_bytes());
        payload.extend_from_slice(&index);
        payload.extend_from_slice(&g.cell_lengths);
        for group in [&g.transforms, &g.keys, &g.slots, &g.cells] {
            shuffle_into(group, &mut payload);
        }
        crate::zstd_io::compress(&payload, self.level)
    }

    fn decode(&mut self, bytes: &[u8]) -> Result<Update, DeltaError> {
        let payload = crate::zstd_io::decompress(bytes, self.decode_limit)?;
        let header = payload.get(..HEADER_BYTES).ok_or(DeltaError::Truncated {
            what: "compact header",
            needed: HEADER_BYTES as u64,
            available: payload.len(),
        })?;
        let word =
            |i: usize| u32::from_le_bytes([header[i], header[i + 1], header[i + 2], header[i + 3]]);
        if word(0) != TAG {
            return Err(DeltaError::BadTag {
                found: word(0),
                expected: TAG,
            });
        }
        let flags = word(4);
        if flags & !FLAG_SNAPSHOT != 0 {
            return Err(DeltaError::UnknownFlags(flags));
        }
        let frame = u64::from(word(8)) | (u64::from(word(12)) << 32);
        let index_len = word(16) as usize;
        let cell_words = u64::from(word(20));
        let rest = &payload[HEADER_BYTES..];
        if index_len > rest.len() {
            return Err(DeltaError::Truncated {
                what: "index stream",
                needed: index_len as u64,
                available: rest.len(),
            });
        }
        let (index, rest) = rest.split_at(index_len);
        let layout = parse_index(index)?;
        let cells = layout.cells() as usize;
        if cells > rest.len() {
            return Err(DeltaError::Truncated {
                what: "cell lengths",
                needed: cells as u64,
                available: rest.len(),
            });
        }
        let (lengths, planes) = rest.split_at(cells);
        let words = layout.fixed_words() + cell_words;
        if planes.len() as u64 != words * 4 {
            return Err(DeltaError::PlaneSize {
                expected: words * 4,
                found: planes.len() as u64,
            });
        }
        if flags & FLAG_SNAPSHOT != 0 {
            self.reference.clear();
        }
        let snapshot = flags & FLAG_SNAPSHOT != 0;
        assemble(
            &layout,
            lengths,
            planes,
            frame,
            snapshot,
            &mut self.reference,
        )
    }

    fn set_decode_limit(&mut self, bytes: u64) {
        self.decode_limit = bytes.min(MAX_DECODED_BYTES);
    }
}

/// The parsed index stream: which slots the planes hold.
struct IndexLayout {
    transforms: Vec<u32>,
    instances: Vec<(u32, Vec<u32>, Vec<u32>)>,
}

impl IndexLayout {
    fn buckets(&self) -> u64 {
        self.instances.iter().map(|i| i.1.len() as u64).sum()
    }
    fn cells(&self) -> u64 {
        self.instances.iter().map(|i| i.2.len() as u64).sum()
    }
    /// Plane words of the transforms and buckets (cells vary in length).
    fn fixed_words(&self) -> u64 {
        self.transforms.len() as u64 * TRANSFORM_WORDS as u64
            + self.buckets() * (KEY_WORDS + SLOT_WORDS) as u64
    }
}

/// Parse the index stream; every count is checked against the bytes left (each entry takes
/// at least one byte) before allocating.
fn parse_index(bytes: &[u8]) -> Result<IndexLayout, DeltaError> {
    let mut r = VarReader { bytes };
    let n = r.count("transform count")?;
    let mut prev = -1i64;
    let transforms = (0..n)
        .map(|_| r.delta(&mut prev, "transform instance"))
        .collect::<Result<Vec<_>, _>>()?;
    let n = r.count("instance count")?;
    let mut instances = Vec::with_capacity(n);
    let mut prev_instance = -1i64;
    for _ in 0..n {
        let instance = r.delta(&mut prev_instance, "instance")?;
        let nb = r.count("bucket count")?;
        let nc = r.count("cell count")?;
        let mut prev = -1i64;
        let buckets = (0..nb)
            .map(|_| r.delta(&mut prev, "bucket index"))
            .collect::<Result<Vec<_>, _>>()?;
        let mut prev = -1i64;
        let cells = (0..nc)
            .map(|_| r.delta(&mut prev, "cell slot"))
            .collect::<Result<Vec<_>, _>>()?;
        instances.push((instance, buckets, cells));
    }
    if !r.bytes.is_empty() {
        return Err(DeltaError::Trailing(r.bytes.len()));
    }
    Ok(IndexLayout {
        transforms,
        instances,
    })
}

/// Rebuild the update from the checked layout and planes, updating the reference state.
fn assemble(
    layout: &IndexLayout,
    lengths: &[u8],
    planes: &[u8],
    frame: u64,
    snapshot: bool,
    r: &mut Reference,
) -> Result<Update, DeltaError> {
    let nt = layout.transforms.len() * TRANSFORM_WORDS;
    let nb = layout.buckets() as usize;
    let (t_planes, rest) = planes.split_at(nt * 4);
    let (k_planes, rest) = rest.split_at(nb * KEY_WORDS * 4);
    let (s_planes, c_planes) = rest.split_at(nb * SLOT_WORDS * 4);
    let t_words = unshuffle(t_planes);
    let k_words = unshuffle(k_planes);
    let s_words = unshuffle(s_planes);
    let c_words = unshuffle(c_planes);

    let transforms = layout
        .transforms
        .iter()
        .zip(t_words.chunks_exact(TRANSFORM_WORDS))
        .map(|(&instance, coded)| {
            let words: [u32; TRANSFORM_WORDS] =
                xor_decode(&mut r.transforms, u64::from(instance), coded);
            (
                instance,
                Affine3A::from_cols_array(&words.map(f32::from_bits)),
            )
        })
        .collect();
    let mut keys = k_words.chunks_exact(KEY_WORDS);
    let mut slots = s_words.chunks_exact(SLOT_WORDS);
    let mut cell_words = &c_words[..];
    let mut lengths = lengths.iter();
    let instances = layout
        .instances
        .iter()
        .map(|(instance, bucket_ids, slot_ids)| {
            let buckets = bucket_ids
                .iter()
                .zip(keys.by_ref().zip(slots.by_ref()))
                .map(|(&b, (kc, sc))| {
                    let k: [u32; KEY_WORDS] = xor_decode(&mut r.keys, key(*instance, b), kc);
                    let s: [u32; SLOT_WORDS] = xor_decode(&mut r.slots, key(*instance, b), sc);
                    let mut bucket = Bucket::default();
                    for (i, e) in bucket.entries.iter_mut().enumerate() {
                        *e = BucketEntry {
                            key: u64::from(k[2 * i]) | (u64::from(k[2 * i + 1]) << 32),
                            slot: s[i],
                        };
                    }
                    (b, bucket)
                })
                .collect();
            let cells = slot_ids
                .iter()
                .zip(lengths.by_ref())
                .map(|(&s, &n)| {
                    let k = key(*instance, s);
                    let prev = r.cells.get(&k).copied().unwrap_or_default();
                    let n = usize::from(n);
                    if n > CELL_POINTS {
                        return Err(DeltaError::CellLength(n));
                    }
                    let m = n.max(cell_len(&prev));
                    let (coded, rest) =
                        cell_words
                            .split_at_checked(m)
                            .ok_or(DeltaError::PlaneSize {
                                expected: c_words.len() as u64 + m as u64,
                                found: c_words.len() as u64,
                            })?;
                    cell_words = rest;
                    let mut points = prev;
                    points.iter_mut().zip(coded).for_each(|(p, c)| *p ^= c);
                    r.cells.insert(k, points);
                    Ok((s, Cell { points }))
                })
                .collect::<Result<_, _>>()?;
            Ok(InstanceDelta {
                instance: *instance,
                buckets,
                cells,
            })
        })
        .collect::<Result<_, _>>()?;
    if !cell_words.is_empty() {
        return Err(DeltaError::Trailing(cell_words.len()));
    }
    Ok(Update {
        frame,
        snapshot,
        transforms,
        instances,
    })
}

/// Append the byte planes of `words`: byte 0 of every word, then byte 1, …
fn shuffle_into(words: &[u32], out: &mut Vec<u8>) {
    for plane in 0..4 {
        out.extend(words.iter().map(|w| (w >> (8 * plane)) as u8));
    }
}

/// Inverse of [`shuffle_into`] (`planes.len()` is a multiple of 4).
fn unshuffle(planes: &[u8]) -> Vec<u32> {
    let n = planes.len() / 4;
    let mut words = vec![0u32; n];
    for plane in 0..4 {
        for (w, &b) in words.iter_mut().zip(&planes[plane * n..(plane + 1) * n]) {
            *w |= u32::from(b) << (8 * plane);
        }
    }
    words
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Append `value − prev` zigzag-coded and make `value` the new `prev`.
fn put_delta(out: &mut Vec<u8>, prev: &mut i64, value: u32) {
    let d = i64::from(value) - *prev;
    *prev = i64::from(value);
    put_varint(out, ((d << 1) ^ (d >> 63)) as u64);
}

/// Reads LEB128 varints with bounds and overflow checks.
struct VarReader<'a> {
    bytes: &'a [u8],
}

impl VarReader<'_> {
    fn varint(&mut self, what: &'static str) -> Result<u64, DeltaError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let Some((&b, rest)) = self.bytes.split_first() else {
                return Err(DeltaError::Truncated {
                    what,
                    needed: 1,
                    available: 0,
                });
            };
            self.bytes = rest;
            let bits = u64::from(b & 0x7f);
            if shift == 63 && bits > 1 {
                return Err(DeltaError::BadVarint(what));
            }
            v |= bits << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(DeltaError::BadVarint(what))
    }

    /// A count of entries that each take at least one more byte.
    fn count(&mut self, what: &'static str) -> Result<usize, DeltaError> {
        let n = self.varint(what)?;
        if n > self.bytes.len() as u64 {
            return Err(DeltaError::Truncated {
                what,
                needed: n,
                available: self.bytes.len(),
            });
        }
        Ok(n as usize)
    }

    /// A zigzag delta against `prev`; the result must be a `u32`.
    fn delta(&mut self, prev: &mut i64, what: &'static str) -> Result<u32, DeltaError> {
        let z = self.varint(what)?;
        let d = (z >> 1) as i64 ^ -((z & 1) as i64);
        let v = prev
            .checked_add(d)
            .and_then(|v| u32::try_from(v).ok())
            .ok_or(DeltaError::BadVarint(what))?;
        *prev = i64::from(v);
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PaperCodec;
    use psao_points::pack::VALID_BIT;

    fn cell(ao: u32, n: usize) -> Cell {
        let mut c = Cell::default();
        for (i, p) in c.points.iter_mut().take(n).enumerate() {
            let noise = (ao ^ (i as u32 + 1)).wrapping_mul(0x9e37_79b9) & 0x7fff_ff00;
            *p = VALID_BIT | noise | (ao & 0xff);
        }
        c
    }

    fn update(frame: u64, snapshot: bool, ao: u32, slots: std::ops::Range<u32>) -> Update {
        let mut bucket = Bucket::default();
        bucket.entries[3] = BucketEntry::new(5 + (1u64 << 33), 2);
        bucket.entries[5] = BucketEntry::new(9, 4);
        Update {
            frame,
            snapshot,
            transforms: vec![
                (0, Affine3A::IDENTITY),
                (
                    2,
                    Affine3A::from_translation(glam::Vec3::new(1.0, 2.0, frame as f32)),
                ),
            ],
            instances: vec![
                InstanceDelta {
                    instance: 0,
                    buckets: vec![(7, bucket), (3, Bucket::default())],
                    cells: slots
                        .clone()
                        .map(|s| (s, cell(ao + s, (s + ao) as usize % 8)))
                        .collect(),
                },
                InstanceDelta {
                    instance: 2,
                    buckets: vec![],
                    cells: vec![(40, cell(ao, 7)), (2, cell(ao, 3))],
                },
            ],
        }
    }

    /// What the paper codec decodes (compacted records): the compact codec must agree.
    fn paper_round_trip(u: &Update) -> Update {
        let mut p = PaperCodec;
        let bytes = p.encode(u);
        p.decode(&bytes).unwrap()
    }

    #[test]
    fn round_trips_a_session_like_the_paper_codec() {
        let mut enc = CompactCodec::new();
        let mut dec = CompactCodec::new();
        let session = [
            update(1, true, 10, 0..50),
            update(2, false, 11, 10..30),
            update(3, false, 12, 0..5),
            update(4, true, 13, 3..9),
            update(5, false, 13, 3..9),
        ];
        for u in &session {
            let bytes = enc.encode(u);
            assert_eq!(dec.decode(&bytes).unwrap(), paper_round_trip(u));
        }
    }

    #[test]
    fn unchanged_records_cost_almost_nothing() {
        let mut enc = CompactCodec::new();
        let first = enc.encode(&update(1, true, 10, 0..2000));
        let again = enc.encode(&update(1, false, 10, 0..2000));
        assert!(
            again.len() * 10 < first.len(),
            "{} vs {}",
            again.len(),
            first.len()
        );
    }

    #[test]
    fn rejects_malformed_input_without_panicking() {
        let mut enc = CompactCodec::new();
        let good = enc.encode(&update(1, true, 10, 0..20));
        let mut dec = CompactCodec::new();
        assert!(dec.decode(&[]).is_err());
        assert!(dec.decode(&good[..good.len() / 2]).is_err());
        let mut flipped = good.clone();
        let mid = flipped.len() / 2;
        flipped[mid] ^= 0x40;
        assert!(
            dec.decode(&flipped).is_err(),
            "zstd checksum must catch a flipped bit"
        );
        // Well-compressed but wrong payloads.
        let z = |p: &[u8]| crate::zstd_io::compress(p, 1);
        assert!(matches!(
            dec.decode(&z(b"PSD1")),
            Err(DeltaError::Truncated { .. })
        ));
        let mut p = Vec::new();
        p.extend_from_slice(b"PSC1");
        p.extend_from_slice(&0u32.to_le_bytes());
        p.extend_from_slice(&7u64.to_le_bytes());
        p.extend_from_slice(&3u32.to_le_bytes());
        p.extend_from_slice(&0u32.to_le_bytes());
        p.extend_from_slice(&[1, 2, 0]); // one transform, no instances, but no planes
        assert!(matches!(
            dec.decode(&z(&p)),
            Err(DeltaError::PlaneSize { .. })
        ));
        let mut huge = p[..24].to_vec();
        huge[16] = 11;
        huge.extend_from_slice(&[0xff; 10]); // a varint longer than 64 bits
        huge.push(0);
        assert!(matches!(
            dec.decode(&z(&huge)),
            Err(DeltaError::BadVarint(_))
        ));
        let mut count = p[..24].to_vec();
        count[16] = 5;
        count.extend_from_slice(&[0xff, 0xff, 0xff, 0xff, 0x0f]); // 4 G transforms
        assert!(matches!(
            dec.decode(&z(&count)),
            Err(DeltaError::Truncated { .. })
        ));
        let mut flags = p.clone();
        flags[4] = 2;
        assert!(matches!(
            dec.decode(&z(&flags)),
            Err(DeltaError::UnknownFlags(2))
        ));
    }

    #[test]
    fn decompression_bombs_are_refused_before_allocating() {
        let bomb = crate::zstd_io::compress(&vec![0u8; 64 << 20], 1);
        assert!(bomb.len() < 64 << 10);
        let mut dec = CompactCodec::new();
        dec.set_decode_limit(1 << 20);
        assert!(matches!(
            dec.decode(&bomb),
            Err(DeltaError::TooLarge { .. })
        ));
    }

    #[test]
    fn varints_round_trip_at_the_edges() {
        let mut out = Vec::new();
        for v in [0, 1, 127, 128, u64::from(u32::MAX), u64::MAX] {
            out.clear();
            put_varint(&mut out, v);
            assert_eq!(VarReader { bytes: &out }.varint("v").unwrap(), v);
        }
        let mut prev = -1;
        let mut out = Vec::new();
        for v in [0u32, u32::MAX, 5, 5, 0] {
            put_delta(&mut out, &mut prev, v);
        }
        let mut r = VarReader { bytes: &out };
        let mut prev = -1;
        for v in [0u32, u32::MAX, 5, 5, 0] {
            assert_eq!(r.delta(&mut prev, "d").unwrap(), v);
        }
    }
}
