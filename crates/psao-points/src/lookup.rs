//! Read access to a grid's cells by coordinate, shared by the server's [`crate::InstanceGrid`]
//! and the client's [`crate::MirrorGrid`], so that reconstruction ([`crate::reconstruct_ao`])
//! visits the same points in the same order whichever stores them.

use glam::{IVec3, UVec3};

use crate::layout::GridLayout;

/// A grid whose allocated cells can be looked up by cell coordinate.
pub trait CellLookup {
    /// The grid's layout.
    fn layout(&self) -> &GridLayout;

    /// The slot and the stored point words of the allocated cell at `coord`. Valid points
    /// keep their order; a server grid's words include its empty entries (0), a mirror's are
    /// the valid points alone.
    fn cell_words(&self, coord: UVec3) -> Option<(u32, &[u32])>;

    /// The allocated cells of the 2×2×2 block whose lowest cell is `base`, as
    /// (cell coordinate, slot, point words), x fastest, then y, then z; unallocated or
    /// out-of-grid cells are skipped. This is the neighbourhood reconstruction visits.
    fn block_cells(&self, base: IVec3) -> impl Iterator<Item = (UVec3, u32, &[u32])> + '_ {
        (0..8).filter_map(move |k: i32| {
            let offset = IVec3::new(k & 1, (k >> 1) & 1, k >> 2);
            self.cell_at_offset(base, offset)
        })
    }

    /// The allocated cells around the block of [`Self::block_cells`]: the 4×4×4 block of
    /// offsets −1..=2 from `base` without its inner 2×2×2, x fastest, then y, then z. This is
    /// where reconstruction looks for a fallback point when the inner block has none.
    fn ring_cells(&self, base: IVec3) -> impl Iterator<Item = (UVec3, u32, &[u32])> + '_ {
        (0..64).filter_map(move |k: i32| {
            let offset = IVec3::new(k & 3, (k >> 2) & 3, k >> 4) - IVec3::ONE;
            if offset.cmpge(IVec3::ZERO).all() && offset.cmple(IVec3::ONE).all() {
                return None;
            }
            self.cell_at_offset(base, offset)
        })
    }

    /// The allocated cell at `base + offset`, if inside the grid.
    #[inline]
    fn cell_at_offset(&self, base: IVec3, offset: IVec3) -> Option<(UVec3, u32, &[u32])> {
        let c = self.layout().checked_coord(base.saturating_add(offset))?;
        self.cell_words(c).map(|(slot, words)| (c, slot, words))
    }
}
