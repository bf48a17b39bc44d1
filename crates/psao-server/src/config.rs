//! Server parameters and their defaults.

use psao_trace::Backend;

use crate::{Invalidation, ServerError};

/// When a point's published record is resent (DESIGN §3 "Server update").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// Resend when the AO estimate differs from the published AO by more than this.
    pub ao: f32,
    /// Resend when the cosine between current and published normal drops below this.
    pub normal_cos: f32,
    /// Resend when the position moved by more than this many quantisation steps (cell / 32)
    /// along some axis.
    pub position_steps: f32,
    /// With lighting: resend when the irradiance moved perceptibly from the published one
    /// (a Weber fraction, [`psao_points::irradiance::irradiance_changed`]).
    pub irradiance: f32,
}

impl Default for Thresholds {
    /// The paper's values: 8/255 AO, cosine 0.6, 3 position steps; irradiance 8/255 of its
    /// luminance.
    fn default() -> Self {
        Self {
            ao: 8.0 / 255.0,
            normal_cos: 0.6,
            position_steps: 3.0,
            irradiance: 8.0 / 255.0,
        }
    }
}

/// Diffuse irradiance at the points besides their AO (DESIGN §12, docs/LIGHTING.md): light
/// paths of [`psao_trace::gi::DiffuseLighting`] traced from each selected point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LightingConfig {
    /// Indirect bounces per path (a fixed depth, see [`psao_trace::gi`]).
    pub bounces: u32,
    /// Light paths traced for a selected point in one frame, beside its
    /// [`ServerConfig::rays_per_point`] AO rays.
    pub paths_per_point: u32,
    /// Whether the points also carry the direct light of suns and point lights. Off by
    /// default: their sharp shadows need more resolution than the points have, so clients
    /// render that light with shadow maps and the points carry only its bounces (DESIGN §12,
    /// [`psao_trace::gi::DiffuseLighting::without_sharp_direct`]).
    pub sharp_direct: bool,
    /// Paths a published irradiance record pools at least while the points around it are
    /// young: its pooling reach widens beyond the clients' reconstruction radius, nearest
    /// coplanar points first, until it holds this many paths, at most to
    /// [`crate::POOL_MAX_REACH`] reconstruction radii (docs/LIGHTING.md, "Pooling"). 0 keeps
    /// the reach at the reconstruction radius.
    pub pool_paths: u32,
}

/// Most bounces a server path may take (each costs a closest-hit ray and a shadow ray per
/// light per path).
pub const MAX_BOUNCES: u32 = 8;
/// Largest `max_samples`: a point's AO sample count is kept in 16 bits.
pub const MAX_SAMPLES_LIMIT: u32 = u16::MAX as u32;

impl Default for LightingConfig {
    /// One bounce (the bounce of the sun and of small lights), 4 paths per point and frame,
    /// the direct light of suns and point lights left to the clients, records pooling at
    /// least 64 paths: the paths one point converges with at the server's defaults (256 AO
    /// samples, 16 rays and 4 paths per frame), so that a young point's record rests on as
    /// many paths as a converged point's own mean.
    fn default() -> Self {
        Self {
            bounces: 1,
            paths_per_point: 4,
            sharp_direct: false,
            pool_paths: 64,
        }
    }
}

