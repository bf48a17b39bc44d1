//! Animation playback: node poses from the playing clips and walkers, instance transforms,
//! and linear-blend skinning of deforming instances.
//!
//! Build an [`Animator`] once per scene (it validates and copies what playback needs), then
//! ask it for a [`ScenePose`] at any scene time; [`Animator::pose_into`] reuses the buffers.
//! Every playing clip loops over its own duration; walkers loop along their paths.

mod sample;
mod skin;
#[cfg(test)]
mod tests;
pub(crate) mod walk;

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec3};
use rayon::prelude::*;

use crate::affine::{invert_or_identity, transformed_box};
use crate::model::{Channel, Node, Scene};
use sample::Sampled;
use skin::BindMesh;
use walk::WalkPath;

/// Why a scene's animation data cannot be played.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AnimationError {
    /// An index (node, mesh, skin, joint) points outside its array.
    #[error("{what} index {index} out of range (only {count})")]
    Index {
        /// What kind of index, and where.
        what: String,
        /// The offending index.
        index: usize,
        /// Number of valid entries.
        count: usize,
    },
    /// The node parent links contain a cycle.
    #[error("node hierarchy contains a cycle")]
    Cycle,
    /// A playing clip's channel is inconsistent.
    #[error("clip '{clip}' channel {channel}: {message}")]
    Channel {
        /// Clip name.
        clip: String,
        /// Channel index within the clip.
        channel: usize,
        /// What is wrong.
        message: String,
    },
    /// A skinned instance's mesh or skin is inconsistent.
    #[error("instance {instance}: {message}")]
    Skin {
        /// Instance index.
        instance: usize,
        /// What is wrong.
        message: String,
    },
    /// A walker is unusable.
    #[error("walker {walker}: {message}")]
    Walker {
        /// Walker index.
        walker: usize,
        /// What is wrong.
        message: String,
    },
}

/// How an instance changes over time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Motion {
    /// Never moves: its transform and vertices stay as stored in the scene.
    Static,
    /// Moves rigidly: its transform changes, its mesh-local vertices do not.
    Rigid,
    /// Deforms by skinning: its mesh-local vertices change (its transform may change too).
    Skinned,
}

/// Deformed vertices of one skinned instance in its mesh-local space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SkinnedGeometry {
    /// One position per mesh vertex.
    pub positions: Vec<Vec3>,
    /// One unit normal per mesh vertex.
    pub normals: Vec<Vec3>,
}

/// Everything that moves, sampled at one scene time.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScenePose {
    /// The scene time in seconds.
    pub time: f32,
    /// World transform of every node.
    pub nodes: Vec<Affine3A>,
    /// Mesh-local to world transform of every instance.
    pub transforms: Vec<Affine3A>,
    /// Per instance: the skinned vertices for [`Motion::Skinned`] instances, else `None`
    /// (the mesh's own vertices apply).
    pub skinned: Vec<Option<SkinnedGeometry>>,
}

/// One instance's geometry in a [`ScenePose`] (the shape of `psao_raster::InstancePose`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosedInstance<'a> {
    /// Mesh-local to world transform.
    pub transform: Affine3A,
    /// Skinned positions replacing the mesh's, when the instance deforms.
    pub positions: Option<&'a [Vec3]>,
    /// Skinned unit normals replacing the mesh's, when the instance deforms.
    pub normals: Option<&'a [Vec3]>,
}

impl ScenePose {
    /// Instance `i`'s transform and deformed vertices; `None` when out of range.
    pub fn instance(&self, i: usize) -> Option<PosedInstance<'_>> {
        let transform = *self.transforms.get(i)?;
        let geometry = self.skinned.get(i).and_then(Option::as_ref);
        Some(PosedInstance {
            transform,
            positions: geometry.map(|g| g.positions.as_slice()),
            normals: geometry.map(|g| g.normals.as_slice()),
        })
    }
}

/// A playing clip, copied with its loop length.
#[derive(Clone, Debug)]
struct Clip {
    duration: f32,
    channels: Vec<Channel>,
}

/// A skinned instance's inputs.
#[derive(Debug)]
struct SkinRig {
    instance: usize,
    joints: Vec<usize>,
    inverse_bind: Vec<Affine3A>,
    mesh: Arc<BindMesh>,
}

