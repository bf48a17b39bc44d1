//! Instance poses: the transforms and deformed vertices a scene is rasterized with.

use glam::{Affine3A, Vec3};
use psao_scene::{Instance, Scene};

/// The geometry of one instance at the moment being rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstancePose<'a> {
    /// Mesh-local (for skinned meshes: skeleton-space) to world transform.
    pub transform: Affine3A,
    /// Deformed vertex positions replacing the mesh's (e.g. after skinning), one per mesh vertex.
    pub positions: Option<&'a [Vec3]>,
    /// Deformed vertex normals replacing the mesh's, one per mesh vertex.
    pub normals: Option<&'a [Vec3]>,
}

impl InstancePose<'static> {
    /// The instance as stored in the scene: its own transform and the undeformed mesh.
    pub fn rest(instance: &Instance) -> Self {
        Self::rigid(instance.transform)
    }

    /// The undeformed mesh placed by `transform`.
    pub fn rigid(transform: Affine3A) -> Self {
        Self {
            transform,
            positions: None,
            normals: None,
        }
    }
}

/// Why a set of poses cannot be rasterized.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PoseError {
    /// The number of poses differs from the number of scene instances.
    #[error("{poses} poses given for {instances} instances")]
    PoseCount {
        /// Poses given.
        poses: usize,
        /// Instances in the scene.
        instances: usize,
    },
    /// An override array's length differs from its mesh's vertex count.
    #[error(
        "instance {instance}: {what} override has {got} entries, mesh has {expected} vertices"
    )]
    VertexCount {
        /// Instance index.
        instance: usize,
        /// `"position"` or `"normal"`.
        what: &'static str,
        /// Override length.
        got: usize,
        /// Mesh vertex count.
        expected: usize,
    },
}

/// Checks that `poses` fit `scene` (one per instance, override lengths equal to vertex counts).
pub fn validate_poses(scene: &Scene, poses: &[InstancePose<'_>]) -> Result<(), PoseError> {
    if poses.len() != scene.instances.len() {
        return Err(PoseError::PoseCount {
            poses: poses.len(),
            instances: scene.instances.len(),
        });
    }
    for (i, (inst, pose)) in scene.instances.iter().zip(poses).enumerate() {
        let expected = scene.meshes.get(inst.mesh).map_or(0, |m| m.positions.len());
        let overrides = [
            ("position", pose.positions.map(<[Vec3]>::len)),
            ("normal", pose.normals.map(<[Vec3]>::len)),
        ];
        for (what, len) in overrides {
            match len {
                Some(got) if got != expected => {
                    return Err(PoseError::VertexCount {
                        instance: i,
                        what,
                        got,
                        expected,
                    })
                }
                _ => {}
            }
        }
    }
    Ok(())
}
