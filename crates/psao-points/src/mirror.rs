//! The client's mirror of an instance grid, stored for what it holds rather than in the
//! server's layout (DESIGN §3 "Grid"): the wire's addresses (bucket index, cell slot) are
//! answered exactly as an [`crate::InstanceGrid`] written with the same buckets and cells would
//! answer them, up to compaction (a bucket's used entries first, a cell's valid points first),
//! which is the form updates carry and the state hash reads.
//!
//! * Bucket entries live in one open-addressing table ([`CellTable`]) keyed by cell id, with
//!   linear probing from a home position that depends on the entry's bucket alone. A bucket's
//!   entries therefore lie in one probe run in the order they were inserted, so a bucket reads
//!   back (in order) by scanning that run, and a cell is found by its id in the same scan.
//! * Cells live in a shared arena holding only their valid points (4 bytes each), addressed by
//!   a paged per-slot word (offset and count); blocks freed when a cell changes size are kept
//!   on per-size free lists and reused.

use glam::UVec3;

use crate::error::PointsError;
use crate::grid::{Bucket, BucketEntry, Cell};
use crate::layout::{GridLayout, CELL_POINTS};
use crate::lookup::CellLookup;
use crate::pack::is_valid;
use crate::paged::Paged;

/// Bits of a cell index word holding the point count.
const COUNT_BITS: u32 = 3;
/// Most arena words a mirror addresses (the offset takes the remaining bits of a u32).
const MAX_ARENA: usize = 1 << (32 - COUNT_BITS);
/// Most probe-table entries per table position before it grows (linear probing stays short).
const MAX_LOAD: f64 = 0.8;
/// Growth of the probe table when full: load falls to `MAX_LOAD / GROWTH`.
const GROWTH: f64 = 1.3;

/// Heap bytes of a [`MirrorGrid`] by what they hold ([`MirrorGrid::memory_parts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MirrorMemory {
    /// The valid points' packed records (4 bytes each).
    pub records: u64,
    /// Arena words not holding a record: freed blocks and spare capacity.
    pub arena_slack: u64,
    /// The per-slot cell index (offset and count; page table and pages).
    pub cell_index: u64,
    /// The bucket-entry table (cell key and slot per table position, empty ones included).
    pub entry_table: u64,
}

impl MirrorMemory {
    /// All parts together: the mirror's heap bytes.
    pub fn total(&self) -> u64 {
        self.records + self.arena_slack + self.cell_index + self.entry_table
    }

    /// The parts with their names, in the order of the fields.
    pub fn named(&self) -> [(&'static str, u64); 4] {
        [
            ("records (u32 per point)", self.records),
            (
                "arena slack (freed blocks, spare capacity)",
                self.arena_slack,
            ),
            ("cell index (u32 per slot, pages of 64)", self.cell_index),
            ("bucket-entry table (cell key, slot)", self.entry_table),
        ]
    }
}

impl std::ops::AddAssign for MirrorMemory {
    fn add_assign(&mut self, o: Self) {
        self.records += o.records;
        self.arena_slack += o.arena_slack;
        self.cell_index += o.cell_index;
        self.entry_table += o.entry_table;
    }
}

/// A cell key in the probe table: cell id + 1, 0 for an empty position.
trait Key: Copy + Default + Eq + std::fmt::Debug {
    fn from_key(key: u64) -> Self;
    fn key(self) -> u64;
}

impl Key for u32 {
    #[inline]
    fn from_key(key: u64) -> Self {
        key as u32
    }
    #[inline]
    fn key(self) -> u64 {
        u64::from(self)
    }
}

impl Key for u64 {
    #[inline]
    fn from_key(key: u64) -> Self {
        key
    }
    #[inline]
    fn key(self) -> u64 {
        self
    }
}

/// One probe-table position: a bucket entry, or empty (`key` 0). Packed to 4-byte alignment
/// so that 64-bit keys take 12 bytes; fields are read by value ([`Entry::key`]).
#[repr(C, packed(4))]
struct Entry<K> {
    key: K,
    slot: u32,
}

impl<K: Key> Clone for Entry<K> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<K: Key> Copy for Entry<K> {}

impl<K: Key> Default for Entry<K> {
    fn default() -> Self {
        Self {
            key: K::default(),
            slot: 0,
        }
    }
}

impl<K: Key> std::fmt::Debug for Entry<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (key, slot) = (self.key(), self.slot);
        write!(f, "Entry {{ key: {key}, slot: {slot} }}")
    }
}

