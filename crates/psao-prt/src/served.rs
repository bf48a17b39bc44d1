//! A served character's self-shadowing, per vertex and frame, as every client computes it
//! (docs/RELIGHTING.md, "Served characters"): `psao run --relight` and `psao view` through
//! `psao_net::relit`, the browser through `psao-wasm`. Pure and portable.
//!
//! A [`ServedRelighter`] holds the served model (a [`Relighter`]) and lighting
//! ([`client_lights`]: the served SH channels, then a white constant sky). Per frame,
//! [`ServedRelighter::relight`] synthesises every vertex's lobes from the pose and shades
//! it, which gives per vertex ([`VertexValues`])
//!
//! * `o_c = S_c / U_c`, the character's self-shadowing under the environment in channel c
//!   (`S_c` the shade with the model's visibility, `U_c` with visibility 1, both in the
//!   served mode: diffuse, Phong or translucent), clamped to [0, 1] ([`vertex_values`]);
//! * `a = S_white`, its self-visibility weighted by the mode's lobe (for diffuse the
//!   cosine-weighted self-visibility, the character's own ambient occlusion, to infinity),
//!   clamped to [0, 1].
//!
//! A renderer interpolates them over its triangles and multiplies a relit pixel's AO or
//! irradiance from the scene's points by [`pixel_factor`].

use glam::Vec3;

use crate::model::PoseModel;
use crate::runtime::{FramePose, Relighter, Rig};
use crate::sh::{ShVec, COEFFS};
use crate::shade::{unit_visibility, Mode, Shader};
use crate::PrtError;

/// Below this unshadowed shade a channel counts as unlit (its self-shadowing is 1).
const UNLIT: f32 = 1e-6;

/// The least occlusion a pixel's factor divides by.
const MIN_OCCLUSION: f32 = 1e-3;

/// Values per vertex: self-shadowing per colour channel, then self-visibility.
pub type VertexValues = [f32; 4];

/// The values of a vertex that is not relit (nothing shadowed).
pub const NOT_RELIT: VertexValues = [1.0; 4];