/// Plays a scene's animations: validated, self-contained copies of what playback needs.
#[derive(Debug)]
pub struct Animator {
    rest: Vec<Node>,
    parents: Vec<Option<usize>>,
    /// Node indices, parents before children.
    order: Vec<usize>,
    clips: Vec<Clip>,
    walkers: Vec<WalkPath>,
    /// Per instance: its node, when it follows one.
    instance_nodes: Vec<Option<usize>>,
    /// Per instance: its stored transform (used while it does not move).
    rest_transforms: Vec<Affine3A>,
    /// Per instance: its mesh's local bounds (min, max); empty meshes have min > max.
    local_bounds: Vec<(Vec3, Vec3)>,
    motion: Vec<Motion>,
    rigs: Vec<SkinRig>,
}

impl Animator {
    /// Validates `scene`'s nodes, playing clips, walkers and skins and prepares playback.
    pub fn new(scene: &Scene) -> Result<Self, AnimationError> {
        let node_count = scene.nodes.len();
        let index =
            |what: String, index: usize, count: usize| AnimationError::Index { what, index, count };
        let parents: Vec<Option<usize>> = scene.nodes.iter().map(|n| n.parent).collect();
        for (i, p) in parents.iter().enumerate() {
            if let Some(p) = *p {
                if p >= node_count {
                    return Err(index(format!("node {i} parent"), p, node_count));
                }
            }
        }
        let order = parents_first(&parents)?;

        let mut clips = Vec::new();
        for &a in &scene.playing {
            let anim = scene
                .animations
                .get(a)
                .ok_or_else(|| index("playing clip".into(), a, scene.animations.len()))?;
            for (c, ch) in anim.channels.iter().enumerate() {
                if ch.node >= node_count {
                    return Err(index(
                        format!("clip '{}' channel {c} node", anim.name),
                        ch.node,
                        node_count,
                    ));
                }
                if let Some(message) = sample::check(ch) {
                    return Err(AnimationError::Channel {
                        clip: anim.name.clone(),
                        channel: c,
                        message,
                    });
                }
            }
            clips.push(Clip {
                duration: anim.duration(),
                channels: anim.channels.clone(),
            });
        }

        let mut walkers = Vec::with_capacity(scene.walkers.len());
        for (w, walker) in scene.walkers.iter().enumerate() {
            let message = walk::check(walker, node_count).or_else(|| {
                parents[walker.node].map(|p| format!("node {} has parent {p}", walker.node))
            });
            if let Some(message) = message {
                return Err(AnimationError::Walker { walker: w, message });
            }
            walkers.push(WalkPath::new(walker));
        }

        // Nodes driven directly, then everything below them.
        let mut driven = vec![false; node_count];
        clips
            .iter()
            .flat_map(|c| &c.channels)
            .for_each(|ch| driven[ch.node] = true);
        walkers.iter().for_each(|w| driven[w.node()] = true);
        let mut moving = driven.clone();
        for &n in &order {
            if let Some(p) = parents[n] {
                moving[n] |= moving[p];
            }
        }

        let mut motion = Vec::with_capacity(scene.instances.len());
        let mut rigs = Vec::new();
        let mut bind_meshes: HashMap<usize, Arc<BindMesh>> = HashMap::new();
        for (i, inst) in scene.instances.iter().enumerate() {
            if let Some(n) = inst.node {
                if n >= node_count {
                    return Err(index(format!("instance {i} node"), n, node_count));
                }
            }
            let mesh = scene.meshes.get(inst.mesh).ok_or_else(|| {
                index(format!("instance {i} mesh"), inst.mesh, scene.meshes.len())
            })?;
            let rigid = inst.node.is_some_and(|n| moving[n]);
            let deforms = match inst.skin {
                Some(s) if !mesh.joints.is_empty() => {
                    let skin = scene
                        .skins
                        .get(s)
                        .ok_or_else(|| index(format!("instance {i} skin"), s, scene.skins.len()))?;
                    let deforms = joints_move_relative(
                        &skin.joints,
                        inst.node,
                        &driven,
                        &parents,
                        node_count,
                    )
                    .map_err(|j| index(format!("instance {i} joint node"), j, node_count))?;
                    if deforms {
                        rigs.push(skin_rig(scene, i, s, &mut bind_meshes)?);
                    }
                    deforms
                }
                _ => false,
            };
            motion.push(if deforms {
                Motion::Skinned
            } else if rigid {
                Motion::Rigid
            } else {
                Motion::Static
            });
        }

        Ok(Self {
            rest: scene.nodes.clone(),
            parents,
            order,
            clips,
            walkers,
            instance_nodes: scene.instances.iter().map(|i| i.node).collect(),
            rest_transforms: scene.instances.iter().map(|i| i.transform).collect(),
            local_bounds: scene
                .instances
                .iter()
                .map(|i| bounds(&scene.meshes[i.mesh].positions))
                .collect(),
            motion,
            rigs,
        })
    }

