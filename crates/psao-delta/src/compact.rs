//! The `compact` codec (DESIGN §4, our default): every record is predicted from a reference
//! (what was last sent for the same slot, or its neighbour in the update), indices are
//! delta-coded varints, residuals are split into byte planes per record kind, and the whole
//! is compressed with zstd at a low level.
//!
//! Payload before compression (integers little-endian):
//! ```text
//! tag "PSC2" · flags u32 (bit 0 snapshot) · frame u64 · index stream length u32 ·
//! coded bucket entries E u32 · coded points P u32
//! index stream (LEB128 varints, zigzag for deltas):
//!     transform count · per transform: instance − previous instance (previous starts at −1)
//!     instance count · per instance: instance − previous, bucket count, cell count,
//!         bucket index − previous (from −1) per bucket, cell slot − previous (from −1) per cell
//! entry counts: one byte per bucket (in index order): (used entries − the reference's) mod 9
//! cell lengths: one byte per cell (in index order): (points − the reference's) mod 8
//! entry choices: E bytes (0..=8) · point choices: P bytes (0..=13)
//! key residuals: 8 byte planes of E u64 (byte 0 of every residual, then byte 1, …)
//! slot residuals: 4 byte planes of E u32 · point residuals: 4 byte planes of P u32
//! transforms: 12 words each (Affine3A columns, f32 bits), XORed with the reference, 4 planes
//! [flag bit 1, lights: light residuals: 4 byte planes of P u32]
//! ```
//! The reference of a slot (instance + bucket index, instance + cell slot, or instance for
//! transforms) is its content as last sent in this session, empty if never sent; a snapshot
//! starts from an empty state. Buckets and cells are compacted (used entries first) so they
//! decode exactly as the `paper` codec does; only used entries and points are coded, and the
//! sums of the decoded counts must equal E and P.
//!
//! * Bucket entry `i` (key ≠ 0) with choice `c` in 0..=7 is coded against entry
//!   `(i + c) mod 8` of its bucket's reference (an empty one past its used entries): with
//!   `t(key) = (key − 1) XOR bucket index` (the cell id with the bits that chose its bucket
//!   cleared) and `t = 0` for an empty entry, the key residual is `t(key) XOR t(reference)`
//!   and the slot residual `slot XOR reference slot`. Choice 8: the key residual is `t(key)`
//!   and the slot residual the position of the entry's cell in this instance's cell list of
//!   the update (a cell published for the first time arrives with its bucket entry).
//! * Point `i` of a cell with choice `c` in 0..=6 is coded against point `(i + c) mod 7` of
//!   the cell's reference (0 past its points); with `c` in 7..=13 against point `c − 7` of
//!   the previous cell of the instance in the update (0 for the first). The residual holds,
//!   in each field's own bits (position x, y, z, octahedral u, v, AO; `psao_points::pack`),
//!   the zigzag-coded difference `field − reference field` modulo the field's range; the
//!   valid bit is not coded (every coded point is valid) and must be 0.
//!
//! * With lighting (flag bit 1) every coded point also has an irradiance record (RGB9E5,
//!   `psao_points::irradiance`): its residual is the record XOR the irradiance record of the
//!   point its choice refers to (the same reference point as its point residual). A cell sent
//!   without lights has zero irradiance records in the reference.
//!
//! The encoder picks each choice to make the residual small: a point inserted into or removed
//! from a cell shifts the others, a moving point changes its position fields a little, a new
//! point resembles a point of the neighbouring cell; any choice decodes exactly. Both ends
//! must see the same sequence of updates; after a decoding error the decoder's state is
//! undefined and the session must start again (with a snapshot).

use glam::Affine3A;
use psao_points::pack::VALID_BIT;
use psao_points::{
    vec_bytes, Bucket, BucketEntry, Cell, KeyMap, PagedRuns, BUCKET_ENTRIES, CELL_POINTS,
};

use crate::model::{compact_bucket, compact_cell, InstanceDelta, Update};
use crate::{Codec, DeltaError, MAX_DECODED_BYTES, MAX_DECODE_LIMIT};

/// zstd level of the compact codec.
pub const COMPACT_LEVEL: i32 = 3;

const TAG: u32 = u32::from_le_bytes(*b"PSC2");
const FLAG_SNAPSHOT: u32 = 1;
const FLAG_LIGHTS: u32 = 2;
const HEADER_BYTES: usize = 28;
const TRANSFORM_WORDS: usize = 12;
/// Point choices: the 7 points of the cell's reference, the 7 points of the previous cell.
const POINT_CHOICES: u8 = 2 * CELL_POINTS as u8;
/// Set residual bits up to which the encoder takes a point of the cell's reference for the
/// same point (moved or re-shaded) and stops looking at other candidates.
const SAME_POINT_BITS: u32 = 8;
/// (shift, bits) of the point record's fields below the valid bit (`psao_points::pack`).
const FIELDS: [(u32, u32); 6] = [(26, 5), (21, 5), (16, 5), (12, 4), (8, 4), (0, 8)];
/// Bytes per coded bucket entry outside the choice: 8 key, 4 slot.
const ENTRY_BYTES: u64 = 12;
/// Bytes per coded point outside the choice.
const POINT_BYTES: u64 = 4;

/// A compacted bucket as the reference keeps it.
#[derive(Clone, Copy, Default)]
struct Entries {
    keys: [u64; BUCKET_ENTRIES],
    slots: [u32; BUCKET_ENTRIES],
}

impl Entries {
    /// The keys and slots of compacted `bucket`.
    fn of(bucket: &Bucket) -> Self {
        Self {
            keys: bucket.entries.map(|e| e.key),
            slots: bucket.entries.map(|e| e.slot),
        }
    }

    /// The entries of a run of the encoder's reference (empty past it).
    fn of_run(run: &[SentEntry]) -> Self {
        let mut out = Self::default();
        for (i, &[low, high, slot]) in run.iter().enumerate() {
            out.keys[i] = u64::from(low) | (u64::from(high) << 32);
            out.slots[i] = slot;
        }
        out
    }
}

/// A used bucket entry in the encoder's reference: the key's low and high words, the slot.
type SentEntry = [u32; 3];

/// What the encoder last sent for one instance, stored for what its receiver holds
/// ([`PagedRuns`] by bucket index and by cell slot): a receiver holds the part of the
/// server's grid its views reached, while the indices run over the server's whole table.
#[derive(Default, Clone)]
struct SentInstance {
    /// The used entries of every bucket, in order.
    buckets: PagedRuns<SentEntry>,
    /// The points of every cell, in order.
    cells: PagedRuns<u32>,
    /// The irradiance records of every cell's points (none when sent without lights).
    lights: PagedRuns<u32>,
}

impl SentInstance {
    /// Store compacted `bucket` at `index` and return the entries it replaces.
    fn swap_bucket(&mut self, index: u32, bucket: &Bucket) -> Entries {
        let old = Entries::of_run(self.buckets.get(index));
        let mut run = [[0; 3]; BUCKET_ENTRIES];
        let n = used_entries(&bucket.entries.map(|e| e.key));
        for (dst, e) in run.iter_mut().zip(&bucket.entries[..n]) {
            *dst = [e.key as u32, (e.key >> 32) as u32, e.slot];
        }
        self.buckets.set(index, &run[..n]);
        old
    }

    /// Store compacted `points` at `slot` and return the points they replace.
    fn swap_cell(&mut self, slot: u32, points: &[u32; CELL_POINTS]) -> [u32; CELL_POINTS] {
        let old = padded(self.cells.get(slot));
        self.cells.set(slot, &points[..used_points(points)]);
        old
    }

