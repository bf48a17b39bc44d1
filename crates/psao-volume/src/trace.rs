//! HDDA traversal through the flat tree and the ray queries built on it: level-set first hit,
//! fog optical depth (ray marching through active bricks only), transmittance and delta
//! tracking with per-L3 majorants.
//!
//! Rays are given in world space with a unit direction; they are mapped to index space with
//! the same parameter `t`, so all distances are world distances.

use crate::grid::{floor_ivec, GridClass, BRICK};
use crate::rng::Rng;
use crate::sample::Sampler;
use crate::volume::{LevelSetBounds, Volume};
use glam::{IVec3, Vec3};

/// A ray in index space with world-space parameter.
#[derive(Clone, Copy, Debug)]
pub struct IndexRay {
    /// Origin (index space).
    pub origin: Vec3,
    /// Direction (index space; a world unit vector mapped by the transform).
    pub dir: Vec3,
    inv: Vec3,
}

impl IndexRay {
    /// Maps a world ray (unit `dir`) into `vol`'s index space.
    pub fn from_world(vol: &Volume, origin: Vec3, dir: Vec3) -> Self {
        let o = vol.transform.world_to_index(origin);
        let d = vol.transform.world_dir_to_index(dir);
        IndexRay::new(o, d)
    }

    /// A ray already in index space: `dir` is a world unit vector mapped by the transform, so
    /// that `t` stays a world distance (many rays from one eye map the eye once, see
    /// [`crate::render::render`]).
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        IndexRay {
            origin,
            dir,
            inv: Vec3::ONE / dir,
        }
    }

    /// Point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// Parameter interval inside box `lo..hi`, if any.
    #[inline]
    pub fn clip(&self, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
        let a = (lo - self.origin) * self.inv;
        let b = (hi - self.origin) * self.inv;
        let t0 = a.min(b).max_element();
        let t1 = a.max(b).min_element();
        (t0 <= t1).then_some((t0, t1))
    }
}

/// Part of a ray inside one L3 node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Entry parameter.
    pub t0: f32,
    /// Exit parameter.
    pub t1: f32,
    /// The L3 node.
    pub leaf: u32,
    /// Index-space origin of the L3 node.
    pub origin: IVec3,
    /// The face of the node's cell the ray enters through at `t0` (−x, +x, −y, +y, −z, +z as
    /// 0..6) when the traversal knows it (a face of the bounds, or a DDA step), else
    /// [`NO_FACE`].
    pub entry: u8,
}

/// [`Segment::entry`] when the traversal does not know the entry face (the ray starts inside
/// the bounds, or rounding put a crossing before the previous one).
pub const NO_FACE: u8 = u8::MAX;

