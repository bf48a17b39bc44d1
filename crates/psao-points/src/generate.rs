//! Point generation per mesh instance (DESIGN §3 "Generation", paper §3.1).
//!
//! `2·M` candidates are spawned uniformly over the instance's surface (triangle chosen with
//! probability proportional to its world-space area, uniform barycentrics), candidates on
//! alpha-masked-out texels are rejected, and weighted sample elimination keeps half of the
//! rest so the points are evenly spread. `M = round(N · area)` with `N` points per unit area.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use glam::{Affine3A, Vec3};
use psao_scene::{AlphaMode, Material, Mesh, Scene};
use rayon::prelude::*;

use crate::elimination::{eliminate_scaled, max_poisson_radius};
use crate::error::PointsError;
use crate::rng::{hash2, Stream};

/// Default points per unit area after elimination (DESIGN §3).
pub const DEFAULT_DENSITY: f32 = 1024.0;

/// Most candidates one instance may spawn.
pub const MAX_SPAWNED: u32 = 1 << 31;

/// Alpha-test hook for alpha-masked materials: called with (triangle index, barycentrics of
/// the candidate with respect to the triangle's three vertices); return `true` to keep the
/// point (the texel is opaque), `false` to reject it (masked out). Textures are not loaded by
/// this crate: the caller samples its alpha texture at the interpolated UV and compares with
/// the material's cutoff, as [`Scene::opaque_at`] does. Only consulted for materials with
/// [`AlphaMode::Mask`].
pub type AlphaTest<'a> = &'a (dyn Fn(u32, Vec3) -> bool + Sync);

/// Scene-level alpha hook: like [`AlphaTest`] with the mesh index first.
pub type SceneAlphaTest<'a> = &'a (dyn Fn(usize, u32, Vec3) -> bool + Sync);

/// Near-field signal of adaptive placement ([`Adaptive`]): called once per instance with the
/// instance index, the world position and unit world normal of every candidate, and the
/// uniform point spacing `2·r_max` in world units; returns one value per candidate in [0, 1]
/// (0: open, nothing near: the base density; 1: the most). Values are clamped (NaN counts as
/// 0); a result of another length counts as all 0.
pub type DensitySignal<'a> = &'a (dyn Fn(usize, &[(Vec3, Vec3)], f32) -> Vec<f32> + Sync);

/// Adaptive placement (issue 15 item 4): the local density rises with a geometric signal
/// (e.g. near-field occlusion) at the same total point count, so detail finer than the uniform
/// spacing holds more points and open flat areas fewer.
///
/// A candidate with signal `s` gets the density factor `f = 1 + (max_boost − 1)·s`; the
/// instance keeps as many points as uniform placement would, with a local spacing
/// proportional to `1/√f` (see [`generate_instance_points_adaptive`]).
#[derive(Clone, Copy)]
pub struct Adaptive<'a> {
    /// Density of the most signalled areas relative to areas without signal (≥ 1; 1 gives
    /// uniform placement, as [`generate_instance_points`]).
    pub max_boost: f32,
    /// The signal.
    pub signal: DensitySignal<'a>,
}

/// How points are generated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GenerateParams {
    /// Points per unit of world-space area after elimination, per side (`N`).
    pub density: f32,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for GenerateParams {
    fn default() -> Self {
        Self {
            density: DEFAULT_DENSITY,
            seed: 0,
        }
    }
}

/// One generated surface point, in the instance's local (mesh) space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Triangle index in the mesh.
    pub triangle: u32,
    /// Barycentric weights of the triangle's three vertices (sum to 1).
    pub bary: Vec3,
    /// Mesh-local position.
    pub position: Vec3,
    /// Mesh-local unit normal (interpolated vertex normal; flipped on the back side).
    pub normal: Vec3,
    /// True for the back-side copy on a double-sided material.
    pub back_face: bool,
}

