//! Weighted sample elimination (C. Yuksel, "Sample Elimination for Generating Poisson Disk
//! Sample Sets", Eurographics 2015): turn a dense random point set into an evenly spread subset.
//!
//! Every point i gets the weight Σ_j (1 − d_ij / d_max)^8 over its neighbours closer than
//! d_max = 2·r_max; the heaviest point is removed repeatedly and its neighbours' weights drop
//! by their shared term, until the requested number of points remains.
//!
//! Neighbour search uses our own flat uniform grid (cell = d_max) instead of a general
//! kd-tree: every query has the same fixed radius and a cell holds a few points, so scanning
//! the 27 surrounding cells is simpler and faster than tree traversal. Cells are grouped into
//! blocks of 16³; points are sorted by (block, cell), a small hash finds a block, and each
//! block resolves its cells' neighbours through a dense 18³ table, so lookups stay in cache
//! even for millions of points. Neighbour lists are built once, in parallel, per block.
//!
//! Weight terms are fixed point (2^-24 resolution): integer sums are exact and independent of
//! summation order, so equal weights tie exactly (isolated symmetric pairs are common) and the
//! result does not depend on the order in which neighbours were removed.
//!
//! Instead of a global max-heap (whose pops jump randomly through memory), removals are
//! scheduled locally. Removing the heaviest point only lowers its neighbours' weights, so a
//! point that outweighs all its remaining neighbours keeps its weight, and its neighbours stay
//! lighter, until the global-max order reaches it: removing it right away gives every point
//! the same weight at removal as the global order does. We therefore remove such local maxima
//! from a stack (spatially coherent, cache friendly) until no point is left, recording each
//! point's removal weight, and then keep the `keep` points with the smallest (weight, index)
//! keys; the global order removes exactly the others, since its removal keys strictly
//! decrease. Each point counts its remaining neighbours that outrank it; it is ready at zero.
//! A unit test checks the result against a textbook max-heap-style implementation.

use glam::Vec3;
use rayon::prelude::*;

use crate::KeyMap;

/// Exponent of the weight function (Yuksel's α = 8).
const ALPHA: i32 = 8;
/// Fractional bits of the fixed-point weight terms.
const WEIGHT_BITS: i32 = 24;
/// Bits per axis of a cell coordinate.
const AXIS_BITS: u32 = 21;
/// Bits per axis of a cell's position inside its block (blocks of 16³ cells).
const BLOCK_BITS: u32 = 4;
const BLOCK: i64 = 1 << BLOCK_BITS;
/// Side of a block's neighbour table: the block plus a one-cell halo.
const TABLE: i64 = BLOCK + 2;
const EMPTY: u32 = u32::MAX;

/// Yuksel's maximum Poisson-disk radius for `count` samples on a surface of `area`:
/// `r_max = sqrt(area / (2·√3·count))`. Disks of this radius around hexagonally packed samples
/// tile the surface, so the expected spacing between neighbours is `2·r_max`.
/// Returns 0 when `count` is 0.
pub fn max_poisson_radius(area: f64, count: usize) -> f64 {
    if count == 0 {
        return 0.0;
    }
    (area / (2.0 * 3f64.sqrt() * count as f64)).sqrt()
}

/// Keep `keep` of `positions` by weighted sample elimination with interaction distance `d_max`
/// (normally `2·r_max` of the output set, see [`max_poisson_radius`]).
///
/// Returns the indices of the kept points in a spatially coherent order (sorted by the
/// neighbour grid's blocks and cells). Deterministic: the result depends only on the inputs,
/// not on the number of threads; among equal weights the point later in that order is removed
/// first. With `keep >= positions.len()` every index is returned; with a non-positive or
/// non-finite `d_max` points do not interact and the lowest indices are kept.
pub fn eliminate(positions: &[Vec3], keep: usize, d_max: f32) -> Vec<u32> {
    eliminate_scaled(positions, None, keep, d_max)
}

