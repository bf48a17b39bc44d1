//! The [`Tracer`] facade: one two-level structure, whichever backend holds it.

use glam::{Affine3A, Vec3};
use psao_scene::{Motion, Scene, ScenePose};

#[cfg(feature = "embree")]
use crate::embree_backend::EmbreeTracer;
use crate::geometry::{check_positions, included_meshes};
use crate::obvhs_backend::ObvhsTracer;
use crate::{Backend, GeometryMode, Hit, Ray, TraceError};

/// Default [`Tracer::update_deforming_mesh`] threshold: rebuild once refits made the BVH's
/// expected cost per ray 30 % higher than a fresh build.
pub const DEFAULT_MAX_COST_RATIO: f32 = 1.3;

/// What [`Tracer::update_deforming_mesh`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshUpdate {
    /// Whether the mesh's BVH was rebuilt (otherwise refitted).
    pub rebuilt: bool,
    /// The cost ratio after the update (`None` where the backend has no metric).
    pub cost_ratio: Option<f32>,
}

/// The backend-specific structure.
enum Inner {
    Obvhs(ObvhsTracer),
    #[cfg(feature = "embree")]
    Embree(EmbreeTracer),
}

/// Batched ray queries against a scene: one BVH per mesh in mesh-local space under a top
/// level over the instances. Queries take `&self` (parallelise over batches with rayon);
/// updates take `&mut self` and need a [`Tracer::commit`] before the next query.
pub struct Tracer {
    backend: Backend,
    mode: GeometryMode,
    /// Vertex count per mesh, to validate updates.
    vertex_counts: Vec<usize>,
    inner: Inner,
}

// Callers share one tracer across rayon workers.
const _: fn() = || {
    fn shared<T: Send + Sync>() {}
    shared::<Tracer>();
};

impl Tracer {
    /// Builds the structure for `scene` (every instance at its current transform) with
    /// `backend`, containing the triangles `mode` selects. Hits report indices into
    /// `scene.instances` and the meshes' `indices`, whatever is left out.
    pub fn new(backend: Backend, scene: &Scene, mode: GeometryMode) -> Result<Tracer, TraceError> {
        let included = included_meshes(scene, mode)?;
        let inner = match backend {
            Backend::Obvhs => Inner::Obvhs(ObvhsTracer::new(scene, &included)),
            #[cfg(feature = "embree")]
            Backend::Embree => Inner::Embree(EmbreeTracer::new(scene, &included)?),
            #[cfg(not(feature = "embree"))]
            Backend::Embree => return Err(TraceError::NotCompiled(backend)),
        };
        Ok(Tracer {
            backend,
            mode,
            vertex_counts: scene.meshes.iter().map(|m| m.positions.len()).collect(),
            inner,
        })
    }

    /// Bytes the backend's structure holds, where the backend counts them: Embree's own count
    /// of its allocations (BVHs, buffers, scenes); `None` for obvhs.
    pub fn structure_bytes(&self) -> Option<u64> {
        match &self.inner {
            Inner::Obvhs(_) => None,
            #[cfg(feature = "embree")]
            Inner::Embree(t) => Some(t.allocated_bytes()),
        }
    }

    /// The backend holding the structure.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Which triangles the structure contains.
    pub fn mode(&self) -> GeometryMode {
        self.mode
    }

    /// Moves instance `instance` (mesh-local to world). Only the top level changes. An index
    /// out of range is ignored; a singular or non-finite transform hides the instance.
    pub fn set_instance_transform(&mut self, instance: usize, transform: Affine3A) {
        match &mut self.inner {
            Inner::Obvhs(t) => t.set_instance_transform(instance, transform),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.set_instance_transform(instance, transform),
        }
    }

    /// Replaces the vertex positions of a deforming mesh (same count, mesh-local space) and
    /// refits its BVH; all instances of the mesh follow.
    pub fn update_mesh_positions(
        &mut self,
        mesh: usize,
        positions: &[Vec3],
    ) -> Result<(), TraceError> {
        self.replace_mesh_positions(mesh, positions, false)
    }

    /// Replaces the vertex positions of a deforming mesh like
    /// [`Tracer::update_mesh_positions`], but builds its BVH from scratch instead of refitting
    /// (slower, restores full quality); later updates refit the new structure.
    pub fn rebuild_mesh_positions(
        &mut self,
        mesh: usize,
        positions: &[Vec3],
    ) -> Result<(), TraceError> {
        self.replace_mesh_positions(mesh, positions, true)
    }

