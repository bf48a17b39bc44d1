//! Spatial blocks of an instance's points with local-space bounds, so culling tests a block
//! against the frusta before (or instead of) its points.

use glam::{Affine3A, Vec3};
use psao_points::vec_bytes;
use psao_trace::ao::hash64;

use crate::frustum::Frustum;
use crate::trace::sample_key;

/// Points per block (the last block of an instance may hold fewer).
pub(crate) const BLOCK_POINTS: usize = 512;
/// Points per sub-block: blocks straddling a frustum test their sub-blocks before their
/// points.
pub(crate) const SUB_POINTS: usize = 64;
/// Sub-blocks per block.
pub(crate) const SUBS_PER_BLOCK: usize = BLOCK_POINTS / SUB_POINTS;
/// Blocks per group: culling tests a group against the frusta before its blocks, so that
/// groups entirely inside or outside cost one test instead of one per block.
pub(crate) const GROUP_BLOCKS: usize = 16;

/// A run of `order` whose points lie in `(lo, hi)` (local space).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block {
    pub start: u32,
    pub end: u32,
    pub lo: Vec3,
    pub hi: Vec3,
}

/// Point indices in culling order and its inverse. The server numbers its points in this
/// order already ([`morton_order`]), so the identity is the usual case and is stored as
/// nothing.
pub(crate) enum PointOrder {
    /// Position `k` holds point `k`.
    Identity(usize),
    /// Position `k` holds point `order[k]`; point `i` sits at position `rank[i]`.
    Permuted { order: Vec<u32>, rank: Vec<u32> },
}

impl PointOrder {
    /// The order `order` (a permutation of `0..order.len()`).
    fn new(order: Vec<u32>) -> Self {
        if order.iter().copied().eq(0..order.len() as u32) {
            return Self::Identity(order.len());
        }
        let mut rank = vec![0; order.len()];
        for (k, &i) in order.iter().enumerate() {
            rank[i as usize] = k as u32;
        }
        Self::Permuted { order, rank }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        match self {
            Self::Identity(n) => *n,
            Self::Permuted { order, .. } => order.len(),
        }
    }

    /// The point at position `k`.
    #[inline]
    pub fn at(&self, k: usize) -> u32 {
        match self {
            Self::Identity(_) => k as u32,
            Self::Permuted { order, .. } => order[k],
        }
    }

    /// The position of point `i`.
    #[inline]
    pub fn rank(&self, i: u32) -> u32 {
        match self {
            Self::Identity(_) => i,
            Self::Permuted { rank, .. } => rank[i as usize],
        }
    }

    /// The points at positions `range`.
    pub fn range(&self, range: std::ops::Range<usize>) -> impl Iterator<Item = u32> + '_ {
        range.map(|k| self.at(k))
    }

    fn heap_bytes(&self) -> u64 {
        match self {
            Self::Identity(_) => 0,
            Self::Permuted { order, rank } => vec_bytes(order) + vec_bytes(rank),
        }
    }
}

/// An instance's points in Morton order of their initial local position, cut into blocks.
pub(crate) struct CullBlocks {
    /// Point indices, block after block.
    pub order: PointOrder,
    /// Instance index and seed of the selection tie-breaks ([`CullBlocks::tie`]).
    instance: u32,
    seed: u64,
    pub blocks: Vec<Block>,
    /// Local bounds of each run of [`SUB_POINTS`] points of `order` (sub-block `j` of block
    /// `b` is `subs[b * SUBS_PER_BLOCK + j]`; a short last block has fewer).
    pub subs: Vec<(Vec3, Vec3)>,
    /// Local bounds of each run of [`GROUP_BLOCKS`] blocks (the last may hold fewer).
    pub groups: Vec<(Vec3, Vec3)>,
}

/// How a block lies relative to one frustum grown by a slack.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    /// Every point of the block is inside.
    Inside,
    /// No point of the block is inside.
    Outside,
    /// Test the points.
    Straddles,
}

