//! Where the server stores every point: cells of an instance's hash grid allocated to slots,
//! and per slot the points in it. This is the allocation side of the grid (what the published
//! grid's buckets and cell slots are copied from); it holds indices of points, not their
//! packed records, which the server recomputes from the points when it publishes.
//!
//! Slots, bucket positions and in-cell indices are allocated exactly as
//! [`psao_points::InstanceGrid`] allocates them (build in cell-id order, free slots reused
//! last-freed first, a point goes to the first free index of its cell), so the published grid
//! and the state hash do not depend on which of the two did the allocating.

use glam::{UVec3, Vec3};
use psao_points::{
    vec_bytes, Bucket, BucketEntry, GridLayout, Paged, PointLoc, BUCKET_ENTRIES, CELL_POINTS,
};

/// Marks "no point" in a member list.
pub(crate) const NONE: u32 = u32::MAX;

/// Bits of a slot's link holding the next slot of its bucket (+1; 0 ends the chain); the
/// bits above hold the slot's position in its bucket.
const NEXT_BITS: u32 = 29;
const NEXT_MASK: u32 = (1 << NEXT_BITS) - 1;
/// Most slots an allocation can have (every slot must fit in [`NEXT_BITS`]).
const MAX_SLOTS: usize = NEXT_MASK as usize - 1;

/// Cell ids per slot: 32 bits each when every id of the layout fits (the usual case).
enum SlotIds {
    Narrow(Vec<u32>),
    Wide(Vec<u64>),
}

impl SlotIds {
    /// Empty, narrow when every cell id of `layout` fits in 32 bits.
    fn new(layout: &GridLayout) -> Self {
        let last = layout.cell_id(layout.dims - UVec3::ONE);
        if u32::try_from(last).is_ok() {
            Self::Narrow(Vec::new())
        } else {
            Self::Wide(Vec::new())
        }
    }

    #[inline]
    fn get(&self, slot: usize) -> Option<u64> {
        match self {
            Self::Narrow(v) => v.get(slot).map(|&id| u64::from(id)),
            Self::Wide(v) => v.get(slot).copied(),
        }
    }

    /// Set the id of `slot` (`id` is an id of the layout the ids were made for).
    fn set(&mut self, slot: usize, id: u64) {
        match self {
            Self::Narrow(v) => v[slot] = id as u32,
            Self::Wide(v) => v[slot] = id,
        }
    }

    fn push(&mut self) {
        match self {
            Self::Narrow(v) => v.push(0),
            Self::Wide(v) => v.push(0),
        }
    }

    fn reserve_exact(&mut self, n: usize) {
        match self {
            Self::Narrow(v) => v.reserve_exact(n),
            Self::Wide(v) => v.reserve_exact(n),
        }
    }

    fn heap_bytes(&self) -> u64 {
        match self {
            Self::Narrow(v) => vec_bytes(v),
            Self::Wide(v) => vec_bytes(v),
        }
    }
}

/// The allocation of one instance's points to grid cells.
pub(crate) struct CellAlloc {
    layout: GridLayout,
    /// Per bucket: its first allocated slot + 1 (0 = empty bucket).
    heads: Paged<u32>,
    /// Per allocated slot: the next slot of its bucket (chained in position order) and its
    /// position in the bucket (see [`NEXT_BITS`]). A bucket entry is (`ids[slot]` + 1, slot),
    /// so the chains are the hash table without a copy of the keys.
    links: Vec<u32>,
    /// Per slot: the points stored there ([`NONE`] = free index).
    members: Vec<[u32; CELL_POINTS]>,
    /// Per slot: the id of the cell allocated there (stale once the slot is freed).
    ids: SlotIds,
    /// Free slots, reused last-freed first.
    free: Vec<u32>,
    /// Stored points.
    stored: usize,
    overflow_cells: u64,
    overflow_points: u64,
}

