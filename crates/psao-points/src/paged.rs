//! Sparse storage behind [`crate::InstanceGrid`]: a paged vector whose pages are allocated on
//! first write, and a hash-bucket table that stores only the entries in use.
//!
//! A grid's logical arrays (every bucket of the table, every cell slot) stay addressable by
//! index, which is what the wire names; what is stored is what was written. A client mirror
//! thereby costs what it holds, a server grid what it uses.

use crate::grid::{Bucket, BucketEntry};
use crate::layout::BUCKET_ENTRIES;
use crate::PointsError;

/// Elements per page of a [`Paged`] vector.
const PAGE: usize = 64;

/// A vector of `len` elements stored in pages of [`PAGE`] elements, each allocated when an
/// element in it is first written; absent pages read as `T::default()`.
#[derive(Clone, Debug, Default)]
pub struct Paged<T> {
    pages: Vec<Option<Box<[T; PAGE]>>>,
    len: usize,
}

impl<T: Copy + Default> Paged<T> {
    /// `len` default elements, no page allocated.
    pub fn new(len: usize) -> Self {
        Self {
            pages: vec![None; len.div_ceil(PAGE)],
            len,
        }
    }

    /// Logical length.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when the logical length is 0.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The element at `i` if its page exists (`None` when absent or past the end).
    #[inline]
    pub fn get(&self, i: usize) -> Option<&T> {
        self.pages.get(i / PAGE)?.as_ref().map(|p| &p[i % PAGE])
    }

    /// The element at `i`, `T::default()` when absent or past the end.
    #[inline]
    pub fn value(&self, i: usize) -> T {
        self.get(i).copied().unwrap_or_default()
    }

    /// Grow the logical length to at least `len` (new elements read as default).
    pub fn grow(&mut self, len: usize) {
        if len > self.len {
            self.len = len;
            self.pages.resize(len.div_ceil(PAGE), None);
        }
    }

    /// The element at `i < len`, allocating its page on first write.
    #[inline]
    pub fn get_mut(&mut self, i: usize) -> &mut T {
        debug_assert!(i < self.len);
        let page = self.pages[i / PAGE].get_or_insert_with(|| Box::new([T::default(); PAGE]));
        &mut page[i % PAGE]
    }

    /// Store `value` at `i < len`; writing the default into an absent page allocates nothing.
    pub fn set(&mut self, i: usize, value: T)
    where
        T: PartialEq,
    {
        if value == T::default() && self.get(i).is_none() {
            return;
        }
        *self.get_mut(i) = value;
    }

    /// Heap bytes: the page table plus the allocated pages.
    pub fn heap_bytes(&self) -> u64 {
        self.page_table_bytes() + self.page_bytes()
    }

    /// Heap bytes of the page table (one pointer per page, allocated or not).
    pub fn page_table_bytes(&self) -> u64 {
        (self.pages.capacity() * std::mem::size_of::<Option<Box<[T; PAGE]>>>()) as u64
    }

    /// Heap bytes of the allocated pages.
    pub fn page_bytes(&self) -> u64 {
        let present = self.pages.iter().filter(|p| p.is_some()).count();
        (present * PAGE * std::mem::size_of::<T>()) as u64
    }
}

/// Bits of [`ChainEntry::link`] holding the next entry (+1; 0 ends the chain).
const NEXT_BITS: u32 = 29;
const NEXT_MASK: u32 = (1 << NEXT_BITS) - 1;
/// Most entries a table can hold at once (every index must fit in [`NEXT_BITS`]).
const MAX_ENTRIES: usize = NEXT_MASK as usize - 1;

/// One used bucket entry, linked to the next entry of its bucket (or of the free list).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, packed(4))]
struct ChainEntry {
    key: u64,
    slot: u32,
    /// Low [`NEXT_BITS`] bits: next entry + 1 (0 = end); high bits: the entry's position in
    /// its bucket, `0..BUCKET_ENTRIES`.
    link: u32,
}

impl ChainEntry {
    #[inline]
    fn next(&self) -> Option<usize> {
        ((self.link & NEXT_MASK) as usize).checked_sub(1)
    }

    #[inline]
    fn position(&self) -> usize {
        (self.link >> NEXT_BITS) as usize
    }

    fn link(position: usize, next: Option<usize>) -> u32 {
        ((position as u32) << NEXT_BITS) | next.map_or(0, |n| n as u32 + 1)
    }
}

