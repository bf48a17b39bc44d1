//! A skinned character at any time of one clip: every skinned primitive of the file merged
//! into one set of vertices in world space, a local frame per vertex that follows the skin,
//! the joint rotations that drive the pose model, and the file's rigid meshes, which only
//! occlude.
//!
//! A character is the whole file, however it is split: each skinned instance (one per glTF
//! node and primitive, with its own skin) contributes the vertices its triangles use, and
//! the pose vector holds every joint of every skin once. Everything that depends on a vertex
//! (its ray directions, see [`Character::keys`], and its tangent, see
//! [`tangent_neighbours`]) is derived from its rest position, not from its index, so a copy
//! of a character split into other primitives is traced and shaded the same.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Affine3A, Mat3, Quat, Vec3};
use psao_scene::{Animator, Mesh, Scene};
use psao_trace::ao::{hash64, orthonormal_basis};

use crate::runtime::Rig;
use crate::PrtError;

/// One instance of the file as part of the character: the mesh vertices it contributes
/// (those its triangles use), in character order.
#[derive(Clone, Debug)]
struct Part {
    instance: usize,
    mesh: usize,
    vertices: Vec<u32>,
}

/// A skinned character of a scene with one of its clips selected.
pub struct Character {
    animator: Animator,
    scene_meshes: Vec<Mesh>,
    /// The skinned instances: the vertices relit.
    parts: Vec<Part>,
    /// The other instances: occluders only.
    rigid: Vec<Part>,
    /// The relit vertices and triangles at rest, in world space.
    mesh: Mesh,
    /// `mesh` followed by the rigid instances' triangles (what rays hit).
    occluders: Mesh,
    /// Per relit vertex: the key of its ray streams (a hash of its rest position).
    keys: Arc<[u64]>,
    /// Skin joint node indices (every skin's, each once).
    joints: Vec<usize>,
    /// Parent node of every node.
    parents: Vec<Option<usize>>,
    /// Rest (bind) local rotation of every joint.
    rest: Vec<Quat>,
    /// Per vertex: the neighbour whose direction fixes the tangent of its local frame.
    neighbours: Vec<u32>,
    clip_name: String,
    duration: f32,
}

/// The character at one time.
#[derive(Clone, Debug)]
pub struct CharacterPose {
    /// Scene time in seconds.
    pub time: f32,
    /// Skinned positions of the relit vertices (space given by `transform`).
    pub positions: Vec<Vec3>,
    /// Skinned unit normals.
    pub normals: Vec<Vec3>,
    /// Per vertex: local frame (columns tangent, bitangent, normal).
    pub frames: Vec<Mat3>,
    /// Per vertex: the key of its ray streams (independent of vertex order).
    pub keys: Arc<[u64]>,
    /// Positions of the occluding vertices that are not relit (rigid meshes), appended
    /// after `positions` in the tracer's mesh.
    pub occluders: Vec<Vec3>,
    /// Positions to world (the identity for characters: they are posed in world space).
    pub transform: Affine3A,
    /// Per skin joint: its local rotation relative to the bind pose, as rotation vector
    /// (axis × angle in radians, angle ≤ π).
    pub joint_rotations: Vec<Vec3>,
    /// Per skin joint: its local transform (relative to its parent node).
    pub joint_local: Vec<Affine3A>,
}

impl CharacterPose {
    /// A pose of a fixed mesh (no joints, no other occluders), vertex `v` keyed `v`, in
    /// the space of `transform`.
    pub fn of_mesh(mesh: &Mesh, frames: Vec<Mat3>, transform: Affine3A) -> Self {
        Self {
            time: 0.0,
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            frames,
            keys: (0..mesh.positions.len() as u64).collect(),
            occluders: Vec::new(),
            transform,
            joint_rotations: Vec::new(),
            joint_local: Vec::new(),
        }
    }
}

