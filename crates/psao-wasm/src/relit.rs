//! Relit characters in the browser (docs/RELIGHTING.md, "Served characters"): the served
//! scene rebuilt as a psao-scene [`Scene`] from `/scene.glb` (web/src/relit.ts hands over its
//! nodes, meshes, skins, instances and playing clips), posed by psao-scene's [`Animator`] as
//! `psao view` poses it, and each served character relit by psao-prt's
//! [`psao_prt::served::ServedRelighter`] from its model file (`/characters/N.prt`) and the
//! served lighting.
//!
//! The characters are the scene's [`skinned_groups`] in their order, as on the server and in
//! `psao view`, and each frame goes through the same [`ServedCharacter`] steps as
//! `psao_net::relit`'s: the relit vertices' world positions and normals from the client's
//! pose at the transforms of the last server update, the joints' local transforms from the
//! pose's nodes, the values scattered onto each instance's mesh vertices. A renderer
//! interpolates the values over its triangles and multiplies a relit pixel's AO or
//! irradiance by [`psao_prt::served::pixel_factor`].

use glam::{Affine3A, Vec3};
use psao_prt::groups::{skinned_groups, SkinnedGroup};
use psao_prt::served::VertexValues;
use psao_prt::served_character::{InstanceGeometry, ServedCharacter};
use psao_scene::{
    AnimatedProperty, Animation, Animator, Channel, Instance, Interpolation, Mesh, Node, Scene,
    ScenePose, Skin,
};

/// Clips a scene may name (each made when named, so that a stray index cannot allocate
/// without bound).
pub const MAX_CLIPS: usize = 1 << 12;

/// Why the scene or a character could not be relit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RelitError {
    /// The scene's data is inconsistent (an index out of range, arrays of other lengths).
    #[error("relit scene: {0}")]
    Scene(String),
    /// A character cannot be relit with its model (or the model is malformed).
    #[error("relit character {character}: {message}")]
    Character {
        /// Its served index.
        character: u32,
        /// Why.
        message: String,
    },
}

impl RelitError {
    /// The status code the C ABI returns for this error (0 is success).
    pub fn code(&self) -> u32 {
        match self {
            Self::Scene(_) => 1,
            Self::Character { .. } => 2,
        }
    }
}

/// One mesh of the scene as the page reads it from `/scene.glb`.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Mesh-local positions.
    pub positions: Vec<Vec3>,
    /// One normal per position.
    pub normals: Vec<Vec3>,
    /// Triangles.
    pub indices: Vec<[u32; 3]>,
    /// Skin joints per vertex (empty when unskinned).
    pub joints: Vec<[u16; 4]>,
    /// Skin weights per vertex (empty when unskinned).
    pub weights: Vec<[f32; 4]>,
}

/// The served scene, its pose and the relit characters with the values of the last frame.
#[derive(Default)]
pub struct RelitScene {
    scene: Scene,
    animator: Option<Animator>,
    groups: Vec<SkinnedGroup>,
    pose: ScenePose,
    characters: Vec<Option<ServedCharacter>>,
    /// Per scene instance: for relit instances, one [`VertexValues`] per mesh vertex.
    values: Vec<Option<Vec<VertexValues>>>,
}

impl RelitScene {
    /// Adds a node (`parent` an earlier or later node's index).
    pub fn push_node(
        &mut self,
        parent: Option<usize>,
        translation: Vec3,
        rotation: glam::Quat,
        scale: Vec3,
    ) {
        self.scene.nodes.push(Node {
            name: format!("node {}", self.scene.nodes.len()),
            parent,
            translation,
            rotation,
            scale,
        });
    }

