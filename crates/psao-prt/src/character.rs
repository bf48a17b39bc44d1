//! A skinned character at any time of one clip: deformed vertices, a local frame per vertex
//! that follows the skin, and the joint rotations that drive the pose model.

use glam::{Affine3A, Mat3, Quat, Vec3};
use psao_scene::{Animator, Mesh, Scene};
use psao_trace::ao::orthonormal_basis;

use crate::PrtError;

/// One skinned mesh of a scene with one of its clips selected.
pub struct Character {
    animator: Animator,
    instance: usize,
    mesh: Mesh,
    /// Skin joint node indices.
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
    /// Skinned positions in mesh-local space.
    pub positions: Vec<Vec3>,
    /// Skinned unit normals in mesh-local space.
    pub normals: Vec<Vec3>,
    /// Per vertex: local frame (columns tangent, bitangent, normal) to mesh space.
    pub frames: Vec<Mat3>,
    /// Mesh-local to world transform.
    pub transform: Affine3A,
    /// Per skin joint: its local rotation relative to the bind pose, as rotation vector
    /// (axis × angle in radians, angle ≤ π).
    pub joint_rotations: Vec<Vec3>,
}

impl Character {
    /// Selects the first skinned instance of `scene` and the clip `clip` (a name, or an index
    /// into the file's clips; `None`: the first clip). Only that clip plays.
    pub fn new(mut scene: Scene, clip: Option<&str>) -> Result<Self, PrtError> {
        let (instance, inst) = scene
            .instances
            .iter()
            .enumerate()
            .find(|(_, i)| {
                i.skin.is_some()
                    && scene
                        .meshes
                        .get(i.mesh)
                        .is_some_and(|m| !m.joints.is_empty())
            })
            .ok_or(PrtError::NoSkin)?;
        let skin = inst.skin.unwrap_or(0);
        let mesh_index = inst.mesh;
        let clip_index = select_clip(&scene, clip)?;
        scene.playing = clip_index.into_iter().collect();
        scene.walkers.clear();
        let animator = Animator::new(&scene)?;
        let skin = scene.skins.get(skin).ok_or(PrtError::NoSkin)?;
        let joints = skin.joints.clone();
        let parents = scene.nodes.iter().map(|n| n.parent).collect();
        let rest = joints.iter().map(|&j| scene.nodes[j].rotation).collect();
        let mesh = scene.meshes[mesh_index].clone();
        let neighbours = tangent_neighbours(&mesh);
        let (clip_name, duration) = clip_index.map_or((String::from("(rest pose)"), 0.0), |c| {
            let a = &scene.animations[c];
            (a.name.clone(), a.duration())
        });
        Ok(Self {
            animator,
            instance,
            mesh,
            joints,
            parents,
            rest,
            neighbours,
            clip_name,
            duration,
        })
    }

    /// The mesh (bind pose) being relit.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.mesh.positions.len()
    }

    /// Number of skin joints.
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

    /// The instance relit (index into the scene's instances).
    pub fn instance(&self) -> usize {
        self.instance
    }

    /// The character at clip time `time` (seconds; the clip loops).
    pub fn pose(&self, time: f32) -> CharacterPose {
        let pose = self.animator.pose_at(time);
        let transform = pose.transforms[self.instance];
        let (positions, normals) = match pose.skinned.get(self.instance).and_then(Option::as_ref) {
            Some(g) => (g.positions.clone(), g.normals.clone()),
            None => (self.mesh.positions.clone(), self.mesh.normals.clone()),
        };
        let frames = skin_frames(&positions, &normals, &self.neighbours);
        let joint_rotations = self
            .joints
            .iter()
            .zip(&self.rest)
            .map(|(&j, rest)| {
                let world = pose.nodes[j];
                let local = match self.parents[j] {
                    Some(p) => pose.nodes[p].inverse() * world,
                    None => world,
                };
                let (_, rotation, _) = local.to_scale_rotation_translation();
                rotation_vector(rest.inverse() * rotation)
            })
            .collect();
        CharacterPose {
            time,
            positions,
            normals,
            frames,
            transform,
            joint_rotations,
        }
    }
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

/// Per vertex, a neighbour in its first triangle that is not at the same place (itself when
/// there is none): the direction to it, projected on the tangent plane, is the frame's x.
fn tangent_neighbours(mesh: &Mesh) -> Vec<u32> {
    let n = mesh.positions.len();
    let mut out: Vec<u32> = (0..n as u32).collect();
    let mut done = vec![false; n];
    for tri in &mesh.indices {
        for k in 0..3 {
            let v = tri[k] as usize;
            if v >= n || done[v] {
                continue;
            }
            for o in [tri[(k + 1) % 3], tri[(k + 2) % 3]] {
                if (o as usize) < n
                    && mesh.positions[o as usize].distance_squared(mesh.positions[v]) > 0.0
                {
                    out[v] = o;
                    done[v] = true;
                    break;
                }
            }
        }
    }
    out
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
}
