//! Per-instance storage: hash buckets → cells → packed points (DESIGN §3 "Grid", paper §3.2).
//!
//! Storage is addressed as two arrays so that a delta is simply "these bucket indices and these
//! cell slots changed": bucket `i` holds up to [`BUCKET_ENTRIES`] (cell key, cell slot) pairs
//! and cell `slot` up to [`CELL_POINTS`] packed 32-bit points (both stored sparsely). Empty entries are all-zero words
//! (key 0, invalid bit clear), so fresh storage is zeroed memory and entries can sit anywhere
//! in a bucket or cell (lookups check every entry; locations of points stay stable).

use glam::{UVec3, Vec3};

use crate::error::PointsError;
#[cfg(feature = "generate")]
use crate::generate::InstancePoints;
use crate::layout::{DecodedPoint, GridLayout, BUCKET_ENTRIES, CELL_POINTS};
use crate::pack::is_valid;
use crate::paged::{BucketTable, Paged};

/// One hash-bucket entry: which cell lives in which slot. Packed to 4-byte alignment so an
/// entry takes 12 bytes, not 16: bucket tables are the largest part of a grid (server and
/// client), and fields are only ever read or written by value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(C, packed(4))]
pub struct BucketEntry {
    /// Cell id + 1 ([`GridLayout::cell_id`]); 0 marks an empty entry.
    pub key: u64,
    /// Index of the cell in the instance's cell array.
    pub slot: u32,
}

impl BucketEntry {
    /// Entry for cell `id` stored in `slot`.
    pub fn new(id: u64, slot: u32) -> Self {
        Self { key: id + 1, slot }
    }

    /// The cell id, or `None` for an empty entry.
    pub fn cell_id(&self) -> Option<u64> {
        self.key.checked_sub(1)
    }
}

/// A hash bucket: up to [`BUCKET_ENTRIES`] cells whose ids hash here.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Bucket {
    /// The entries, empty ones anywhere.
    pub entries: [BucketEntry; BUCKET_ENTRIES],
}

impl Bucket {
    /// Slot of the cell with id `id`, if this bucket holds it.
    #[inline]
    pub fn find(&self, id: u64) -> Option<u32> {
        let key = id + 1;
        self.entries.iter().find(|e| e.key == key).map(|e| e.slot)
    }

    /// Number of non-empty entries.
    pub fn len(&self) -> usize {
        self.entries.iter().filter(|e| e.key != 0).count()
    }

    /// True when no entry is used.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A cell: up to [`CELL_POINTS`] packed points (see [`crate::pack`]); 0 = empty entry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Cell {
    /// Packed points, empty ones anywhere.
    pub points: [u32; CELL_POINTS],
}

impl Cell {
    /// Number of valid points.
    pub fn count(&self) -> usize {
        self.points.iter().filter(|&&b| is_valid(b)).count()
    }
}

/// Heap bytes of an [`InstanceGrid`] by what they hold ([`InstanceGrid::memory_parts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GridMemory {
    /// The packed records of the valid points (4 bytes each).
    pub records: u64,
    /// Empty record entries of cells holding at least one point.
    pub empty_entries: u64,
    /// Cell slots of allocated pages that hold no point.
    pub unheld_cells: u64,
    /// The cell pages' table (one pointer per page of cell slots).
    pub cell_page_table: u64,
    /// Per-bucket chain heads (page table and pages).
    pub bucket_heads: u64,
    /// The bucket entry pool (key, slot, link).
    pub bucket_entries: u64,
    /// The server side's slot keys and free slots.
    pub slot_lists: u64,
}

impl GridMemory {
    /// All parts together: the grid's heap bytes.
    pub fn total(&self) -> u64 {
        self.records
            + self.empty_entries
            + self.unheld_cells
            + self.cell_page_table
            + self.bucket_heads
            + self.bucket_entries
            + self.slot_lists
    }