/// Steps through the L3 nodes of `frame` hit by `ray` between `t_min` and `t_max` (HDDA): one
/// incremental 3D DDA over the 8³ cells from where the ray enters the bounds, which tests one
/// bit per cell of a non-empty 128³ cell (and ranks only L3 nodes), looks up the L2 node once
/// per 128³ cell it enters and crosses an empty 128³ cell in one step. `visit` returns `false`
/// to stop.
pub fn march(
    vol: &Volume,
    frame: usize,
    ray: &IndexRay,
    t_min: f32,
    t_max: f32,
    mut visit: impl FnMut(Segment) -> bool,
) {
    let (lo, hi) = vol.index_bounds(frame);
    let (lo_f, hi_f) = (lo.as_vec3(), hi.as_vec3());
    let Some((a, b)) = ray.clip(lo_f, hi_f) else {
        return;
    };
    let end = b.min(t_max);
    let mut t = a.max(t_min);
    if t >= end || t.is_nan() {
        return;
    }
    const B: i32 = BRICK as i32;
    // Cells of 8³ voxels, in cell coordinates (voxel >> 3); the bounds are leaf-aligned.
    let (cell_lo, cell_hi) = (lo >> 3i32, (hi >> 3i32) - IVec3::ONE);
    let top = vol.tree.l1[frame].origin >> 3i32;
    let forward = ray.dir.cmpgt(Vec3::ZERO);
    let step = IVec3::select(forward, IVec3::ONE, IVec3::NEG_ONE);
    let ahead = IVec3::select(forward, IVec3::ONE, IVec3::ZERO);
    let still = ray.dir.cmpeq(Vec3::ZERO);
    let delta = Vec3::select(still, Vec3::INFINITY, (ray.inv * B as f32).abs());
    // Parameters where the ray crosses the far planes (along its direction) of the box of
    // cells `c` .. `c + size − 1`, per axis.
    let far_planes = |c: IVec3, size: i32| {
        let plane = ((c + ahead * size) * B).as_vec3();
        Vec3::select(still, Vec3::INFINITY, (plane - ray.origin) * ray.inv)
    };
    let face = |axis: usize| (2 * axis + !forward.test(axis) as usize) as u8;
    let nearest = |v: Vec3| {
        if v.x <= v.y && v.x <= v.z {
            0
        } else if v.y <= v.z {
            1
        } else {
            2
        }
    };
    // The first cell: where the ray enters the bounds (through a face of both), or where it
    // starts inside them.
    let mut cell = (floor_ivec(ray.at(t)) >> 3i32).clamp(cell_lo, cell_hi);
    let mut entry = NO_FACE;
    if a >= t_min {
        let near = ((lo_f - ray.origin) * ray.inv).min((hi_f - ray.origin) * ray.inv);
        let axis = if near.x >= near.y && near.x >= near.z {
            0
        } else if near.y >= near.z {
            1
        } else {
            2
        };
        cell[axis] = if forward.test(axis) {
            cell_lo[axis]
        } else {
            cell_hi[axis]
        };
        entry = face(axis);
    }
    let mut far = far_planes(cell, 1);
    loop {
        let c1 = (cell - top) >> 4i32;
        let l2_lo = top + (c1 << 4i32);
        let Some(n2) = vol.tree.l2_child(frame, c1) else {
            // An empty 128³ cell: on to the cell where the ray leaves it.
            let exit = far_planes(l2_lo, 16);
            let axis = nearest(exit);
            if exit[axis] >= end || exit[axis].is_nan() {
                return;
            }
            t = t.max(exit[axis]);
            cell = (floor_ivec(ray.at(t)) >> 3i32).clamp(l2_lo, l2_lo + IVec3::splat(15));
            cell[axis] = l2_lo[axis] + if forward.test(axis) { 16 } else { -1 };
            if cell.cmplt(cell_lo).any() || cell.cmpgt(cell_hi).any() {
                return;
            }
            entry = face(axis);
            far = far_planes(cell, 1);
            continue;
        };
        let mut c2 = cell - l2_lo;
        loop {
            // `far` holds the parameters where the ray leaves the current cell per axis.
            let axis = nearest(far);
            let cross = far[axis];
            let next = cross.min(end).max(t);
            if let Some(leaf) = vol.tree.leaf_in_l2(n2, c2) {
                if !visit(Segment {
                    t0: t,
                    t1: next,
                    leaf,
                    origin: cell * B,
                    entry,
                }) {
                    return;
                }
            }
            if next >= end {
                return;
            }
            // The next cell is entered through its face across `axis` at `next`, unless
            // rounding put the crossing before `t`.
            entry = if next == cross { face(axis) } else { NO_FACE };
            t = next;
            cell[axis] += step[axis];
            c2[axis] += step[axis];
            far[axis] += delta[axis];
            if cell[axis] < cell_lo[axis] || cell[axis] > cell_hi[axis] {
                return;
            }
            if !(0..16).contains(&c2[axis]) {
                break;
            }
        }
    }
}

/// The world-space sampling step: half the smallest voxel edge.
pub fn step_length(vol: &Volume) -> f32 {
    0.5 * vol.transform.scale.min_element() as f32
}