    /// The two above: validate, then refit or `rebuild` in the backend.
    fn replace_mesh_positions(
        &mut self,
        mesh: usize,
        positions: &[Vec3],
        rebuild: bool,
    ) -> Result<(), TraceError> {
        self.check_update(mesh, positions)?;
        match &mut self.inner {
            Inner::Obvhs(t) => {
                if rebuild {
                    t.rebuild_mesh_positions(mesh, positions);
                } else {
                    t.update_mesh_positions(mesh, positions);
                }
                Ok(())
            }
            #[cfg(feature = "embree")]
            Inner::Embree(t) if rebuild => t.rebuild_mesh_positions(mesh, positions),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.update_mesh_positions(mesh, positions),
        }
    }

    /// How much a deforming mesh's BVH has degraded through refits: its surface-area-heuristic
    /// cost relative to right after its last full build (1 = as built, 1.5 = 50 % more
    /// expected work per ray). `None` for meshes that were never updated, meshes left out
    /// of the structure, and the Embree backend (which exposes no such metric).
    pub fn mesh_cost_ratio(&self, mesh: usize) -> Option<f32> {
        match &self.inner {
            Inner::Obvhs(t) => t.mesh_cost_ratio(mesh),
            #[cfg(feature = "embree")]
            Inner::Embree(_) => None,
        }
    }

    /// The per-frame update of a skinned mesh: refits, unless the last refit left the BVH's
    /// cost ratio ([`Tracer::mesh_cost_ratio`]) above `max_cost_ratio`, then rebuilds.
    pub fn update_deforming_mesh(
        &mut self,
        mesh: usize,
        positions: &[Vec3],
        max_cost_ratio: f32,
    ) -> Result<MeshUpdate, TraceError> {
        let rebuild = self
            .mesh_cost_ratio(mesh)
            .is_some_and(|r| r > max_cost_ratio);
        if rebuild {
            self.rebuild_mesh_positions(mesh, positions)?;
        } else {
            self.update_mesh_positions(mesh, positions)?;
        }
        Ok(MeshUpdate {
            rebuilt: rebuild,
            cost_ratio: self.mesh_cost_ratio(mesh),
        })
    }

    /// Moves the structure to `pose`, a pose of `scene`'s animation whose instances move as
    /// `motion` says (see [`psao_scene::Animator::motion`]): every moving instance to its
    /// posed transform, every skinned mesh to its posed vertices (refitted or rebuilt as by
    /// [`Tracer::update_deforming_mesh`] with [`DEFAULT_MAX_COST_RATIO`]); then commits.
    pub fn apply_pose(
        &mut self,
        scene: &Scene,
        motion: &[Motion],
        pose: &ScenePose,
    ) -> Result<(), TraceError> {
        for (i, m) in motion.iter().enumerate() {
            if *m == Motion::Static {
                continue;
            }
            if let Some(&transform) = pose.transforms.get(i) {
                self.set_instance_transform(i, transform);
            }
            if let (Some(Some(geometry)), Some(instance)) =
                (pose.skinned.get(i), scene.instances.get(i))
            {
                self.update_deforming_mesh(
                    instance.mesh,
                    &geometry.positions,
                    DEFAULT_MAX_COST_RATIO,
                )?;
            }
        }
        self.commit();
        Ok(())
    }

    /// Rebuilds the top level after transform or mesh updates; call before querying again.
    pub fn commit(&mut self) {
        match &mut self.inner {
            Inner::Obvhs(t) => t.commit(),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.commit(),
        }
    }

    /// Checks a vertex update: the mesh exists and the positions fit it and are finite.
    fn check_update(&self, mesh: usize, positions: &[Vec3]) -> Result<(), TraceError> {
        let expected = *self.vertex_counts.get(mesh).ok_or(TraceError::NoSuchMesh {
            mesh,
            meshes: self.vertex_counts.len(),
        })?;
        if positions.len() != expected {
            return Err(TraceError::PositionCount {
                mesh,
                expected,
                got: positions.len(),
            });
        }
        check_positions(mesh, positions)
    }

    /// For each ray: is anything hit with `0 < t < tmax`? Traces on the calling thread;
    /// processes `min(rays.len(), out.len())` rays. Untraceable rays (non-finite, zero
    /// direction, `tmax <= 0`) report `false`.
    pub fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        debug_assert_eq!(rays.len(), out.len());
        match &self.inner {
            Inner::Obvhs(t) => rays
                .iter()
                .zip(out.iter_mut())
                .for_each(|(r, o)| *o = t.occluded_one(r)),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.occluded(rays, out),
        }
    }

    /// For each ray: the closest hit with `0 < t < tmax`, if any. Traces on the calling
    /// thread; processes `min(rays.len(), out.len())` rays.
    pub fn intersect(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        debug_assert_eq!(rays.len(), out.len());
        match &self.inner {
            Inner::Obvhs(t) => rays
                .iter()
                .zip(out.iter_mut())
                .for_each(|(r, o)| *o = t.intersect_one(r)),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.intersect(rays, out),
        }
    }
}
