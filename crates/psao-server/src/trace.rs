//! Culling, budgeted selection and tracing of AO samples (DESIGN §3 "CPU server").

use glam::Vec3;
use psao_trace::ao::{ao_rays_range, medium_stream, sample_value, Medium, MediumSampler};
use psao_trace::{Hit, Ray, Tracer};
use rayon::prelude::*;

use crate::blocks::{WorldBox, BLOCK_POINTS, GROUP_BLOCKS, SUBS_PER_BLOCK, SUB_POINTS};
use crate::frustum::Frustum;
use crate::instance::InstanceState;
use crate::light::LightSample;
use crate::summary::{bin, bin_of, count_up_to, offset_of, LAST_BIN};

/// Rays traced together per parallel work item. The batch's points are neighbours (points
/// are numbered in Morton order) and each point's rays stay together, so a
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
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Traced {
    pub instance: u32,
    pub index: u32,
    /// Sum of the new samples' values ([`psao_trace::ao::sample_value`]).
    pub sum: f32,
    /// Number of new samples.
    pub rays: u32,
    /// New light paths, with lighting.
    pub light: LightSample,
}

/// The key that identifies a point's AO sample sequence.
pub(crate) fn sample_key(instance: u32, index: u32) -> u64 {
    (u64::from(instance) << 32) | u64::from(index)
}

// A sub-block is one word of a block's visibility mask.
const _: () = assert!(SUB_POINTS == 64 && BLOCK_POINTS.is_multiple_of(SUB_POINTS));

/// Which points of a block straddling the frusta are visible: bit `o % 64` of word `o / 64`
/// for the point at offset `o` in the block.
type VisibleMask = [u64; BLOCK_POINTS / 64];

/// A block with visible points to select from: its instance, the position of its first
/// point in the instance's block order, the summary entries of its unconverged points
/// (ascending by bin) and, for a block straddling the frusta, which of them are visible
/// (`None`: all). Masking the entries as they are read avoids copying the visible ones.
struct VisibleBlock<'a> {
    instance: u32,
    start: u32,
    entries: &'a [u32],
    mask: Option<VisibleMask>,
}

impl VisibleBlock<'_> {
    /// Whether the point of entry `e` is visible.
    #[inline]
    fn sees(&self, e: u32) -> bool {
        self.mask.as_ref().is_none_or(|m| {
            let o = offset_of(e);
            m[o / 64] & (1 << (o % 64)) != 0
        })
    }

    /// The visible entries with a bin up to `max_bin`, ascending.
    fn up_to(&self, max_bin: u16) -> impl Iterator<Item = u32> + '_ {
        let n = count_up_to(self.entries, max_bin);
        self.entries[..n].iter().copied().filter(|&e| self.sees(e))
    }
}

/// What [`cull`] found.
pub(crate) struct Culled {
    /// Stored points inside some frustum.
    pub visible: usize,
    /// Every candidate [`select`] may keep (and possibly more).
    pub candidates: Vec<Candidate>,
    /// The selection bin ([`crate::summary::bin`]) up to which candidates were needed: a good
    /// `guess` for the next frame.
    pub cut: u16,
}

