//! A volume: the flat tree of all frames over one encoded brick pool, plus per-L3 majorants
//! derived from the decoded bricks.

use crate::cluster::{cluster, ClusterParams};
use crate::codec::{BrickFormat, BrickPool};
use crate::error::{Result, VolumeError};
use crate::grid::{GridClass, SparseGrid, Transform, BRICK, BRICK_VOXELS};
use crate::tree::{FlatTree, Locate, TreeStats};
use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// A multi-frame sparse volume.
#[derive(Clone, Debug)]
pub struct Volume {
    /// Fog or level set.
    pub class: GridClass,
    /// Index-to-world map (shared by all frames).
    pub transform: Transform,
    /// Value outside the leaves.
    pub background: f32,
    /// The flat tree.
    pub tree: FlatTree,
    /// The shared brick pool.
    pub pool: BrickPool,
    /// Per L3 node: maximum decoded value over the 9³ voxels that trilinear samples inside
    /// the node can reach (its brick and the touching layers of its +x/+y/+z neighbours).
    pub(crate) l3_max: Vec<f32>,
    /// Per L3 node: minimum over the same voxels (level sets skip nodes with a positive minimum).
    pub(crate) l3_min: Vec<f32>,
    /// Per L3 node: the L3 nodes at offsets `d` = 1..8 (bit 0: +x, 1: +y, 2: +z; entry
    /// `d − 1`) that trilinear samples near its +faces read, [`NO_LEAF`] where there is none.
    pub(crate) l3_next: Vec<[u32; 7]>,
    /// Level sets only (else empty): per L3 node, bounds of the interpolated field in it.
    pub(crate) l3_bounds: Vec<LevelSetBounds>,
    /// Per frame: index-space bounds of the leaves (min, max exclusive).
    pub(crate) bounds: Vec<(IVec3, IVec3)>,
}

/// Bounds of a level set's trilinear field inside one L3 node, from the 9³ voxels samples in
/// it read (its brick and the touching layers of its +neighbours, or the background).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelSetBounds {
    /// Per axis, the smallest forward difference (a lower bound on that partial derivative).
    pub slope_min: Vec3,
    /// Per axis, the largest forward difference (an upper bound on that partial derivative).
    pub slope_max: Vec3,
    /// Smallest value on each face of the node's cell: −x, +x, −y, +y, −z, +z.
    pub face_min: [f32; 6],
    /// The largest corner value of the voxel cells none of whose corners is at (or above) the
    /// background: where the field exceeds it, the point lies in a cell touching the narrow
    /// band's clamp (−∞ if every cell does).
    pub linear_max: f32,
    /// Per axis, the smallest and largest forward difference of the cells that touch the
    /// clamp, which bound the field's partial derivatives wherever it exceeds `linear_max`
    /// (the node's own bounds if no cell touches it).
    pub edge_slope_min: Vec3,
    /// See `edge_slope_min`.
    pub edge_slope_max: Vec3,
}

/// Marks a missing neighbour in [`Volume`]'s neighbour table.
pub(crate) const NO_LEAF: u32 = u32::MAX;

/// How a volume was built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuildStats {
    /// Bricks before clustering (leaves of all frames plus one per distinct tile value).
    pub bricks_before: usize,
    /// Bricks in the pool.
    pub bricks_after: usize,
    /// Bricks that took part in k-means.
    pub cluster_candidates: usize,
}

/// Errors against a reference over active voxels, with values normalised by the value range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorStats {
    /// Root mean square error.
    pub rmse: f64,
    /// Maximum absolute error.
    pub max_error: f64,
    /// Active voxels compared.
    pub active_voxels: u64,
}

/// Memory of a volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SizeStats {
    /// The tree.
    pub tree: TreeStats,
    /// Brick pool bytes (with the BC7 refinement layer).
    pub brick_bytes: usize,
    /// Voxels stored in the pool (bricks × 512).
    pub brick_voxels: usize,
    /// Active voxels of all frames.
    pub active_voxels: u64,
}

impl SizeStats {
    /// Brick bytes × 8 / stored voxels.
    pub fn bits_per_voxel_bricks(&self) -> f64 {
        self.brick_bytes as f64 * 8.0 / self.brick_voxels as f64
    }

    /// (Brick + tree bytes) × 8 / stored voxels.
    pub fn bits_per_voxel_total(&self) -> f64 {
        (self.brick_bytes + self.tree.total_bytes()) as f64 * 8.0 / self.brick_voxels as f64
    }

    /// (Brick + tree bytes) × 8 / active voxels.
    pub fn bits_per_active_voxel(&self) -> f64 {
        (self.brick_bytes + self.tree.total_bytes()) as f64 * 8.0 / self.active_voxels as f64
    }
}

