//! Per-block summaries of the points' sampling state, so culling and selection cost
//! O(visible blocks + candidates) instead of O(visible points): each block of
//! [`CullBlocks`] keeps its number of stored points and its unconverged stored points sorted
//! by selection [`bin`]. The server refreshes the summary of every point whose sample count
//! or storage changed ([`BlockSummaries::refresh`]).

use psao_points::vec_bytes;
use rayon::prelude::*;

use crate::blocks::{CullBlocks, BLOCK_POINTS};
use crate::instance::Points;

/// The largest selection bin (shared by every count from [`COUNT_LEVELS`] on).
pub(crate) const LAST_BIN: u16 = 0xFFFD;
/// `listed` value of a stored point that is converged (not listed).
const CONVERGED: u16 = 0xFFFE;
/// `listed` value of a point that is not stored.
const UNSTORED: u16 = 0xFFFF;
/// Changed entries of a block up to which they are shifted in place rather than merged.
const FEW_CHANGES: usize = 8;
/// Sample counts with a level of their own; counts from here on share [`LAST_BIN`].
const COUNT_LEVELS: u32 = 255;

/// The selection bin of a point with `count` samples and tie-break `tie`: its count, then
/// the tie's top 8 bits. Monotone in the candidate key `count << 32 | tie`, so the points
/// of the bins up to some bin are exactly the points with a key up to some key.
#[inline]
pub(crate) fn bin(count: u32, tie: u32) -> u16 {
    if count >= COUNT_LEVELS {
        LAST_BIN
    } else {
        ((count << 8) | (tie >> 24)) as u16
    }
}

/// One listed point: `bin << 16 | offset in its block`. Entries sort by bin first.
#[inline]
fn entry(bin: u16, offset: usize) -> u32 {
    (u32::from(bin) << 16) | offset as u32
}

/// Offset in its block of the point of entry `e`.
#[inline]
pub(crate) fn offset_of(e: u32) -> usize {
    (e & 0xFFFF) as usize
}

/// Bin of entry `e`.
#[inline]
pub(crate) fn bin_of(e: u32) -> u16 {
    (e >> 16) as u16
}

/// How many of the ascending `entries` have a bin up to `max_bin`.
#[inline]
pub(crate) fn count_up_to(entries: &[u32], max_bin: u16) -> usize {
    let limit = (u32::from(max_bin) + 1) << 16;
    entries.partition_point(|&e| e < limit)
}

/// Summaries of every block of one instance's [`CullBlocks`].
pub(crate) struct BlockSummaries {
    /// Per block: its stored points.
    stored: Vec<u32>,
    /// Per block: its listed points (the first `len` entries of its range in `entries`).
    len: Vec<u16>,
    /// Block after block (ranges as in [`CullBlocks::order`]): the entries of the block's
    /// stored points with fewer than `max_samples` samples, ascending.
    entries: Vec<u32>,
    /// Per position in [`CullBlocks::order`]: the bin the point is listed under, or
    /// [`CONVERGED`] / [`UNSTORED`].
    listed: Vec<u16>,
    /// Samples at which a point is converged (no longer listed).
    max_samples: u32,
}

impl BlockSummaries {
    /// Heap bytes of the per-block counts and lists.
    pub fn heap_bytes(&self) -> u64 {
        vec_bytes(&self.stored)
            + vec_bytes(&self.len)
            + vec_bytes(&self.entries)
            + vec_bytes(&self.listed)
    }

    /// Summaries of `blocks` for the current state of `points`.
    pub fn new(blocks: &CullBlocks, points: &Points, max_samples: u32) -> Self {
        let n = blocks.order.len();
        let mut out = Self {
            stored: vec![0; blocks.blocks.len()],
            len: vec![0; blocks.blocks.len()],
            entries: vec![0; n],
            listed: vec![UNSTORED; n],
            max_samples,
        };
        out.rebuild(blocks, points);
        out
    }

    /// The state point `i` should be summarised under.
    #[inline]
    fn state(&self, blocks: &CullBlocks, points: &Points, i: usize, k: usize) -> u16 {
        if !points.stored.get(i) {
            UNSTORED
        } else if points.progress(i) >= self.max_samples {
            CONVERGED
        } else {
            bin(points.progress(i), blocks.tie(k))
        }
    }

    /// Recompute every block from `points` (after most points changed).
    pub fn rebuild(&mut self, blocks: &CullBlocks, points: &Points) {
        for k in 0..blocks.order.len() {
            self.listed[k] = self.state(blocks, points, blocks.order.at(k) as usize, k);
        }
        let listed = &self.listed;
        self.entries
            .par_chunks_mut(BLOCK_POINTS)
            .zip(self.stored.par_iter_mut())
            .zip(self.len.par_iter_mut())
            .enumerate()
            .for_each(|(b, ((entries, stored), len))| {
                let states = &listed[b * BLOCK_POINTS..][..entries.len()];
                *stored = states.iter().filter(|&&s| s != UNSTORED).count() as u32;
                let mut n = 0;
                for (offset, &s) in states.iter().enumerate() {
                    if s <= LAST_BIN {
                        entries[n] = entry(s, offset);
                        n += 1;
                    }
                }
                entries[..n].sort_unstable();
                *len = n as u16;
            });
    }

