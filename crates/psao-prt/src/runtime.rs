//! Per-frame relighting as a client runs it (paper §4.3): from a frame's joint transforms
//! and skinned vertices to one shade per vertex and colour channel.
//!
//! A client that animates and skins the character itself keeps a [`Relighter`]: the
//! trained [`PoseModel`], a [`Shader`] and the character's [`Rig`] (what turns joint
//! transforms into the model's pose vector, and skinned vertices into the frames
//! visibility is stored in). Per frame it passes the joints' local transforms, the skinned
//! positions and normals, the SH lighting and the eye; [`Relighter::shade`] synthesises
//! the lobes (one matrix-vector product) and shades every vertex. Both run on the calling
//! rayon pool (all cores, or one inside a one-thread pool).

use glam::{Affine3A, Quat, Vec3};

use crate::character::{rotation_vector, skin_frames};
use crate::model::PoseModel;
use crate::sh::ShVec;
use crate::shade::{Shader, ShadingGeometry, Visibility};
use crate::PrtError;

/// What relighting needs of a character besides its model.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// Per skin joint (the model's joint order): its rest (bind) local rotation.
    pub rest: Vec<Quat>,
    /// Per relit vertex: the vertex whose direction fixes the tangent of its frame (see
    /// [`crate::character::tangent_neighbours`]).
    pub neighbours: Vec<u32>,
}

impl Rig {
    /// Per joint, its local rotation relative to the rest pose as a rotation vector, from
    /// its local transform (relative to its parent node). Errors when the count differs
    /// from the rig's.
    pub fn joint_rotations(&self, local: &[Affine3A]) -> Result<Vec<Vec3>, PrtError> {
        if local.len() != self.rest.len() {
            return Err(PrtError::Parameter(format!(
                "{} joint transforms for a rig of {} joints",
                local.len(),
                self.rest.len()
            )));
        }
        Ok(local
            .iter()
            .zip(&self.rest)
            .map(|(t, rest)| {
                let (_, rotation, _) = t.to_scale_rotation_translation();
                rotation_vector(rest.inverse() * rotation)
            })
            .collect())
    }
}

/// One frame of a character as the client has it.
#[derive(Clone, Copy, Debug)]
pub struct FramePose<'a> {
    /// Per skin joint: its local transform (relative to its parent node).
    pub joint_local: &'a [Affine3A],
    /// Skinned positions of the relit vertices.
    pub positions: &'a [Vec3],
    /// Skinned normals of the relit vertices.
    pub normals: &'a [Vec3],
    /// Positions and normals to world.
    pub transform: Affine3A,
}

/// A character's model, shader and rig, ready to relight it frame after frame.
pub struct Relighter {
    model: PoseModel,
    shader: Shader,
    rig: Rig,
    /// The model's outputs of the last frame (reused).
    raw: Vec<f32>,
}

impl Relighter {
    /// Errors when the rig is not the model's character's (joint or vertex counts).
    pub fn new(model: PoseModel, shader: Shader, rig: Rig) -> Result<Self, PrtError> {
        if rig.rest.len() != model.joints || rig.neighbours.len() != model.vertices {
            return Err(PrtError::Parameter(format!(
                "a rig of {} joints and {} vertices for a model of {} joints and {} vertices",
                rig.rest.len(),
                rig.neighbours.len(),
                model.joints,
                model.vertices
            )));
        }
        if let Some(&n) = rig
            .neighbours
            .iter()
            .find(|&&n| n as usize >= model.vertices)
        {
            return Err(PrtError::Parameter(format!(
                "tangent neighbour {n} of {} vertices",
                model.vertices
            )));
        }
        Ok(Self {
            model,
            shader,
            rig,
            raw: Vec::new(),
        })
    }

    /// The model.
    pub fn model(&self) -> &PoseModel {
        &self.model
    }

