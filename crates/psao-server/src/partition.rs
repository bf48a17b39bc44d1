//! Splitting a scene's points between trace nodes (docs/SCALE-OUT.md): the units are the
//! culling blocks of every instance (runs of Morton-ordered points, see `blocks.rs`), taken
//! in (instance, block) order and cut into `n` contiguous runs of about equal point count.
//! The cut depends only on the scene's points, so every node computes the same owners.

use std::fmt;
use std::str::FromStr;

/// Partition `index` of `count` (`psao trace-node --partition k/n`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Partition {
    /// 0-based index, below `count`.
    pub index: u32,
    /// Number of partitions, at least 1.
    pub count: u32,
}

/// Most partitions of a scene (owners are stored as `u16`).
pub const MAX_PARTITIONS: u32 = 1024;

/// Why a partition text was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("partition `{text}`: {reason} (expected k/n with 0 <= k < n <= {MAX_PARTITIONS})")]
pub struct PartitionError {
    text: String,
    reason: &'static str,
}

impl FromStr for Partition {
    type Err = PartitionError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let fail = |reason| PartitionError {
            text: text.to_string(),
            reason,
        };
        let (k, n) = text.split_once('/').ok_or_else(|| fail("no `/`"))?;
        let index: u32 = k.trim().parse().map_err(|_| fail("k is not a number"))?;
        let count: u32 = n.trim().parse().map_err(|_| fail("n is not a number"))?;
        if count == 0 || count > MAX_PARTITIONS {
            return Err(fail("n out of range"));
        }
        if index >= count {
            return Err(fail("k must be below n"));
        }
        Ok(Partition { index, count })
    }
}

impl fmt::Display for Partition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The partition (0..`n`) of each unit of `sizes` (point counts, in a stable order): `n`
/// contiguous runs, a unit going to the partition its first point falls in when the total
/// is cut into `n` equal shares. Runs may be empty when one unit outweighs a share.
pub fn balanced_runs(sizes: &[u64], n: u32) -> Vec<u32> {
    let n = u64::from(n.max(1));
    let total: u64 = sizes.iter().sum::<u64>().max(1);
    let mut start = 0u64;
    sizes
        .iter()
        .map(|&s| {
            // The unit's middle point decides, so a big unit goes where most of it lies.
            let middle = start + s / 2;
            start += s;
            ((u128::from(middle) * u128::from(n) / u128::from(total)) as u64).min(n - 1) as u32
        })
        .collect()
}

/// Which partition owns each point of each instance.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Owners {
    count: u32,
    /// Per instance, per point index: the owning partition.
    of: Vec<Vec<u16>>,
}

impl Owners {
    /// Owners from per-instance blocks: `blocks[i]` lists instance `i`'s blocks, each the
    /// point indices it holds.
    pub(crate) fn from_blocks(blocks: &[Vec<&[u32]>], points: &[usize], count: u32) -> Owners {
        let sizes: Vec<u64> = blocks
            .iter()
            .flat_map(|bs| bs.iter().map(|b| b.len() as u64))
            .collect();
        let mut runs = balanced_runs(&sizes, count).into_iter();
        let of = blocks
            .iter()
            .zip(points)
            .map(|(bs, &n)| {
                let mut owner = vec![0u16; n];
                for b in bs {
                    let k = runs.next().unwrap_or(0) as u16;
                    for &i in b.iter() {
                        owner[i as usize] = k;
                    }
                }
                owner
            })
            .collect();
        Owners { count, of }
    }

    /// Number of partitions.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The partition owning point `index` of `instance` (0 when out of range).
    pub fn owner(&self, instance: u32, index: u32) -> u32 {
        self.of
            .get(instance as usize)
            .and_then(|o| o.get(index as usize))
            .map_or(0, |&k| u32::from(k))
    }

    /// The snapshot chunk of every point (per instance, per point index): its ordinal among
    /// its partition's points in (instance, index) order, divided by `chunk_points` (at
    /// least 1). A chunk therefore names the same points every time.
    pub fn chunks(&self, chunk_points: usize) -> Vec<Vec<u32>> {
        let chunk_points = chunk_points.max(1);
        let mut ordinal = vec![0usize; self.count as usize];
        self.of
            .iter()
            .map(|owners| {
                owners
                    .iter()
                    .map(|&k| {
                        let n = &mut ordinal[k as usize];
                        let chunk = *n / chunk_points;
                        *n += 1;
                        chunk as u32
                    })
                    .collect()
            })
            .collect()
    }

    /// Points owned by each partition.
    pub fn points_per_partition(&self) -> Vec<u64> {
        let mut n = vec![0u64; self.count as usize];
        for &k in self.of.iter().flatten() {
            n[k as usize] += 1;
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses_partitions() {
        assert_eq!(
            "1/4".parse::<Partition>(),
            Ok(Partition { index: 1, count: 4 })
        );
        assert_eq!("1/4".parse::<Partition>().unwrap().to_string(), "1/4");
        for bad in ["", "1", "4/4", "0/0", "a/2", "1/b", "0/1025", "-1/2"] {
            let e = bad.parse::<Partition>().unwrap_err();
            assert!(e.to_string().contains("expected k/n"), "{bad}: {e}");
        }
        assert!("1023/1024".parse::<Partition>().is_ok());
    }

    #[test]
    fn runs_are_contiguous_balanced_and_stable() {
        let sizes: Vec<u64> = (0..100).map(|i| 512 - (i % 7) * 60).collect();
        let total: u64 = sizes.iter().sum();
        for n in [1, 2, 3, 4, 7] {
            let runs = balanced_runs(&sizes, n);
            assert_eq!(runs, balanced_runs(&sizes, n), "stable");
            assert!(runs.windows(2).all(|w| w[0] <= w[1]), "contiguous");
            assert_eq!(runs.last(), Some(&(n - 1)));
            let mut load = vec![0u64; n as usize];
            for (s, k) in sizes.iter().zip(&runs) {
                load[*k as usize] += s;
            }
            let share = total / u64::from(n);
            for l in load {
                // Off a share by at most one unit.
                assert!(l.abs_diff(share) <= 512, "n={n}: {l} vs {share}");
            }
        }
        // One huge unit: the others still get partitions, never an index out of range.
        let runs = balanced_runs(&[10, 1_000_000, 10], 4);
        assert!(runs.iter().all(|&k| k < 4));
        assert!(balanced_runs(&[], 3).is_empty());
        assert_eq!(balanced_runs(&[0, 0], 2), vec![0, 0]);
    }

    #[test]
    fn owners_cover_every_point() {
        let a: Vec<u32> = (0..6).collect();
        let b: Vec<u32> = (6..10).collect();
        let c: Vec<u32> = vec![2, 0, 1];
        let blocks = vec![vec![&a[..], &b[..]], vec![&c[..]]];
        let owners = Owners::from_blocks(&blocks, &[10, 3], 2);
        assert_eq!(owners.points_per_partition().iter().sum::<u64>(), 13);
        assert_eq!(owners.owner(0, 0), 0);
        assert_eq!(owners.owner(1, 2), 1);
        assert_eq!(owners.owner(9, 9), 0, "out of range");
        // Chunks of 3: partition 0 holds points 0..6 of instance 0 (chunks 0, 0, 0, 1, 1, 1).
        let chunks = owners.chunks(3);
        assert_eq!(chunks[0][..6], [0, 0, 0, 1, 1, 1]);
        assert_eq!(
            chunks[0][6..],
            [0, 0, 0, 1],
            "partition 1 starts again at chunk 0"
        );
        assert_eq!(chunks[1], [1, 1, 2]);
    }
}
