//! Deterministic sample generation for AO rays: hashing, the R2 sequence, cosine-weighted
//! hemisphere directions and the self-intersection offset.

use glam::Vec3;

/// Mixes the bits of `x` so that every input bit affects every output bit (xor-shift and
/// odd-multiply rounds, the splitmix64 finaliser constants).
///
/// Why a hash and not a seeded RNG: every AO sample is addressed by (seed, point key, sample
/// index). Deriving its random numbers statelessly from that triple means no RNG state is
/// shared or advanced between threads, so the result of a sample is the same whichever
/// thread traces it, in whichever order, and a point can resume sampling at any index.
pub fn hash64(mut x: u64) -> u64 {
    x ^= x >> 30;
    x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x ^= x >> 27;
    x = x.wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Hash of the pair (seed, key); asymmetric, so (a, b) and (b, a) differ.
fn hash_pair(seed: u64, key: u64) -> u64 {
    hash64(hash64(seed ^ 0x9e37_79b9_7f4a_7c15).wrapping_add(key))
}

/// R2 step per axis in 0.32 fixed point: 1/g and 1/g² with g the plastic number
/// (the real root of x³ = x + 1), after Roberts' R2 low-discrepancy sequence.
const R2_STEP: [u32; 2] = [0xc13f_a9a9, 0x91e1_0da6];

/// 0.32 fixed point to a float in [0, 1) (the top 24 bits, exactly representable).
fn unit_float(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Sample `index` of the 2-D R2 sequence, toroidally shifted (Cranley–Patterson rotation) by
/// a random offset hashed from (`seed`, `key`). Both coordinates are in [0, 1). Points with
/// different keys get independent rotations; consecutive indices of one key stay well
/// stratified.
pub fn sample_2d(seed: u64, key: u64, index: u32) -> (f32, f32) {
    Sequence2d::new(seed, key).at(index)
}

/// The 2-D sequence of one (seed, key): [`sample_2d`] with the hash of the pair computed once,
/// for drawing many samples of one point.
#[derive(Clone, Copy, Debug)]
pub struct Sequence2d {
    /// The rotation, x in the low and y in the high half (0.32 fixed point each).
    shift: u64,
}

impl Sequence2d {
    /// The sequence of `key` under `seed`.
    pub fn new(seed: u64, key: u64) -> Self {
        Self {
            shift: hash_pair(seed, key),
        }
    }

    /// Sample `index`: equal to [`sample_2d`]`(seed, key, index)`.
    #[inline]
    pub fn at(&self, index: u32) -> (f32, f32) {
        let h = self.shift;
        // Fixed-point arithmetic keeps the sequence exact for any index (wrapping is mod 1).
        let x = index.wrapping_mul(R2_STEP[0]).wrapping_add(h as u32);
        let y = index
            .wrapping_mul(R2_STEP[1])
            .wrapping_add((h >> 32) as u32);
        (unit_float(x), unit_float(y))
    }
}

/// The random stream of the medium sampling of AO sample `index` of point `key`: hashed
/// from (seed, key, index) with another salt than the sample's direction, so the medium's
/// random numbers are independent of the direction and of every other sample.
pub fn medium_stream(seed: u64, key: u64, index: u32) -> u64 {
    hash64(hash_pair(seed ^ 0x6d65_6469_756d_0000, key) ^ u64::from(index))
}

/// Two unit vectors that complete the unit vector `n` to a right-handed orthonormal basis,
/// continuous everywhere except across n.z = 0 where the sign flips (Duff et al. 2017,
/// "Building an orthonormal basis, revisited"): no branch on a small |n.z|, no singularity.
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// A unit direction in the hemisphere around `n` with pdf cos θ / π, from two uniform numbers
/// in [0, 1). `n` need not be exactly unit (it is normalised; a zero normal means +z).
pub fn cosine_hemisphere(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    Hemisphere::new(n).cosine(u1, u2)
}

/// The frame of one normal: [`cosine_hemisphere`] with the normalisation and the basis
/// computed once, for drawing many directions around one normal.
#[derive(Clone, Copy, Debug)]
pub struct Hemisphere {
    n: Vec3,
    t: Vec3,
    b: Vec3,
}

impl Hemisphere {
    /// The hemisphere around `n` (normalised; a zero normal means +z).
    pub fn new(n: Vec3) -> Self {
        let n = n.normalize_or(Vec3::Z);
        let (t, b) = orthonormal_basis(n);
        Self { n, t, b }
    }

    /// A cosine-distributed direction: equal to [`cosine_hemisphere`]`(n, u1, u2)`.
    #[inline]
    pub fn cosine(&self, u1: f32, u2: f32) -> Vec3 {
        self.cosine_at(u1, azimuth(u2))
    }

    /// [`Hemisphere::cosine`] with the azimuth's sine and cosine given ([`azimuth`] of
    /// `u2`).
    #[inline]
    fn cosine_at(&self, u1: f32, (sin, cos): (f32, f32)) -> Vec3 {
        let r = u1.clamp(0.0, 1.0).sqrt();
        let z = (1.0 - u1).max(0.0).sqrt();
        (self.t * (r * cos) + self.b * (r * sin) + self.n * z).normalize_or(self.n)
    }

    /// [`Hemisphere::cosine`] of `G` samples at once, from their `u1` and the sines and
    /// cosines of their azimuths ([`azimuth`] of their `u2`), into `out`: the same
    /// arithmetic as [`Hemisphere::cosine`] lane by lane (so the same bits), written as
    /// loops over arrays without branches, which the compiler vectorises.
    #[inline]
    pub fn cosine_lanes<const G: usize>(
        &self,
        u1: &[f32; G],
        sin: &[f32; G],
        cos: &[f32; G],
        out: &mut [Vec3; G],
    ) {
        let (mut x, mut y, mut z) = ([0.0f32; G], [0.0f32; G], [0.0f32; G]);
        for k in 0..G {
            let r = u1[k].clamp(0.0, 1.0).sqrt();
            let h = (1.0 - u1[k]).max(0.0).sqrt();
            let (rc, rs) = (r * cos[k], r * sin[k]);
            // As glam: (t·rc + b·rs) + n·h per component.
            x[k] = self.t.x * rc + self.b.x * rs + self.n.x * h;
            y[k] = self.t.y * rc + self.b.y * rs + self.n.y * h;
            z[k] = self.t.z * rc + self.b.z * rs + self.n.z * h;
        }
        for k in 0..G {
            // `Vec3::normalize_or(n)`: 1 / sqrt(x·x + y·y + z·z), the fallback unless that is
            // finite and positive.
            let rcp = 1.0 / (x[k] * x[k] + y[k] * y[k] + z[k] * z[k]).sqrt();
            let ok = rcp.is_finite() && rcp > 0.0;
            x[k] = if ok { x[k] * rcp } else { self.n.x };
            y[k] = if ok { y[k] * rcp } else { self.n.y };
            z[k] = if ok { z[k] * rcp } else { self.n.z };
        }
        for k in 0..G {
            out[k] = Vec3::new(x[k], y[k], z[k]);
        }
    }
}

/// Sine and cosine of the azimuth 2π·`u2` of a hemisphere sample (`u2` in [0, 1]), within
/// 2·10⁻⁷ of the exact values (unit test). Written out rather than calling `f32::sin_cos`: a
/// library call per sample keeps [`azimuths`]' loop from vectorising, and it was about 40 %
/// of the time spent making AO rays. The turn is split exactly into a quarter turn `q` and a
/// remainder of at most an eighth of a turn (`4·u2 − q`, exact in floats), whose sine and
/// cosine are polynomials (the minimax coefficients of the Cephes library's `sinf`/`cosf` on
/// [−π/4, π/4]); the quarter turn swaps and negates them without branches.
#[inline]
pub fn azimuth(u2: f32) -> (f32, f32) {
    let turns = 4.0 * u2;
    // Rounded to the nearest quarter by truncation (`f32::round` is a library call on
    // x86-64's baseline, which would stop the vectorising); `turns` is not negative.
    let q = (turns + 0.5) as i32;
    let x = (turns - q as f32) * std::f32::consts::FRAC_PI_2;
    let z = x * x;
    let sin = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x;
    let cos = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    // The quarter turns 0..3 (4 is 0 again): +(s, c), (c, −s), −(s, c), (−c, s).
    let (sin, cos) = if q & 1 != 0 { (cos, sin) } else { (sin, cos) };
    let sin_negative = q & 2 != 0;
    let cos_negative = (q + 1) & 2 != 0;
    (
        if sin_negative { -sin } else { sin },
        if cos_negative { -cos } else { cos },
    )
}

/// [`azimuth`] of `G` samples at once (the same bits lane by lane), in a loop the compiler
/// vectorises.
#[inline]
pub fn azimuths<const G: usize>(u2: &[f32; G], sin: &mut [f32; G], cos: &mut [f32; G]) {
    for k in 0..G {
        (sin[k], cos[k]) = azimuth(u2[k]);
    }
}

/// Offset that does not shrink below this many scene units (metres), for points near the
/// world origin where relative precision is fine but intersection error is not zero.
const OFFSET_ABSOLUTE: f32 = 1e-4;

/// Offset per unit of the largest |coordinate|: 2⁻¹⁶, i.e. 128 float ulps of that coordinate,
/// well above the rounding error of a ray-triangle test at that position.
const OFFSET_RELATIVE: f32 = 1.0 / 65536.0;

/// Moves the surface point `x` along its unit normal `n` so that rays leaving it do not hit
/// the surface they start on. Float spacing grows with the magnitude of the coordinates, so
/// the offset is `1e-4 + 2⁻¹⁶·max|xᵢ|`: 0.1 mm near the origin, ~0.6 mm at 30 m, still
/// robust for scenes far from the origin. Small enough not to bias AO at R ≈ 0.6.
pub fn ray_offset(x: Vec3, n: Vec3) -> Vec3 {
    x + n * (OFFSET_ABSOLUTE + OFFSET_RELATIVE * x.abs().max_element())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal_everywhere() {
        let normals = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.0, 1e-8, -1.0).normalize(),
            Vec3::new(1.0, 2.0, -3.0).normalize(),
            Vec3::new(-0.3, 0.9, 1e-7).normalize(),
        ];
        for n in normals {
            let (t, b) = orthonormal_basis(n);
            for (v, w) in [(t, b), (t, n), (b, n)] {
                assert!(v.dot(w).abs() < 1e-6, "{n} {v} {w}");
            }
            assert!((t.length() - 1.0).abs() < 1e-6 && (b.length() - 1.0).abs() < 1e-6);
            assert!((t.cross(b) - n).length() < 1e-5, "right-handed for {n}");
        }
    }

    #[test]
    fn cosine_directions_have_the_right_moments() {
        // E[cos θ] = 2/3 and E[cos² θ] = 1/2 for pdf cos θ / π.
        let n = Vec3::new(0.2, -0.5, 0.8).normalize();
        let count = 4096;
        let (mut m1, mut m2) = (0.0, 0.0);
        for i in 0..count {
            let (u1, u2) = sample_2d(7, 3, i);
            let d = cosine_hemisphere(n, u1, u2);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let c = d.dot(n);
            assert!(c >= 0.0);
            m1 += c;
            m2 += c * c;
        }
        assert!((m1 / count as f32 - 2.0 / 3.0).abs() < 0.01);
        assert!((m2 / count as f32 - 0.5).abs() < 0.01);
    }

    #[test]
    fn lanes_give_the_bits_of_one_direction_at_a_time() {
        let mut normals = vec![Vec3::Z, -Vec3::Z, Vec3::ZERO, Vec3::new(0.0, 1e-8, -1.0)];
        normals.extend((0..200u64).map(|i| {
            let h = hash64(i);
            let c = |s: u32| ((h >> s) & 0xffff) as f32 / 32768.0 - 1.0;
            Vec3::new(c(0), c(16), c(32))
        }));
        for (i, &n) in normals.iter().enumerate() {
            let (sequence, hemisphere) = (Sequence2d::new(3, i as u64), Hemisphere::new(n));
            let mut u = [[0.0f32; 16]; 3];
            for k in 0..16 {
                let (u1, u2) = sample_2d(3, i as u64, k as u32 * 7);
                assert_eq!(sequence.at(k as u32 * 7), (u1, u2));
                // The ends of [0, 1] as well as sequence values.
                u[0][k] = [0.0, 1.0 - f32::EPSILON / 2.0, u1][k % 3];
                (u[1][k], u[2][k]) = azimuth(u2);
            }
            let mut lanes = [Vec3::ZERO; 16];
            hemisphere.cosine_lanes(&u[0], &u[1], &u[2], &mut lanes);
            for (k, lane) in lanes.iter().enumerate() {
                let u2 = sample_2d(3, i as u64, k as u32 * 7).1;
                let one = cosine_hemisphere(n, u[0][k], u2);
                assert_eq!(
                    lane.to_array().map(f32::to_bits),
                    one.to_array().map(f32::to_bits)
                );
            }
        }
    }

    #[test]
    fn azimuths_are_within_two_tenths_of_a_millionth_of_the_exact_sine_and_cosine() {
        // Every 24-bit value the sequence yields near the quarter-turn seams, and a sweep.
        let seams = (0..5u32).flat_map(|q| {
            let at = (q << 22) as i64;
            (at - 300..at + 300).filter(|&v| (0..1 << 24).contains(&v))
        });
        let sweep = (0..1i64 << 24).step_by(97);
        let (mut worst, mut lanes) = (0.0f64, [0.0f32; 16]);
        for (i, v) in seams.chain(sweep).enumerate() {
            let u = v as f32 / (1u32 << 24) as f32;
            let (s, c) = azimuth(u);
            let (es, ec) = (std::f64::consts::TAU * f64::from(u)).sin_cos();
            worst = worst.max((f64::from(s) - es).abs().max((f64::from(c) - ec).abs()));
            lanes[i % 16] = u;
        }
        assert!(worst < 2e-7, "worst error {worst:e}");
        let (mut sin, mut cos) = ([0.0; 16], [0.0; 16]);
        azimuths(&lanes, &mut sin, &mut cos);
        for k in 0..16 {
            let one = azimuth(lanes[k]);
            assert_eq!(
                (sin[k].to_bits(), cos[k].to_bits()),
                (one.0.to_bits(), one.1.to_bits())
            );
        }
    }

    #[test]
    fn samples_are_deterministic_stratified_and_keyed() {
        assert_eq!(sample_2d(1, 2, 3), sample_2d(1, 2, 3));
        assert_ne!(sample_2d(1, 2, 3), sample_2d(2, 1, 3));
        assert_ne!(sample_2d(1, 2, 3), sample_2d(1, 3, 3));
        // 64 consecutive R2 points cover every cell of an 8×8 grid at most a few times.
        let mut grid = [0u32; 64];
        for i in 0..64 {
            let (x, y) = sample_2d(42, 9, i);
            assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
            grid[(x * 8.0) as usize * 8 + (y * 8.0) as usize] += 1;
        }
        assert!(grid.iter().all(|&c| c <= 3), "{grid:?}");
        assert!(grid.iter().filter(|&&c| c == 0).count() <= 12, "{grid:?}");
    }

    #[test]
    fn offset_scales_with_distance_from_origin() {
        let near = ray_offset(Vec3::ZERO, Vec3::Y).y;
        let far = ray_offset(Vec3::new(1e4, 0.0, 0.0), Vec3::Y).y;
        assert!(near > 0.0 && near < 1e-3);
        // At 10 km the offset must exceed the float spacing there (~1 mm) by a wide margin.
        assert!(far > 100.0 * (f32::from_bits(1e4f32.to_bits() + 1) - 1e4));
    }
}
