//! Short runs of records addressed by a dense index, stored for what they hold: per page of
//! [`SLOTS`] indices, a 4-bit record count per index and one vector of the page's records,
//! index after index. An index's records start where the counts of the indices before it in
//! the page add up to (a few word operations), so a held run costs its records plus its share
//! of its page (counts, vector header, spare room), and indices nobody wrote cost nothing
//! beyond the page table. A client mirror's cells are kept this way, and the compact
//! encoder's reference (psao-delta) keeps its buckets and cells this way.

/// Indices per page.
const SLOTS: usize = 64;
/// Indices whose counts share one word.
const PER_WORD: usize = 16;
/// Records of spare room a page's vector gets when it must grow (so that a run gaining
/// records does not reallocate its page every time).
const SPARE: usize = 4;
/// Most records one index may hold (its count has 4 bits).
pub const MAX_RUN: usize = 15;

/// One page of indices.
#[derive(Clone, Debug)]
struct Page<T> {
    /// 4-bit record count per index.
    counts: [u64; SLOTS / PER_WORD],
    /// The records of the page's indices, in index order.
    records: Vec<T>,
}

impl<T> Default for Page<T> {
    fn default() -> Self {
        Self {
            counts: [0; SLOTS / PER_WORD],
            records: Vec::new(),
        }
    }
}

/// Sum of the sixteen 4-bit fields of `x`.
#[inline]
fn nibble_sum(x: u64) -> usize {
    const LOW: u64 = 0x0f0f_0f0f_0f0f_0f0f;
    let bytes = (x & LOW) + ((x >> 4) & LOW);
    (bytes.wrapping_mul(0x0101_0101_0101_0101) >> 56) as usize
}

impl<T: Copy> Page<T> {
    /// Where index `j` (of this page) starts in `records`, and its record count.
    #[inline]
    fn span(&self, j: usize) -> (usize, usize) {
        let (w, shift) = (j / PER_WORD, 4 * (j % PER_WORD));
        let before: usize = self.counts[..w].iter().map(|&c| nibble_sum(c)).sum();
        let word = self.counts[w];
        let below = word & ((1u64 << shift) - 1);
        (before + nibble_sum(below), ((word >> shift) & 15) as usize)
    }

    /// Replace index `j`'s records with `new` (at most [`MAX_RUN`]).
    fn set(&mut self, j: usize, new: &[T]) {
        let (offset, count) = self.span(j);
        if count == new.len() {
            self.records[offset..offset + count].copy_from_slice(new);
            return;
        }
        let len = self.records.len() - count + new.len();
        if len > self.records.capacity() {
            self.records.reserve_exact(len + SPARE - self.records.len());
        }
        self.records
            .splice(offset..offset + count, new.iter().copied());
        let (w, shift) = (j / PER_WORD, 4 * (j % PER_WORD));
        self.counts[w] = (self.counts[w] & !(15 << shift)) | ((new.len() as u64) << shift);
    }
}

/// Runs of up to [`MAX_RUN`] records by index (see the module documentation). Every index
/// reads as an empty run until written.
#[derive(Clone, Debug)]
pub struct PagedRuns<T> {
    /// Pages by index / [`SLOTS`], allocated when an index in them first holds records.
    pages: Vec<Option<Box<Page<T>>>>,
    /// Records held.
    records: usize,
}

impl<T> Default for PagedRuns<T> {
    fn default() -> Self {
        Self {
            pages: Vec::new(),
            records: 0,
        }
    }
}

impl<T: Copy> PagedRuns<T> {
    /// The records of `index`, in the order written (empty when never written).
    #[inline]
    pub fn get(&self, index: u32) -> &[T] {
        let s = index as usize;
        match self.pages.get(s / SLOTS) {
            Some(Some(page)) => {
                let (offset, count) = page.span(s % SLOTS);
                &page.records[offset..offset + count]
            }
            _ => &[],
        }
    }

