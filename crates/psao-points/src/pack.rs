//! The 32-bit point record (DESIGN §3 "Packing").
//!
//! ```text
//!  31  30..26  25..21  20..16  15..12  11..8   7..0
//!  V   pos.x   pos.y   pos.z   oct.u   oct.v   AO
//! ```
//! * `V`: 1 = the entry holds a point; an all-zero word is an empty entry.
//! * position: 5 bits per axis, the point's offset inside its grid cell in 32 steps; decoding
//!   returns the centre of the step, so the error is at most half a step (cell / 64) per axis.
//! * normal: octahedral map, 4 bits per coordinate. Only levels 0..=14 are used (value
//!   `q / 7 − 1`) so that 0 and ±1 are exact and the six axis directions (floors, walls,
//!   ceilings) decode without error; code 15 decodes like 14. The encoder picks the best of the
//!   four surrounding lattice points. Worst-case angular error: [`NORMAL_MAX_ERROR_DEG`].
//! * AO: `round(ao · 255)`, error at most 1/510.

use std::sync::OnceLock;

use glam::{Vec2, Vec3};

/// Bit that marks an entry as holding a point.
pub const VALID_BIT: u32 = 1 << 31;
/// Quantisation steps per axis of a cell.
pub const POSITION_STEPS: u32 = 32;
/// Largest angle (degrees) between a unit normal and its 8-bit octahedral decoding: 11.38°
/// measured over 200k directions (a brute-force search over all 256 codes gives 11.36°, so the
/// encoder is near optimal; the centred 16-level variant would reach 9.8° but miss the axes by
/// up to 5.8°). The test `normal_error_bound` checks it.
pub const NORMAL_MAX_ERROR_DEG: f32 = 11.5;

const SHIFT_X: u32 = 26;
const SHIFT_Y: u32 = 21;
const SHIFT_Z: u32 = 16;
const SHIFT_NORMAL: u32 = 8;
const OCT_LEVELS: f32 = 14.0;

/// A point record with its fields decoded, position relative to its cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unpacked {
    /// Position inside the cell as a fraction of the cell size, each axis in (0, 1).
    pub frac: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// Ambient occlusion in [0, 1].
    pub ao: f32,
}

/// Pack a point: `frac` is its offset inside the cell divided by the cell size (clamped to
/// [0, 1]), `normal` any non-zero vector (zero or non-finite encodes +Z), `ao` in [0, 1]
/// (clamped; NaN packs as 0). The result always has [`VALID_BIT`] set.
pub fn pack_point(frac: Vec3, normal: Vec3, ao: f32) -> u32 {
    let q = |f: f32| ((f * POSITION_STEPS as f32) as u32).min(POSITION_STEPS - 1);
    VALID_BIT
        | (q(frac.x) << SHIFT_X)
        | (q(frac.y) << SHIFT_Y)
        | (q(frac.z) << SHIFT_Z)
        | (u32::from(encode_normal(normal)) << SHIFT_NORMAL)
        | u32::from(quantize_ao(ao))
}

/// Decode a record; `None` when the valid bit is clear.
pub fn unpack_point(bits: u32) -> Option<Unpacked> {
    is_valid(bits).then(|| Unpacked {
        frac: unpack_frac(bits),
        normal: unpack_normal(bits),
        ao: dequantize_ao(bits as u8),
    })
}

/// True when the record holds a point.
#[inline]
pub fn is_valid(bits: u32) -> bool {
    bits & VALID_BIT != 0
}

/// The cell-relative position of a record (centre of its quantisation step).
#[inline]
pub fn unpack_frac(bits: u32) -> Vec3 {
    let f = |shift: u32| (((bits >> shift) & 31) as f32 + 0.5) * (1.0 / POSITION_STEPS as f32);
    Vec3::new(f(SHIFT_X), f(SHIFT_Y), f(SHIFT_Z))
}

/// The decoded normal of every 8-bit code (built once).
pub fn normal_table() -> &'static [Vec3; 256] {
    static TABLE: OnceLock<[Vec3; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|c| decode_normal(c as u8)))
}

/// The normal of a record (table lookup).
#[inline]
pub fn unpack_normal(bits: u32) -> Vec3 {
    normal_table()[normal_code(bits) as usize]
}

/// The 8-bit octahedral normal code of a record.
#[inline]
pub fn normal_code(bits: u32) -> u8 {
    (bits >> SHIFT_NORMAL) as u8
}

/// The AO of a record.
#[inline]
pub fn unpack_ao(bits: u32) -> f32 {
    dequantize_ao(bits as u8)
}

/// Replace the AO of a record, keeping everything else.
#[inline]
pub fn with_ao(bits: u32, ao: f32) -> u32 {
    (bits & !0xFF) | u32::from(quantize_ao(ao))
}