/// Count the stored points inside any frustum (grown by each instance's reconstruction
/// reach) and list the unconverged ones that may be among the `max_points` that [`select`]
/// keeps: every visible unconverged point in the selection bins up to the smallest bin that,
/// with all below it, holds `max_points` of them (a superset of what `select` keeps, since
/// bins are monotone in the key; `select` decides). Groups of blocks are tested against the
/// frusta first, then the blocks of straddling groups against the frusta their group
/// straddles: blocks inside take their counts from their summaries, only blocks straddling a
/// frustum test their sub-blocks and points. The cut is searched from `guess` (the previous
/// frame's cut) on the blocks' sorted summaries; the result does not depend on `guess`.
pub(crate) fn cull(
    instances: &[InstanceState],
    frusta: &[Frustum],
    max_points: usize,
    guess: u16,
) -> Culled {
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
        .flat_map(|(ii, inst)| (0..inst.blocks.groups.len() as u32).map(move |g| (ii as u32, g)))
        .collect();
    // Fold state: visible count, blocks, bin window, and scratch lists of the frusta a group,
    // a block and a sub-block straddle (reused from group to group).
    type Scratch<'f> = [Vec<&'f Frustum>; 3];
    let fresh = || {
        let scratch: Scratch = [Vec::new(), Vec::new(), Vec::new()];
        (0usize, Vec::new(), BinWindow::around(guess), scratch)
    };
    let (visible, blocks, window, _) = work
        .par_iter()
        .fold(
            fresh,
            |(mut visible, mut out, mut window, mut scratch), &(ii, g)| {
                let inst = &instances[ii as usize];
                let [group_straddling, straddling, sub_straddling] = &mut scratch;
                let group_inside = WorldBox::new(inst.blocks.groups[g as usize], &inst.transform)
                    .classify(
                        near[ii as usize].iter().copied(),
                        inst.slack,
                        group_straddling,
                    );
                if !group_inside && group_straddling.is_empty() {
                    return (visible, out, window, scratch);
                }
                let first = g as usize * GROUP_BLOCKS;
                let last = (first + GROUP_BLOCKS).min(inst.blocks.blocks.len());
                for b in first..last {
                    let block = &inst.blocks.blocks[b];
                    // Inside the group's frustum, or tested against the frusta it straddles.
                    let inside = group_inside || {
                        let frusta = group_straddling.iter().copied();
                        block
                            .world(&inst.transform)
                            .classify(frusta, inst.slack, straddling)
                    };
                    let mask = if inside {
                        visible += inst.summaries.stored(b) as usize;
                        None
                    } else {
                        match straddling_mask(inst, b, straddling, sub_straddling, &mut visible) {
                            Some(mask) => Some(mask),
                            None => continue,
                        }
                    };
                    let vb = VisibleBlock {
                        instance: ii,
                        start: block.start,
                        entries: inst.summaries.entries(b),
                        mask,
                    };
                    if !vb.entries.is_empty() {
                        window.add(&vb);
                        out.push(vb);
                    }
                }
                (visible, out, window, scratch)
            },
        )
        .reduce(fresh, |(n, mut a, w, s), (m, mut b, v, _)| {
            a.append(&mut b);
            (n + m, a, w.merge(&v), s)
        });
    if max_points == 0 {
        return Culled {
            visible,
            candidates: Vec::new(),
            cut: 0,
        };
    }
    let cut = window
        .cut(max_points)
        .unwrap_or_else(|start| find_cut(&blocks, max_points, start));
    let candidates = blocks
        .par_iter()
        .flat_map_iter(|vb| {
            let inst = &instances[vb.instance as usize];
            vb.up_to(cut).map(move |e| {
                let k = vb.start as usize + offset_of(e);
                let i = inst.blocks.order.at(k);
                let (count, tie) = (inst.points.progress(i as usize), inst.blocks.tie(k));
                debug_assert_eq!(bin(count, tie), bin_of(e), "summaries are up to date");
                Candidate {
                    key: (u64::from(count) << 32) | u64::from(tie),
                    instance: vb.instance,
                    index: i,
                }
            })
        })
        .collect::<Vec<_>>();
    Culled {
        visible,
        candidates,
        cut,
    }
}

