//! Brick deduplication by k-means (thesis §4.5): only bricks whose normalised variance
//! (variance of the range-normalised values divided by their mean) is under a threshold take
//! part; distances are normalised Manhattan distances (mean absolute difference of the
//! range-normalised values). Bricks of a cluster are replaced by its centre.

use crate::error::{Result, VolumeError};
use crate::grid::BRICK_VOXELS;
use crate::rng::Rng;
use rayon::prelude::*;

/// Clustering parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterParams {
    /// Number of cluster centres.
    pub k: usize,
    /// k-means iterations.
    pub iterations: usize,
    /// Normalised-variance threshold: bricks above it are kept as they are.
    pub threshold: f32,
    /// Seed of the initial centre choice.
    pub seed: u64,
}

/// Result of clustering.
#[derive(Clone, Debug)]
pub struct Clustering {
    /// The new bricks: the kept ones, then the used centres.
    pub bricks: Vec<[f32; BRICK_VOXELS]>,
    /// For each input brick, its index in `bricks`.
    pub remap: Vec<u32>,
    /// Bricks that took part in k-means.
    pub candidates: usize,
}

/// Mean absolute difference of two bricks (values already normalised), 8 lanes at a time.
#[inline]
pub fn manhattan(a: &[f32; BRICK_VOXELS], b: &[f32; BRICK_VOXELS]) -> f32 {
    let mut acc = [0.0f32; 8];
    for (ca, cb) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += (ca[l] - cb[l]).abs();
        }
    }
    acc.iter().sum::<f32>() / BRICK_VOXELS as f32
}

/// Variance of a brick's normalised values divided by their mean (0 for an all-zero brick).
pub fn normalised_variance(b: &[f32; BRICK_VOXELS]) -> f32 {
    let n = BRICK_VOXELS as f32;
    let mean = b.iter().sum::<f32>() / n;
    if mean <= 0.0 {
        return 0.0;
    }
    let var = b.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n;
    var / mean
}

fn nearest(b: &[f32; BRICK_VOXELS], centres: &[[f32; BRICK_VOXELS]]) -> u32 {
    let mut best = (f32::INFINITY, 0u32);
    for (j, c) in centres.iter().enumerate() {
        let d = manhattan(b, c);
        if d < best.0 {
            best = (d, j as u32);
        }
    }
    best.1
}

/// Clusters `bricks` whose values span `lo..=hi`.
pub fn cluster(
    bricks: &[[f32; BRICK_VOXELS]],
    lo: f32,
    hi: f32,
    params: &ClusterParams,
) -> Result<Clustering> {
    if params.k == 0
        || params.iterations == 0
        || params.threshold.is_nan()
        || params.threshold < 0.0
    {
        return Err(VolumeError::InvalidParameter(format!(
            "clustering needs k >= 1, iterations >= 1 and threshold >= 0 (got {params:?})"
        )));
    }
    let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    let norm: Vec<[f32; BRICK_VOXELS]> = bricks
        .par_iter()
        .map(|b| {
            let mut n = [0.0; BRICK_VOXELS];
            for (o, v) in n.iter_mut().zip(b) {
                *o = (v - lo) * scale;
            }
            n
        })
        .collect();
    let candidates: Vec<usize> = (0..bricks.len())
        .filter(|&i| normalised_variance(&norm[i]) < params.threshold)
        .collect();
    if candidates.len() <= params.k {
        return Ok(Clustering {
            bricks: bricks.to_vec(),
            remap: (0..bricks.len() as u32).collect(),
            candidates: candidates.len(),
        });
    }
    // Seeded choice of k distinct initial centres (partial Fisher-Yates).
    let mut rng = Rng::new(params.seed, 0x5eed);
    let mut pick = candidates.clone();
    for i in 0..params.k {
        let j = i + (rng.next_u32() as usize % (pick.len() - i));
        pick.swap(i, j);
    }
    let mut centres: Vec<[f32; BRICK_VOXELS]> = pick[..params.k].iter().map(|&i| norm[i]).collect();
    let mut assign: Vec<u32> = Vec::new();
    for it in 0..=params.iterations {
        assign = candidates
            .par_iter()
            .map(|&i| nearest(&norm[i], &centres))
            .collect();
        if it == params.iterations {
            break;
        }
        let mut sums = vec![[0.0f32; BRICK_VOXELS]; params.k];
        let mut counts = vec![0u32; params.k];
        for (&i, &c) in candidates.iter().zip(&assign) {
            counts[c as usize] += 1;
            for (s, v) in sums[c as usize].iter_mut().zip(&norm[i]) {
                *s += v;
            }
        }
        for ((centre, sum), &n) in centres.iter_mut().zip(&sums).zip(&counts) {
            if n > 0 {
                for (c, s) in centre.iter_mut().zip(sum) {
                    *c = s / n as f32;
                }
            }
        }
    }
    let mut is_candidate = vec![false; bricks.len()];
    for &i in &candidates {
        is_candidate[i] = true;
    }
    let mut out = Vec::new();
    let mut remap = vec![0u32; bricks.len()];
    for (i, b) in bricks.iter().enumerate() {
        if !is_candidate[i] {
            remap[i] = out.len() as u32;
            out.push(*b);
        }
    }
    let mut centre_slot = vec![u32::MAX; params.k];
    for (&i, &c) in candidates.iter().zip(&assign) {
        if centre_slot[c as usize] == u32::MAX {
            centre_slot[c as usize] = out.len() as u32;
            let mut b = [0.0; BRICK_VOXELS];
            for (o, v) in b.iter_mut().zip(&centres[c as usize]) {
                *o = lo + v * (hi - lo);
            }
            out.push(b);
        }
        remap[i] = centre_slot[c as usize];
    }
    Ok(Clustering {
        bricks: out,
        remap,
        candidates: candidates.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_duplicates_merge_and_detailed_bricks_stay() {
        let mut bricks = Vec::new();
        for i in 0..40 {
            bricks.push([0.5 + (i % 4) as f32 * 1e-3; BRICK_VOXELS]);
        }
        let mut noisy = [0.0; BRICK_VOXELS];
        for (j, v) in noisy.iter_mut().enumerate() {
            *v = (j % 2) as f32;
        }
        bricks.push(noisy);
        let p = ClusterParams {
            k: 2,
            iterations: 5,
            threshold: 0.1,
            seed: 1,
        };
        let c = cluster(&bricks, 0.0, 1.0, &p).unwrap();
        assert_eq!(c.candidates, 40);
        assert!(c.bricks.len() <= 3);
        assert_eq!(c.bricks[c.remap[40] as usize], noisy);
        for (i, orig) in bricks.iter().enumerate().take(40) {
            let b = &c.bricks[c.remap[i] as usize];
            assert!((b[0] - orig[0]).abs() < 3e-3);
        }
        let again = cluster(&bricks, 0.0, 1.0, &p).unwrap();
        assert_eq!(again.remap, c.remap);
        assert!(cluster(&bricks, 0.0, 1.0, &ClusterParams { k: 0, ..p }).is_err());
    }
}
