//! Environment lighting: an equirectangular (latitude–longitude) radiance map (the
//! convention of [`psao_scene::LatLongMap`]), its order-4 SH projection per colour channel,
//! and rotation about the vertical axis.

use glam::{Mat3, Vec3};
use psao_scene::LatLongMap;

use crate::rotation::ShRotation;
use crate::sh::{self, ShVec, COEFFS};
use crate::PrtError;

/// Rec. 709 luminance weights.
pub const LUMINANCE: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// A linear-radiance latitude–longitude map (the scene crate's map, with the SH projection
/// relighting needs).
#[derive(Clone, Debug)]
pub struct EnvMap {
    map: LatLongMap,
}

impl From<LatLongMap> for EnvMap {
    fn from(map: LatLongMap) -> Self {
        Self { map }
    }
}

impl EnvMap {
    /// A map of `width × height` RGB pixels, row-major from the top; negative or
    /// non-finite values are refused.
    pub fn new(width: usize, height: usize, pixels: Vec<[f32; 3]>) -> Result<Self, PrtError> {
        let map = LatLongMap::new(width, height, pixels).map_err(PrtError::Parameter)?;
        Ok(Self { map })
    }

    /// The direction at the centre of pixel (x, y).
    pub fn direction(&self, x: usize, y: usize) -> Vec3 {
        self.map.direction(x, y)
    }

    /// Radiance in direction `d` (unit), nearest pixel.
    pub fn radiance(&self, d: Vec3) -> [f32; 3] {
        self.map.radiance(d)
    }

    /// Order-4 SH projection of each channel (pixel solid angles `Δφ Δθ sin θ`).
    pub fn project(&self) -> ShLighting {
        let mut rgb = [[0.0f64; COEFFS]; 3];
        let (width, height) = (self.map.width(), self.map.height());
        let dphi = std::f64::consts::TAU / width as f64;
        let dtheta = std::f64::consts::PI / height as f64;
        for y in 0..height {
            let theta = (y as f64 + 0.5) * dtheta;
            let w = dphi * dtheta * theta.sin();
            for x in 0..width {
                let basis = sh::eval_f64(self.direction(x, y).as_dvec3().normalize());
                let p = self.map.pixels()[y * width + x];
                for (c, acc) in rgb.iter_mut().enumerate() {
                    let v = w * p[c] as f64;
                    for (a, b) in acc.iter_mut().zip(&basis) {
                        *a += v * b;
                    }
                }
            }
        }
        ShLighting {
            rgb: rgb.map(|c| c.map(|x| x as f32)),
        }
    }
}

/// Radiance arriving from a world direction (what the Monte Carlo reference integrates).
pub trait Radiance: Sync {
    /// Linear RGB radiance arriving from unit direction `d`.
    fn radiance_from(&self, d: Vec3) -> [f32; 3];
}

impl Radiance for EnvMap {
    fn radiance_from(&self, d: Vec3) -> [f32; 3] {
        self.radiance(d)
    }
}

/// The band-limited lighting the run time uses, evaluated per direction (it may be
/// negative where the order-4 projection rings).
impl Radiance for ShLighting {
    fn radiance_from(&self, d: Vec3) -> [f32; 3] {
        let y = sh::eval(d);
        self.rgb.map(|c| sh::dot(&c, &y))
    }
}

/// SH environment lighting, one vector per colour channel (world frame).
#[derive(Clone, Debug, PartialEq)]
pub struct ShLighting {
    /// Red, green and blue radiance coefficients.
    pub rgb: [ShVec; 3],
}

impl ShLighting {
    /// The luminance channel.
    pub fn luminance(&self) -> ShVec {
        std::array::from_fn(|i| (0..3).map(|c| LUMINANCE[c] * self.rgb[c][i]).sum())
    }

    /// The lighting turned by `angle` radians about +Y.
    pub fn rotated_about_up(&self, angle: f32) -> Self {
        let r = ShRotation::new(Mat3::from_rotation_y(angle));
        Self {
            rgb: self.rgb.map(|c| r.apply(&c)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_sky_projects_to_a_constant() {
        let env = EnvMap::new(64, 32, vec![[1.0, 2.0, 0.5]; 64 * 32]).unwrap();
        let l = env.project();
        let c0 = 2.0 * std::f32::consts::PI.sqrt();
        for (c, scale) in [1.0, 2.0, 0.5].iter().enumerate() {
            assert!((l.rgb[c][0] - c0 * scale).abs() < 1e-3 * c0 * scale);
            assert!(l.rgb[c][1..].iter().all(|v| v.abs() < 1e-2));
        }
    }

    #[test]
    fn lookup_and_direction_agree() {
        let pixels = (0..16 * 8).map(|i| [i as f32, 0.0, 0.0]).collect();
        let env = EnvMap::new(16, 8, pixels).unwrap();
        for (x, y) in [(0, 0), (5, 3), (15, 7)] {
            assert_eq!(env.radiance(env.direction(x, y))[0], (y * 16 + x) as f32);
        }
    }

    #[test]
    fn sky_above_projects_to_an_upward_lobe() {
        // Light only from the upper half: band-1 coefficient along y is positive, others 0.
        let (w, h) = (64, 32);
        let pixels = (0..w * h)
            .map(|i| if i / w < h / 2 { [1.0; 3] } else { [0.0; 3] })
            .collect();
        let l = EnvMap::new(w, h, pixels).unwrap().project().luminance();
        assert!(l[1] > 0.5);
        assert!(l[2].abs() < 1e-2 && l[3].abs() < 1e-2);
    }

    #[test]
    fn sh_lighting_evaluates_its_expansion() {
        let l = ShLighting {
            rgb: [
                crate::shade::unit_visibility(),
                [0.0; COEFFS],
                std::array::from_fn(|i| if i == 2 { 1.0 } else { 0.0 }),
            ],
        };
        let d = Vec3::new(0.3, -0.4, 0.866).normalize();
        let v = l.radiance_from(d);
        assert!((v[0] - 1.0).abs() < 1e-5 && v[1] == 0.0);
        // y_10 = √(3/4π)·z in this basis.
        assert!((v[2] - (3.0 / (4.0 * std::f32::consts::PI)).sqrt() * d.z).abs() < 1e-5);
    }

    #[test]
    fn rejects_bad_maps() {
        assert!(EnvMap::new(2, 2, vec![[0.0; 3]; 3]).is_err());
        assert!(EnvMap::new(1, 1, vec![[f32::NAN, 0.0, 0.0]]).is_err());
    }
}
