//! Keyframe sampling of one glTF animation channel: step, linear (slerp for rotations) and
//! cubic-spline (Hermite) interpolation, clamped to the first and last keys.

use glam::{Quat, Vec3, Vec4};

use crate::model::{AnimatedProperty, Channel, Interpolation};

/// A sampled channel value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Sampled {
    /// A translation or scale.
    Vector(Vec3),
    /// A unit rotation.
    Rotation(Quat),
}

/// Floats per key value of a property.
pub(crate) fn width(property: AnimatedProperty) -> usize {
    match property {
        AnimatedProperty::Rotation => 4,
        AnimatedProperty::Translation | AnimatedProperty::Scale => 3,
    }
}

/// The channel's value at clip time `t` (seconds). Before the first key the first value
/// holds, after the last key the last one. The channel must be consistent (checked by
/// [`super::Animator::new`]).
pub(crate) fn sample(channel: &Channel, t: f32) -> Sampled {
    let w = width(channel.property);
    let cubic = channel.interpolation == Interpolation::CubicSpline;
    // Offset of key k's value (cubic keys store in-tangent, value, out-tangent).
    let value_at = |k: usize| {
        let start = if cubic { (3 * k + 1) * w } else { k * w };
        load(&channel.values[start..start + w])
    };
    let times = &channel.times;
    let next = times.partition_point(|&x| x <= t);
    let raw = if next == 0 {
        value_at(0)
    } else if next == times.len() {
        value_at(times.len() - 1)
    } else {
        let k = next - 1;
        let dt = times[k + 1] - times[k];
        let s = (t - times[k]) / dt;
        match channel.interpolation {
            Interpolation::Step => value_at(k),
            Interpolation::Linear => {
                if channel.property == AnimatedProperty::Rotation {
                    let a = Quat::from_vec4(value_at(k)).normalize();
                    let b = Quat::from_vec4(value_at(k + 1)).normalize();
                    return Sampled::Rotation(a.slerp(b, s).normalize());
                }
                value_at(k).lerp(value_at(k + 1), s)
            }
            Interpolation::CubicSpline => {
                let out_tangent = load(&channel.values[(3 * k + 2) * w..(3 * k + 3) * w]);
                let in_tangent = load(&channel.values[(3 * k + 3) * w..(3 * k + 4) * w]);
                hermite(value_at(k), out_tangent, value_at(k + 1), in_tangent, s, dt)
            }
        }
    };
    match channel.property {
        AnimatedProperty::Rotation => {
            Sampled::Rotation(raw.try_normalize().map_or(Quat::IDENTITY, Quat::from_vec4))
        }
        AnimatedProperty::Translation | AnimatedProperty::Scale => Sampled::Vector(raw.truncate()),
    }
}

/// A value of 3 or 4 floats as a `Vec4` (w = 0 for 3).
fn load(v: &[f32]) -> Vec4 {
    Vec4::new(v[0], v[1], v[2], v.get(3).copied().unwrap_or(0.0))
}

/// The glTF cubic Hermite spline between `p0` (out-tangent `m0`) and `p1` (in-tangent `m1`)
/// at normalised time `s` over an interval of `dt` seconds.
fn hermite(p0: Vec4, m0: Vec4, p1: Vec4, m1: Vec4, s: f32, dt: f32) -> Vec4 {
    let s2 = s * s;
    let s3 = s2 * s;
    p0 * (2.0 * s3 - 3.0 * s2 + 1.0)
        + m0 * (dt * (s3 - 2.0 * s2 + s))
        + p1 * (-2.0 * s3 + 3.0 * s2)
        + m1 * (dt * (s3 - s2))
}

/// Why a channel cannot be sampled, or `None` when it is consistent.
pub(crate) fn check(channel: &Channel) -> Option<String> {
    let per_key = width(channel.property)
        * if channel.interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
    if channel.times.is_empty() {
        return Some("no keyframes".into());
    }
    if channel.times.iter().any(|t| !t.is_finite()) || channel.values.iter().any(|v| !v.is_finite())
    {
        return Some("non-finite key time or value".into());
    }
    if channel.times.windows(2).any(|w| w[1] < w[0]) {
        return Some("key times decrease".into());
    }
    if channel.values.len() != channel.times.len() * per_key {
        return Some(format!(
            "{} values for {} keys ({per_key} floats per key expected)",
            channel.values.len(),
            channel.times.len()
        ));
    }
    None
}