impl<K: Key> Entry<K> {
    /// The key (cell id + 1; 0 when empty).
    #[inline]
    fn key(&self) -> u64 {
        let key = self.key;
        key.key()
    }

    #[inline]
    fn is_empty(&self) -> bool {
        self.key() == 0
    }
}

/// Open-addressing table of bucket entries keyed by cell id (see the module documentation).
#[derive(Clone, Debug)]
struct CellTable<K: Key> {
    /// `bucket_count − 1` (a power of two minus one): a key's bucket is `(key − 1) & mask`.
    bucket_mask: u64,
    positions: Vec<Entry<K>>,
    len: usize,
}

impl<K: Key> CellTable<K> {
    fn new(bucket_count: u32) -> Self {
        Self {
            bucket_mask: u64::from(bucket_count) - 1,
            positions: Vec::new(),
            len: 0,
        }
    }

    #[inline]
    fn bucket_of(&self, key: u64) -> u64 {
        (key - 1) & self.bucket_mask
    }

    /// The position where bucket `b`'s probe run starts (table not empty).
    #[inline]
    fn home(&self, b: u64) -> usize {
        let hash = (b.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as u32;
        ((u64::from(hash) * self.positions.len() as u64) >> 32) as usize
    }

    #[inline]
    fn next(&self, i: usize) -> usize {
        if i + 1 == self.positions.len() {
            0
        } else {
            i + 1
        }
    }

    /// Positions of the probe run of bucket `b`, in probe order, up to the first empty one.
    #[inline]
    fn run(&self, b: u64) -> impl Iterator<Item = usize> + '_ {
        let first = (!self.positions.is_empty()).then(|| self.home(b));
        std::iter::successors(first, move |&i| Some(self.next(i)))
            .take_while(move |&i| !self.positions[i].is_empty())
    }

    /// Slot of the entry with `key` (cell id + 1).
    #[inline]
    fn find(&self, key: u64) -> Option<u32> {
        self.run(self.bucket_of(key))
            .map(|i| self.positions[i])
            .find(|e| e.key() == key)
            .map(|e| e.slot)
    }

