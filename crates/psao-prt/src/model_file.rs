//! The versioned byte format of a [`PoseModel`] (the binary writes and reads the file).
//!
//! Layout, little-endian: magic `PSAOPRT\0`, format version (u32), character name (u32
//! length + UTF-8), vertices, joints, lobes, active-joint count (u32 each), the active joint
//! indices (u32 each), the pose limits (their axis count `r` (u32; 0: none), then only when
//! `r > 0` the mean (`3·active` f32), the axes (`r × 3·active` f32), per axis its least
//! and greatest coordinate (f32 each), per axis the ball's unit (f32) and the ball's radius
//! (f32; 0: no ball)), the weights (f32 each,
//! `(1 + 3·active) × vertices·lobes·7`), and an FNV-1a 64 checksum of everything before it. Every count is checked against the bytes
//! that remain before anything is allocated, so truncated, foreign or corrupt files get an
//! error, never a panic or a huge allocation.

use crate::model::{PoseLimits, PoseModel, LOBE_DIM};
use crate::PrtError;

/// First bytes of every model file.
pub const MAGIC: &[u8; 8] = b"PSAOPRT\0";
/// The format version written and accepted.
pub const VERSION: u32 = 3;
/// Longest character name accepted.
const MAX_NAME: usize = 4096;

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The model as bytes.
pub fn to_bytes(model: &PoseModel) -> Vec<u8> {
    let mut out = Vec::with_capacity(64 + model.weights.len() * 4);
    out.extend_from_slice(MAGIC);
    let u32s = |out: &mut Vec<u8>, v: u32| out.extend_from_slice(&v.to_le_bytes());
    u32s(&mut out, VERSION);
    u32s(&mut out, model.character.len() as u32);
    out.extend_from_slice(model.character.as_bytes());
    for v in [
        model.vertices,
        model.joints,
        model.lobes,
        model.active.len(),
    ] {
        u32s(&mut out, v as u32);
    }
    for &j in &model.active {
        u32s(&mut out, j);
    }
    let limits = &model.limits;
    u32s(&mut out, limits.range.len() as u32);
    if !limits.range.is_empty() {
        // Without a ball: zero units and radius 0.
        let scale = if limits.scale.len() == limits.range.len() {
            limits.scale.clone()
        } else {
            vec![0.0; limits.range.len()]
        };
        let radius = if scale.iter().any(|&s| s > 0.0) {
            limits.radius
        } else {
            0.0
        };
        for v in limits
            .mean
            .iter()
            .chain(&limits.axes)
            .chain(limits.range.iter().flatten())
            .chain(&scale)
            .chain([&radius])
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    for w in &model.weights {
        out.extend_from_slice(&w.to_le_bytes());
    }
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], PrtError> {
        if self.bytes.len() - self.at < n {
            return Err(PrtError::Model(format!(
                "truncated: {what} needs {n} bytes at offset {}, only {} left",
                self.at,
                self.bytes.len() - self.at
            )));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, PrtError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    /// `n` f32 values (the bytes checked before anything is allocated).
    fn f32s(&mut self, n: usize, what: &str) -> Result<Vec<f32>, PrtError> {
        let bytes = n
            .checked_mul(4)
            .ok_or_else(|| PrtError::Model(format!("{what}: count overflows")))?;
        Ok(self
            .take(bytes, what)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect())
    }
}

/// Reads a model from bytes written by [`to_bytes`].
pub fn from_bytes(bytes: &[u8]) -> Result<PoseModel, PrtError> {
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(PrtError::Model(
            "not a psao relighting model (wrong magic bytes)".into(),
        ));
    }
    let mut r = Reader {
        bytes,
        at: MAGIC.len(),
    };
    let version = r.u32("version")?;
    if version != VERSION {
        return Err(PrtError::Model(format!(
            "format version {version}, this build reads version {VERSION}"
        )));
    }
    let name_len = r.u32("name length")? as usize;
    if name_len > MAX_NAME {
        return Err(PrtError::Model(format!("name length {name_len} is absurd")));
    }
    let character = String::from_utf8(r.take(name_len, "name")?.to_vec())
        .map_err(|_| PrtError::Model("character name is not UTF-8".into()))?;
    let vertices = r.u32("vertex count")? as usize;
    let joints = r.u32("joint count")? as usize;
    let lobes = r.u32("lobe count")? as usize;
    let active_len = r.u32("active joint count")? as usize;
    if !(1..=3).contains(&lobes) {
        return Err(PrtError::Model(format!(
            "lobe count {lobes} (expected 1..3)"
        )));
    }
    if active_len > joints {
        return Err(PrtError::Model(format!(
            "{active_len} active joints but only {joints} joints"
        )));
    }
    let active_bytes = r.take(active_len * 4, "active joints")?;
    let active: Vec<u32> = active_bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(&j) = active.iter().find(|&&j| j as usize >= joints) {
        return Err(PrtError::Model(format!("active joint {j} of {joints}")));
    }
    let axes = r.u32("pose axis count")? as usize;
    let p = 3 * active_len;
    if axes > p {
        return Err(PrtError::Model(format!(
            "{axes} pose axes for {p} pose numbers"
        )));
    }
    let limits = if axes == 0 {
        PoseLimits::default()
    } else {
        let mean = r.f32s(p, "pose mean")?;
        let axis_values = r.f32s(axes * p, "pose axes")?;
        let range = r
            .f32s(2 * axes, "pose ranges")?
            .chunks_exact(2)
            .map(|c| [c[0], c[1]])
            .collect();
        let scale = r.f32s(axes, "ball units")?;
        let radius = r.f32s(1, "ball radius")?[0];
        if scale.iter().any(|&s| s < 0.0) {
            return Err(PrtError::Model("negative pose-limit ball unit".into()));
        }
        // As written: a ball needs a positive radius and some positive unit.
        let ball = radius > 0.0 && scale.iter().any(|&s| s > 0.0);
        PoseLimits {
            mean,
            axes: axis_values,
            range,
            scale: if ball { scale } else { Vec::new() },
            radius: if ball { radius } else { 0.0 },
        }
    };
    let count = (1 + 3 * active_len)
        .checked_mul(vertices)
        .and_then(|n| n.checked_mul(lobes * LOBE_DIM))
        .ok_or_else(|| PrtError::Model("weight count overflows".into()))?;
    let weights = r.f32s(count, "weights")?;
    let end = r.at;
    let sum: [u8; 8] = r.take(8, "checksum")?.try_into().expect("8 bytes");
    if r.at != bytes.len() {
        return Err(PrtError::Model(format!(
            "{} unexpected bytes after the checksum",
            bytes.len() - r.at
        )));
    }
    let stored = u64::from_le_bytes(sum);
    if stored != fnv1a(&bytes[..end]) {
        return Err(PrtError::Model(
            "checksum mismatch: the file is corrupt".into(),
        ));
    }
    if weights
        .iter()
        .chain(&limits.mean)
        .chain(&limits.axes)
        .chain(limits.range.iter().flatten())
        .chain(&limits.scale)
        .chain([&limits.radius])
        .any(|w| !w.is_finite())
    {
        return Err(PrtError::Model("non-finite weight or pose limit".into()));
    }
    Ok(PoseModel {
        character,
        vertices,
        joints,
        lobes,
        active,
        weights,
        limits,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> PoseModel {
        PoseModel {
            character: "Fox".into(),
            vertices: 2,
            joints: 3,
            lobes: 1,
            active: vec![0, 2],
            weights: (0..7 * 7 * 2).map(|i| i as f32 * 0.5).collect(),
            limits: PoseLimits {
                mean: vec![0.1; 6],
                axes: vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                range: vec![[-0.5, 0.25]],
                scale: vec![0.2],
                radius: 1.5,
            },
        }
    }

    #[test]
    fn round_trips() {
        let m = model();
        assert_eq!(from_bytes(&to_bytes(&m)).unwrap(), m);
        // Limits without a ball, and no limits at all.
        let mut boxed = model();
        boxed.limits = boxed.limits.box_only();
        assert_eq!(from_bytes(&to_bytes(&boxed)).unwrap(), boxed);
        let mut free = model();
        free.limits = PoseLimits::default();
        assert_eq!(from_bytes(&to_bytes(&free)).unwrap(), free);
    }

    #[test]
    fn a_ball_reads_back_only_as_written() {
        // Found by the `prt_model` fuzzer: a positive radius with no positive unit read as a
        // ball but wrote back as none, so a read model did not round-trip.
        let mut flat = model();
        flat.limits.scale = vec![0.0];
        let read = from_bytes(&to_bytes(&flat)).unwrap();
        assert_eq!(read.limits, flat.limits.box_only());
        assert_eq!(
            to_bytes(&from_bytes(&to_bytes(&read)).unwrap()),
            to_bytes(&read)
        );
        let mut negative = model();
        negative.limits.scale = vec![-0.2];
        let e = from_bytes(&to_bytes(&negative)).unwrap_err();
        assert!(e.to_string().contains("negative"), "{e}");
    }

    #[test]
    fn rejects_truncated_foreign_and_corrupt_bytes() {
        let bytes = to_bytes(&model());
        for cut in [0, 5, 12, 20, bytes.len() - 9, bytes.len() - 1] {
            assert!(from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        assert!(from_bytes(b"glTF\x02\x00\x00\x00 not a model at all")
            .unwrap_err()
            .to_string()
            .contains("magic"));
        let mut corrupt = bytes.clone();
        corrupt[60] ^= 1;
        assert!(from_bytes(&corrupt).is_err());
        // An absurd vertex count is refused without allocating.
        let mut huge = bytes[..8 + 4 + 4 + 3].to_vec();
        for v in [u32::MAX, 3, 1, 0] {
            huge.extend_from_slice(&v.to_le_bytes());
        }
        assert!(from_bytes(&huge)
            .unwrap_err()
            .to_string()
            .contains("truncated"));
    }
}