/// The points of one mesh instance and the statistics the grid needs.
#[derive(Clone, Debug, PartialEq)]
pub struct InstancePoints {
    /// The points; on double-sided materials each front point is followed by its back copy.
    pub points: Vec<SurfacePoint>,
    /// Mean Poisson radius `r_max` of one side's points in world units: the expected spacing
    /// between neighbouring points is `2 · r_max`. 0 when there are no points.
    pub poisson_radius: f32,
    /// [`Self::poisson_radius`] in local units (scaled by `sqrt(local area / world area)`,
    /// exact for uniform scale, an area-preserving average for non-uniform scale).
    pub poisson_radius_local: f32,
    /// Surface area (one side) in world units.
    pub area: f32,
    /// Surface area (one side) in local units.
    pub area_local: f32,
    /// 2 for double-sided materials, else 1.
    pub sides: u8,
    /// Local bounding box (min, max) of the mesh.
    pub local_bounds: (Vec3, Vec3),
    /// Candidates spawned before alpha rejection and elimination.
    pub spawned: usize,
    /// Candidates rejected by the alpha hook.
    pub alpha_rejected: usize,
}

impl InstancePoints {
    /// Poisson radius of all points of the instance together (both sides counted), in local
    /// units: `poisson_radius_local / sqrt(sides)`. The grid cell is 4× this, so a cell holds
    /// the same expected number of points whether the material is double-sided or not.
    pub fn grid_radius_local(&self) -> f32 {
        self.poisson_radius_local / f32::from(self.sides.max(1)).sqrt()
    }
}

/// The seed of instance `index` derived from a scene seed.
pub fn instance_seed(seed: u64, index: usize) -> u64 {
    hash2(seed, index as u64)
}

/// A spawned candidate: triangle and two barycentrics (the first is `1 − b1 − b2`).
#[derive(Clone, Copy)]
struct Candidate {
    triangle: u32,
    b1: f32,
    b2: f32,
}

impl Candidate {
    fn bary(&self) -> Vec3 {
        Vec3::new((1.0 - self.b1 - self.b2).max(0.0), self.b1, self.b2)
    }
}

/// Validated local triangles of a mesh with per-triangle world and local areas.
struct Triangles {
    verts: Vec<[Vec3; 3]>,
    /// Cumulative world-space area (f64 for a precise area-weighted choice).
    cdf: Vec<f64>,
    area_local: f64,
}

impl Triangles {
    fn new(mesh: &Mesh, transform: &Affine3A) -> Result<Self, PointsError> {
        let count = mesh.positions.len();
        let mut verts = Vec::with_capacity(mesh.indices.len());
        let mut cdf = Vec::with_capacity(mesh.indices.len());
        let (mut total, mut area_local) = (0.0f64, 0.0f64);
        for (t, tri) in mesh.indices.iter().enumerate() {
            let t = t as u32;
            let v = tri.map(|i| mesh.positions.get(i as usize).copied());
            let [Some(a), Some(b), Some(c)] = v else {
                let index = tri[v.iter().position(Option::is_none).unwrap_or(0)];
                return Err(PointsError::IndexOutOfRange {
                    triangle: t,
                    index,
                    count,
                });
            };
            let [wa, wb, wc] = [a, b, c].map(|p| transform.transform_point3(p));
            let world = 0.5 * f64::from((wb - wa).cross(wc - wa).length());
            let local = 0.5 * f64::from((b - a).cross(c - a).length());
            if !(world.is_finite() && local.is_finite() && wa.is_finite()) {
                return Err(PointsError::NonFiniteGeometry(t));
            }
            total += world;
            area_local += local;
            verts.push([a, b, c]);
            cdf.push(total);
        }
        Ok(Self {
            verts,
            cdf,
            area_local,
        })
    }

    fn area(&self) -> f64 {
        self.cdf.last().copied().unwrap_or(0.0)
    }