    /// Bucket `b`'s entries in the order they were inserted.
    fn entries_of(&self, b: u64) -> impl Iterator<Item = BucketEntry> + '_ {
        self.run(b)
            .map(|i| self.positions[i])
            .filter(move |e| self.bucket_of(e.key()) == b)
            .map(|e| BucketEntry {
                key: e.key(),
                slot: e.slot,
            })
    }

    /// Replace bucket `b`'s entries with the used entries of `bucket`, in order.
    fn set_bucket(&mut self, b: u64, bucket: &Bucket) {
        loop {
            let found = self
                .run(b)
                .find(|&i| self.bucket_of(self.positions[i].key()) == b);
            match found {
                Some(i) => self.remove_at(i),
                None => break,
            }
        }
        let used = bucket.entries.iter().filter(|e| e.key != 0);
        self.reserve(used.clone().count());
        for e in used {
            self.insert(b, e.key, e.slot);
        }
    }

    /// Store an entry at the end of bucket `b`'s run (room reserved).
    fn insert(&mut self, b: u64, key: u64, slot: u32) {
        let mut i = self.home(b);
        while !self.positions[i].is_empty() {
            i = self.next(i);
        }
        self.positions[i] = Entry {
            key: K::from_key(key),
            slot,
        };
        self.len += 1;
    }

    /// Empty position `i`, shifting later entries of its run back so that every entry stays
    /// reachable from its home without an empty position between (their order is kept).
    fn remove_at(&mut self, mut hole: usize) {
        let cap = self.positions.len();
        let mut j = self.next(hole);
        while !self.positions[j].is_empty() {
            let home = self.home(self.bucket_of(self.positions[j].key()));
            // The entry may fill the hole when the hole lies between its home and it.
            if (j + cap - home) % cap >= (j + cap - hole) % cap {
                self.positions[hole] = self.positions[j];
                hole = j;
            }
            j = self.next(j);
        }
        self.positions[hole] = Entry::default();
        self.len -= 1;
    }

    /// Make room for `more` entries within [`MAX_LOAD`], rehashing into a larger table.
    fn reserve(&mut self, more: usize) {
        let need = self.len + more;
        if (need as f64) <= MAX_LOAD * self.positions.len() as f64 {
            return;
        }
        let cap = ((need as f64 / MAX_LOAD) * GROWTH).ceil() as usize + 8;
        let old = std::mem::replace(&mut self.positions, vec![Entry::default(); cap]);
        self.len = 0;
        // Visit each run from its start (after an empty position) so entries of one bucket
        // are re-inserted in their order.
        let Some(start) = old.iter().position(Entry::is_empty) else {
            return;
        };
        for k in 1..=old.len() {
            let e = old[(start + k) % old.len()];
            if !e.is_empty() {
                self.insert(self.bucket_of(e.key()), e.key(), e.slot);
            }
        }
    }

    fn heap_bytes(&self) -> u64 {
        crate::vec_bytes(&self.positions)
    }
}

/// The probe table with 32-bit keys when every cell id of the layout fits, else 64-bit.
#[derive(Clone, Debug)]
enum Entries {
    Narrow(CellTable<u32>),
    Wide(CellTable<u64>),
}

/// Calls `$body` with `$t` bound to whichever table `$entries` holds.
macro_rules! with_table {
    ($entries:expr, $t:ident => $body:expr) => {
        match $entries {
            Entries::Narrow($t) => $body,
            Entries::Wide($t) => $body,
        }
    };
}

/// Cells by slot: valid points packed in an arena (see the module documentation).
#[derive(Clone, Debug, Default)]
struct CellStore {
    /// Per slot: `offset << COUNT_BITS | count`; 0 for a slot without points.
    index: Paged<u32>,
    arena: Vec<u32>,
    /// Per block size, the first free block's offset + 1 (0: none); a free block's first
    /// word links to the next one the same way.
    free: [u32; CELL_POINTS + 1],
    /// Words of the arena in free blocks.
    free_words: usize,
}

impl CellStore {
    /// The valid points of `slot`, in order.
    #[inline]
    fn records(&self, slot: u32) -> &[u32] {
        let word = self.index.value(slot as usize);
        let (offset, count) = ((word >> COUNT_BITS) as usize, (word & 7) as usize);
        &self.arena[offset..offset + count]
    }

    /// Replace `slot`'s points with the valid words of `cell`, in order.
    fn set(&mut self, slot: u32, cell: &Cell) -> Result<(), PointsError> {
        let mut records = [0u32; CELL_POINTS];
        let mut n = 0;
        for &bits in cell.points.iter().filter(|&&b| is_valid(b)) {
            records[n] = bits;
            n += 1;
        }
        let s = slot as usize;
        let word = self.index.value(s);
        let (offset, count) = ((word >> COUNT_BITS) as usize, (word & 7) as usize);
        if count == n {
            self.arena[offset..offset + n].copy_from_slice(&records[..n]);
            return Ok(());
        }
        if count > 0 {
            self.arena[offset] = self.free[count];
            self.free[count] = offset as u32 + 1;
            self.free_words += count;
        }
        let word = if n == 0 {
            0
        } else {
            let offset = self.alloc(n)?;
            self.arena[offset..offset + n].copy_from_slice(&records[..n]);
            ((offset as u32) << COUNT_BITS) | n as u32
        };
        if s >= self.index.len() {
            self.index.grow(s + 1);
        }
        self.index.set(s, word);
        Ok(())
    }

