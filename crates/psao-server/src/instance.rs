//! Per-instance server state: the points, their allocation in the hash grid, their AO
//! accumulators, and the published (authoritative) grid that clients mirror.

use glam::{Affine3A, Mat3A, UVec3, Vec3};
use psao_points::{
    Bucket, Cell, GridLayout, InstancePoints, MirrorGrid, CELL_POINTS, DEFAULT_INTERPOLATION_FACTOR,
};

use crate::alloc::CellAlloc;
use crate::blocks::CullBlocks;
use crate::changes::{stamp, ChangeLog};
use crate::light::LightSums;
use crate::summary::BlockSummaries;
use crate::ServerError;

/// Marks "no point" in a member list.
pub(crate) use crate::alloc::NONE;

/// Server state of one mesh instance.
pub(crate) struct InstanceState {
    /// Local-to-world transform.
    pub transform: Affine3A,
    /// Inverse transpose of the linear part, for normals.
    pub normal_matrix: Mat3A,
    /// World-space bounds of the instance's points.
    pub world_bounds: (Vec3, Vec3),
    /// World-space distance within which a point still affects reconstruction (Poisson
    /// radius × interpolation factor): culling keeps points this close to the frustum.
    pub slack: f32,
    /// Poisson radius, local units.
    pub poisson_radius: f32,
    /// Where every stored point lives (all points, whether published or not).
    pub alloc: CellAlloc,
    /// The published grid: what clients mirror, kept as a client keeps it (a [`MirrorGrid`]:
    /// variable-length cells and one table of bucket entries, which costs what is published
    /// rather than fixed-size cells per slot).
    pub grid: MirrorGrid,
    /// Points (structure of arrays).
    pub points: Points,
    /// Server frame at which each published bucket / cell last changed (0 = never).
    /// (Saturated, see [`crate::changes::stamp`].)
    pub bucket_stamp: Vec<u32>,
    pub cell_stamp: Vec<u32>,
    /// Largest stamp of this instance.
    pub max_stamp: u64,
    /// The buckets and cells stamped in recent frames.
    pub changes: ChangeLog,
    /// The points in spatial blocks with local bounds, for culling.
    pub blocks: CullBlocks,
    /// Per block: stored points and unconverged points by selection bin.
    pub summaries: BlockSummaries,
    /// Published cells and buckets that points left (moved to another cell) since the last
    /// publish: they must be refreshed even if no point is republished into them.
    pub pending_cells: Vec<u32>,
    pub pending_buckets: Vec<usize>,
    /// With lighting: the published irradiance records of each published cell's points
    /// (same order as its point records; empty without lighting or past the last lit slot).
    pub light_cells: Vec<[u32; CELL_POINTS]>,
}

/// Per-point state of one instance.
#[derive(Default)]
pub(crate) struct Points {
    /// Local position and unit normal.
    pub position: Vec<Vec3>,
    pub normal: Vec<Vec3>,
    /// Whether the point is stored in the allocation (in the cell containing its position,
    /// see [`InstanceState::slot_of`]); clear when it overflowed.
    pub stored: Bits,
    /// Sum of AO samples and their number (at most [`crate::MAX_SAMPLES_LIMIT`], so 16 bits: read
    /// and write it through [`Points::samples`] and [`Points::set_samples`]).
    pub sum: Vec<f32>,
    pub count: Vec<u16>,
    /// Last published record (0 = never published), and whether it was published in the
    /// point's current slot (cleared when the point changes cell).
    pub published: Vec<u32>,
    pub published_here: Bits,
    /// Irradiance accumulators, when the server computes lighting.
    pub light: Option<LightSums>,
}

impl Points {
    /// Point `i`'s progress for selection and convergence: its AO samples, or with lighting
    /// the smaller of those and its light paths counted in AO samples (see `light.rs`).
    #[inline]
    pub fn progress(&self, i: usize) -> u32 {
        match &self.light {
            None => self.samples(i),
            Some(l) => self.samples(i).min(l.progress(i)),
        }
    }

