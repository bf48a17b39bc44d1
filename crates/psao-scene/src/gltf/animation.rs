//! glTF skins and animation clips.

use ::gltf::accessor::Dimensions;
use ::gltf::animation::{Interpolation as GltfInterpolation, Property};
use glam::Mat4;

use super::accessor::BufferData;
use crate::error::SceneError;
use crate::model::{AnimatedProperty, Animation, Channel, Interpolation, Skin};

/// Converts a skin; a missing inverse-bind accessor means identity matrices.
pub(super) fn skin(skin: &::gltf::Skin, data: &BufferData) -> Result<Skin, SceneError> {
    let name = skin
        .name()
        .map_or_else(|| format!("skin{}", skin.index()), str::to_owned);
    let joints: Vec<usize> = skin.joints().map(|n| n.index()).collect();
    let inverse_bind = match skin.inverse_bind_matrices() {
        None => vec![Mat4::IDENTITY; joints.len()],
        Some(acc) => {
            let flat = data.floats(
                &acc,
                &[Dimensions::Mat4],
                &format!("{name} inverseBindMatrices"),
            )?;
            let mats: Vec<Mat4> = flat.chunks_exact(16).map(Mat4::from_cols_slice).collect();
            if mats.len() < joints.len() {
                return Err(SceneError::parse(
                    data.path,
                    "glTF",
                    format!(
                        "{name}: {} inverse bind matrices for {} joints",
                        mats.len(),
                        joints.len()
                    ),
                ));
            }
            mats.into_iter().take(joints.len()).collect()
        }
    };
    Ok(Skin {
        name,
        joints,
        inverse_bind,
    })
}

/// Converts a clip; morph-weight channels are skipped with a warning.
pub(super) fn animation(
    anim: &::gltf::Animation,
    data: &BufferData,
) -> Result<Animation, SceneError> {
    let name = anim
        .name()
        .map_or_else(|| format!("animation{}", anim.index()), str::to_owned);
    let mut channels = Vec::new();
    for (c, channel) in anim.channels().enumerate() {
        let target = channel.target();
        let (property, dims) = match target.property() {
            Property::Translation => (AnimatedProperty::Translation, Dimensions::Vec3),
            Property::Rotation => (AnimatedProperty::Rotation, Dimensions::Vec4),
            Property::Scale => (AnimatedProperty::Scale, Dimensions::Vec3),
            Property::MorphTargetWeights => {
                tracing::warn!(
                    "{}: {name}: morph-weight channel {c} skipped",
                    data.path.display()
                );
                continue;
            }
        };
        let what = format!("{name} channel {c}");
        let sampler = channel.sampler();
        let interpolation = match sampler.interpolation() {
            GltfInterpolation::Step => Interpolation::Step,
            GltfInterpolation::Linear => Interpolation::Linear,
            GltfInterpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let times = data.floats(
            &sampler.input(),
            &[Dimensions::Scalar],
            &format!("{what} times"),
        )?;
        let values = data.floats(&sampler.output(), &[dims], &format!("{what} values"))?;
        let bad =
            |message: String| SceneError::parse(data.path, "glTF", format!("{what}: {message}"));
        if times.is_empty() {
            return Err(bad("no keyframes".into()));
        }
        if times.windows(2).any(|w| w[1] < w[0]) {
            return Err(bad("key times decrease".into()));
        }
        let per_key = dims.multiplicity()
            * if interpolation == Interpolation::CubicSpline {
                3
            } else {
                1
            };
        if values.len() != times.len() * per_key {
            return Err(bad(format!(
                "{} values for {} keys ({per_key} floats per key expected)",
                values.len(),
                times.len()
            )));
        }
        channels.push(Channel {
            node: target.node().index(),
            property,
            interpolation,
            times,
            values,
        });
    }
    Ok(Animation { name, channels })
}