    /// The offset of a block of `n` words: a freed one of that size, else the arena's end
    /// (grown by an eighth at a time, so spare capacity stays small).
    fn alloc(&mut self, n: usize) -> Result<usize, PointsError> {
        if let Some(offset) = (self.free[n] as usize).checked_sub(1) {
            self.free[n] = self.arena[offset];
            self.free_words -= n;
            return Ok(offset);
        }
        let offset = self.arena.len();
        if offset + n > MAX_ARENA {
            return Err(PointsError::ArenaFull { max: MAX_ARENA });
        }
        if self.arena.capacity() < offset + n {
            self.arena.reserve_exact((offset / 8).max(256));
        }
        self.arena.resize(offset + n, 0);
        Ok(offset)
    }

    fn points(&self) -> usize {
        self.arena.len() - self.free_words
    }
}

/// An instance grid as a client mirrors it: created empty from the layout
/// ([`MirrorGrid::new`]), written with received buckets and cells ([`MirrorGrid::set_bucket`],
/// [`MirrorGrid::set_cell`]), read by bucket index and cell slot in compacted form and by
/// cell coordinate ([`CellLookup`]). See the module documentation for the storage.
#[derive(Clone, Debug)]
pub struct MirrorGrid {
    layout: GridLayout,
    entries: Entries,
    cells: CellStore,
    /// Slots addressed so far (by a cell or a bucket entry); cells past it read as empty.
    slot_count: usize,
}

impl PartialEq for MirrorGrid {
    /// Same layout, slot count, buckets and cells (whatever the storage).
    fn eq(&self, other: &Self) -> bool {
        self.layout == other.layout
            && self.slot_count == other.slot_count
            && self.buckets().eq(other.buckets())
            && self.cells().eq(other.cells())
    }
}

impl CellLookup for MirrorGrid {
    fn layout(&self) -> &GridLayout {
        &self.layout
    }

    #[inline]
    fn cell_words(&self, coord: UVec3) -> Option<(u32, &[u32])> {
        let slot = self.find_cell(coord)?;
        ((slot as usize) < self.slot_count).then(|| (slot, self.cells.records(slot)))
    }
}

impl MirrorGrid {
    /// An empty mirror: every bucket empty, no cells. The layout's bucket count must be a
    /// power of two (see `psao_client::layout_is_usable`).
    pub fn new(layout: GridLayout) -> Self {
        let top = layout.dims.saturating_sub(UVec3::ONE);
        let narrow = layout.cell_id(top) < u64::from(u32::MAX);
        let buckets = layout.bucket_count.max(1);
        Self {
            entries: if narrow {
                Entries::Narrow(CellTable::new(buckets))
            } else {
                Entries::Wide(CellTable::new(buckets))
            },
            layout,
            cells: CellStore::default(),
            slot_count: 0,
        }
    }

    /// The mirror's layout.
    pub fn layout(&self) -> &GridLayout {
        &self.layout
    }

    /// Number of hash buckets (`layout().bucket_count`).
    pub fn bucket_count(&self) -> usize {
        self.layout.bucket_count as usize
    }

    /// Hash bucket `index`, its used entries first in order (empty when out of range).
    pub fn bucket(&self, index: usize) -> Bucket {
        let mut out = Bucket::default();
        if index < self.bucket_count() {
            with_table!(&self.entries, t => {
                for (dst, e) in out.entries.iter_mut().zip(t.entries_of(index as u64)) {
                    *dst = e;
                }
            });
        }
        out
    }

