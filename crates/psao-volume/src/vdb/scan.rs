//! A dry run over a float 5-4-3 tree's topology and leaf data that reads the bytes exactly as
//! `vdb-rs` will, checking every count and length against the bytes that are left and the
//! limits of [`super`], before `vdb-rs` allocates anything for it. It counts the nodes,
//! leaves and active tiles, so a file whose tiles would cover billions of voxels (or whose
//! length fields ask for gigabytes) is refused in time linear in its size.

use super::{MAX_CELLS, MAX_INTERNAL_NODES, MAX_LEAVES, MAX_ROOT_NODES};
use crate::error::{Result, VolumeError};

/// Per-grid compression flags (OpenVDB `COMPRESS_*`).
const ZIP: u32 = 1;
const ACTIVE_MASK: u32 = 2;
const BLOSC: u32 = 4;
/// Bytes of a Blosc frame header.
const BLOSC_HEADER: usize = 16;
/// Index coordinates of a root child stay within ±2³⁰ (so no sum of offsets overflows).
const MAX_ORIGIN: i32 = 1 << 30;
/// Index span of a root child (a 5-level internal node).
const ROOT_CHILD_SPAN: i32 = 4096;

/// Where the grid's tree starts and how its values are stored.
#[derive(Clone, Copy, Debug)]
pub(super) struct TreeLayout {
    /// Byte offset of the root's tile count (just after the background value).
    pub topology: u64,
    /// Byte offset of the leaf data.
    pub blocks: u64,
    /// Compression flags of the grid.
    pub compression: u32,
    /// Whether values are stored as 16-bit floats.
    pub half_float: bool,
}

/// What the tree holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct TreeCounts {
    /// 5-level internal nodes (root children).
    pub root_children: usize,
    /// 4-level internal nodes.
    pub internal: usize,
    /// Leaves (8³ voxels each).
    pub leaves: usize,
    /// Active tiles of 4-level nodes (8³ voxels each).
    pub tiles8: usize,
    /// Active tiles of 5-level nodes (128³ voxels each).
    pub tiles128: usize,
}

impl TreeCounts {
    /// 8³ cells the grid covers: leaves plus the cells of its active tiles.
    pub fn cells(&self) -> u64 {
        self.leaves as u64 + self.tiles8 as u64 + self.tiles128 as u64 * 4096
    }
}

/// Checks the tree of a grid laid out as `layout` in `bytes` and counts its nodes; `label`
/// names the file in errors.
pub(super) fn scan(bytes: &[u8], label: &str, layout: TreeLayout) -> Result<TreeCounts> {
    if layout.compression & !(ZIP | ACTIVE_MASK | BLOSC) != 0 {
        return Err(VolumeError::InvalidVdb(
            label.into(),
            format!("unknown compression flags {:#x}", layout.compression),
        ));
    }
    let mut r = Bytes {
        bytes,
        at: usize::try_from(layout.topology).unwrap_or(usize::MAX),
        label,
        layout,
    };
    let mut counts = TreeCounts::default();
    // Root tiles: coordinates, value, active flag (`vdb-rs` reads and drops them).
    let tiles = r.u32()? as usize;
    let roots = r.u32()? as usize;
    r.skip(tiles.saturating_mul(17), "root tiles")?;
    if roots > MAX_ROOT_NODES {
        return Err(r.limit("root children", roots as u64, MAX_ROOT_NODES as u64));
    }
    for _ in 0..roots {
        let origin = [r.i32()?, r.i32()?, r.i32()?];
        if origin.iter().any(|&c| {
            c.rem_euclid(ROOT_CHILD_SPAN) != 0 || c.unsigned_abs() > MAX_ORIGIN.unsigned_abs()
        }) {
            return Err(r.bad(&format!(
                "root child origin {origin:?} is not a multiple of 4096 within ±2^30"
            )));
        }
        counts.root_children += 1;
        let (children, tiles) = r.node(5)?;
        counts.tiles128 += tiles;
        for _ in 0..children {
            counts.internal += 1;
            if counts.internal > MAX_INTERNAL_NODES {
                return Err(r.limit(
                    "internal nodes",
                    counts.internal as u64,
                    MAX_INTERNAL_NODES as u64,
                ));
            }
            let (leaves, tiles) = r.node(4)?;
            counts.tiles8 += tiles;
            counts.leaves += leaves;
            if counts.leaves > MAX_LEAVES {
                return Err(r.limit("leaves", counts.leaves as u64, MAX_LEAVES as u64));
            }
            r.skip(leaves * 64, "leaf masks")?;
        }
    }
    if counts.cells() > MAX_CELLS as u64 {
        return Err(VolumeError::LimitExceeded {
            label: label.into(),
            what: "voxels (active tiles included)",
            count: counts.cells() * 512,
            limit: MAX_CELLS as u64 * 512,
        });
    }
    r.at = usize::try_from(layout.blocks).unwrap_or(usize::MAX);
    for _ in 0..counts.leaves {
        let mask = r.take(64, "leaf value mask")?;
        let active = mask.iter().map(|b| b.count_ones() as usize).sum();
        r.values(512, active)?;
    }
    Ok(counts)
}