/// [`eliminate`] with a local interaction distance: point `i` carries a scale `s_i` in
/// (0, 1] (`scales[i]`, same order as `positions`) and a pair interacts within
/// `d_max · (s_i + s_j) / 2` (symmetric, so removals subtract the terms the weights were built
/// from). Where the scales are small the kept points end up denser: their local spacing follows
/// the scale (Yuksel's adaptive sampling with a symmetric pair distance). `None`, or a
/// `scales` slice of another length than `positions`, behaves as all scales 1; scales are
/// clamped to [1/64, 1] (NaN counts as 1).
pub fn eliminate_scaled(
    positions: &[Vec3],
    scales: Option<&[f32]>,
    keep: usize,
    d_max: f32,
) -> Vec<u32> {
    let n = positions.len();
    if keep >= n {
        return (0..n as u32).collect();
    }
    if keep == 0 {
        return Vec::new();
    }
    if !(d_max.is_finite() && d_max > 0.0) {
        return (0..keep as u32).collect();
    }
    let grid = BlockGrid::new(positions, d_max);
    let sorted: Vec<Vec3> = grid.order.iter().map(|&i| positions[i as usize]).collect();
    let sorted_scales: Option<Vec<f32>> = scales.filter(|s| s.len() == n).map(|s| {
        grid.order
            .iter()
            .map(|&i| {
                let x = s[i as usize];
                if x.is_nan() {
                    1.0
                } else {
                    x.clamp(1.0 / 64.0, 1.0)
                }
            })
            .collect()
    });
    let nbrs = Neighbours::build(&grid, &sorted, sorted_scales.as_deref(), d_max);
    drop(sorted);
    let mut w = nbrs.weight_sums();
    remove_all_by_local_maxima(&nbrs, &mut w);

    // w now holds every point's removal weight; the n − keep largest (weight, index) keys are
    // the points the global order removes first.
    let mut keys: Vec<(u64, u32)> = w
        .iter()
        .enumerate()
        .map(|(k, &wk)| (wk, k as u32))
        .collect();
    let split = n - keep;
    keys.select_nth_unstable_by(split, |a, b| b.cmp(a));
    let mut kept: Vec<u32> = keys[split..].iter().map(|&(_, k)| k).collect();
    kept.sort_unstable();
    kept.into_iter().map(|k| grid.order[k as usize]).collect()
}

/// Run the elimination until no point is left, removing local maxima in stack order; on
/// return `w[j]` is point j's weight at the moment it was removed.
fn remove_all_by_local_maxima(nbrs: &Neighbours, w: &mut [u64]) {
    let n = w.len();
    // Remaining neighbours that outrank each point: (w, index) compared lexicographically.
    let mut blockers: Vec<u32> = {
        let w: &[u64] = w;
        (0..n)
            .into_par_iter()
            .map(|i| {
                let ki = (w[i], i);
                let (index, _) = nbrs.list(i);
                index
                    .iter()
                    .filter(|&&x| (w[x as usize], x as usize) > ki)
                    .count() as u32
            })
            .collect()
    };
    let mut removed = vec![false; n];
    let mut queued = vec![false; n];
    let mut stack: Vec<u32> = Vec::new();
    for (i, &b) in blockers.iter().enumerate() {
        if b == 0 {
            queued[i] = true;
            stack.push(i as u32);
        }
    }
    while let Some(j) = stack.pop() {
        let j = j as usize;
        queued[j] = false;
        if blockers[j] != 0 {
            continue; // outranked again since it was queued; requeued when it becomes free
        }
        removed[j] = true;
        let (index, weight) = nbrs.list(j);
        for (&i, &t) in index.iter().zip(weight) {
            let i = i as usize;
            if removed[i] {
                continue;
            }
            // j outranked i and is gone; i gets lighter and may drop below some neighbours.
            blockers[i] -= 1;
            let old = (w[i], i);
            w[i] -= u64::from(t);
            let new = (w[i], i);
            for &x in nbrs.list(i).0 {
                let x = x as usize;
                if removed[x] {
                    continue;
                }
                let kx = (w[x], x);
                if old > kx && new < kx {
                    blockers[i] += 1;
                    blockers[x] -= 1;
                    if blockers[x] == 0 && !queued[x] {
                        queued[x] = true;
                        stack.push(x as u32);
                    }
                }
            }
            if blockers[i] == 0 && !queued[i] {
                queued[i] = true;
                stack.push(i as u32);
            }
        }
    }
    debug_assert!(
        removed.iter().all(|&r| r),
        "every point is eventually a local maximum"
    );
}