    /// Replace the records of `index` with `new`. A page is allocated when an index in it
    /// first holds records and freed when it holds none again.
    ///
    /// # Panics
    /// When `new` holds more than [`MAX_RUN`] records (a caller's bug: buckets and cells
    /// hold at most 8).
    pub fn set(&mut self, index: u32, new: &[T]) {
        assert!(
            new.len() <= MAX_RUN,
            "a run holds at most {MAX_RUN} records"
        );
        let (p, j) = (index as usize / SLOTS, index as usize % SLOTS);
        if p >= self.pages.len() {
            if new.is_empty() {
                return;
            }
            // Grow the page table by an eighth at least, exactly (no doubling).
            let more = (p + 1 - self.pages.len()).max(self.pages.len() / 8);
            self.pages.reserve_exact(more);
            self.pages.resize_with(p + 1, || None);
        }
        let page = match &mut self.pages[p] {
            Some(page) => page,
            None if new.is_empty() => return,
            empty => empty.insert(Box::default()),
        };
        let before = page.span(j).1;
        page.set(j, new);
        self.records = self.records + new.len() - before;
        if page.records.is_empty() {
            self.pages[p] = None;
        }
    }

    /// Forget every run and free the pages (the page table keeps its allocation).
    pub fn clear(&mut self) {
        self.pages.clear();
        self.records = 0;
    }

    /// Records held.
    pub fn len(&self) -> usize {
        self.records
    }

    /// True when no index holds a record.
    pub fn is_empty(&self) -> bool {
        self.records == 0
    }

    /// Heap bytes of the page table and pages without their records.
    pub fn index_bytes(&self) -> u64 {
        let table = self.pages.capacity() * std::mem::size_of::<Option<Box<Page<T>>>>();
        let pages = self.pages.iter().flatten().count() * std::mem::size_of::<Page<T>>();
        (table + pages) as u64
    }

    /// Heap bytes of the pages' record vectors (held records and spare room).
    pub fn record_bytes(&self) -> u64 {
        let records: usize = self
            .pages
            .iter()
            .flatten()
            .map(|p| p.records.capacity())
            .sum();
        (records * std::mem::size_of::<T>()) as u64
    }

    /// All heap bytes ([`Self::index_bytes`] + [`Self::record_bytes`]).
    pub fn heap_bytes(&self) -> u64 {
        self.index_bytes() + self.record_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nibble_sums_and_spans() {
        assert_eq!(nibble_sum(0), 0);
        assert_eq!(nibble_sum(u64::MAX), 16 * 15);
        assert_eq!(nibble_sum(0x7070_0000_0000_0007), 21);
        let mut page = Page::default();
        for j in 0..SLOTS {
            page.set(j, &vec![j as u32; j % 8]);
        }
        let mut offset = 0;
        for j in 0..SLOTS {
            assert_eq!(page.span(j), (offset, j % 8));
            assert!(page.records[offset..offset + j % 8]
                .iter()
                .all(|&w| w == j as u32));
            offset += j % 8;
        }
        assert_eq!(page.records.len(), offset);
    }

    #[test]
    fn runs_read_back_as_written_and_empty_pages_are_freed() {
        let mut runs = PagedRuns::<[u32; 3]>::default();
        assert_eq!(runs.get(5), &[] as &[[u32; 3]]);
        runs.set(700, &[[1, 2, 3], [4, 5, 6]]);
        runs.set(701, &[[7, 8, 9]]);
        runs.set(640, &[[0, 0, 1]; MAX_RUN]);
        assert_eq!(runs.get(700), &[[1, 2, 3], [4, 5, 6]]);
        assert_eq!(runs.get(701), &[[7, 8, 9]]);
        assert_eq!(runs.get(640).len(), MAX_RUN);
        assert_eq!(runs.get(699), &[] as &[[u32; 3]]);
        assert_eq!(runs.len(), 3 + MAX_RUN);
        runs.set(700, &[[9, 9, 9]]);
        assert_eq!(
            (runs.get(700), runs.get(701)),
            (&[[9, 9, 9]][..], &[[7, 8, 9]][..])
        );
        assert!(runs.record_bytes() >= 12 * (2 + MAX_RUN) as u64);
        for index in [640, 700, 701] {
            runs.set(index, &[]);
        }
        assert!(runs.is_empty());
        assert_eq!(runs.record_bytes(), 0);
        // An empty run past the table allocates nothing.
        runs.set(1 << 20, &[]);
        assert!(runs.index_bytes() < 1024);
        runs.set(3, &[[1, 1, 1]]);
        runs.clear();
        assert_eq!((runs.len(), runs.get(3)), (0, &[] as &[[u32; 3]]));
    }

    #[test]
    #[should_panic(expected = "at most 15")]
    fn longer_runs_are_refused() {
        PagedRuns::<u32>::default().set(0, &[1; MAX_RUN + 1]);
    }
}