/// A table of hash buckets that stores only used entries: per bucket the head of a chain of
/// entries ordered by their position in the bucket (so a bucket reads back exactly as it was
/// written, holes included). Heads live in a [`Paged`] vector, entries in one pool.
#[derive(Clone, Debug, Default)]
pub(crate) struct BucketTable {
    /// Per bucket: first entry + 1 (0 = empty bucket).
    heads: Paged<u32>,
    entries: Vec<ChainEntry>,
    /// First free entry + 1 (0 = none), chained through `link`.
    free: u32,
    used: usize,
}

impl BucketTable {
    /// `count` empty buckets.
    pub fn new(count: usize) -> Self {
        Self {
            heads: Paged::new(count),
            ..Self::default()
        }
    }

    /// Number of buckets.
    pub fn len(&self) -> usize {
        self.heads.len()
    }

    /// Number of used entries over all buckets.
    pub fn used(&self) -> usize {
        self.used
    }

    /// Heap bytes of the per-bucket chain heads (page table and pages).
    pub fn head_bytes(&self) -> u64 {
        self.heads.heap_bytes()
    }

    /// Heap bytes of the entry pool (16 bytes per entry, free ones and spare capacity included).
    pub fn entry_bytes(&self) -> u64 {
        crate::vec_bytes(&self.entries)
    }