/// Everything that configures a [`crate::Server`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServerConfig {
    /// Points per unit area after elimination (DESIGN §3: 1024).
    pub density: f32,
    /// AO ray length; `None` uses the scene's `ao_radius`.
    pub ao_radius: Option<f32>,
    /// Rays traced for a selected point in one frame.
    pub rays_per_point: u32,
    /// Most rays traced in one server frame.
    pub ray_budget: u64,
    /// Samples after which a point counts as converged and is no longer traced (1 to
    /// [`MAX_SAMPLES_LIMIT`]).
    pub max_samples: u32,
    /// Widening of the view frustum: the tangents of both half-angles are scaled by
    /// `1 + frustum_margin` (0.2 = 20 % wider).
    pub frustum_margin: f32,
    /// Publishing thresholds.
    pub thresholds: Thresholds,
    /// Drop generated points buried inside closed geometry before they are stored (see
    /// `bury.rs`: [`crate::BURIAL_MIN_INSIDE`] of [`crate::BURIAL_RAYS`] unbounded rays hit
    /// the back side of single-sided surfaces), so they take no cell capacity and never
    /// blend into visible surfaces.
    pub cull_buried: bool,
    /// Which points restart their AO when something moved.
    pub invalidation: Invalidation,
    /// Seed of point generation, the burial test and AO sampling.
    pub seed: u64,
    /// Ray-tracing backend.
    pub backend: Backend,
    /// Adaptive point placement (issue 15 item 4): the density of the points with the most
    /// near-field occlusion relative to open areas, at the same total count (1 = uniform
    /// placement, the default; see `start_points.rs` for the signal).
    pub adaptive_boost: f32,
    /// Diffuse irradiance at the points (`None`: AO only, the default).
    pub lighting: Option<LightingConfig>,
}

impl Default for ServerConfig {
    /// Density 1024, the scene's AO radius, 16 rays per point and frame, 2 M rays per
    /// frame, 256 samples to converge, 20 % frustum margin, paper thresholds, buried points
    /// culled, proximity invalidation, seed 0, the default backend, AO only.
    fn default() -> Self {
        Self {
            density: psao_points::DEFAULT_DENSITY,
            ao_radius: None,
            rays_per_point: 16,
            ray_budget: 2_000_000,
            max_samples: 256,
            frustum_margin: 0.2,
            thresholds: Thresholds::default(),
            cull_buried: true,
            invalidation: Invalidation::Proximity,
            seed: 0,
            backend: Backend::default(),
            adaptive_boost: 1.0,
            lighting: None,
        }
    }
}

impl ServerConfig {
    /// Check the values that point generation and tracing do not check themselves.
    pub(crate) fn validate(&self) -> Result<(), ServerError> {
        let bad = |what: &str| Err(ServerError::InvalidConfig(what.to_string()));
        if self.rays_per_point == 0 {
            return bad("rays_per_point must be at least 1");
        }
        if self.max_samples == 0 {
            return bad("max_samples must be at least 1");
        }
        if self.max_samples > MAX_SAMPLES_LIMIT {
            return bad(&format!("max_samples must be at most {MAX_SAMPLES_LIMIT}"));
        }
        if !(self.frustum_margin.is_finite() && self.frustum_margin >= 0.0) {
            return bad("frustum_margin must be finite and >= 0");
        }
        if !(self.adaptive_boost.is_finite() && self.adaptive_boost >= 1.0) {
            return bad("adaptive_boost must be finite and >= 1");
        }
        if let Some(l) = &self.lighting {
            if l.paths_per_point == 0 {
                return bad("lighting paths_per_point must be at least 1");
            }
            if l.bounces > MAX_BOUNCES {
                return bad(&format!("lighting bounces must be at most {MAX_BOUNCES}"));
            }
        }
        let t = &self.thresholds;
        let finite = [t.ao, t.normal_cos, t.position_steps, t.irradiance];
        if !finite.iter().all(|v| v.is_finite()) {
            return bad("thresholds must be finite");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_samples_is_bounded_by_the_counts_width() {
        let with = |max_samples| ServerConfig {
            max_samples,
            ..ServerConfig::default()
        };
        assert!(with(1).validate().is_ok());
        assert!(with(MAX_SAMPLES_LIMIT).validate().is_ok());
        assert!(matches!(
            with(MAX_SAMPLES_LIMIT + 1).validate(),
            Err(ServerError::InvalidConfig(_))
        ));
        assert!(matches!(
            with(0).validate(),
            Err(ServerError::InvalidConfig(_))
        ));
    }
}