    /// Candidate `k` of the stream `seed`: area-weighted triangle, uniform barycentrics.
    fn spawn(&self, seed: u64, k: u64) -> Candidate {
        let mut rng = Stream::new(seed, k);
        let x = rng.next_f64() * self.area();
        let triangle = self
            .cdf
            .partition_point(|&c| c <= x)
            .min(self.cdf.len() - 1) as u32;
        let s = rng.next_f32().sqrt();
        let u = rng.next_f32();
        Candidate {
            triangle,
            b1: s * (1.0 - u),
            b2: s * u,
        }
    }

    /// A candidate on `c`'s triangle near it: uniform in the disk of world radius `radius`
    /// around it (in the triangle's plane, up to [`EXTRA_TRIES`] draws), or uniform on the
    /// whole triangle when its world area is below the disk's; `None` when every draw missed.
    fn spawn_near(
        &self,
        c: &Candidate,
        radius: f32,
        transform: &Affine3A,
        rng: &mut Stream,
    ) -> Option<Candidate> {
        let t = c.triangle as usize;
        let [a, b, cc] = self.verts[t];
        let world_area = self.cdf[t] - if t == 0 { 0.0 } else { self.cdf[t - 1] };
        if world_area <= f64::from(std::f32::consts::PI * radius * radius) {
            let s = rng.next_f32().sqrt();
            let u = rng.next_f32();
            return Some(Candidate {
                triangle: c.triangle,
                b1: s * (1.0 - u),
                b2: s * u,
            });
        }
        let [wa, wb, wc] = [a, b, cc].map(|p| transform.transform_point3(p));
        let (e1, e2) = (wb - wa, wc - wa);
        let x = e1.normalize_or_zero();
        let y = e1.cross(e2).cross(e1).normalize_or_zero();
        let w = c.bary();
        let centre = wa * w.x + wb * w.y + wc * w.z;
        // Barycentrics of a world point in the triangle's plane.
        let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let det = d00 * d11 - d01 * d01;
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        for _ in 0..EXTRA_TRIES {
            let r = radius * rng.next_f32().sqrt();
            let phi = std::f32::consts::TAU * rng.next_f32();
            let q = centre + x * (r * phi.cos()) + y * (r * phi.sin()) - wa;
            let (d20, d21) = (q.dot(e1), q.dot(e2));
            let b1 = (d11 * d20 - d01 * d21) / det;
            let b2 = (d00 * d21 - d01 * d20) / det;
            if b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0 {
                return Some(Candidate {
                    triangle: c.triangle,
                    b1,
                    b2,
                });
            }
        }
        None
    }

    fn local_position(&self, c: &Candidate) -> Vec3 {
        let [a, b, cc] = self.verts[c.triangle as usize];
        let w = c.bary();
        a * w.x + b * w.y + cc * w.z
    }
}

/// Interpolated vertex normal, falling back to the face normal (and +Z for degenerate faces).
fn local_normal(mesh: &Mesh, tris: &Triangles, c: &Candidate) -> Vec3 {
    let [a, b, cc] = tris.verts[c.triangle as usize];
    let face = (b - a).cross(cc - a).normalize_or(Vec3::Z);
    if mesh.normals.len() != mesh.positions.len() {
        return face;
    }
    let idx = mesh.indices[c.triangle as usize];
    let w = c.bary();
    let n = mesh.normals[idx[0] as usize] * w.x
        + mesh.normals[idx[1] as usize] * w.y
        + mesh.normals[idx[2] as usize] * w.z;
    n.normalize_or(face)
}