/// The selection tie-break of point `index` of instance `instance`: spreads equal sample
/// counts over the scene instead of taking them in index order.
pub(crate) fn tie_of(instance: u32, index: u32, seed: u64) -> u32 {
    hash64(sample_key(instance, index) ^ seed.rotate_left(29)) as u32
}

impl CullBlocks {
    /// Heap bytes of the order and bounds.
    pub fn heap_bytes(&self) -> u64 {
        self.order.heap_bytes()
            + vec_bytes(&self.blocks)
            + vec_bytes(&self.subs)
            + vec_bytes(&self.groups)
    }

    /// The selection tie-break of the point at position `k` (a seeded hash of the point,
    /// recomputed rather than stored).
    #[inline]
    pub fn tie(&self, k: usize) -> u32 {
        tie_of(self.instance, self.order.at(k), self.seed)
    }

    /// Blocks of `positions` (instance `instance`, tie-breaks from `seed`).
    pub fn new(positions: &[Vec3], instance: u32, seed: u64) -> Self {
        let order = PointOrder::new(morton_order(positions));
        let blocks: Vec<Block> = (0..order.len())
            .step_by(BLOCK_POINTS)
            .map(|start| Block {
                start: start as u32,
                end: (start + BLOCK_POINTS).min(order.len()) as u32,
                lo: Vec3::ZERO,
                hi: Vec3::ZERO,
            })
            .collect();
        let subs = vec![(Vec3::ZERO, Vec3::ZERO); blocks.len() * SUBS_PER_BLOCK];
        let groups = vec![(Vec3::ZERO, Vec3::ZERO); blocks.len().div_ceil(GROUP_BLOCKS)];
        let mut out = Self {
            order,
            instance,
            seed,
            blocks,
            subs,
            groups,
        };
        out.refresh_bounds(positions);
        out
    }

    /// Recompute every block's and sub-block's bounds from the current `positions` (call
    /// after points moved in local space; membership stays).
    pub fn refresh_bounds(&mut self, positions: &[Vec3]) {
        let (order, n) = (&self.order, self.order.len());
        for (start, sub) in (0..n).step_by(SUB_POINTS).zip(&mut self.subs) {
            let run = order.range(start..(start + SUB_POINTS).min(n));
            *sub = bounds(run.map(|i| positions[i as usize]));
        }
        for (b, block) in self.blocks.iter_mut().enumerate() {
            let n = (block.end - block.start) as usize;
            let subs = &self.subs[b * SUBS_PER_BLOCK..][..n.div_ceil(SUB_POINTS)];
            let init = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            let (lo, hi) = subs
                .iter()
                .fold(init, |(lo, hi), s| (lo.min(s.0), hi.max(s.1)));
            (block.lo, block.hi) = (lo, hi);
        }
        for (group, blocks) in self.groups.iter_mut().zip(self.blocks.chunks(GROUP_BLOCKS)) {
            let init = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            *group = blocks
                .iter()
                .fold(init, |(lo, hi), b| (lo.min(b.lo), hi.max(b.hi)));
        }
    }
}

impl Block {
    /// The block placed in the world by `transform`.
    pub fn world(&self, transform: &Affine3A) -> WorldBox {
        WorldBox::new((self.lo, self.hi), transform)
    }
}

/// A local box placed in the world: centre, half extents along the world axes, and its
/// magnitude (for the rounding margin). Computed once, tested against several frusta.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WorldBox {
    centre: Vec3,
    extent: Vec3,
    size: f32,
}

impl WorldBox {
    /// The box `(lo, hi)` under `transform`.
    #[inline]
    pub fn new((lo, hi): (Vec3, Vec3), transform: &Affine3A) -> Self {
        let centre = transform.transform_point3((lo + hi) * 0.5);
        let half = (hi - lo) * 0.5;
        let m = transform.matrix3;
        let extent = m.x_axis.abs() * half.x + m.y_axis.abs() * half.y + m.z_axis.abs() * half.z;
        let extent = Vec3::from(extent);
        Self {
            centre,
            extent,
            size: extent.max_element() + centre.abs().max_element(),
        }
    }