/// Block coordinates packed into one key (17 bits per axis).
#[inline]
fn block_key(b: [i64; 3]) -> u64 {
    let bits = AXIS_BITS - BLOCK_BITS;
    ((b[0] as u64) << (2 * bits)) | ((b[1] as u64) << bits) | b[2] as u64
}

#[inline]
fn unpack_block(key: u64) -> [i64; 3] {
    let bits = AXIS_BITS - BLOCK_BITS;
    let mask = (1u64 << bits) - 1;
    [
        (key >> (2 * bits)) as i64,
        ((key >> bits) & mask) as i64,
        (key & mask) as i64,
    ]
}

/// Points sorted by (block, cell inside block), with the occupied cells and blocks.
struct BlockGrid {
    /// Point indices in sorted order.
    order: Vec<u32>,
    /// Start of each occupied cell in `order` (plus one final end).
    cell_start: Vec<u32>,
    /// Local coordinates of each occupied cell inside its block.
    cell_local: Vec<[u8; 3]>,
    /// First cell of each occupied block (plus one final end).
    block_cells: Vec<u32>,
    /// Key of each occupied block.
    block_key: Vec<u64>,
    /// Block key → block index.
    lookup: KeyMap<u32>,
}

impl BlockGrid {
    fn new(positions: &[Vec3], d_max: f32) -> Self {
        let (lo, hi) = positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        // Cells at least d_max wide so the 27 surrounding cells hold every neighbour; wider
        // only when the extent would not fit in the coordinate bits.
        let max_cell = ((1u32 << AXIS_BITS) - 1) as f32;
        let cell = d_max.max((hi - lo).max_element() / (max_cell - 1.0));
        let inv_cell = 1.0 / cell;
        let sort_key = |p: Vec3| {
            let c = ((p - lo) * inv_cell).floor().min(Vec3::splat(max_cell));
            let c = [c.x as u64, c.y as u64, c.z as u64];
            let m = (1u64 << BLOCK_BITS) - 1;
            let block = block_key(c.map(|v| (v >> BLOCK_BITS) as i64));
            let local = (c[0] & m) | ((c[1] & m) << BLOCK_BITS) | ((c[2] & m) << (2 * BLOCK_BITS));
            (block << (3 * BLOCK_BITS)) | local
        };
        let mut keyed: Vec<(u64, u32)> = positions
            .par_iter()
            .enumerate()
            .map(|(i, p)| (sort_key(*p), i as u32))
            .collect();
        keyed.par_sort_unstable();

        let local_mask = (1u64 << (3 * BLOCK_BITS)) - 1;
        let m = (1u64 << BLOCK_BITS) - 1;
        let (mut cell_start, mut cell_local) = (Vec::new(), Vec::new());
        let (mut block_cells, mut block_keys) = (Vec::new(), Vec::new());
        let mut prev = None;
        for (k, &(key, _)) in keyed.iter().enumerate() {
            if prev == Some(key) {
                continue;
            }
            let block = key >> (3 * BLOCK_BITS);
            if prev.map(|p| p >> (3 * BLOCK_BITS)) != Some(block) {
                block_cells.push(cell_start.len() as u32);
                block_keys.push(block);
            }
            let local = key & local_mask;
            cell_local.push([
                (local & m) as u8,
                ((local >> BLOCK_BITS) & m) as u8,
                (local >> (2 * BLOCK_BITS)) as u8,
            ]);
            cell_start.push(k as u32);
            prev = Some(key);
        }
        cell_start.push(keyed.len() as u32);
        block_cells.push(cell_local.len() as u32);
        let mut lookup = KeyMap::with_capacity_and_hasher(block_keys.len(), Default::default());
        for (b, &key) in block_keys.iter().enumerate() {
            lookup.insert(key, b as u32);
        }
        Self {
            order: keyed.into_iter().map(|(_, i)| i).collect(),
            cell_start,
            cell_local,
            block_cells,
            block_key: block_keys,
            lookup,
        }
    }

