//! Binary visibility of a posed character over the whole sphere at every vertex, projected to
//! order-4 SH in the vertex's local frame (paper §3.2: not cosine-weighted).

use glam::{Mat3, Vec3};
use psao_scene::{Mesh, Scene};
use psao_trace::ao::{ray_offset, sample_2d};
use psao_trace::{Backend, GeometryMode, Ray, Tracer, DEFAULT_MAX_COST_RATIO};
use rayon::prelude::*;

use crate::character::CharacterPose;
use crate::sh::{self, ShVec, COEFFS};
use crate::PrtError;

/// Rays longer than any character (visibility is to infinity).
const RAY_LENGTH: f32 = 1.0e30;

/// Vertices per parallel task.
const CHUNK: usize = 64;

/// Ray queries against the character's own deforming mesh.
pub struct SelfTracer {
    tracer: Tracer,
}

impl SelfTracer {
    /// A tracer holding only `mesh` (its bind pose), in mesh-local space.
    pub fn new(mesh: &Mesh) -> Result<Self, PrtError> {
        let scene = Scene::of_meshes(vec![mesh.clone()]);
        Ok(Self {
            tracer: Tracer::new(Backend::default(), &scene, GeometryMode::Primary)?,
        })
    }

    /// Moves the mesh to the pose's skinned positions (refit, or rebuild once refits degraded).
    pub fn set_pose(&mut self, pose: &CharacterPose) -> Result<(), PrtError> {
        self.tracer
            .update_deforming_mesh(0, &pose.positions, DEFAULT_MAX_COST_RATIO)?;
        self.tracer.commit();
        Ok(())
    }

    /// Whether each ray hits the mesh.
    pub fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        self.tracer.occluded(rays, out);
    }
}

/// A uniform direction on the sphere from two numbers in [0, 1).
pub fn uniform_sphere(u1: f32, u2: f32) -> Vec3 {
    let z = 1.0 - 2.0 * u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Per vertex of `pose` (traced by `tracer`, already set to the pose): the SH projection of
/// binary visibility to infinity in the vertex's local frame, from `rays` stratified
/// uniform directions (R2 sequence, rotation hashed from `seed` and the vertex). Runs on
/// all rayon threads; the result depends only on the inputs and `seed`.
pub fn visibility_sh(
    tracer: &SelfTracer,
    pose: &CharacterPose,
    rays: u32,
    seed: u64,
) -> Vec<ShVec> {
    let n = pose.positions.len();
    let mut out = vec![[0.0f32; COEFFS]; n];
    let weight = 4.0 * std::f32::consts::PI / rays.max(1) as f32;
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| {
            let mut batch = Vec::with_capacity(rays as usize);
            let mut local = Vec::with_capacity(rays as usize);
            let mut hit = vec![false; rays as usize];
            for (k, slot) in chunk.iter_mut().enumerate() {
                let v = c * CHUNK + k;
                let frame: Mat3 = pose.frames[v];
                let origin = ray_offset(pose.positions[v], frame.z_axis);
                batch.clear();
                local.clear();
                for i in 0..rays {
                    let (u1, u2) = sample_2d(seed, v as u64, i);
                    let d = uniform_sphere(u1, u2);
                    local.push(d);
                    batch.push(Ray::new(origin, frame * d, RAY_LENGTH));
                }
                tracer.occluded(&batch, &mut hit);
                let mut acc = [0.0f32; COEFFS];
                for (d, h) in local.iter().zip(&hit) {
                    if !h {
                        for (a, y) in acc.iter_mut().zip(sh::eval(*d)) {
                            *a += y;
                        }
                    }
                }
                *slot = acc.map(|a| a * weight);
            }
        });
    out
}