    /// Store the first `n` irradiance records of `light` (0 past them) at `slot` and return
    /// the records they replace.
    fn swap_light(
        &mut self,
        slot: u32,
        light: &[u32; CELL_POINTS],
        n: usize,
    ) -> [u32; CELL_POINTS] {
        let old = padded(self.lights.get(slot));
        self.lights.set(slot, &light[..n]);
        old
    }
}

/// A cell's records from a run (0 past it).
fn padded(run: &[u32]) -> [u32; CELL_POINTS] {
    let mut out = [0; CELL_POINTS];
    out[..run.len()].copy_from_slice(run);
    out
}

/// The encoder's reference: what it last sent in this session, which is what its receiver
/// holds (transforms by instance, the rest per instance as a [`SentInstance`]).
#[derive(Default, Clone)]
struct Sent {
    transforms: Vec<[u32; TRANSFORM_WORDS]>,
    instances: Vec<SentInstance>,
}

impl Sent {
    /// Forget everything (a snapshot follows), freeing the records.
    fn clear(&mut self) {
        self.transforms.clear();
        for i in &mut self.instances {
            i.buckets.clear();
            i.cells.clear();
            i.lights.clear();
        }
    }

    /// Heap bytes of the reference (allocated capacity).
    fn heap_bytes(&self) -> u64 {
        let runs = self
            .instances
            .iter()
            .map(|i| i.buckets.heap_bytes() + i.cells.heap_bytes() + i.lights.heap_bytes());
        vec_bytes(&self.transforms) + vec_bytes(&self.instances) + runs.sum::<u64>()
    }

    /// Points held (all instances).
    fn points(&self) -> usize {
        self.instances.iter().map(|i| i.cells.len()).sum()
    }
}

/// Records stored densely by instance, bucket index and cell slot: the decoder's reference
/// ([`Reference`]), whose indices come from the wire.
#[derive(Default, Clone)]
struct Received {
    transforms: Vec<[u32; TRANSFORM_WORDS]>,
    buckets: Vec<Vec<Entries>>,
    cells: Vec<Vec<[u32; CELL_POINTS]>>,
    /// Irradiance records of the cells' points (empty until a lit update).
    lights: Vec<Vec<[u32; CELL_POINTS]>>,
}

/// The decoder's reference: what it last received, dense like the encoder's. Its indices
/// come from the wire, so every element it grows by is charged to a byte budget, the decode
/// limit: a legitimate stream's indices stay within its instance table, whose dense records
/// take fewer bytes than a snapshot of that table (the limit a client sets). Vectors may
/// hold up to twice their length in capacity.
#[derive(Default, Clone)]
struct Reference {
    records: Received,
    /// Bytes of elements the vectors hold.
    bytes: u64,
}

impl Reference {
    /// Forget everything (a snapshot follows), keeping the allocations.
    fn clear(&mut self) {
        self.records.clear();
        self.bytes = 0;
    }
}

/// `v[index]`, growing `v` with defaults first and charging the new elements to `bytes`,
/// which may not pass `limit`.
fn grown<'v, T: Clone + Default>(
    v: &'v mut Vec<T>,
    index: u32,
    bytes: &mut u64,
    limit: u64,
) -> Result<&'v mut T, DeltaError> {
    let i = index as usize;
    if i >= v.len() {
        let needed = *bytes + (i + 1 - v.len()) as u64 * std::mem::size_of::<T>() as u64;
        if needed > limit {
            return Err(DeltaError::ReferenceTooLarge { needed, limit });
        }
        *bytes = needed;
        v.resize(i + 1, T::default());
    }
    Ok(&mut v[i])
}

/// `v[index]`, or the default (empty) record past its end.
fn stored<T: Copy + Default>(v: &[T], index: u32) -> T {
    v.get(index as usize).copied().unwrap_or_default()
}

impl Received {
    /// Forget everything (a snapshot follows), keeping the allocations.
    fn clear(&mut self) {
        self.transforms.clear();
        self.buckets.iter_mut().for_each(Vec::clear);
        self.cells.iter_mut().for_each(Vec::clear);
        self.lights.iter_mut().for_each(Vec::clear);
    }

    /// Heap bytes of the records (allocated capacity, outer vectors included).
    fn heap_bytes(&self) -> u64 {
        fn bytes<T>(v: &Vec<T>) -> u64 {
            (v.capacity() * std::mem::size_of::<T>()) as u64
        }
        fn nested<T>(v: &Vec<Vec<T>>) -> u64 {
            bytes(v) + v.iter().map(bytes).sum::<u64>()
        }
        bytes(&self.transforms) + nested(&self.buckets) + nested(&self.cells) + nested(&self.lights)
    }
}

/// Records ahead of the one being coded whose reference is fetched into the cache: the
/// references of an update's records lie scattered over the whole state, and coding one
/// record takes too long for the processor to reach the next record's load by itself.
const PREFETCH_AHEAD: usize = 8;