    /// Fill `table` (18³, index x + 18·y + 324·z, origin one cell below block `b`'s corner)
    /// with the indices of the occupied cells of block `b` and its one-cell halo.
    fn fill_table(&self, b: usize, table: &mut [u32]) {
        table.fill(EMPTY);
        let centre = unpack_block(self.block_key[b]);
        let limit = 1i64 << (AXIS_BITS - BLOCK_BITS);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let nb = [centre[0] + dx, centre[1] + dy, centre[2] + dz];
                    if nb.iter().any(|&v| v < 0 || v >= limit) {
                        continue;
                    }
                    let Some(&o) = self.lookup.get(&block_key(nb)) else {
                        continue;
                    };
                    let o = o as usize;
                    for c in self.block_cells[o]..self.block_cells[o + 1] {
                        let l = self.cell_local[c as usize];
                        let t = [
                            i64::from(l[0]) + dx * BLOCK + 1,
                            i64::from(l[1]) + dy * BLOCK + 1,
                            i64::from(l[2]) + dz * BLOCK + 1,
                        ];
                        if t.iter().all(|&v| (0..TABLE).contains(&v)) {
                            table[(t[0] + TABLE * (t[1] + TABLE * t[2])) as usize] = c;
                        }
                    }
                }
            }
        }
    }
}

/// Fixed-point weight term `(1 − d/d_max)^8 · 2^24` of a pair at squared distance `d2`
/// (0 at or beyond `d_max`).
#[inline]
fn weight_term(d2: f32, d_max: f32) -> u32 {
    if d2 >= d_max * d_max {
        return 0;
    }
    let t = (1.0 - d2.sqrt() * (1.0 / d_max)).max(0.0).powi(ALPHA);
    (t * (1u32 << WEIGHT_BITS) as f32 + 0.5) as u32
}

/// Neighbour lists of one block's points: offsets per point (plus one end) into the block's
/// neighbour indices (sorted order) and their non-zero weight terms.
#[derive(Default)]
struct BlockNeighbours {
    start: Vec<u32>,
    index: Vec<u32>,
    weight: Vec<u32>,
}

/// Neighbour lists of all points, kept per block as built (no concatenation copy).
struct Neighbours {
    blocks: Vec<BlockNeighbours>,
    /// Block of each point (sorted order).
    block_of: Vec<u32>,
    /// First point of each block.
    first: Vec<u32>,
}

impl Neighbours {
    /// Neighbour indices and weight terms of point `j` (sorted order).
    #[inline]
    fn list(&self, j: usize) -> (&[u32], &[u32]) {
        let b = self.block_of[j] as usize;
        let part = &self.blocks[b];
        let l = j - self.first[b] as usize;
        let (s, e) = (part.start[l] as usize, part.start[l + 1] as usize);
        (&part.index[s..e], &part.weight[s..e])
    }

    /// Every point's weight: the sum of its terms.
    fn weight_sums(&self) -> Vec<u64> {
        (0..self.block_of.len())
            .into_par_iter()
            .map(|j| self.list(j).1.iter().map(|&t| u64::from(t)).sum())
            .collect()
    }

