//! Relit characters on a client (docs/RELIGHTING.md, "Served characters"): the skinned
//! characters of the scene shaded with the relighting models the server sends
//! ([`psao_wire::RelightingMsg`]), frame by frame from the client's own pose.
//!
//! Per frame and character, a [`psao_prt::served::ServedRelighter`] (through
//! [`ServedCharacter`]) synthesises every vertex's lobes from the pose and gives its
//! self-shadowing `o_c` per colour channel under the served lighting and its
//! self-visibility `a` ([`psao_prt::served`], the computation the browser shares).
//! Both are interpolated over the rasterized triangles. The points the server traces on the
//! character's surfaces see the scene *and* the character, so their AO `A` (and their
//! irradiance) already count the character's own occlusion. A relit pixel's AO or irradiance
//! from the points is therefore multiplied by `m_c = o_c / max(A, a)` ([`pixel_factor`]): the
//! ambient term becomes `o_c · min(1, A / a)`, the model's self-shadowing times what the scene
//! casts beyond the character's own occlusion (the points' occlusion divided by the
//! model's estimate of its self part, when it is the larger). A character that does not
//! shadow itself (`o = a = 1`) keeps the points' shading unchanged.

use glam::{Affine3A, Vec3};
use psao_prt::groups::skinned_groups;
use psao_prt::served::{pixel_factor, VertexValues, NOT_RELIT};
use psao_prt::served_character::{InstanceGeometry, ServedCharacter};
use psao_prt::PrtError;
use psao_raster::{GBuffer, InstancePose};
use psao_scene::Scene;
use psao_wire::RelightingMsg;
use rayon::prelude::*;

use crate::NetError;

/// The relit characters of a scene on a client, and the values of the frame last relit.
#[derive(Default)]
pub struct RelitCharacters {
    /// By served index.
    characters: Vec<Option<ServedCharacter>>,
    /// Per scene instance: for relit instances, one [`VertexValues`] per mesh vertex.
    values: Vec<Option<Vec<VertexValues>>>,
}

impl RelitCharacters {
    /// Whether no character is relit.
    pub fn is_empty(&self) -> bool {
        self.characters.iter().all(Option::is_none)
    }

    /// Relights character `msg.character` of `scene` with the served model and lighting
    /// (replacing an earlier one). Errors when the message is malformed, the scene has no
    /// such character or the model is another character's.
    pub fn insert(&mut self, scene: &Scene, msg: &RelightingMsg) -> Result<(), NetError> {
        msg.validate()?;
        let fail = |source| NetError::Relight {
            character: msg.character,
            source,
        };
        let index = msg.character as usize;
        let group = skinned_groups(scene)
            .into_iter()
            .nth(index)
            .ok_or_else(|| {
                fail(PrtError::Parameter(
                    "the scene has no such skinned character".into(),
                ))
            })?;
        let character =
            ServedCharacter::new(index, &group, &msg.model, &msg.lighting).map_err(fail)?;
        if self.characters.len() <= index {
            self.characters.resize_with(index + 1, || None);
        }
        self.characters[index] = Some(character);
        Ok(())
    }

    /// Relights every character in one frame: `nodes` the world transform of every scene
    /// node, `poses` every instance as rasterized, `eye` the camera position.
    pub fn relight(
        &mut self,
        scene: &Scene,
        nodes: &[Affine3A],
        poses: &[InstancePose<'_>],
        eye: Vec3,
    ) -> Result<(), NetError> {
        self.values.resize(scene.instances.len(), None);
        for (index, slot) in self.characters.iter_mut().enumerate() {
            let Some(c) = slot else { continue };
            let geometry = |i: usize| {
                let pose = poses
                    .get(i)
                    .copied()
                    .unwrap_or(InstancePose::rest(&scene.instances[i]));
                InstanceGeometry {
                    transform: pose.transform,
                    positions: pose.positions,
                    normals: pose.normals,
                }
            };
            c.relight(scene, nodes, geometry, eye)
                .map_err(|source| NetError::Relight {
                    character: index as u32,
                    source,
                })?;
            c.scatter(scene, &mut self.values);
        }
        Ok(())
    }

    /// Per pixel of `gbuffer`, the factor of its AO or irradiance from the points (1 where
    /// no relit character is seen), from the frame last relit and the points' AO `ao`;
    /// `None` when no character is relit.
    pub fn pixel_factors(&self, scene: &Scene, gbuffer: &GBuffer, ao: &[f32]) -> Option<Vec<Vec3>> {
        if self.is_empty() {
            return None;
        }
        let pixels = gbuffer.width as usize * gbuffer.height as usize;
        Some(
            (0..pixels)
                .into_par_iter()
                .map(|i| self.pixel(scene, gbuffer, ao, i).unwrap_or(Vec3::ONE))
                .collect(),
        )
    }

    /// Pixel `i`'s factor when it shows a relit instance.
    fn pixel(&self, scene: &Scene, gbuffer: &GBuffer, ao: &[f32], i: usize) -> Option<Vec3> {
        let instance = *gbuffer.instance.get(i)? as usize;
        let values = self.values.get(instance)?.as_ref()?;
        let mesh = scene.meshes.get(scene.instances.get(instance)?.mesh)?;
        let tri = mesh.indices.get(*gbuffer.triangle.get(i)? as usize)?;
        let b = *gbuffer.barycentric.get(i)?;
        let weights = [1.0 - b.x - b.y, b.x, b.y];
        let mut v = [0.0f32; 4];
        for (&k, w) in tri.iter().zip(weights) {
            let x = values.get(k as usize).unwrap_or(&NOT_RELIT);
            for (acc, x) in v.iter_mut().zip(x) {
                *acc += w * x;
            }
        }
        let ao = ao.get(i).copied().unwrap_or(1.0);
        Some(pixel_factor(Vec3::new(v[0], v[1], v[2]), v[3], ao))
    }
}
