//! Ambient occlusion as defined once for all of psao (DESIGN §2): at a point x with normal n,
//! trace N cosine-weighted hemisphere rays of length R from x offset along n;
//! AO(x) = mean(min(hit distance, R) / R), a miss counting 1.

mod sampling;

use glam::Vec3;
use rayon::prelude::*;

pub use sampling::{cosine_hemisphere, hash64, orthonormal_basis, ray_offset, sample_2d};

use crate::{sort_rays_spatially, Hit, Ray, Tracer};

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
    out.extend((0..count).map(|i| {
        let (u1, u2) = sample_2d(seed, key, first.wrapping_add(i));
        Ray::new(origin, cosine_hemisphere(n, u1, u2), radius)
    }));
}

/// AO from the closest hits of one point's rays: the mean of min(t, R)/R with a miss counting
/// 1. Returns 1 (unoccluded) for no rays or a non-positive radius.
pub fn ao_value(hits: &[Option<Hit>], radius: f32) -> f32 {
    if hits.is_empty() || radius.is_nan() || radius <= 0.0 {
        return 1.0;
    }
    let sum: f32 = hits
        .iter()
        .map(|h| h.map_or(1.0, |h| (h.t / radius).min(1.0)))
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
        .for_each(|(chunk, (out, pts))| {
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
            for (o, point_hits) in out.iter_mut().zip(hits.chunks(spp_len)) {
                *o = ao_value(point_hits, radius);
            }
        });
    result
}
