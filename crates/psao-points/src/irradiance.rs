//! The 32-bit irradiance record of a point (DESIGN §12): linear RGB in the shared-exponent
//! RGB9E5 layout of OpenGL's `EXT_texture_shared_exponent` (bits 0–8 red, 9–17 green,
//! 18–26 blue mantissas, 27–31 the exponent, bias 15).
//!
//! Why RGB9E5 and not LogLuv: irradiance is linear RGB and stays linear RGB in the client's
//! shading (`base colour × irradiance`); RGB9E5 decodes with one multiply per channel and is a
//! native sampled texture format of WebGL2 and OpenGL ES 3, so the browser viewer can keep the
//! records in a texture as they arrive. Its precision is relative to the brightest channel
//! (a step of at most 2⁻⁹ of it, 0.2 %), which suits diffuse irradiance (smooth, mostly
//! weakly saturated colours); LogLuv's uniform 0.3 % per channel over 38 decades would only pay
//! off for strongly saturated, extremely dim channels, at the price of a colour-space
//! conversion and a logarithm per decode. The range, 2⁻²⁴ to [`RGB9E5_MAX`] = 65408, covers
//! irradiance from starlight to a direct sun in the scene's units; larger values clamp.

use glam::Vec3;

/// Mantissa bits per channel.
const MANTISSA_BITS: i32 = 9;
/// Exponent bias.
const BIAS: i32 = 15;
/// Largest exponent.
const MAX_EXPONENT: i32 = 31;
/// Largest value a channel can hold: (511 / 512) · 2¹⁶.
pub const RGB9E5_MAX: f32 = 511.0 / 512.0 * 65536.0;

/// Irradiance below which differences do not count as perceptible (in the scene's units; the
/// default sky gives an open surface 0.6·π ≈ 1.9): the absolute floor of
/// [`irradiance_changed`], so noise in near-black points is not resent.
pub const IRRADIANCE_FLOOR: f32 = 0.01;

