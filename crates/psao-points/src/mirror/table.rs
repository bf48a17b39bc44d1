//! A mirror's bucket entries: one open-addressing table keyed by cell id, probed linearly
//! from a home position that depends on the entry's bucket alone, so a bucket's entries lie in
//! one probe run in the order they were inserted (a bucket reads back by scanning that run,
//! and a cell is found by its id in the same scan). Removal shifts the run back (no
//! tombstones); the table grows by [`GROWTH`] when more than [`MAX_LOAD`] of it is used.
//!
//! Positions are stored *quotiented* where they fit in 48 bits (6 bytes): the bucket `b` of
//! an entry is not stored but recovered from its position. Buckets are scrambled by a
//! bijection `h = b·S mod B` (`B` = bucket count, a power of two) and `h`'s home is
//! `⌊h·L / B⌋` for a table of `L` positions; an entry stores its distance from its home
//! (8 bits), the rest `h − first(home)` where `first` is the smallest `h` of that home, the
//! quotient `id / B` of its cell id and its slot. Tables whose entries do not fit (huge
//! grids, or very small tables, where the rest takes many bits) store the whole cell id and
//! slot in 12 bytes.

use crate::grid::{Bucket, BucketEntry};

/// Most entries per table position before the table grows. Linear probing stays short
/// enough (a miss scans about 12 positions at a load of 0.8, 22 at 0.85), and at a mean load
/// of about 0.8 the table costs 7.5 bytes per held cell.
const MAX_LOAD: f64 = 0.85;
/// Growth of the table when full: load falls to `MAX_LOAD / GROWTH`.
const GROWTH: f64 = 1.15;
/// Bits of a quotiented position holding its distance from home + 1 (0: empty position).
const SHIFT_BITS: u32 = 8;
/// Longest distance from home a quotiented position records; an insertion further away
/// grows the table instead.
const MAX_SHIFT: usize = (1 << SHIFT_BITS) - 2;
/// Bits of a quotiented position.
const NARROW_BITS: u32 = 48;
/// The odd multiplier scrambling buckets, and its inverse modulo 2⁶⁴.
const SCRAMBLE: u64 = 0x9e37_79b9_7f4a_7c15;
const UNSCRAMBLE: u64 = inverse(SCRAMBLE);

/// The inverse of odd `a` modulo 2⁶⁴ (Newton's iteration doubles the correct bits).
const fn inverse(a: u64) -> u64 {
    let mut x = a;
    let mut k = 0;
    while k < 6 {
        x = x.wrapping_mul(2u64.wrapping_sub(a.wrapping_mul(x)));
        k += 1;
    }
    x
}

/// Bits needed to write `x`.
fn bits(x: u64) -> u32 {
    64 - x.leading_zeros()
}

/// A position storing a whole cell key (id + 1; 0 when empty) and slot. Packed to 4-byte
/// alignment; fields are read by value.
#[derive(Clone, Copy, Default)]
#[repr(C, packed(4))]
struct Wide {
    key: u64,
    slot: u32,
}

/// Where bucket `b`'s run starts and what its quotiented entries record.
#[derive(Clone, Copy)]
struct Target {
    bucket: u64,
    home: usize,
    /// `h − first(home)`.
    rest: u64,
}

/// Bucket entries of one grid (see the module documentation).
#[derive(Clone, Debug)]
pub(super) struct CellTable {
    /// log2 of the bucket count.
    k: u32,
    /// Bits of a key quotient (`id >> k`) and of a slot, for quotiented positions.
    quotient_bits: u32,
    slot_bits: u32,
    /// Bits of the rest at the present table length (quotiented positions).
    rest_bits: u32,
    /// Quotiented positions (48-bit little-endian words), or empty when `wide` is used.
    narrow: Vec<[u8; 6]>,
    /// Whole positions, or empty when `narrow` is used.
    wide: Vec<Wide>,
    len: usize,
}

impl std::fmt::Debug for Wide {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (key, slot) = (self.key, self.slot);
        write!(f, "Wide {{ key: {key}, slot: {slot} }}")
    }
}

impl CellTable {
    /// An empty table for `bucket_count` buckets (a power of two), cell ids up to `max_id`
    /// and slots below `max_slots`.
    pub(super) fn new(bucket_count: u32, max_id: u64, max_slots: u64) -> Self {
        let k = bucket_count.max(1).trailing_zeros();
        Self {
            k,
            quotient_bits: bits(max_id >> k),
            slot_bits: bits(max_slots.saturating_sub(1)),
            rest_bits: 0,
            narrow: Vec::new(),
            wide: Vec::new(),
            len: 0,
        }
    }

