//! World- and clip-space vertices of every instance in the pose being rasterized.

use glam::{Mat3A, Vec3, Vec4};
use psao_scene::Scene;
use rayon::prelude::*;

use crate::mask::Cut;
use crate::pose::InstancePose;
use crate::view::View;

/// Reusable transformed-vertex storage of one instance.
#[derive(Default)]
pub(crate) struct VertexBuffers {
    world: Vec<Vec3>,
    clip: Vec<Vec4>,
}

/// One instance's transformed geometry.
pub(crate) struct PosedInstance<'a> {
    /// Triangles (indices into `world`/`clip`); empty when the instance's mesh is missing.
    pub indices: &'a [[u32; 3]],
    /// World-space vertex positions.
    pub world: &'a [Vec3],
    /// Clip-space vertex positions.
    pub clip: &'a [Vec4],
    /// Local-space vertex normals, when present for every vertex.
    pub normals: Option<&'a [Vec3]>,
    /// Local-to-world normal transform, when the transform is invertible.
    pub normal_matrix: Option<Mat3A>,
    /// Whether back faces may be culled (the material is single-sided).
    pub single_sided: bool,
    /// How the material's alpha mask cuts the surface.
    pub cut: Cut<'a>,
}

/// (instance, triangle within its mesh) of global triangle `id`, given the first global id
/// of each instance.
pub(crate) fn locate(first_id: &[u32], id: u32) -> Option<(usize, u32)> {
    let instance = first_id.partition_point(|&f| f <= id).checked_sub(1)?;
    Some((instance, id - first_id[instance]))
}

impl PosedInstance<'_> {
    /// Vertex indices and world-space vertices of triangle `tri`, `None` when an index is out
    /// of range.
    pub fn triangle(&self, tri: usize) -> Option<([u32; 3], [Vec3; 3])> {
        let idx = *self.indices.get(tri)?;
        let [a, b, c] = idx.map(|i| self.world.get(i as usize).copied());
        Some((idx, [a?, b?, c?]))
    }
}

/// Transforms every instance of `scene` by its pose (`poses` has one entry per instance),
/// reusing `buffers` for the vertex data.
pub(crate) fn pose_instances<'a>(
    scene: &'a Scene,
    poses: &[InstancePose<'a>],
    view: &View,
    buffers: &'a mut Vec<VertexBuffers>,
) -> Vec<PosedInstance<'a>> {
    buffers.resize_with(scene.instances.len(), VertexBuffers::default);
    buffers
        .par_iter_mut()
        .zip(&scene.instances)
        .zip(poses)
        .for_each(|((buf, inst), pose)| {
            buf.world.clear();
            buf.clip.clear();
            if let Some(mesh) = scene.meshes.get(inst.mesh) {
                let local = pose.positions.unwrap_or(&mesh.positions);
                buf.world.par_extend(
                    local
                        .par_iter()
                        .map(|&p| pose.transform.transform_point3(p)),
                );
                buf.clip.par_extend(
                    buf.world
                        .par_iter()
                        .map(|&p| view.view_proj * p.extend(1.0)),
                );
            }
        });
    buffers
        .iter()
        .zip(&scene.instances)
        .zip(poses)
        .map(|((buf, inst), pose)| {
            let mesh = scene.meshes.get(inst.mesh);
            let material = mesh.and_then(|m| scene.materials.get(m.material));
            let cut = mesh
                .zip(material)
                .map_or(Cut::Nothing, |(m, mat)| Cut::of(m, mat, buf.world.len()));
            let normals = mesh
                .map(|m| pose.normals.unwrap_or(&m.normals))
                .filter(|n| n.len() == buf.world.len());
            let linear = pose.transform.matrix3;
            let normal_matrix = Some(linear.inverse().transpose())
                .filter(|m| linear.determinant() != 0.0 && m.is_finite());
            PosedInstance {
                indices: mesh.map_or(&[], |m| &m.indices),
                world: &buf.world,
                clip: &buf.clip,
                normals,
                normal_matrix,
                single_sided: !matches!(material, Some(m) if m.double_sided),
                cut,
            }
        })
        .collect()
}
