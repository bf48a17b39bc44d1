//! The client's mirror of an instance grid, stored for what it holds rather than in the
//! server's layout (DESIGN §3 "Grid"): the wire's addresses (bucket index, cell slot) are
//! answered exactly as an [`crate::InstanceGrid`] written with the same buckets and cells would
//! answer them, up to compaction (a bucket's used entries first, a cell's valid points first),
//! which is the form updates carry and the state hash reads.
//!
//! * Bucket entries live in one open-addressing table keyed by cell id ([`table`]), with
//!   linear probing from a home position that depends on the entry's bucket alone, stored in
//!   6 bytes per position (quotiented: the bucket is recovered from the position) where they
//!   fit. A bucket's entries lie in one probe run in the order they were inserted, so a bucket
//!   reads back (in order) by scanning that run, and a cell is found by its id in the same
//!   scan.
//! * Cells live in pages of 64 slots ([`cells`], [`PagedRuns`]): a 4-bit point count per slot
//!   and one vector of the page's valid points (4 bytes each).

use glam::UVec3;

use crate::error::PointsError;
use crate::grid::{Bucket, Cell};
use crate::layout::GridLayout;
use crate::lookup::CellLookup;

mod cells;
mod runs;
mod table;

use cells::CellStore;
pub use runs::{PagedRuns, MAX_RUN};
use table::CellTable;

/// Heap bytes of a [`MirrorGrid`] by what they hold ([`MirrorGrid::memory_parts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MirrorMemory {
    /// The valid points' packed records (4 bytes each).
    pub records: u64,
    /// Room in the cell pages' record vectors not holding a record.
    pub spare_records: u64,
    /// The cell pages' counts and vector headers, and their page table.
    pub cell_index: u64,
    /// The bucket-entry table (cell key and slot per table position, empty ones included).
    pub entry_table: u64,
}

impl MirrorMemory {
    /// All parts together: the mirror's heap bytes.
    pub fn total(&self) -> u64 {
        self.records + self.spare_records + self.cell_index + self.entry_table
    }

    /// The parts with their names, in the order of the fields.
    pub fn named(&self) -> [(&'static str, u64); 4] {
        [
            ("records (u32 per point)", self.records),
            ("spare room in cell pages", self.spare_records),
            ("cell pages (4-bit counts, 64 slots)", self.cell_index),
            ("bucket-entry table (6 or 12 bytes)", self.entry_table),
        ]
    }
}

impl std::ops::AddAssign for MirrorMemory {
    fn add_assign(&mut self, o: Self) {
        self.records += o.records;
        self.spare_records += o.spare_records;
        self.cell_index += o.cell_index;
        self.entry_table += o.entry_table;
    }
}

/// An instance grid as a client mirrors it: created empty from the layout
/// ([`MirrorGrid::new`]), written with received buckets and cells ([`MirrorGrid::set_bucket`],
/// [`MirrorGrid::set_cell`]), read by bucket index and cell slot in compacted form and by
/// cell coordinate ([`CellLookup`]). See the module documentation for the storage.
#[derive(Clone, Debug)]
pub struct MirrorGrid {
    layout: GridLayout,
    entries: CellTable,
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
        let max_slots = layout.max_cells() as u64;
        Self {
            entries: CellTable::new(layout.bucket_count, layout.cell_id(top), max_slots),
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
            for (dst, e) in out
                .entries
                .iter_mut()
                .zip(self.entries.entries_of(index as u64))
            {
                *dst = e;
            }
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
        self.entries.len()
    }

    /// Number of stored points.
    pub fn point_count(&self) -> usize {
        self.cells.points()
    }

    /// Slot of the cell at `coord`, if a bucket entry names it.
    #[inline]
    pub fn find_cell(&self, coord: UVec3) -> Option<u32> {
        let key = self.layout.cell_id(coord) + 1;
        self.entries.find(key)
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
        self.entries.set_bucket(index as u64, &bucket);
        if let Some(top) = used().map(|e| e.slot as usize + 1).max() {
            self.slot_count = self.slot_count.max(top);
        }
        Ok(())
    }