/// A vertex's values from its shades under the [`client_lights`] (R, G, B under the
/// environment, then under the white sky) with the model's visibility, `shade`, and with
/// visibility 1, `unshadowed`: `[o_r, o_g, o_b, a]` (module documentation).
pub fn vertex_values(shade: &[f32], unshadowed: &[f32]) -> VertexValues {
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

/// The factor of a relit pixel's AO or irradiance from the points, per channel:
/// `o / max(ao, a)` with the pixel's interpolated self-shadowing `o` and self-visibility
/// `a` and the points' AO `ao` (`psao_net::relit`'s documentation).
pub fn pixel_factor(o: Vec3, a: f32, ao: f32) -> Vec3 {
    o / ao.max(a).max(MIN_OCCLUSION)
}

/// A served character's model and lighting, ready to give its [`VertexValues`] frame after
/// frame.
pub struct ServedRelighter {
    relighter: Relighter,
    lights: Vec<ShVec>,
}

impl ServedRelighter {
    /// The model shaded in `mode` under the served lighting (`served`: SH radiance, 16
    /// numbers per colour channel, see [`client_lights`]), for the character of `rig`.
    /// Errors when the mode's parameters are out of range or the rig is not the model's
    /// character's.
    pub fn new(model: PoseModel, rig: Rig, mode: Mode, served: &[f32]) -> Result<Self, PrtError> {
        Ok(Self {
            relighter: Relighter::new(model, Shader::new(mode)?, rig)?,
            lights: client_lights(served),
        })
    }

    /// The relighter (its compacted model and shader).
    pub fn relighter(&self) -> &Relighter {
        &self.relighter
    }

    /// Every vertex's [`VertexValues`] at `pose` seen from `eye` (world; used by Phong) into
    /// `out` (resized to one per vertex; reused from frame to frame, nothing else is
    /// allocated per frame besides a scratch per task), on the calling rayon pool. Errors
    /// when the pose's joint or vertex counts are not the model's.
    pub fn relight(
        &mut self,
        pose: &FramePose<'_>,
        eye: Vec3,
        out: &mut Vec<VertexValues>,
    ) -> Result<(), PrtError> {
        out.resize(self.relighter.compact().vertices(), NOT_RELIT);
        self.relighter.shade_with(
            pose,
            &self.lights,
            eye,
            1,
            out,
            |shade, unshadowed, slot| {
                slot[0] = vertex_values(shade, unshadowed);
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LOBE_DIM;
    use crate::sh;
    use glam::{Affine3A, Quat};

    /// Per band, the clamped-cosine convolution divided by π (`A_l / π`).
    const DIFFUSE_BANDS: [f32; 4] = [1.0, 2.0 / 3.0, 0.25, 0.0];

    /// The unshadowed diffuse shade at unit normal `n` of SH radiance `light` (albedo 1),
    /// in closed form.
    fn unshadowed_diffuse(light: &ShVec, n: Vec3) -> f32 {
        let y = sh::eval(n);
        (0..COEFFS)
            .map(|i| DIFFUSE_BANDS[sh::band_of(i)] * light[i] * y[i])
            .sum()
    }

    /// Some SH radiance per channel: a sky brighter above, with a coloured band-2 part.
    fn sky() -> Vec<f32> {
        (0..3)
            .flat_map(|c| {
                let mut l = unit_visibility().map(|x| x * (0.8 + 0.1 * c as f32));
                l[1] = 0.5;
                l[3] = -0.2 * c as f32;
                l[6] = 0.15;
                l
            })
            .collect()
    }

    /// Three vertices, each with `lobes` (axis in the local frame, zonal coefficients);
    /// no pose effect.
    fn model(lobes: &[(Vec3, [f32; 4])]) -> PoseModel {
        let per = lobes.len() * LOBE_DIM;
        let mut weights = vec![0.0f32; 4 * 3 * per];
        for v in 0..3 {
            for (x, (axis, c)) in lobes.iter().enumerate() {
                let o = v * per + x * LOBE_DIM;
                weights[o..o + 3].copy_from_slice(&axis.to_array());
                weights[o + 3..o + 7].copy_from_slice(c);
            }
        }
        PoseModel {
            character: "t".into(),
            vertices: 3,
            joints: 1,
            lobes: lobes.len(),
            active: vec![0],
            weights,
            limits: Default::default(),
        }
    }

    fn rig() -> Rig {
        Rig {
            rest: vec![Quat::IDENTITY],
            neighbours: vec![1, 2, 0],
        }
    }

    const NORMALS: [Vec3; 3] = [
        Vec3::Z,
        Vec3::new(0.3, 0.9, -0.2),
        Vec3::new(-0.6, -0.5, 0.4),
    ];
    const POSITIONS: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

    fn pose(normals: &[Vec3]) -> FramePose<'_> {
        FramePose {
            joint_local: &[Affine3A::IDENTITY],
            positions: &POSITIONS,
            normals,
            transform: Affine3A::IDENTITY,
        }
    }

    fn normals() -> Vec<Vec3> {
        NORMALS.iter().map(|n| n.normalize()).collect()
    }

    #[test]
    fn an_all_visible_character_is_shaded_as_plain_sh_diffuse_and_not_shadowed() {
        // One lobe of visibility 1.
        let m = model(&[(Vec3::Z, [unit_visibility()[0], 0.0, 0.0, 0.0])]);
        let served = sky();
        let normals = normals();
        let mut r = Relighter::new(m.clone(), Shader::new(Mode::Diffuse).unwrap(), rig()).unwrap();
        let lights = client_lights(&served);
        let shades = r.shade(&pose(&normals), &lights, Vec3::Z).unwrap();
        for (v, n) in normals.iter().enumerate() {
            for (c, light) in lights.iter().enumerate() {
                let (got, want) = (shades[v * 4 + c], unshadowed_diffuse(light, *n));
                assert!(
                    (got - want).abs() < 2e-3 * want.abs().max(1.0),
                    "vertex {v} channel {c}: {got} vs {want}"
                );
            }
        }
        // A constant radiance of 1 is shaded 1 (albedo 1) at any normal, and the values
        // say: nothing shadowed.
        assert!((unshadowed_diffuse(&unit_visibility(), normals[2]) - 1.0).abs() < 1e-6);
        let mut served_r = ServedRelighter::new(m, rig(), Mode::Diffuse, &served).unwrap();
        let mut values = Vec::new();
        served_r
            .relight(&pose(&normals), Vec3::Z, &mut values)
            .unwrap();
        for v in &values {
            assert!(v.iter().all(|x| (x - 1.0).abs() < 1e-4), "{v:?}");
        }
    }

    #[test]
    fn a_half_occluded_vertex_is_self_shadowed_in_every_mode() {
        // A lobe of visibility about the local +x (tangent) direction: the vertices see
        // less than all of their hemisphere.
        let m = model(&[(Vec3::X, [1.5, 1.6, 0.4, -0.2])]);
        let served = sky();
        let normals = normals();
        for mode in [
            Mode::Diffuse,
            Mode::Phong { alpha: 8.0 },
            Mode::Translucent { transmission: 0.3 },
        ] {
            let mut r = ServedRelighter::new(m.clone(), rig(), mode, &served).unwrap();
            let mut values = Vec::new();
            r.relight(&pose(&normals), Vec3::new(0.5, 2.0, 3.0), &mut values)
                .unwrap();
            assert_eq!(values.len(), 3);
            for v in &values {
                assert!(v.iter().all(|x| (0.0..=1.0).contains(x)), "{mode:?}: {v:?}");
                assert!(v.iter().any(|x| *x < 0.95), "{mode:?}: {v:?}");
            }
        }
    }

    #[test]
    fn vertex_values_are_self_shadowing_and_self_visibility_in_0_1() {
        let v = vertex_values(&[0.4, 0.0, 0.9, 0.7], &[0.8, 0.0, 0.6, 1.0]);
        // Half of red, an unlit green counts as unshadowed, ringing above 1 is clamped.
        assert_eq!(v, [0.5, 1.0, 1.0, 0.7]);
        assert_eq!(vertex_values(&[-0.1, 0.2, 0.2, 1.3], &[1.0; 4])[0], 0.0);
        assert_eq!(vertex_values(&[0.2; 4], &[1.0; 4])[3], 0.2);
        assert_eq!(vertex_values(&[0.2, 0.2, 0.2, 1.3], &[1.0; 4])[3], 1.0);
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