/// A cursor that never reads past the end.
struct Bytes<'a> {
    bytes: &'a [u8],
    at: usize,
    label: &'a str,
    layout: TreeLayout,
}

impl<'a> Bytes<'a> {
    fn bad(&self, what: &str) -> VolumeError {
        VolumeError::InvalidVdb(self.label.into(), format!("{what} (at byte {})", self.at))
    }

    fn limit(&self, what: &'static str, count: u64, limit: u64) -> VolumeError {
        VolumeError::LimitExceeded {
            label: self.label.into(),
            what,
            count,
            limit,
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| self.bad(&format!("file ends inside the {what}")))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn skip(&mut self, n: usize, what: &str) -> Result<()> {
        self.take(n, what).map(|_| ())
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1, "tree")?[0])
    }

    fn u32(&mut self) -> Result<u32> {
        let b = self.take(4, "tree")?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn i32(&mut self) -> Result<i32> {
        Ok(self.u32()? as i32)
    }

    fn i64(&mut self) -> Result<i64> {
        let b = self.take(8, "tree")?;
        let mut a = [0; 8];
        a.copy_from_slice(b);
        Ok(i64::from_le_bytes(a))
    }

    /// An internal node with `log2` children per axis: its child and value masks, then its
    /// values. Returns (children, active tiles).
    fn node(&mut self, log2: u32) -> Result<(usize, usize)> {
        let n = 1usize << (3 * log2);
        let child = self.take(n / 8, "node child mask")?;
        let value = self.take(n / 8, "node value mask")?;
        let children = child.iter().map(|b| b.count_ones() as usize).sum();
        let tiles = child
            .iter()
            .zip(value)
            .map(|(c, v)| (v & !c).count_ones() as usize)
            .sum();
        let active = value.iter().map(|b| b.count_ones() as usize).sum();
        self.values(n, active)?;
        Ok((children, tiles))
    }

    /// The values of a node of `n` entries, `active` of them active: the metadata byte, the
    /// inactive values and selection mask it announces, then the (compressed) values.
    fn values(&mut self, n: usize, active: usize) -> Result<()> {
        let meta = self.u8()?;
        if meta > 6 {
            return Err(self.bad(&format!("unknown node metadata {meta}")));
        }
        let inactive = match meta {
            2 | 4 => 1,
            5 => 2,
            _ => 0,
        };
        self.skip(4 * inactive, "inactive values")?;
        if matches!(meta, 3..=5) {
            self.skip(n / 8, "selection mask")?;
        }
        let count = if self.layout.compression & ACTIVE_MASK != 0 && meta != 6 {
            active
        } else {
            n
        };
        let size = if self.layout.half_float { 2 } else { 4 };
        let raw = count * size;
        if self.layout.compression & (BLOSC | ZIP) == 0 {
            return self.skip(raw, "node values");
        }
        let stored = self.i64()?;
        if stored <= 0 {
            // Stored uncompressed: the length must be exactly the values'.
            if stored.unsigned_abs() != raw as u64 {
                return Err(self.bad(&format!(
                    "{} uncompressed bytes where {raw} are expected",
                    stored.unsigned_abs()
                )));
            }
            return self.skip(raw, "node values");
        }
        let stored = usize::try_from(stored).unwrap_or(usize::MAX);
        let data = self.take(stored, "compressed node values")?;
        if self.layout.compression & BLOSC != 0 && count > 0 {
            // `vdb-rs` trusts the frame header: its sizes must match the values and the bytes.
            if data.len() < BLOSC_HEADER {
                return Err(self.bad("Blosc frame shorter than its header"));
            }
            let word = |i: usize| {
                u32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]) as usize
            };
            let (nbytes, cbytes) = (word(4), word(12));
            if nbytes != raw || cbytes > data.len() || cbytes < BLOSC_HEADER {
                return Err(self.bad(&format!(
                    "Blosc frame of {nbytes} bytes ({cbytes} compressed, {} stored) where {raw} are expected",
                    data.len()
                )));
            }
        }
        Ok(())
    }
}
