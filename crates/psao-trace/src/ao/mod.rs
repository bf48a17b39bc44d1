//! Ambient occlusion as defined once for all of psao (DESIGN §2): at a point x with normal n,
//! trace N cosine-weighted hemisphere rays of length R from x offset along n;
//! AO(x) = mean(min(hit distance, R) / R), a miss counting 1. With a participating
//! [`Medium`] the hit distance of each ray is weighted by the medium's transmittance (see
//! [`sample_value`] and the `medium` module).

mod medium;
mod sampling;

use glam::Vec3;
use rayon::prelude::*;

pub use medium::{Medium, MediumSampler};
use sampling::azimuths;
pub use sampling::{
    cosine_hemisphere, hash64, medium_stream, orthonormal_basis, ray_offset, sample_2d, Hemisphere,
    Sequence2d,
};

use crate::{sort_rays_spatially, Hit, Ray, Tracer};

/// Samples of one point generated together by [`ao_rays_range`].
const SAMPLE_GROUP: usize = 16;

/// Rays traced together per parallel work item in [`ambient_occlusion_batch`].
const RAYS_PER_CHUNK: usize = 4096;

/// Appends the `spp` AO rays of point `x` with unit normal `n` (samples 0..spp) to `out`.
pub fn ao_rays(x: Vec3, n: Vec3, radius: f32, spp: u32, seed: u64, key: u64, out: &mut Vec<Ray>) {
    ao_rays_range(x, n, radius, 0, spp, seed, key, out);
}

/// Appends AO rays for sample indices `first..first + count` of point `x` (key `key`), so a
/// point can accumulate samples over several frames without repeating any.
#[allow(clippy::too_many_arguments)]
pub fn ao_rays_range(
    x: Vec3,
    n: Vec3,
    radius: f32,
    first: u32,
    count: u32,
    seed: u64,
    key: u64,
    out: &mut Vec<Ray>,
) {
    let origin = ray_offset(x, n);
    // The point's sequence and frame once, then only per-sample work, in groups of lanes
    // (vectorised).
    let (sequence, hemisphere) = (Sequence2d::new(seed, key), Hemisphere::new(n));
    out.reserve(count as usize);
    let [mut u1, mut u2, mut sin, mut cos] = [[0.0; SAMPLE_GROUP]; 4];
    let mut dirs = [Vec3::ZERO; SAMPLE_GROUP];
    for start in (0..count).step_by(SAMPLE_GROUP) {
        let len = (count - start).min(SAMPLE_GROUP as u32) as usize;
        for k in 0..len {
            (u1[k], u2[k]) = sequence.at(first.wrapping_add(start + k as u32));
        }
        azimuths(&u2, &mut sin, &mut cos);
        hemisphere.cosine_lanes(&u1, &sin, &cos, &mut dirs);
        out.extend(dirs[..len].iter().map(|&d| Ray::new(origin, d, radius)));
    }
}

