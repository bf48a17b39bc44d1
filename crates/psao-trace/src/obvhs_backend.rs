//! Pure-Rust backend on `obvhs`: one compressed 8-wide BVH (CWBVH) per mesh in mesh-local space
//! and a CWBVH over the instances' world bounds. A rigid move only rebuilds the small top
//! level; a deforming mesh keeps its binary BVH, whose boxes are refitted and re-compressed.

use glam::{Affine3A, UVec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::ploc::PlocBuilder;
use obvhs::ray::Ray as ObRay;
use obvhs::{traverse, BvhBuildParams};
use psao_scene::Scene;
use rayon::prelude::*;

use crate::geometry::usable_inverse;
use crate::{Hit, Ray};

/// Most primitives a CWBVH leaf may hold (the format's limit).
const MAX_LEAF_PRIMITIVES: u32 = 3;

/// A triangle stored for Möller–Trumbore: base vertex and the two edges from it.
#[derive(Clone, Copy, Debug)]
struct Triangle {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

impl Triangle {
    fn new(positions: &[Vec3], tri: [u32; 3]) -> Self {
        let [a, b, c] = tri.map(|i| Vec3A::from(positions[i as usize]));
        Self {
            v0: a,
            e1: b - a,
            e2: c - a,
        }
    }

    fn aabb(positions: &[Vec3], tri: [u32; 3]) -> Aabb {
        let [a, b, c] = tri.map(|i| Vec3A::from(positions[i as usize]));
        Aabb::new(a.min(b).min(c), a.max(b).max(c))
    }

    /// `(t, u, v)` of the hit with `0 < t < ray.tmax`, both faces counting.
    #[inline(always)]
    fn intersect(&self, ray: &ObRay) -> Option<(f32, f32, f32)> {
        let p = ray.direction.cross(self.e2);
        let det = self.e1.dot(p);
        if det == 0.0 {
            return None;
        }
        let inv_det = 1.0 / det;
        let s = ray.origin - self.v0;
        let u = s.dot(p) * inv_det;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = ray.direction.dot(q) * inv_det;
        if !(v >= 0.0 && u + v <= 1.0) {
            return None;
        }
        let t = self.e2.dot(q) * inv_det;
        (t > 0.0 && t < ray.tmax).then_some((t, u, v))
    }
}

/// An obvhs ray with `tmin = 0`. Negative zeros in the direction become positive: obvhs takes
/// the traversal octant from `d < 0` but the slab inverse from the sign bit, and the mismatch
/// makes axis-parallel rays with a `-0.0` component miss every box.
#[inline(always)]
fn ob_ray(origin: Vec3A, direction: Vec3A, tmax: f32) -> ObRay {
    ObRay::new(origin, direction + Vec3A::ZERO, 0.0, tmax)
}

/// Builds a binary BVH over `aabbs` with obvhs's PLOC builder and reinsertion optimisation:
/// the slower, better preset for structures that are traced many times (static meshes, the
/// small top level), the medium one for deforming meshes, whose quality decays with refits.
fn build_bvh2(aabbs: &[Aabb], traced_long: bool) -> Bvh2 {
    let params = if traced_long {
        BvhBuildParams::slow_build()
    } else {
        BvhBuildParams::medium_build()
    };
    let mut bvh2 = PlocBuilder::with_capacity(aabbs.len()).build(
        params.ploc_search_distance,
        aabbs,
        (0..aabbs.len() as u32).collect(),
        params.sort_precision,
        params.search_depth_threshold,
    );
    ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
    bvh2
}

/// Surface-area-heuristic cost of a binary BVH relative to its root's surface area: the
/// expected number of node visits plus triangle tests for a random ray through the root
/// (traversal and intersection weighted 1 each). Refitting keeps the topology while the
/// boxes grow, so the cost rises as the deformation moves away from the built pose.
fn sah_cost(bvh2: &Bvh2) -> f32 {
    let Some(root) = bvh2.nodes.first() else {
        return 0.0;
    };
    let root_area = root.aabb().half_area();
    if root_area.is_nan() || root_area <= 0.0 {
        return 0.0;
    }
    let sum: f32 = bvh2
        .nodes
        .iter()
        .map(|n| {
            let weight = if n.is_leaf() {
                n.prim_count as f32
            } else {
                1.0
            };
            n.aabb().half_area() * weight
        })
        .sum();
    sum / root_area
}

/// One mesh's bottom-level structure.
struct Blas {
    /// The wide BVH that is traversed.
    bvh: CwBvh,
    /// Triangles in `bvh.primitive_indices` order, so leaves index them directly.
    tris: Vec<Triangle>,
    /// Local-space bounds.
    lo: Vec3,
    hi: Vec3,
    /// The mesh's triangles (needed to refit).
    indices: Vec<[u32; 3]>,
    /// The binary BVH kept for deforming meshes; refitting it keeps the topology.
    refit: Option<Bvh2>,
    /// Normalised SAH cost ([`sah_cost`]) right after the last full build.
    built_cost: f32,
    /// Normalised SAH cost now (after any refits).
    cost: f32,
}

impl Blas {
    fn new(positions: &[Vec3], indices: &[[u32; 3]], deforming: bool) -> Self {
        let aabbs: Vec<Aabb> = indices
            .iter()
            .map(|&t| Triangle::aabb(positions, t))
            .collect();
        let bvh2 = build_bvh2(&aabbs, !deforming);
        let mut blas = Self {
            bvh: CwBvh::default(),
            tris: Vec::new(),
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            indices: indices.to_vec(),
            refit: None,
            built_cost: 0.0,
            cost: 0.0,
        };
        blas.set_built(bvh2, positions, deforming);
        blas
    }

    /// Installs a freshly built `bvh2` (kept for refits when `keep`) as the new reference.
    fn set_built(&mut self, bvh2: Bvh2, positions: &[Vec3], keep: bool) {
        self.compress(&bvh2, positions);
        self.built_cost = sah_cost(&bvh2);
        self.cost = self.built_cost;
        self.refit = keep.then_some(bvh2);
    }

    /// Rebuilds the structure from scratch for new vertex positions (kept for refits).
    fn rebuild(&mut self, positions: &[Vec3]) {
        let aabbs: Vec<Aabb> = self
            .indices
            .iter()
            .map(|&t| Triangle::aabb(positions, t))
            .collect();
        self.set_built(build_bvh2(&aabbs, false), positions, true);
    }

    /// SAH cost now relative to right after the last full build (1 = as good as built).
    fn cost_ratio(&self) -> f32 {
        if self.built_cost > 0.0 {
            self.cost / self.built_cost
        } else {
            1.0
        }
    }

    /// Converts `bvh2` to the traversed wide BVH and lays the triangles out in its order.
    fn compress(&mut self, bvh2: &Bvh2, positions: &[Vec3]) {
        self.bvh = bvh2_to_cwbvh(bvh2, MAX_LEAF_PRIMITIVES, true, false);
        self.tris = self
            .bvh
            .primitive_indices
            .iter()
            .map(|&i| Triangle::new(positions, self.indices[i as usize]))
            .collect();
        self.lo = self.bvh.total_aabb.min.into();
        self.hi = self.bvh.total_aabb.max.into();
    }

    /// Moves the vertices: refits the kept binary BVH (building one on the first call) and
    /// re-compresses it.
    fn update_positions(&mut self, positions: &[Vec3]) {
        let aabbs: Vec<Aabb> = self
            .indices
            .iter()
            .map(|&t| Triangle::aabb(positions, t))
            .collect();
        match self.refit.take() {
            Some(mut bvh2) => {
                for node in bvh2.nodes.iter_mut().filter(|n| n.is_leaf()) {
                    let first = node.first_index as usize;
                    let prims = &bvh2.primitive_indices[first..first + node.prim_count as usize];
                    let aabb = prims
                        .iter()
                        .fold(Aabb::empty(), |acc, &p| acc.union(&aabbs[p as usize]));
                    node.set_aabb(aabb);
                }
                bvh2.refit_all();
                self.compress(&bvh2, positions);
                self.cost = sah_cost(&bvh2);
                self.refit = Some(bvh2);
            }
            None => self.set_built(build_bvh2(&aabbs, false), positions, true),
        }
    }

    /// Closest hit `(slot, u, v)`; shortens `ray.tmax` to its distance.
    #[inline]
    fn closest(&self, ray: &mut ObRay) -> Option<(u32, f32, f32)> {
        let mut found = None;
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        traverse!(
            self.bvh,
            node,
            state,
            node.intersect_ray(ray, state.oct_inv4),
            {
                let slot = state.primitive_id as usize;
                if let Some((t, u, v)) = self.tris[slot].intersect(ray) {
                    ray.tmax = t;
                    found = Some((slot as u32, u, v));
                }
            }
        );
        found
    }

    /// Whether any triangle is hit.
    #[inline]
    fn any(&self, ray: &ObRay) -> bool {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut hit = false;
        'search: {
            traverse!(
                self.bvh,
                node,
                state,
                node.intersect_ray(ray, state.oct_inv4),
                {
                    if self.tris[state.primitive_id as usize]
                        .intersect(ray)
                        .is_some()
                    {
                        hit = true;
                        break 'search;
                    }
                }
            );
        }
        hit
    }
}

/// A top-level primitive: one placed instance.
#[derive(Clone, Copy, Debug)]
struct TopItem {
    /// World to mesh-local transform.
    inverse: Affine3A,
    /// Index into the scene's instances.
    instance: u32,
    /// Index into the scene's meshes (its BLAS exists).
    mesh: u32,
    /// Whether the transform is a pure translation.
    translation_only: bool,
}

impl TopItem {
    /// The world ray in mesh-local space (same parameter t).
    #[inline(always)]
    fn local_ray(&self, world: &ObRay) -> ObRay {
        if self.translation_only {
            // Common case (e.g. OBJ objects): the direction and its inverse carry over.
            ObRay {
                origin: world.origin + self.inverse.translation,
                ..*world
            }
        } else {
            ob_ray(
                self.inverse.transform_point3a(world.origin),
                self.inverse.transform_vector3a(world.direction),
                world.tmax,
            )
        }
    }
}

/// The obvhs two-level structure.
pub(crate) struct ObvhsTracer {
    /// Per mesh; `None` for meshes left out of the structure.
    blas: Vec<Option<Blas>>,
    /// Per scene instance: (mesh, mesh-to-world transform).
    instances: Vec<(usize, Affine3A)>,
    /// Top level over the usable instances.
    tlas: CwBvh,
    /// Top-level primitives in `tlas.primitive_indices` order.
    top: Vec<TopItem>,
    /// Whether the top level is stale.
    dirty: bool,
}

impl ObvhsTracer {
    /// Builds all bottom levels (meshes with `included[m]`, in parallel) and the top level.
    pub(crate) fn new(scene: &Scene, included: &[bool]) -> Self {
        let blas = scene
            .meshes
            .par_iter()
            .zip(included)
            .map(|(mesh, &inc)| {
                inc.then(|| Blas::new(&mesh.positions, &mesh.indices, !mesh.joints.is_empty()))
            })
            .collect();
        let mut tracer = Self {
            blas,
            instances: scene
                .instances
                .iter()
                .map(|i| (i.mesh, i.transform))
                .collect(),
            tlas: CwBvh::default(),
            top: Vec::new(),
            dirty: true,
        };
        tracer.commit();
        tracer
    }

    pub(crate) fn set_instance_transform(&mut self, instance: usize, transform: Affine3A) {
        if let Some(slot) = self.instances.get_mut(instance) {
            slot.1 = transform;
            self.dirty = true;
        }
    }

    pub(crate) fn update_mesh_positions(&mut self, mesh: usize, positions: &[Vec3]) {
        if let Some(Some(blas)) = self.blas.get_mut(mesh) {
            blas.update_positions(positions);
            self.dirty = true;
        }
    }

    pub(crate) fn rebuild_mesh_positions(&mut self, mesh: usize, positions: &[Vec3]) {
        if let Some(Some(blas)) = self.blas.get_mut(mesh) {
            blas.rebuild(positions);
            self.dirty = true;
        }
    }

    /// The mesh's SAH cost relative to its last full build (`None` unless it deforms).
    pub(crate) fn mesh_cost_ratio(&self, mesh: usize) -> Option<f32> {
        let blas = self.blas.get(mesh)?.as_ref()?;
        blas.refit.as_ref().map(|_| blas.cost_ratio())
    }

    /// Rebuilds the top level when a transform or a mesh changed.
    pub(crate) fn commit(&mut self) {
        if !self.dirty {
            return;
        }
        let mut items = Vec::new();
        let mut aabbs = Vec::new();
        for (i, &(mesh, transform)) in self.instances.iter().enumerate() {
            let (Some(Some(blas)), Some(inverse)) =
                (self.blas.get(mesh), usable_inverse(&transform))
            else {
                continue;
            };
            let (lo, hi) = psao_scene::affine::transformed_box(&transform, blas.lo, blas.hi);
            aabbs.push(Aabb::new(lo.into(), hi.into()));
            items.push(TopItem {
                inverse,
                instance: i as u32,
                mesh: mesh as u32,
                translation_only: transform.matrix3 == glam::Mat3A::IDENTITY,
            });
        }
        if items.is_empty() {
            self.tlas = CwBvh::default();
            self.top.clear();
        } else {
            self.tlas = bvh2_to_cwbvh(&build_bvh2(&aabbs, true), MAX_LEAF_PRIMITIVES, true, false);
            self.top = self
                .tlas
                .primitive_indices
                .iter()
                .map(|&p| items[p as usize])
                .collect();
        }
        self.dirty = false;
    }

    #[inline]
    fn blas(&self, item: &TopItem) -> Option<&Blas> {
        self.blas.get(item.mesh as usize).and_then(Option::as_ref)
    }

    /// Closest hit of one ray.
    pub(crate) fn intersect_one(&self, ray: &Ray) -> Option<Hit> {
        if self.top.is_empty() || !ray.is_traceable() {
            return None;
        }
        let mut world = ob_ray(ray.origin.into(), ray.dir.into(), ray.tmax);
        let mut best = None;
        let mut state = self.tlas.new_traversal(world.direction);
        let mut node;
        traverse!(
            self.tlas,
            node,
            state,
            node.intersect_ray(&world, state.oct_inv4),
            {
                let item = &self.top[state.primitive_id as usize];
                if let Some(blas) = self.blas(item) {
                    let mut local = item.local_ray(&world);
                    if let Some((slot, u, v)) = blas.closest(&mut local) {
                        world.tmax = local.tmax;
                        best = Some(Hit {
                            t: local.tmax,
                            instance: item.instance,
                            triangle: blas.bvh.primitive_indices[slot as usize],
                            u,
                            v,
                        });
                    }
                }
            }
        );
        best
    }

    /// Whether one ray hits anything.
    pub(crate) fn occluded_one(&self, ray: &Ray) -> bool {
        if self.top.is_empty() || !ray.is_traceable() {
            return false;
        }
        let world = ob_ray(ray.origin.into(), ray.dir.into(), ray.tmax);
        let mut state = self.tlas.new_traversal(world.direction);
        let mut node;
        let mut hit = false;
        'search: {
            traverse!(
                self.tlas,
                node,
                state,
                node.intersect_ray(&world, state.oct_inv4),
                {
                    let item = &self.top[state.primitive_id as usize];
                    if self
                        .blas(item)
                        .is_some_and(|b| b.any(&item.local_ray(&world)))
                    {
                        hit = true;
                        break 'search;
                    }
                }
            );
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3, tmax: f32) -> ObRay {
        ob_ray(o.into(), d.into(), tmax)
    }

    #[test]
    fn triangle_barycentrics_and_range() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let tri = Triangle::new(&p, [0, 1, 2]);
        let (t, u, v) = tri
            .intersect(&ray(Vec3::new(0.25, 0.5, 2.0), -Vec3::Z, 10.0))
            .unwrap();
        assert!((t - 2.0).abs() < 1e-6 && (u - 0.25).abs() < 1e-6 && (v - 0.5).abs() < 1e-6);
        // Back face counts too; tmax is exclusive; behind the origin is a miss.
        assert!(tri
            .intersect(&ray(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 10.0))
            .is_some());
        assert!(tri
            .intersect(&ray(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 1.0))
            .is_none());
        assert!(tri
            .intersect(&ray(Vec3::new(0.2, 0.2, 1.0), Vec3::Z, 10.0))
            .is_none());
        assert!(tri
            .intersect(&ray(Vec3::new(0.8, 0.8, 1.0), -Vec3::Z, 10.0))
            .is_none());
    }

    #[test]
    fn single_triangle_blas_and_refit() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut blas = Blas::new(&p, &[[0, 1, 2]], false);
        let mut r = ray(Vec3::new(0.1, 0.1, 1.0), -Vec3::Z, 5.0);
        assert!(blas.closest(&mut r).is_some());
        assert!((r.tmax - 1.0).abs() < 1e-6);
        let moved: Vec<Vec3> = p.iter().map(|&v| v + Vec3::new(5.0, 0.0, 0.0)).collect();
        blas.update_positions(&moved);
        assert!(!blas.any(&ray(Vec3::new(0.1, 0.1, 1.0), -Vec3::Z, 5.0)));
        assert!(blas.any(&ray(Vec3::new(5.1, 0.1, 1.0), -Vec3::Z, 5.0)));
        // A second update goes through the kept binary BVH (a true refit).
        assert!(blas.refit.is_some());
        blas.update_positions(&p);
        assert!(blas.any(&ray(Vec3::new(0.1, 0.1, 1.0), -Vec3::Z, 5.0)));
    }
}
