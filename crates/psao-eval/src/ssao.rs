//! The SSAO baseline: a standard hemisphere screen-space AO on the client's G-buffer.
//!
//! Per pixel, 16 kernel samples in the view-space hemisphere around the normal (cosine-weighted
//! directions, lengths growing quadratically towards the AO radius), rotated by a 4×4 tile of
//! random angles; a sample is occluded when the G-buffer depth at its projection lies in front of
//! it, weighted by a range check that fades occluders farther than the radius. The result is
//! blurred over the 4×4 noise tile. Values are in [0, 1] with 1 = unoccluded, as in DESIGN §2.

use crate::AoImage;
use glam::{Mat4, Vec3};
use psao_raster::GBuffer;
use psao_scene::Camera;
use rayon::prelude::*;

/// Side of the square noise tile (and of the blur that removes its pattern).
const NOISE_TILE: usize = 4;

/// Settings of the SSAO baseline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SsaoSettings {
    /// World-space sampling radius (the AO radius).
    pub radius: f32,
    /// Kernel samples per pixel.
    pub samples: u32,
    /// Depth bias as a fraction of the radius, against self-occlusion.
    pub bias: f32,
    /// Seed of the kernel and noise tile.
    pub seed: u64,
}

impl SsaoSettings {
    /// The standard configuration: 16 samples at the given radius.
    pub fn new(radius: f32) -> Self {
        Self {
            radius,
            samples: 16,
            bias: 0.025,
            seed: 1,
        }
    }
}

/// SSAO of `gbuffer` seen by `camera` (1 where nothing is covered).
pub fn ssao(gbuffer: &GBuffer, camera: &Camera, settings: &SsaoSettings) -> AoImage {
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    let view = camera.view();
    let proj = camera.projection(w as f32 / h.max(1) as f32);
    let kernel = kernel(settings.samples.max(1), settings.seed);
    let noise: Vec<f32> = (0..NOISE_TILE * NOISE_TILE)
        .map(|i| unit_hash(settings.seed ^ 0x5eed, i as u64) * std::f32::consts::TAU)
        .collect();
    let mut raw = vec![1.0f32; w * h];
    raw.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let i = y * w + x;
                if gbuffer.covered(i) {
                    let angle = noise[(y % NOISE_TILE) * NOISE_TILE + x % NOISE_TILE];
                    *out = pixel_ao(gbuffer, i, &view, &proj, &kernel, angle, settings);
                }
            }
        });
    AoImage {
        width: gbuffer.width,
        height: gbuffer.height,
        data: blur(gbuffer, &raw),
    }
}

/// Unblurred SSAO at pixel `i`.
fn pixel_ao(
    g: &GBuffer,
    i: usize,
    view: &Mat4,
    proj: &Mat4,
    kernel: &[Vec3],
    angle: f32,
    s: &SsaoSettings,
) -> f32 {
    let p = view.transform_point3(g.position[i]);
    let n = view.transform_vector3(g.normal[i]).normalize_or_zero();
    if n == Vec3::ZERO {
        return 1.0;
    }
    // Tangent frame around n, rotated by the pixel's noise angle.
    let helper = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let t0 = (helper - n * n.dot(helper)).normalize();
    let b0 = n.cross(t0);
    let (sin, cos) = angle.sin_cos();
    let t = t0 * cos + b0 * sin;
    let b = n.cross(t);
    let depth = -p.z;
    let bias = s.bias * s.radius;
    let (w, h) = (g.width as f32, g.height as f32);
    let mut occlusion = 0.0;
    for k in kernel {
        let q = p + (t * k.x + b * k.y + n * k.z) * s.radius;
        let clip = *proj * q.extend(1.0);
        if clip.w <= 1e-6 {
            continue;
        }
        let px = (clip.x / clip.w * 0.5 + 0.5) * w;
        let py = (0.5 - clip.y / clip.w * 0.5) * h;
        if !(0.0..w).contains(&px) || !(0.0..h).contains(&py) {
            continue;
        }
        let j = py as usize * g.width as usize + px as usize;
        let scene_depth = g.depth[j];
        if scene_depth < -q.z - bias {
            let range = (s.radius / (depth - scene_depth).abs().max(1e-6)).min(1.0);
            occlusion += range * range * (3.0 - 2.0 * range);
        }
    }
    1.0 - occlusion / kernel.len() as f32
}

