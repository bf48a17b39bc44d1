//! Linear blend skinning in the instance's mesh-local space.

use std::sync::Arc;

use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use rayon::prelude::*;

use crate::model::Mesh;

/// Vertices per parallel task.
const CHUNK: usize = 2048;

/// The bind-pose data of one skinned mesh, copied once (weights renormalised).
#[derive(Debug)]
pub(crate) struct BindMesh {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    joints: Vec<[u16; 4]>,
    weights: Vec<[f32; 4]>,
}

impl BindMesh {
    /// Copies `mesh`'s skinning inputs; weights are clamped to ≥ 0 and renormalised to sum
    /// to 1 (all-zero: the first slot gets 1). The mesh must have one joint/weight set per
    /// vertex and normals matching positions (or none: then skinned normals are +Y).
    pub(crate) fn new(mesh: &Mesh) -> Arc<Self> {
        let weights = mesh
            .weights
            .iter()
            .map(|w| {
                let w = w.map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 });
                let sum: f32 = w.iter().sum();
                if sum > 0.0 {
                    w.map(|x| x / sum)
                } else {
                    [1.0, 0.0, 0.0, 0.0]
                }
            })
            .collect();
        let normals = if mesh.normals.len() == mesh.positions.len() {
            mesh.normals.clone()
        } else {
            vec![Vec3::Y; mesh.positions.len()]
        };
        Arc::new(Self {
            positions: mesh.positions.clone(),
            normals,
            joints: mesh.joints.clone(),
            weights,
        })
    }

    /// Vertex count.
    pub(crate) fn len(&self) -> usize {
        self.positions.len()
    }

    /// Largest joint index used (`None` for a mesh without vertices).
    pub(crate) fn max_joint(&self) -> Option<u16> {
        self.joints.iter().flatten().copied().max()
    }

    /// Skins every vertex with the per-joint `matrices` (bind space → mesh-local space),
    /// writing `positions` and unit `normals` (resized to the vertex count).
    pub(crate) fn skin(
        &self,
        matrices: &[Affine3A],
        positions: &mut Vec<Vec3>,
        normals: &mut Vec<Vec3>,
    ) {
        // Normals transform by the inverse transpose of each joint's linear part.
        let normal_matrices: Vec<Mat3A> = matrices
            .iter()
            .map(|m| {
                let inv = m.matrix3.inverse();
                if inv.is_finite() {
                    inv.transpose()
                } else {
                    m.matrix3
                }
            })
            .collect();
        positions.resize(self.len(), Vec3::ZERO);
        normals.resize(self.len(), Vec3::ZERO);
        positions
            .par_chunks_mut(CHUNK)
            .zip(normals.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (pos, nrm))| {
                let base = c * CHUNK;
                for (i, (p_out, n_out)) in pos.iter_mut().zip(nrm.iter_mut()).enumerate() {
                    let v = base + i;
                    let p = Vec3A::from(self.positions[v]);
                    let n = Vec3A::from(self.normals[v]);
                    let mut sp = Vec3A::ZERO;
                    let mut sn = Vec3A::ZERO;
                    for (&j, &w) in self.joints[v].iter().zip(&self.weights[v]) {
                        if w > 0.0 {
                            sp += w * matrices[j as usize].transform_point3a(p);
                            sn += w * (normal_matrices[j as usize] * n);
                        }
                    }
                    *p_out = sp.into();
                    *n_out = sn.try_normalize().unwrap_or(n).into();
                }
            });
    }
}
