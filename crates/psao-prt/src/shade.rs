//! Run-time shading (paper §4.3): visibility (lobes, a projected SH vector, or none) →
//! into the BRDF's frame → SH (eq. 1) → normalised-Phong operator → dot with the lighting
//! rotated into that frame.

use glam::{Affine3A, Mat3, Vec3};
use psao_trace::ao::orthonormal_basis;
use rayon::prelude::*;

use crate::filter::{Filter, Prepared};
use crate::model::PoseModel;
use crate::phong::PhongOperator;
use crate::rotation::ShRotation;
use crate::sh::{ShVec, COEFFS};
use crate::zonal::ZhLobe;
use crate::PrtError;

/// The reflection models.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    /// Lambertian with albedo 1 (the α = 1 operator about the normal).
    Diffuse,
    /// Normalised Phong about the view's reflection vector with exponent `alpha` (≥ 1).
    Phong {
        /// The Phong exponent.
        alpha: f32,
    },
    /// Thin-membrane translucency (paper §4.1 after Sloan et al. 2005): a shadowed diffuse
    /// front lobe plus an unshadowed diffuse lobe about −n carrying light from behind.
    Translucent {
        /// Fraction of the shade transmitted through the membrane (0..1).
        transmission: f32,
    },
}

impl Mode {
    /// Checks the parameters.
    pub fn validate(self) -> Result<Self, PrtError> {
        match self {
            Mode::Phong { alpha } if !(alpha.is_finite() && alpha >= 1.0) => {
                Err(PrtError::Parameter(format!(
                    "Phong exponent {alpha} (must be a finite number ≥ 1)"
                )))
            }
            Mode::Translucent { transmission } if !(0.0..=1.0).contains(&transmission) => Err(
                PrtError::Parameter(format!("transmission {transmission} (must be in 0..1)")),
            ),
            m => Ok(m),
        }
    }
}

/// Where each vertex's visibility comes from.
#[derive(Clone, Copy)]
pub enum Visibility<'a> {
    /// Nothing is shadowed (visibility 1).
    Unshadowed,
    /// SH vectors in the local frames (e.g. projected at the true pose).
    Projected(&'a [ShVec]),
    /// Raw outputs of a pose model (see [`PoseModel::predict_raw`]).
    Model(&'a PoseModel, &'a [f32]),
}

/// The pose's geometry as shading needs it.
#[derive(Clone, Copy)]
pub struct ShadingGeometry<'a> {
    /// Mesh-local positions.
    pub positions: &'a [Vec3],
    /// Per vertex local frame (tangent, bitangent, normal) in mesh space.
    pub frames: &'a [Mat3],
    /// Mesh-local to world.
    pub transform: Affine3A,
}

/// The SH vector of the constant 1 (unshadowed visibility).
pub fn unit_visibility() -> ShVec {
    let mut v = [0.0; COEFFS];
    v[0] = 2.0 * std::f32::consts::PI.sqrt();
    v
}

/// Entries of the horizon table over `cos ∈ [−1, 1]`.
const HORIZON_ENTRIES: usize = 257;
/// Integration steps per horizon table entry.
const HORIZON_STEPS: usize = 512;

/// The fraction of the normalised Phong lobe `(α+1)/(2π) cos^α` about an axis `r` that lies
/// above the tangent plane of a normal `n`, tabulated over `cos = r·n` (linear
/// interpolation). No BRDF receives light from below its surface, and the eq. 2 operator
/// integrates over the hemisphere about `r`, which crosses that horizon when `r` is not
/// `n`; the shade is scaled by this fraction (exact when visibility × lighting is constant
/// over the lobe). Visibility below the horizon is stored as 1 (see
/// [`crate::visibility`]), so the horizon is counted once.
#[derive(Clone, Debug)]
pub struct HorizonTable {
    values: Vec<f32>,
}

