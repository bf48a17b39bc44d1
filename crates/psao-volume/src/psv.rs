//! The `.psv` file: a compact, versioned, checksummed copy of a built volume that loads
//! without `vdb-rs`.
//!
//! Layout (little-endian): magic `PSVOLUME`, version `u32`, payload length `u64`, FNV-1a 64
//! checksum of the payload `u64`, payload. The payload holds class, format, transform,
//! background and value range, then the L1 nodes (origin, mask, first child), the L2 nodes
//! (mask, first child, first mask), the L3 nodes (brick | has-mask bit), the coded
//! mask table, the brick pool and the BC7 refinement layer (count, brick indices, records).
//! Rank prefixes and majorants are rebuilt on load.

use crate::codec::{BrickFormat, BrickPool, REFINEMENT_BYTES};
use crate::error::{Result, VolumeError};
use crate::grid::{GridClass, Transform};
use crate::mask;
use crate::tree::{FlatTree, L1Node, L2Node, L3Node};
use crate::volume::Volume;
use glam::{DVec3, IVec3};

const MAGIC: &[u8; 8] = b"PSVOLUME";
/// Current `.psv` format version.
pub const VERSION: u32 = 1;
const HEADER: usize = 8 + 4 + 8 + 8;

/// FNV-1a 64-bit hash.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf29ce484222325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100000001b3)
    })
}

/// Serialises `vol`.
pub fn to_bytes(vol: &Volume) -> Vec<u8> {
    let mut p = Vec::new();
    p.push(match vol.class {
        GridClass::Fog => 0u8,
        GridClass::LevelSet => 1,
    });
    p.push(vol.pool.format.code());
    p.extend_from_slice(&[0, 0]);
    for v in vol
        .transform
        .scale
        .to_array()
        .into_iter()
        .chain(vol.transform.translation.to_array())
    {
        p.extend_from_slice(&v.to_le_bytes());
    }
    for v in [vol.background, vol.pool.lo, vol.pool.hi] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    let t = &vol.tree;
    p.extend_from_slice(&(t.l1.len() as u32).to_le_bytes());
    for n in &t.l1 {
        for c in n.origin.to_array() {
            p.extend_from_slice(&c.to_le_bytes());
        }
        n.mask
            .iter()
            .for_each(|w| p.extend_from_slice(&w.to_le_bytes()));
        p.extend_from_slice(&n.first.to_le_bytes());
    }
    p.extend_from_slice(&(t.l2.len() as u32).to_le_bytes());
    for n in &t.l2 {
        n.mask
            .iter()
            .for_each(|w| p.extend_from_slice(&w.to_le_bytes()));
        p.extend_from_slice(&n.first.to_le_bytes());
        p.extend_from_slice(&n.mask_first.to_le_bytes());
    }
    p.extend_from_slice(&(t.l3.len() as u32).to_le_bytes());
    for n in &t.l3 {
        p.extend_from_slice(&n.0.to_le_bytes());
    }
    p.extend_from_slice(&(t.masks.len() as u64).to_le_bytes());
    p.extend_from_slice(&t.masks);
    p.extend_from_slice(&(vol.pool.data.len() as u64).to_le_bytes());
    p.extend_from_slice(&vol.pool.data);
    p.extend_from_slice(&(vol.pool.refined.len() as u32).to_le_bytes());
    for i in &vol.pool.refined {
        p.extend_from_slice(&i.to_le_bytes());
    }
    p.extend_from_slice(&vol.pool.refinement);
    let mut out = Vec::with_capacity(HEADER + p.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(p.len() as u64).to_le_bytes());
    out.extend_from_slice(&fnv1a(&p).to_le_bytes());
    out.extend_from_slice(&p);
    out
}

/// Writes `vol` to `path`.
pub fn write_file(vol: &Volume, path: &std::path::Path) -> Result<()> {
    std::fs::write(path, to_bytes(vol)).map_err(|source| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a `.psv` file.
pub fn read_file(path: &std::path::Path) -> Result<Volume> {
    let bytes = std::fs::read(path).map_err(|source| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    from_bytes(&bytes)
}

/// Whether `bytes` start like a `.psv` file.
pub fn is_psv(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| VolumeError::InvalidPsv("truncated payload".into()))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(self.u64()?))
    }
    fn count(&mut self, item_bytes: usize) -> Result<usize> {
        let n = self.u32()? as usize;
        if n.saturating_mul(item_bytes) > self.b.len() - self.at {
            return Err(VolumeError::InvalidPsv("count larger than the file".into()));
        }
        Ok(n)
    }
}

fn bad(m: &str) -> VolumeError {
    VolumeError::InvalidPsv(m.into())
}

