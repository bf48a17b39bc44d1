//! A volume placed in a scene as a participating medium for AO rays
//! ([`psao_trace::ao::Medium`]): placement (scale, rotation, translation), one frame, and a
//! density scale turning normalised density into extinction per metre.

use crate::error::{Result, VolumeError};
use crate::grid::GridClass;
use crate::rng::Rng;
use crate::sample::Sampler;
use crate::trace::{level_set_hit, tentative_collisions, IndexRay};
use crate::volume::Volume;
use glam::{Quat, Vec3};
use psao_trace::ao::{Medium, MediumSampler};

/// Where a volume sits in the scene: a point `v` of the volume's own world space goes to
/// `translation + rotation · (scale ⊙ v)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Offset after rotation.
    pub translation: Vec3,
    /// Rotation after scaling.
    pub rotation: Quat,
    /// Per-axis scale (positive).
    pub scale: Vec3,
}

impl Default for Placement {
    /// The identity.
    fn default() -> Self {
        Placement {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

/// Weights of ratio tracking below this are continued with Russian roulette (probability ½,
/// weight doubled), so dense media end rays early without bias.
const ROULETTE_WEIGHT: f32 = 0.05;

/// One frame of a volume placed in the scene, with extinction σ = `density_scale` × density /
/// (the volume's largest value): `density_scale` is the extinction per metre (scene unit) at
/// the densest voxel. Level sets are opaque inside (`density_scale` is unused).
pub struct PlacedVolume {
    volume: Volume,
    frame: usize,
    /// Scene world to the placement's local frame (before rotation): `inverse_rotation · (p − translation)`.
    inverse_rotation: Quat,
    translation: Vec3,
    /// Local-frame box of the frame's leaves (what HDDA can visit).
    lo: Vec3,
    hi: Vec3,
    /// Extinction per unit of stored density.
    sigma_per_value: f32,
}

impl std::fmt::Debug for PlacedVolume {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlacedVolume")
            .field("class", &self.volume.class)
            .field("frame", &self.frame)
            .field("bricks", &self.volume.pool.len())
            .field("local_bounds", &(self.lo, self.hi))
            .field("sigma_per_value", &self.sigma_per_value)
            .finish()
    }
}

impl PlacedVolume {
    /// Places frame `frame` of `volume` with `placement`; `density_scale` is the extinction
    /// per metre at the volume's largest stored value.
    pub fn new(
        mut volume: Volume,
        frame: usize,
        placement: Placement,
        density_scale: f32,
    ) -> Result<PlacedVolume> {
        let p = placement;
        if frame >= volume.frames() {
            return Err(VolumeError::InvalidParameter(format!(
                "frame {frame} of a {}-frame volume",
                volume.frames()
            )));
        }
        if !(p.scale.is_finite() && p.scale.cmpgt(Vec3::ZERO).all()) {
            return Err(VolumeError::InvalidParameter(format!(
                "placement scale must be positive and finite, got {}",
                p.scale
            )));
        }
        if !(p.translation.is_finite() && p.rotation.is_finite() && p.rotation.length() > 0.0) {
            return Err(VolumeError::InvalidParameter(
                "placement translation and rotation must be finite".into(),
            ));
        }
        if !(density_scale.is_finite() && density_scale >= 0.0) {
            return Err(VolumeError::InvalidParameter(format!(
                "density scale must be finite and >= 0, got {density_scale}"
            )));
        }
        // Fold the scale into the index-to-world map: index → local frame.
        let s = p.scale.as_dvec3();
        volume.transform.scale *= s;
        volume.transform.translation *= s;
        let (ilo, ihi) = volume.index_bounds(frame);
        let a = volume.transform.index_to_world(ilo.as_vec3());
        let b = volume.transform.index_to_world(ihi.as_vec3());
        let max = volume.pool.hi;
        let sigma_per_value = if max > 0.0 { density_scale / max } else { 0.0 };
        Ok(PlacedVolume {
            frame,
            inverse_rotation: p.rotation.normalize().inverse(),
            translation: p.translation,
            lo: a.min(b),
            hi: a.max(b),
            sigma_per_value,
            volume,
        })
    }

    /// The placed volume (its transform maps index space to the placement's local frame).
    pub fn volume(&self) -> &Volume {
        &self.volume
    }

    /// World-space axis-aligned bounds of the placed frame.
    pub fn world_bounds(&self) -> (Vec3, Vec3) {
        let rotation = self.inverse_rotation.inverse();
        let mut lo = Vec3::INFINITY;
        let mut hi = Vec3::NEG_INFINITY;
        for c in 0..8 {
            let corner = Vec3::select(
                glam::BVec3::new(c & 1 != 0, c & 2 != 0, c & 4 != 0),
                self.hi,
                self.lo,
            );
            let w = self.translation + rotation * corner;
            lo = lo.min(w);
            hi = hi.max(w);
        }
        (lo, hi)
    }

    /// Local-frame ray of a world ray, if its first `length` units can touch the leaves.
    #[inline]
    fn local_ray(&self, origin: Vec3, dir: Vec3, length: f32) -> Option<(Vec3, Vec3)> {
        let o = self.inverse_rotation * (origin - self.translation);
        let d = self.inverse_rotation * dir;
        let inv = Vec3::ONE / d;
        let a = (self.lo - o) * inv;
        let b = (self.hi - o) * inv;
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(length);
        (t0 <= t1).then_some((o, d))
    }
}

impl Medium for PlacedVolume {
    fn sampler(&self) -> Box<dyn MediumSampler + '_> {
        Box::new(PlacedSampler {
            placed: self,
            sampler: None,
        })
    }
}

/// Per-worker sampler of a [`PlacedVolume`]; the brick cache is made on the first ray that
/// reaches the volume, so workers whose rays all miss it allocate nothing.
struct PlacedSampler<'a> {
    placed: &'a PlacedVolume,
    sampler: Option<Sampler<'a>>,
}