    /// Point `i`'s AO samples.
    #[inline]
    pub fn samples(&self, i: usize) -> u32 {
        u32::from(self.count[i])
    }

    /// Set point `i`'s AO samples to `n`, which never exceeds the validated `max_samples`
    /// (at most [`crate::MAX_SAMPLES_LIMIT`]); larger values are held at the limit.
    #[inline]
    pub fn set_samples(&mut self, i: usize, n: u32) {
        self.count[i] = u16::try_from(n).unwrap_or(u16::MAX);
    }
}

/// One bit per point.
#[derive(Default)]
pub(crate) struct Bits(Vec<u64>);

impl Bits {
    /// `n` clear bits.
    pub fn new(n: usize) -> Self {
        Self(vec![0; n.div_ceil(64)])
    }

    /// `n` bits, bit `i` set to `f(i)`.
    pub fn from_fn(n: usize, f: impl Fn(usize) -> bool) -> Self {
        let mut bits = Self::new(n);
        for i in (0..n).filter(|&i| f(i)) {
            bits.set(i, true);
        }
        bits
    }

    /// Bit `i`.
    #[inline]
    pub fn get(&self, i: usize) -> bool {
        (self.0[i / 64] >> (i % 64)) & 1 != 0
    }

    /// Set bit `i` to `value`.
    #[inline]
    pub fn set(&mut self, i: usize, value: bool) {
        let mask = 1u64 << (i % 64);
        if value {
            self.0[i / 64] |= mask;
        } else {
            self.0[i / 64] &= !mask;
        }
    }

    /// Heap bytes of the words.
    pub fn heap_bytes(&self) -> u64 {
        psao_points::vec_bytes(&self.0)
    }
}

impl InstanceState {
    /// Build the allocation grid from generated points (DESIGN §3 layout) of instance
    /// `index`; nothing is published yet. `seed` spreads the tracing order. `deforming`
    /// instances get a grid padded by the mesh's largest extent on every side, so their points
    /// keep a cell when skinning moves them (cells are virtual: the padding costs no memory).
    /// Points count as converged at `max_samples` samples.
    pub fn new(
        points: &InstancePoints,
        transform: Affine3A,
        index: u32,
        seed: u64,
        deforming: bool,
        max_samples: u32,
    ) -> Result<Self, ServerError> {
        let mut layout = GridLayout::for_points(points)?;
        if deforming {
            let hi = layout.origin + layout.dims.as_vec3() * layout.cell_size;
            let pad = Vec3::splat((hi - layout.origin).max_element());
            layout = GridLayout::new(
                (layout.origin - pad, hi + pad),
                layout.poisson_radius,
                layout.cell_size,
                points.area_local,
            )?;
        }
        let positions: Vec<Vec3> = points.points.iter().map(|s| s.position).collect();
        let (alloc, locs) = CellAlloc::build(layout, &positions);
        let n = points.points.len();
        let p = Points {
            position: positions,
            normal: points.points.iter().map(|s| s.normal).collect(),
            stored: Bits::from_fn(n, |i| locs[i].is_some()),
            sum: vec![0.0; n],
            count: vec![0; n],
            published: vec![0; n],
            published_here: Bits::new(n),
            light: None,
        };
        let blocks = CullBlocks::new(&p.position, index, seed);
        let summaries = BlockSummaries::new(&blocks, &p, max_samples);
        let mut state = Self {
            transform,
            normal_matrix: transform.matrix3.inverse().transpose(),
            world_bounds: (Vec3::ZERO, Vec3::ZERO),
            slack: points.poisson_radius * DEFAULT_INTERPOLATION_FACTOR,
            poisson_radius: points.poisson_radius_local,
            grid: MirrorGrid::new(layout),
            bucket_stamp: vec![0; layout.bucket_count as usize],
            cell_stamp: vec![0; alloc.slot_count()],
            alloc,
            points: p,
            max_stamp: 0,
            changes: ChangeLog::default(),
            blocks,
            summaries,
            pending_cells: Vec::new(),
            pending_buckets: Vec::new(),
            light_cells: Vec::new(),
        };
        state.refresh_cull_bounds();
        Ok(state)
    }