    /// Bring the summaries of `changed` points (indices, any order, repeats allowed) up to
    /// date with their current sample count and storage in `points` (a [`Self::rebuild`]
    /// when they are many).
    pub fn refresh(&mut self, blocks: &CullBlocks, points: &Points, changed: &[u32]) {
        if changed.is_empty() {
            return;
        }
        if changed.len() >= self.listed.len() / 4 {
            self.rebuild(blocks, points);
            return;
        }
        let mut ks: Vec<u32> = changed.par_iter().map(|&i| blocks.order.rank(i)).collect();
        ks.par_sort_unstable();
        ks.dedup();
        // (block, first change, end of its changes) for each block with changes.
        let mut groups: Vec<(usize, usize, usize)> = Vec::new();
        for (at, &k) in ks.iter().enumerate() {
            let b = k as usize / BLOCK_POINTS;
            match groups.last_mut() {
                Some(g) if g.0 == b => g.2 = at + 1,
                _ => groups.push((b, at, at + 1)),
            }
        }
        let states: Vec<u16> = ks
            .par_iter()
            .map(|&k| {
                let k = k as usize;
                self.state(blocks, points, blocks.order.at(k) as usize, k)
            })
            .collect();
        let update = |(b, from, to): (usize, usize, usize),
                      entries: &mut [u32],
                      listed: &mut [u16],
                      stored: &mut u32,
                      len: &mut u16| {
            // The entries leaving and joining the block.
            let (mut gone, mut added) = (Vec::new(), Vec::new());
            for (&k, &new) in ks[from..to].iter().zip(&states[from..to]) {
                let offset = k as usize - b * BLOCK_POINTS;
                let old = std::mem::replace(&mut listed[offset], new);
                if old == new {
                    continue;
                }
                if old == UNSTORED {
                    *stored += 1;
                } else if new == UNSTORED {
                    *stored -= 1;
                }
                if old <= LAST_BIN {
                    gone.push(entry(old, offset));
                }
                if new <= LAST_BIN {
                    added.push(entry(new, offset));
                }
            }
            if gone.is_empty() && added.is_empty() {
                return;
            }
            if gone.len() + added.len() <= FEW_CHANGES {
                // Shift entries in place (cheaper than a merge pass for a few changes).
                let mut n = usize::from(*len);
                for e in gone {
                    let at = entries[..n].partition_point(|&x| x < e);
                    debug_assert_eq!(entries[at], e, "listed entries mirror `listed`");
                    entries.copy_within(at + 1..n, at);
                    n -= 1;
                }
                for e in added {
                    let at = entries[..n].partition_point(|&x| x < e);
                    entries.copy_within(at..n, at + 1);
                    entries[at] = e;
                    n += 1;
                }
                *len = n as u16;
                return;
            }
            gone.sort_unstable();
            added.sort_unstable();
            // One merge pass: the kept entries and the added ones.
            let n = usize::from(*len);
            let mut buffer = [0u32; BLOCK_POINTS];
            let mut n_kept = 0;
            let mut g = gone.iter().peekable();
            for &e in &entries[..n] {
                if g.peek() == Some(&&e) {
                    g.next();
                } else {
                    buffer[n_kept] = e;
                    n_kept += 1;
                }
            }
            let kept = &buffer[..n_kept];
            debug_assert!(g.next().is_none(), "listed entries mirror `listed`");
            let (mut a, mut c) = (0, 0);
            for slot in entries.iter_mut().take(kept.len() + added.len()) {
                if c == added.len() || (a < kept.len() && kept[a] < added[c]) {
                    *slot = kept[a];
                    a += 1;
                } else {
                    *slot = added[c];
                    c += 1;
                }
            }
            *len = (kept.len() + added.len()) as u16;
        };
        // The blocks with changes (groups ascend by block), then their updates in parallel.
        let mut parts = self
            .entries
            .chunks_mut(BLOCK_POINTS)
            .zip(self.listed.chunks_mut(BLOCK_POINTS))
            .zip(self.stored.iter_mut())
            .zip(self.len.iter_mut())
            .enumerate();
        let work: Vec<_> = groups
            .iter()
            .filter_map(|g| parts.find(|(b, _)| *b == g.0).map(|(_, parts)| (*g, parts)))
            .collect();
        work.into_par_iter().with_min_len(16).for_each(
            |(g, (((entries, listed), stored), len))| update(g, entries, listed, stored, len),
        );
    }

    /// Stored points of block `b`.
    #[inline]
    pub fn stored(&self, b: usize) -> u32 {
        self.stored[b]
    }

    /// Whether the point at position `k` of [`CullBlocks::order`] is stored.
    #[inline]
    pub fn is_stored(&self, k: usize) -> bool {
        self.listed[k] != UNSTORED
    }