/// First zero crossing (outside to inside) of a level set along the ray.
///
/// A lower bound on the field is carried along the ray: nodes whose minimum is positive set it
/// to that minimum, a node entered through a face starts from that face's minimum, and inside
/// a node the bound falls at most at the node's fastest rate along the ray (from its bounds on
/// the partial derivatives of the trilinear field). A node the bound proves positive is crossed
/// without a sample; otherwise the next sample is taken half a fixed step (½ voxel) past where
/// the bound could first reach zero. From a sample of value `v > 0` the step is the largest of
/// the fixed step, 0.8 `v` (values are world distances, as the dense march's rule of today)
/// and `v` over that rate plus half a fixed step. The hit is interpolated linearly between the
/// last positive and the first other sample, refined by regula falsi when the positive end is
/// a bound or the bracket is wide. Returns the hit parameter.
pub fn level_set_hit(s: &mut Sampler, ray: &IndexRay, t_max: f32) -> Option<f32> {
    let vol = s.volume();
    let dt = step_length(vol);
    let mut bracket = None;
    // The last sample or bound: (t, value, whether the value is a sample rather than a bound).
    let mut prev: Option<(f32, f32, bool)> = None;
    // A lower bound on the field at the end of the previous node (valid if contiguous).
    let mut bound: Option<f32> = None;
    let mut last_end = f32::NEG_INFINITY;
    march(vol, s.frame(), ray, 0.0, t_max, |seg| {
        if seg.t0 > last_end + 1e-3 {
            prev = None;
            bound = None;
        }
        last_end = seg.t1;
        let floor = vol.minorant(seg.leaf);
        if floor > 0.0 {
            prev = Some((seg.t1, floor, false));
            bound = Some(floor);
            return true;
        }
        let (fall, entry) = match vol.level_set_bounds(seg.leaf) {
            Some(lb) => {
                let fall = Fall::new(lb, ray.dir);
                (fall, entry_bound(ray, &seg, lb, &fall))
            }
            None => (Fall::UNBOUNDED, None),
        };
        let mut t = seg.t0 + 0.5 * dt;
        let start = match (bound, entry) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        if let Some(b) = start.filter(|&b| b > 0.0) {
            let reach = fall.reach(b);
            if seg.t0 + reach >= seg.t1 {
                // Proven positive through the whole node.
                let end = fall.after(b, seg.t1 - seg.t0);
                prev = Some((seg.t1, end, false));
                bound = Some(end);
                return true;
            }
            if !matches!(prev, Some((_, _, true))) {
                prev = Some((seg.t0, b, false));
            }
            t = seg.t0 + reach + 0.5 * dt;
        }
        while t < seg.t1 {
            let v = s.trilinear_in(seg.leaf, seg.origin, ray.at(t));
            if let Some((tp, vp, sampled)) = prev {
                if vp > 0.0 && v <= 0.0 {
                    bracket = Some(((tp, vp, sampled), (t, v), (seg.leaf, seg.origin)));
                    return false;
                }
            }
            prev = Some((t, v, true));
            if v <= 0.0 {
                t += dt;
                continue;
            }
            let reach = fall.reach(v);
            if t + reach >= seg.t1 {
                bound = Some(fall.after(v, seg.t1 - t));
                return true;
            }
            t += dt.max(0.8 * v).max(reach + 0.5 * dt);
        }
        // Stepped past the node's end: no bound there.
        bound = None;
        true
    });
    bracket.map(|(a, b, node)| refine_crossing(s, ray, a, b, node, dt))
}

/// How fast a level set's field can fall along a ray inside one L3 node (per unit of the ray
/// parameter): at most `edge` while it is above `theta` (there it lies in cells touching the
/// narrow band's clamp, where it turns from the background to linear and falls slower), at
/// most `all` anywhere.
#[derive(Clone, Copy, Debug)]
struct Fall {
    theta: f32,
    edge: f32,
    all: f32,
}

impl Fall {
    /// No bounds: the field may fall arbitrarily fast.
    const UNBOUNDED: Fall = Fall {
        theta: f32::INFINITY,
        edge: f32::INFINITY,
        all: f32::INFINITY,
    };