    /// Where the box lies relative to `frustum` grown by `slack`. Conservative with a
    /// margin for rounding: `Inside` and `Outside` hold for every point in the box that the
    /// per-point test [`Frustum::contains`] would see.
    #[inline]
    pub fn side(&self, frustum: &Frustum, slack: f32) -> Side {
        let mut inside = true;
        for plane in frustum.planes() {
            let n = plane.truncate();
            let d = n.dot(self.centre) + plane.w;
            let r = n.abs().dot(self.extent);
            // Rounding of the per-point transform and dot product stays far below this.
            let eps = 1e-4 * (1.0 + self.size + plane.w.abs());
            if d + r < -slack - eps {
                return Side::Outside;
            }
            // NaN planes (degenerate views) fail this and leave the decision to the points.
            inside &= d - r >= -slack + eps;
        }
        if inside {
            Side::Inside
        } else {
            Side::Straddles
        }
    }

    /// Whether the box lies inside one of `frusta` (grown by `slack`); when it does not,
    /// `straddling` (cleared first) holds the frusta it straddles.
    pub fn classify<'f>(
        &self,
        frusta: impl IntoIterator<Item = &'f Frustum>,
        slack: f32,
        straddling: &mut Vec<&'f Frustum>,
    ) -> bool {
        straddling.clear();
        for f in frusta {
            match self.side(f, slack) {
                Side::Inside => return true,
                Side::Straddles => straddling.push(f),
                Side::Outside => {}
            }
        }
        false
    }
}

/// Bounds of `points` (an empty box at the origin when there are none).
fn bounds(points: impl Iterator<Item = Vec3>) -> (Vec3, Vec3) {
    let init = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let (lo, hi) = points.fold(init, |(lo, hi), p| (lo.min(p), hi.max(p)));
    if lo.cmple(hi).all() {
        (lo, hi)
    } else {
        (Vec3::ZERO, Vec3::ZERO)
    }
}