fn local_bounds(mesh: &Mesh) -> (Vec3, Vec3) {
    if mesh.positions.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    mesh.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// Generate the points of one instance of `mesh` placed by `transform` (mesh-local → world).
///
/// Areas and the elimination distance are measured in world units, so `params.density` is
/// points per world unit², per side; stored positions and normals are mesh-local. Double-sided
/// materials get a back-side copy of every point (same position, flipped normal). `alpha` is
/// consulted for alpha-masked materials only (see [`AlphaTest`]). Deterministic for a given
/// `params.seed`, independent of the thread count.
pub fn generate_instance_points(
    mesh: &Mesh,
    material: &Material,
    transform: &Affine3A,
    params: &GenerateParams,
    alpha: Option<AlphaTest<'_>>,
) -> Result<InstancePoints, PointsError> {
    generate_instance_points_adaptive(mesh, material, transform, params, alpha, None, 0)
}

/// [`generate_instance_points`] with adaptive placement: `adaptive` (when its boost is > 1)
/// is asked for the signal of the `2·M` uniform candidates (`instance` is handed to it);
/// each candidate with factor `f > 1` spawns `f − 1` extra candidates on average near it (on
/// its triangle, within one uniform spacing, or anywhere on the triangle when that is
/// smaller), so the candidates keep twice the wanted local density; elimination then keeps
/// `M` points with a pair interaction distance `2·r_u·√(f̄)·(1/√f_i + 1/√f_j)/2`, where `r_u`
/// is the uniform Poisson radius and `f̄` the mean factor over the uniform candidates (the
/// area-weighted mean of `f`). [`InstancePoints::poisson_radius`] stays the uniform `r_u`, so
/// the grid's cells (and their 7-point capacity) and hash table are sized as for uniform
/// placement: cells sized for the sparsest local spacing `r_u·√(f̄)` would hold `f` times
/// their share of points where the signal is strong and overflow (measured on the built-in
/// hall at boost 2: whole cells refused, white gaps in the grille). The reconstruction radius
/// `2√2·r_u` still reaches across the sparser open areas as long as `f̄` stays modest.
/// Deterministic for a given seed and signal.
pub fn generate_instance_points_adaptive(
    mesh: &Mesh,
    material: &Material,
    transform: &Affine3A,
    params: &GenerateParams,
    alpha: Option<AlphaTest<'_>>,
    adaptive: Option<Adaptive<'_>>,
    instance: usize,
) -> Result<InstancePoints, PointsError> {
    if let Some(a) = adaptive {
        if !(a.max_boost.is_finite() && a.max_boost >= 1.0) {
            return Err(PointsError::InvalidBoost(a.max_boost));
        }
    }
    let adaptive = adaptive.filter(|a| a.max_boost > 1.0);
    if !(params.density.is_finite() && params.density > 0.0) {
        return Err(PointsError::InvalidDensity(params.density));
    }
    let tris = Triangles::new(mesh, transform)?;
    let sides: u8 = if material.double_sided { 2 } else { 1 };
    let area = tris.area();
    let mut out = InstancePoints {
        points: Vec::new(),
        poisson_radius: 0.0,
        poisson_radius_local: 0.0,
        area: area as f32,
        area_local: tris.area_local as f32,
        sides,
        local_bounds: local_bounds(mesh),
        spawned: 0,
        alpha_rejected: 0,
    };
    if area <= 0.0 {
        return Ok(out);
    }
    let wanted = (f64::from(params.density) * area).round().max(1.0);
    let spawn = 2.0 * wanted;
    if spawn > f64::from(MAX_SPAWNED) {
        return Err(PointsError::TooManyPoints {
            requested: spawn,
            max: MAX_SPAWNED,
        });
    }
    let spawn = spawn as u64;
    let seed = params.seed;
    let mask = match (alpha, material.alpha_mode) {
        (Some(f), AlphaMode::Mask { .. }) => Some(f),
        _ => None,
    };
    let candidates: Vec<Candidate> = (0..spawn)
        .into_par_iter()
        .map(|k| tris.spawn(seed, k))
        .filter(|c| mask.is_none_or(|f| f(c.triangle, c.bary())))
        .collect();
    out.spawned = spawn as usize;
    out.alpha_rejected = spawn as usize - candidates.len();
    if candidates.is_empty() {
        return Ok(out);
    }

    let keep = candidates.len().div_ceil(2);
    let kept_area = area * candidates.len() as f64 / spawn as f64;
    let r_uniform = max_poisson_radius(kept_area, keep);
    let mut r_max = r_uniform;
    let mut candidates = candidates;
    let mut scales: Option<Vec<f32>> = None;
    if let Some(a) = adaptive {
        let (extra, factors, mean) = adaptive_candidates(
            &tris,
            mesh,
            transform,
            &candidates,
            a,
            instance,
            (seed, spawn),
            2.0 * r_max as f32,
            mask,
        );
        r_max *= f64::from(mean).sqrt();
        candidates.extend(extra);
        scales = Some(factors.iter().map(|f| 1.0 / f.sqrt()).collect());
    }
    let world: Vec<Vec3> = candidates
        .par_iter()
        .map(|c| transform.transform_point3(tris.local_position(c)))
        .collect();
    let kept = eliminate_scaled(&world, scales.as_deref(), keep, (2.0 * r_max) as f32);

    out.points = Vec::with_capacity(kept.len() * usize::from(sides));
    for &i in &kept {
        let c = &candidates[i as usize];
        let front = SurfacePoint {
            triangle: c.triangle,
            bary: c.bary(),
            position: tris.local_position(c),
            normal: local_normal(mesh, &tris, c),
            back_face: false,
        };
        out.points.push(front);
        if material.double_sided {
            out.points.push(SurfacePoint {
                normal: -front.normal,
                back_face: true,
                ..front
            });
        }
    }
    // The grid and the reconstruction keep the uniform radius (see the function's docs).
    out.poisson_radius = r_uniform as f32;
    out.poisson_radius_local = (r_uniform * (tris.area_local / area).sqrt()) as f32;
    Ok(out)
}

/// Salt of the random choices of extra candidates (decorrelated from the uniform stream).
const EXTRA_SALT: u64 = 0x6164_6170_7469_7665;
/// Tries per extra candidate to land on its triangle within the spread disk.
const EXTRA_TRIES: u64 = 4;

/// The extra candidates of adaptive placement and the factor of every candidate (the uniform
/// ones first, then the extras), with the mean factor of the uniform ones. `stream` is the
/// instance's seed and the uniform spawn count (extras draw from indices above it); `spacing`
/// is the uniform spacing `2·r_u` in world units.
#[allow(clippy::too_many_arguments)]
fn adaptive_candidates(
    tris: &Triangles,
    mesh: &Mesh,
    transform: &Affine3A,
    base: &[Candidate],
    adaptive: Adaptive<'_>,
    instance: usize,
    stream: (u64, u64),
    spacing: f32,
    mask: Option<AlphaTest<'_>>,
) -> (Vec<Candidate>, Vec<f32>, f32) {
    let normal_matrix = transform.matrix3.inverse().transpose();
    let probes: Vec<(Vec3, Vec3)> = base
        .par_iter()
        .map(|c| {
            let p = transform.transform_point3(tris.local_position(c));
            let n = normal_matrix
                .mul_vec3(local_normal(mesh, tris, c))
                .normalize_or(Vec3::Z);
            (p, n)
        })
        .collect();
    let signal = (adaptive.signal)(instance, &probes, spacing);
    let boost = adaptive.max_boost;
    let mut factors: Vec<f32> = (0..base.len())
        .map(|i| {
            let s = signal
                .get(i)
                .copied()
                .filter(|_| signal.len() == base.len());
            let s = s.filter(|x| !x.is_nan()).unwrap_or(0.0).clamp(0.0, 1.0);
            1.0 + (boost - 1.0) * s
        })
        .collect();
    let mean = factors.iter().map(|&f| f64::from(f)).sum::<f64>() / base.len().max(1) as f64;
    let (seed, spawned) = stream;
    let seed = seed ^ EXTRA_SALT;
    // Per uniform candidate: how many extras (f − 1 on average) and where.
    let extras: Vec<(Candidate, f32)> = base
        .par_iter()
        .zip(factors.par_iter())
        .enumerate()
        .flat_map_iter(|(i, (c, &f))| {
            let mut rng = Stream::new(seed, spawned + i as u64);
            let want = f - 1.0;
            let count = want.floor() as u32 + u32::from(rng.next_f32() < want.fract());
            let mut out = Vec::with_capacity(count as usize);
            for _ in 0..count {
                if let Some(e) = tris.spawn_near(c, spacing, transform, &mut rng) {
                    if mask.is_none_or(|m| m(e.triangle, e.bary())) {
                        out.push((e, f));
                    }
                }
            }
            out
        })
        .collect();
    let (extra, extra_factors): (Vec<Candidate>, Vec<f32>) = extras.into_iter().unzip();
    factors.extend(extra_factors);
    (extra, factors, mean as f32)
}

/// World-space area of a mesh under `transform` (invalid triangles count 0); used to schedule.
fn world_area(mesh: &Mesh, transform: &Affine3A) -> f64 {
    mesh.indices
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions.get(i as usize).copied());
            let [a, b, c] = [a?, b?, c?].map(|p| transform.transform_point3(p));
            Some(0.5 * f64::from((b - a).cross(c - a).length()))
        })
        .filter(|a| a.is_finite())
        .sum()
}