    /// Entries held.
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// Whether positions are quotiented.
    #[cfg(test)]
    pub(super) fn is_narrow(&self) -> bool {
        !self.narrow.is_empty()
    }

    #[inline]
    fn cap(&self) -> usize {
        self.narrow.len().max(self.wide.len())
    }

    #[inline]
    fn mask(&self) -> u64 {
        (1u64 << self.k) - 1
    }

    #[inline]
    fn next(&self, i: usize) -> usize {
        if i + 1 == self.cap() {
            0
        } else {
            i + 1
        }
    }

    /// Home of scrambled bucket `h` in a table of `cap` positions.
    #[inline]
    fn home_of(&self, h: u64, cap: usize) -> usize {
        ((u128::from(h) * cap as u128) >> self.k) as usize
    }

    /// The smallest scrambled bucket whose home is `home` (table of `cap` positions).
    #[inline]
    fn first(&self, home: usize, cap: usize) -> u64 {
        ((home as u128) << self.k).div_ceil(cap as u128) as u64
    }

    /// Bucket `b`'s home and rest (table not empty).
    #[inline]
    fn target(&self, bucket: u64) -> Target {
        let h = bucket.wrapping_mul(SCRAMBLE) & self.mask();
        let home = self.home_of(h, self.cap());
        Target {
            bucket,
            home,
            rest: h - self.first(home, self.cap()),
        }
    }

    #[inline]
    fn word(&self, i: usize) -> u64 {
        let mut bytes = [0u8; 8];
        bytes[..6].copy_from_slice(&self.narrow[i]);
        u64::from_le_bytes(bytes)
    }

    #[inline]
    fn is_empty_at(&self, i: usize) -> bool {
        if self.narrow.is_empty() {
            let key = self.wide[i].key;
            key == 0
        } else {
            self.narrow[i] == [0; 6]
        }
    }

    /// Distance of position `i` from `home`, around the table.
    #[inline]
    fn distance(&self, i: usize, home: usize) -> usize {
        (i + self.cap() - home) % self.cap()
    }

    /// The home of the entry at non-empty position `i`.
    #[inline]
    fn home_at(&self, i: usize) -> usize {
        if self.narrow.is_empty() {
            let key = self.wide[i].key;
            let h = ((key - 1) & self.mask()).wrapping_mul(SCRAMBLE) & self.mask();
            self.home_of(h, self.cap())
        } else {
            let shift = (self.word(i) & 0xff) as usize - 1;
            (i + self.cap() - shift) % self.cap()
        }
    }

    /// Whether the entry at non-empty position `i` belongs to `t`'s bucket.
    #[inline]
    fn in_bucket(&self, i: usize, t: &Target) -> bool {
        if self.narrow.is_empty() {
            let key = self.wide[i].key;
            (key - 1) & self.mask() == t.bucket
        } else {
            let w = self.word(i);
            let rest = (w >> SHIFT_BITS) & ((1 << self.rest_bits) - 1);
            (w & 0xff) as usize == self.distance(i, t.home) + 1 && rest == t.rest
        }
    }

    /// Key and slot of the entry at position `i` of `t`'s bucket.
    #[inline]
    fn entry_at(&self, i: usize, t: &Target) -> (u64, u32) {
        if self.narrow.is_empty() {
            let e = self.wide[i];
            (e.key, e.slot)
        } else {
            let w = self.word(i) >> (SHIFT_BITS + self.rest_bits);
            let quotient = w & ((1 << self.quotient_bits) - 1);
            let slot = (w >> self.quotient_bits) & ((1 << self.slot_bits) - 1);
            (((quotient << self.k) | t.bucket) + 1, slot as u32)
        }
    }

    /// The bucket, key and slot of the entry at non-empty position `i`.
    fn decode(&self, i: usize) -> (u64, u64, u32) {
        if self.narrow.is_empty() {
            let e = self.wide[i];
            ((e.key - 1) & self.mask(), e.key, e.slot)
        } else {
            let home = self.home_at(i);
            let rest = (self.word(i) >> SHIFT_BITS) & ((1 << self.rest_bits) - 1);
            let h = self.first(home, self.cap()) + rest;
            let bucket = h.wrapping_mul(UNSCRAMBLE) & self.mask();
            let t = Target { bucket, home, rest };
            let (key, slot) = self.entry_at(i, &t);
            (bucket, key, slot)
        }
    }

