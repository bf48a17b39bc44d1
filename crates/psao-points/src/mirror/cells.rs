//! A mirror's cells by slot: per page of [`SLOTS`] slots, a 4-bit point count per slot and
//! one vector of the page's valid points, slot after slot. A slot's points start where the
//! counts of the slots before it in the page add up to (a few word operations), so a held
//! cell costs its points plus its share of its page (counts, vector header, spare room).

use crate::grid::Cell;
use crate::layout::CELL_POINTS;
use crate::pack::is_valid;

/// Cell slots per page.
const SLOTS: usize = 64;
/// Slots whose counts share one word.
const PER_WORD: usize = 16;
/// Records of spare room a page's vector gets when it must grow (so that a cell gaining
/// points does not reallocate its page every time).
const SPARE: usize = 4;

/// One page of slots.
#[derive(Clone, Debug, Default)]
struct Page {
    /// 4-bit point count per slot.
    counts: [u64; SLOTS / PER_WORD],
    /// The valid points of the page's slots, in slot order.
    records: Vec<u32>,
}

/// Sum of the sixteen 4-bit fields of `x`.
#[inline]
fn nibble_sum(x: u64) -> usize {
    const LOW: u64 = 0x0f0f_0f0f_0f0f_0f0f;
    let bytes = (x & LOW) + ((x >> 4) & LOW);
    (bytes.wrapping_mul(0x0101_0101_0101_0101) >> 56) as usize
}

impl Page {
    /// Where slot `j` (of this page) starts in `records`, and its point count.
    #[inline]
    fn span(&self, j: usize) -> (usize, usize) {
        let (w, shift) = (j / PER_WORD, 4 * (j % PER_WORD));
        let before: usize = self.counts[..w].iter().map(|&c| nibble_sum(c)).sum();
        let word = self.counts[w];
        let below = word & ((1u64 << shift) - 1);
        (before + nibble_sum(below), ((word >> shift) & 15) as usize)
    }

    /// Replace slot `j`'s points with `new`.
    fn set(&mut self, j: usize, new: &[u32]) {
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

/// Cells by slot (see the module documentation).
#[derive(Clone, Debug, Default)]
pub(super) struct CellStore {
    /// Pages by slot / [`SLOTS`], allocated when a slot in them first holds points.
    pages: Vec<Option<Box<Page>>>,
    /// Points held.
    points: usize,
}

impl CellStore {
    /// The valid points of `slot`, in order.
    #[inline]
    pub(super) fn records(&self, slot: u32) -> &[u32] {
        let s = slot as usize;
        match self.pages.get(s / SLOTS) {
            Some(Some(page)) => {
                let (offset, count) = page.span(s % SLOTS);
                &page.records[offset..offset + count]
            }
            _ => &[],
        }
    }

    /// Replace `slot`'s points with the valid words of `cell`, in order.
    pub(super) fn set(&mut self, slot: u32, cell: &Cell) {
        let mut records = [0u32; CELL_POINTS];
        let mut n = 0;
        for &bits in cell.points.iter().filter(|&&b| is_valid(b)) {
            records[n] = bits;
            n += 1;
        }
        let (p, j) = (slot as usize / SLOTS, slot as usize % SLOTS);
        if p >= self.pages.len() {
            if n == 0 {
                return;
            }
            // Grow the page table by an eighth at least, exactly (no doubling).
            let more = (p + 1 - self.pages.len()).max(self.pages.len() / 8);
            self.pages.reserve_exact(more);
            self.pages.resize(p + 1, None);
        }
        let page = match &mut self.pages[p] {
            Some(page) => page,
            None if n == 0 => return,
            empty => empty.insert(Box::default()),
        };
        let before = page.span(j).1;
        page.set(j, &records[..n]);
        self.points = self.points + n - before;
        if page.records.is_empty() {
            self.pages[p] = None;
        }
    }

    /// Points held.
    pub(super) fn points(&self) -> usize {
        self.points
    }

    /// Heap bytes of the page table and pages without their records.
    pub(super) fn index_bytes(&self) -> u64 {
        let table = self.pages.capacity() * std::mem::size_of::<Option<Box<Page>>>();
        let pages = self.pages.iter().flatten().count() * std::mem::size_of::<Page>();
        (table + pages) as u64
    }

    /// Heap bytes of the pages' record vectors (held points and spare room).
    pub(super) fn record_bytes(&self) -> u64 {
        let words: usize = self
            .pages
            .iter()
            .flatten()
            .map(|p| p.records.capacity())
            .sum();
        4 * words as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pack::VALID_BIT;

    #[test]
    fn nibble_sums_and_spans() {
        assert_eq!(nibble_sum(0), 0);
        assert_eq!(nibble_sum(u64::MAX), 16 * 15);
        assert_eq!(nibble_sum(0x7070_0000_0000_0007), 21);
        let mut page = Page::default();
        let words = |n: usize, v: u32| vec![VALID_BIT | v; n];
        for j in 0..SLOTS {
            page.set(j, &words(j % 8, j as u32));
        }
        let mut offset = 0;
        for j in 0..SLOTS {
            assert_eq!(page.span(j), (offset, j % 8));
            assert!(page.records[offset..offset + j % 8]
                .iter()
                .all(|&w| w == VALID_BIT | j as u32));
            offset += j % 8;
        }
        assert_eq!(page.records.len(), offset);
    }

    #[test]
    fn empty_pages_are_freed() {
        let mut store = CellStore::default();
        let mut cell = Cell::default();
        cell.points[3] = VALID_BIT | 9;
        store.set(700, &cell);
        assert_eq!(
            (store.points(), store.records(700)),
            (1, &[VALID_BIT | 9][..])
        );
        assert!(store.record_bytes() > 0);
        store.set(700, &Cell::default());
        assert_eq!(store.points(), 0);
        assert_eq!(store.record_bytes(), 0);
        assert_eq!(store.records(700), &[] as &[u32]);
        // An empty cell past the table allocates nothing.
        store.set(1 << 20, &Cell::default());
        assert!(store.index_bytes() < 1024);
    }
}