impl Character {
    /// Every skinned instance of `scene` (relit, and occluding) and every other instance
    /// (occluding), with the clip `clip` (a name, or an index into the file's clips;
    /// `None`: the first clip). Only that clip plays.
    pub fn new(mut scene: Scene, clip: Option<&str>) -> Result<Self, PrtError> {
        let skinned = |i: &psao_scene::Instance| {
            i.skin.is_some()
                && scene
                    .meshes
                    .get(i.mesh)
                    .is_some_and(|m| !m.joints.is_empty())
        };
        let mut parts = Vec::new();
        let mut rigid = Vec::new();
        let mut skins = Vec::new();
        for (index, inst) in scene.instances.iter().enumerate() {
            let Some(mesh) = scene.meshes.get(inst.mesh) else {
                continue;
            };
            let part = Part {
                instance: index,
                mesh: inst.mesh,
                vertices: used_vertices(mesh),
            };
            if part.vertices.is_empty() {
                continue;
            }
            if skinned(inst) {
                skins.extend(inst.skin);
                parts.push(part);
            } else {
                rigid.push(part);
            }
        }
        if parts.is_empty() {
            return Err(PrtError::NoSkin);
        }
        let clip_index = select_clip(&scene, clip)?;
        scene.playing = clip_index.into_iter().collect();
        scene.walkers.clear();
        let animator = Animator::new(&scene)?;
        let mut joints: Vec<usize> = Vec::new();
        for s in skins {
            for &j in &scene.skins.get(s).ok_or(PrtError::NoSkin)?.joints {
                if !joints.contains(&j) {
                    joints.push(j);
                }
            }
        }
        let parents = scene.nodes.iter().map(|n| n.parent).collect();
        let rest = joints.iter().map(|&j| scene.nodes[j].rotation).collect();
        let mesh = merge(&parts, &scene);
        let others = merge(&rigid, &scene);
        let mut occluders = mesh.clone();
        let offset = occluders.positions.len() as u32;
        occluders.positions.extend_from_slice(&others.positions);
        occluders.normals.extend_from_slice(&others.normals);
        occluders
            .indices
            .extend(others.indices.iter().map(|t| t.map(|i| i + offset)));
        let keys = mesh.positions.iter().map(|&p| position_key(p)).collect();
        let neighbours = tangent_neighbours(&mesh.positions, &mesh.indices);
        let (clip_name, duration) = clip_index.map_or((String::from("(rest pose)"), 0.0), |c| {
            let a = &scene.animations[c];
            (a.name.clone(), a.duration())
        });
        Ok(Self {
            animator,
            scene_meshes: std::mem::take(&mut scene.meshes),
            parts,
            rigid,
            mesh,
            occluders,
            keys,
            joints,
            parents,
            rest,
            neighbours,
            clip_name,
            duration,
        })
    }

    /// The relit vertices and their triangles at rest (world space).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Everything rays hit: [`Self::mesh`] followed by the rigid meshes' triangles.
    pub fn occluder_mesh(&self) -> &Mesh {
        &self.occluders
    }

    /// Number of relit vertices.
    pub fn vertex_count(&self) -> usize {
        self.mesh.positions.len()
    }

    /// Number of skinned instances (glTF node × primitive) merged into the character.
    pub fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// Number of rigid instances that occlude it.
    pub fn rigid_count(&self) -> usize {
        self.rigid.len()
    }

    /// Number of skin joints (every skin's joints, each once).
    pub fn joint_count(&self) -> usize {
        self.joints.len()
    }

    /// Name of the selected clip.
    pub fn clip_name(&self) -> &str {
        &self.clip_name
    }

    /// Length of the selected clip in seconds (0 without clips).
    pub fn duration(&self) -> f32 {
        self.duration
    }

    /// Per vertex: the key of its ray streams, a hash of its rest position (so vertices at
    /// the same place, split between primitives or not, sample the same directions).
    pub fn keys(&self) -> &Arc<[u64]> {
        &self.keys
    }

    /// What a client needs besides the model to relight this character frame by frame
    /// (see [`crate::runtime`]).
    pub fn rig(&self) -> Rig {
        Rig {
            rest: self.rest.clone(),
            neighbours: self.neighbours.clone(),
        }
    }

    /// The skinned instances relit, in character order: each instance's index in the scene
    /// the character was made from and the mesh vertices it contributes (relit vertices are
    /// numbered through these lists one after the other).
    pub fn parts(&self) -> impl Iterator<Item = (usize, &[u32])> {
        self.parts
            .iter()
            .map(|p| (p.instance, p.vertices.as_slice()))
    }