    /// Recompute the culling bounds (world bounds and the blocks' local bounds) from the
    /// points' current local positions: call after points moved in local space.
    pub fn refresh_cull_bounds(&mut self) {
        self.refresh_world_bounds();
        self.blocks.refresh_bounds(&self.points.position);
    }

    /// Bring the block summaries of `changed` points up to date (after their sample count or
    /// storage changed).
    pub fn refresh_summaries(&mut self, changed: &[u32]) {
        self.summaries.refresh(&self.blocks, &self.points, changed);
    }

    /// Recompute every block summary (after most points changed).
    pub fn rebuild_summaries(&mut self) {
        self.summaries.rebuild(&self.blocks, &self.points);
    }

    /// Store `cell` in published slot `slot` and stamp it (and the change log) with `frame`.
    pub fn publish_cell(&mut self, slot: u32, cell: Cell, frame: u64) {
        let stored = self.grid.set_cell(slot, cell);
        debug_assert!(stored.is_ok(), "allocation slots are valid grid slots");
        self.cell_stamp[slot as usize] = stamp(frame);
        self.max_stamp = frame;
        self.changes.cell(frame, slot);
    }

    /// Store `bucket` in published bucket `b` and stamp it (and the change log) with `frame`.
    pub fn publish_bucket(&mut self, b: usize, bucket: Bucket, frame: u64) {
        let stored = self.grid.set_bucket(b, bucket);
        debug_assert!(stored.is_ok(), "allocation buckets are valid grid buckets");
        self.bucket_stamp[b] = stamp(frame);
        self.max_stamp = frame;
        self.changes.bucket(frame, b as u32);
    }

    /// Move the instance (rigid motion: points stay in local space).
    pub fn set_transform(&mut self, transform: Affine3A) {
        self.transform = transform;
        self.normal_matrix = transform.matrix3.inverse().transpose();
    }

    /// Recompute the world bounds after the transform changed (after points moved in local
    /// space, [`InstanceState::refresh_cull_bounds`] instead).
    pub fn refresh_world_bounds(&mut self) {
        self.world_bounds = world_bounds(&self.points.position, &self.transform);
    }

    /// Allocation slot of point `i`: the cell containing its position, when it is stored.
    #[inline]
    pub fn slot_of(&self, i: usize) -> Option<u32> {
        if !self.points.stored.get(i) {
            return None;
        }
        let slot = self
            .layout()
            .cell_coord(self.points.position[i])
            .and_then(|c| self.alloc.find_cell(c));
        debug_assert!(
            slot.is_some_and(|s| self.alloc.members(s).contains(&(i as u32))),
            "a stored point lives in the cell of its position"
        );
        slot
    }

    /// Store point `i` (already at its new local `position`; `old` is the slot it was stored
    /// in at its previous position) in the allocation cell that contains it: it leaves its
    /// old cell (freed when empty; the old cell and its bucket are queued for refreshing, and
    /// a publication there is withdrawn) and is inserted into the new one (allocated if
    /// needed). Overflow or leaving the grid leaves it unstored.
    pub fn rehome(&mut self, i: usize, old: Option<u32>, position: Vec3) {
        if let Some(old) = old {
            self.alloc.remove(i as u32, old);
            self.pending_cells.push(old);
            self.pending_buckets.push(self.slot_bucket(old));
            self.points.published_here.set(i, false);
        }
        let stored = self.alloc.insert(i as u32, position).is_some();
        self.points.stored.set(i, stored);
        let cells = self.alloc.slot_count();
        if self.cell_stamp.len() < cells {
            self.cell_stamp.resize(cells, 0);
        }
    }

