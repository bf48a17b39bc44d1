//! The glTF node tree: local transforms, parent links, world transforms and the nodes of
//! the displayed scene, validated to be a forest (no node with two parents, no cycles).

use std::path::Path;

use ::gltf::scene::Transform;
use ::gltf::Document;
use glam::{Affine3A, Mat4, Quat, Vec3, Vec4};

use crate::error::SceneError;
use crate::model::Node;

/// The validated node forest of one glTF document.
pub(super) struct Hierarchy {
    /// All nodes of the document, same indices as in the file.
    pub nodes: Vec<Node>,
    /// World transform of every node at rest.
    pub world: Vec<Affine3A>,
    /// Nodes of the displayed scene (default scene, else all roots), parents first.
    pub shown: Vec<usize>,
}

/// Builds the forest; errors on non-finite transforms, shared children and cycles.
pub(super) fn build(doc: &Document, path: &Path) -> Result<Hierarchy, SceneError> {
    let mut nodes = Vec::with_capacity(doc.nodes().len());
    let mut children = Vec::with_capacity(doc.nodes().len());
    for node in doc.nodes() {
        let (translation, rotation, scale) = local_trs(node.transform()).ok_or_else(|| {
            SceneError::non_finite(path, format!("node {} transform", node.index()))
        })?;
        nodes.push(Node {
            name: node
                .name()
                .map_or_else(|| format!("node{}", node.index()), str::to_owned),
            parent: None,
            translation,
            rotation,
            scale,
        });
        children.push(node.children().map(|c| c.index()).collect::<Vec<_>>());
    }
    for (parent, kids) in children.iter().enumerate() {
        for &child in kids {
            let slot = nodes
                .get_mut(child)
                .ok_or_else(|| SceneError::index(path, "child node", child, children.len()))?;
            if child == parent || slot.parent.is_some() {
                return Err(SceneError::parse(
                    path,
                    "glTF",
                    format!("node {child} has more than one parent or is its own child"),
                ));
            }
            slot.parent = Some(parent);
        }
    }
    let roots: Vec<usize> = (0..nodes.len())
        .filter(|&i| nodes[i].parent.is_none())
        .collect();
    let mut world = vec![Affine3A::IDENTITY; nodes.len()];
    let reached = visit(&roots, &children, |node, parent| {
        let local = nodes[node].local_transform();
        world[node] = parent.map_or(local, |p| world[p] * local);
    });
    if reached.len() != nodes.len() {
        return Err(SceneError::parse(
            path,
            "glTF",
            "node hierarchy contains a cycle",
        ));
    }
    let scene_roots = match doc.default_scene() {
        Some(scene) => scene.nodes().map(|n| n.index()).collect(),
        None => roots,
    };
    let shown = visit(&scene_roots, &children, |_, _| {});
    Ok(Hierarchy {
        nodes,
        world,
        shown,
    })
}

/// Depth-first walk from `roots`, each node once, parents before children; calls
/// `f(node, parent_in_walk)` and returns the visit order.
fn visit(
    roots: &[usize],
    children: &[Vec<usize>],
    mut f: impl FnMut(usize, Option<usize>),
) -> Vec<usize> {
    let mut seen = vec![false; children.len()];
    let mut order = Vec::new();
    let mut stack: Vec<(usize, Option<usize>)> = roots.iter().rev().map(|&r| (r, None)).collect();
    while let Some((node, parent)) = stack.pop() {
        if node >= seen.len() || seen[node] {
            continue;
        }
        seen[node] = true;
        f(node, parent);
        order.push(node);
        stack.extend(children[node].iter().rev().map(|&c| (c, Some(node))));
    }
    order
}

/// A node's local TRS; `None` when any number is non-finite.
fn local_trs(t: Transform) -> Option<(Vec3, Quat, Vec3)> {
    let (t, r, s) = match t {
        Transform::Matrix { matrix } => decompose(Mat4::from_cols_array_2d(&matrix))?,
        Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => (
            Vec3::from_array(translation),
            Quat::from_array(rotation),
            Vec3::from_array(scale),
        ),
    };
    if !(t.is_finite() && r.is_finite() && s.is_finite()) {
        return None;
    }
    let r = Vec4::from(r).try_normalize().map_or_else(
        || {
            tracing::warn!("zero-length node rotation replaced by identity");
            Quat::IDENTITY
        },
        Quat::from_vec4,
    );
    Some((t, r, s))
}

/// Splits an affine matrix into translation, rotation and scale; a zero scale axis yields
/// an identity rotation instead of NaNs.
fn decompose(m: Mat4) -> Option<(Vec3, Quat, Vec3)> {
    if !m.is_finite() {
        return None;
    }
    let (s, r, t) = m.to_scale_rotation_translation();
    if s.cmpeq(Vec3::ZERO).any() || !r.is_finite() {
        Some((t, Quat::IDENTITY, s))
    } else {
        Some((t, r, s))
    }
}