/// Hint the processor to fetch `v[index]` (if there is one) into the cache. No effect on
/// results.
#[inline]
fn prefetch<T>(v: &[T], index: u32) {
    #[cfg(target_arch = "x86_64")]
    if let Some(x) = v.get(index as usize) {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: SSE is part of every x86_64 processor, and a prefetch only hints the
        // cache (it never faults nor changes memory); `x` is a live element besides.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(x).cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (v, index);
}

/// Store `new` at `index` of `v` (growing it with empty records) and return what was there.
fn swap_in<T: Copy + Default>(v: &mut Vec<T>, index: u32, new: T) -> T {
    let i = index as usize;
    if i >= v.len() {
        v.resize(i + 1, T::default());
    }
    std::mem::replace(&mut v[i], new)
}

/// The element of `v` for `instance`, created empty when missing.
fn instance_of<T: Default>(v: &mut Vec<T>, instance: u32) -> &mut T {
    let i = instance as usize;
    if i >= v.len() {
        v.resize_with(i + 1, T::default);
    }
    &mut v[i]
}

/// Choice of a bucket entry whose slot is coded as its cell's position in the update.
const RANK_CHOICE: u8 = BUCKET_ENTRIES as u8;

/// Used entries of a compacted bucket (keys non-zero first).
fn used_entries(keys: &[u64; BUCKET_ENTRIES]) -> usize {
    keys.iter().take_while(|&&k| k != 0).count()
}

/// Points of a compacted cell.
fn used_points(points: &[u32; CELL_POINTS]) -> usize {
    points.iter().take_while(|&&p| p != 0).count()
}

/// The count byte of a record holding `n` of at most `capacity` entries whose reference held
/// `old`: `(n − old) mod (capacity + 1)`.
fn count_code(n: usize, old: usize, capacity: usize) -> u8 {
    ((n + capacity + 1 - old) % (capacity + 1)) as u8
}

/// Inverse of [`count_code`], checked: the code must be at most `capacity` (else
/// `out_of_range(code)`) and the `n` coded records must fit in a plane of `plane` records
/// of which `at` are used.
fn decode_count(
    code: u8,
    old: usize,
    capacity: usize,
    (at, plane): (usize, usize),
    out_of_range: fn(usize) -> DeltaError,
) -> Result<usize, DeltaError> {
    if usize::from(code) > capacity {
        return Err(out_of_range(code.into()));
    }
    let n = (usize::from(code) + old) % (capacity + 1);
    if at + n > plane {
        return Err(DeltaError::PlaneSize {
            expected: (at + n) as u64,
            found: plane as u64,
        });
    }
    Ok(n)
}

/// Significant bits of `v`.
fn bits(v: u32) -> u32 {
    32 - v.leading_zeros()
}

/// Significant bits of `v`.
fn bits64(v: u64) -> u32 {
    64 - v.leading_zeros()
}

/// `(key − 1) XOR index` for a used entry, 0 for an empty one (see the module doc).
fn hashed_key(key: u64, index: u32) -> u64 {
    key.checked_sub(1).map_or(0, |k| k ^ u64::from(index))
}

/// Bits of the point fields (everything but the valid bit).
const FIELD_BITS: u32 = !VALID_BIT;
/// The lowest bit of every field.
const FIELD_LOW: u32 = field_bits(0);
/// The highest bit of every field.
const FIELD_HIGH: u32 = field_bits(1);

/// The lowest (`top` = 0) or highest (`top` = 1) bit of every field of [`FIELDS`].
const fn field_bits(top: u32) -> u32 {
    let mut bits = 0;
    let mut f = 0;
    while f < FIELDS.len() {
        let (shift, width) = FIELDS[f];
        bits |= 1 << (shift + top * (width - 1));
        f += 1;
    }
    bits
}

/// Zigzag-coded `(word − reference) mod 2^bits` of every field, valid bit cleared. All
/// fields at once in one word (no borrow crosses a field).
fn point_residual(word: u32, reference: u32) -> u32 {
    let (a, b) = (word & FIELD_BITS, reference & FIELD_BITS);
    let d = (((a | FIELD_HIGH) - (b & !FIELD_HIGH)) ^ ((a ^ !b) & FIELD_HIGH)) & FIELD_BITS;
    // Negative fields: all their bits set, i.e. from their lowest bit up to their sign bit.
    let sign = d & FIELD_HIGH;
    let lows = FIELDS.iter().fold(0, |acc, &(shift, width)| {
        acc | (((sign >> shift) >> (width - 1)) & 1) << shift
    });
    let negative = (sign << 1).wrapping_sub(lows);
    ((d << 1) & FIELD_BITS & !FIELD_LOW) ^ negative
}

/// Inverse of [`point_residual`]: the valid point `residual` codes against `reference`.
fn apply_point_residual(residual: u32, reference: u32) -> u32 {
    FIELDS.iter().fold(VALID_BIT, |acc, &(shift, bits)| {
        let mask = (1u32 << bits) - 1;
        let z = (residual >> shift) & mask;
        let d = (z >> 1) ^ (0u32.wrapping_sub(z & 1) & mask);
        acc | (((reference >> shift).wrapping_add(d) & mask) << shift)
    })
}

/// The reference point of choice `c` (below [`POINT_CHOICES`]) for point `i` of a cell
/// (see the module doc).
fn point_reference(
    c: u8,
    i: usize,
    reference: &[u32; CELL_POINTS],
    previous: &[u32; CELL_POINTS],
) -> u32 {
    let c = usize::from(c);
    match c.checked_sub(CELL_POINTS) {
        None => reference[(i + c) % CELL_POINTS],
        Some(k) => previous[k],
    }
}

/// The codec's byte streams of one update, before layout.
#[derive(Default)]
struct Streams {
    index: Vec<u8>,
    entry_counts: Vec<u8>,
    cell_lengths: Vec<u8>,
    entry_choices: Vec<u8>,
    point_choices: Vec<u8>,
    keys: Vec<u64>,
    slots: Vec<u32>,
    points: Vec<u32>,
    transforms: Vec<u32>,
    lights: Vec<u32>,
}

/// The irradiance records of a cell being coded: (its own, its reference's, the previous
/// cell's in the update).
type LightRefs<'a> = (
    &'a [u32; CELL_POINTS],
    &'a [u32; CELL_POINTS],
    &'a [u32; CELL_POINTS],
);

impl Streams {
    /// Code the used entries of compacted `bucket` against `reference`; `ranks` maps the
    /// cell slots of the instance's delta to their position in its cell list.
    fn bucket(&mut self, index: u32, bucket: &Bucket, reference: &Entries, ranks: &KeyMap<u32>) {
        let n = used_entries(&bucket.entries.map(|e| e.key));
        for (i, e) in bucket.entries[..n].iter().enumerate() {
            let t = hashed_key(e.key, index);
            let mut best = (u32::MAX, 0, 0, 0);
            for c in 0..BUCKET_ENTRIES {
                let r = (i + c) % BUCKET_ENTRIES;
                let k = t ^ hashed_key(reference.keys[r], index);
                let s = e.slot ^ reference.slots[r];
                let cost = bits64(k) + bits(s);
                if cost < best.0 {
                    best = (cost, c as u8, k, s);
                }
                if cost == 0 {
                    break;
                }
            }
            if let Some(&rank) = ranks.get(&u64::from(e.slot)) {
                let cost = bits64(t) + bits(rank);
                if cost < best.0 {
                    best = (cost, RANK_CHOICE, t, rank);
                }
            }
            self.entry_choices.push(best.1);
            self.keys.push(best.2);
            self.slots.push(best.3);
        }
        let old = used_entries(&reference.keys);
        self.entry_counts.push(count_code(n, old, BUCKET_ENTRIES));
    }

    /// Code the points of compacted `points` against `reference`, and their irradiance
    /// records against those of the same reference points with `lights`.
    fn cell(
        &mut self,
        points: &[u32; CELL_POINTS],
        reference: &[u32; CELL_POINTS],
        previous: &[u32; CELL_POINTS],
        lights: Option<LightRefs>,
    ) {
        let n = used_points(points);
        for (i, &point) in points[..n].iter().enumerate() {
            let mut best = (u32::MAX, 0, 0);
            let mut raw_tried = false;
            for c in 0..POINT_CHOICES {
                let r = point_reference(c, i, reference, previous);
                // Every empty reference codes the point raw: try the first only.
                if r == 0 && std::mem::replace(&mut raw_tried, true) {
                    continue;
                }
                let residual = point_residual(point, r);
                // Set bits: a cheap stand-in for what the residual costs after zstd.
                let cost = residual.count_ones();
                if cost < best.0 {
                    best = (cost, c, residual);
                }
                if cost == 0 || (c + 1 == CELL_POINTS as u8 && best.0 <= SAME_POINT_BITS) {
                    break;
                }
            }
            self.point_choices.push(best.1);
            self.points.push(best.2);
            if let Some((own, reference, previous)) = lights {
                self.lights
                    .push(own[i] ^ point_reference(best.1, i, reference, previous));
            }
        }
        let old = used_points(reference);
        self.cell_lengths.push(count_code(n, old, CELL_POINTS));
    }

    /// The uncompressed payload.
    fn payload(&self, flags: u32, frame: u64) -> Vec<u8> {
        let bytes = HEADER_BYTES
            + self.index.len()
            + self.entry_counts.len()
            + self.cell_lengths.len()
            + self.entry_choices.len() * (1 + ENTRY_BYTES as usize)
            + self.point_choices.len() * (1 + POINT_BYTES as usize)
            + self.transforms.len() * 4
            + self.lights.len() * 4;
        let mut out = Vec::with_capacity(bytes);
        out.extend_from_slice(&TAG.to_le_bytes());
        out.extend_from_slice(&flags.to_le_bytes());
        out.extend_from_slice(&frame.to_le_bytes());
        out.extend_from_slice(&(self.index.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.entry_choices.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.point_choices.len() as u32).to_le_bytes());
        for bytes in [
            &self.index,
            &self.entry_counts,
            &self.cell_lengths,
            &self.entry_choices,
            &self.point_choices,
        ] {
            out.extend_from_slice(bytes);
        }
        for plane in 0..8 {
            out.extend(self.keys.iter().map(|k| (k >> (8 * plane)) as u8));
        }
        shuffle_into(&self.slots, &mut out);
        shuffle_into(&self.points, &mut out);
        shuffle_into(&self.transforms, &mut out);
        shuffle_into(&self.lights, &mut out);
        out
    }
}

