//! Culling, budgeted selection and tracing of AO samples (DESIGN §3 "CPU server").

use glam::Vec3;
use psao_trace::ao::{ao_rays_range, medium_stream, sample_value, Medium, MediumSampler};
use psao_trace::{sort_rays_spatially, Hit, Ray, Tracer};
use rayon::prelude::*;

use crate::blocks::Side;
use crate::frustum::Frustum;
use crate::instance::{InstanceState, Points, NONE};

/// Rays traced together per parallel work item. The batch's points are neighbours (the
/// selection is put in Morton order first) and each point's rays stay together, so a
/// 16-ray packet shares its origin: measured faster than re-sorting the rays of a batch
/// by origin and octant (Embree: −25 % CPU time per step; obvhs: about equal).
const BATCH_RAYS: usize = 8192;

/// A visible point that still needs samples.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    /// Priority, smallest first: sample count (high half), then the point's seeded
    /// tie-break ([`crate::blocks::tie_of`], low half).
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

/// Sample-count levels of the selection histogram (counts from here on share a level).
const COUNT_LEVELS: usize = 64;
/// Tie-break levels per count level (the tie's top bits).
const TIE_LEVELS: usize = 256;

/// The selection histogram bin of a point: monotone in its [`Candidate::key`] (counts
/// below the last level split by the tie's top bits, the rest share the last bin).
#[inline]
fn bin(count: u32, tie: u32) -> usize {
    let level = count as usize;
    if level >= COUNT_LEVELS - 1 {
        COUNT_LEVELS * TIE_LEVELS - 1
    } else {
        level * TIE_LEVELS + (tie >> 24) as usize
    }
}

/// The visible points found by the first culling pass.
#[derive(Default)]
struct Visible {
    /// Stored points inside some frustum.
    count: usize,
    /// Histogram of [`bin`] over the visible points that need samples.
    hist: Vec<u32>,
    /// (instance, block) of blocks entirely inside some frustum.
    blocks: Vec<(u32, u32)>,
    /// (instance, position in the instance's block order) of visible points of the other
    /// blocks.
    points: Vec<(u32, u32)>,
    /// The candidates in bins up to the guessed cut.
    guessed: Vec<Candidate>,
}

impl Visible {
    /// Count visible point `index` of `instance` and, when it needs samples, its bin; keep
    /// it as a candidate when its bin is at most `guess`.
    #[inline]
    fn note(&mut self, instance: u32, index: u32, count: u32, tie: u32, limits: &Limits) {
        self.count += 1;
        if count < limits.max_samples {
            if self.hist.is_empty() {
                self.hist = vec![0; COUNT_LEVELS * TIE_LEVELS];
            }
            let b = bin(count, tie);
            self.hist[b] += 1;
            if b <= limits.guess {
                self.guessed.push(Candidate {
                    key: (u64::from(count) << 32) | u64::from(tie),
                    instance,
                    index,
                });
            }
        }
    }

    /// [`Visible::note`] for every stored point of a block that lies inside a frustum:
    /// `order` and `ties` are the block's part of [`crate::blocks::CullBlocks`].
    fn note_block(
        &mut self,
        instance: u32,
        order: &[u32],
        ties: &[u32],
        points: &Points,
        limits: &Limits,
    ) {
        if self.hist.is_empty() {
            self.hist = vec![0; COUNT_LEVELS * TIE_LEVELS];
        }
        let hist = &mut self.hist[..COUNT_LEVELS * TIE_LEVELS];
        for (&i, &tie) in order.iter().zip(ties) {
            let i = i as usize;
            if points.slot[i] == NONE {
                continue;
            }
            self.count += 1;
            let count = points.count[i];
            if count < limits.max_samples {
                let b = bin(count, tie);
                hist[b] += 1;
                if b <= limits.guess {
                    self.guessed.push(Candidate {
                        key: (u64::from(count) << 32) | u64::from(tie),
                        instance,
                        index: i as u32,
                    });
                }
            }
        }
    }

    fn merge(mut self, mut other: Visible) -> Visible {
        self.count += other.count;
        if self.hist.is_empty() {
            self.hist = other.hist;
        } else {
            for (a, b) in self.hist.iter_mut().zip(&other.hist) {
                *a += b;
            }
        }
        self.blocks.append(&mut other.blocks);
        self.points.append(&mut other.points);
        self.guessed.append(&mut other.guessed);
        self
    }
}

/// What culling keeps: points with fewer samples than `max_samples`, kept in pass 1 when
/// their bin is at most `guess`.
struct Limits {
    max_samples: u32,
    guess: usize,
}

/// What [`cull`] found.
pub(crate) struct Culled {
    /// Stored points inside some frustum.
    pub visible: usize,
    /// Every candidate [`select`] may keep (and possibly more).
    pub candidates: Vec<Candidate>,
    /// The histogram bin up to which candidates were needed (`usize::MAX`: all): a good
    /// `guess` for the next frame.
    pub cut: usize,
}