    /// Stored points among positions `range` of [`CullBlocks::order`].
    #[inline]
    pub fn stored_in(&self, range: std::ops::Range<usize>) -> usize {
        self.listed[range]
            .iter()
            .filter(|&&s| s != UNSTORED)
            .count()
    }

    /// The listed entries of block `b` (its unconverged stored points), ascending.
    #[inline]
    pub fn entries(&self, b: usize) -> &[u32] {
        &self.entries[b * BLOCK_POINTS..][..usize::from(self.len[b])]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blocks::tie_of;
    use glam::Vec3;
    use psao_trace::ao::hash64;

    /// `n` points on a 2D spread, every 7th unstored, with hashed sample counts.
    fn points(n: usize) -> Points {
        let position = (0..n as u64)
            .map(|i| {
                let h = hash64(i);
                Vec3::new((h & 0xffff) as f32, ((h >> 16) & 0xffff) as f32, 0.0)
            })
            .collect();
        Points {
            position,
            normal: vec![Vec3::Z; n],
            stored: crate::instance::Bits::from_fn(n, |i| i % 7 != 3),
            sum: vec![0.0; n],
            count: (0..n as u64)
                .map(|i| (hash64(i ^ 99) % 40) as u16)
                .collect(),
            published: vec![0; n],
            published_here: crate::instance::Bits::new(n),
            light: None,
        }
    }

    /// Every block's summary recomputed from scratch by the definition.
    fn assert_consistent(s: &BlockSummaries, blocks: &CullBlocks, p: &Points, max: u32) {
        for (b, blk) in blocks.blocks.iter().enumerate() {
            let range = blk.start as usize..blk.end as usize;
            let stored = range
                .clone()
                .filter(|&k| p.stored.get(blocks.order.at(k) as usize))
                .count();
            let mut expected: Vec<u32> = range
                .clone()
                .filter_map(|k| {
                    let i = blocks.order.at(k) as usize;
                    (p.stored.get(i) && p.samples(i) < max)
                        .then(|| entry(bin(p.samples(i), blocks.tie(k)), k - range.start))
                })
                .collect();
            expected.sort_unstable();
            assert_eq!(s.stored(b) as usize, stored, "block {b}");
            assert_eq!(s.stored_in(range.clone()), stored, "block {b}");
            assert_eq!(s.entries(b), &expected[..], "block {b}");
        }
    }

    #[test]
    fn bins_are_monotone_in_the_key() {
        let mut keys: Vec<(u32, u32)> = [0u32, 1, 15, 63, 64, 200, 254, 255, 256, u32::MAX]
            .into_iter()
            .flat_map(|c| [0u32, 1 << 24, u32::MAX >> 1, u32::MAX].map(move |t| (c, t)))
            .collect();
        keys.sort_unstable();
        for w in keys.windows(2) {
            assert!(bin(w[0].0, w[0].1) <= bin(w[1].0, w[1].1), "{w:?}");
        }
        assert_eq!(bin(u32::MAX, u32::MAX), LAST_BIN);
    }

    #[test]
    fn refreshed_summaries_match_the_point_state() {
        let n = 5 * BLOCK_POINTS + 77;
        let mut p = points(n);
        let blocks = CullBlocks::new(&p.position, 2, 5);
        let max = 32;
        let mut s = BlockSummaries::new(&blocks, &p, max);
        assert_consistent(&s, &blocks, &p, max);
        assert_eq!(blocks.tie(0), tie_of(2, blocks.order.at(0), 5));
        for round in 0..6u64 {
            // Trace some points (some converge), restart others, store and unstore a few.
            let mut changed = Vec::new();
            for i in 0..n {
                let h = hash64(i as u64 ^ (round << 40));
                match h % 29 {
                    0 | 1 => p.set_samples(i, (p.samples(i) + 16).min(max)),
                    2 => p.set_samples(i, 0),
                    3 => p.stored.set(i, !p.stored.get(i)),
                    _ => continue,
                }
                changed.push(i as u32);
                if h.is_multiple_of(5) {
                    changed.push(i as u32);
                }
            }
            changed.reverse();
            // Few enough for the incremental path.
            assert!(changed.len() < n / 4, "{}", changed.len());
            s.refresh(&blocks, &p, &changed);
            assert_consistent(&s, &blocks, &p, max);
        }
        // A few changes per block (shifted in place rather than merged).
        let few: Vec<u32> = (0..n as u32).step_by(97).collect();
        for &i in &few {
            let i = i as usize;
            p.set_samples(i, if p.samples(i) == 0 { 5 } else { 0 });
        }
        s.refresh(&blocks, &p, &few);
        assert_consistent(&s, &blocks, &p, max);
        // A rebuild after changes nobody reported matches as well.
        for i in 0..n {
            p.set_samples(i, (p.samples(i) * 3 + 1) % (max + 2));
        }
        s.rebuild(&blocks, &p);
        assert_consistent(&s, &blocks, &p, max);
    }
}