/// For block `b` of `inst`, which straddles the frusta `straddling` (none: outside all):
/// count its stored points inside some frustum into `visible` (sub-blocks first, then the
/// points of the sub-blocks that straddle one) and return which points those are (`None`:
/// none). `sub_straddling` is scratch.
fn straddling_mask<'f>(
    inst: &InstanceState,
    b: usize,
    straddling: &[&'f Frustum],
    sub_straddling: &mut Vec<&'f Frustum>,
    visible: &mut usize,
) -> Option<VisibleMask> {
    if straddling.is_empty() {
        return None;
    }
    let (summaries, block) = (&inst.summaries, &inst.blocks.blocks[b]);
    let mut mask: VisibleMask = [0; BLOCK_POINTS / 64];
    let (positions, order) = (&inst.points.position, &inst.blocks.order);
    let start = block.start as usize;
    let subs = &inst.blocks.subs[b * SUBS_PER_BLOCK..];
    for (j, k0) in (start..block.end as usize).step_by(SUB_POINTS).enumerate() {
        let range = k0..(k0 + SUB_POINTS).min(block.end as usize);
        let sub_inside = WorldBox::new(subs[j], &inst.transform).classify(
            straddling.iter().copied(),
            inst.slack,
            sub_straddling,
        );
        if sub_inside {
            // Entries are stored points: marking all is enough.
            *visible += summaries.stored_in(range);
            mask[(k0 - start) / 64] = u64::MAX;
            continue;
        }
        if sub_straddling.is_empty() {
            continue;
        }
        for k in range {
            if !summaries.is_stored(k) {
                continue;
            }
            let w = inst
                .transform
                .transform_point3(positions[order.at(k) as usize]);
            if sub_straddling.iter().any(|f| f.contains(w, inst.slack)) {
                *visible += 1;
                let offset = k - start;
                mask[offset / 64] |= 1 << (offset % 64);
            }
        }
    }
    mask.iter().any(|&w| w != 0).then_some(mask)
}

/// Selection bins counted around the guessed cut in the culling pass.
const WINDOW_BINS: usize = 32;
/// Bins of the window below the guess (the cut mostly moves up as points take samples).
const WINDOW_BELOW: u16 = 4;

/// Visible entry counts of a window of bins, and of the entries below it.
#[derive(Clone, Copy)]
struct BinWindow {
    first: u16,
    below: usize,
    counts: [u32; WINDOW_BINS],
}

impl BinWindow {
    /// An empty window starting a little below `guess`.
    fn around(guess: u16) -> Self {
        Self {
            first: guess.min(LAST_BIN).saturating_sub(WINDOW_BELOW),
            below: 0,
            counts: [0; WINDOW_BINS],
        }
    }

    /// Count the visible entries of `block` below and in the window. Entries below the
    /// window are few when the guess is good: they are read one by one (masked blocks must
    /// be, and it saves a search of the others).
    fn add(&mut self, block: &VisibleBlock) {
        let end = usize::from(self.first) + WINDOW_BINS;
        for &e in block.entries {
            let bin = usize::from(bin_of(e));
            if bin >= end {
                break;
            }
            if !block.sees(e) {
                continue;
            }
            match bin.checked_sub(usize::from(self.first)) {
                Some(at) => self.counts[at] += 1,
                None => self.below += 1,
            }
        }
    }

    fn merge(mut self, other: &BinWindow) -> Self {
        self.below += other.below;
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += b;
        }
        self
    }

    /// The smallest bin holding, with all below it, `max_points` entries when it lies in
    /// the window; otherwise `Err` with a bin to search from.
    fn cut(&self, max_points: usize) -> Result<u16, u16> {
        if self.below >= max_points {
            return Err(self.first.saturating_sub(1));
        }
        let mut n = self.below;
        for (j, &c) in self.counts.iter().enumerate() {
            n += c as usize;
            if n >= max_points {
                return Ok(self.first + j as u16);
            }
        }
        Err((usize::from(self.first) + WINDOW_BINS).min(usize::from(LAST_BIN)) as u16)
    }
}