    /// Shades every vertex of `pose` under `lights` (SH radiance in world space, one vector
    /// per channel) seen from `eye` (world): `lights.len()` values per vertex, interleaved.
    /// Errors when the pose's joint or vertex counts are not the model's.
    pub fn shade(
        &mut self,
        pose: &FramePose<'_>,
        lights: &[ShVec],
        eye: Vec3,
    ) -> Result<Vec<f32>, PrtError> {
        let n = self.model.vertices;
        if pose.positions.len() != n || pose.normals.len() != n {
            return Err(PrtError::Parameter(format!(
                "{} positions and {} normals for a model of {n} vertices",
                pose.positions.len(),
                pose.normals.len()
            )));
        }
        let rotations = self.rig.joint_rotations(pose.joint_local)?;
        self.model
            .predict_raw(&self.model.pose_vector(&rotations), &mut self.raw);
        let frames = skin_frames(pose.positions, pose.normals, &self.rig.neighbours);
        self.shader.shade(
            Visibility::Model(&self.model, &self.raw),
            ShadingGeometry {
                positions: pose.positions,
                frames: &frames,
                transform: pose.transform,
            },
            lights,
            eye,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LOBE_DIM;
    use crate::shade::{unit_visibility, Mode};

    /// One joint with a rest rotation, two vertices each other's tangent neighbour, one
    /// lobe whose axis tilts with the joint's rotation about z.
    fn relighter() -> Relighter {
        let n = 2 * LOBE_DIM;
        let mut weights = vec![0.0f32; 4 * n];
        for v in 0..2 {
            let c = v * LOBE_DIM;
            // Constant: axis +z, coefficients of a half-open lobe.
            weights[c + 2] = 1.0;
            weights[c + 3..c + 7].copy_from_slice(&[2.0, 1.0, 0.3, 0.0]);
            // The rotation about z tilts the axis towards +x.
            weights[3 * n + c] = 2.0;
        }
        let model = PoseModel {
            character: "t".into(),
            vertices: 2,
            joints: 1,
            lobes: 1,
            active: vec![0],
            weights,
            limits: Default::default(),
        };
        let rig = Rig {
            rest: vec![Quat::from_rotation_x(0.3)],
            neighbours: vec![1, 0],
        };
        Relighter::new(model, Shader::new(Mode::Diffuse).unwrap(), rig).unwrap()
    }

    #[test]
    fn joint_rotations_are_relative_to_the_rest_pose() {
        let rig = relighter().rig;
        let local = Affine3A::from_rotation_translation(
            Quat::from_rotation_x(0.3) * Quat::from_rotation_z(0.5),
            Vec3::new(1.0, 2.0, 3.0),
        );
        let r = rig.joint_rotations(&[local]).unwrap();
        assert!((r[0] - Vec3::new(0.0, 0.0, 0.5)).length() < 1e-5, "{r:?}");
        assert!(rig.joint_rotations(&[]).is_err());
    }

    #[test]
    fn a_frame_is_shaded_from_its_joint_transforms_and_skinned_vertices() {
        let mut r = relighter();
        let positions = [Vec3::ZERO, Vec3::X];
        let normals = [Vec3::Z; 2];
        // Brighter towards +z: the shade depends on where the lobe points.
        let mut sky = unit_visibility();
        sky[2] = 1.5;
        let shade = |r: &mut Relighter, angle: f32| {
            let local =
                Affine3A::from_quat(Quat::from_rotation_x(0.3) * Quat::from_rotation_z(angle));
            let pose = FramePose {
                joint_local: &[local],
                positions: &positions,
                normals: &normals,
                transform: Affine3A::IDENTITY,
            };
            r.shade(&pose, &[sky], Vec3::Z)
        };
        // At rest the lobe is about the normal; rotating the joint tilts it away, which
        // changes the shade of every vertex alike.
        let rest = shade(&mut r, 0.0).unwrap();
        let tilted = shade(&mut r, 0.4).unwrap();
        assert_eq!(rest.len(), 2);
        assert!((rest[0] - rest[1]).abs() < 1e-6 && (tilted[0] - tilted[1]).abs() < 1e-6);
        assert!((rest[0] - tilted[0]).abs() > 1e-3, "{rest:?} vs {tilted:?}");
        // The same as shading the model's prediction directly.
        let model = r.model().clone();
        let mut raw = Vec::new();
        model.predict_raw(&model.pose_vector(&[Vec3::new(0.0, 0.0, 0.4)]), &mut raw);
        let frames = skin_frames(&positions, &normals, &[1, 0]);
        let direct = Shader::new(Mode::Diffuse)
            .unwrap()
            .shade(
                Visibility::Model(&model, &raw),
                ShadingGeometry {
                    positions: &positions,
                    frames: &frames,
                    transform: Affine3A::IDENTITY,
                },
                &[sky],
                Vec3::Z,
            )
            .unwrap();
        assert!(direct
            .iter()
            .zip(&tilted)
            .all(|(a, b)| (a - b).abs() < 1e-6));
    }

    #[test]
    fn mismatched_rigs_and_frames_are_refused() {
        let r = relighter();
        let bad_rig = Rig {
            rest: vec![Quat::IDENTITY],
            neighbours: vec![0, 5],
        };
        assert!(Relighter::new(
            r.model.clone(),
            Shader::new(Mode::Diffuse).unwrap(),
            bad_rig
        )
        .is_err());
        let mut r = relighter();
        let pose = FramePose {
            joint_local: &[Affine3A::IDENTITY],
            positions: &[Vec3::ZERO],
            normals: &[Vec3::Z],
            transform: Affine3A::IDENTITY,
        };
        assert!(r.shade(&pose, &[unit_visibility()], Vec3::Z).is_err());
    }
}
