//! Culling, budgeted selection and tracing of AO samples (DESIGN §3 "CPU server").

use glam::Vec3;
use psao_trace::ao::{ao_rays_range, hash64, medium_stream, sample_value, Medium, MediumSampler};
use psao_trace::{sort_rays_spatially, Hit, Ray, Tracer};
use rayon::prelude::*;

use crate::frustum::Frustum;
use crate::instance::{InstanceState, NONE};

/// Points culled per parallel work item.
const CULL_CHUNK: usize = 8192;
/// Rays traced together per parallel work item. The batch's points are neighbours (the
/// selection is put in Morton order first) and each point's rays stay together, so a
/// 16-ray packet shares its origin: measured faster than re-sorting the rays of a batch
/// by origin and octant (Embree: −25 % CPU time per step; obvhs: about equal).
const BATCH_RAYS: usize = 8192;

/// A visible point that still needs samples.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    /// Priority, smallest first: sample count (high half), then a seeded hash of the point
    /// (low half) so equal counts are spread over the scene instead of taken in index order.
    pub key: u64,
    pub instance: u32,
    pub index: u32,
}

impl Candidate {
    /// A total order (keys can tie; ids cannot).
    fn order(&self) -> (u64, u32, u32) {
        (self.key, self.instance, self.index)
    }
}

/// Samples traced for one point in one frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Traced {
    pub instance: u32,
    pub index: u32,
    /// Sum of the new samples' values ([`psao_trace::ao::sample_value`]).
    pub sum: f32,
    /// Number of new samples.
    pub rays: u32,
}

/// The key that identifies a point's AO sample sequence.
pub(crate) fn sample_key(instance: u32, index: u32) -> u64 {
    (u64::from(instance) << 32) | u64::from(index)
}

/// Count the stored points inside any frustum (grown by each instance's reconstruction
/// reach) and list those with fewer than `max_samples` samples. Deterministic order.
pub(crate) fn cull(
    instances: &[InstanceState],
    frusta: &[Frustum],
    max_samples: u32,
    seed: u64,
) -> (usize, Vec<Candidate>) {
    let parts: Vec<(usize, Vec<Candidate>)> = instances
        .par_iter()
        .enumerate()
        .flat_map(|(ii, inst)| {
            let near: Vec<&Frustum> = frusta
                .iter()
                .filter(|f| f.may_intersect(inst.world_bounds, inst.slack))
                .collect();
            let n = if near.is_empty() {
                0
            } else {
                inst.points.position.len()
            };
            let starts: Vec<usize> = (0..n).step_by(CULL_CHUNK).collect();
            starts.into_par_iter().map(move |start| {
                let p = &inst.points;
                let mut visible = 0;
                let mut out = Vec::new();
                for i in start..(start + CULL_CHUNK).min(n) {
                    if p.slot[i] == NONE {
                        continue;
                    }
                    let w = inst.transform.transform_point3(p.position[i]);
                    if !near.iter().any(|f| f.contains(w, inst.slack)) {
                        continue;
                    }
                    visible += 1;
                    if p.count[i] < max_samples {
                        let key = sample_key(ii as u32, i as u32);
                        let tie = hash64(key ^ seed.rotate_left(29)) as u32;
                        out.push(Candidate {
                            key: (u64::from(p.count[i]) << 32) | u64::from(tie),
                            instance: ii as u32,
                            index: i as u32,
                        });
                    }
                }
                (visible, out)
            })
        })
        .collect();
    let visible = parts.iter().map(|p| p.0).sum();
    (visible, parts.into_iter().flat_map(|p| p.1).collect())
}

/// Keep the `max_points` candidates that need samples most (fewest samples first), in
/// (instance, index) order.
pub(crate) fn select(mut candidates: Vec<Candidate>, max_points: usize) -> Vec<Candidate> {
    if candidates.len() > max_points {
        if max_points == 0 {
            return Vec::new();
        }
        candidates.select_nth_unstable_by_key(max_points - 1, Candidate::order);
        candidates.truncate(max_points);
    }
    candidates.par_sort_unstable_by_key(|c| (c.instance, c.index));
    candidates
}

/// One point's share of a batch.
struct Job {
    instance: u32,
    index: u32,
    origin: Vec3,
    normal: Vec3,
    first: u32,
    rays: u32,
}

/// Trace up to `rays_per_point` new samples (never beyond `max_samples`) for each selected
/// point, in spatially coherent batches (points in Morton order of position and normal
/// octant) on the rayon pool, through `medium` if any (one medium sampler per work item).
/// Results are in the order of `selected` and do not depend on the number of threads.
#[allow(clippy::too_many_arguments)]
pub(crate) fn trace(
    tracer: &Tracer,
    medium: Option<&dyn Medium>,
    instances: &[InstanceState],
    selected: &[Candidate],
    radius: f32,
    rays_per_point: u32,
    max_samples: u32,
    seed: u64,
) -> Vec<Traced> {
    let jobs: Vec<Job> = selected
        .par_iter()
        .map(|c| {
            let inst = &instances[c.instance as usize];
            let (origin, normal) = inst.world(c.index as usize);
            let count = inst.points.count[c.index as usize];
            Job {
                instance: c.instance,
                index: c.index,
                origin,
                normal,
                first: count,
                rays: rays_per_point.min(max_samples.saturating_sub(count)),
            }
        })
        .collect();
    // Group nearby points (and similar normals) into the same batches.
    let probes: Vec<Ray> = jobs
        .iter()
        .map(|j| Ray::new(j.origin, j.normal, 1.0))
        .collect();
    let order = sort_rays_spatially(&probes);
    let per_batch = (BATCH_RAYS / rays_per_point.max(1) as usize).max(1);
    let mut traced: Vec<(u32, Traced)> = order
        .par_chunks(per_batch)
        .map_init(
            || medium.map(|m| m.sampler()),
            |sampler, batch| {
                trace_batch(tracer, sampler.as_deref_mut(), &jobs, batch, radius, seed)
            },
        )
        .flatten_iter()
        .collect();
    traced.sort_unstable_by_key(|t| t.0);
    traced.into_iter().map(|t| t.1).collect()
}

/// Trace the jobs `batch` (indices into `jobs`); returns (job index, result) pairs.
fn trace_batch(
    tracer: &Tracer,
    mut medium: Option<&mut (dyn MediumSampler + '_)>,
    jobs: &[Job],
    batch: &[u32],
    radius: f32,
    seed: u64,
) -> Vec<(u32, Traced)> {
    let mut rays = Vec::new();
    for &j in batch {
        let job = &jobs[j as usize];
        let key = sample_key(job.instance, job.index);
        ao_rays_range(
            job.origin, job.normal, radius, job.first, job.rays, seed, key, &mut rays,
        );
    }
    let mut hits: Vec<Option<Hit>> = vec![None; rays.len()];
    tracer.intersect(&rays, &mut hits);
    let mut at = 0;
    batch
        .iter()
        .map(|&j| {
            let job = &jobs[j as usize];
            let n = job.rays as usize;
            let key = sample_key(job.instance, job.index);
            let sum = rays[at..at + n]
                .iter()
                .zip(&hits[at..at + n])
                .zip(job.first..)
                .map(|((ray, hit), i)| {
                    let stream = medium_stream(seed, key, i);
                    sample_value(ray, hit.as_ref(), radius, medium.as_deref_mut(), stream)
                })
                .sum();
            at += n;
            let result = Traced {
                instance: job.instance,
                index: job.index,
                sum,
                rays: job.rays,
            };
            (j, result)
        })
        .collect()
}
