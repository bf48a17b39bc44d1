//! The signal of adaptive point placement (issue 15 item 4, `ServerConfig::adaptive_boost`):
//! near-field occlusion of a candidate point, measured with a few short rays.
//!
//! AO changes fastest where geometry is close: in grooves, at the foot of walls, between bars.
//! A candidate traces [`NEAR_FIELD_RAYS`] cosine-distributed rays of length
//! [`NEAR_FIELD_SPACINGS`] uniform point spacings; the fraction that hits something is its
//! signal. Open flat ground scores 0. A candidate whose every ray hits (it sits inside closed
//! geometry: a tile's underside, a slab under a tile, which the burial test drops later)
//! also scores 0, so buried surfaces do not take density from visible ones. Both lengths
//! follow the point spacing, nothing follows a scene.

use glam::Vec3;
use psao_trace::ao::{cosine_hemisphere, hash64, ray_offset, sample_2d};
use psao_trace::{sort_rays_spatially, Ray, Tracer};
use rayon::prelude::*;

/// Rays per candidate.
pub const NEAR_FIELD_RAYS: u32 = 8;
/// Length of the rays in uniform point spacings (`2·r_max`).
pub const NEAR_FIELD_SPACINGS: f32 = 2.0;
/// Candidates handled together per parallel work item.
const CHUNK: usize = 1024;
/// Decorrelates these rays from the AO and burial rays.
const NEAR_FIELD_SALT: u64 = 0x6e65_6172_6669_656c;

/// The near-field signal of every candidate `(world position, unit world normal)` of
/// instance `instance` at uniform spacing `spacing` (world units), in [0, 1]; seeded by
/// `seed`, independent of the thread count.
pub(crate) fn near_field_signal(
    tracer: &Tracer,
    seed: u64,
    instance: usize,
    probes: &[(Vec3, Vec3)],
    spacing: f32,
) -> Vec<f32> {
    let length = NEAR_FIELD_SPACINGS * spacing;
    if !(length.is_finite() && length > 0.0) {
        return vec![0.0; probes.len()];
    }
    let starts: Vec<Ray> = probes.iter().map(|&(x, n)| Ray::new(x, n, 1.0)).collect();
    let order = sort_rays_spatially(&starts);
    let seed = hash64(seed ^ NEAR_FIELD_SALT);
    let per = NEAR_FIELD_RAYS as usize;
    let scored: Vec<(u32, f32)> = order
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            let mut rays = Vec::with_capacity(chunk.len() * per);
            for &j in chunk {
                let (x, n) = probes[j as usize];
                let key = ((instance as u64) << 32) ^ u64::from(j);
                let origin = ray_offset(x, n);
                rays.extend((0..NEAR_FIELD_RAYS).map(|i| {
                    let (u1, u2) = sample_2d(seed, key, i);
                    Ray::new(origin, cosine_hemisphere(n, u1, u2), length)
                }));
            }
            let mut hit = vec![false; rays.len()];
            tracer.occluded(&rays, &mut hit);
            let hits: Vec<u32> = hit
                .chunks(per)
                .map(|h| h.iter().filter(|&&b| b).count() as u32)
                .collect();
            chunk
                .iter()
                .zip(hits)
                .map(|(&j, h)| {
                    let s = if h >= NEAR_FIELD_RAYS {
                        0.0
                    } else {
                        h as f32 / NEAR_FIELD_RAYS as f32
                    };
                    (j, s)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let mut out = vec![0.0; probes.len()];
    for (j, s) in scored {
        out[j as usize] = s;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_scene::builtin::shapes::cuboid;
    use psao_scene::Scene;
    use psao_trace::{Backend, GeometryMode};

    #[test]
    fn signal_is_zero_in_the_open_and_rises_next_to_a_wall() {
        // A 2 × 2 × 0.2 m box whose top is at y = 0.1 (cuboid is centred).
        let scene = Scene::of_meshes(vec![cuboid(Vec3::new(1.0, 0.1, 1.0))]);
        let tracer = Tracer::new(Backend::default(), &scene, GeometryMode::Occlusion).unwrap();
        let spacing = 0.034;
        let probes = [
            // On the top, far from any other geometry: open.
            (Vec3::new(0.0, 0.1, 0.0), Vec3::Y),
            // On the floor-level plane y = −0.1 just outside the box's side face, facing up:
            // half the hemisphere is the wall (the point sits at the wall's foot).
            (Vec3::new(1.0 + 0.2 * spacing, -0.1, 0.0), Vec3::Y),
            // Inside the box, facing up: every ray hits its top's back side.
            (Vec3::new(0.0, 0.0, 0.0), Vec3::Y),
        ];
        let s = near_field_signal(&tracer, 5, 0, &probes, spacing);
        assert_eq!(s[0], 0.0);
        assert!(s[1] > 0.0 && s[1] < 1.0, "{}", s[1]);
        assert_eq!(s[2], 0.0, "enclosed points score 0");
        assert_eq!(s, near_field_signal(&tracer, 5, 0, &probes, spacing));
        assert!(near_field_signal(&tracer, 5, 0, &probes, 0.0)
            .iter()
            .all(|&x| x == 0.0));
    }
}