    /// The rates of a node with bounds `lb` along index-space direction `dir`.
    fn new(lb: &LevelSetBounds, dir: Vec3) -> Self {
        let rate = |lo: Vec3, hi: Vec3| (-(lo * dir).min(hi * dir).element_sum()).max(0.0);
        let all = rate(lb.slope_min, lb.slope_max);
        Fall {
            theta: lb.linear_max.max(0.0),
            edge: rate(lb.edge_slope_min, lb.edge_slope_max).min(all),
            all,
        }
    }

    /// The least parameter distance in which the field can fall from `b` > 0 to zero.
    #[inline]
    fn reach(&self, b: f32) -> f32 {
        if b > self.theta {
            let low = if self.theta > 0.0 {
                self.theta / self.all
            } else {
                0.0
            };
            (b - self.theta) / self.edge + low
        } else {
            b / self.all
        }
    }

    /// A lower bound on the field a parameter distance `d` ≥ 0 after a point where it is at
    /// least `b`.
    #[inline]
    fn after(&self, b: f32, d: f32) -> f32 {
        if b > self.theta {
            let high = (b - self.theta) / self.edge;
            if d <= high {
                return b - self.edge * d;
            }
            self.theta - self.all * (d - high)
        } else {
            b - self.all * d
        }
    }
}

/// A lower bound on the field where `ray` enters the cell of `seg` (the minimum of the face it
/// enters through), carried to `seg.t0` at rates `fall`; `None` if the ray starts in the cell.
/// The face is the traversal's when it knows it, else found from the cell's slabs.
fn entry_bound(ray: &IndexRay, seg: &Segment, lb: &LevelSetBounds, fall: &Fall) -> Option<f32> {
    if seg.entry != NO_FACE {
        // Entered through this face at `t0`.
        return Some(lb.face_min[seg.entry as usize]);
    }
    let lo = seg.origin.as_vec3();
    let a = (lo - ray.origin) * ray.inv;
    let b = (lo + Vec3::splat(BRICK as f32) - ray.origin) * ray.inv;
    let near = a.min(b);
    let t_in = near.max_element();
    if !(t_in > 0.0 && t_in < f32::INFINITY) {
        return None;
    }
    let axis = if near.x == t_in {
        0
    } else if near.y == t_in {
        1
    } else if near.z == t_in {
        2
    } else {
        return None;
    };
    let face = 2 * axis + (ray.dir[axis] < 0.0) as usize;
    Some(fall.after(lb.face_min[face], (seg.t0 - t_in).max(0.0)))
}

/// The zero crossing between `a` (positive; `sampled` false if its value is only a bound) and
/// `b` (not positive) along `ray`: linear interpolation, after up to two regula falsi steps
/// when `a` is a bound or the bracket is wider than 16 `dt` (steps stop once it is under `dt`).
/// `(leaf, origin)` is the L3 node of `b`: samples in it skip the tree search.
fn refine_crossing(
    s: &mut Sampler,
    ray: &IndexRay,
    (mut ta, mut va, sampled): (f32, f32, bool),
    (mut tb, mut vb): (f32, f32),
    (leaf, origin): (u32, IVec3),
    dt: f32,
) -> f32 {
    if !sampled || tb - ta > 16.0 * dt {
        if !sampled {
            let v = s.trilinear_in(leaf, origin, ray.at(ta));
            if v > 0.0 {
                va = v;
            }
        }
        for _ in 0..2 {
            if tb - ta <= dt {
                break;
            }
            let tm = ta + (tb - ta) * va / (va - vb);
            let vm = s.trilinear_in(leaf, origin, ray.at(tm));
            if vm > 0.0 {
                (ta, va) = (tm, vm);
            } else {
                (tb, vb) = (tm, vm);
            }
        }
    }
    ta + (tb - ta) * va / (va - vb)
}