impl HorizonTable {
    /// The table for exponent `alpha` (≥ 1). In the lobe's polar angle θ, the directions at
    /// azimuth φ above the horizon satisfy `c cos θ + s sin θ cos φ > 0` (c, s: cosine and
    /// sine of the angle between r and n), a closed-form share of φ; θ is integrated with
    /// the midpoint rule in `w = cos^{α+1} θ`, in which the lobe's measure is uniform.
    pub fn new(alpha: f32) -> Self {
        let a = alpha as f64;
        let values = (0..HORIZON_ENTRIES)
            .map(|k| {
                let c = -1.0 + 2.0 * k as f64 / (HORIZON_ENTRIES - 1) as f64;
                let s = (1.0 - c * c).max(0.0).sqrt();
                let sum: f64 = (0..HORIZON_STEPS)
                    .map(|j| {
                        let w = (j as f64 + 0.5) / HORIZON_STEPS as f64;
                        let cos_t = w.powf(1.0 / (a + 1.0));
                        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                        let (p, q) = (c * cos_t, s * sin_t);
                        if q <= p.abs() {
                            if p > 0.0 {
                                1.0
                            } else {
                                0.0
                            }
                        } else {
                            (-p / q).acos() / std::f64::consts::PI
                        }
                    })
                    .sum();
                (sum / HORIZON_STEPS as f64) as f32
            })
            .collect();
        Self { values }
    }

    /// The fraction for `cos = r·n` (clamped to [−1, 1]).
    pub fn fraction(&self, cos: f32) -> f32 {
        let x = (cos.clamp(-1.0, 1.0) + 1.0) * 0.5 * (HORIZON_ENTRIES - 1) as f32;
        let i = (x as usize).min(HORIZON_ENTRIES - 2);
        let t = x - i as f32;
        self.values[i] * (1.0 - t) + self.values[i + 1] * t
    }
}

/// Prepared operators for one mode.
pub struct Shader {
    mode: Mode,
    /// What is done to visibility before shading (see [`crate::filter`]).
    filter: Prepared,
    op: PhongOperator,
    /// Phong's horizon (None for the modes whose lobes are about the normal).
    horizon: Option<HorizonTable>,
    /// Transfer of the unshadowed diffuse lobe about −z (translucency's back side).
    back: ShVec,
}

impl Shader {
    /// Operators for `mode`, visibility unfiltered.
    pub fn new(mode: Mode) -> Result<Self, PrtError> {
        Self::with_filter(mode, Filter::default())
    }

    /// Operators for `mode`, visibility filtered by `filter` before shading.
    pub fn with_filter(mode: Mode, filter: Filter) -> Result<Self, PrtError> {
        let mode = mode.validate()?;
        let op = match mode {
            Mode::Phong { alpha } => PhongOperator::new(alpha),
            _ => PhongOperator::diffuse(),
        };
        // The clamped cosine about −z: zonal, so band l flips sign with (−1)^l.
        let front = PhongOperator::diffuse().apply(&unit_visibility());
        let back = std::array::from_fn(|i| {
            if crate::sh::band_of(i) % 2 == 1 {
                -front[i]
            } else {
                front[i]
            }
        });
        let horizon = match mode {
            Mode::Phong { alpha } => Some(HorizonTable::new(alpha)),
            _ => None,
        };
        Ok(Self {
            mode,
            filter: Prepared::new(filter),
            op,
            horizon,
            back,
        })
    }

    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The visibility filter.
    pub fn filter(&self) -> Filter {
        self.filter.filter()
    }

    /// Applies the visibility filter to `v` (a function on the sphere, in any frame).
    pub fn filter_visibility(&self, v: &mut ShVec) {
        self.filter.apply(v);
    }

    /// The share of a glossy lobe above the horizon for `cos = r·n` (1 for the modes whose
    /// lobes are about the normal).
    pub fn above_horizon(&self, cos: f32) -> f32 {
        self.horizon.as_ref().map_or(1.0, |h| h.fraction(cos))
    }

