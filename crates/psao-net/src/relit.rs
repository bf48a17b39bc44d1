//! Relit characters on a client (docs/RELIGHTING.md, "Served characters"): the skinned
//! characters of the scene shaded with the relighting models the server sends
//! ([`psao_wire::RelightingMsg`]), frame by frame from the client's own pose.
//!
//! Per frame and character, [`psao_prt::runtime::Relighter`] synthesises every vertex's lobes
//! from the pose and shades it (diffuse) under the served SH lighting and under a white
//! constant sky. Per vertex that gives
//!
//! * `o_c = S_c / U_c`, the character's self-shadowing under the environment in channel c
//!   (`S_c` the shadowed diffuse shade, `U_c` the unshadowed one at the skinned normal,
//!   [`unshadowed_diffuse`]), clamped to [0, 1];
//! * `a = S_white`, its cosine-weighted self-visibility (the character's own ambient
//!   occlusion, to infinity), clamped to [0, 1].
//!
//! Both are interpolated over the rasterized triangles. The points the server traces on the
//! character's surfaces see the scene *and* the character, so their AO `A` (and their
//! irradiance) already count the character's own occlusion. A relit pixel's AO or irradiance
//! from the points is therefore multiplied by `m_c = o_c / max(A, a)` ([`pixel_factor`]): the
//! ambient term becomes `o_c · min(1, A / a)`, the model's self-shadowing times what the scene
//! casts beyond the character's own occlusion (the points' occlusion divided by the
//! model's estimate of its self part, when it is the larger). A character that does not
//! shadow itself (`o = a = 1`) keeps the points' shading unchanged.

use glam::{Affine3A, Vec3};
use psao_prt::character::{normal_matrix, Character};
use psao_prt::groups::skinned_groups;
use psao_prt::model_file;
use psao_prt::runtime::{FramePose, Relighter};
use psao_prt::sh::{self, ShVec, COEFFS};
use psao_prt::shade::{unit_visibility, Mode, Shader};
use psao_prt::PrtError;
use psao_raster::{GBuffer, InstancePose};
use psao_scene::Scene;
use psao_wire::RelightingMsg;
use rayon::prelude::*;

use crate::NetError;

/// Per band, the clamped-cosine convolution divided by π (`A_l / π`): what turns SH radiance
/// into the unshadowed diffuse shade of a Lambertian surface of albedo 1.
const DIFFUSE_BANDS: [f32; 4] = [1.0, 2.0 / 3.0, 0.25, 0.0];

/// Below this unshadowed shade a channel counts as unlit (its self-shadowing is 1).
const UNLIT: f32 = 1e-6;

/// The least occlusion a pixel's factor divides by.
const MIN_OCCLUSION: f32 = 1e-3;

/// Values per vertex: self-shadowing per colour channel, then self-visibility.
pub type VertexValues = [f32; 4];

/// Per vertex of a relit instance's mesh, the values of a vertex that is not relit.
const NOT_RELIT: VertexValues = [1.0; 4];

/// The unshadowed diffuse shade at unit normal `n` of SH radiance `light` (albedo 1:
/// irradiance / π).
pub fn unshadowed_diffuse(light: &ShVec, n: Vec3) -> f32 {
    let y = sh::eval(n);
    (0..COEFFS)
        .map(|i| DIFFUSE_BANDS[sh::band_of(i)] * light[i] * y[i])
        .sum()
}

/// A vertex's values from its shades (`shade`: R, G, B under the environment, then under a
/// white constant sky) and its unshadowed shades per channel: `[o_r, o_g, o_b, a]` (module
/// documentation).
pub fn vertex_values(shade: [f32; 4], unshadowed: [f32; 3]) -> VertexValues {
    let o = |c: usize| {
        if unshadowed[c] > UNLIT {
            (shade[c] / unshadowed[c]).clamp(0.0, 1.0)
        } else {
            1.0
        }
    };
    [o(0), o(1), o(2), shade[3].clamp(0.0, 1.0)]
}

/// The lighting a client relights with: the served channels (`SH_COEFFS` numbers each, one
/// channel repeated as grey, a fourth dropped), then a white constant sky (whose shade is
/// the self-visibility).
pub fn client_lights(served: &[f32]) -> Vec<ShVec> {
    let mut lights: Vec<ShVec> = served
        .chunks_exact(COEFFS)
        .take(3)
        .map(|c| c.try_into().expect("16 numbers"))
        .collect();
    let grey = lights.first().copied().unwrap_or_else(unit_visibility);
    lights.resize(3, grey);
    lights.push(unit_visibility());
    lights
}