    /// The parts with their names, in the order of the fields.
    pub fn named(&self) -> [(&'static str, u64); 7] {
        [
            ("records (u32 per point)", self.records),
            ("empty entries of held cells", self.empty_entries),
            ("unheld cells of allocated pages", self.unheld_cells),
            ("cell page table", self.cell_page_table),
            ("bucket heads", self.bucket_heads),
            ("bucket entries", self.bucket_entries),
            ("slot lists", self.slot_lists),
        ]
    }
}

impl std::ops::AddAssign for GridMemory {
    fn add_assign(&mut self, o: Self) {
        self.records += o.records;
        self.empty_entries += o.empty_entries;
        self.unheld_cells += o.unheld_cells;
        self.cell_page_table += o.cell_page_table;
        self.bucket_heads += o.bucket_heads;
        self.bucket_entries += o.bucket_entries;
        self.slot_lists += o.slot_lists;
    }
}

/// Where a point is stored: its cell slot and its index inside the cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PointLoc {
    /// Cell slot.
    pub slot: u32,
    /// Index inside the cell, `0..CELL_POINTS`.
    pub index: u8,
}

/// Read for absent cells.
static EMPTY_CELL: Cell = Cell {
    points: [0; CELL_POINTS],
};

/// The hash grid of one instance. The server builds and updates it; tests and tools can also
/// create an empty one from the layout ([`InstanceGrid::new`]) and write buckets and cells with
/// [`InstanceGrid::set_bucket`] / [`InstanceGrid::set_cell`] (clients mirror into a
/// [`crate::MirrorGrid`], which stores only what it holds).
///
/// Storage is sparse (see [`crate::paged`]): bucket `i` and cell slot `s` are addressable for
/// every `i < bucket_count()` and `s < max_cells()`, but only written entries and pages of
/// written cells take memory; the rest read as empty.
#[derive(Clone, Debug)]
pub struct InstanceGrid {
    layout: GridLayout,
    buckets: BucketTable,
    cells: Paged<Cell>,
    /// Key of the cell in each slot allocated by [`Self::build`] / [`Self::insert`] (0 when
    /// free); not kept for buckets written with [`Self::set_bucket`].
    slot_keys: Vec<u64>,
    /// Free slots below `cells.len()` (server side), reused last-freed first.
    free: Vec<u32>,
    overflow_cells: u64,
    overflow_points: u64,
}

impl PartialEq for InstanceGrid {
    /// Same layout, buckets, cell slots and overflow counters (whatever the storage).
    fn eq(&self, other: &Self) -> bool {
        self.layout == other.layout
            && self.slot_count() == other.slot_count()
            && (self.overflow_cells, self.overflow_points)
                == (other.overflow_cells, other.overflow_points)
            && self.buckets().eq(other.buckets())
            && self.cells().eq(other.cells())
    }
}

impl crate::CellLookup for InstanceGrid {
    fn layout(&self) -> &GridLayout {
        &self.layout
    }

    #[inline]
    fn cell_words(&self, coord: UVec3) -> Option<(u32, &[u32])> {
        let slot = self.find_cell(coord)?;
        self.slot_cell(slot).map(|cell| (slot, &cell.points[..]))
    }
}

impl InstanceGrid {
    /// Heap bytes the grid's tables hold (allocated capacity).
    pub fn heap_bytes(&self) -> u64 {
        self.memory_parts().total()
    }

    /// Where [`Self::heap_bytes`] goes, part by part (the parts add up to it).
    pub fn memory_parts(&self) -> GridMemory {
        let (mut held_cells, mut points) = (0u64, 0u64);
        for cell in self.cells().filter(|c| c.count() > 0) {
            held_cells += 1;
            points += cell.count() as u64;
        }
        let cell_bytes = std::mem::size_of::<Cell>() as u64;
        let record_bytes = std::mem::size_of::<u32>() as u64;
        GridMemory {
            records: points * record_bytes,
            empty_entries: held_cells * cell_bytes - points * record_bytes,
            unheld_cells: self.cells.page_bytes() - held_cells * cell_bytes,
            cell_page_table: self.cells.page_table_bytes(),
            bucket_heads: self.buckets.head_bytes(),
            bucket_entries: self.buckets.entry_bytes(),
            slot_lists: crate::vec_bytes(&self.slot_keys) + crate::vec_bytes(&self.free),
        }
    }