/// The smallest bin that, with all below it, holds at least `max_points` of the visible
/// entries of `blocks` ([`LAST_BIN`] if they hold fewer): galloping from `guess`, then
/// bisecting.
fn find_cut(blocks: &[VisibleBlock], max_points: usize, guess: u16) -> u16 {
    let enough = |bin: u16| -> bool {
        let n: usize = blocks.par_iter().map(|b| b.up_to(bin).count()).sum();
        n >= max_points
    };
    if !enough(LAST_BIN) {
        return LAST_BIN;
    }
    // Invariant: `lo` (-1: none) has too few entries, `hi` enough.
    let guess = i32::from(guess.min(LAST_BIN));
    let (mut lo, mut hi);
    if enough(guess as u16) {
        hi = guess;
        let mut step = 1;
        loop {
            let probe = hi - step;
            if probe < 0 {
                lo = -1;
                break;
            }
            if enough(probe as u16) {
                hi = probe;
                step *= 2;
            } else {
                lo = probe;
                break;
            }
        }
    } else {
        lo = guess;
        let mut step = 1;
        loop {
            let probe = (lo + step).min(i32::from(LAST_BIN));
            if enough(probe as u16) {
                hi = probe;
                break;
            }
            lo = probe;
            step *= 2;
        }
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if enough(mid as u16) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi as u16
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
/// point, in spatially coherent batches (runs of `selected`, whose points are numbered in
/// Morton order of position) on the rayon pool, through `medium` if any (one medium sampler
/// per work item). Results are in the order of `selected` and do not depend on the number
/// of threads.
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
    let job = |c: &Candidate| {
        let inst = &instances[c.instance as usize];
        let (origin, normal) = inst.world(c.index as usize);
        let count = inst.points.samples(c.index as usize);
        Job {
            instance: c.instance,
            index: c.index,
            origin,
            normal,
            first: count,
            rays: rays_per_point.min(max_samples.saturating_sub(count)),
        }
    };
    // `selected` is in (instance, index) order and the server numbers each instance's points
    // in Morton order of their positions ([`crate::blocks::morton_order`]), so consecutive
    // candidates are neighbours already: batches are runs of them, with no sort and no
    // permutation back.
    let per_batch = (BATCH_RAYS / rays_per_point.max(1) as usize).max(1);
    selected
        .par_chunks(per_batch)
        .map_init(
            || (medium.map(|m| m.sampler()), Scratch::default()),
            |(sampler, scratch), batch| {
                scratch.jobs.clear();
                scratch.jobs.extend(batch.iter().map(job));
                trace_batch(tracer, sampler.as_deref_mut(), scratch, radius, seed)
            },
        )
        .flatten_iter()
        .collect()
}

/// A work item's buffers, reused from batch to batch.
#[derive(Default)]
struct Scratch {
    jobs: Vec<Job>,
    rays: Vec<Ray>,
    hits: Vec<Option<Hit>>,
}

/// Trace the jobs of `scratch` with its buffers; returns their results in the order of the
/// jobs.
fn trace_batch(
    tracer: &Tracer,
    mut medium: Option<&mut (dyn MediumSampler + '_)>,
    scratch: &mut Scratch,
    radius: f32,
    seed: u64,
) -> Vec<Traced> {
    let Scratch { jobs, rays, hits } = scratch;
    rays.clear();
    for job in jobs.iter() {
        let key = sample_key(job.instance, job.index);
        ao_rays_range(
            job.origin, job.normal, radius, job.first, job.rays, seed, key, rays,
        );
    }
    hits.clear();
    hits.resize(rays.len(), None);
    tracer.intersect(rays, hits);
    let mut at = 0;
    jobs.iter()
        .map(|job| {
            let n = job.rays as usize;
            let key = sample_key(job.instance, job.index);
            let sum = rays[at..at + n]
                .iter()
                .zip(&hits[at..at + n])
                .zip(job.first..)
                .map(|((ray, hit), i)| {
                    // The stream only matters to a medium.
                    let stream = if medium.is_some() {
                        medium_stream(seed, key, i)
                    } else {
                        0
                    };
                    sample_value(ray, hit.as_ref(), radius, medium.as_deref_mut(), stream)
                })
                .sum();
            at += n;
            Traced {
                instance: job.instance,
                index: job.index,
                sum,
                rays: job.rays,
                light: LightSample::default(),
            }
        })
        .collect()
}
