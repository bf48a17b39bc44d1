//! The [`Tracer`] facade: one two-level structure, whichever backend holds it.

use glam::{Affine3A, Vec3};
use psao_scene::Scene;

#[cfg(feature = "embree")]
use crate::embree_backend::EmbreeTracer;
use crate::geometry::{check_positions, included_meshes};
use crate::obvhs_backend::ObvhsTracer;
use crate::{Backend, GeometryMode, Hit, Ray, TraceError};

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
        check_positions(mesh, positions)?;
        match &mut self.inner {
            Inner::Obvhs(t) => {
                t.update_mesh_positions(mesh, positions);
                Ok(())
            }
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.update_mesh_positions(mesh, positions),
        }
    }

    /// Rebuilds the top level after transform or mesh updates; call before querying again.
    pub fn commit(&mut self) {
        match &mut self.inner {
            Inner::Obvhs(t) => t.commit(),
            #[cfg(feature = "embree")]
            Inner::Embree(t) => t.commit(),
        }
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