    fn build(grid: &BlockGrid, sorted: &[Vec3], scales: Option<&[f32]>, d_max: f32) -> Self {
        let d2_max = d_max * d_max;
        let nblocks = grid.block_key.len();
        let first: Vec<u32> = (0..nblocks)
            .map(|b| grid.cell_start[grid.block_cells[b] as usize])
            .collect();
        let mut block_of = vec![0u32; sorted.len()];
        for b in 0..nblocks {
            let end = first.get(b + 1).map_or(sorted.len(), |&e| e as usize);
            block_of[first[b] as usize..end].fill(b as u32);
        }
        let blocks: Vec<BlockNeighbours> = (0..nblocks)
            .into_par_iter()
            .map_init(
                || vec![EMPTY; (TABLE * TABLE * TABLE) as usize],
                |table, b| {
                    grid.fill_table(b, table);
                    let mut part = BlockNeighbours {
                        start: vec![0],
                        ..Default::default()
                    };
                    for c in grid.block_cells[b]..grid.block_cells[b + 1] {
                        let l = grid.cell_local[c as usize].map(i64::from);
                        let mut ranges = [(0u32, 0u32); 27];
                        let mut nr = 0;
                        for dz in 0..3 {
                            for dy in 0..3 {
                                for dx in 0..3 {
                                    let t =
                                        (l[0] + dx) + TABLE * ((l[1] + dy) + TABLE * (l[2] + dz));
                                    let o = table[t as usize];
                                    if o != EMPTY {
                                        let o = o as usize;
                                        ranges[nr] = (grid.cell_start[o], grid.cell_start[o + 1]);
                                        nr += 1;
                                    }
                                }
                            }
                        }
                        let c = c as usize;
                        for k in grid.cell_start[c]..grid.cell_start[c + 1] {
                            let p = sorted[k as usize];
                            for &(lo, hi) in &ranges[..nr] {
                                for m in lo..hi {
                                    let d2 = p.distance_squared(sorted[m as usize]);
                                    if d2 >= d2_max || m == k {
                                        continue;
                                    }
                                    let w = match scales {
                                        Some(sc) => weight_term(
                                            d2,
                                            d_max * 0.5 * (sc[k as usize] + sc[m as usize]),
                                        ),
                                        None => weight_term(d2, d_max),
                                    };
                                    if w > 0 {
                                        part.index.push(m);
                                        part.weight.push(w);
                                    }
                                }
                            }
                            part.start.push(part.index.len() as u32);
                        }
                    }
                    part
                },
            )
            .collect();
        Self {
            blocks,
            block_of,
            first,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Stream;

    fn random_square(n: usize, seed: u64) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let mut s = Stream::new(seed, i as u64);
                Vec3::new(s.next_f32(), s.next_f32(), 0.0)
            })
            .collect()
    }

    fn min_distance(points: &[Vec3]) -> f32 {
        let mut best = f32::INFINITY;
        for (i, a) in points.iter().enumerate() {
            for b in &points[i + 1..] {
                best = best.min(a.distance(*b));
            }
        }
        best
    }

    /// Textbook elimination: recompute every weight by brute force and remove the maximum.
    fn brute_force(points: &[Vec3], keep: usize, d_max: f32) -> Vec<u32> {
        let mut alive: Vec<u32> = (0..points.len() as u32).collect();
        let weight_of = |i: u32, alive: &[u32]| -> u64 {
            alive
                .iter()
                .filter(|&&j| j != i)
                .map(|&j| points[i as usize].distance_squared(points[j as usize]))
                .map(|d2| u64::from(weight_term(d2, d_max)))
                .sum()
        };
        while alive.len() > keep {
            let (pos, _) = alive
                .iter()
                .enumerate()
                .map(|(p, &i)| (p, (weight_of(i, &alive), i)))
                .max_by_key(|a| a.1)
                .unwrap();
            alive.remove(pos);
        }
        alive
    }

    #[test]
    fn matches_brute_force_elimination() {
        // A tilted 4 × 0.25 strip: several 16³-cell blocks along x; plus a coincident point.
        let mut pts: Vec<Vec3> = random_square(400, 5)
            .into_iter()
            .map(|p| Vec3::new(4.0 * p.x, 0.25 * p.y, 1.2 * p.x))
            .collect();
        pts.push(pts[0]);
        let keep = 200;
        let d_max = 2.0 * max_poisson_radius(1.0, keep) as f32;
        // Put the input in grid order so that "later in grid order" = "higher index" for ties.
        let grid = BlockGrid::new(&pts, d_max);
        let pts: Vec<Vec3> = grid.order.iter().map(|&i| pts[i as usize]).collect();
        let mut fast = eliminate(&pts, keep, d_max);
        fast.sort_unstable();
        let slow = brute_force(&pts, keep, d_max);
        assert_eq!(fast, slow);
    }

    #[test]
    fn radius_formula() {
        // Hexagonal packing of 2·r_max spacing: area per point (√3/2)·(2r)² = 2√3·r².
        let r = max_poisson_radius(10.0, 1000);
        assert!((2.0 * 3f64.sqrt() * r * r * 1000.0 - 10.0).abs() < 1e-9);
        assert_eq!(max_poisson_radius(1.0, 0), 0.0);
    }

    #[test]
    fn keeps_requested_count_and_spreads_points() {
        let input = random_square(4000, 11);
        let keep = 2000;
        let r = max_poisson_radius(1.0, keep) as f32;
        let kept = eliminate(&input, keep, 2.0 * r);
        assert_eq!(kept.len(), keep);
        let mut sorted = kept.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), keep, "indices must be unique");
        let pts: Vec<Vec3> = kept.iter().map(|&i| input[i as usize]).collect();
        let random_min = min_distance(&input[..keep]);
        let wse_min = min_distance(&pts);
        assert!(wse_min > 0.5 * r, "min distance {wse_min} vs r_max {r}");
        assert!(
            wse_min > 5.0 * random_min,
            "{wse_min} vs random {random_min}"
        );
    }

    #[test]
    fn unit_scales_match_plain_elimination() {
        let input = random_square(3000, 7);
        let d = 2.0 * max_poisson_radius(1.0, 1500) as f32;
        let ones = vec![1.0f32; input.len()];
        assert_eq!(
            eliminate(&input, 1500, d),
            eliminate_scaled(&input, Some(&ones), 1500, d)
        );
        // A slice of the wrong length is ignored.
        assert_eq!(
            eliminate(&input, 1500, d),
            eliminate_scaled(&input, Some(&ones[1..]), 1500, d)
        );
    }

    #[test]
    fn small_scales_keep_more_points() {
        // Half scale on the left half of the square: its local spacing halves, so it keeps
        // clearly more than half of the points (about 4/5 for a quartered disk area).
        let input = random_square(8000, 3);
        let scales: Vec<f32> = input
            .iter()
            .map(|p| if p.x < 0.5 { 0.5 } else { 1.0 })
            .collect();
        let keep = 2000;
        let d = 2.0 * max_poisson_radius(1.0, keep) as f32 * (2.5f32).sqrt();
        let kept = eliminate_scaled(&input, Some(&scales), keep, d);
        assert_eq!(kept.len(), keep);
        let left = kept.iter().filter(|&&i| input[i as usize].x < 0.5).count();
        assert!(left as f32 > 0.7 * keep as f32, "left {left} of {keep}");
        // Deterministic.
        assert_eq!(kept, eliminate_scaled(&input, Some(&scales), keep, d));
    }

    #[test]
    fn trivial_cases() {
        let input = random_square(10, 1);
        assert_eq!(eliminate(&input, 20, 0.1).len(), 10);
        assert_eq!(eliminate(&input, 0, 0.1), Vec::<u32>::new());
        assert_eq!(eliminate(&input, 3, 0.0), vec![0, 1, 2]);
        assert!(eliminate(&[], 0, 1.0).is_empty());
    }
}