    /// What the shade of a vertex whose BRDF axis (the normal, or Phong's reflection vector)
    /// is the unit `axis` (world) is made of under `light` (SH radiance, world): `(g, back)`
    /// with `shade = above · v·g + back` for the vertex's visibility `v` in world space and
    /// the horizon share `above` ([`Self::above_horizon`]). With R the rotation of SH
    /// coefficients into a frame whose z is the axis and M the operator, `v·g` is
    /// `(M·R·v)·(R·L)` as [`Self::shade`] computes it, so `g = Rᵀ·M·R·L` (M is symmetric);
    /// the operator is symmetric about z, so every such frame gives the same `g`.
    /// Translucency's share `1 − τ` is folded into `g` and its unshadowed back lobe (about
    /// −axis) is `back`; the other modes have `back = 0`.
    pub fn axis_transfer(&self, axis: Vec3, light: &ShVec) -> (ShVec, f32) {
        let (t, b) = orthonormal_basis(axis);
        let frame = Mat3::from_cols(t, b, axis);
        let local = ShRotation::new(frame.transpose()).apply(light);
        let g = ShRotation::new(frame).apply(&self.op.apply(&local));
        match self.mode {
            Mode::Translucent { transmission } => (
                g.map(|x| (1.0 - transmission) * x),
                transmission * crate::sh::dot(&self.back, &local),
            ),
            _ => (g, 0.0),
        }
    }

    /// What the shade of a zonal lobe is under the constant radiance 1: `(u, back)` such that
    /// a lobe of zonal coefficients `c_l` about the unit axis `s` shades
    /// `above · Σ_l c_l·u_l·P_l(s·axis) + back` for the BRDF axis `axis` (`P_l` the Legendre
    /// polynomials, `above` as in [`Self::axis_transfer`]). The operator turns the constant
    /// into a function symmetric about the axis with zonal coefficients `u_l`, and the
    /// product of two zonal functions integrates to `Σ_l (4π/(2l+1))·a_l·b_l·P_l` of their
    /// axes' cosine (the lobe's expansion, eq. 1, and the addition theorem). Visibility 1 is
    /// the lobe `c = (2√π, 0, 0, 0)`, so the unshadowed shade is `above · 2√π·u_0 + back`.
    pub fn constant_transfer(&self) -> ([f32; crate::sh::BANDS], f32) {
        let unit = unit_visibility();
        let g = self.op.apply(&unit);
        let (front, back) = match self.mode {
            Mode::Translucent { transmission } => (
                1.0 - transmission,
                transmission * crate::sh::dot(&self.back, &unit),
            ),
            _ => (1.0, 0.0),
        };
        (
            std::array::from_fn(|l| front * g[crate::sh::index(l, 0)]),
            back,
        )
    }