    /// Adds a mesh; errors when its arrays disagree in length or a triangle names a vertex
    /// it does not have.
    pub fn push_mesh(&mut self, m: MeshData) -> Result<(), RelitError> {
        let n = m.positions.len();
        let bad =
            |what: &str| RelitError::Scene(format!("mesh {}: {what}", self.scene.meshes.len()));
        if m.normals.len() != n {
            return Err(bad("one normal per position needed"));
        }
        if m.joints.len() != m.weights.len() || !(m.joints.is_empty() || m.joints.len() == n) {
            return Err(bad("joints and weights need one set per position"));
        }
        if m.indices.iter().flatten().any(|&i| i as usize >= n) {
            return Err(bad("a triangle names a missing vertex"));
        }
        self.scene.meshes.push(Mesh {
            name: format!("mesh {}", self.scene.meshes.len()),
            positions: m.positions,
            normals: m.normals,
            indices: m.indices,
            joints: m.joints,
            weights: m.weights,
            ..Mesh::default()
        });
        Ok(())
    }

    /// Adds a skin: its joint nodes and their inverse bind matrices.
    pub fn push_skin(&mut self, joints: Vec<usize>, inverse_bind: Vec<glam::Mat4>) {
        self.scene.skins.push(Skin {
            name: format!("skin {}", self.scene.skins.len()),
            joints,
            inverse_bind,
        });
    }

    /// Adds an instance (instance `i` of the welcome's table).
    pub fn push_instance(
        &mut self,
        mesh: usize,
        node: Option<usize>,
        skin: Option<usize>,
        transform: Affine3A,
    ) {
        self.scene.instances.push(Instance {
            mesh,
            node,
            transform,
            skin,
        });
    }

    /// Adds a channel to clip `clip` (below [`MAX_CLIPS`]).
    pub fn push_channel(&mut self, clip: usize, channel: Channel) -> Result<(), RelitError> {
        self.clip(clip)?.channels.push(channel);
        Ok(())
    }

    /// Plays clip `clip` (below [`MAX_CLIPS`]).
    pub fn play(&mut self, clip: usize) -> Result<(), RelitError> {
        self.clip(clip)?;
        self.scene.playing.push(clip);
        Ok(())
    }

    /// Clip `clip`, made (with the clips before it) when new.
    fn clip(&mut self, clip: usize) -> Result<&mut Animation, RelitError> {
        if clip >= MAX_CLIPS {
            return Err(RelitError::Scene(format!(
                "clip {clip}: at most {MAX_CLIPS} clips"
            )));
        }
        while self.scene.animations.len() <= clip {
            let name = format!("clip {}", self.scene.animations.len());
            self.scene.animations.push(Animation {
                name,
                channels: Vec::new(),
            });
        }
        Ok(&mut self.scene.animations[clip])
    }

    /// Checks the scene and prepares its playback and characters; returns how many
    /// characters it has.
    pub fn finish(&mut self) -> Result<usize, RelitError> {
        let animator = Animator::new(&self.scene).map_err(|e| RelitError::Scene(e.to_string()))?;
        self.groups = skinned_groups(&self.scene);
        self.animator = Some(animator);
        self.values = vec![None; self.scene.instances.len()];
        Ok(self.groups.len())
    }

    /// Relights character `index` with its served `model` file and `lighting` (SH, 16
    /// numbers per colour channel), diffuse as `psao view` does. Errors when the scene is
    /// not finished, has no such character, or the model is malformed or another's.
    pub fn insert(
        &mut self,
        index: u32,
        model: &[u8],
        lighting: &[f32],
    ) -> Result<usize, RelitError> {
        let fail = |message: String| RelitError::Character {
            character: index,
            message,
        };
        if self.animator.is_none() {
            return Err(RelitError::Scene("the scene is not finished".into()));
        }
        let group = self
            .groups
            .get(index as usize)
            .ok_or_else(|| fail("the scene has no such skinned character".into()))?;
        let character = ServedCharacter::new(index as usize, group, model, lighting)
            .map_err(|e| fail(e.to_string()))?;
        let vertices = character.vertex_count();
        if self.characters.len() <= index as usize {
            self.characters.resize_with(index as usize + 1, || None);
        }
        self.characters[index as usize] = Some(character);
        Ok(vertices)
    }

