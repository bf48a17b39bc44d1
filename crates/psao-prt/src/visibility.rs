//! Binary visibility of a posed character over the whole sphere at every vertex, projected to
//! order-4 SH in the vertex's local frame (paper §3.2: not cosine-weighted).
//!
//! Only the hemisphere above the tangent plane is traced; the one below counts as visible.
//! No BRDF receives light from below its surface (the shading applies that horizon itself,
//! see [`crate::shade`]), so the values there are free, and 1 is the choice that order-4 SH
//! can represent: an unoccluded vertex then has the constant visibility 1 exactly, where the
//! truncated expansion of the hemisphere step (0 below) rings to 0.81 at the normal and
//! darkened every unoccluded vertex under a glossy lobe (by 10 % at Phong α = 16).

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

/// Ray queries against the character's own deforming mesh and the rigid meshes of its file.
pub struct SelfTracer {
    tracer: Tracer,
    positions: Vec<Vec3>,
}

impl SelfTracer {
    /// A tracer holding only `mesh` (e.g. [`crate::character::Character::occluder_mesh`]:
    /// the relit vertices first, then the rigid occluders').
    pub fn new(mesh: &Mesh) -> Result<Self, PrtError> {
        let scene = Scene::of_meshes(vec![mesh.clone()]);
        Ok(Self {
            tracer: Tracer::new(Backend::default(), &scene, GeometryMode::Primary)?,
            positions: Vec::new(),
        })
    }

    /// Moves the mesh to the pose's positions followed by its occluders' (refit, or
    /// rebuild once refits degraded).
    pub fn set_pose(&mut self, pose: &CharacterPose) -> Result<(), PrtError> {
        self.positions.clear();
        self.positions.extend_from_slice(&pose.positions);
        self.positions.extend_from_slice(&pose.occluders);
        self.tracer
            .update_deforming_mesh(0, &self.positions, DEFAULT_MAX_COST_RATIO)?;
        self.tracer.commit();
        Ok(())
    }

    /// Whether each ray hits the mesh.
    pub fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        self.tracer.occluded(rays, out);
    }
}

/// A uniform direction on the upper (z ≥ 0) hemisphere from two numbers in [0, 1).
pub fn uniform_hemisphere(u1: f32, u2: f32) -> Vec3 {
    let z = 1.0 - u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// The SH projection of the lower (z < 0) hemisphere's indicator: zonal, band l is
/// `(−1)^l` times the upper hemisphere's `√π, √(3π)/2, 0, −√(7π)/8`.
pub fn lower_hemisphere() -> ShVec {
    let pi = std::f32::consts::PI;
    let mut v = [0.0; COEFFS];
    v[0] = pi.sqrt();
    v[2] = -(3.0 * pi).sqrt() / 2.0;
    v[12] = (7.0 * pi).sqrt() / 8.0;
    v
}

/// Per vertex of `pose` (traced by `tracer`, already set to the pose): the SH projection of
/// binary visibility to infinity in the vertex's local frame, from `rays` stratified
/// uniform directions over the upper hemisphere (R2 sequence, rotation hashed from `seed`
/// and the vertex's key), the lower hemisphere counted as visible (see the module's doc). Runs
/// on all rayon threads; the result depends only on the inputs and `seed`.
pub fn visibility_sh(
    tracer: &SelfTracer,
    pose: &CharacterPose,
    rays: u32,
    seed: u64,
) -> Vec<ShVec> {
    let n = pose.positions.len();
    let mut out = vec![[0.0f32; COEFFS]; n];
    let weight = 2.0 * std::f32::consts::PI / rays.max(1) as f32;
    let below = lower_hemisphere();
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
                    let (u1, u2) = sample_2d(seed, pose.keys[v], i);
                    let d = uniform_hemisphere(u1, u2);
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
                *slot = std::array::from_fn(|i| acc[i] * weight + below[i]);
            }
        });
    out
}