/// The compact codec. Stateful: one instance per sending or receiving end of a session.
/// The encoder's memory grows with what it sent (the records its receiver holds, 12 bytes
/// per bucket entry and 4 per point, plus their pages) and by 8 bytes per 64 bucket indices
/// or cell slots up to the largest it was given; the decoder's with the largest instance,
/// bucket index and cell slot it decodes (dense records), within the decode limit
/// ([`Codec::set_decode_limit`]).
#[derive(Clone)]
pub struct CompactCodec {
    /// The decoder's reference.
    reference: Reference,
    /// The encoder's reference.
    sent: Sent,
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
            .field("reference_bytes", &self.reference.bytes)
            .field("sent_points", &self.sent.points())
            .finish()
    }
}

impl CompactCodec {
    /// A codec with an empty reference state, [`COMPACT_LEVEL`] and the
    /// [`MAX_DECODED_BYTES`] decoding limit.
    pub fn new() -> Self {
        Self {
            reference: Reference::default(),
            sent: Sent::default(),
            level: COMPACT_LEVEL,
            decode_limit: MAX_DECODED_BYTES,
        }
    }

    /// Take `update` into the encoder's reference and, with `streams`, code it there against
    /// the reference it replaces.
    fn record(&mut self, update: &Update, mut streams: Option<&mut Streams>) {
        if update.snapshot {
            self.sent.clear();
        }
        let lit = update.has_lights();
        let r = &mut self.sent;
        if let Some(st) = streams.as_deref_mut() {
            put_varint(&mut st.index, update.transforms.len() as u64);
        }
        let mut prev = -1i64;
        for (instance, t) in &update.transforms {
            let words = t.to_cols_array().map(f32::to_bits);
            let old = swap_in(&mut r.transforms, *instance, words);
            if let Some(st) = streams.as_deref_mut() {
                put_delta(&mut st.index, &mut prev, *instance);
                st.transforms
                    .extend(words.iter().zip(old).map(|(w, p)| w ^ p));
            }
        }
        if let Some(st) = streams.as_deref_mut() {
            put_varint(&mut st.index, update.instances.len() as u64);
        }
        let mut prev_instance = -1i64;
        for d in &update.instances {
            // When coding: the instance's index entries, and where each cell slot stands in
            // this delta (for bucket entries coded by rank).
            let ranks = streams.as_deref_mut().map(|st| {
                put_delta(&mut st.index, &mut prev_instance, d.instance);
                put_varint(&mut st.index, d.buckets.len() as u64);
                put_varint(&mut st.index, d.cells.len() as u64);
                let mut ranks = KeyMap::default();
                for (rank, (s, _)) in d.cells.iter().enumerate() {
                    ranks.entry(u64::from(*s)).or_insert(rank as u32);
                }
                ranks
            });
            let mut prev = -1i64;
            let sent = instance_of(&mut r.instances, d.instance);
            for (b, bucket) in &d.buckets {
                let bucket = compact_bucket(bucket);
                let old = sent.swap_bucket(*b, &bucket);
                if let (Some(st), Some(ranks)) = (streams.as_deref_mut(), &ranks) {
                    put_delta(&mut st.index, &mut prev, *b);
                    st.bucket(*b, &bucket, &old, ranks);
                }
            }
            let mut prev = -1i64;
            let (mut previous, mut previous_light) = ([0; CELL_POINTS], [0; CELL_POINTS]);
            for (k, (s, cell)) in d.cells.iter().enumerate() {
                let points = compact_cell(cell).points;
                let old = sent.swap_cell(*s, &points);
                // Records past the cell's points are not coded: the reference holds 0 there.
                let n = used_points(&points);
                let mut light = d.lights.get(k).copied().unwrap_or_default();
                light[n..].fill(0);
                let old_light = if lit {
                    sent.swap_light(*s, &light, n)
                } else {
                    // A cell sent without lights has zero irradiance records.
                    sent.lights.set(*s, &[]);
                    [0; CELL_POINTS]
                };
                if let Some(st) = streams.as_deref_mut() {
                    put_delta(&mut st.index, &mut prev, *s);
                    let lights = lit.then_some((&light, &old_light, &previous_light));
                    st.cell(&points, &old, &previous, lights);
                }
                previous = points;
                previous_light = light;
            }
        }
    }
}

impl Codec for CompactCodec {
    fn name(&self) -> &'static str {
        "compact"
    }

    fn encode(&mut self, update: &Update) -> Vec<u8> {
        let mut st = Streams::default();
        self.record(update, Some(&mut st));
        let flags = if update.snapshot { FLAG_SNAPSHOT } else { 0 }
            | if update.has_lights() { FLAG_LIGHTS } else { 0 };
        crate::zstd_io::compress(&st.payload(flags, update.frame), self.level)
    }

    fn advance(&mut self, update: &Update) {
        self.record(update, None);
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
        if flags & !(FLAG_SNAPSHOT | FLAG_LIGHTS) != 0 {
            return Err(DeltaError::UnknownFlags(flags));
        }
        let lit = flags & FLAG_LIGHTS != 0;
        let frame = u64::from(word(8)) | (u64::from(word(12)) << 32);
        let index_len = word(16) as usize;
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
        let totals = (word(20) as usize, word(24) as usize);
        let sections = Sections::split(&layout, totals, lit, rest)?;
        let snapshot = flags & FLAG_SNAPSHOT != 0;
        if snapshot {
            self.reference.clear();
        }
        assemble(
            &layout,
            &sections,
            (frame, snapshot),
            &mut self.reference,
            self.decode_limit,
        )
    }

    fn set_decode_limit(&mut self, bytes: u64) {
        self.decode_limit = bytes.min(MAX_DECODE_LIMIT);
    }

    fn heap_bytes(&self) -> u64 {
        self.sent.heap_bytes() + self.reference.records.heap_bytes()
    }
}

/// The parsed index stream: which slots the sections hold.
struct IndexLayout {
    transforms: Vec<u32>,
    instances: Vec<(u32, Vec<u32>, Vec<u32>)>,
}