    /// How each instance moves (indexed like `Scene::instances`).
    pub fn motion(&self) -> &[Motion] {
        &self.motion
    }

    /// Whether anything moves at all.
    pub fn is_dynamic(&self) -> bool {
        self.motion.iter().any(|&m| m != Motion::Static)
    }

    /// World-space bounds (min, max) of instance `i` in `pose` (skinned vertices where the
    /// pose has them, else the mesh's box under the instance transform); `None` when `i` is
    /// out of range or the mesh has no vertices.
    pub fn world_bounds(&self, pose: &ScenePose, i: usize) -> Option<(Vec3, Vec3)> {
        let transform = *pose.transforms.get(i)?;
        let (lo, hi) = self.mesh_bounds(pose, i)?;
        Some(transformed_box(&transform, lo, hi))
    }

    /// Mesh-space bounds (min, max) of instance `i` in `pose`: its skinned vertices where the
    /// pose has them, else its mesh's box; `None` as for [`Self::world_bounds`].
    pub fn mesh_bounds(&self, pose: &ScenePose, i: usize) -> Option<(Vec3, Vec3)> {
        let (lo, hi) = match pose.skinned.get(i).and_then(Option::as_ref) {
            Some(g) => bounds(&g.positions),
            None => *self.local_bounds.get(i)?,
        };
        (lo.cmple(hi).all()).then_some((lo, hi))
    }

    /// The pose at scene time `time` (seconds).
    pub fn pose_at(&self, time: f32) -> ScenePose {
        let mut pose = ScenePose::default();
        self.pose_into(time, &mut pose);
        pose
    }

    /// Writes the pose at `time` into `pose`, reusing its buffers.
    pub fn pose_into(&self, time: f32, pose: &mut ScenePose) {
        pose.time = time;
        self.node_worlds(time, &mut pose.nodes);
        pose.transforms.clear();
        pose.transforms.extend(
            self.instance_nodes
                .iter()
                .zip(&self.motion)
                .zip(&self.rest_transforms)
                .map(|((node, motion), rest)| match (motion, node) {
                    (Motion::Static, _) | (_, None) => *rest,
                    (_, Some(n)) => pose.nodes[*n],
                }),
        );
        pose.skinned.resize(self.motion.len(), None);
        for (slot, motion) in pose.skinned.iter_mut().zip(&self.motion) {
            if *motion != Motion::Skinned {
                *slot = None;
            } else if slot.is_none() {
                *slot = Some(SkinnedGeometry::default());
            }
        }
        // Each rig owns a distinct instance: hand out the slots in rig order.
        let mut slots: Vec<Option<&mut SkinnedGeometry>> =
            pose.skinned.iter_mut().map(Option::as_mut).collect();
        let work: Vec<(&SkinRig, &mut SkinnedGeometry)> = self
            .rigs
            .iter()
            .filter_map(|rig| slots[rig.instance].take().map(|g| (rig, g)))
            .collect();
        let nodes = &pose.nodes;
        let transforms = &pose.transforms;
        work.into_par_iter().for_each(|(rig, out)| {
            let to_local = invert_or_identity(&transforms[rig.instance]);
            let matrices: Vec<Affine3A> = rig
                .joints
                .iter()
                .zip(&rig.inverse_bind)
                .map(|(&j, ib)| to_local * nodes[j] * *ib)
                .collect();
            rig.mesh
                .skin(&matrices, &mut out.positions, &mut out.normals);
        });
    }

    /// World transforms of all nodes at `time`.
    fn node_worlds(&self, time: f32, world: &mut Vec<Affine3A>) {
        let mut local: Vec<(Vec3, Quat, Vec3)> = self
            .rest
            .iter()
            .map(|n| (n.translation, n.rotation, n.scale))
            .collect();
        for clip in &self.clips {
            let t = if clip.duration > 0.0 {
                time.rem_euclid(clip.duration)
            } else {
                0.0
            };
            for ch in &clip.channels {
                let slot = &mut local[ch.node];
                match (sample::sample(ch, t), ch.property) {
                    (Sampled::Rotation(r), _) => slot.1 = r,
                    (Sampled::Vector(v), crate::model::AnimatedProperty::Scale) => slot.2 = v,
                    (Sampled::Vector(v), _) => slot.0 = v,
                }
            }
        }
        for w in &self.walkers {
            let slot = &mut local[w.node()];
            let (t, r) = w.local_at(time, slot.2);
            slot.0 = t;
            slot.1 = r;
        }
        world.clear();
        world.resize(self.rest.len(), Affine3A::IDENTITY);
        for &n in &self.order {
            let (t, r, s) = local[n];
            let l = Affine3A::from_scale_rotation_translation(s, r, t);
            world[n] = match self.parents[n] {
                Some(p) => world[p] * l,
                None => l,
            };
        }
    }
}