/// Rec. 709 luminance of linear RGB.
pub fn luminance(rgb: Vec3) -> f32 {
    rgb.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// Whether irradiance `new` differs perceptibly from `old`: some channel moved by more than
/// `threshold` times the brighter of the two luminances (a Weber fraction; 8/255 ≈ 3 % like
/// the AO threshold), with luminances below [`IRRADIANCE_FLOOR`] counted as the floor.
pub fn irradiance_changed(old: Vec3, new: Vec3, threshold: f32) -> bool {
    let scale = luminance(old).max(luminance(new)).max(IRRADIANCE_FLOOR);
    (new - old).abs().max_element() > threshold * scale
}

/// `2^e` for an exponent in the range RGB9E5 uses.
fn exp2i(e: i32) -> f32 {
    f32::from_bits(((e + 127) as u32) << 23)
}

/// The record of linear RGB `rgb`: negative and NaN channels are 0, channels above
/// [`RGB9E5_MAX`] (and +∞) are clamped to it; each channel is rounded to the nearest step of
/// the shared exponent.
pub fn pack_rgb9e5(rgb: Vec3) -> u32 {
    let clamp = |v: f32| {
        if v > 0.0 {
            v.min(RGB9E5_MAX)
        } else {
            0.0 // negative, zero and NaN
        }
    };
    let c = [clamp(rgb.x), clamp(rgb.y), clamp(rgb.z)];
    let max = c[0].max(c[1]).max(c[2]);
    // ⌊log₂ max⌋ from the float's exponent (zero and subnormals land below the range).
    let floor_log2 = ((max.to_bits() >> 23) & 0xff) as i32 - 127;
    let mut exponent = floor_log2.max(-BIAS - 1) + 1 + BIAS;
    let max_mantissa = (max / exp2i(exponent - BIAS - MANTISSA_BITS) + 0.5).floor();
    if max_mantissa >= (1 << MANTISSA_BITS) as f32 {
        exponent += 1;
    }
    debug_assert!((0..=MAX_EXPONENT).contains(&exponent));
    let step = exp2i(exponent - BIAS - MANTISSA_BITS);
    let m = c.map(|v| ((v / step + 0.5).floor() as u32).min((1 << MANTISSA_BITS) - 1));
    m[0] | m[1] << 9 | m[2] << 18 | (exponent as u32) << 27
}

/// The linear RGB of a record.
pub fn unpack_rgb9e5(bits: u32) -> Vec3 {
    let step = exp2i((bits >> 27) as i32 - BIAS - MANTISSA_BITS);
    let m = |shift: u32| ((bits >> shift) & 0x1ff) as f32 * step;
    Vec3::new(m(0), m(9), m(18))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(v: Vec3) -> Vec3 {
        unpack_rgb9e5(pack_rgb9e5(v))
    }

    #[test]
    fn zero_and_exact_values_round_trip_exactly() {
        assert_eq!(round_trip(Vec3::ZERO), Vec3::ZERO);
        for v in [
            Vec3::ONE,
            Vec3::new(0.5, 0.25, 0.125),
            Vec3::new(3.0, 0.0, 1.5),
            Vec3::splat(RGB9E5_MAX),
            Vec3::new(511.0, 1.0, 0.0),
        ] {
            assert_eq!(round_trip(v), v, "{v}");
        }
    }

    #[test]
    fn error_is_at_most_half_a_step_of_the_brightest_channel() {
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..20_000 {
            // Spread over 2⁻¹⁵ … 2¹⁵, above the smallest exponent (where steps stop shrinking).
            let scale = 2f32.powf(next() * 30.0 - 15.0);
            let v = Vec3::new(next(), next(), next()) * scale;
            let max = v.max_element();
            if max < 2f32.powi(-15) {
                continue;
            }
            let err = (round_trip(v) - v).abs().max_element();
            // A step is at most 2⁻⁸ of the brightest channel (just over it when rounding moved
            // the exponent up), and rounding errs by half a step.
            assert!(err <= max / 511.0, "{v}: error {err}");
        }
    }

    #[test]
    fn huge_tiny_negative_and_nan_channels_are_clamped() {
        assert_eq!(round_trip(Vec3::splat(1e9)), Vec3::splat(RGB9E5_MAX));
        assert_eq!(
            round_trip(Vec3::new(f32::INFINITY, 1.0, 0.0)),
            Vec3::new(RGB9E5_MAX, 0.0, 0.0)
        );
        assert_eq!(
            round_trip(Vec3::new(-1.0, f32::NAN, 2.0)),
            Vec3::new(0.0, 0.0, 2.0)
        );
        assert_eq!(round_trip(Vec3::splat(f32::NEG_INFINITY)), Vec3::ZERO);
        // Below the smallest step (2⁻²⁴) a value rounds to zero; at it, it is kept.
        assert_eq!(round_trip(Vec3::splat(1e-9)), Vec3::ZERO);
        let smallest = 2f32.powi(-24);
        assert_eq!(round_trip(Vec3::new(smallest, 0.0, 0.0)).x, smallest);
        // A channel far below the brightest keeps the brightest channel's step.
        let v = round_trip(Vec3::new(100.0, 0.01, 0.0));
        assert_eq!(v.x, 100.0);
        assert!(v.y < 0.25 && v.z == 0.0);
    }

    #[test]
    fn perceptible_changes_are_relative_above_the_floor() {
        let t = 8.0 / 255.0;
        let grey = Vec3::splat(2.0);
        assert!(!irradiance_changed(grey, grey * 1.02, t));
        assert!(irradiance_changed(grey, grey * 1.05, t));
        // A colour shift at the same luminance counts.
        assert!(irradiance_changed(grey, Vec3::new(2.2, 1.95, 2.0), t));
        // Near black, differences below the floor's fraction do not.
        assert!(!irradiance_changed(
            Vec3::ZERO,
            Vec3::splat(IRRADIANCE_FLOOR * 0.03),
            t
        ));
        assert!(irradiance_changed(
            Vec3::ZERO,
            Vec3::splat(IRRADIANCE_FLOOR * 0.05),
            t
        ));
        // RGB9E5's rounding is well below the threshold.
        let v = Vec3::new(0.7, 1.3, 0.2);
        assert!(!irradiance_changed(v, round_trip(v), t));
    }

    #[test]
    fn rounding_up_to_the_next_exponent_is_exact() {
        // Just below 2: the mantissa rounds to 512 at exponent 0 and moves to exponent 1.
        let v = Vec3::new(1.9999, 0.0, 0.0);
        let bits = pack_rgb9e5(v);
        assert_eq!(unpack_rgb9e5(bits), Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(bits & 0x1ff, 256);
    }
}
