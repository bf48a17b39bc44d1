//! One served character on a client, frame by frame: the steps `psao view`/`psao run`
//! (`psao_net::relit`) and the browser (`psao-wasm`) share around a [`ServedRelighter`].
//! Pure and portable.
//!
//! A [`ServedCharacter`] is built from the scene's [`SkinnedGroup`], its served model file
//! and the served lighting (checked to be that character's model). Per frame,
//! [`ServedCharacter::relight`] gathers the relit vertices' world positions and normals
//! from where the client rasterizes each instance ([`InstanceGeometry`]), takes the joints'
//! local transforms from the pose's nodes, relights, and [`ServedCharacter::scatter`] puts
//! the values onto each instance's mesh vertices ([`NOT_RELIT`] where a mesh vertex is not
//! the character's).

use glam::{Affine3A, Vec3};
use psao_scene::Scene;

use crate::character::{normal_matrix, Character};
use crate::groups::SkinnedGroup;
use crate::model_file;
use crate::runtime::FramePose;
use crate::served::{ServedRelighter, VertexValues, NOT_RELIT};
use crate::shade::Mode;
use crate::PrtError;

/// Where a client draws one instance in a frame.
#[derive(Clone, Copy, Debug)]
pub struct InstanceGeometry<'a> {
    /// Its world transform.
    pub transform: Affine3A,
    /// Its skinned positions in the mesh's frame (`None`: the mesh's own).
    pub positions: Option<&'a [Vec3]>,
    /// Its skinned normals (`None`: the mesh's own).
    pub normals: Option<&'a [Vec3]>,
}

/// A served character ready to relight, with the scratch of its frames.
pub struct ServedCharacter {
    character: Character,
    /// Per part of the character: its instance in the whole scene.
    instances: Vec<usize>,
    relighter: ServedRelighter,
    /// World positions and normals of the relit vertices (scratch).
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// The relit vertices' values, in character order.
    values: Vec<VertexValues>,
}

impl ServedCharacter {
    /// Character `index` of a scene (its skinned `group`), relit diffuse with the served
    /// `model` file under the served `lighting` (16 SH numbers per colour channel). Errors
    /// when the model is malformed or was trained on another character.
    pub fn new(
        index: usize,
        group: &SkinnedGroup,
        model: &[u8],
        lighting: &[f32],
    ) -> Result<Self, PrtError> {
        let character = Character::new(group.scene.clone(), None)?;
        let model = model_file::from_bytes(model)?;
        if model.vertices != character.vertex_count() || model.joints != character.joint_count() {
            return Err(PrtError::WrongCharacter {
                model: model.character.clone(),
                model_vertices: model.vertices,
                model_joints: model.joints,
                character: format!("character {index} of the scene"),
                vertices: character.vertex_count(),
                joints: character.joint_count(),
            });
        }
        let relighter = ServedRelighter::new(model, character.rig(), Mode::Diffuse, lighting)?;
        Ok(Self {
            character,
            instances: group.instances.clone(),
            relighter,
            positions: Vec::new(),
            normals: Vec::new(),
            values: Vec::new(),
        })
    }

    /// Vertices relit per frame.
    pub fn vertex_count(&self) -> usize {
        self.character.vertex_count()
    }

    /// Relights one frame of `scene` seen from `eye`: `nodes` the world transform of every
    /// scene node, `geometry(i)` where instance `i` is drawn.
    pub fn relight<'g>(
        &mut self,
        scene: &Scene,
        nodes: &[Affine3A],
        geometry: impl Fn(usize) -> InstanceGeometry<'g>,
        eye: Vec3,
    ) -> Result<(), PrtError> {
        self.gather(scene, geometry);
        let joint_local = self.character.joint_local(nodes);
        let pose = FramePose {
            joint_local: &joint_local,
            positions: &self.positions,
            normals: &self.normals,
            transform: Affine3A::IDENTITY,
        };
        self.relighter.relight(&pose, eye, &mut self.values)
    }

    /// The relit vertices' world positions and normals (an instance's own mesh where its
    /// geometry has none).
    fn gather<'g>(&mut self, scene: &Scene, geometry: impl Fn(usize) -> InstanceGeometry<'g>) {
        self.positions.clear();
        self.normals.clear();
        for (part, vertices) in self.character.parts() {
            let instance = self.instances[part];
            let mesh = &scene.meshes[scene.instances[instance].mesh];
            let g = geometry(instance);
            let p = g.positions.unwrap_or(&mesh.positions);
            let n = g.normals.unwrap_or(&mesh.normals);
            let to_normal = normal_matrix(g.transform);
            for &v in vertices {
                let v = v as usize;
                let position = p.get(v).copied().unwrap_or(Vec3::ZERO);
                self.positions.push(g.transform.transform_point3(position));
                let normal = n.get(v).copied().unwrap_or(Vec3::Z);
                self.normals
                    .push((to_normal * normal).normalize_or(Vec3::Z));
            }
        }
    }

    /// The last frame's values onto the instances' mesh vertices: `values[i]` for each of
    /// the character's instances `i` (those beyond `values` are skipped), one per mesh
    /// vertex.
    pub fn scatter(&self, scene: &Scene, values: &mut [Option<Vec<VertexValues>>]) {
        let mut relit = self.values.iter();
        for (part, vertices) in self.character.parts() {
            let instance = self.instances[part];
            let count = scene.meshes[scene.instances[instance].mesh].positions.len();
            let Some(slot) = values.get_mut(instance) else {
                continue;
            };
            let out = slot.get_or_insert_with(Vec::new);
            out.clear();
            out.resize(count, NOT_RELIT);
            for (&v, x) in vertices.iter().zip(&mut relit) {
                out[v as usize] = *x;
            }
        }
    }
}