impl Volume {
    /// Builds a volume from frames (one grid each) in `format`, optionally clustering bricks.
    pub fn build(
        frames: &[SparseGrid],
        format: BrickFormat,
        clustering: Option<&ClusterParams>,
    ) -> Result<(Volume, BuildStats)> {
        let first = frames.first().ok_or(VolumeError::Empty)?;
        for (i, g) in frames.iter().enumerate() {
            if g.class != first.class {
                return Err(VolumeError::FrameMismatch(format!(
                    "frame {i} is a {} grid, frame 0 a {} grid",
                    g.class.name(),
                    first.class.name()
                )));
            }
            if g.transform != first.transform {
                return Err(VolumeError::FrameMismatch(format!(
                    "frame {i} has another transform than frame 0"
                )));
            }
        }
        let mut tree = FlatTree::default();
        let mut bricks: Vec<[f32; BRICK_VOXELS]> = Vec::new();
        // One brick per distinct tile value, shared by every cell of every tile of that value.
        let mut constant: HashMap<u32, u32> = HashMap::new();
        for g in frames {
            let first = bricks.len() as u32;
            bricks.extend(g.leaves.iter().map(|l| *l.values));
            let mut cells = Vec::new();
            for t in &g.tiles {
                let brick = *constant.entry(t.value.to_bits()).or_insert_with(|| {
                    bricks.push([t.value; BRICK_VOXELS]);
                    bricks.len() as u32 - 1
                });
                cells.extend(t.cell_origins().map(|o| (o, brick)));
            }
            tree.push_frame(&g.leaves, first, &cells)?;
        }
        let (lo, hi) = bricks
            .par_iter()
            .map(|b| {
                b.iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, c), &v| {
                        (a.min(v), c.max(v))
                    })
            })
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(VolumeError::InvalidParameter(
                "voxel values are not finite".into(),
            ));
        }
        let bricks_before = bricks.len();
        let mut candidates = 0;
        if let Some(p) = clustering {
            let c = cluster(&bricks, lo, hi, p)?;
            for n in &mut tree.l3 {
                n.set_brick(c.remap[n.brick() as usize]);
            }
            bricks = c.bricks;
            candidates = c.candidates;
        }
        let pool = BrickPool::encode(format, &bricks, lo, hi);
        let volume = Volume::assemble(first.class, first.transform, first.background, tree, pool)?;
        Ok((
            volume,
            BuildStats {
                bricks_before,
                bricks_after: bricks.len(),
                cluster_candidates: candidates,
            },
        ))
    }

    /// Puts a volume together from its parts, checking consistency and deriving majorants.
    pub fn assemble(
        class: GridClass,
        transform: Transform,
        background: f32,
        tree: FlatTree,
        pool: BrickPool,
    ) -> Result<Volume> {
        let bricks = pool.len();
        if tree.l3.iter().any(|n| n.brick() as usize >= bricks) {
            return Err(VolumeError::InvalidParameter(
                "an L3 node points past the brick pool".into(),
            ));
        }
        // Per brick and per corner offset d (bit 0: x, 1: y, 2: z): value range over the
        // voxels whose local coordinate is 0 along the axes set in d (d = 0: whole brick).
        // A trilinear sample in a node reads its brick and these parts of its +neighbours.
        let brick_range: Vec<[(f32, f32); 8]> = (0..bricks as u32)
            .into_par_iter()
            .map(|i| {
                let mut b = [0.0; BRICK_VOXELS];
                pool.decode(i, &mut b);
                let mut r = [(f32::INFINITY, f32::NEG_INFINITY); 8];
                for z in 0..BRICK {
                    for y in 0..BRICK {
                        for x in 0..BRICK {
                            let v = b[crate::grid::voxel_index(x, y, z)];
                            let on = (x == 0) as usize
                                | ((y == 0) as usize) << 1
                                | ((z == 0) as usize) << 2;
                            for (d, e) in r.iter_mut().enumerate() {
                                if d & on == d {
                                    *e = (e.0.min(v), e.1.max(v));
                                }
                            }
                        }
                    }
                }
                r
            })
            .collect();
        let mut bounds = Vec::new();
        let mut l3_max = vec![0.0f32; tree.l3.len()];
        let mut l3_min = vec![0.0f32; tree.l3.len()];
        let mut l3_next = vec![[NO_LEAF; 7]; tree.l3.len()];
        for frame in 0..tree.frames() {
            let mut lo = IVec3::MAX;
            let mut hi = IVec3::MIN;
            for (_, i, o) in tree.leaves().filter(|(f, _, _)| *f == frame) {
                lo = lo.min(o);
                hi = hi.max(o + IVec3::splat(BRICK as i32));
                let (mut mn, mut mx) = brick_range[tree.l3[i as usize].brick() as usize][0];
                // `d` is both the neighbour offset and the part of its brick that is read.
                #[allow(clippy::needless_range_loop)]
                for d in 1..8usize {
                    let off = IVec3::new((d & 1) as i32, ((d >> 1) & 1) as i32, (d >> 2) as i32);
                    let (a, b) = match tree.locate(frame, o + off * BRICK as i32) {
                        Locate::Leaf(j, _) => {
                            l3_next[i as usize][d - 1] = j;
                            brick_range[tree.l3[j as usize].brick() as usize][d]
                        }
                        _ => (background, background),
                    };
                    mn = mn.min(a);
                    mx = mx.max(b);
                }
                l3_max[i as usize] = mx;
                l3_min[i as usize] = mn;
            }
            if lo.x > hi.x {
                return Err(VolumeError::Empty);
            }
            bounds.push((lo, hi));
        }
        let l3_bounds = if class == GridClass::LevelSet {
            level_set_bounds(&tree, &pool, &l3_next, background)
        } else {
            Vec::new()
        };
        Ok(Volume {
            class,
            transform,
            background,
            tree,
            pool,
            l3_max,
            l3_min,
            l3_next,
            l3_bounds,
            bounds,
        })
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.tree.frames()
    }

    /// Index-space bounds of `frame` (min, max exclusive).
    pub fn index_bounds(&self, frame: usize) -> (IVec3, IVec3) {
        self.bounds[frame]
    }

    /// World-space axis-aligned bounds of `frame` (min, max).
    pub fn world_bounds(&self, frame: usize) -> (Vec3, Vec3) {
        let (lo, hi) = self.bounds[frame];
        let a = self.transform.index_to_world(lo.as_vec3());
        let b = self.transform.index_to_world(hi.as_vec3() - Vec3::ONE);
        (a.min(b), a.max(b))
    }

    /// Sizes of the tree and the pool.
    pub fn sizes(&self, active_voxels: u64) -> SizeStats {
        SizeStats {
            tree: self.tree.stats(),
            brick_bytes: self.pool.byte_size(),
            brick_voxels: self.pool.len() * BRICK_VOXELS,
            active_voxels,
        }
    }

    /// Majorant of L3 node `i` (maximum reachable value).
    pub fn majorant(&self, i: u32) -> f32 {
        self.l3_max[i as usize]
    }

    /// Minimum reachable value inside L3 node `i`.
    pub fn minorant(&self, i: u32) -> f32 {
        self.l3_min[i as usize]
    }

    /// The L3 node at offset `d` (1..8, bit 0: +x, 1: +y, 2: +z) from L3 node `i`, or
    /// [`NO_LEAF`].
    #[inline]
    pub(crate) fn next_leaf(&self, i: u32, d: usize) -> u32 {
        self.l3_next[i as usize][d - 1]
    }

    /// Level sets: bounds of the trilinear field inside L3 node `i` (`None` for fog).
    #[inline]
    pub fn level_set_bounds(&self, i: u32) -> Option<&LevelSetBounds> {
        self.l3_bounds.get(i as usize)
    }

    /// RMSE and maximum error of the decoded volume against the source frames over their
    /// active voxels, values normalised by the pool's value range.
    pub fn compare(&self, frames: &[SparseGrid]) -> Result<ErrorStats> {
        if frames.len() != self.frames() {
            return Err(VolumeError::FrameMismatch(format!(
                "{} reference frames for a {}-frame volume",
                frames.len(),
                self.frames()
            )));
        }
        let range = (self.pool.hi - self.pool.lo).max(f32::MIN_POSITIVE) as f64;
        let per_leaf: Vec<(f64, f64, u64)> = frames
            .par_iter()
            .enumerate()
            .flat_map_iter(|(f, g)| g.leaves.iter().map(move |l| (f, l)))
            .map(|(f, leaf)| {
                let mut out = [0.0; BRICK_VOXELS];
                match self.tree.locate(f, leaf.origin) {
                    Locate::Leaf(i, _) => {
                        self.pool.decode(self.tree.l3[i as usize].brick(), &mut out)
                    }
                    _ => out = [self.background; BRICK_VOXELS],
                }
                let (mut se, mut mx, mut n) = (0.0f64, 0.0f64, 0u64);
                for (k, (&a, &b)) in leaf.values.iter().zip(&out).enumerate() {
                    if leaf.is_active(k) {
                        let e = (a - b).abs() as f64 / range;
                        se += e * e;
                        mx = mx.max(e);
                        n += 1;
                    }
                }
                (se, mx, n)
            })
            .collect();
        // A tile's cells share one brick: its first cell's error stands for all of them.
        let per_tile = frames.iter().enumerate().flat_map(|(f, g)| {
            g.tiles.iter().map(move |t| {
                let mut out = [self.background; BRICK_VOXELS];
                if let Locate::Leaf(i, _) = self.tree.locate(f, t.origin) {
                    self.pool.decode(self.tree.l3[i as usize].brick(), &mut out);
                }
                let (mut se, mut mx) = (0.0f64, 0.0f64);
                for &b in &out {
                    let e = (t.value - b).abs() as f64 / range;
                    se += e * e;
                    mx = mx.max(e);
                }
                let cells = t.cells() as f64;
                (se * cells, mx, BRICK_VOXELS as u64 * t.cells())
            })
        });
        let per_tile: Vec<_> = per_tile.collect();
        let (se, mx, n) = per_leaf
            .iter()
            .chain(&per_tile)
            .fold((0.0, 0.0f64, 0), |a, b| {
                (a.0 + b.0, a.1.max(b.1), a.2 + b.2)
            });
        Ok(ErrorStats {
            rmse: if n > 0 { (se / n as f64).sqrt() } else { 0.0 },
            max_error: mx,
            active_voxels: n,
        })
    }
}