    /// Replace the cell in `slot` (apply a received cell): its valid points are kept, in order.
    pub fn set_cell(&mut self, slot: u32, cell: Cell) -> Result<(), PointsError> {
        self.check_slot(slot)?;
        self.cells.set(slot, &cell);
        self.slot_count = self.slot_count.max(slot as usize + 1);
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
            spare_records: self.cells.record_bytes() - records,
            cell_index: self.cells.index_bytes(),
            entry_table: self.entries.heap_bytes(),
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::grid::{BucketEntry, InstanceGrid};
    use crate::layout::tests::layout;
    use crate::pack::{is_valid, VALID_BIT};
    use crate::rng::mix64;

    /// A random cell coordinate of `l`.
    fn random_coord(l: &GridLayout, r: &mut u64) -> UVec3 {
        let mut axis = |d: u32| {
            *r = mix64(*r);
            (*r % u64::from(d)) as u32
        };
        UVec3::new(axis(l.dims.x), axis(l.dims.y), axis(l.dims.z))
    }

    /// The bucket of a random cell with up to 8 distinct cells of it (found among random
    /// coordinates), in random slots: its index and the bucket.
    fn random_bucket(l: &GridLayout, r: &mut u64) -> (usize, Bucket) {
        let index = l.bucket_of(l.cell_id(random_coord(l, r)));
        *r = mix64(*r);
        let n = (*r % 9) as usize;
        let mut bucket = Bucket::default();
        let mut k = 0;
        for _ in 0..4000 {
            if k == n {
                break;
            }
            let id = l.cell_id(random_coord(l, r));
            if l.bucket_of(id) == index && !bucket.entries.iter().any(|e| e.key == id + 1) {
                *r = mix64(*r);
                bucket.entries[k] = BucketEntry::new(id, (*r % l.max_cells() as u64) as u32);
                k += 1;
            }
        }
        (index, bucket)
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

    /// The bucket's used entries first, in order.
    fn compacted(b: &Bucket) -> Bucket {
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

    /// Writes `rounds` random buckets and cells into a mirror and a grid of `l`, comparing
    /// every bucket, every slot and the coordinates written (and random others) every 100
    /// rounds; returns the mirror.
    fn mirror_like_grid(l: GridLayout, rounds: usize, seed: u64) -> MirrorGrid {
        let (mut grid, mut mirror) = (InstanceGrid::new(l), MirrorGrid::new(l));
        let mut r = seed;
        let mut coords = Vec::new();
        for round in 0..rounds {
            r = mix64(r);
            if r.is_multiple_of(3) {
                let slot = (r >> 8) as u32 % l.max_cells() as u32;
                let cell = random_cell(&mut r);
                grid.set_cell(slot, cell).unwrap();
                mirror.set_cell(slot, cell).unwrap();
            } else {
                let (index, bucket) = random_bucket(&l, &mut r);
                coords.extend(
                    bucket
                        .entries
                        .iter()
                        .filter(|e| e.key != 0)
                        .filter_map(|e| l.coord_of_id(e.key - 1)),
                );
                grid.set_bucket(index, bucket).unwrap();
                mirror.set_bucket(index, bucket).unwrap();
            }
            if round % 100 != 99 {
                continue;
            }
            assert_eq!(mirror.slot_count(), grid.slot_count());
            for b in 0..l.bucket_count as usize {
                assert_eq!(mirror.bucket(b), compacted(&grid.bucket(b)), "bucket {b}");
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
            let others: Vec<UVec3> = (0..200).map(|_| random_coord(&l, &mut r)).collect();
            for &c in coords.iter().chain(&others) {
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
            let parts = mirror.memory_parts();
            assert_eq!(parts.records, 4 * points as u64);
            assert_eq!(parts.total(), mirror.heap_bytes());
        }
        assert!(mirror.cell_count() > 0 && mirror.point_count() > 0);
        mirror
    }

    /// The mirror answers every bucket, slot and coordinate as a grid written with the same
    /// buckets and cells does, up to compaction, over many replacements (table growth,
    /// deletions inside probe runs, wrap-around, pages filling and emptying), with quotiented
    /// (6-byte) table positions.
    #[test]
    fn mirror_answers_like_a_grid_written_the_same_way() {
        for seed in [7, 8, 9] {
            let m = mirror_like_grid(layout(), 3000, seed);
            assert!(m.entries.is_narrow());
        }
    }

    /// The same with cell ids past what 6 bytes hold: whole (12-byte) positions.
    #[test]
    fn huge_grids_use_whole_keys_and_answer_alike() {
        let l = GridLayout {
            origin: Vec3::ZERO,
            cell_size: 1.0,
            dims: UVec3::new(1 << 20, 1 << 20, 2),
            poisson_radius: 0.25,
            bucket_count: 1 << 4,
        };
        let m = mirror_like_grid(l, 1000, 11);
        assert!(!m.entries.is_narrow());
        let c = UVec3::new(5, 7, 1);
        assert!(l.cell_id(c) > u64::from(u32::MAX));
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
        assert!(m.set_bucket(1 << 20, b).is_err(), "out of range");
        b.entries[0].slot = l.max_cells() as u32;
        assert!(m.set_bucket(3, b).is_err(), "slot out of range");
        assert_eq!((m.cell_count(), m.slot_count(), m.heap_bytes()), (0, 0, 0));
    }

    #[test]
    fn cells_changing_size_stay_in_their_pages() {
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
        let bytes = m.heap_bytes();
        for round in 0..5 {
            for slot in 0..10 {
                m.set_cell(slot, cell(if (slot + round) % 2 == 0 { 2 } else { 3 }))
                    .unwrap();
            }
        }
        assert!(m.heap_bytes() <= bytes, "shrinking cells need no more room");
        assert_eq!(m.point_count(), 5 * 2 + 5 * 3);
        m.set_cell(4, Cell::default()).unwrap();
        assert_eq!(m.records(4), &[] as &[u32]);
        let parts = m.memory_parts();
        assert_eq!(parts.records, 4 * m.point_count() as u64);
        assert_eq!(parts.total(), m.heap_bytes());
    }
}