    /// Per skin joint (the model's order): its local transform (relative to its parent
    /// node) in a pose whose node world transforms are `nodes` (one per node of the scene).
    /// A node missing from `nodes` counts as at the origin.
    pub fn joint_local(&self, nodes: &[Affine3A]) -> Vec<Affine3A> {
        let world = |n: usize| nodes.get(n).copied().unwrap_or(Affine3A::IDENTITY);
        self.joints
            .iter()
            .map(|&j| match self.parents[j] {
                Some(p) => world(p).inverse() * world(j),
                None => world(j),
            })
            .collect()
    }

    /// The character at clip time `time` (seconds; the clip loops), in world space.
    pub fn pose(&self, time: f32) -> CharacterPose {
        let pose = self.animator.pose_at(time);
        let place = |parts: &[Part], normals: bool| {
            let mut p = Vec::new();
            let mut n = Vec::new();
            for part in parts {
                let mesh = &self.scene_meshes[part.mesh];
                let t = pose.transforms[part.instance];
                let (src_p, src_n) = match pose.skinned.get(part.instance).and_then(Option::as_ref)
                {
                    Some(g) => (&g.positions[..], &g.normals[..]),
                    None => (&mesh.positions[..], &mesh.normals[..]),
                };
                let normal_matrix = normal_matrix(t);
                for &v in &part.vertices {
                    p.push(t.transform_point3(src_p[v as usize]));
                    if normals {
                        let nv = src_n.get(v as usize).copied().unwrap_or(Vec3::Z);
                        n.push((normal_matrix * nv).normalize_or(Vec3::Z));
                    }
                }
            }
            (p, n)
        };
        let (positions, normals) = place(&self.parts, true);
        let (occluders, _) = place(&self.rigid, false);
        let frames = skin_frames(&positions, &normals, &self.neighbours);
        let joint_local = self.joint_local(&pose.nodes);
        let joint_rotations = self
            .rig()
            .joint_rotations(&joint_local)
            .expect("one local transform per joint");
        CharacterPose {
            time,
            positions,
            normals,
            frames,
            keys: self.keys.clone(),
            occluders,
            transform: Affine3A::IDENTITY,
            joint_rotations,
            joint_local,
        }
    }
}

/// The vertices of `mesh` that its triangles use, in order.
fn used_vertices(mesh: &Mesh) -> Vec<u32> {
    let n = mesh.positions.len();
    let mut used = vec![false; n];
    for t in &mesh.indices {
        if t.iter().all(|&i| (i as usize) < n) {
            t.iter().for_each(|&i| used[i as usize] = true);
        }
    }
    (0..n as u32).filter(|&v| used[v as usize]).collect()
}

/// The parts' vertices (placed by their instance's transform at rest) and triangles as
/// one mesh.
fn merge(parts: &[Part], scene: &Scene) -> Mesh {
    let mut out = Mesh {
        name: "character".into(),
        ..Mesh::default()
    };
    for part in parts {
        let t = scene.instances[part.instance].transform;
        let mesh = &scene.meshes[part.mesh];
        let base = out.positions.len() as u32;
        let mut index = vec![u32::MAX; mesh.positions.len()];
        let normal_matrix = normal_matrix(t);
        for (k, &v) in part.vertices.iter().enumerate() {
            index[v as usize] = base + k as u32;
            out.positions
                .push(t.transform_point3(mesh.positions[v as usize]));
            let n = mesh.normals.get(v as usize).copied().unwrap_or(Vec3::Z);
            out.normals.push((normal_matrix * n).normalize_or(Vec3::Z));
        }
        let n = mesh.positions.len();
        for tri in &mesh.indices {
            if tri.iter().all(|&i| (i as usize) < n) {
                out.indices.push(tri.map(|i| index[i as usize]));
            }
        }
    }
    out
}

/// The matrix that takes normals through `t` (inverse transpose of its linear part; the
/// linear part itself when that is singular).
pub fn normal_matrix(t: Affine3A) -> Mat3 {
    let m = Mat3::from(t.matrix3);
    if m.determinant().abs() > 1e-20 {
        m.inverse().transpose()
    } else {
        m
    }
}

/// The bits of a position with −0 made +0 (equal positions give equal bits).
fn position_bits(p: Vec3) -> [u32; 3] {
    [p.x + 0.0, p.y + 0.0, p.z + 0.0].map(f32::to_bits)
}