/// Count the stored points inside any frustum (grown by each instance's reconstruction
/// reach) and list those with fewer than `max_samples` samples that may be among the
/// `max_points` that [`select`] keeps (a superset of them; `select` decides). Blocks are
/// tested against the frusta first; only blocks straddling a frustum test their points.
/// One pass counts the candidates per key bin (finding the cut) and keeps those up to
/// `guess` (the previous frame's cut plus a margin); a second pass over the visible points
/// runs only when the cut lies beyond the guess. The result does not depend on `guess`.
pub(crate) fn cull(
    instances: &[InstanceState],
    frusta: &[Frustum],
    max_samples: u32,
    max_points: usize,
    guess: usize,
) -> Culled {
    let limits = Limits { max_samples, guess };
    let near: Vec<Vec<&Frustum>> = instances
        .iter()
        .map(|inst| {
            frusta
                .iter()
                .filter(|f| f.may_intersect(inst.world_bounds, inst.slack))
                .collect()
        })
        .collect();
    let work: Vec<(u32, u32)> = instances
        .iter()
        .enumerate()
        .filter(|(ii, _)| !near[*ii].is_empty())
        .flat_map(|(ii, inst)| (0..inst.blocks.blocks.len() as u32).map(move |b| (ii as u32, b)))
        .collect();
    let visible = work
        .par_iter()
        .fold(Visible::default, |mut acc, &(ii, b)| {
            let inst = &instances[ii as usize];
            let p = &inst.points;
            let blocks = &inst.blocks;
            let block = &blocks.blocks[b as usize];
            let mut straddling: Vec<&Frustum> = Vec::new();
            let mut inside = false;
            for f in &near[ii as usize] {
                match block.side(&inst.transform, f, inst.slack) {
                    Side::Inside => {
                        inside = true;
                        break;
                    }
                    Side::Straddles => straddling.push(f),
                    Side::Outside => {}
                }
            }
            let range = block.start as usize..block.end as usize;
            if inside {
                acc.blocks.push((ii, b));
                let (order, ties) = (&blocks.order[range.clone()], &blocks.tie[range]);
                acc.note_block(ii, order, ties, p, &limits);
            } else if !straddling.is_empty() {
                for k in range {
                    let i = blocks.order[k] as usize;
                    if p.slot[i] == NONE {
                        continue;
                    }
                    let w = inst.transform.transform_point3(p.position[i]);
                    if straddling.iter().any(|f| f.contains(w, inst.slack)) {
                        acc.note(ii, i as u32, p.count[i], blocks.tie[k], &limits);
                        acc.points.push((ii, k as u32));
                    }
                }
            }
            acc
        })
        .reduce(Visible::default, Visible::merge);
    // The smallest bin that, with all below it, holds `max_points` candidates: every point
    // `select` keeps lies in a bin up to it.
    let mut cut = usize::MAX;
    let mut below = 0usize;
    for (bin, &n) in visible.hist.iter().enumerate() {
        below += n as usize;
        if below >= max_points {
            cut = bin;
            break;
        }
    }
    if max_points == 0 {
        return Culled {
            visible: visible.count,
            candidates: Vec::new(),
            cut: 0,
        };
    }
    if cut <= guess {
        let mut candidates = visible.guessed;
        candidates.retain(|c| bin((c.key >> 32) as u32, c.key as u32) <= cut);
        return Culled {
            visible: visible.count,
            candidates,
            cut,
        };
    }
    let candidate = |ii: u32, k: usize| {
        let inst = &instances[ii as usize];
        let i = inst.blocks.order[k];
        let (count, tie) = (inst.points.count[i as usize], inst.blocks.tie[k]);
        (inst.points.slot[i as usize] != NONE && count < max_samples && bin(count, tie) <= cut)
            .then(|| Candidate {
                key: (u64::from(count) << 32) | u64::from(tie),
                instance: ii,
                index: i,
            })
    };
    let mut out: Vec<Candidate> = visible
        .blocks
        .par_iter()
        .flat_map_iter(|&(ii, b)| {
            let block = instances[ii as usize].blocks.blocks[b as usize];
            (block.start as usize..block.end as usize).filter_map(move |k| candidate(ii, k))
        })
        .collect();
    out.par_extend(
        visible
            .points
            .par_iter()
            .filter_map(|&(ii, k)| candidate(ii, k as usize)),
    );
    Culled {
        visible: visible.count,
        candidates: out,
        cut,
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_are_monotone_in_the_key() {
        let keys = [0u32, 1, 15, 16, 62, 63, 64, 200, u32::MAX]
            .into_iter()
            .flat_map(|c| [0u32, 1 << 24, u32::MAX >> 1, u32::MAX].map(move |t| (c, t)));
        let mut v: Vec<(u32, u32)> = keys.collect();
        v.sort_unstable();
        for w in v.windows(2) {
            assert!(bin(w[0].0, w[0].1) <= bin(w[1].0, w[1].1), "{w:?}");
        }
    }
}