    /// The grid layout.
    pub fn layout(&self) -> &GridLayout {
        self.alloc.layout()
    }

    /// Cell coordinate of allocation slot `slot`.
    pub fn slot_coord(&self, slot: u32) -> Option<UVec3> {
        self.layout().coord_of_id(self.alloc.slot_id(slot)?)
    }

    /// The hash bucket of the cell in allocation slot `slot`.
    pub fn slot_bucket(&self, slot: u32) -> usize {
        self.layout()
            .bucket_of(self.alloc.slot_id(slot).unwrap_or_default())
    }

    /// World position and unit normal of point `i`.
    #[inline]
    pub fn world(&self, i: usize) -> (Vec3, Vec3) {
        let p = self.transform.transform_point3(self.points.position[i]);
        let n = self.normal_matrix.mul_vec3(self.points.normal[i]);
        (p, n.normalize_or_zero())
    }

    /// The published content of slot `slot`: its members' published records, compacted.
    pub fn published_cell(&self, slot: u32) -> Cell {
        let mut cell = Cell::default();
        let records = self
            .alloc
            .members(slot)
            .iter()
            .filter(|&&m| m != NONE && self.points.published_here.get(m as usize))
            .map(|&m| self.points.published[m as usize]);
        for (dst, bits) in cell.points.iter_mut().zip(records) {
            *dst = bits;
        }
        cell
    }

    /// The irradiance records of [`InstanceState::published_cell`]'s points, in its order
    /// (`None` without lighting).
    pub fn published_light_cell(&self, slot: u32) -> Option<[u32; CELL_POINTS]> {
        let light = self.points.light.as_ref()?;
        let mut out = [0; CELL_POINTS];
        let records = self
            .alloc
            .members(slot)
            .iter()
            .filter(|&&m| m != NONE && self.points.published_here.get(m as usize))
            .map(|&m| light.published[m as usize]);
        for (dst, bits) in out.iter_mut().zip(records) {
            *dst = bits;
        }
        Some(out)
    }

    /// The published irradiance records of slot `slot` (zeros where none were published).
    pub fn light_cell(&self, slot: u32) -> [u32; CELL_POINTS] {
        self.light_cells
            .get(slot as usize)
            .copied()
            .unwrap_or_default()
    }

    /// The published content of bucket `b`: the allocation bucket's entries whose cells hold
    /// a published point, compacted. Reads the published grid's cells, so refresh those
    /// (with [`InstanceState::published_cell`]) first.
    pub fn published_bucket(&self, b: usize) -> Bucket {
        let mut bucket = Bucket::default();
        let alloc = self.alloc.bucket(b);
        let entries = alloc
            .entries
            .iter()
            .filter(|e| e.key != 0 && self.grid.cell(e.slot).points[0] != 0);
        for (dst, e) in bucket.entries.iter_mut().zip(entries) {
            *dst = *e;
        }
        bucket
    }
}

/// World-space bounds of local positions under `transform` (a point box if there are none).
fn world_bounds(positions: &[Vec3], transform: &Affine3A) -> (Vec3, Vec3) {
    let init = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let (lo, hi) = positions.iter().fold(init, |(lo, hi), p| {
        let w = transform.transform_point3(*p);
        (lo.min(w), hi.max(w))
    });
    if lo.cmple(hi).all() {
        (lo, hi)
    } else {
        let t = transform.translation.into();
        (t, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MAX_SAMPLES_LIMIT;

    #[test]
    fn sample_counts_read_back_up_to_the_limit() {
        let mut p = Points {
            count: vec![0; 4],
            ..Points::default()
        };
        for (i, n) in [0, 1, 256, MAX_SAMPLES_LIMIT].into_iter().enumerate() {
            p.set_samples(i, n);
            assert_eq!(p.samples(i), n);
            assert_eq!(p.progress(i), n);
        }
        assert_eq!(std::mem::size_of_val(&p.count[0]), 2, "16 bits per count");
    }
}