/// Optical depth ∫ density dt along the ray up to `t_max` (midpoint rule, at most half a voxel
/// per step, active bricks only; multiply by a density scale for extinction).
pub fn optical_depth(s: &mut Sampler, ray: &IndexRay, t_max: f32) -> f32 {
    let vol = s.volume();
    let dt = step_length(vol);
    let mut tau = 0.0;
    march(vol, s.frame(), ray, 0.0, t_max, |seg| {
        if vol.majorant(seg.leaf) <= 0.0 {
            return true;
        }
        let n = ((seg.t1 - seg.t0) / dt).ceil().max(1.0);
        let h = (seg.t1 - seg.t0) / n;
        let mut t = seg.t0 + 0.5 * h;
        for _ in 0..n as usize {
            tau += s.trilinear_in(seg.leaf, seg.origin, ray.at(t)).max(0.0) * h;
            t += h;
        }
        true
    });
    tau
}

/// Transmittance along a world ray with a reusable sampler: `exp(-density_scale · τ)` for fog
/// volumes; for level sets 0 if the ray enters the surface before `t_max`, else 1.
pub fn transmittance_with(
    s: &mut Sampler,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    density_scale: f32,
) -> f32 {
    let ray = IndexRay::from_world(s.volume(), origin, dir);
    match s.volume().class {
        GridClass::Fog => (-density_scale * optical_depth(s, &ray, t_max)).exp(),
        GridClass::LevelSet => {
            if level_set_hit(s, &ray, t_max).is_some() {
                0.0
            } else {
                1.0
            }
        }
    }
}

/// Tentative collisions along `ray` before `t_max`, sampled with the per-L3 majorants
/// (extinction = `density_scale` × density; empty nodes skipped by HDDA): `visit(t, σ, μ, rng)`
/// gets each collision distance with the real and the majorant extinction there, in order,
/// and returns whether to go on. The shared step of delta and ratio tracking.
pub(crate) fn tentative_collisions(
    s: &mut Sampler,
    ray: &IndexRay,
    t_max: f32,
    density_scale: f32,
    rng: &mut Rng,
    mut visit: impl FnMut(f32, f32, f32, &mut Rng) -> bool,
) {
    let vol = s.volume();
    march(vol, s.frame(), ray, 0.0, t_max, |seg| {
        let mu = vol.majorant(seg.leaf) * density_scale;
        if mu <= 0.0 {
            return true;
        }
        let mut t = seg.t0;
        loop {
            t -= (1.0 - rng.next_f32()).ln() / mu;
            if t >= seg.t1 {
                return true;
            }
            let sigma = s.trilinear_in(seg.leaf, seg.origin, ray.at(t)).max(0.0) * density_scale;
            if !visit(t, sigma, mu, rng) {
                return false;
            }
        }
    });
}

/// Delta tracking: the first real collision along the ray before `t_max`, sampled with the
/// per-L3 majorants (extinction = `density_scale` × density).
pub fn delta_track(
    s: &mut Sampler,
    ray: &IndexRay,
    t_max: f32,
    density_scale: f32,
    rng: &mut Rng,
) -> Option<f32> {
    let mut hit = None;
    tentative_collisions(s, ray, t_max, density_scale, rng, |t, sigma, mu, rng| {
        if rng.next_f32() * mu < sigma {
            hit = Some(t);
            return false;
        }
        true
    });
    hit
}

impl Volume {
    /// Transmittance of frame `frame` along the world ray `origin + t · dir` (unit `dir`) for
    /// `0 ≤ t ≤ t_max`; deterministic (no random numbers). Fog: `exp(-density_scale ∫ density)`
    /// by ray marching through active bricks only; level set: 0 if the ray hits the surface,
    /// else 1. Thread-safe (`&self`); for many rays per thread use [`transmittance_with`] with
    /// one [`Sampler`] to reuse decoded bricks.
    pub fn transmittance(
        &self,
        frame: usize,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        density_scale: f32,
    ) -> f32 {
        let mut s = Sampler::new(self, frame.min(self.frames() - 1));
        transmittance_with(&mut s, origin, dir, t_max, density_scale)
    }
}
