//! Checks on the raw glTF JSON that the `gltf` crate (1.4) needs but does not make itself:
//! its validator indexes the POSITION accessor unchecked, and its animation wrappers
//! unwrap channel targets that validation never looked at.

use std::path::Path;

use ::gltf::json::mesh::Semantic;
use ::gltf::json::validation::Checked;
use ::gltf::json::Root;

use crate::error::SceneError;

/// Fails on references the `gltf` crate would otherwise panic on.
pub(super) fn precheck(root: &Root, path: &Path) -> Result<(), SceneError> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(acc) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) {
                if acc.value() >= root.accessors.len() {
                    return Err(SceneError::index(
                        path,
                        format!("mesh {m} primitive {p} POSITION accessor"),
                        acc.value(),
                        root.accessors.len(),
                    ));
                }
            }
        }
    }
    for (a, anim) in root.animations.iter().enumerate() {
        for (c, channel) in anim.channels.iter().enumerate() {
            let node = channel.target.node.value();
            if node >= root.nodes.len() {
                return Err(SceneError::index(
                    path,
                    format!("animation {a} channel {c} target node"),
                    node,
                    root.nodes.len(),
                ));
            }
            if channel.target.path == Checked::Invalid {
                return Err(SceneError::parse(
                    path,
                    "glTF",
                    format!("animation {a} channel {c}: unknown target path"),
                ));
            }
        }
    }
    Ok(())
}