/// The ray-stream key of a vertex at rest position `p`.
fn position_key(p: Vec3) -> u64 {
    let [x, y, z] = position_bits(p);
    hash64(hash64((x as u64) << 32 | y as u64) ^ z as u64)
}

/// The clip index for `clip` (name first, then index); `None` when the file has no clips
/// and none was asked for.
fn select_clip(scene: &Scene, clip: Option<&str>) -> Result<Option<usize>, PrtError> {
    let Some(want) = clip else {
        return Ok((!scene.animations.is_empty()).then_some(0));
    };
    let by_name = scene.animations.iter().position(|a| a.name == want);
    let by_index = want
        .parse::<usize>()
        .ok()
        .filter(|&i| i < scene.animations.len());
    by_name
        .or(by_index)
        .map(Some)
        .ok_or_else(|| PrtError::UnknownClip {
            requested: want.to_string(),
            available: if scene.animations.is_empty() {
                "no clips".into()
            } else {
                scene
                    .animations
                    .iter()
                    .enumerate()
                    .map(|(i, a)| format!("{i} `{}`", a.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            },
        })
}

/// The rotation vector (axis × angle) of `q`, taking the shorter way round.
pub fn rotation_vector(q: Quat) -> Vec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let (axis, angle) = q.normalize().to_axis_angle();
    if angle.is_finite() && axis.is_finite() {
        axis * angle
    } else {
        Vec3::ZERO
    }
}

/// Per vertex, the neighbour whose direction fixes the tangent of its frame, chosen from
/// positions only: vertices at the same place are one (so a seam or a split between
/// primitives does not change it), and among the places adjacent to a vertex's place, the
/// least in (x, y, z) order is taken (itself when there is none).
pub fn tangent_neighbours(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<u32> {
    let n = positions.len();
    let mut first: HashMap<[u32; 3], u32> = HashMap::with_capacity(n);
    let place: Vec<u32> = positions
        .iter()
        .enumerate()
        .map(|(v, &p)| *first.entry(position_bits(p)).or_insert(v as u32))
        .collect();
    let less = |a: u32, b: u32| {
        let (p, q) = (positions[a as usize], positions[b as usize]);
        p.x.total_cmp(&q.x)
            .then(p.y.total_cmp(&q.y))
            .then(p.z.total_cmp(&q.z))
            .is_lt()
    };
    let mut best: Vec<Option<u32>> = vec![None; n];
    for tri in indices {
        if tri.iter().any(|&i| i as usize >= n) {
            continue;
        }
        for k in 0..3 {
            let a = place[tri[k] as usize];
            for o in [tri[(k + 1) % 3], tri[(k + 2) % 3]] {
                let b = place[o as usize];
                if b != a && best[a as usize].map_or(true, |c| less(b, c)) {
                    best[a as usize] = Some(b);
                }
            }
        }
    }
    (0..n)
        .map(|v| best[place[v] as usize].unwrap_or(v as u32))
        .collect()
}

/// Local frames (tangent, bitangent, normal) that follow the skin: z is the vertex normal,
/// x the direction to the vertex's fixed neighbour projected on the tangent plane.
pub fn skin_frames(positions: &[Vec3], normals: &[Vec3], neighbours: &[u32]) -> Vec<Mat3> {
    positions
        .iter()
        .zip(normals)
        .zip(neighbours)
        .map(|((&p, &n), &o)| {
            let n = n.normalize_or(Vec3::Z);
            let e = positions[o as usize] - p;
            let t = (e - n * e.dot(n)).normalize_or_zero();
            let t = if t == Vec3::ZERO {
                orthonormal_basis(n).0
            } else {
                t
            };
            Mat3::from_cols(t, n.cross(t), n)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_vector_round_trips() {
        let q = Quat::from_axis_angle(Vec3::new(1.0, -2.0, 0.5).normalize(), 1.2);
        let v = rotation_vector(q);
        let back = Quat::from_scaled_axis(v);
        assert!(back.dot(q).abs() > 0.99999);
        assert!(rotation_vector(-q).distance(v) < 1e-5);
    }

    #[test]
    fn frames_are_orthonormal_with_z_on_the_normal() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, 0.2)];
        let n = vec![Vec3::new(0.0, 0.3, 1.0).normalize(); 3];
        let frames = skin_frames(&p, &n, &[1, 2, 0]);
        for (f, n) in frames.iter().zip(&n) {
            assert!(f.z_axis.distance(*n) < 1e-6);
            assert!((f.determinant() - 1.0).abs() < 1e-5);
            assert!(f.x_axis.dot(f.z_axis).abs() < 1e-6);
        }
    }

    /// Two triangles sharing an edge, once as one mesh and once split (the shared edge's
    /// vertices duplicated): every vertex at the same place gets a neighbour at the same
    /// place, and the same key.
    #[test]
    fn neighbours_and_keys_depend_on_positions_not_on_indices() {
        let quad = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let joined = tangent_neighbours(&quad, &[[0, 1, 2], [0, 2, 3]]);
        let split_positions = [quad[0], quad[1], quad[2], quad[2], quad[3], quad[0]];
        let split = tangent_neighbours(&split_positions, &[[0, 1, 2], [5, 3, 4]]);
        for (v, &p) in split_positions.iter().enumerate() {
            let w = quad.iter().position(|&q| q == p).unwrap();
            assert_eq!(split_positions[split[v] as usize], quad[joined[w] as usize]);
            assert_eq!(position_key(p), position_key(quad[w]));
        }
        // The least neighbour in (x, y, z) order: (0, 1, 0) for the origin, the origin for
        // the others.
        assert_eq!(joined, vec![3, 0, 0, 0]);
        assert_ne!(position_key(quad[0]), position_key(quad[1]));
        assert_eq!(
            position_key(Vec3::new(-0.0, 0.0, 0.0)),
            position_key(Vec3::ZERO)
        );
    }

    /// A skinned square (one joint) under a larger rigid square roof, and a mesh without a skin
    /// that no triangle uses: the character is the square's vertices, the roof occludes
    /// them (visibility straight up is 0), and a vertex no triangle uses is not relit.
    #[test]
    fn rigid_meshes_occlude_and_unused_vertices_are_dropped() {
        use psao_scene::{Instance, Node, Skin};
        let square = |z: f32, h: f32, extra: bool| {
            let mut positions = vec![
                Vec3::new(-h, -h, z),
                Vec3::new(h, -h, z),
                Vec3::new(h, h, z),
                Vec3::new(-h, h, z),
            ];
            if extra {
                positions.push(Vec3::new(5.0, 5.0, 5.0));
            }
            let n = positions.len();
            Mesh {
                normals: vec![Vec3::Z; n],
                positions,
                indices: vec![[0, 1, 2], [0, 2, 3]],
                ..Mesh::default()
            }
        };
        let mut skinned = square(0.0, 1.0, true);
        skinned.joints = vec![[0; 4]; 5];
        skinned.weights = vec![[1.0, 0.0, 0.0, 0.0]; 5];
        let mut scene = Scene::of_meshes(vec![skinned, square(0.5, 3.0, false)]);
        scene.nodes = vec![Node {
            name: "joint".into(),
            parent: None,
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }];
        scene.skins = vec![Skin {
            name: "skin".into(),
            joints: vec![0],
            inverse_bind: vec![glam::Mat4::IDENTITY],
        }];
        scene.instances[0] = Instance {
            mesh: 0,
            node: None,
            transform: Affine3A::IDENTITY,
            skin: Some(0),
        };
        let c = Character::new(scene, None).unwrap();
        assert_eq!((c.part_count(), c.rigid_count()), (1, 1));
        assert_eq!(c.vertex_count(), 4);
        assert_eq!(c.occluder_mesh().indices.len(), 4);
        let pose = c.pose(0.0);
        assert_eq!(pose.occluders.len(), 4);
        let mut tracer = crate::visibility::SelfTracer::new(c.occluder_mesh()).unwrap();
        tracer.set_pose(&pose).unwrap();
        let v = crate::visibility::visibility_sh(&tracer, &pose, 256, 1);
        for (k, sh) in v.iter().enumerate() {
            let up = crate::sh::value(sh, Vec3::Z);
            assert!(
                up < 0.3,
                "vertex {k}: visibility {up} straight up under the roof"
            );
        }
    }
}