    /// Relights every character at scene time `time` (seconds) seen from `eye`; instance `i`
    /// is at `transforms[i]` when given (the last server update's), else where the pose puts
    /// it.
    pub fn relight(
        &mut self,
        time: f32,
        transforms: &[Option<Affine3A>],
        eye: Vec3,
    ) -> Result<(), RelitError> {
        let Some(animator) = &self.animator else {
            return Err(RelitError::Scene("the scene is not finished".into()));
        };
        animator.pose_into(time, &mut self.pose);
        for (index, slot) in self.characters.iter_mut().enumerate() {
            let Some(c) = slot else { continue };
            let (scene, pose) = (&self.scene, &self.pose);
            let geometry = |i: usize| {
                let own = pose.instance(i);
                InstanceGeometry {
                    transform: transforms
                        .get(i)
                        .copied()
                        .flatten()
                        .or(own.map(|p| p.transform))
                        .unwrap_or(scene.instances[i].transform),
                    positions: own.and_then(|o| o.positions),
                    normals: own.and_then(|o| o.normals),
                }
            };
            c.relight(scene, &pose.nodes, geometry, eye)
                .map_err(|e| RelitError::Character {
                    character: index as u32,
                    message: e.to_string(),
                })?;
            c.scatter(&self.scene, &mut self.values);
        }
        Ok(())
    }

    /// Instance `instance`'s values of the last frame, one per mesh vertex; `None` when it is
    /// not relit (or nothing was relit yet).
    pub fn values(&self, instance: usize) -> Option<&[VertexValues]> {
        self.values.get(instance)?.as_deref()
    }

    /// Vertices relit per frame (over every character given a model).
    pub fn vertex_count(&self) -> usize {
        self.characters
            .iter()
            .flatten()
            .map(ServedCharacter::vertex_count)
            .sum()
    }

    /// The scene's characters (its skinned node groups), once finished.
    pub fn character_count(&self) -> usize {
        self.groups.len()
    }
}