    /// Shades every vertex under `lights` (SH radiance in world space, one vector per
    /// channel) seen from `eye` (world; used by Phong). Returns `channels` values per vertex,
    /// interleaved. Runs on all rayon threads. Errors when the visibility, frames and
    /// positions do not all have one entry per vertex.
    pub fn shade(
        &self,
        visibility: Visibility<'_>,
        geometry: ShadingGeometry<'_>,
        lights: &[ShVec],
        eye: Vec3,
    ) -> Result<Vec<f32>, PrtError> {
        let ch = lights.len();
        let n = geometry.positions.len();
        let vis_len = match visibility {
            Visibility::Unshadowed => n,
            Visibility::Projected(v) => v.len(),
            Visibility::Model(m, raw) if raw.len() == m.output_len() => m.vertices,
            Visibility::Model(..) => usize::MAX,
        };
        if geometry.frames.len() != n || vis_len != n {
            return Err(PrtError::Parameter(format!(
                "shading {n} vertices with {} frames and visibility for {}",
                geometry.frames.len(),
                if vis_len == usize::MAX {
                    "a mismatched model output".to_string()
                } else {
                    vis_len.to_string()
                }
            )));
        }
        let mut out = vec![0.0f32; n * ch];
        let linear = orthonormalised(Mat3::from(geometry.transform.matrix3));
        let unit = unit_visibility();
        out.par_chunks_mut(ch.max(1) * 256)
            .enumerate()
            .for_each_init(Vec::new, |lobes: &mut Vec<ZhLobe>, (c, chunk)| {
                for (k, slot) in chunk.chunks_mut(ch.max(1)).enumerate() {
                    let v = c * 256 + k;
                    let local_to_world = linear * geometry.frames[v];
                    // The BRDF frame in local coordinates (identity for the normal) and the
                    // share of the lobe above the horizon.
                    let (brdf, above) = match &self.horizon {
                        Some(horizon) => {
                            let p = geometry.transform.transform_point3(geometry.positions[v]);
                            let n = local_to_world.z_axis;
                            let wo = (eye - p).normalize_or(n);
                            let r = 2.0 * n.dot(wo) * n - wo;
                            let r_local = local_to_world.transpose() * r;
                            let (t, b) = orthonormal_basis(r_local);
                            (
                                Some(Mat3::from_cols(t, b, r_local)),
                                horizon.fraction(n.dot(wo)),
                            )
                        }
                        None => (None, 1.0),
                    };
                    // Visibility in the BRDF frame.
                    let mut vis: ShVec = match (visibility, brdf) {
                        (Visibility::Unshadowed, _) => unit,
                        (Visibility::Projected(sh), None) => sh[v],
                        (Visibility::Projected(sh), Some(g)) => {
                            ShRotation::new(g.transpose()).apply(&sh[v])
                        }
                        (Visibility::Model(model, raw), g) => {
                            model.lobes_of(raw, v, lobes);
                            let mut out = [0.0; COEFFS];
                            for l in lobes.iter() {
                                let axis = g.map_or(l.axis, |g| g.transpose() * l.axis);
                                ZhLobe { axis, ..*l }.add_to(&mut out);
                            }
                            out
                        }
                    };
                    if !matches!(visibility, Visibility::Unshadowed) {
                        self.filter.apply(&mut vis);
                    }
                    let transfer = self.op.apply(&vis);
                    let frame = brdf.map_or(local_to_world, |g| local_to_world * g);
                    let to_frame = ShRotation::new(frame.transpose());
                    for (o, light) in slot.iter_mut().zip(lights) {
                        let l = to_frame.apply(light);
                        let front = crate::sh::dot(&transfer, &l);
                        *o = match self.mode {
                            Mode::Translucent { transmission } => {
                                (1.0 - transmission) * front
                                    + transmission * crate::sh::dot(&self.back, &l)
                            }
                            _ => above * front,
                        };
                    }
                }
            });
        Ok(out)
    }
}