impl CellAlloc {
    /// Store the points at local `positions` (point `i` at `positions[i]`): cells are
    /// allocated in cell-id order and within a cell points keep their index order, the first
    /// [`CELL_POINTS`] winning. Returns the allocation and each point's location (`None`
    /// when it overflowed or lies outside the grid).
    pub fn build(layout: GridLayout, positions: &[Vec3]) -> (Self, Vec<Option<PointLoc>>) {
        let mut alloc = Self {
            heads: Paged::new(layout.bucket_count as usize),
            layout,
            links: Vec::new(),
            members: Vec::new(),
            ids: SlotIds::new(&layout),
            free: Vec::new(),
            stored: 0,
            overflow_cells: 0,
            overflow_points: 0,
        };
        let mut locs = vec![None; positions.len()];
        let mut keyed: Vec<(u64, u32)> = Vec::with_capacity(positions.len());
        for (i, &p) in positions.iter().enumerate() {
            match layout.cell_coord(p) {
                Some(c) => keyed.push((layout.cell_id(c), i as u32)),
                None => alloc.overflow_points += 1,
            }
        }
        keyed.sort_unstable();
        let cells = keyed.chunk_by(|a, b| a.0 == b.0).count();
        alloc.members.reserve_exact(cells);
        alloc.ids.reserve_exact(cells);
        alloc.links.reserve_exact(cells);
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            let Some(slot) = alloc.alloc_cell(group[0].0) else {
                alloc.overflow_cells += 1;
                alloc.overflow_points += group.len() as u64;
                continue;
            };
            for (k, &(_, i)) in group.iter().enumerate() {
                if k >= CELL_POINTS {
                    alloc.overflow_points += 1;
                    continue;
                }
                alloc.members[slot as usize][k] = i;
                alloc.stored += 1;
                locs[i as usize] = Some(PointLoc {
                    slot,
                    index: k as u8,
                });
            }
        }
        (alloc, locs)
    }

    /// The grid layout.
    pub fn layout(&self) -> &GridLayout {
        &self.layout
    }

    /// Heap bytes of the tables.
    pub fn heap_bytes(&self) -> u64 {
        self.heads.heap_bytes()
            + vec_bytes(&self.links)
            + vec_bytes(&self.members)
            + self.ids.heap_bytes()
            + vec_bytes(&self.free)
    }

    /// Number of slots ever allocated (free ones included).
    pub fn slot_count(&self) -> usize {
        self.members.len()
    }

    /// The points in `slot` ([`NONE`] at free indices).
    #[inline]
    pub fn members(&self, slot: u32) -> &[u32; CELL_POINTS] {
        &self.members[slot as usize]
    }

    /// Id of the cell in `slot` (of the cell last there when the slot is free).
    #[inline]
    pub fn slot_id(&self, slot: u32) -> Option<u64> {
        self.ids.get(slot as usize)
    }

    /// The slots of bucket `b`, in position order.
    #[inline]
    fn chain(&self, b: usize) -> impl Iterator<Item = u32> + '_ {
        let first = self.heads.value(b).checked_sub(1);
        std::iter::successors(first, |&s| {
            (self.links[s as usize] & NEXT_MASK).checked_sub(1)
        })
    }

    /// Position of `slot` in its bucket.
    #[inline]
    fn position(&self, slot: u32) -> usize {
        (self.links[slot as usize] >> NEXT_BITS) as usize
    }

    /// Point the chain element before some slot (`before`, or the head of bucket `b` when
    /// `None`) to `next`.
    fn relink(&mut self, b: usize, before: Option<u32>, next: Option<u32>) {
        let next = next.map_or(0, |n| n + 1);
        match before {
            Some(p) => {
                let link = &mut self.links[p as usize];
                *link = (*link & !NEXT_MASK) | next;
            }
            None => self.heads.set(b, next),
        }
    }

    /// Id of the cell in allocated `slot`.
    #[inline]
    fn id(&self, slot: u32) -> u64 {
        self.ids.get(slot as usize).unwrap_or_default()
    }

    /// Bucket `b` as allocated.
    pub fn bucket(&self, b: usize) -> Bucket {
        let mut out = Bucket::default();
        for s in self.chain(b) {
            out.entries[self.position(s)] = BucketEntry::new(self.id(s), s);
        }
        out
    }

    /// Slot of the cell at `coord`, if allocated.
    #[inline]
    pub fn find_cell(&self, coord: UVec3) -> Option<u32> {
        let id = self.layout.cell_id(coord);
        self.chain(self.layout.bucket_of(id))
            .find(|&s| self.id(s) == id)
    }

    /// Number of stored points.
    pub fn point_count(&self) -> usize {
        self.stored
    }

    /// Cell allocations refused because the bucket was full.
    pub fn overflow_cells(&self) -> u64 {
        self.overflow_cells
    }

    /// Points not stored because their bucket or cell was full or they fell outside the grid.
    pub fn overflow_points(&self) -> u64 {
        self.overflow_points
    }

    /// Store point `i` at local `position` in the cell containing it (allocated if needed).
    /// `None` (counted as an overflow) when the cell's bucket or the cell is full or the
    /// position lies outside the grid.
    pub fn insert(&mut self, i: u32, position: Vec3) -> Option<PointLoc> {
        let Some(coord) = self.layout.cell_coord(position) else {
            self.overflow_points += 1;
            return None;
        };
        let slot = match self.find_cell(coord) {
            Some(slot) => slot,
            None => {
                let Some(slot) = self.alloc_cell(self.layout.cell_id(coord)) else {
                    self.overflow_cells += 1;
                    self.overflow_points += 1;
                    return None;
                };
                slot
            }
        };
        let cell = &mut self.members[slot as usize];
        let Some(index) = cell.iter().position(|&m| m == NONE) else {
            self.overflow_points += 1;
            return None;
        };
        cell[index] = i;
        self.stored += 1;
        Some(PointLoc {
            slot,
            index: index as u8,
        })
    }

    /// Remove point `i` from `slot` (nothing when it is not there); a cell left empty is
    /// freed and its bucket entry cleared.
    pub fn remove(&mut self, i: u32, slot: u32) {
        let cell = &mut self.members[slot as usize];
        let Some(k) = cell.iter().position(|&m| m == i) else {
            return;
        };
        cell[k] = NONE;
        self.stored -= 1;
        if cell.iter().all(|&m| m == NONE) {
            let b = self.layout.bucket_of(self.id(slot));
            let before = self.chain(b).take_while(|&s| s != slot).last();
            let after = (self.links[slot as usize] & NEXT_MASK).checked_sub(1);
            self.relink(b, before, after);
            self.links[slot as usize] = 0;
            self.free.push(slot);
        }
    }

    /// Allocate a slot for the cell `id` at the first free position of its bucket; `None`
    /// when the bucket is full (or every slot number is taken).
    fn alloc_cell(&mut self, id: u64) -> Option<u32> {
        let b = self.layout.bucket_of(id);
        // The first position not taken, and the slot after which it goes.
        let mut position = 0;
        let mut before = None;
        for s in self.chain(b) {
            if self.position(s) != position {
                break;
            }
            position += 1;
            before = Some(s);
        }
        if position >= BUCKET_ENTRIES {
            return None;
        }
        let slot = match self.free.pop() {
            Some(s) => s,
            None if self.members.len() < MAX_SLOTS => {
                self.members.push([NONE; CELL_POINTS]);
                self.ids.push();
                self.links.push(0);
                self.members.len() as u32 - 1
            }
            None => return None,
        };
        let after = match before {
            Some(p) => self.links[p as usize] & NEXT_MASK,
            None => self.heads.value(b),
        };
        self.links[slot as usize] = ((position as u32) << NEXT_BITS) | after;
        self.relink(b, before, Some(slot));
        self.members[slot as usize] = [NONE; CELL_POINTS];
        self.ids.set(slot as usize, id);
        Some(slot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_points::InstanceGrid;

    /// Positions on a few planes through a small grid, many sharing cells.
    fn positions(n: usize, seed: u32) -> Vec<Vec3> {
        let mut x = seed.wrapping_mul(2654435761) | 1;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 10_000) as f32 / 10_000.0
        };
        (0..n)
            .map(|_| Vec3::new(next() * 3.0, (next() * 3.0).floor() * 0.9, next() * 2.0))
            .collect()
    }

    #[test]
    fn allocates_like_the_instance_grid() {
        // A small table so buckets fill and cells overflow.
        let layout = GridLayout::new((Vec3::ZERO, Vec3::splat(3.0)), 0.05, 0.2, 2.0).unwrap();
        let start = positions(800, 7);
        let normal = Vec3::Y;
        let (mut grid, grid_locs) =
            InstanceGrid::build(layout, start.iter().map(|&p| (p, normal, 1.0)));
        let (mut alloc, locs) = CellAlloc::build(layout, &start);
        assert_eq!(locs, grid_locs);
        assert!(alloc.overflow_points() > 0, "the test must overflow");
        // Move points around (removing and re-inserting), as the dynamics do.
        let mut locs = locs;
        let mut now = start.clone();
        for (i, p) in positions(800, 9).into_iter().enumerate().take(500) {
            now[i] = p;
            if let Some(loc) = locs[i] {
                grid.remove(loc).unwrap();
                alloc.remove(i as u32, loc.slot);
            }
            let g = grid.insert(p, normal, 1.0).ok();
            locs[i] = alloc.insert(i as u32, p);
            assert_eq!(locs[i], g, "point {i}");
        }
        for b in 0..grid.bucket_count() {
            assert_eq!(alloc.bucket(b), grid.bucket(b), "bucket {b}");
        }
        assert_eq!(alloc.slot_count(), grid.slot_count());
        assert_eq!(alloc.point_count(), grid.point_count());
        assert_eq!(
            (alloc.overflow_cells(), alloc.overflow_points()),
            (grid.overflow_cells(), grid.overflow_points())
        );
        for (i, loc) in locs.iter().enumerate() {
            if let Some(loc) = loc {
                assert_eq!(alloc.members(loc.slot)[usize::from(loc.index)], i as u32);
                let c = layout.cell_coord(now[i]).unwrap();
                assert_eq!(alloc.find_cell(c), Some(loc.slot));
                assert_eq!(alloc.slot_id(loc.slot), Some(layout.cell_id(c)));
            }
        }
    }

    #[test]
    fn cell_ids_past_32_bits_are_kept_whole() {
        let layout = GridLayout::new((Vec3::ZERO, Vec3::splat(4000.0)), 0.2, 1.0, 10.0).unwrap();
        let far = Vec3::new(3999.5, 3999.5, 3999.5);
        assert!(layout.cell_id(layout.cell_coord(far).unwrap()) > u64::from(u32::MAX));
        let (mut alloc, locs) = CellAlloc::build(layout, &[Vec3::ZERO, far]);
        assert!(matches!(alloc.ids, SlotIds::Wide(_)));
        let loc = alloc.insert(2, far).unwrap();
        assert_eq!(loc.slot, locs[1].unwrap().slot);
        let c = layout.cell_coord(far).unwrap();
        assert_eq!(alloc.slot_id(loc.slot), Some(layout.cell_id(c)));
        assert_eq!(alloc.find_cell(c), Some(loc.slot));
    }
}
