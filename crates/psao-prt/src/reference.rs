//! Monte Carlo reference of the shading integral at the true pose: traced binary visibility
//! × the full-resolution environment radiance × the BRDF (zero below the vertex's tangent
//! plane), importance-sampled by the BRDF lobe so that each sample's weight is exactly 1.

use glam::{Mat3, Vec3};
use psao_trace::ao::{cosine_hemisphere, orthonormal_basis, ray_offset, sample_2d};
use psao_trace::Ray;
use rayon::prelude::*;

use crate::character::CharacterPose;
use crate::lighting::Radiance;
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
/// under `env` (the full-resolution map, or the SH lighting to isolate visibility errors).
/// Deterministic per seed.
pub fn reference_shading<R: Radiance + ?Sized>(
    tracer: &SelfTracer,
    pose: &CharacterPose,
    env: &R,
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
                    let (u1, u2) = sample_2d(seed, pose.keys[v], i);
                    let d = match alpha {
                        Some(a) => phong_sample(axis, a, u1, u2),
                        None => cosine_hemisphere(axis, u1, u2),
                    };
                    // The BRDF is zero below the surface: such samples bring nothing.
                    if d.dot(n) <= 0.0 {
                        continue;
                    }
                    dirs.push(d);
                    rays.push(Ray::new(origin, d, RAY_LENGTH));
                }
                hits.resize(rays.len(), false);
                tracer.occluded(rays, hits);
                let mut front = [0.0f32; 3];
                for (d, h) in dirs.iter().zip(hits.iter()) {
                    if !h {
                        let l = env.radiance_from(to_env * *d);
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
                            let (u1, u2) = sample_2d(seed ^ 0x6261_636b, pose.keys[v], i);
                            let l = env.radiance_from(to_env * cosine_hemisphere(-n, u1, u2));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::ShLighting;
    use crate::shade::{unit_visibility, Shader, ShadingGeometry, Visibility};
    use glam::Affine3A;
    use psao_scene::Mesh;

    /// A flat square of side 20 in z = 0, facing +z, with a vertex at its centre.
    fn plane() -> (Mesh, CharacterPose) {
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(-10.0, -10.0, 0.0),
            Vec3::new(10.0, -10.0, 0.0),
            Vec3::new(10.0, 10.0, 0.0),
            Vec3::new(-10.0, 10.0, 0.0),
        ];
        let normals = vec![Vec3::Z; 5];
        let mesh = Mesh {
            positions,
            normals,
            indices: vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]],
            ..Mesh::default()
        };
        let pose = CharacterPose::of_mesh(&mesh, vec![Mat3::IDENTITY; 5], Affine3A::IDENTITY);
        (mesh, pose)
    }

    /// Reference and run time compute the same integral: at the centre of a plane, whose
    /// upper hemisphere is open and lower one blocked, under smooth lighting (the SH lighting
    /// itself, so nothing is lost to band-limiting), every mode's unshadowed run-time shade
    /// equals the Monte Carlo reference. The views keep each lobe above the plane (Phong
    /// α = 64 about a reflection vector 40° off the normal: the lobe's part beyond the horizon,
    /// 50° from its axis, carries cos(50°)^65 ≈ 3e-13 of it), so visibility is 1 wherever the
    /// BRDF is non-zero. 8192 samples of radiance within 1 ± 0.6 leave a standard error below
    /// 0.007; the tolerance is 0.03.
    #[test]
    fn reference_and_run_time_integrate_the_same_shading() {
        let (mesh, pose) = plane();
        let mut tracer = SelfTracer::new(&mesh).unwrap();
        tracer.set_pose(&pose).unwrap();
        let mut light = unit_visibility();
        light[1] = 0.3;
        light[2] = 0.4;
        light[3] = -0.3;
        light[6] = 0.25;
        light[8] = 0.2;
        let lighting = ShLighting { rgb: [light; 3] };
        let angle = 40f32.to_radians();
        let oblique = Vec3::new(angle.sin(), 0.0, angle.cos()) * 10.0;
        for (mode, eye) in [
            (Mode::Diffuse, Vec3::Z * 10.0),
            (Mode::Phong { alpha: 64.0 }, Vec3::Z * 10.0),
            (Mode::Phong { alpha: 64.0 }, oblique),
            (Mode::Phong { alpha: 1.0 }, Vec3::Z * 10.0),
            (Mode::Translucent { transmission: 0.4 }, oblique),
        ] {
            let reference = reference_shading(
                &tracer,
                &pose,
                &lighting,
                &ReferenceSettings {
                    mode,
                    eye,
                    env_rotation: 0.0,
                    samples: 8192,
                    seed: 3,
                },
            )[0][0];
            let run_time = Shader::new(mode)
                .unwrap()
                .shade(
                    Visibility::Unshadowed,
                    ShadingGeometry {
                        positions: &pose.positions,
                        frames: &pose.frames,
                        transform: pose.transform,
                    },
                    &[light],
                    eye,
                )
                .unwrap()[0];
            assert!(
                (reference - run_time).abs() < 0.03,
                "{mode:?}, eye {eye}: reference {reference}, run time {run_time}"
            );
        }
    }

    /// A glossy lobe that crosses the horizon (reflection vector 70° off the normal, α = 8:
    /// about 20 % of the lobe is below the plane) under constant radiance 1: the reference
    /// drops the samples below the surface and the run time scales by the horizon table, so
    /// both give the share of the lobe above the plane. The plane's visibility, traced with
    /// the lower hemisphere counted as visible, is the constant 1 (up to sampling), so
    /// "projected" shading equals unshadowed shading at this unoccluded vertex.
    #[test]
    fn the_horizon_is_applied_once_by_reference_and_run_time() {
        let (mesh, pose) = plane();
        let mut tracer = SelfTracer::new(&mesh).unwrap();
        tracer.set_pose(&pose).unwrap();
        let sky = unit_visibility();
        let angle = 70f32.to_radians();
        let eye = Vec3::new(angle.sin(), 0.0, angle.cos()) * 10.0;
        let mode = Mode::Phong { alpha: 8.0 };
        let reference = reference_shading(
            &tracer,
            &pose,
            &ShLighting { rgb: [sky; 3] },
            &ReferenceSettings {
                mode,
                eye,
                env_rotation: 0.0,
                samples: 8192,
                seed: 4,
            },
        )[0][0];
        let visibility = crate::visibility::visibility_sh(&tracer, &pose, 4096, 2);
        for (c, u) in visibility[0].iter().zip(&sky) {
            assert!((c - u).abs() < 0.02, "{:?}", visibility[0]);
        }
        let geometry = ShadingGeometry {
            positions: &pose.positions,
            frames: &pose.frames,
            transform: pose.transform,
        };
        let shader = Shader::new(mode).unwrap();
        let unshadowed = shader
            .shade(Visibility::Unshadowed, geometry, &[sky], eye)
            .unwrap()[0];
        let projected = shader
            .shade(Visibility::Projected(&visibility), geometry, &[sky], eye)
            .unwrap()[0];
        assert!(
            (0.6..0.95).contains(&reference),
            "share above the plane {reference}"
        );
        assert!(
            (reference - unshadowed).abs() < 0.02,
            "reference {reference}, run time {unshadowed}"
        );
        assert!(
            (projected - unshadowed).abs() < 0.03,
            "projected {projected}, unshadowed {unshadowed}"
        );
    }
}