    /// Indices of bucket `b`'s entries, in position order.
    #[inline]
    fn chain(&self, b: usize) -> impl Iterator<Item = usize> + '_ {
        let first = (self.heads.value(b) as usize).checked_sub(1);
        std::iter::successors(first, |&e| self.entries[e].next())
    }

    /// Slot of the first entry of bucket `b` with `key`.
    #[inline]
    pub fn find(&self, b: usize, key: u64) -> Option<u32> {
        self.chain(b)
            .map(|e| self.entries[e])
            .find(|e| e.key == key)
            .map(|e| e.slot)
    }

    /// Number of used entries of bucket `b`.
    pub fn len_of(&self, b: usize) -> usize {
        self.chain(b).count()
    }

    /// Bucket `b` as stored (empty entries where nothing was written).
    pub fn bucket(&self, b: usize) -> Bucket {
        let mut out = Bucket::default();
        for e in self.chain(b).map(|e| self.entries[e]) {
            out.entries[e.position()] = BucketEntry {
                key: e.key,
                slot: e.slot,
            };
        }
        out
    }

    /// Replace bucket `b < len` with `bucket` (its used entries keep their positions).
    pub fn set(&mut self, b: usize, bucket: &Bucket) -> Result<(), PointsError> {
        let new = bucket.entries.iter().filter(|e| e.key != 0).count();
        if self.used - self.len_of(b) + new > MAX_ENTRIES {
            return Err(PointsError::TooManyEntries { max: MAX_ENTRIES });
        }
        self.clear(b);
        let mut next = None;
        for (position, e) in bucket.entries.iter().enumerate().rev() {
            if e.key != 0 {
                next = Some(self.alloc(e.key, e.slot, position, next));
            }
        }
        self.heads.set(b, next.map_or(0, |n| n as u32 + 1));
        Ok(())
    }

    /// Store (`key`, `slot`) at the first free position of bucket `b`; `None` when full.
    pub fn insert(&mut self, b: usize, key: u64, slot: u32) -> Result<Option<usize>, PointsError> {
        if self.used >= MAX_ENTRIES {
            return Err(PointsError::TooManyEntries { max: MAX_ENTRIES });
        }
        // The first position not taken, and the entry after which it goes.
        let mut position = 0;
        let mut before = None;
        for e in self.chain(b) {
            if self.entries[e].position() != position {
                break;
            }
            position += 1;
            before = Some(e);
        }
        if position >= BUCKET_ENTRIES {
            return Ok(None);
        }
        let after = match before {
            Some(e) => self.entries[e].next(),
            None => (self.heads.value(b) as usize).checked_sub(1),
        };
        let new = self.alloc(key, slot, position, after);
        match before {
            Some(e) => self.relink(e, Some(new)),
            None => self.heads.set(b, new as u32 + 1),
        }
        Ok(Some(position))
    }

    /// Remove the first entry of bucket `b` with `key` (its position becomes a hole).
    pub fn remove(&mut self, b: usize, key: u64) {
        let mut before = None;
        let mut found = None;
        for e in self.chain(b) {
            if self.entries[e].key == key {
                found = Some(e);
                break;
            }
            before = Some(e);
        }
        let Some(e) = found else { return };
        let after = self.entries[e].next();
        match before {
            Some(p) => self.relink(p, after),
            None => self.heads.set(b, after.map_or(0, |n| n as u32 + 1)),
        }
        self.release(e);
    }

    /// Empty bucket `b`.
    fn clear(&mut self, b: usize) {
        let chain: Vec<usize> = self.chain(b).collect();
        for e in chain {
            self.release(e);
        }
        self.heads.set(b, 0);
    }

    fn relink(&mut self, e: usize, next: Option<usize>) {
        let position = self.entries[e].position();
        self.entries[e].link = ChainEntry::link(position, next);
    }

    fn alloc(&mut self, key: u64, slot: u32, position: usize, next: Option<usize>) -> usize {
        let entry = ChainEntry {
            key,
            slot,
            link: ChainEntry::link(position, next),
        };
        self.used += 1;
        match (self.free as usize).checked_sub(1) {
            Some(e) => {
                self.free = self.entries[e].link & NEXT_MASK;
                self.entries[e] = entry;
                e
            }
            None => {
                self.entries.push(entry);
                self.entries.len() - 1
            }
        }
    }

    fn release(&mut self, e: usize) {
        self.entries[e] = ChainEntry {
            key: 0,
            slot: 0,
            link: self.free,
        };
        self.free = e as u32 + 1;
        self.used -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bucket(entries: &[(usize, u64, u32)]) -> Bucket {
        let mut b = Bucket::default();
        for &(p, key, slot) in entries {
            b.entries[p] = BucketEntry { key, slot };
        }
        b
    }

    #[test]
    fn paged_vectors_allocate_pages_on_first_write() {
        let mut v: Paged<u64> = Paged::new(1000);
        assert_eq!((v.len(), v.value(999), v.get(5)), (1000, 0, None));
        let empty = v.heap_bytes();
        v.set(3, 0);
        assert_eq!(
            v.heap_bytes(),
            empty,
            "writing the default allocates nothing"
        );
        v.set(130, 7);
        assert_eq!(v.value(130), 7);
        assert_eq!(v.get(129), Some(&0));
        assert_eq!(v.heap_bytes(), empty + 8 * PAGE as u64);
        v.grow(2000);
        assert_eq!((v.len(), v.value(130), v.value(1999)), (2000, 7, 0));
        assert_eq!(v.value(5000), 0, "past the end reads as default");
    }

    #[test]
    fn buckets_read_back_as_written_and_insert_fills_holes_first() {
        let mut t = BucketTable::new(4);
        let b = bucket(&[(1, 11, 3), (4, 12, 9), (7, 13, 2)]);
        t.set(2, &b).unwrap();
        assert_eq!(t.bucket(2), b);
        assert_eq!(t.bucket(1), Bucket::default());
        assert_eq!((t.len_of(2), t.used()), (3, 3));
        assert_eq!(t.find(2, 12), Some(9));
        assert_eq!(t.find(2, 14), None);
        assert_eq!(t.insert(2, 20, 5).unwrap(), Some(0));
        assert_eq!(t.insert(2, 21, 6).unwrap(), Some(2));
        t.remove(2, 12);
        assert_eq!(t.insert(2, 22, 7).unwrap(), Some(3));
        assert_eq!(t.insert(2, 23, 8).unwrap(), Some(4));
        assert_eq!(
            t.bucket(2),
            bucket(&[
                (0, 20, 5),
                (1, 11, 3),
                (2, 21, 6),
                (3, 22, 7),
                (4, 23, 8),
                (7, 13, 2)
            ])
        );
        assert_eq!(t.insert(2, 24, 1).unwrap(), Some(5));
        assert_eq!(t.insert(2, 25, 1).unwrap(), Some(6));
        assert_eq!(t.insert(2, 26, 1).unwrap(), None, "full");
        // Freed entries are reused: replacing the bucket does not grow the pool.
        let pool = t.entries.len();
        t.set(2, &bucket(&[(5, 30, 1)])).unwrap();
        t.set(3, &bucket(&[(0, 31, 1), (1, 32, 2)])).unwrap();
        assert_eq!((t.used(), t.entries.len()), (3, pool));
        t.set(2, &Bucket::default()).unwrap();
        assert_eq!((t.len_of(2), t.used()), (0, 2));
    }
}