impl IndexLayout {
    fn buckets(&self) -> usize {
        self.instances.iter().map(|i| i.1.len()).sum()
    }
    fn cells(&self) -> usize {
        self.instances.iter().map(|i| i.2.len()).sum()
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

/// The payload after the index stream, split into its sections (sizes checked).
struct Sections<'a> {
    entry_counts: &'a [u8],
    cell_lengths: &'a [u8],
    entry_choices: &'a [u8],
    point_choices: &'a [u8],
    keys: Vec<u64>,
    slots: Vec<u32>,
    points: Vec<u32>,
    transforms: Vec<u32>,
    /// Light residuals, one per point, when the update is lit.
    lights: Option<Vec<u32>>,
}

impl<'a> Sections<'a> {
    /// Split `bytes` for `layout`, the header's totals of (entries, points) and whether the
    /// update is `lit`.
    fn split(
        layout: &IndexLayout,
        (entries, points): (usize, usize),
        lit: bool,
        bytes: &'a [u8],
    ) -> Result<Self, DeltaError> {
        let (nb, nc) = (layout.buckets(), layout.cells());
        let transform_bytes = layout.transforms.len() as u64 * TRANSFORM_WORDS as u64 * 4;
        let expected = (nb + nc) as u64
            + entries as u64 * (1 + ENTRY_BYTES)
            + points as u64 * (1 + POINT_BYTES + if lit { 4 } else { 0 })
            + transform_bytes;
        if bytes.len() as u64 != expected {
            return Err(DeltaError::PlaneSize {
                expected,
                found: bytes.len() as u64,
            });
        }
        let (entry_counts, rest) = bytes.split_at(nb);
        let (cell_lengths, rest) = rest.split_at(nc);
        let (entry_choices, rest) = rest.split_at(entries);
        let (point_choices, rest) = rest.split_at(points);
        let (key_planes, rest) = rest.split_at(entries * 8);
        let (slot_planes, rest) = rest.split_at(entries * 4);
        let (point_planes, rest) = rest.split_at(points * 4);
        let (transform_planes, light_planes) = rest.split_at(transform_bytes as usize);
        let mut keys = vec![0u64; entries];
        for (plane, bytes) in key_planes.chunks_exact(entries.max(1)).enumerate() {
            for (k, &b) in keys.iter_mut().zip(bytes) {
                *k |= u64::from(b) << (8 * plane);
            }
        }
        Ok(Self {
            entry_counts,
            cell_lengths,
            entry_choices,
            point_choices,
            keys,
            slots: unshuffle(slot_planes),
            points: unshuffle(point_planes),
            transforms: unshuffle(transform_planes),
            lights: lit.then(|| unshuffle(light_planes)),
        })
    }
}

/// Rebuild the update of `(frame, snapshot)` from the checked layout and sections, updating
/// the reference state (growing it within `limit` bytes).
fn assemble(
    layout: &IndexLayout,
    s: &Sections,
    (frame, snapshot): (u64, bool),
    r: &mut Reference,
    limit: u64,
) -> Result<Update, DeltaError> {
    let Reference { records, bytes } = r;
    let transforms = layout
        .transforms
        .iter()
        .zip(s.transforms.chunks_exact(TRANSFORM_WORDS))
        .map(|(&instance, coded)| {
            let old = grown(&mut records.transforms, instance, bytes, limit)?;
            let words: [u32; TRANSFORM_WORDS] = std::array::from_fn(|i| coded[i] ^ old[i]);
            *old = words;
            Ok((
                instance,
                Affine3A::from_cols_array(&words.map(f32::from_bits)),
            ))
        })
        .collect::<Result<_, DeltaError>>()?;
    let mut entry_counts = s.entry_counts.iter();
    let mut cell_lengths = s.cell_lengths.iter();
    let mut entry = 0usize;
    let mut point = 0usize;
    let mut instances = Vec::with_capacity(layout.instances.len());
    for (instance, bucket_ids, slot_ids) in &layout.instances {
        let mut buckets = Vec::with_capacity(bucket_ids.len());
        let received = grown(&mut records.buckets, *instance, bytes, limit)?;
        for (k, (&b, &code)) in bucket_ids.iter().zip(entry_counts.by_ref()).enumerate() {
            if let Some(&ahead) = bucket_ids.get(k + PREFETCH_AHEAD) {
                prefetch(received, ahead);
            }
            let old = stored(received, b);
            let n = decode_count(
                code,
                used_entries(&old.keys),
                BUCKET_ENTRIES,
                (entry, s.entry_choices.len()),
                DeltaError::EntryCount,
            )?;
            let mut bucket = Bucket::default();
            for i in 0..n {
                let (c, kr, sr) = (s.entry_choices[entry], s.keys[entry], s.slots[entry]);
                entry += 1;
                let (t, slot) = if c == RANK_CHOICE {
                    let slot = slot_ids
                        .get(sr as usize)
                        .ok_or(DeltaError::BadChoice("bucket entry"))?;
                    (kr, *slot)
                } else if c < RANK_CHOICE {
                    let o = (i + usize::from(c)) % BUCKET_ENTRIES;
                    (kr ^ hashed_key(old.keys[o], b), sr ^ old.slots[o])
                } else {
                    return Err(DeltaError::BadChoice("bucket entry"));
                };
                let key = (t ^ u64::from(b))
                    .checked_add(1)
                    .ok_or(DeltaError::BadRecord("bucket key"))?;
                bucket.entries[i] = BucketEntry { key, slot };
            }
            *grown(received, b, bytes, limit)? = Entries::of(&bucket);
            buckets.push((b, bucket));
        }
        let mut cells = Vec::with_capacity(slot_ids.len());
        let mut lights = Vec::with_capacity(if s.lights.is_some() {
            slot_ids.len()
        } else {
            0
        });
        let (mut previous, mut previous_light) = ([0; CELL_POINTS], [0; CELL_POINTS]);
        let received = grown(&mut records.cells, *instance, bytes, limit)?;
        let mut received_lights = match s.lights {
            Some(_) => Some(grown(&mut records.lights, *instance, bytes, limit)?),
            None => records.lights.get_mut(*instance as usize),
        };
        for (k, (&slot, &code)) in slot_ids.iter().zip(cell_lengths.by_ref()).enumerate() {
            if let Some(&ahead) = slot_ids.get(k + PREFETCH_AHEAD) {
                prefetch(received, ahead);
            }
            let old = stored(received, slot);
            let old_light = received_lights
                .as_deref()
                .map_or([0; CELL_POINTS], |l| stored(l, slot));
            let mut light = [0; CELL_POINTS];
            let n = decode_count(
                code,
                used_points(&old),
                CELL_POINTS,
                (point, s.point_choices.len()),
                DeltaError::CellLength,
            )?;
            let mut cell = Cell::default();
            let decoded = cell.points.iter_mut().zip(light.iter_mut()).take(n);
            for (i, (record, irradiance)) in decoded.enumerate() {
                let (c, residual) = (s.point_choices[point], s.points[point]);
                if c >= POINT_CHOICES {
                    return Err(DeltaError::BadChoice("point"));
                }
                if residual & VALID_BIT != 0 {
                    return Err(DeltaError::BadRecord("point residual"));
                }
                let reference = point_reference(c, i, &old, &previous);
                *record = apply_point_residual(residual, reference);
                if let Some(residuals) = &s.lights {
                    *irradiance =
                        residuals[point] ^ point_reference(c, i, &old_light, &previous_light);
                }
                point += 1;
            }
            *grown(received, slot, bytes, limit)? = cell.points;
            match (&s.lights, received_lights.as_deref_mut()) {
                (Some(_), Some(l)) => {
                    *grown(l, slot, bytes, limit)? = light;
                    lights.push(light);
                }
                (None, Some(l)) => forget_light(l, slot),
                _ => {}
            }
            previous = cell.points;
            previous_light = light;
            cells.push((slot, cell));
        }
        instances.push(InstanceDelta {
            instance: *instance,
            buckets,
            cells,
            lights,
        });
    }
    if entry != s.entry_choices.len() || point != s.point_choices.len() {
        return Err(DeltaError::Trailing(
            s.entry_choices.len() - entry + s.point_choices.len() - point,
        ));
    }
    Ok(Update {
        frame,
        snapshot,
        transforms,
        instances,
    })
}

/// A cell sent without lights has zero irradiance records in the reference (nothing to do
/// where the reference never held any).
fn forget_light(lights: &mut [[u32; CELL_POINTS]], slot: u32) {
    if let Some(l) = lights.get_mut(slot as usize) {
        *l = [0; CELL_POINTS];
    }
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
                    lights: Vec::new(),
                },
                InstanceDelta {
                    instance: 2,
                    buckets: vec![],
                    cells: vec![(40, cell(ao, 7)), (2, cell(ao, 3))],
                    lights: Vec::new(),
                },
            ],
        }
    }

    /// What the paper codec decodes (compacted records): the compact codec must agree.
    fn paper_round_trip(u: &Update) -> Update {
        let mut p = PaperCodec::new();
        let bytes = p.encode(u);
        p.decode(&bytes).unwrap()
    }

    /// A deterministic pseudo-random sequence (SplitMix64).
    fn rng(seed: u64) -> impl FnMut() -> u64 {
        let mut state = seed;
        move || {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
    }

    /// A session like a server's: cells fill point by point (inserted anywhere, so the
    /// others shift), points move a little and change AO, buckets gain and lose entries
    /// whose cells arrive in the same update.
    fn growing_session(seed: u64, frames: u64) -> Vec<Update> {
        let mut next = rng(seed);
        let mut cells: Vec<Vec<u32>> = vec![Vec::new(); 64];
        let mut buckets: Vec<Vec<BucketEntry>> = vec![Vec::new(); 16];
        let mut session = Vec::new();
        for frame in 0..frames {
            let mut changed_cells = std::collections::BTreeSet::new();
            let mut changed_buckets = std::collections::BTreeSet::new();
            for _ in 0..12 {
                let slot = (next() % 64) as usize;
                let cell = &mut cells[slot];
                let r = next();
                match r % 4 {
                    0 if cell.len() < CELL_POINTS => {
                        let at = (r >> 8) as usize % (cell.len() + 1);
                        cell.insert(at, VALID_BIT | (next() as u32 & 0x7fff_ffff));
                    }
                    1 if !cell.is_empty() => {
                        let at = (r >> 8) as usize % cell.len();
                        cell[at] = (cell[at] & !0xff) | (next() as u32 & 0xff);
                    }
                    2 if !cell.is_empty() => {
                        let at = (r >> 8) as usize % cell.len();
                        cell[at] ^= 1 << (16 + (r >> 16) % 15);
                    }
                    3 if !cell.is_empty() => {
                        cell.remove((r >> 8) as usize % cell.len());
                    }
                    _ => continue,
                }
                changed_cells.insert(slot as u32);
                let b = slot % 16;
                let entry = BucketEntry::new(b as u64 + 16 * slot as u64, slot as u32);
                let bucket = &mut buckets[b];
                let present = bucket.iter().position(|e| *e == entry);
                match (cell.is_empty(), present) {
                    (true, Some(k)) => {
                        bucket.remove(k);
                    }
                    (false, None) => bucket.insert((r >> 32) as usize % (bucket.len() + 1), entry),
                    _ => continue,
                }
                changed_buckets.insert(b as u32);
            }
            let to_cell = |c: &Vec<u32>| {
                let mut cell = Cell::default();
                cell.points[..c.len()].copy_from_slice(c);
                cell
            };
            let to_bucket = |entries: &Vec<BucketEntry>| {
                let mut bucket = Bucket::default();
                bucket.entries[..entries.len()].copy_from_slice(entries);
                bucket
            };
            session.push(Update {
                frame,
                snapshot: frame == 0,
                transforms: vec![(0, Affine3A::from_translation(glam::Vec3::X * frame as f32))],
                instances: vec![InstanceDelta {
                    instance: 1,
                    buckets: changed_buckets
                        .iter()
                        .map(|&b| (b, to_bucket(&buckets[b as usize])))
                        .collect(),
                    cells: changed_cells
                        .iter()
                        .map(|&s| (s, to_cell(&cells[s as usize])))
                        .collect(),
                    lights: Vec::new(),
                }],
            });
        }
        session
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

    /// `updates` merged into one, as the server coalesces them: later records win, and the
    /// last update's frame and transforms are kept.
    fn coalesce(updates: &[Update]) -> Update {
        let mut buckets = std::collections::BTreeMap::new();
        let mut cells = std::collections::BTreeMap::new();
        for u in updates {
            for d in &u.instances {
                buckets.extend(d.buckets.iter().map(|(b, v)| ((d.instance, *b), *v)));
                cells.extend(d.cells.iter().map(|(c, v)| ((d.instance, *c), *v)));
            }
        }
        let last = updates.last().expect("updates to coalesce");
        let instances: std::collections::BTreeSet<u32> =
            buckets.keys().chain(cells.keys()).map(|k| k.0).collect();
        Update {
            frame: last.frame,
            snapshot: updates[0].snapshot,
            transforms: last.transforms.clone(),
            instances: instances
                .into_iter()
                .map(|i| InstanceDelta {
                    instance: i,
                    buckets: buckets
                        .iter()
                        .filter(|k| k.0 .0 == i)
                        .map(|(k, v)| (k.1, *v))
                        .collect(),
                    cells: cells
                        .iter()
                        .filter(|k| k.0 .0 == i)
                        .map(|(k, v)| (k.1, *v))
                        .collect(),
                    lights: Vec::new(),
                })
                .collect(),
        }
    }

    /// Both references are counted: the encoder's by what it sent, the decoder's by the
    /// highest slot decoded.
    #[test]
    fn heap_bytes_count_both_references() {
        let (mut enc, mut dec) = (CompactCodec::new(), CompactCodec::new());
        assert_eq!(enc.heap_bytes(), 0);
        let u = update(1, true, 10, 0..50);
        let points: usize = (u.instances.iter().flat_map(|d| &d.cells))
            .map(|(_, c)| c.count())
            .sum();
        let entries = 2 * 12;
        let bytes = enc.encode(&u);
        let sent = enc.heap_bytes();
        // At least 4 bytes per point and 12 per bucket entry sent.
        assert!(sent >= (4 * points + entries) as u64, "{sent}");
        dec.decode(&bytes).unwrap();
        // One 28-byte cell record per decoded slot.
        assert!(dec.heap_bytes() >= 50 * 28);
        let both = dec.heap_bytes();
        dec.encode(&u);
        assert!(dec.heap_bytes() >= both + (4 * points) as u64);
    }

    /// The encoder's reference costs what it sent, not the highest index it was given.
    #[test]
    fn the_encoders_reference_costs_what_it_sent() {
        let mut u = update(1, true, 10, 0..0);
        let far = (1 << 20) + 5;
        u.instances[0].buckets[0].0 = far / 2;
        u.instances[0].cells = vec![(far, cell(3, 7))];
        let mut enc = CompactCodec::new();
        enc.encode(&u);
        // Dense records up to slot 2^20 would take 28 MiB; a page table of 8 bytes per 64
        // indices of each kind and a few pages remain.
        let table = (far / 64 + 1) * 8 + (far / 128 + 1) * 8;
        let sent = enc.heap_bytes();
        assert!(sent < u64::from(table) * 5 / 4 + 4096, "{sent} vs {table}");
        // A snapshot without the far cell forgets it.
        enc.encode(&update(2, true, 10, 0..0));
        assert!(enc.sent.instances[0].cells.is_empty());
        assert!(enc.sent.instances[0].buckets.get(far / 2).is_empty());
    }

    /// After any session, what the encoder keeps for every slot is what the decoder
    /// received there.
    #[test]
    fn the_encoder_keeps_what_the_decoder_received() {
        for seed in 0..3 {
            let (mut enc, mut dec) = (CompactCodec::new(), CompactCodec::new());
            let mut held = (0, 0);
            for (k, u) in growing_session(seed, 120).iter().enumerate() {
                let sent = if k % 4 == 3 { u.clone() } else { lit(u) };
                dec.decode(&enc.encode(&sent)).unwrap();
                let (sent, received) = (&enc.sent, &dec.reference.records);
                assert_eq!(
                    sent.transforms, received.transforms,
                    "seed {seed} update {k}"
                );
                for (i, mine) in sent.instances.iter().enumerate() {
                    let entries = |b: usize| {
                        received
                            .buckets
                            .get(i)
                            .and_then(|v| v.get(b))
                            .copied()
                            .unwrap_or_default()
                    };
                    for b in 0..16 {
                        let (e, r) = (Entries::of_run(mine.buckets.get(b as u32)), entries(b));
                        assert_eq!((e.keys, e.slots), (r.keys, r.slots), "bucket {b}");
                        held.0 += used_entries(&e.keys);
                    }
                    let records = |v: &Vec<Vec<[u32; CELL_POINTS]>>, s: usize| {
                        v.get(i).and_then(|v| v.get(s)).copied().unwrap_or_default()
                    };
                    for s in 0..64 {
                        let cell = padded(mine.cells.get(s as u32));
                        assert_eq!(cell, records(&received.cells, s), "cell {s}");
                        let light = padded(mine.lights.get(s as u32));
                        assert_eq!(light, records(&received.lights, s), "light {s}");
                        held.1 += used_points(&cell);
                    }
                }
            }
            assert!(held.0 > 1000 && held.1 > 1000, "{held:?}");
        }
    }

    #[test]
    fn receivers_in_the_same_state_get_the_same_bytes() {
        let session = growing_session(7, 24);
        let (head, tail) = session.split_at(16);
        // One client got every update, one got the first and then the rest coalesced, one
        // only advanced through them (the server sent it another client's bytes).
        let mut every = CompactCodec::new();
        let mut coalesced = CompactCodec::new();
        let mut advanced = CompactCodec::new();
        for u in head {
            every.encode(u);
            advanced.advance(u);
        }
        coalesced.encode(&head[0]);
        coalesced.encode(&coalesce(&head[1..]));
        let mut changed = 0;
        for u in tail {
            let bytes = every.encode(u);
            assert_eq!(coalesced.encode(u), bytes, "frame {}", u.frame);
            assert_eq!(advanced.encode(u), bytes, "frame {}", u.frame);
            changed += u.changed_cells();
        }
        assert!(changed > 0, "the tail changes cells");
    }

    #[test]
    fn round_trips_growing_shifting_and_moving_records() {
        for seed in 0..4 {
            let mut enc = CompactCodec::new();
            let mut dec = CompactCodec::new();
            for u in growing_session(seed, 200) {
                let bytes = enc.encode(&u);
                assert_eq!(
                    dec.decode(&bytes).unwrap(),
                    paper_round_trip(&u),
                    "seed {seed}"
                );
            }
        }
    }

    /// `u` with irradiance records derived from each point's record (0 past the cell's
    /// points), as a lit server sends them: unchanged points keep their records.
    fn lit(u: &Update) -> Update {
        let mut u = u.clone();
        for d in &mut u.instances {
            d.lights = (d.cells.iter())
                .map(|(_, c)| {
                    (compact_cell(c).points).map(|p| {
                        if p == 0 {
                            0
                        } else {
                            p.wrapping_mul(0x9e37_79b9) >> 5
                        }
                    })
                })
                .collect();
        }
        u
    }

    #[test]
    fn irradiance_records_round_trip_in_both_codecs() {
        for seed in 0..3 {
            let (mut enc, mut dec) = (CompactCodec::new(), CompactCodec::new());
            let mut plain = CompactCodec::new();
            let (mut ao_bytes, mut lit_bytes, mut lit_updates) = (0, 0, 0);
            for (k, u) in growing_session(seed, 150).iter().enumerate() {
                // Every fifth update goes without lights: its cells forget theirs.
                let sent = if k % 5 == 4 { u.clone() } else { lit(u) };
                let paper = paper_round_trip(&sent);
                let lights = |u: &Update| -> Vec<Vec<[u32; CELL_POINTS]>> {
                    u.instances.iter().map(|d| d.lights.clone()).collect()
                };
                assert_eq!(
                    lights(&paper),
                    lights(&sent),
                    "paper, seed {seed} update {k}"
                );
                let bytes = enc.encode(&sent);
                let got = dec.decode(&bytes).unwrap();
                assert_eq!(got, paper, "compact, seed {seed} update {k}");
                lit_updates += usize::from(got.has_lights());
                lit_bytes += bytes.len();
                ao_bytes += plain.encode(u).len();
            }
            assert!(lit_updates > 100);
            assert!(lit_bytes > ao_bytes, "{lit_bytes} vs {ao_bytes}");
        }
        // Unchanged records cost almost nothing: the same lit cells sent again.
        let session = growing_session(1, 40);
        let last = lit(session.last().unwrap());
        let mut enc = CompactCodec::new();
        session.iter().take(39).for_each(|u| enc.advance(&lit(u)));
        enc.advance(&last);
        let again = enc.encode(&last).len();
        let mut plain = CompactCodec::new();
        session.iter().for_each(|u| plain.advance(u));
        let plain_again = plain.encode(session.last().unwrap()).len();
        assert!(again <= plain_again + 16, "{again} vs {plain_again}");
    }

    #[test]
    fn mutated_payloads_give_errors_or_updates_never_panics() {
        // The parsers behind zstd's checksum: change a few bytes of real payloads (from a
        // decoder state that has seen the session so far) and decode.
        let mut next = rng(11);
        let mut enc = CompactCodec::new();
        let mut dec = CompactCodec::new();
        let (mut rejected, mut accepted) = (0, 0);
        for u in growing_session(5, 40) {
            let bytes = enc.encode(&u);
            let payload = crate::zstd_io::decompress(&bytes, MAX_DECODED_BYTES).unwrap();
            for _ in 0..50 {
                let mut bad = payload.clone();
                for _ in 0..1 + next() % 4 {
                    let at = (next() % bad.len() as u64) as usize;
                    bad[at] = next() as u8;
                }
                match dec.clone().decode(&crate::zstd_io::compress(&bad, 1)) {
                    Ok(_) => accepted += 1,
                    Err(_) => rejected += 1,
                }
            }
            assert_eq!(dec.decode(&bytes).unwrap(), paper_round_trip(&u));
        }
        // Most changes hit residual bytes, which decode to other valid records.
        assert!(rejected > 0 && accepted > 0, "{rejected} / {accepted}");
    }

    #[test]
    fn point_residuals_invert_for_any_reference() {
        let mut next = rng(7);
        for _ in 0..100_000 {
            let word = VALID_BIT | (next() as u32 & !VALID_BIT);
            let reference = next() as u32;
            let residual = point_residual(word, reference);
            assert_eq!(residual & VALID_BIT, 0);
            assert_eq!(apply_point_residual(residual, reference), word);
        }
        let p = VALID_BIT | (7 << 26) | (3 << 16) | 200;
        assert_eq!(point_residual(p, p), 0, "an unchanged point costs nothing");
        // One step down in x and +2 in AO are small residuals.
        let moved = p - (1 << 26) + 2;
        assert_eq!(point_residual(moved, p), (1 << 26) | 4);
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
    fn a_point_inserted_into_a_cell_costs_about_one_point() {
        // 2000 cells of 3 points, then the same cells with a fourth point inserted first
        // (every old point shifts by one).
        let mut next = rng(3);
        let points: Vec<[u32; 4]> = (0..2000)
            .map(|_| std::array::from_fn(|_| VALID_BIT | (next() as u32 & 0x7fff_ffff)))
            .collect();
        let cells = |with_new: bool| {
            let cells = points.iter().enumerate().map(|(s, p)| {
                let mut cell = Cell::default();
                let src = if with_new { &p[..] } else { &p[1..] };
                cell.points[..src.len()].copy_from_slice(src);
                (s as u32, cell)
            });
            Update {
                frame: 0,
                snapshot: !with_new,
                transforms: vec![],
                instances: vec![InstanceDelta {
                    instance: 0,
                    buckets: vec![],
                    cells: cells.collect(),
                    lights: Vec::new(),
                }],
            }
        };
        let mut enc = CompactCodec::new();
        let first = enc.encode(&cells(false)).len();
        let grown = enc.encode(&cells(true)).len();
        assert!(grown * 2 < first, "{grown} bytes after {first}");
    }

    /// Decompress, let `edit` change the payload (given its section offsets), recompress.
    fn edited(bytes: &[u8], edit: impl FnOnce(&mut Vec<u8>, &Offsets)) -> Vec<u8> {
        let mut payload = crate::zstd_io::decompress(bytes, MAX_DECODED_BYTES).unwrap();
        let word = |i: usize| u32::from_le_bytes(payload[i..i + 4].try_into().unwrap()) as usize;
        let index = HEADER_BYTES + word(16);
        let layout = parse_index(&payload[HEADER_BYTES..index]).unwrap();
        let (entries, words) = (word(20), word(24));
        let lengths = index + layout.buckets();
        let entry_choices = lengths + layout.cells();
        let point_choices = entry_choices + entries;
        let keys = point_choices + words;
        let slots = keys + 8 * entries;
        let offsets = Offsets {
            counts: index,
            lengths,
            entry_choices,
            point_choices,
            keys,
            slots,
            points: slots + 4 * entries,
            entries,
            words,
        };
        edit(&mut payload, &offsets);
        crate::zstd_io::compress(&payload, 1)
    }

    /// A change to a payload, given its section offsets.
    type Edit = dyn Fn(&mut Vec<u8>, &Offsets);

    /// Byte offsets of the payload's sections.
    struct Offsets {
        counts: usize,
        lengths: usize,
        entry_choices: usize,
        point_choices: usize,
        keys: usize,
        slots: usize,
        points: usize,
        entries: usize,
        words: usize,
    }

    #[test]
    fn rejects_bad_choices_counts_and_residuals() {
        let u = update(1, true, 10, 0..20);
        let good = CompactCodec::new().encode(&u);
        let decode = |bytes: &[u8]| CompactCodec::new().decode(bytes);
        assert_eq!(decode(&good).unwrap(), paper_round_trip(&u));
        let cases: [(&str, Box<Edit>); 7] = [
            (
                "point choice",
                Box::new(|p, o| p[o.point_choices] = POINT_CHOICES),
            ),
            (
                "entry choice",
                Box::new(|p, o| p[o.entry_choices] = RANK_CHOICE + 1),
            ),
            (
                "rank",
                Box::new(|p, o| {
                    p[o.entry_choices] = RANK_CHOICE;
                    p[o.slots + 3 * o.entries] = 0xff;
                }),
            ),
            ("entry count", Box::new(|p, o| p[o.counts] = 9)),
            ("cell length", Box::new(|p, o| p[o.lengths] = 8)),
            (
                "valid bit",
                Box::new(|p, o| p[o.points + 3 * o.words] |= 0x80),
            ),
            (
                "key",
                Box::new(|p, o| {
                    // key − 1 = residual XOR bucket index = 2^64 − 1: no key.
                    p[o.entry_choices] = 0;
                    for plane in 0..8 {
                        p[o.keys + plane * o.entries] = 0xff;
                    }
                    p[o.keys] ^= 7; // the first bucket is bucket 7
                }),
            ),
        ];
        for (what, edit) in cases {
            let bytes = edited(&good, |p, o| edit(p, o));
            assert!(decode(&bytes).is_err(), "{what} accepted");
        }
        // Totals in the header that disagree with the counts.
        let more = edited(&good, |p, o| {
            let total = (o.words as u32 + 1).to_le_bytes();
            p[24..28].copy_from_slice(&total);
            p.insert(o.points, 0);
        });
        assert!(matches!(decode(&more), Err(DeltaError::PlaneSize { .. })));
        let fewer = edited(&good, |p, o| {
            p[o.lengths] = (p[o.lengths] + 1) % 8;
        });
        assert!(decode(&fewer).is_err());
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
            dec.decode(&z(b"PSC2")),
            Err(DeltaError::Truncated { .. })
        ));
        let mut old = vec![0u8; HEADER_BYTES];
        old[..4].copy_from_slice(b"PSC1");
        assert!(matches!(
            dec.decode(&z(&old)),
            Err(DeltaError::BadTag { .. })
        ));
        let mut p = Vec::new();
        p.extend_from_slice(b"PSC2");
        p.extend_from_slice(&0u32.to_le_bytes());
        p.extend_from_slice(&7u64.to_le_bytes());
        p.extend_from_slice(&3u32.to_le_bytes());
        p.extend_from_slice(&0u32.to_le_bytes());
        p.extend_from_slice(&0u32.to_le_bytes());
        p.extend_from_slice(&[1, 2, 0]); // one transform, no instances, but no planes
        assert!(matches!(
            dec.decode(&z(&p)),
            Err(DeltaError::PlaneSize { .. })
        ));
        let mut totals = p.clone();
        totals[20..28].copy_from_slice(&[0xff; 8]); // 4 G entries and points claimed
        assert!(matches!(
            dec.decode(&z(&totals)),
            Err(DeltaError::PlaneSize { .. })
        ));
        let mut huge = p[..HEADER_BYTES].to_vec();
        huge[16] = 11;
        huge.extend_from_slice(&[0xff; 10]); // a varint longer than 64 bits
        huge.push(0);
        assert!(matches!(
            dec.decode(&z(&huge)),
            Err(DeltaError::BadVarint(_))
        ));
        let mut count = p[..HEADER_BYTES].to_vec();
        count[16] = 5;
        count.extend_from_slice(&[0xff, 0xff, 0xff, 0xff, 0x0f]); // 4 G transforms
        assert!(matches!(
            dec.decode(&z(&count)),
            Err(DeltaError::Truncated { .. })
        ));
        let mut flags = p.clone();
        flags[4] = 4;
        assert!(matches!(
            dec.decode(&z(&flags)),
            Err(DeltaError::UnknownFlags(4))
        ));
        // The lights flag without the light residuals: the planes do not add up.
        flags[4] = FLAG_LIGHTS as u8;
        assert!(matches!(
            dec.decode(&z(&flags)),
            Err(DeltaError::PlaneSize { .. })
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
    fn far_indices_are_refused_before_they_grow_the_reference() {
        // A cell slot 100 000 needs 100 001 dense cells (2.8 MB) in the decoder's reference.
        let far = update(1, true, 7, 100_000..100_001);
        let bytes = CompactCodec::new().encode(&far);
        assert!(bytes.len() < 1024, "a few records");
        let mut dec = CompactCodec::new();
        dec.set_decode_limit(1 << 20);
        assert!(matches!(
            dec.decode(&bytes),
            Err(DeltaError::ReferenceTooLarge { limit, .. }) if limit == 1 << 20
        ));
        // Within the limit the same update decodes, and the reference keeps what it decoded.
        let mut dec = CompactCodec::new();
        dec.set_decode_limit(4 << 20);
        assert_eq!(dec.decode(&bytes).unwrap(), paper_round_trip(&far));
        let next = update(2, false, 9, 100_000..100_001);
        let mut enc = CompactCodec::new();
        enc.encode(&far);
        assert_eq!(
            dec.decode(&enc.encode(&next)).unwrap(),
            paper_round_trip(&next)
        );
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