/// Per relit vertex, its [`VertexValues`] (into `out`, resized) from its shades under the
/// [`client_lights`] (4 per vertex) and its world normal.
pub fn values_of_shades(
    shades: &[f32],
    normals: &[Vec3],
    lights: &[ShVec],
    out: &mut Vec<VertexValues>,
) {
    out.resize(normals.len(), NOT_RELIT);
    out.par_iter_mut()
        .zip(normals.par_iter().zip(shades.par_chunks_exact(4)))
        .for_each(|(o, (n, s))| {
            let unshadowed = std::array::from_fn(|c| unshadowed_diffuse(&lights[c], *n));
            *o = vertex_values([s[0], s[1], s[2], s[3]], unshadowed);
        });
}

/// The factor of a relit pixel's AO or irradiance from the points, per channel:
/// `o / max(ao, a)` with the pixel's interpolated self-shadowing `o` and self-visibility
/// `a` and the points' AO `ao` (module documentation).
pub fn pixel_factor(o: Vec3, a: f32, ao: f32) -> Vec3 {
    o / ao.max(a).max(MIN_OCCLUSION)
}

/// One served character, ready to relight.
struct RelitCharacter {
    character: Character,
    /// Per instance of the character's group: its index in the scene.
    instances: Vec<usize>,
    relighter: Relighter,
    /// The served lighting (one vector per colour channel), then a white constant sky.
    lights: Vec<ShVec>,
    /// Scratch: world positions and normals of the relit vertices, and their shades.
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    shades: Vec<f32>,
    /// The relit vertices' values in character order.
    values: Vec<VertexValues>,
}