impl Scene {
    /// How each instance moves; errors when the animation data is inconsistent.
    pub fn instance_motion(&self) -> Result<Vec<Motion>, AnimationError> {
        Animator::new(self).map(|a| a.motion)
    }

    /// Whether any instance moves (rigidly or by skinning); errors like [`Animator::new`].
    pub fn is_dynamic(&self) -> Result<bool, AnimationError> {
        Animator::new(self).map(|a| a.is_dynamic())
    }

    /// The pose at `time` (a one-off: keep an [`Animator`] to pose every frame).
    pub fn pose_at(&self, time: f32) -> Result<ScenePose, AnimationError> {
        Animator::new(self).map(|a| a.pose_at(time))
    }
}

/// Node indices with every parent before its children; errors on a cycle.
fn parents_first(parents: &[Option<usize>]) -> Result<Vec<usize>, AnimationError> {
    let n = parents.len();
    let mut children = vec![Vec::new(); n];
    for (i, p) in parents.iter().enumerate() {
        if let Some(p) = *p {
            children[p].push(i);
        }
    }
    let mut order: Vec<usize> = (0..n).filter(|&i| parents[i].is_none()).collect();
    let mut k = 0;
    while k < order.len() {
        let node = order[k];
        order.extend(&children[node]);
        k += 1;
    }
    if order.len() == n {
        Ok(order)
    } else {
        Err(AnimationError::Cycle)
    }
}

/// Whether some joint has a driven node on its path to the root that is not also above the
/// mesh's own node (motion of shared ancestors moves the whole instance rigidly). `Err(j)`
/// for a joint index out of range.
fn joints_move_relative(
    joints: &[usize],
    mesh_node: Option<usize>,
    driven: &[bool],
    parents: &[Option<usize>],
    node_count: usize,
) -> Result<bool, usize> {
    let mut shared = vec![false; node_count];
    let mut n = mesh_node;
    while let Some(i) = n {
        shared[i] = true;
        n = parents[i];
    }
    let mut moves = false;
    for &j in joints {
        if j >= node_count {
            return Err(j);
        }
        let mut n = Some(j);
        while let Some(i) = n {
            moves |= driven[i] && !shared[i];
            n = parents[i];
        }
    }
    Ok(moves)
}

/// The skinning inputs of instance `i` with skin `s` (bind meshes shared between instances).
fn skin_rig(
    scene: &Scene,
    i: usize,
    s: usize,
    bind_meshes: &mut HashMap<usize, Arc<BindMesh>>,
) -> Result<SkinRig, AnimationError> {
    let inst = &scene.instances[i];
    let mesh = &scene.meshes[inst.mesh];
    let skin = &scene.skins[s];
    let bad = |message: String| AnimationError::Skin {
        instance: i,
        message,
    };
    let n = mesh.positions.len();
    if mesh.joints.len() != n || mesh.weights.len() != n {
        return Err(bad(format!(
            "mesh '{}' has {n} vertices but {} joint and {} weight sets",
            mesh.name,
            mesh.joints.len(),
            mesh.weights.len()
        )));
    }
    if skin.inverse_bind.len() != skin.joints.len() {
        return Err(bad(format!(
            "skin '{}' has {} joints but {} inverse bind matrices",
            skin.name,
            skin.joints.len(),
            skin.inverse_bind.len()
        )));
    }
    if skin.inverse_bind.iter().any(|m| !m.is_finite()) {
        return Err(bad(format!(
            "skin '{}' has a non-finite inverse bind matrix",
            skin.name
        )));
    }
    let bind = bind_meshes
        .entry(inst.mesh)
        .or_insert_with(|| BindMesh::new(mesh))
        .clone();
    if let Some(j) = bind
        .max_joint()
        .filter(|&j| j as usize >= skin.joints.len())
    {
        return Err(AnimationError::Index {
            what: format!("instance {i} vertex joint"),
            index: j as usize,
            count: skin.joints.len(),
        });
    }
    Ok(SkinRig {
        instance: i,
        joints: skin.joints.clone(),
        inverse_bind: skin
            .inverse_bind
            .iter()
            .map(|m| Affine3A::from_mat4(*m))
            .collect(),
        mesh: bind,
    })
}

/// Axis-aligned bounds (min, max) of `points`; min > max when empty.
fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}