/// Box blur over the noise tile, averaging only covered pixels.
fn blur(g: &GBuffer, raw: &[f32]) -> Vec<f32> {
    let (w, h) = (g.width as usize, g.height as usize);
    let half = NOISE_TILE as isize / 2;
    let mut out = vec![1.0f32; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                if !g.covered(y * w + x) {
                    continue;
                }
                let (mut sum, mut count) = (0.0, 0u32);
                for dy in -half..half {
                    for dx in -half..half {
                        let (sx, sy) = (x as isize + dx, y as isize + dy);
                        if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                            continue;
                        }
                        let j = sy as usize * w + sx as usize;
                        if g.covered(j) {
                            sum += raw[j];
                            count += 1;
                        }
                    }
                }
                *o = if count > 0 {
                    sum / count as f32
                } else {
                    raw[y * w + x]
                };
            }
        });
    out
}

/// Kernel offsets in the unit hemisphere (z up): cosine-weighted directions, lengths growing
/// quadratically from 0.1 to 1 so that more samples fall near the pixel.
fn kernel(samples: u32, seed: u64) -> Vec<Vec3> {
    (0..samples)
        .map(|i| {
            let u1 = unit_hash(seed, 2 * i as u64);
            let u2 = unit_hash(seed, 2 * i as u64 + 1);
            let r = u1.sqrt();
            let phi = std::f32::consts::TAU * u2;
            let dir = Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
            let f = (i as f32 + 0.5) / samples as f32;
            dir * (0.1 + 0.9 * f * f)
        })
        .collect()
}

/// A uniform value in [0, 1) from (seed, index): a SplitMix64 finaliser, so that the kernel and
/// noise tile are fixed by the seed without carrying a generator around.
fn unit_hash(seed: u64, index: u64) -> f32 {
    let mut z = seed
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(index.wrapping_add(1).wrapping_mul(0xbf58_476d_1ce4_e5b9));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;
    use psao_raster::{rasterize, RasterOptions};
    use psao_scene::{Mesh, Scene};

    /// A floor with a wall standing on it along z = 0.
    fn corner_scene() -> Scene {
        let quad = |p: [Vec3; 4], n: Vec3| Mesh {
            name: "quad".into(),
            positions: p.to_vec(),
            normals: vec![n; 4],
            uvs: vec![Vec2::ZERO; 4],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        let floor = quad(
            [
                Vec3::new(-5.0, 0.0, -5.0),
                Vec3::new(-5.0, 0.0, 5.0),
                Vec3::new(5.0, 0.0, 5.0),
                Vec3::new(5.0, 0.0, -5.0),
            ],
            Vec3::Y,
        );
        let wall = quad(
            [
                Vec3::new(-5.0, 0.0, 0.0),
                Vec3::new(5.0, 0.0, 0.0),
                Vec3::new(5.0, 3.0, 0.0),
                Vec3::new(-5.0, 3.0, 0.0),
            ],
            Vec3::Z,
        );
        Scene::of_meshes(vec![floor, wall])
    }

    #[test]
    fn corner_is_darker_than_open_floor_and_values_stay_in_range() {
        let scene = corner_scene();
        let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.0), Vec3::new(0.0, 0.0, 0.0), 60.0);
        let g = rasterize(&scene, &camera, &RasterOptions::new(160, 90));
        let ao = ssao(&g, &camera, &SsaoSettings::new(0.6));
        assert!(ao.data.iter().all(|v| (0.0..=1.0).contains(v)));
        // Mean AO of floor pixels near the wall vs. far from it.
        let (mut near, mut far) = ((0.0, 0), (0.0, 0));
        for i in 0..g.len() {
            if g.covered(i) && g.instance[i] == 0 {
                let z = g.position[i].z;
                if z > 0.02 && z < 0.15 {
                    near = (near.0 + ao.data[i], near.1 + 1);
                } else if z > 1.5 {
                    far = (far.0 + ao.data[i], far.1 + 1);
                }
            }
        }
        assert!(near.1 > 10 && far.1 > 10, "{near:?} {far:?}");
        let (near, far) = (near.0 / near.1 as f32, far.0 / far.1 as f32);
        assert!(near + 0.1 < far, "corner {near} vs open floor {far}");
        assert!(far > 0.9, "open floor should be nearly unoccluded: {far}");
    }

    #[test]
    fn deterministic_per_seed() {
        let scene = corner_scene();
        let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.0), Vec3::ZERO, 60.0);
        let g = rasterize(&scene, &camera, &RasterOptions::new(64, 36));
        let a = ssao(&g, &camera, &SsaoSettings::new(0.6));
        let b = ssao(&g, &camera, &SsaoSettings::new(0.6));
        assert_eq!(a, b);
    }
}