/// The relit characters of a scene on a client, and the values of the frame last relit.
#[derive(Default)]
pub struct RelitCharacters {
    /// By served index.
    characters: Vec<Option<RelitCharacter>>,
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
        let character = Character::new(group.scene, None).map_err(fail)?;
        let model = model_file::from_bytes(&msg.model).map_err(fail)?;
        if model.vertices != character.vertex_count() || model.joints != character.joint_count() {
            return Err(fail(PrtError::WrongCharacter {
                model: model.character.clone(),
                model_vertices: model.vertices,
                model_joints: model.joints,
                character: format!("character {index} of the scene"),
                vertices: character.vertex_count(),
                joints: character.joint_count(),
            }));
        }
        let shader = Shader::new(Mode::Diffuse).map_err(fail)?;
        let relighter = Relighter::new(model, shader, character.rig()).map_err(fail)?;
        let lights = client_lights(&msg.lighting);
        if self.characters.len() <= index {
            self.characters.resize_with(index + 1, || None);
        }
        self.characters[index] = Some(RelitCharacter {
            character,
            instances: group.instances,
            relighter,
            lights,
            positions: Vec::new(),
            normals: Vec::new(),
            shades: Vec::new(),
            values: Vec::new(),
        });
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
            c.gather(scene, poses);
            let joint_local = c.character.joint_local(nodes);
            let pose = FramePose {
                joint_local: &joint_local,
                positions: &c.positions,
                normals: &c.normals,
                transform: Affine3A::IDENTITY,
            };
            c.relighter
                .shade_into(&pose, &c.lights, eye, &mut c.shades)
                .map_err(|source| NetError::Relight {
                    character: index as u32,
                    source,
                })?;
            values_of_shades(&c.shades, &c.normals, &c.lights, &mut c.values);
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

impl RelitCharacter {
    /// The relit vertices' world positions and normals from the rasterized poses (an
    /// instance's own mesh where its pose has none).
    fn gather(&mut self, scene: &Scene, poses: &[InstancePose<'_>]) {
        self.positions.clear();
        self.normals.clear();
        for (part, vertices) in self.character.parts() {
            let instance = self.instances[part];
            let mesh = &scene.meshes[scene.instances[instance].mesh];
            let pose = poses
                .get(instance)
                .copied()
                .unwrap_or(InstancePose::rest(&scene.instances[instance]));
            let (p, n) = (
                pose.positions.unwrap_or(&mesh.positions),
                pose.normals.unwrap_or(&mesh.normals),
            );
            let to_normal = normal_matrix(pose.transform);
            for &v in vertices {
                let v = v as usize;
                self.positions.push(
                    pose.transform
                        .transform_point3(p.get(v).copied().unwrap_or(Vec3::ZERO)),
                );
                let normal = n.get(v).copied().unwrap_or(Vec3::Z);
                self.normals
                    .push((to_normal * normal).normalize_or(Vec3::Z));
            }
        }
    }

    /// The frame's [`VertexValues`] onto the instances' mesh vertices.
    fn scatter(&self, scene: &Scene, values: &mut [Option<Vec<VertexValues>>]) {
        let mut relit = self.values.iter();
        for (part, vertices) in self.character.parts() {
            let instance = self.instances[part];
            let count = scene.meshes[scene.instances[instance].mesh].positions.len();
            let out = values[instance].get_or_insert_with(Vec::new);
            out.clear();
            out.resize(count, NOT_RELIT);
            for (&v, x) in vertices.iter().zip(&mut relit) {
                out[v as usize] = *x;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;
    use psao_prt::model::{PoseModel, LOBE_DIM};
    use psao_prt::runtime::Rig;

    /// Some SH radiance per channel: a sky brighter above, with a coloured band-2 part.
    fn sky() -> [ShVec; 3] {
        std::array::from_fn(|c| {
            let mut l = unit_visibility().map(|x| x * (0.8 + 0.1 * c as f32));
            l[1] = 0.5;
            l[3] = -0.2 * c as f32;
            l[6] = 0.15;
            l
        })
    }

    #[test]
    fn an_all_visible_character_is_shaded_as_plain_sh_diffuse() {
        // Three vertices with different normals, one lobe of visibility 1, no pose effect.
        let n = 3 * LOBE_DIM;
        let mut weights = vec![0.0f32; 4 * n];
        for v in 0..3 {
            weights[v * LOBE_DIM + 2] = 1.0;
            weights[v * LOBE_DIM + 3] = unit_visibility()[0];
        }
        let model = PoseModel {
            character: "t".into(),
            vertices: 3,
            joints: 1,
            lobes: 1,
            active: vec![0],
            weights,
            limits: Default::default(),
        };
        let rig = Rig {
            rest: vec![Quat::IDENTITY],
            neighbours: vec![1, 2, 0],
        };
        let mut r = Relighter::new(model, Shader::new(Mode::Diffuse).unwrap(), rig).unwrap();
        let normals = [
            Vec3::Z,
            Vec3::new(0.3, 0.9, -0.2).normalize(),
            Vec3::new(-0.6, -0.5, 0.4).normalize(),
        ];
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let lights = sky();
        let shades = r
            .shade(
                &FramePose {
                    joint_local: &[Affine3A::IDENTITY],
                    positions: &positions,
                    normals: &normals,
                    transform: Affine3A::IDENTITY,
                },
                &lights,
                Vec3::Z,
            )
            .unwrap();
        for (v, n) in normals.iter().enumerate() {
            for (c, light) in lights.iter().enumerate() {
                let (got, want) = (shades[v * 3 + c], unshadowed_diffuse(light, *n));
                assert!(
                    (got - want).abs() < 2e-3 * want.abs().max(1.0),
                    "{got} vs {want}"
                );
            }
        }
        // A constant radiance of 1 is shaded 1 (albedo 1) at any normal.
        assert!((unshadowed_diffuse(&unit_visibility(), normals[2]) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn vertex_values_are_self_shadowing_and_self_visibility_in_0_1() {
        let v = vertex_values([0.4, 0.0, 0.9, 0.7], [0.8, 0.0, 0.6]);
        // Half of red, an unlit green counts as unshadowed, ringing above 1 is clamped.
        assert_eq!(v, [0.5, 1.0, 1.0, 0.7]);
        assert_eq!(vertex_values([-0.1, 0.2, 0.2, 1.3], [1.0; 3])[0], 0.0);
        assert_eq!(vertex_values([0.2; 4], [1.0; 3])[3], 0.2);
        assert_eq!(vertex_values([0.2, 0.2, 0.2, 1.3], [1.0; 3])[3], 1.0);
    }

    #[test]
    fn pixels_keep_what_the_scene_casts_and_take_the_models_self_shadowing() {
        let o = Vec3::new(0.8, 0.6, 0.4);
        // No self-shadowing: the points' AO is kept whatever it is.
        for ao in [0.2, 0.7, 1.0] {
            assert_eq!(pixel_factor(Vec3::ONE, 1.0, ao), Vec3::ONE);
        }
        // The points see no more occlusion than the character's own: the model's alone.
        let ao = 0.8;
        assert!((ao * pixel_factor(o, 0.7, ao) - o).abs().max_element() < 1e-6);
        // The scene occludes more: its share A / a on top of the model's self-shadowing.
        let ao = 0.35;
        assert!(
            (ao * pixel_factor(o, 0.7, ao) - o * 0.5)
                .abs()
                .max_element()
                < 1e-6
        );
        // Nothing is divided by zero.
        assert!(pixel_factor(o, 0.0, 0.0).is_finite());
    }
}