    /// Positions of `t`'s probe run, in probe order, up to the first empty one.
    #[inline]
    fn run(&self, t: Target) -> impl Iterator<Item = usize> + '_ {
        let first = (self.cap() > 0).then_some(t.home);
        std::iter::successors(first, move |&i| Some(self.next(i)))
            .take_while(move |&i| !self.is_empty_at(i))
    }

    /// Slot of the entry with `key` (cell id + 1).
    #[inline]
    pub(super) fn find(&self, key: u64) -> Option<u32> {
        if self.len == 0 {
            return None;
        }
        let t = self.target((key - 1) & self.mask());
        let mut i = t.home;
        if self.narrow.is_empty() {
            while !self.is_empty_at(i) {
                let e = self.wide[i];
                if e.key == key {
                    return Some(e.slot);
                }
                i = self.next(i);
            }
            return None;
        }
        let quotient = (key - 1) >> self.k;
        if bits(quotient) > self.quotient_bits {
            return None; // no cell of the grid
        }
        // A quotiented entry of this key at distance d from home reads `base + d + 1` below
        // its slot bits.
        let low = SHIFT_BITS + self.rest_bits + self.quotient_bits;
        let base = (t.rest << SHIFT_BITS) | (quotient << (SHIFT_BITS + self.rest_bits));
        let mut expected = base + 1;
        while !self.is_empty_at(i) {
            let w = self.word(i);
            if w & ((1 << low) - 1) == expected {
                return Some((w >> low) as u32);
            }
            i = self.next(i);
            expected += 1;
            if expected & 0xff == 0 {
                // Past the longest distance a quotiented entry records.
                return None;
            }
        }
        None
    }

    /// Bucket `b`'s entries in the order they were inserted.
    pub(super) fn entries_of(&self, b: u64) -> impl Iterator<Item = BucketEntry> + '_ {
        let t = (self.len > 0).then(|| self.target(b));
        t.into_iter().flat_map(move |t| {
            self.run(t)
                .filter(move |&i| self.in_bucket(i, &t))
                .map(move |i| {
                    let (key, slot) = self.entry_at(i, &t);
                    BucketEntry { key, slot }
                })
        })
    }

    /// Replace bucket `b`'s entries with the used entries of `bucket`, in order.
    pub(super) fn set_bucket(&mut self, b: u64, bucket: &Bucket) {
        if self.len > 0 {
            let t = self.target(b);
            loop {
                let found = self.run(t).find(|&i| self.in_bucket(i, &t));
                match found {
                    Some(i) => self.remove_at(i),
                    None => break,
                }
            }
        }
        let used = bucket.entries.iter().filter(|e| e.key != 0);
        self.reserve(used.clone().count());
        for e in used {
            while !self.insert(b, e.key, e.slot) {
                self.rebuild(self.grown());
            }
        }
    }

    /// Store an entry at the end of bucket `b`'s run (room reserved); false, storing
    /// nothing, when a quotiented position would lie too far from home.
    fn insert(&mut self, b: u64, key: u64, slot: u32) -> bool {
        let t = self.target(b);
        let mut i = t.home;
        while !self.is_empty_at(i) {
            i = self.next(i);
        }
        if self.narrow.is_empty() {
            self.wide[i] = Wide { key, slot };
        } else {
            let shift = self.distance(i, t.home);
            if shift > MAX_SHIFT {
                return false;
            }
            let quotient = (key - 1) >> self.k;
            let w = (shift as u64 + 1)
                | (t.rest << SHIFT_BITS)
                | (quotient << (SHIFT_BITS + self.rest_bits))
                | (u64::from(slot) << (SHIFT_BITS + self.rest_bits + self.quotient_bits));
            self.narrow[i].copy_from_slice(&w.to_le_bytes()[..6]);
        }
        self.len += 1;
        true
    }

    /// Empty position `i`, shifting later entries of its run back so that every entry stays
    /// reachable from its home without an empty position between (their order is kept).
    fn remove_at(&mut self, mut hole: usize) {
        let mut j = self.next(hole);
        while !self.is_empty_at(j) {
            let home = self.home_at(j);
            // The entry may fill the hole when the hole lies between its home and it.
            if self.distance(j, home) >= self.distance(j, hole) {
                if self.narrow.is_empty() {
                    self.wide[hole] = self.wide[j];
                } else {
                    let shift = self.distance(hole, home) as u64 + 1;
                    let w = (self.word(j) & !0xff) | shift;
                    self.narrow[hole].copy_from_slice(&w.to_le_bytes()[..6]);
                }
                hole = j;
            }
            j = self.next(j);
        }
        if self.narrow.is_empty() {
            self.wide[hole] = Wide::default();
        } else {
            self.narrow[hole] = [0; 6];
        }
        self.len -= 1;
    }

    /// A length past the present one by [`GROWTH`].
    fn grown(&self) -> usize {
        (self.cap() as f64 * GROWTH).ceil() as usize + 8
    }

    /// Make room for `more` entries within [`MAX_LOAD`], rebuilding into a larger table.
    fn reserve(&mut self, more: usize) {
        let need = self.len + more;
        if (need as f64) <= MAX_LOAD * self.cap() as f64 {
            return;
        }
        let cap = ((need as f64 / MAX_LOAD) * GROWTH).ceil() as usize + 8;
        self.rebuild(cap);
    }

    /// Rebuild into a table of at least `cap` positions (quotiented when the entries fit),
    /// larger again until every quotiented entry lies near enough its home. Entries are
    /// re-inserted run by run from a run's start, so entries of one bucket keep their order.
    fn rebuild(&mut self, cap: usize) {
        let old = std::mem::replace(
            self,
            Self {
                narrow: Vec::new(),
                wide: Vec::new(),
                len: 0,
                ..*self
            },
        );
        let entries: Vec<(u64, u64, u32)> = match (0..old.cap()).find(|&i| old.is_empty_at(i)) {
            Some(start) => (1..=old.cap())
                .map(|k| (start + k) % old.cap())
                .filter(|&i| !old.is_empty_at(i))
                .map(|i| old.decode(i))
                .collect(),
            None => Vec::new(),
        };
        debug_assert_eq!(entries.len(), old.len);
        let mut cap = cap.max(1);
        loop {
            self.alloc(cap);
            if entries
                .iter()
                .all(|&(b, key, slot)| self.insert(b, key, slot))
            {
                return;
            }
            cap = (cap as f64 * GROWTH).ceil() as usize + 8;
        }
    }

    /// Empty positions for `cap` entries, quotiented when an entry fits in [`NARROW_BITS`].
    fn alloc(&mut self, cap: usize) {
        let homes_per_bucket = (1u64 << self.k).div_ceil(cap as u64);
        self.rest_bits = bits(homes_per_bucket);
        let fits = SHIFT_BITS + self.rest_bits + self.quotient_bits + self.slot_bits <= NARROW_BITS;
        self.len = 0;
        (self.narrow, self.wide) = if fits {
            (vec![[0; 6]; cap], Vec::new())
        } else {
            (Vec::new(), vec![Wide::default(); cap])
        };
    }

    /// Heap bytes (allocated positions, empty ones included).
    pub(super) fn heap_bytes(&self) -> u64 {
        (self.narrow.capacity() * 6 + self.wide.capacity() * std::mem::size_of::<Wide>()) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scrambling_is_a_bijection_and_homes_invert() {
        assert_eq!(SCRAMBLE.wrapping_mul(UNSCRAMBLE), 1);
        let t = CellTable::new(1 << 10, 1 << 20, 1 << 13);
        for cap in [1usize, 7, 100, 1000, 1024, 5000] {
            let mut seen = vec![false; 1 << 10];
            for b in 0..1u64 << 10 {
                let h = b.wrapping_mul(SCRAMBLE) & t.mask();
                assert!(!std::mem::replace(&mut seen[h as usize], true));
                assert_eq!(h.wrapping_mul(UNSCRAMBLE) & t.mask(), b);
                let home = t.home_of(h, cap);
                assert!(home < cap);
                let first = t.first(home, cap);
                assert!(first <= h && t.home_of(first, cap) == home);
                assert!(first == 0 || t.home_of(first - 1, cap) < home);
                assert!(bits(h - first) <= bits((1u64 << 10).div_ceil(cap as u64)));
            }
        }
    }
}