    /// An empty grid: all buckets empty, no cells.
    pub fn new(layout: GridLayout) -> Self {
        Self {
            buckets: BucketTable::new(layout.bucket_count as usize),
            layout,
            cells: Paged::new(0),
            slot_keys: Vec::new(),
            free: Vec::new(),
            overflow_cells: 0,
            overflow_points: 0,
        }
    }

    /// Build a grid from (local position, local normal, AO) triples. Returns the grid and, per
    /// input point, where it was stored (`None` when dropped). Cells are allocated in cell-id
    /// order; within a cell, points keep their input order and the first [`CELL_POINTS`] win.
    /// Every refused cell allocation (full bucket) counts once in [`Self::overflow_cells`];
    /// every dropped point (full bucket, full cell, outside the grid) in
    /// [`Self::overflow_points`].
    pub fn build<I>(layout: GridLayout, points: I) -> (Self, Vec<Option<PointLoc>>)
    where
        I: IntoIterator<Item = (Vec3, Vec3, f32)>,
    {
        let mut grid = Self::new(layout);
        let points: Vec<(Vec3, Vec3, f32)> = points.into_iter().collect();
        let mut locs = vec![None; points.len()];
        let mut keyed: Vec<(u64, UVec3, u32)> = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            match layout.cell_coord(p.0) {
                Some(c) => keyed.push((layout.cell_id(c), c, i as u32)),
                None => grid.overflow_points += 1,
            }
        }
        keyed.sort_unstable_by_key(|&(id, _, i)| (id, i));
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            let (id, coord, _) = group[0];
            let Ok(slot) = grid.alloc_cell(id) else {
                grid.overflow_cells += 1;
                grid.overflow_points += group.len() as u64;
                continue;
            };
            for (k, &(_, _, i)) in group.iter().enumerate() {
                if k >= CELL_POINTS {
                    grid.overflow_points += 1;
                    continue;
                }
                let (pos, normal, ao) = points[i as usize];
                grid.cells.get_mut(slot as usize).points[k] = layout.pack(coord, pos, normal, ao);
                locs[i as usize] = Some(PointLoc {
                    slot,
                    index: k as u8,
                });
            }
        }
        (grid, locs)
    }

    /// [`Self::build`] with [`GridLayout::for_points`] and the same AO for every point.
    #[cfg(feature = "generate")]
    pub fn from_points(
        points: &InstancePoints,
        ao: f32,
    ) -> Result<(Self, Vec<Option<PointLoc>>), PointsError> {
        let layout = GridLayout::for_points(points)?;
        Ok(Self::build(
            layout,
            points.points.iter().map(|p| (p.position, p.normal, ao)),
        ))
    }

    /// The grid's layout.
    pub fn layout(&self) -> &GridLayout {
        &self.layout
    }

    /// Number of hash buckets (`layout().bucket_count`).
    pub fn bucket_count(&self) -> usize {
        self.buckets.len()
    }

    /// Hash bucket `index` (empty when out of range).
    pub fn bucket(&self, index: usize) -> Bucket {
        if index < self.buckets.len() {
            self.buckets.bucket(index)
        } else {
            Bucket::default()
        }
    }

    /// All hash buckets in index order (`bucket_count()` of them).
    pub fn buckets(&self) -> impl Iterator<Item = Bucket> + '_ {
        (0..self.buckets.len()).map(|b| self.buckets.bucket(b))
    }

    /// Number of cell slots written so far (cells past it read as empty).
    pub fn slot_count(&self) -> usize {
        self.cells.len()
    }

    /// The cell in `slot` (empty when free, never written, or past [`Self::slot_count`]).
    #[inline]
    pub fn cell(&self, slot: u32) -> &Cell {
        self.cells.get(slot as usize).unwrap_or(&EMPTY_CELL)
    }

    /// All cell slots below [`Self::slot_count`] in order (free slots are all-zero).
    pub fn cells(&self) -> impl Iterator<Item = &Cell> + '_ {
        (0..self.cells.len() as u32).map(|s| self.cell(s))
    }

    /// Cell allocations refused because the bucket was full.
    pub fn overflow_cells(&self) -> u64 {
        self.overflow_cells
    }

    /// Points dropped because their bucket or cell was full or they fell outside the grid.
    pub fn overflow_points(&self) -> u64 {
        self.overflow_points
    }

    /// Number of allocated cells (used bucket entries).
    pub fn cell_count(&self) -> usize {
        self.buckets.used()
    }

    /// Number of stored points.
    pub fn point_count(&self) -> usize {
        self.cells().map(Cell::count).sum()
    }

    /// Slot of the cell at `coord`, if allocated.
    #[inline]
    pub fn find_cell(&self, coord: UVec3) -> Option<u32> {
        let id = self.layout.cell_id(coord);
        self.buckets.find(self.layout.bucket_of(id), id + 1)
    }

    /// The cell in `slot` if the slot is below [`Self::slot_count`].
    #[inline]
    fn slot_cell(&self, slot: u32) -> Option<&Cell> {
        ((slot as usize) < self.cells.len()).then(|| self.cell(slot))
    }

    /// Slot of the allocated cell containing local position `p`.
    pub fn cell_of(&self, p: Vec3) -> Option<u32> {
        self.layout.cell_coord(p).and_then(|c| self.find_cell(c))
    }

    /// The allocated cells among the 2×2×2 cells whose centres surround local position `p`,
    /// as (cell coordinate, slot); unallocated or out-of-grid cells are `None`.
    pub fn nearest_cells(&self, p: Vec3) -> [Option<(UVec3, u32)>; 8] {
        let base = self.layout.nearest_base(p);
        std::array::from_fn(|k| {
            let offset = glam::IVec3::new((k & 1) as i32, ((k >> 1) & 1) as i32, (k >> 2) as i32);
            let c = self.layout.checked_coord(base.saturating_add(offset))?;
            self.find_cell(c).map(|slot| (c, slot))
        })
    }

    /// The decoded points of the cell at `coord` (nothing when it is not allocated).
    pub fn cell_points(&self, coord: UVec3) -> impl Iterator<Item = DecodedPoint> + '_ {
        let cell = self.find_cell(coord).and_then(|s| self.slot_cell(s));
        cell.into_iter()
            .flat_map(|c| c.points.iter())
            .filter_map(move |&bits| self.layout.unpack(coord, bits))
    }

    /// The packed record at `loc`, if it holds a point.
    pub fn point(&self, loc: PointLoc) -> Option<u32> {
        let bits = *self
            .slot_cell(loc.slot)?
            .points
            .get(usize::from(loc.index))?;
        is_valid(bits).then_some(bits)
    }

    /// Store a point at local position `position`. Overflow (full bucket, full cell, outside
    /// the grid) drops the point, is counted, and is reported as the matching error.
    pub fn insert(
        &mut self,
        position: Vec3,
        normal: Vec3,
        ao: f32,
    ) -> Result<PointLoc, PointsError> {
        let Some(coord) = self.layout.cell_coord(position) else {
            self.overflow_points += 1;
            return Err(PointsError::OutsideGrid(position));
        };
        let id = self.layout.cell_id(coord);
        let slot = match self.find_cell(coord) {
            Some(slot) => slot,
            None => self.alloc_cell(id).inspect_err(|_| {
                self.overflow_cells += 1;
                self.overflow_points += 1;
            })?,
        };
        let bits = self.layout.pack(coord, position, normal, ao);
        let cell = self.cells.get_mut(slot as usize);
        let Some(index) = cell.points.iter().position(|&b| !is_valid(b)) else {
            self.overflow_points += 1;
            return Err(PointsError::CellFull { slot });
        };
        cell.points[index] = bits;
        Ok(PointLoc {
            slot,
            index: index as u8,
        })
    }

    /// Remove the point at `loc`; a cell left empty is freed and its bucket entry cleared.
    pub fn remove(&mut self, loc: PointLoc) -> Result<(), PointsError> {
        self.point(loc).ok_or(PointsError::NoSuchPoint {
            slot: loc.slot,
            index: loc.index,
        })?;
        let slot = loc.slot as usize;
        let cell = self.cells.get_mut(slot);
        cell.points[usize::from(loc.index)] = 0;
        if cell.count() == 0 {
            let key = self.slot_keys.get_mut(slot).map_or(0, std::mem::take);
            if let Some(id) = key.checked_sub(1) {
                self.buckets.remove(self.layout.bucket_of(id), key);
                self.free.push(loc.slot);
            }
        }
        Ok(())
    }

    /// Move/refresh the point at `loc`: rewritten in place when it stays in its cell, else
    /// removed and re-inserted (an overflow then drops it and is reported like [`Self::insert`]).
    pub fn update(
        &mut self,
        loc: PointLoc,
        position: Vec3,
        normal: Vec3,
        ao: f32,
    ) -> Result<PointLoc, PointsError> {
        self.point(loc).ok_or(PointsError::NoSuchPoint {
            slot: loc.slot,
            index: loc.index,
        })?;
        if let Some(coord) = self.layout.cell_coord(position) {
            if self.slot_keys.get(loc.slot as usize) == Some(&(self.layout.cell_id(coord) + 1)) {
                let bits = self.layout.pack(coord, position, normal, ao);
                self.cells.get_mut(loc.slot as usize).points[usize::from(loc.index)] = bits;
                return Ok(loc);
            }
        }
        self.remove(loc)?;
        self.insert(position, normal, ao)
    }

    /// Replace bucket `index` (client side: apply a received bucket). Every referenced slot
    /// must be addressable and every key must belong to a cell of this grid that hashes to
    /// this bucket; slots get an (empty) cell if they have none yet.
    pub fn set_bucket(&mut self, index: usize, bucket: Bucket) -> Result<(), PointsError> {
        if index >= self.buckets.len() {
            return Err(PointsError::BucketOutOfRange {
                index,
                count: self.buckets.len(),
            });
        }
        for e in bucket.entries.iter().filter(|e| e.key != 0) {
            self.check_slot(e.slot)?;
            let id = e.key - 1;
            if self.layout.coord_of_id(id).is_none() || self.layout.bucket_of(id) != index {
                return Err(PointsError::InvalidBucketEntry {
                    bucket: index,
                    key: e.key,
                });
            }
        }
        self.buckets.set(index, &bucket)?;
        for e in bucket.entries.iter().filter(|e| e.key != 0) {
            self.cells.grow(e.slot as usize + 1);
        }
        Ok(())
    }

    /// Replace the cell in `slot` (client side: apply a received cell).
    pub fn set_cell(&mut self, slot: u32, cell: Cell) -> Result<(), PointsError> {
        self.check_slot(slot)?;
        self.cells.grow(slot as usize + 1);
        self.cells.set(slot as usize, cell);
        Ok(())
    }

    fn check_slot(&self, slot: u32) -> Result<(), PointsError> {
        let max = self.layout.max_cells();
        if slot as usize >= max {
            return Err(PointsError::CellSlotOutOfRange { slot, max });
        }
        Ok(())
    }

    /// Allocate a cell for `id` in its bucket (server side).
    fn alloc_cell(&mut self, id: u64) -> Result<u32, PointsError> {
        let b = self.layout.bucket_of(id);
        let slot = match self.free.last() {
            Some(&s) => s,
            None => self.cells.len() as u32,
        };
        if self.buckets.insert(b, id + 1, slot)?.is_none() {
            return Err(PointsError::BucketFull { bucket: b });
        }
        if self.free.pop().is_none() {
            self.cells.grow(slot as usize + 1);
        }
        if self.slot_keys.len() <= slot as usize {
            self.slot_keys.resize(slot as usize + 1, 0);
        }
        self.cells.set(slot as usize, Cell::default());
        self.slot_keys[slot as usize] = id + 1;
        Ok(slot)
    }
}