/// The indices of `positions` in Morton order of their position in their bounding box
/// (10 bits per axis; equal codes by index). The server numbers each instance's generated
/// points in this order of their rest positions (so [`crate::Server::points`] lists them
/// so), and culls them in blocks of it. Positions already in this order give `0, 1, 2, …`.
pub fn morton_order(positions: &[Vec3]) -> Vec<u32> {
    let (lo, hi) = bounds(positions.iter().copied());
    let scale = 1023.0 / (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let mut keyed: Vec<(u32, u32)> = positions
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let q = ((p - lo) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0));
            (morton3(q.x as u32, q.y as u32, q.z as u32), i as u32)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Interleave the low 10 bits of x, y, z.
fn morton3(x: u32, y: u32, z: u32) -> u32 {
    fn spread(mut v: u32) -> u32 {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    }
    spread(x) | (spread(y) << 1) | (spread(z) << 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::View;
    use glam::Quat;
    use psao_scene::Camera;

    fn points() -> Vec<Vec3> {
        (0..30_000)
            .map(|i| {
                let h = hash64(i);
                let f = |s: u32| ((h >> s) & 0xffff) as f32 / 65535.0;
                Vec3::new(f(0) * 8.0 - 4.0, f(16) * 2.0, f(32) * 8.0 - 4.0)
            })
            .collect()
    }

    #[test]
    fn blocks_cover_every_point_once_and_bound_it() {
        let p = points();
        let b = CullBlocks::new(&p, 3, 7);
        let mut seen: Vec<u32> = b.order.range(0..p.len()).collect();
        seen.sort_unstable();
        for (k, &i) in seen.iter().enumerate() {
            assert_eq!(b.order.rank(b.order.at(k)), k as u32);
            assert_eq!(b.order.at(b.order.rank(i) as usize), i);
        }
        assert_eq!(seen, (0..p.len() as u32).collect::<Vec<_>>());
        assert_eq!(b.blocks.len(), p.len().div_ceil(BLOCK_POINTS));
        for blk in &b.blocks {
            for i in b.order.range(blk.start as usize..blk.end as usize) {
                let q = p[i as usize];
                assert!(q.cmpge(blk.lo).all() && q.cmple(blk.hi).all());
            }
        }
        for (k, i) in b.order.range(0..p.len()).enumerate() {
            let (lo, hi) = b.subs[k / SUB_POINTS];
            assert!(p[i as usize].cmpge(lo).all() && p[i as usize].cmple(hi).all());
        }
        for (g, blocks) in b.blocks.chunks(GROUP_BLOCKS).enumerate() {
            let (lo, hi) = b.groups[g];
            assert!(blocks
                .iter()
                .all(|blk| blk.lo.cmpge(lo).all() && blk.hi.cmple(hi).all()));
        }
        assert_eq!(b.groups.len(), b.blocks.len().div_ceil(GROUP_BLOCKS));
        assert_eq!(b.tie(0), tie_of(3, b.order.at(0), 7));
    }

    #[test]
    fn refreshed_bounds_hold_moved_points() {
        let p = points();
        let mut b = CullBlocks::new(&p, 0, 0);
        let moved: Vec<Vec3> = p.iter().map(|q| *q * 0.5 + Vec3::X).collect();
        b.refresh_bounds(&moved);
        for blk in &b.blocks {
            for i in b.order.range(blk.start as usize..blk.end as usize) {
                let q = moved[i as usize];
                assert!(q.cmpge(blk.lo).all() && q.cmple(blk.hi).all());
            }
        }
        for (k, i) in b.order.range(0..p.len()).enumerate() {
            let (lo, hi) = b.subs[k / SUB_POINTS];
            assert!(moved[i as usize].cmpge(lo).all() && moved[i as usize].cmple(hi).all());
        }
    }

    #[test]
    fn block_sides_agree_with_the_per_point_test() {
        let p = points();
        let b = CullBlocks::new(&p, 0, 0);
        let transform = Affine3A::from_scale_rotation_translation(
            Vec3::splat(1.5),
            Quat::from_rotation_y(0.7),
            Vec3::new(1.0, 0.0, -2.0),
        );
        let mut sides = [0; 3];
        // A narrow view (some blocks outside) and a wide one (some blocks inside).
        for (eye, target, fov) in [
            (Vec3::new(0.0, 1.0, 5.0), Vec3::new(2.0, 0.5, -1.0), 25.0),
            (Vec3::new(0.0, 1.0, 6.0), Vec3::new(1.0, 0.5, 0.0), 40.0),
        ] {
            let view = View {
                camera: Camera::look_at(eye, target, fov),
                aspect: 1.5,
            };
            let f = Frustum::new(&view, 0.1);
            let blocks = b
                .blocks
                .iter()
                .map(|blk| ((blk.lo, blk.hi), blk.start..blk.end));
            let used = p.len().div_ceil(SUB_POINTS);
            let subs = b.subs[..used].iter().enumerate().map(|(j, s)| {
                let start = (j * SUB_POINTS) as u32;
                (*s, start..(start + SUB_POINTS as u32).min(p.len() as u32))
            });
            for (bounds, range) in blocks.chain(subs) {
                let side = WorldBox::new(bounds, &transform).side(&f, 0.05);
                sides[side as usize] += 1;
                let mut inside = b
                    .order
                    .range(range.start as usize..range.end as usize)
                    .map(|i| f.contains(transform.transform_point3(p[i as usize]), 0.05));
                match side {
                    Side::Inside => assert!(inside.all(|x| x)),
                    Side::Outside => assert!(!inside.any(|x| x)),
                    Side::Straddles => {}
                }
            }
        }
        assert!(sides.iter().all(|&n| n > 0), "{sides:?}");
    }
}
