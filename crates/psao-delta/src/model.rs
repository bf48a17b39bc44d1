//! What a server sends: the instance table (once) and per-frame updates.

use glam::Affine3A;
use psao_points::pack::is_valid;
use psao_points::{Bucket, Cell, GridLayout, CELL_POINTS};

/// What a joining client needs to know about one instance (part of the welcome).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceInfo {
    /// Grid geometry and hash-table size; the client creates `MirrorGrid::new(layout)`.
    pub layout: GridLayout,
    /// Poisson radius in instance-local units; the reconstruction radius is based on it.
    pub poisson_radius: f32,
    /// Points the server keeps in this instance's grid (overflowed points excluded).
    pub point_count: u32,
}

/// The buckets and cells of one instance that changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstanceDelta {
    /// Instance index (into the instance table).
    pub instance: u32,
    /// (bucket index, new content), empty entries last.
    pub buckets: Vec<(u32, Bucket)>,
    /// (cell slot, new content), empty entries last.
    pub cells: Vec<(u32, Cell)>,
    /// With lighting (DESIGN §12): one array per entry of `cells`, in the same order, whose
    /// record `k` is the irradiance of the cell's point `k`
    /// ([`psao_points::irradiance::pack_rgb9e5`]; 0 past the cell's points). Empty without
    /// lighting.
    pub lights: Vec<[u32; CELL_POINTS]>,
}

/// One server → client update: everything that changed since the client's previous update,
/// or, when `snapshot` is set, everything the client needs from scratch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Update {
    /// Server frame number the update was taken at.
    pub frame: u64,
    /// A full snapshot (first update of a client, or after a resync): the client starts from
    /// empty grids before applying it.
    pub snapshot: bool,
    /// (instance index, local-to-world transform) of every instance at this frame.
    pub transforms: Vec<(u32, Affine3A)>,
    /// Changed buckets and cells, per instance with changes.
    pub instances: Vec<InstanceDelta>,
}

impl Update {
    /// Number of changed cells over all instances.
    pub fn changed_cells(&self) -> usize {
        self.instances.iter().map(|d| d.cells.len()).sum()
    }

    /// Number of changed buckets over all instances.
    pub fn changed_buckets(&self) -> usize {
        self.instances.iter().map(|d| d.buckets.len()).sum()
    }

    /// Whether the update carries irradiance records.
    pub fn has_lights(&self) -> bool {
        self.instances.iter().any(|d| !d.lights.is_empty())
    }

    /// True when no bucket or cell changed (transforms do not count).
    pub fn is_empty(&self) -> bool {
        self.changed_cells() == 0 && self.changed_buckets() == 0
    }
}

/// The bucket with its used entries first (in their order) and all-zero empty entries last,
/// the form the paper transmits (§3.4).
pub fn compact_bucket(bucket: &Bucket) -> Bucket {
    let mut out = Bucket::default();
    let used = bucket.entries.iter().filter(|e| e.key != 0);
    for (dst, src) in out.entries.iter_mut().zip(used) {
        *dst = *src;
    }
    out
}

/// The cell with its valid points first (in their order) and zero words last.
pub fn compact_cell(cell: &Cell) -> Cell {
    let mut out = Cell::default();
    let valid = cell.points.iter().filter(|&&b| is_valid(b));
    for (dst, src) in out.points.iter_mut().zip(valid) {
        *dst = *src;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_points::pack::VALID_BIT;
    use psao_points::BucketEntry;

    #[test]
    fn compaction_moves_empties_last_and_keeps_order() {
        let mut b = Bucket::default();
        b.entries[2] = BucketEntry::new(5, 9);
        b.entries[6] = BucketEntry::new(13, 1);
        let c = compact_bucket(&b);
        assert_eq!(c.entries[0], BucketEntry::new(5, 9));
        assert_eq!(c.entries[1], BucketEntry::new(13, 1));
        assert!(c.entries[2..].iter().all(|e| *e == BucketEntry::default()));

        let mut cell = Cell::default();
        cell.points[1] = VALID_BIT | 7;
        cell.points[3] = 0x1234; // invalid garbage is dropped
        cell.points[5] = VALID_BIT | 8;
        let c = compact_cell(&cell);
        assert_eq!(c.points, [VALID_BIT | 7, VALID_BIT | 8, 0, 0, 0, 0, 0]);
    }

    #[test]
    fn counts_and_emptiness() {
        let mut u = Update {
            transforms: vec![(0, Affine3A::IDENTITY)],
            ..Default::default()
        };
        assert!(u.is_empty());
        u.instances.push(InstanceDelta {
            instance: 3,
            buckets: vec![(1, Bucket::default())],
            cells: vec![(0, Cell::default()), (4, Cell::default())],
            lights: Vec::new(),
        });
        assert!(!u.has_lights());
        assert!(!u.is_empty());
        assert_eq!((u.changed_buckets(), u.changed_cells()), (1, 2));
    }
}