/// Per L3 node of a level set, its [`LevelSetBounds`] from its 9³ voxel window.
fn level_set_bounds(
    tree: &FlatTree,
    pool: &BrickPool,
    next: &[[u32; 7]],
    background: f32,
) -> Vec<LevelSetBounds> {
    (0..tree.l3.len())
        .into_par_iter()
        .map(|i| {
            let mut v = [background; 9 * 9 * 9];
            let mut b = [0.0; BRICK_VOXELS];
            for d in 0..8usize {
                let leaf = if d == 0 { i as u32 } else { next[i][d - 1] };
                if leaf == NO_LEAF {
                    continue;
                }
                pool.decode(tree.l3[leaf as usize].brick(), &mut b);
                let bit = [d & 1, (d >> 1) & 1, d >> 2];
                // Only the part of the neighbour that lies in the 9³ window.
                let span = bit.map(|o| if o == 1 { 1 } else { BRICK });
                for z in 0..span[2] {
                    for y in 0..span[1] {
                        for x in 0..span[0] {
                            let at = (bit[0] * BRICK + x)
                                + 9 * ((bit[1] * BRICK + y) + 9 * (bit[2] * BRICK + z));
                            v[at] = b[crate::grid::voxel_index(x, y, z)];
                        }
                    }
                }
            }
            let mut out = LevelSetBounds {
                slope_min: Vec3::INFINITY,
                slope_max: Vec3::NEG_INFINITY,
                face_min: [f32::INFINITY; 6],
                linear_max: f32::NEG_INFINITY,
                edge_slope_min: Vec3::INFINITY,
                edge_slope_max: Vec3::NEG_INFINITY,
            };
            // Cells touching the clamp versus the others.
            for z in 0..8 {
                for y in 0..8 {
                    for x in 0..8 {
                        let at = x + 9 * (y + 9 * z);
                        let c = [0, 1, 9, 10, 81, 82, 90, 91].map(|o| v[at + o]);
                        if c.iter().all(|&x| x < background) {
                            let hi = c.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                            out.linear_max = out.linear_max.max(hi);
                            continue;
                        }
                        for (axis, bit) in [1usize, 2, 4].into_iter().enumerate() {
                            for k in (0..8).filter(|k| k & bit == 0) {
                                let diff = c[k | bit] - c[k];
                                out.edge_slope_min[axis] = out.edge_slope_min[axis].min(diff);
                                out.edge_slope_max[axis] = out.edge_slope_max[axis].max(diff);
                            }
                        }
                    }
                }
            }
            for z in 0..9 {
                for y in 0..9 {
                    for x in 0..9 {
                        let at = x + 9 * (y + 9 * z);
                        let c = [x, y, z];
                        for (axis, step) in [1, 9, 81].into_iter().enumerate() {
                            if c[axis] < 8 {
                                let diff = v[at + step] - v[at];
                                out.slope_min[axis] = out.slope_min[axis].min(diff);
                                out.slope_max[axis] = out.slope_max[axis].max(diff);
                            }
                            let face = match c[axis] {
                                0 => 2 * axis,
                                8 => 2 * axis + 1,
                                _ => continue,
                            };
                            out.face_min[face] = out.face_min[face].min(v[at]);
                        }
                    }
                }
            }
            if out.edge_slope_min.x > out.edge_slope_max.x {
                // No cell touches the clamp.
                out.edge_slope_min = out.slope_min;
                out.edge_slope_max = out.slope_max;
            }
            out
        })
        .collect()
}