impl MediumSampler for PlacedSampler<'_> {
    fn transmitted_length(&mut self, origin: Vec3, dir: Vec3, length: f32, stream: u64) -> f32 {
        let p = self.placed;
        let Some((o, d)) = p.local_ray(origin, dir, length) else {
            return length;
        };
        let s = self
            .sampler
            .get_or_insert_with(|| Sampler::new(&p.volume, p.frame));
        let ray = IndexRay::from_world(&p.volume, o, d);
        match p.volume.class {
            GridClass::Fog => {
                let mut rng = Rng::new(stream, 0);
                transmitted_length(s, &ray, length, p.sigma_per_value, &mut rng)
            }
            GridClass::LevelSet => {
                level_set_hit(s, &ray, length).map_or(length, |t| t.clamp(0.0, length))
            }
        }
    }
}

/// Unbiased estimate of ∫₀ᴸ T(s) ds along `ray` (extinction `sigma_per_value` × trilinear
/// density) by ratio tracking with the per-L3 majorants: tentative collisions are drawn with
/// the majorant μ of each node, and the running weight W = Π (1 − σ/μ) over the collisions
/// before s is an unbiased estimate of T(s) for every s at once, so ∫ W ds (a sum of
/// weight × gap) is an unbiased estimate of the integral. Empty nodes are skipped by HDDA;
/// small weights are continued by Russian roulette.
pub fn transmitted_length(
    s: &mut Sampler,
    ray: &IndexRay,
    length: f32,
    sigma_per_value: f32,
    rng: &mut Rng,
) -> f32 {
    let (mut weight, mut integral, mut last) = (1.0f32, 0.0f32, 0.0f32);
    if sigma_per_value > 0.0 {
        tentative_collisions(s, ray, length, sigma_per_value, rng, |t, sigma, mu, rng| {
            integral += weight * (t - last);
            last = t;
            weight *= (1.0 - sigma / mu).max(0.0);
            if weight < ROULETTE_WEIGHT {
                if rng.next_f32() < 0.5 {
                    weight = 0.0;
                    return false;
                }
                weight *= 2.0;
            }
            true
        });
    }
    (integral + weight * (length - last).max(0.0)).clamp(0.0, length)
}