/// `round(ao · 255)` after clamping to [0, 1]; NaN gives 0.
#[inline]
pub fn quantize_ao(ao: f32) -> u8 {
    (ao.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Inverse of [`quantize_ao`].
#[inline]
pub fn dequantize_ao(q: u8) -> f32 {
    f32::from(q) * (1.0 / 255.0)
}

#[inline]
fn sign_nz(x: f32) -> f32 {
    if x >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// Octahedral coordinates in [-1, 1]² of a non-zero vector.
fn oct_from_dir(n: Vec3) -> Vec2 {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs());
    if n.z >= 0.0 {
        Vec2::new(n.x, n.y)
    } else {
        Vec2::new(
            (1.0 - n.y.abs()) * sign_nz(n.x),
            (1.0 - n.x.abs()) * sign_nz(n.y),
        )
    }
}

/// Unit vector of octahedral coordinates.
#[inline]
fn dir_from_oct(o: Vec2) -> Vec3 {
    let z = 1.0 - o.x.abs() - o.y.abs();
    let v = if z >= 0.0 {
        Vec3::new(o.x, o.y, z)
    } else {
        Vec3::new(
            (1.0 - o.y.abs()) * sign_nz(o.x),
            (1.0 - o.x.abs()) * sign_nz(o.y),
            z,
        )
    };
    v.normalize()
}

#[inline]
fn level_to_oct(q: u8) -> f32 {
    f32::from(q.min(OCT_LEVELS as u8)) * (2.0 / OCT_LEVELS) - 1.0
}

/// 8-bit octahedral code (u in the high nibble, v in the low nibble) of a direction.
pub fn encode_normal(n: Vec3) -> u8 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if !(l1.is_finite() && l1 > 0.0) {
        return encode_normal(Vec3::Z);
    }
    let unit = n.normalize();
    let o = (oct_from_dir(n) + 1.0) * (OCT_LEVELS * 0.5);
    let (u0, v0) = (
        (o.x.floor() as u8).min(OCT_LEVELS as u8),
        (o.y.floor() as u8).min(OCT_LEVELS as u8),
    );
    let mut best = (f32::NEG_INFINITY, 0u8);
    for du in 0..2u8 {
        for dv in 0..2u8 {
            let (u, v) = (
                (u0 + du).min(OCT_LEVELS as u8),
                (v0 + dv).min(OCT_LEVELS as u8),
            );
            let code = (u << 4) | v;
            let d = decode_normal(code).dot(unit);
            if d > best.0 {
                best = (d, code);
            }
        }
    }
    best.1
}

/// Unit normal of an 8-bit octahedral code.
#[inline]
pub fn decode_normal(code: u8) -> Vec3 {
    dir_from_oct(Vec2::new(level_to_oct(code >> 4), level_to_oct(code & 15)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fibonacci_sphere(n: usize) -> impl Iterator<Item = Vec3> {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        (0..n).map(move |i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
    }

    #[test]
    fn normal_error_bound() {
        let mut worst = 0.0f32;
        for n in fibonacci_sphere(200_000) {
            let d = decode_normal(encode_normal(n)).dot(n).clamp(-1.0, 1.0);
            worst = worst.max(d.acos().to_degrees());
        }
        println!("worst octahedral 4+4-bit error: {worst:.3} deg");
        assert!(worst <= NORMAL_MAX_ERROR_DEG, "{worst}");
        // The bound is tight-ish: the quantisation is really this coarse.
        assert!(worst > 0.6 * NORMAL_MAX_ERROR_DEG, "{worst}");
    }

    #[test]
    fn axis_normals_are_exact() {
        for n in [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ] {
            assert!(decode_normal(encode_normal(n)).distance(n) < 1e-6, "{n}");
        }
        assert_eq!(decode_normal(encode_normal(Vec3::ZERO)), Vec3::Z);
        assert_eq!(decode_normal(encode_normal(Vec3::NAN)), Vec3::Z);
        for code in 0..=255u8 {
            assert!((decode_normal(code).length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn position_within_half_step() {
        let half = 0.5 / POSITION_STEPS as f32;
        for i in 0..=1000 {
            let t = i as f32 / 1000.0;
            let frac = Vec3::new(t, (t * 7.3).fract(), (1.0 - t) * 0.999);
            let u = unpack_point(pack_point(frac, Vec3::Y, 0.5)).unwrap();
            let err = (u.frac - frac).abs().max_element();
            assert!(err <= half + 1e-6, "{frac} -> {} err {err}", u.frac);
        }
        // Out-of-range offsets clamp into the cell.
        let u = unpack_point(pack_point(Vec3::new(-0.2, 1.5, f32::NAN), Vec3::Y, 0.0)).unwrap();
        assert!(u.frac.cmpge(Vec3::ZERO).all() && u.frac.cmple(Vec3::ONE).all());
    }

    #[test]
    fn ao_within_1_over_510() {
        for i in 0..=10_000 {
            let ao = i as f32 / 10_000.0;
            let back = unpack_ao(pack_point(Vec3::ZERO, Vec3::Z, ao));
            assert!((back - ao).abs() <= 1.0 / 510.0 + 1e-7, "{ao} -> {back}");
        }
        assert_eq!(unpack_ao(pack_point(Vec3::ZERO, Vec3::Z, 2.0)), 1.0);
        assert_eq!(unpack_ao(pack_point(Vec3::ZERO, Vec3::Z, -1.0)), 0.0);
        let bits = pack_point(Vec3::splat(0.3), Vec3::X, 0.2);
        let changed = with_ao(bits, 0.9);
        assert_eq!(changed & !0xFF, bits & !0xFF);
        assert_eq!(quantize_ao(unpack_ao(changed)), quantize_ao(0.9));
    }

    #[test]
    fn validity() {
        assert!(unpack_point(0).is_none());
        assert!(!is_valid(0));
        let bits = pack_point(Vec3::splat(0.5), Vec3::NEG_Y, 1.0);
        assert!(is_valid(bits));
        assert!(unpack_point(bits).unwrap().normal.distance(Vec3::NEG_Y) < 1e-6);
    }
}