/// A channel of clip data: `property` 0 translation, 1 rotation, 2 scale; `interpolation` 0
/// step, 1 linear, 2 cubic spline. `None` for other numbers.
pub fn channel(
    node: usize,
    property: u32,
    interpolation: u32,
    times: Vec<f32>,
    values: Vec<f32>,
) -> Option<Channel> {
    let property = match property {
        0 => AnimatedProperty::Translation,
        1 => AnimatedProperty::Rotation,
        2 => AnimatedProperty::Scale,
        _ => return None,
    };
    let interpolation = match interpolation {
        0 => Interpolation::Step,
        1 => Interpolation::Linear,
        2 => Interpolation::CubicSpline,
        _ => return None,
    };
    Some(Channel {
        node,
        property,
        interpolation,
        times,
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat};
    use psao_prt::model::PoseModel;
    use psao_prt::model_file;

    /// A unit square on two joints (its upper edge on the second, 0.5 up) that a clip bends
    /// over 1 s, at the origin, and a second, rigid square beside it.
    fn scene() -> RelitScene {
        let mut s = RelitScene::default();
        s.push_node(None, Vec3::ZERO, Quat::IDENTITY, Vec3::ONE);
        s.push_node(Some(0), Vec3::new(0.0, 0.5, 0.0), Quat::IDENTITY, Vec3::ONE);
        let square = |skinned: bool| MeshData {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)],
            normals: vec![Vec3::Z; 4],
            indices: vec![[0, 1, 2], [1, 3, 2]],
            joints: if skinned {
                vec![[0; 4], [0; 4], [1, 0, 0, 0], [1, 0, 0, 0]]
            } else {
                Vec::new()
            },
            weights: if skinned {
                vec![[1.0, 0.0, 0.0, 0.0]; 4]
            } else {
                Vec::new()
            },
        };
        s.push_mesh(square(true)).unwrap();
        s.push_mesh(square(false)).unwrap();
        s.push_skin(
            vec![0, 1],
            vec![
                Mat4::IDENTITY,
                Mat4::from_translation(Vec3::new(0.0, -0.5, 0.0)),
            ],
        );
        s.push_instance(
            1,
            None,
            None,
            Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)),
        );
        s.push_instance(0, Some(0), Some(0), Affine3A::IDENTITY);
        let bent = Quat::from_rotation_x(1.2);
        let values = [Quat::IDENTITY, bent]
            .iter()
            .flat_map(|q| q.to_array())
            .collect();
        s.push_channel(0, channel(1, 1, 1, vec![0.0, 1.0], values).unwrap())
            .unwrap();
        s.play(0).unwrap();
        s
    }

    /// A model of `vertices` vertices and 2 joints whose one lobe per vertex is `lobe`
    /// (axis in the vertex's frame, zonal coefficients) whatever the pose.
    fn model(vertices: usize, lobe: (Vec3, [f32; 4])) -> Vec<u8> {
        let per = 7;
        let mut weights = vec![0.0f32; 4 * vertices * per];
        for v in 0..vertices {
            weights[v * per..v * per + 3].copy_from_slice(&lobe.0.to_array());
            weights[v * per + 3..v * per + 7].copy_from_slice(&lobe.1);
        }
        model_file::to_bytes(&PoseModel {
            character: "square".into(),
            vertices,
            joints: 2,
            lobes: 1,
            active: vec![1],
            weights,
            limits: Default::default(),
        })
    }

    /// A sky brighter above, 16 numbers per channel.
    fn lighting() -> Vec<f32> {
        (0..3)
            .flat_map(|_| {
                let mut l = [0.0f32; 16];
                l[0] = 3.0;
                l[2] = 1.0;
                l
            })
            .collect()
    }

    #[test]
    fn a_served_character_is_relit_onto_its_instances_vertices() {
        let mut s = scene();
        assert_eq!(s.finish().unwrap(), 1);
        let open = (Vec3::Z, [2.0 * std::f32::consts::PI.sqrt(), 0.0, 0.0, 0.0]);
        assert_eq!(s.insert(0, &model(4, open), &lighting()).unwrap(), 4);
        s.relight(0.5, &[None, None], Vec3::new(0.0, 1.0, 4.0))
            .unwrap();
        // The rigid square is not relit; the character's vertices see everything.
        assert!(s.values(0).is_none());
        let values = s.values(1).unwrap();
        assert_eq!(values.len(), 4);
        for v in values {
            assert!(v.iter().all(|x| (x - 1.0).abs() < 1e-3), "{v:?}");
        }
        // A lobe of visibility about a tangent: self-shadowed, within [0, 1].
        let half = (Vec3::X, [1.5, 1.6, 0.4, -0.2]);
        s.insert(0, &model(4, half), &lighting()).unwrap();
        let moved = Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0));
        s.relight(0.25, &[None, Some(moved)], Vec3::new(0.0, 1.0, 4.0))
            .unwrap();
        let values = s.values(1).unwrap();
        assert!(values.iter().flatten().all(|x| (0.0..=1.0).contains(x)));
        assert!(values.iter().flatten().any(|&x| x < 0.95), "{values:?}");
    }

    #[test]
    fn bad_scenes_models_and_characters_are_refused() {
        let mut s = scene();
        let open = (Vec3::Z, [1.0, 0.0, 0.0, 0.0]);
        // Not finished yet.
        assert_eq!(
            s.insert(0, &model(4, open), &lighting())
                .unwrap_err()
                .code(),
            1
        );
        s.finish().unwrap();
        for (index, bytes) in [
            (0, model(5, open)),
            (1, model(4, open)),
            (0, b"junk".to_vec()),
        ] {
            let e = s.insert(index, &bytes, &lighting()).unwrap_err();
            assert_eq!(e.code(), 2, "{e}");
        }
        let mut bad = MeshData {
            positions: vec![Vec3::ZERO],
            normals: vec![Vec3::Z],
            indices: vec![[0, 0, 1]],
            ..MeshData::default()
        };
        assert!(s.push_mesh(bad.clone()).is_err());
        bad.indices.clear();
        bad.normals.clear();
        assert!(s.push_mesh(bad).is_err());
        assert!(s.play(MAX_CLIPS).is_err());
        assert!(channel(0, 3, 1, Vec::new(), Vec::new()).is_none());
        // A skin joint that is no node.
        let mut s = scene();
        s.push_skin(vec![7], vec![Mat4::IDENTITY]);
        s.push_instance(0, None, Some(1), Affine3A::IDENTITY);
        assert_eq!(s.finish().unwrap_err().code(), 1);
    }
}
