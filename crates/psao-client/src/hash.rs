//! A deterministic fingerprint of point-grid contents, so that a client's mirror can be
//! compared with the server's grids without shipping them.
//!
//! Words are folded with `h = (rotl(h, 5) ^ w) · K` (K odd): for fixed other words every
//! step is a bijection of both `h` and `w`, so two states that differ in exactly one word
//! always hash differently; a 64-bit finaliser spreads the result. Buckets and cells are
//! hashed in their compacted form (used entries first, in order; the form updates carry),
//! so a server grid and a client mirror of it hash alike.
//!
//! Irradiance records (DESIGN §12) are folded in per instance only when some record of its
//! used cells is non-zero: an AO-only state hashes exactly as before lighting existed.

use psao_delta::{compact_bucket, compact_cell};
use psao_points::{Bucket, Cell, InstanceGrid, MirrorGrid, CELL_POINTS};

const MULTIPLIER: u64 = 0x517c_c1b7_2722_0a95;
/// Word folded in for an instance without a grid.
const NO_GRID: u64 = 0x6e6f_5f67_7269_6421;
/// Word folded in before an instance's irradiance records.
const LIGHTS: u64 = 0x6c69_6768_745f_7265;

/// Incremental word hasher.
struct Hasher(u64);

impl Hasher {
    #[inline]
    fn word(&mut self, w: u64) {
        self.0 = (self.0.rotate_left(5) ^ w).wrapping_mul(MULTIPLIER);
    }

    fn finish(&self) -> u64 {
        // SplitMix64 finaliser.
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
}

/// What the state hash reads of a grid: a server's [`InstanceGrid`] and a client's
/// [`MirrorGrid`] of it give the same words.
pub trait HashedGrid {
    /// Number of hash buckets.
    fn bucket_count(&self) -> usize;
    /// Every bucket in index order, compacted (used entries first, in order).
    fn compact_buckets(&self) -> impl Iterator<Item = Bucket> + '_;
    /// Number of cell slots written (cells past it read as empty).
    fn slot_count(&self) -> usize;
    /// The cell in `slot`, compacted (valid points first, in order).
    fn compact_cell(&self, slot: u32) -> Cell;
}

impl HashedGrid for InstanceGrid {
    fn bucket_count(&self) -> usize {
        InstanceGrid::bucket_count(self)
    }
    fn compact_buckets(&self) -> impl Iterator<Item = Bucket> + '_ {
        self.buckets().map(|b| compact_bucket(&b))
    }
    fn slot_count(&self) -> usize {
        InstanceGrid::slot_count(self)
    }
    fn compact_cell(&self, slot: u32) -> Cell {
        compact_cell(self.cell(slot))
    }
}

impl HashedGrid for MirrorGrid {
    fn bucket_count(&self) -> usize {
        MirrorGrid::bucket_count(self)
    }
    fn compact_buckets(&self) -> impl Iterator<Item = Bucket> + '_ {
        self.buckets()
    }
    fn slot_count(&self) -> usize {
        MirrorGrid::slot_count(self)
    }
    fn compact_cell(&self, slot: u32) -> Cell {
        self.cell(slot)
    }
}

/// Hash of the buckets and cells of a sequence of grids (`None` = an instance without a grid),
/// instance by instance, each bucket and cell compacted. Trailing cell slots without points are
/// ignored, so a mirror that never received a freed trailing slot hashes like the server grid
/// that still has it; so are counters, free lists and transforms. [`crate::ClientState::state_hash`]
/// uses [`lit_state_hash_of`]; a server without lighting calls this on its own grids
/// (`grids.iter().map(Some)`) to compare.
pub fn state_hash_of<'a, G, I>(grids: I) -> u64
where
    G: HashedGrid + 'a,
    I: IntoIterator<Item = Option<&'a G>>,
{
    lit_state_hash_of(grids, |_, _| [0; CELL_POINTS])
}

/// [`state_hash_of`] also covering irradiance records: `lights(instance, slot)` gives the
/// records of a cell slot (zeros where none). An instance's records (those of its used slots)
/// are folded in after its cells, and only when one of them is non-zero, so without lighting
/// the hash is [`state_hash_of`]'s.
pub fn lit_state_hash_of<'a, G, I, L>(grids: I, lights: L) -> u64
where
    G: HashedGrid + 'a,
    I: IntoIterator<Item = Option<&'a G>>,
    L: Fn(usize, u32) -> [u32; CELL_POINTS],
{
    let mut h = Hasher(0x243f_6a88_85a3_08d3);
    let mut instances = 0u64;
    for (index, grid) in grids.into_iter().enumerate() {
        instances += 1;
        let Some(grid) = grid else {
            h.word(NO_GRID);
            continue;
        };
        h.word(grid.bucket_count() as u64);
        for bucket in grid.compact_buckets() {
            for e in &bucket.entries {
                h.word(e.key);
                h.word(u64::from(e.slot));
            }
        }
        let used = (0..grid.slot_count() as u32)
            .rev()
            .find(|&s| grid.compact_cell(s).count() > 0)
            .map_or(0, |last| last + 1);
        h.word(u64::from(used));
        for slot in 0..used {
            fold_pairs(&mut h, &grid.compact_cell(slot).points);
        }
        if (0..used).any(|s| lights(index, s) != [0; CELL_POINTS]) {
            h.word(LIGHTS);
            for s in 0..used {
                fold_pairs(&mut h, &lights(index, s));
            }
        }
    }
    h.word(instances);
    h.finish()
}

/// Folds 32-bit words two at a time (an odd last word with a zero high half).
fn fold_pairs(h: &mut Hasher, words: &[u32]) {
    for pair in words.chunks(2) {
        let hi = pair.get(1).map_or(0, |&w| u64::from(w) << 32);
        h.word(hi | u64::from(pair[0]));
    }
}