/// Generate the points of every instance of `scene` (returned in instance order), in parallel:
/// instances are handed to the worker threads largest first (each one's own work is also
/// parallel). Instance `i` uses the seed [`instance_seed`]`(params.seed, i)`; a mesh's material
/// index out of range falls back to the default material. `alpha` receives the mesh index
/// first.
pub fn generate_scene_points(
    scene: &Scene,
    params: &GenerateParams,
    alpha: Option<SceneAlphaTest<'_>>,
) -> Result<Vec<InstancePoints>, PointsError> {
    generate_scene_points_adaptive(scene, params, alpha, None)
}

/// [`generate_scene_points`] with adaptive placement ([`generate_instance_points_adaptive`];
/// the signal receives the instance index).
pub fn generate_scene_points_adaptive(
    scene: &Scene,
    params: &GenerateParams,
    alpha: Option<SceneAlphaTest<'_>>,
    adaptive: Option<Adaptive<'_>>,
) -> Result<Vec<InstancePoints>, PointsError> {
    let fallback = Material::default();
    let run = |i: usize| {
        let inst = &scene.instances[i];
        let mesh = scene
            .meshes
            .get(inst.mesh)
            .ok_or(PointsError::MeshOutOfRange {
                instance: i,
                mesh: inst.mesh,
                count: scene.meshes.len(),
            })?;
        let material = scene.materials.get(mesh.material).unwrap_or(&fallback);
        let hook = alpha.map(|f| move |t: u32, b: Vec3| f(inst.mesh, t, b));
        let p = GenerateParams {
            seed: instance_seed(params.seed, i),
            ..*params
        };
        generate_instance_points_adaptive(
            mesh,
            material,
            &inst.transform,
            &p,
            hook.as_ref().map(|h| h as AlphaTest<'_>),
            adaptive,
            i,
        )
    };
    let mut order: Vec<(f64, usize)> = scene
        .instances
        .par_iter()
        .enumerate()
        .map(|(i, inst)| {
            let area = scene
                .meshes
                .get(inst.mesh)
                .map_or(0.0, |m| world_area(m, &inst.transform));
            (area, i)
        })
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let next = AtomicUsize::new(0);
    let done = Mutex::new(Vec::with_capacity(order.len()));
    rayon::scope(|s| {
        for _ in 0..rayon::current_num_threads() {
            s.spawn(|_| {
                while let Some(&(_, i)) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let result = run(i);
                    if let Ok(mut d) = done.lock() {
                        d.push((i, result));
                    }
                }
            });
        }
    });
    let mut done = done.into_inner().unwrap_or_default();
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, r)| r).collect()
}