    /// All hash buckets in index order (`bucket_count()` of them), compacted.
    pub fn buckets(&self) -> impl Iterator<Item = Bucket> + '_ {
        (0..self.bucket_count()).map(|b| self.bucket(b))
    }

    /// Number of cell slots addressed so far (cells past it read as empty).
    pub fn slot_count(&self) -> usize {
        self.slot_count
    }

    /// The valid points of the cell in `slot`, in order (none when empty or never written).
    #[inline]
    pub fn records(&self, slot: u32) -> &[u32] {
        self.cells.records(slot)
    }

    /// The cell in `slot`, compacted (empty when free, never written, or past
    /// [`Self::slot_count`]).
    pub fn cell(&self, slot: u32) -> Cell {
        let mut cell = Cell::default();
        let records = self.records(slot);
        cell.points[..records.len()].copy_from_slice(records);
        cell
    }

    /// All cell slots below [`Self::slot_count`] in order, compacted.
    pub fn cells(&self) -> impl Iterator<Item = Cell> + '_ {
        (0..self.slot_count as u32).map(|s| self.cell(s))
    }

    /// Number of cells with bucket entries.
    pub fn cell_count(&self) -> usize {
        with_table!(&self.entries, t => t.len)
    }

    /// Number of stored points.
    pub fn point_count(&self) -> usize {
        self.cells.points()
    }

    /// Slot of the cell at `coord`, if a bucket entry names it.
    #[inline]
    pub fn find_cell(&self, coord: UVec3) -> Option<u32> {
        let key = self.layout.cell_id(coord) + 1;
        with_table!(&self.entries, t => t.find(key))
    }

    /// Replace bucket `index` (apply a received bucket). Every referenced slot must be
    /// addressable, every key must belong to a cell of this grid that hashes to this bucket,
    /// and no key may appear twice; on error nothing changes.
    pub fn set_bucket(&mut self, index: usize, bucket: Bucket) -> Result<(), PointsError> {
        if index >= self.bucket_count() {
            return Err(PointsError::BucketOutOfRange {
                index,
                count: self.bucket_count(),
            });
        }
        let used = || bucket.entries.iter().filter(|e| e.key != 0);
        for (k, e) in used().enumerate() {
            self.check_slot(e.slot)?;
            let id = e.key - 1;
            let duplicate = used().take(k).any(|d| d.key == e.key);
            if duplicate
                || self.layout.coord_of_id(id).is_none()
                || self.layout.bucket_of(id) != index
            {
                return Err(PointsError::InvalidBucketEntry {
                    bucket: index,
                    key: e.key,
                });
            }
        }
        with_table!(&mut self.entries, t => t.set_bucket(index as u64, &bucket));
        if let Some(top) = used().map(|e| e.slot as usize + 1).max() {
            self.slot_count = self.slot_count.max(top);
        }
        Ok(())
    }

    /// Replace the cell in `slot` (apply a received cell): its valid points are kept, in order.
    pub fn set_cell(&mut self, slot: u32, cell: Cell) -> Result<(), PointsError> {
        self.check_slot(slot)?;
        self.cells.set(slot, &cell)?;
        self.slot_count = self.slot_count.max(slot as usize + 1);
        Ok(())
    }

    /// Whether `cells` more cells fit in the arena whatever their points (else
    /// [`Self::set_cell`] may fail with [`PointsError::ArenaFull`]).
    pub fn has_room_for(&self, cells: usize) -> Result<(), PointsError> {
        let room = MAX_ARENA - self.cells.arena.len();
        if cells.saturating_mul(CELL_POINTS) > room {
            return Err(PointsError::ArenaFull { max: MAX_ARENA });
        }
        Ok(())
    }

    fn check_slot(&self, slot: u32) -> Result<(), PointsError> {
        let max = self.layout.max_cells();
        if slot as usize >= max {
            return Err(PointsError::CellSlotOutOfRange { slot, max });
        }
        Ok(())
    }

    /// Heap bytes the mirror holds (allocated capacity).
    pub fn heap_bytes(&self) -> u64 {
        self.memory_parts().total()
    }

    /// Where [`Self::heap_bytes`] goes, part by part (the parts add up to it).
    pub fn memory_parts(&self) -> MirrorMemory {
        let records = 4 * self.point_count() as u64;
        MirrorMemory {
            records,
            arena_slack: crate::vec_bytes(&self.cells.arena) - records,
            cell_index: self.cells.index.heap_bytes(),
            entry_table: with_table!(&self.entries, t => t.heap_bytes()),
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::grid::InstanceGrid;
    use crate::layout::tests::layout;
    use crate::pack::VALID_BIT;
    use crate::rng::mix64;

    /// A bucket of `index` with up to 8 distinct cells of it, in random slots.
    fn random_bucket(l: &GridLayout, index: usize, r: &mut u64) -> Bucket {
        let mut next = || {
            *r = mix64(*r);
            *r
        };
        let ids: Vec<u64> = (0..l.cell_id(l.dims - UVec3::ONE) + 1)
            .filter(|&id| l.coord_of_id(id).is_some() && l.bucket_of(id) == index)
            .collect();
        let mut bucket = Bucket::default();
        let n = (next() % 9) as usize;
        for k in 0..n {
            let id = ids[(next() as usize) % ids.len()];
            if !bucket_has(&bucket, id) {
                bucket.entries[k] = BucketEntry::new(id, (next() % l.max_cells() as u64) as u32);
            }
        }
        bucket
    }

    fn bucket_has(b: &Bucket, id: u64) -> bool {
        b.entries.iter().any(|e| e.key == id + 1)
    }

    fn random_cell(r: &mut u64) -> Cell {
        let mut cell = Cell::default();
        for w in &mut cell.points {
            *r = mix64(*r);
            // About a third of the words are empty, some invalid but not zero.
            *w = match *r % 6 {
                0 | 1 => 0,
                2 => (*r >> 8) as u32 & !VALID_BIT,
                _ => (*r >> 8) as u32 | VALID_BIT,
            };
        }
        cell
    }

    /// The mirror answers every bucket, slot and coordinate as a grid written with the same
    /// buckets and cells does, up to compaction, over many replacements (table growth,
    /// deletions inside probe runs, wrap-around, freed and reused arena blocks).
    #[test]
    fn mirror_answers_like_a_grid_written_the_same_way() {
        let l = layout();
        let (mut grid, mut mirror) = (InstanceGrid::new(l), MirrorGrid::new(l));
        let mut r = 7u64;
        for round in 0..3000 {
            r = mix64(r);
            if r.is_multiple_of(3) {
                let slot = (r >> 8) as u32 % l.max_cells() as u32;
                let cell = random_cell(&mut r);
                grid.set_cell(slot, cell).unwrap();
                mirror.set_cell(slot, cell).unwrap();
            } else {
                let index = (r >> 8) as usize % l.bucket_count as usize;
                let bucket = random_bucket(&l, index, &mut r);
                grid.set_bucket(index, bucket).unwrap();
                mirror.set_bucket(index, bucket).unwrap();
            }
            if round % 100 != 99 {
                continue;
            }
            assert_eq!(mirror.slot_count(), grid.slot_count());
            for b in 0..l.bucket_count as usize {
                assert_eq!(
                    mirror.bucket(b),
                    psao_compact_bucket(&grid.bucket(b)),
                    "bucket {b}"
                );
            }
            for s in 0..l.max_cells() as u32 {
                let valid: Vec<u32> = grid
                    .cell(s)
                    .points
                    .into_iter()
                    .filter(|&w| is_valid(w))
                    .collect();
                assert_eq!(mirror.records(s), &valid[..], "slot {s}");
            }
            for id in 0..l.cell_id(l.dims - UVec3::ONE) + 1 {
                let Some(c) = l.coord_of_id(id) else { continue };
                assert_eq!(mirror.find_cell(c), grid.find_cell(c));
                let words = |w: &[u32]| {
                    w.iter()
                        .copied()
                        .filter(|&b| is_valid(b))
                        .collect::<Vec<_>>()
                };
                assert_eq!(
                    mirror.cell_words(c).map(|(s, w)| (s, words(w))),
                    grid.cell_words(c).map(|(s, w)| (s, words(w)))
                );
            }
            let points: usize = (0..l.max_cells() as u32)
                .map(|s| grid.cell(s).count())
                .sum();
            assert_eq!(mirror.point_count(), points);
        }
        assert!(mirror.cell_count() > 0 && mirror.point_count() > 0);
    }

    /// The bucket's used entries first, in order.
    fn psao_compact_bucket(b: &Bucket) -> Bucket {
        let mut out = Bucket::default();
        for (dst, e) in out
            .entries
            .iter_mut()
            .zip(b.entries.iter().filter(|e| e.key != 0))
        {
            *dst = *e;
        }
        out
    }

    #[test]
    fn ids_past_32_bits_use_wide_keys() {
        let l = GridLayout {
            origin: Vec3::ZERO,
            cell_size: 1.0,
            dims: UVec3::new(1 << 20, 1 << 20, 2),
            poisson_radius: 0.25,
            bucket_count: 1 << 4,
        };
        let mut m = MirrorGrid::new(l);
        assert!(matches!(m.entries, Entries::Wide(_)));
        let c = UVec3::new(5, 7, 1);
        let id = l.cell_id(c);
        assert!(id > u64::from(u32::MAX));
        let mut b = Bucket::default();
        b.entries[3] = BucketEntry::new(id, 9);
        m.set_bucket(l.bucket_of(id), b).unwrap();
        let mut cell = Cell::default();
        cell.points[2] = VALID_BIT | 5;
        m.set_cell(9, cell).unwrap();
        assert_eq!(m.find_cell(c), Some(9));
        assert_eq!(m.cell_words(c), Some((9, &[VALID_BIT | 5][..])));
        assert_eq!(
            m.bucket(l.bucket_of(id)).entries[0],
            BucketEntry::new(id, 9)
        );
        assert!(matches!(
            MirrorGrid::new(layout()).entries,
            Entries::Narrow(_)
        ));
    }

    #[test]
    fn refused_buckets_change_nothing() {
        let l = layout();
        let mut m = MirrorGrid::new(l);
        let id = (0..).find(|&id| l.bucket_of(id) == 3).unwrap();
        let mut b = Bucket::default();
        b.entries[0] = BucketEntry::new(id, 1);
        b.entries[2] = BucketEntry::new(id, 2);
        assert!(matches!(
            m.set_bucket(3, b),
            Err(PointsError::InvalidBucketEntry { bucket: 3, .. })
        ));
        b.entries[2] = BucketEntry::default();
        assert!(m.set_bucket(4, b).is_err(), "hashes to bucket 3");
        assert!(m.set_bucket(16, b).is_err(), "out of range");
        b.entries[0].slot = l.max_cells() as u32;
        assert!(m.set_bucket(3, b).is_err(), "slot out of range");
        assert_eq!((m.cell_count(), m.slot_count(), m.heap_bytes()), (0, 0, 0));
    }

    #[test]
    fn cells_changing_size_reuse_freed_blocks() {
        let mut m = MirrorGrid::new(layout());
        let cell = |n: usize| {
            let mut c = Cell::default();
            for (k, w) in c.points.iter_mut().enumerate().take(n) {
                *w = VALID_BIT | k as u32;
            }
            c
        };
        for slot in 0..10 {
            m.set_cell(slot, cell(3)).unwrap();
        }
        let words = m.cells.arena.len();
        for round in 0..5 {
            for slot in 0..10 {
                m.set_cell(slot, cell(if (slot + round) % 2 == 0 { 2 } else { 3 }))
                    .unwrap();
            }
        }
        assert!(
            m.cells.arena.len() <= words + 2 * 10,
            "freed blocks are reused"
        );
        assert_eq!(m.point_count(), 5 * 2 + 5 * 3);
        m.set_cell(4, Cell::default()).unwrap();
        assert_eq!(m.records(4), &[] as &[u32]);
        let parts = m.memory_parts();
        assert_eq!(parts.records, 4 * m.point_count() as u64);
        assert_eq!(parts.total(), m.heap_bytes());
    }
}