/// The rotation part of a linear map with uniform scale (columns normalised).
pub fn orthonormalised(m: Mat3) -> Mat3 {
    let x = m.x_axis.normalize_or(Vec3::X);
    let y = (m.y_axis - x * x.dot(m.y_axis)).normalize_or(Vec3::Y);
    Mat3::from_cols(x, y, x.cross(y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zonal::ZhLobe;

    fn one_vertex(frame: Mat3) -> (Vec<Vec3>, Vec<Mat3>) {
        (vec![Vec3::ZERO], vec![frame])
    }

    #[test]
    fn unshadowed_diffuse_under_a_uniform_sky_is_the_sky_radiance() {
        let (p, f) = one_vertex(Mat3::from_rotation_x(0.7));
        let geometry = ShadingGeometry {
            positions: &p,
            frames: &f,
            transform: Affine3A::IDENTITY,
        };
        let sky = unit_visibility(); // radiance 1 everywhere
        let s = Shader::new(Mode::Diffuse).unwrap();
        let v = s
            .shade(Visibility::Unshadowed, geometry, &[sky], Vec3::Z)
            .unwrap()[0];
        assert!((v - 1.0).abs() < 1e-4, "{v}");
        // Phong: all of the sky when the reflection vector is the normal, else the share of
        // the lobe above the horizon.
        let s = Shader::new(Mode::Phong { alpha: 20.0 }).unwrap();
        let n = f[0].z_axis;
        for (eye, expected) in [
            (n * 4.0, 1.0),
            (
                Vec3::new(0.0, 3.0, 1.0),
                HorizonTable::new(20.0).fraction(n.dot(Vec3::new(0.0, 3.0, 1.0).normalize())),
            ),
        ] {
            let v = s
                .shade(Visibility::Unshadowed, geometry, &[sky], eye)
                .unwrap()[0];
            assert!((v - expected).abs() < 1e-3, "{v} vs {expected}");
        }
    }

    #[test]
    fn model_lobes_and_projected_sh_shade_alike() {
        // One lobe as "model" output and its SH expansion as "projected" visibility.
        let lobe = ZhLobe {
            axis: Vec3::new(0.3, 0.2, 0.9).normalize(),
            coeffs: [1.5, 1.2, 0.6, 0.2],
        };
        let model = PoseModel {
            character: "t".into(),
            vertices: 1,
            joints: 0,
            lobes: 1,
            active: vec![],
            weights: vec![],
            limits: Default::default(),
        };
        let raw = [lobe.axis.x, lobe.axis.y, lobe.axis.z, 1.5, 1.2, 0.6, 0.2];
        let sh = [lobe.to_sh()];
        let (p, f) = one_vertex(Mat3::from_rotation_y(0.4));
        let geometry = ShadingGeometry {
            positions: &p,
            frames: &f,
            transform: Affine3A::from_rotation_z(0.3),
        };
        let light: ShVec = std::array::from_fn(|i| 1.0 / (1.0 + i as f32));
        for mode in [
            Mode::Diffuse,
            Mode::Phong { alpha: 8.0 },
            Mode::Translucent { transmission: 0.3 },
        ] {
            let s = Shader::new(mode).unwrap();
            let eye = Vec3::new(1.0, 2.0, 3.0);
            let a = s
                .shade(Visibility::Model(&model, &raw), geometry, &[light], eye)
                .unwrap()[0];
            let b = s
                .shade(Visibility::Projected(&sh), geometry, &[light], eye)
                .unwrap()[0];
            assert!(
                (a - b).abs() < 1e-4 * a.abs().max(1.0),
                "{mode:?}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn horizon_fraction_has_its_closed_values_and_matches_sampling() {
        for alpha in [1.0, 16.0, 100.0] {
            let h = HorizonTable::new(alpha);
            // r = n: the whole lobe is above; r in the plane: half; r = −n: none.
            assert!((h.fraction(1.0) - 1.0).abs() < 1e-3, "{alpha}");
            assert!((h.fraction(0.0) - 0.5).abs() < 1e-3, "{alpha}");
            assert!(h.fraction(-1.0).abs() < 1e-3, "{alpha}");
            for c in [0.1f32, 0.35, 0.8] {
                // Mirroring r through the tangent plane swaps above and below.
                assert!((h.fraction(c) + h.fraction(-c) - 1.0).abs() < 2e-3);
            }
        }
        // Against Monte Carlo sampling of the lobe (200 000 samples: σ ≈ 0.0011).
        let alpha = 4.0f32;
        let h = HorizonTable::new(alpha);
        let c = 0.3f32;
        let r = Vec3::new((1.0 - c * c).sqrt(), 0.0, c);
        let (t, b) = orthonormal_basis(r);
        let n = 200_000;
        let above = (0..n)
            .filter(|&i| {
                let (u1, u2) = psao_trace::ao::sample_2d(5, 0, i);
                let cos = (1.0 - u1).powf(1.0 / (alpha + 1.0));
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let (sp, cp) = (std::f32::consts::TAU * u2).sin_cos();
                (t * (sin * cp) + b * (sin * sp) + r * cos).z > 0.0
            })
            .count() as f32
            / n as f32;
        assert!(
            (above - h.fraction(c)).abs() < 5e-3,
            "{above} vs {}",
            h.fraction(c)
        );
    }

    #[test]
    fn bad_parameters_are_refused() {
        assert!(Shader::new(Mode::Phong { alpha: 0.5 }).is_err());
        assert!(Shader::new(Mode::Translucent { transmission: 2.0 }).is_err());
    }
}
