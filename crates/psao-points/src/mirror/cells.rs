//! A mirror's cells by slot: the valid points of every slot as a [`PagedRuns`] (pages of 64
//! slots, a 4-bit point count per slot and one vector of the page's valid points), so a held
//! cell costs its points plus its share of its page (counts, vector header, spare room).

use crate::grid::Cell;
use crate::layout::CELL_POINTS;
use crate::pack::is_valid;

use super::runs::PagedRuns;

/// Cells by slot (see the module documentation).
#[derive(Clone, Debug, Default)]
pub(super) struct CellStore {
    /// The valid points of every slot, in pages of slots.
    runs: PagedRuns<u32>,
}

impl CellStore {
    /// The valid points of `slot`, in order.
    #[inline]
    pub(super) fn records(&self, slot: u32) -> &[u32] {
        self.runs.get(slot)
    }

    /// Replace `slot`'s points with the valid words of `cell`, in order.
    pub(super) fn set(&mut self, slot: u32, cell: &Cell) {
        let mut records = [0u32; CELL_POINTS];
        let mut n = 0;
        for &bits in cell.points.iter().filter(|&&b| is_valid(b)) {
            records[n] = bits;
            n += 1;
        }
        self.runs.set(slot, &records[..n]);
    }

    /// Points held.
    pub(super) fn points(&self) -> usize {
        self.runs.len()
    }

    /// Heap bytes of the page table and pages without their records.
    pub(super) fn index_bytes(&self) -> u64 {
        self.runs.index_bytes()
    }

    /// Heap bytes of the pages' record vectors (held points and spare room).
    pub(super) fn record_bytes(&self) -> u64 {
        self.runs.record_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pack::VALID_BIT;

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
