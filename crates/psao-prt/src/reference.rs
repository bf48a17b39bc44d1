//! Monte Carlo reference of the shading integral at the true pose: traced binary visibility
//! × the full-resolution environment radiance × the BRDF, importance-sampled by the BRDF
//! lobe so that each sample's weight is exactly 1.

use glam::{Mat3, Vec3};
use psao_trace::ao::{cosine_hemisphere, orthonormal_basis, ray_offset, sample_2d};
use psao_trace::Ray;
use rayon::prelude::*;

use crate::character::CharacterPose;
use crate::lighting::EnvMap;
use crate::shade::{orthonormalised, Mode};
use crate::visibility::SelfTracer;

/// Rays longer than any character.
const RAY_LENGTH: f32 = 1.0e30;

/// A direction from the normalised Phong lobe `(α+1)/(2π) cos^α` about `axis`.
fn phong_sample(axis: Vec3, alpha: f32, u1: f32, u2: f32) -> Vec3 {
    let cos = (1.0 - u1).powf(1.0 / (alpha + 1.0));
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (t, b) = orthonormal_basis(axis);
    let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
    (t * (sin * c) + b * (sin * s) + axis * cos).normalize_or(axis)
}

/// How a reference is rendered.
#[derive(Clone, Copy, Debug)]
pub struct ReferenceSettings {
    /// The reflection model.
    pub mode: Mode,
    /// Camera position (world), for Phong's reflection vector.
    pub eye: Vec3,
    /// Turn of the environment about +Y, radians.
    pub env_rotation: f32,
    /// Samples per vertex.
    pub samples: u32,
    /// Seed of the sample sequence.
    pub seed: u64,
}

/// Per vertex of `pose` (set on `tracer`), the reference shade of every colour channel
/// under `env`. Deterministic per seed.
pub fn reference_shading(
    tracer: &SelfTracer,
    pose: &CharacterPose,
    env: &EnvMap,
    settings: &ReferenceSettings,
) -> Vec<[f32; 3]> {
    let ReferenceSettings {
        mode,
        eye,
        env_rotation,
        samples,
        seed,
    } = *settings;
    let linear = orthonormalised(Mat3::from(pose.transform.matrix3));
    let to_env = Mat3::from_rotation_y(-env_rotation) * linear;
    (0..pose.positions.len())
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(rays, dirs, hits): &mut (Vec<Ray>, Vec<Vec3>, Vec<bool>), v| {
                let n = pose.frames[v].z_axis;
                let p = pose.positions[v];
                let origin = ray_offset(p, n);
                // The lobe axis in mesh space and whether samples are traced.
                let (axis, alpha) = match mode {
                    Mode::Phong { alpha } => {
                        let pw = pose.transform.transform_point3(p);
                        let nw = linear * n;
                        let wo = (eye - pw).normalize_or(nw);
                        let r = 2.0 * nw.dot(wo) * nw - wo;
                        (linear.transpose() * r, Some(alpha))
                    }
                    _ => (n, None),
                };
                rays.clear();
                dirs.clear();
                for i in 0..samples {
                    let (u1, u2) = sample_2d(seed, v as u64, i);
                    let d = match alpha {
                        Some(a) => phong_sample(axis, a, u1, u2),
                        None => cosine_hemisphere(axis, u1, u2),
                    };
                    dirs.push(d);
                    rays.push(Ray::new(origin, d, RAY_LENGTH));
                }
                hits.resize(rays.len(), false);
                tracer.occluded(rays, hits);
                let mut front = [0.0f32; 3];
                for (d, h) in dirs.iter().zip(hits.iter()) {
                    if !h {
                        let l = env.radiance(to_env * *d);
                        for c in 0..3 {
                            front[c] += l[c];
                        }
                    }
                }
                let k = 1.0 / samples.max(1) as f32;
                let front = front.map(|x| x * k);
                match mode {
                    Mode::Translucent { transmission } => {
                        let mut back = [0.0f32; 3];
                        for i in 0..samples {
                            let (u1, u2) = sample_2d(seed ^ 0x6261_636b, v as u64, i);
                            let l = env.radiance(to_env * cosine_hemisphere(-n, u1, u2));
                            for c in 0..3 {
                                back[c] += l[c];
                            }
                        }
                        std::array::from_fn(|c| {
                            (1.0 - transmission) * front[c] + transmission * back[c] * k
                        })
                    }
                    _ => front,
                }
            },
        )
        .collect()
}
