//! The ray tracer as the [`RayCaster`] of the camera path generator
//! ([`psao_scene::path_gen`]): closest hits, their side and whether their material is
//! non-diffuse.

use glam::Vec3;
use psao_scene::{
    generate_paths, CameraPath, CastHit, Material, PathGenConfig, PathGenError, RayCaster, Scene,
};
use psao_trace::surface::Surfaces;
use psao_trace::{Backend, GeometryMode, Ray, TraceError, Tracer};

/// Why [`generate_traced_paths`] made no paths.
#[derive(Debug, thiserror::Error)]
pub enum TracedPathsError {
    /// The tracer could not be built.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// The generator failed.
    #[error(transparent)]
    Paths(#[from] PathGenError),
}

/// `count` camera paths through `scene` for `seed` ([`generate_paths`]), cast with a new
/// primary-ray tracer of `backend`.
pub fn generate_traced_paths(
    scene: &Scene,
    backend: Backend,
    config: &PathGenConfig,
    count: usize,
    seed: u64,
) -> Result<Vec<CameraPath>, TracedPathsError> {
    let tracer = Tracer::new(backend, scene, GeometryMode::Primary)?;
    Ok(generate_paths(
        scene,
        &TracerCaster::new(scene, &tracer),
        config,
        count,
        seed,
    )?)
}

/// Casts the generator's rays with a [`Tracer`] of `scene` (any geometry mode).
pub struct TracerCaster<'a> {
    tracer: &'a Tracer,
    surfaces: Surfaces<'a>,
}

impl<'a> TracerCaster<'a> {
    /// A caster over `tracer`, built for `scene` at its stored transforms.
    pub fn new(scene: &'a Scene, tracer: &'a Tracer) -> Self {
        Self {
            tracer,
            surfaces: Surfaces::new(scene),
        }
    }
}

impl RayCaster for TracerCaster<'_> {
    fn cast(&self, origin: Vec3, dir: Vec3, max: f32) -> Option<CastHit> {
        let ray = Ray::new(origin, dir, max);
        let mut hit = [None];
        self.tracer.intersect(&[ray], &mut hit);
        let hit = hit[0]?;
        let scene = self.surfaces.scene();
        // A hit on a degenerate triangle has no side: count it as a front-facing surface.
        let (front, material) = self
            .surfaces
            .surface(&ray, &hit)
            .map_or((true, None), |s| (s.front, Some(s.material)));
        Some(CastHit {
            t: hit.t,
            front,
            non_diffuse: material
                .and_then(|m| scene.materials.get(m))
                .is_some_and(Material::is_non_diffuse),
        })
    }
}