/// Parses and validates a `.psv` file held in memory.
pub fn from_bytes(bytes: &[u8]) -> Result<Volume> {
    if bytes.len() < HEADER || !is_psv(bytes) {
        return Err(bad("wrong magic (not a .psv file)"));
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != VERSION {
        return Err(VolumeError::InvalidPsv(format!(
            "version {version}, this build reads version {VERSION}"
        )));
    }
    let len = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
    let sum = u64::from_le_bytes(bytes[20..28].try_into().expect("8 bytes"));
    let payload = &bytes[HEADER..];
    if payload.len() as u64 != len {
        return Err(VolumeError::InvalidPsv(format!(
            "payload is {} bytes, header says {len} (truncated?)",
            payload.len()
        )));
    }
    if fnv1a(payload) != sum {
        return Err(bad("checksum mismatch (damaged file)"));
    }
    let mut r = Reader { b: payload, at: 0 };
    let head = r.take(4)?;
    let class = match head[0] {
        0 => GridClass::Fog,
        1 => GridClass::LevelSet,
        _ => return Err(bad("unknown grid class")),
    };
    let format = BrickFormat::from_code(head[1]).ok_or_else(|| bad("unknown brick format"))?;
    let scale = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
    let translation = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
    let (background, lo, hi) = (r.f32()?, r.f32()?, r.f32()?);
    let mut tree = FlatTree::default();
    for _ in 0..r.count(12 + 4096 + 4)? {
        let o = IVec3::new(r.u32()? as i32, r.u32()? as i32, r.u32()? as i32);
        let mask: Vec<u64> = (0..512).map(|_| r.u64()).collect::<Result<_>>()?;
        let first = r.u32()?;
        let mut acc = 0;
        let prefix = mask
            .iter()
            .map(|w| {
                let p = acc;
                acc += w.count_ones();
                p as u16
            })
            .collect();
        tree.l1.push(L1Node {
            origin: o,
            mask,
            prefix,
            first,
        });
    }
    for _ in 0..r.count(512 + 8)? {
        let mut mask = [0u64; 64];
        for w in &mut mask {
            *w = r.u64()?;
        }
        let first = r.u32()?;
        let mask_first = r.u32()?;
        let mut prefix = [0u16; 64];
        let mut acc = 0u32;
        for (p, w) in prefix.iter_mut().zip(&mask) {
            *p = acc as u16;
            acc += w.count_ones();
        }
        tree.l2.push(L2Node {
            mask,
            prefix,
            first,
            mask_first,
        });
    }
    for _ in 0..r.count(4)? {
        tree.l3.push(L3Node(r.u32()?));
    }
    let mask_len = r.u64()? as usize;
    tree.masks = r.take(mask_len)?.to_vec();
    let pool_len = r.u64()? as usize;
    let data = r.take(pool_len)?.to_vec();
    let refined: Vec<u32> = (0..r.count(4 + REFINEMENT_BYTES)?)
        .map(|_| r.u32())
        .collect::<Result<_>>()?;
    let refinement = r.take(refined.len() * REFINEMENT_BYTES)?.to_vec();
    if r.at != payload.len() {
        return Err(bad("trailing bytes after the brick pool"));
    }
    // Structural checks: children in range, masks complete, pool whole bricks.
    for n in &tree.l1 {
        let kids: u32 = n.mask.iter().map(|w| w.count_ones()).sum();
        if n.first as u64 + kids as u64 > tree.l2.len() as u64 {
            return Err(bad("L1 children out of range"));
        }
    }
    for n in &tree.l2 {
        let kids: u32 = n.mask.iter().map(|w| w.count_ones()).sum();
        if n.first as u64 + kids as u64 > tree.l3.len() as u64 {
            return Err(bad("L2 children out of range"));
        }
    }
    // Every coded mask must be complete and the table used exactly, in child order.
    let mut at = 0usize;
    for n in &tree.l2 {
        if n.mask_first as usize != at {
            return Err(bad("mask table out of order"));
        }
        let kids: u32 = n.mask.iter().map(|w| w.count_ones()).sum();
        for l3 in &tree.l3[n.first as usize..(n.first + kids) as usize] {
            if l3.has_mask() {
                at += tree
                    .masks
                    .get(at..)
                    .and_then(mask::coded_len)
                    .ok_or_else(|| bad("coded mask out of range"))?;
            }
        }
    }
    if at != tree.masks.len() {
        return Err(bad("mask table size mismatch"));
    }
    if data.len() % format.brick_bytes() != 0 || !(lo.is_finite() && hi.is_finite()) {
        return Err(bad("brick pool of partial bricks"));
    }
    if !(scale.is_finite() && translation.is_finite() && scale.min_element() > 0.0) {
        return Err(bad("degenerate transform"));
    }
    let bricks = data.len() / format.brick_bytes();
    if !refined.is_empty()
        && (format != BrickFormat::Bc7
            || refined.windows(2).any(|w| w[0] >= w[1])
            || refined.iter().any(|&i| i as usize >= bricks))
    {
        return Err(bad("invalid refinement list"));
    }
    let pool = BrickPool {
        format,
        lo,
        hi,
        data,
        refined,
        refinement,
    };
    Volume::assemble(
        class,
        Transform { scale, translation },
        background,
        tree,
        pool,
    )
    .map_err(|e| VolumeError::InvalidPsv(e.to_string()))
}
