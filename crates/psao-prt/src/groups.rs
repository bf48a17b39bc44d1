//! The skinned characters of a scene: one per skinned node group (the skinned instances
//! under one root node; in a scene file, one asset), each as the scene reduced to the
//! group's instances and the first playing clip that moves it. The server trains one model
//! per group and clients relight the same groups in the same order (docs/RELIGHTING.md,
//! "Served characters").

use psao_scene::{Instance, Scene};

/// One skinned node group of a scene.
#[derive(Clone, Debug)]
pub struct SkinnedGroup {
    /// The root node of the group's hierarchy.
    pub root: usize,
    /// The scene with only the group's instances (skinned and rigid) and, as its only clip,
    /// the first playing clip that moves the group (none when no playing clip does).
    pub scene: Scene,
    /// Per instance of [`Self::scene`]: its index in the whole scene.
    pub instances: Vec<usize>,
}

/// The scene's skinned node groups, in the order of their first skinned instance.
pub fn skinned_groups(scene: &Scene) -> Vec<SkinnedGroup> {
    let root = |inst: &Instance| {
        let node = inst.node.or_else(|| {
            let skin = scene.skins.get(inst.skin?)?;
            skin.joints.first().copied()
        })?;
        Some(root_of(scene, node))
    };
    let skinned = |inst: &Instance| {
        inst.skin.is_some()
            && scene
                .meshes
                .get(inst.mesh)
                .is_some_and(|m| !m.joints.is_empty())
    };
    let mut roots: Vec<usize> = Vec::new();
    for inst in scene.instances.iter().filter(|i| skinned(i)) {
        if let Some(r) = root(inst) {
            if !roots.contains(&r) {
                roots.push(r);
            }
        }
    }
    roots
        .into_iter()
        .map(|r| {
            let instances: Vec<usize> = (0..scene.instances.len())
                .filter(|&i| root(&scene.instances[i]) == Some(r))
                .collect();
            let mut sub = scene.clone();
            sub.instances = instances
                .iter()
                .map(|&i| scene.instances[i].clone())
                .collect();
            let clip = scene.playing.iter().copied().find(|&a| {
                scene.animations.get(a).is_some_and(|a| {
                    a.channels
                        .iter()
                        .any(|c| c.node < scene.nodes.len() && root_of(scene, c.node) == r)
                })
            });
            sub.animations = clip
                .and_then(|a| scene.animations.get(a).cloned())
                .into_iter()
                .collect();
            sub.playing = (0..sub.animations.len()).collect();
            SkinnedGroup {
                root: r,
                scene: sub,
                instances,
            }
        })
        .collect()
}

/// The root of `node`'s hierarchy (at most as many steps as there are nodes).
fn root_of(scene: &Scene, node: usize) -> usize {
    let mut n = node;
    for _ in 0..scene.nodes.len() {
        match scene.nodes.get(n).and_then(|x| x.parent) {
            Some(p) => n = p,
            None => break,
        }
    }
    n
}