/// The value of one AO sample: D / R, where L = min(t, R) is the distance to the closest
/// surface hit (R on a miss) and D = ∫₀ᴸ T(s) ds the transmittance-weighted distance along
/// the ray through `medium` (D = L without a medium). `stream` seeds the medium's random
/// choices (use [`medium_stream`] of the sample's seed, key and index). This is the one AO
/// estimator of psao: the server's points, the reference and the baselines all use it.
pub fn sample_value(
    ray: &Ray,
    hit: Option<&Hit>,
    radius: f32,
    medium: Option<&mut (dyn MediumSampler + '_)>,
    stream: u64,
) -> f32 {
    let length = surface_length(hit, radius);
    match medium {
        Some(m) => m.transmitted_length(ray.origin, ray.dir, length, stream) / radius,
        None => length / radius,
    }
}

/// min(t, R) for a hit at t, R for a miss.
fn surface_length(hit: Option<&Hit>, radius: f32) -> f32 {
    hit.map_or(radius, |h| h.t.min(radius))
}

/// AO from the closest hits of one point's rays: the mean of min(t, R)/R with a miss counting
/// 1. Returns 1 (unoccluded) for no rays or a non-positive radius.
pub fn ao_value(hits: &[Option<Hit>], radius: f32) -> f32 {
    if hits.is_empty() || radius.is_nan() || radius <= 0.0 {
        return 1.0;
    }
    let sum: f32 = hits
        .iter()
        .map(|h| surface_length(h.as_ref(), radius) / radius)
        .sum();
    sum / hits.len() as f32
}

/// AO of one point (see the module docs); `key` identifies the point for sampling.
pub fn ambient_occlusion(
    tracer: &Tracer,
    x: Vec3,
    n: Vec3,
    radius: f32,
    spp: u32,
    seed: u64,
    key: u64,
) -> f32 {
    let mut rays = Vec::with_capacity(spp as usize);
    ao_rays(x, n, radius, spp, seed, key, &mut rays);
    let mut hits = vec![None; rays.len()];
    tracer.intersect(&rays, &mut hits);
    ao_value(&hits, radius)
}

/// AO of many `(position, unit normal)` points, point i sampled with key `keys(i)`. Runs in
/// parallel on the rayon pool over chunks of points whose rays are sorted spatially and traced
/// as one batch. Each value depends only on its own rays, so the result equals
/// [`ambient_occlusion`] per point and does not depend on the number of threads.
pub fn ambient_occlusion_batch(
    tracer: &Tracer,
    points: &[(Vec3, Vec3)],
    radius: f32,
    spp: u32,
    seed: u64,
    keys: impl Fn(usize) -> u64 + Sync,
) -> Vec<f32> {
    ambient_occlusion_batch_in(tracer, None, points, radius, spp, seed, keys)
}

/// [`ambient_occlusion_batch`] with the rays passing through `medium` (one medium sampler
/// per parallel work item). Deterministic: the medium's random numbers of sample i of point
/// k come from [`medium_stream`]`(seed, key(k), i)`.
pub fn ambient_occlusion_batch_in(
    tracer: &Tracer,
    medium: Option<&dyn Medium>,
    points: &[(Vec3, Vec3)],
    radius: f32,
    spp: u32,
    seed: u64,
    keys: impl Fn(usize) -> u64 + Sync,
) -> Vec<f32> {
    let mut result = vec![1.0; points.len()];
    if spp == 0 {
        return result;
    }
    let points_per_chunk = (RAYS_PER_CHUNK / spp as usize).max(1);
    let spp_len = spp as usize;
    result
        .par_chunks_mut(points_per_chunk)
        .zip(points.par_chunks(points_per_chunk))
        .enumerate()
        .for_each_init(
            || medium.map(|m| m.sampler()),
            |sampler, (chunk, (out, pts))| {
                let base = chunk * points_per_chunk;
                let mut rays = Vec::with_capacity(pts.len() * spp_len);
                for (i, &(x, n)) in pts.iter().enumerate() {
                    ao_rays(x, n, radius, spp, seed, keys(base + i), &mut rays);
                }
                let order = sort_rays_spatially(&rays);
                let sorted: Vec<Ray> = order.iter().map(|&i| rays[i as usize]).collect();
                let mut sorted_hits = vec![None; sorted.len()];
                tracer.intersect(&sorted, &mut sorted_hits);
                let mut hits = vec![None; rays.len()];
                for (&i, h) in order.iter().zip(sorted_hits) {
                    hits[i as usize] = h;
                }
                let valid = radius.is_finite() && radius > 0.0;
                for (i, (o, point_hits)) in out.iter_mut().zip(hits.chunks(spp_len)).enumerate() {
                    if !valid {
                        continue;
                    }
                    let key = keys(base + i);
                    let point_rays = &rays[i * spp_len..(i + 1) * spp_len];
                    let sum: f32 = point_rays
                        .iter()
                        .zip(point_hits)
                        .enumerate()
                        .map(|(s, (ray, hit))| {
                            let stream = medium_stream(seed, key, s as u32);
                            sample_value(ray, hit.as_ref(), radius, sampler.as_deref_mut(), stream)
                        })
                        .sum();
                    *o = sum / spp as f32;
                }
            },
        );
    result
}
