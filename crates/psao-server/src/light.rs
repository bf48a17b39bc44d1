//! Diffuse irradiance at the points (DESIGN §12, docs/LIGHTING.md): beside its AO, a point
//! selected in a server frame takes [`LightingConfig::paths_per_point`] light paths of
//! [`DiffuseLighting`] (environment, lights with shadow rays, `bounces` indirect bounces),
//! accumulated into a running linear RGB mean.
//!
//! By default the points leave out the direct light of suns and point lights (clients render
//! it with shadow maps) and keep its bounces ([`LightingConfig::sharp_direct`]).
//!
//! # One selection, one budget
//!
//! AO and irradiance share the point set, the selection and the ray budget: a point's
//! *progress* is the smaller of its AO samples and its light paths counted in AO samples (a
//! path is worth `rays_per_point / paths_per_point` of them), so the tracer's "fewest samples
//! first" serves whichever of the two lags, a point whose irradiance was invalidated is
//! selected again even when its AO is converged, and a point counts as converged when both
//! are. Each selected point is charged [`charge`] rays: its AO rays plus the most rays its
//! paths can trace.
//!
//! # Pooling
//!
//! A point's published irradiance is the mean of the paths of the points around it, within
//! the clients' reconstruction radius, that lie in its tangent plane
//! ([`InstanceState::pooled_irradiance`]), weighted by their paths: diffuse irradiance
//! varies little over that distance (a few point spacings; the sharp shadows of suns and
//! point lights are the clients'), while one point's few paths are noisy, so neighbouring
//! coplanar points share their samples. Points on another plane (a crease, a step, the
//! other side of a thin wall) keep theirs apart. Each point still takes its own paths and
//! converges as before; what it accumulates (`Server::irradiance`) is its own.
//!
//! While the points around are young (a cold start, a view turned to new surfaces: a few
//! paths each, and most neighbours not traced yet) that radius holds few paths. The reach
//! then widens, nearest coplanar points first, until the pool holds
//! [`LightingConfig::pool_paths`] paths (by default those a converged point averages), at
//! most to [`POOL_MAX_REACH`] reconstruction radii; as paths accumulate it shrinks back to
//! the reconstruction radius. A young record trades some blur of the irradiance over a few
//! point spacings for the noise of a handful of paths, which is the larger error; the same
//! plane test bounds the reach on curved or creased geometry.
//!
//! # Noise
//!
//! A rectangle light is sampled at one point of its area per path vertex, weighted by
//! `cos θ · cos θ' · area / d²`: at vertices near a panel (a beam beside it, a wall under
//! it) a sample can be hundreds of times its mean, and with a few paths per point such
//! samples show as bright blotches that take seconds to average out. The points' paths cap
//! each rectangle sample at `π ×` its radiance, the irradiance of an emitter filling the
//! hemisphere, above which no expectation lies
//! ([`DiffuseLighting::with_clamped_rect_samples`]; the per-pixel reference does not).
//!
//! # Invalidation
//!
//! Moving geometry restarts a point's irradiance exactly as its AO (the proximity rule of
//! [`crate::Invalidation`], the same kept fraction). A sun whose direction follows keys
//! relights the points once it turned by more than [`SUN_TOLERANCE_DEG`] from the direction
//! the points' paths were traced with: without bounces the points facing it before or
//! after (none when the points leave its direct light to the clients); with bounces every
//! point (its bounce may reach any of them). Paths are always
//! traced with the lights of the last relighting, so the samples of a point agree.

use glam::{UVec3, Vec3};
use psao_points::irradiance::{irradiance_changed, pack_rgb9e5, unpack_rgb9e5};
use psao_points::DEFAULT_INTERPOLATION_FACTOR;
use psao_scene::{Light, LightShape, Scene, ScenePose};
use psao_trace::gi::DiffuseLighting;
use psao_trace::Tracer;
use rayon::prelude::*;

use crate::instance::{InstanceState, NONE};
use crate::trace::{sample_key, Candidate};
use crate::LightingConfig;

/// Angle in degrees a keyed sun turns before it relights the points. The direct light of
/// an unshadowed surface changes by at most the angle in radians (≤ 1.75 % of the sun's
/// irradiance, below the 8/255 ≈ 3.1 % the AO threshold allows), and the shadow edge of an
/// occluder 2 m away moves by 3.5 cm, about the spacing of the points at the default
/// density: finer turns would change what the points can show by less than they resolve.
pub const SUN_TOLERANCE_DEG: f32 = 1.0;

/// Cosine of the largest angle between the normals of two points whose paths pool (about
/// 26°).
pub const POOL_COS: f32 = 0.9;

/// Largest offset, in Poisson radii, of a point from another's tangent plane for their
/// paths to pool.
pub const POOL_PLANE: f32 = 0.5;

/// Largest reach, in reconstruction radii (Poisson radius × interpolation factor, the
/// clients' kernel), that a young point's pooling widens to while it holds fewer than
/// [`LightingConfig::pool_paths`] paths: about 5.7 point spacings (2 Poisson radii each),
/// 16 times the area (about 116 coplanar points against 7 within the reconstruction
/// radius), so that even a frame that traces one point in sixteen finds several.
pub const POOL_MAX_REACH: f32 = 4.0;

/// Irradiance accumulators of one instance's points.
pub(crate) struct LightSums {
    /// Sum of the irradiance samples (linear RGB) and their number, per point.
    pub sum: Vec<Vec3>,
    pub count: Vec<u32>,
    /// Last published irradiance record (RGB9E5) per point.
    pub published: Vec<u32>,
    /// AO rays and light paths per selected point and frame: the rate between the counts.
    rays_per_point: u32,
    paths_per_point: u32,
    /// Paths a published record pools at least, reach permitting
    /// ([`LightingConfig::pool_paths`]).
    pool_paths: u32,
}

impl LightSums {
    /// Empty accumulators for `n` points traced with `rays_per_point` AO rays and
    /// `config`'s paths per selected point and frame.
    pub fn new(n: usize, rays_per_point: u32, config: &LightingConfig) -> Self {
        Self {
            sum: vec![Vec3::ZERO; n],
            count: vec![0; n],
            published: vec![0; n],
            rays_per_point,
            paths_per_point: config.paths_per_point,
            pool_paths: config.pool_paths,
        }
    }

    /// Point `i`'s light paths counted in AO samples.
    #[inline]
    pub fn progress(&self, i: usize) -> u32 {
        let scaled = u64::from(self.count[i]) * u64::from(self.rays_per_point)
            / u64::from(self.paths_per_point);
        u32::try_from(scaled).unwrap_or(u32::MAX)
    }

    /// The paths after which a point's irradiance counts as converged: as many frames of
    /// paths as `max_samples` AO samples take.
    pub fn max_paths(&self, max_samples: u32) -> u32 {
        let paths = (u64::from(max_samples) * u64::from(self.paths_per_point))
            .div_ceil(u64::from(self.rays_per_point));
        u32::try_from(paths).unwrap_or(u32::MAX)
    }

    /// Keep as many of point `i`'s paths (their mean unchanged) as its AO kept of its
    /// samples, `ao_kept`, counted in paths and rounded up: the same fraction of both, and a
    /// light progress never below the AO's, so that AO and irradiance that advanced together
    /// stay together (the point is re-traced when the AO alone would have been).
    pub fn keep_as_ao(&mut self, i: usize, ao_kept: u32) {
        let paths = (u64::from(ao_kept) * u64::from(self.paths_per_point))
            .div_ceil(u64::from(self.rays_per_point));
        self.keep(i, u32::try_from(paths).unwrap_or(u32::MAX));
    }

    /// Keep `left` of point `i`'s paths (at most all; their mean unchanged).
    fn keep(&mut self, i: usize, left: u32) {
        let count = self.count[i];
        let left = left.min(count);
        self.sum[i] = if count == 0 {
            Vec3::ZERO
        } else {
            self.sum[i] * (left as f32 / count as f32)
        };
        self.count[i] = left;
    }

    /// Forget every sample.
    pub fn clear(&mut self) {
        self.sum.fill(Vec3::ZERO);
        self.count.fill(0);
    }

    /// Heap bytes.
    pub fn heap_bytes(&self) -> u64 {
        psao_points::vec_bytes(&self.sum)
            + psao_points::vec_bytes(&self.count)
            + psao_points::vec_bytes(&self.published)
    }
}

impl InstanceState {
    /// Point `i`'s irradiance as it is published (module docs, "Pooling"): the mean of the
    /// paths of every point within the reconstruction radius of it (the clients' kernel
    /// reach: Poisson radius × interpolation factor, local units) that lies in its tangent plane
    /// (normals within [`POOL_COS`], offsets along its normal within [`POOL_PLANE`] Poisson
    /// radii), its own included, each point weighted by its paths; while those hold fewer
    /// than [`LightingConfig::pool_paths`] paths, also of the nearest coplanar points beyond
    /// (by distance, then index), until they do or the reach is [`POOL_MAX_REACH`] radii.
    /// `None` while `i` has no paths or without lighting.
    pub(crate) fn pooled_irradiance(&self, i: usize) -> Option<Vec3> {
        let light = self.points.light.as_ref()?;
        if light.count[i] == 0 {
            return None;
        }
        let radius = self.poisson_radius * DEFAULT_INTERPOLATION_FACTOR;
        let (mut sum, mut count) = (light.sum[i], u64::from(light.count[i]));
        self.coplanar_lit_points(i, radius, |j, _| {
            sum += light.sum[j];
            count += u64::from(light.count[j]);
        });
        let wanted = u64::from(light.pool_paths);
        if count < wanted {
            let mut farther = Vec::new();
            self.coplanar_lit_points(i, radius * POOL_MAX_REACH, |j, d2| {
                if d2 > radius * radius {
                    farther.push((d2, j));
                }
            });
            farther.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for (_, j) in farther {
                if count >= wanted {
                    break;
                }
                sum += light.sum[j];
                count += u64::from(light.count[j]);
            }
        }
        Some(sum / count as f32)
    }

    /// Call `f(j, d²)` for every point `j ≠ i` with light paths within `reach` of point `i`
    /// (local units; `d` its distance) that lies in `i`'s tangent plane: normals within
    /// [`POOL_COS`], offset along `i`'s normal within [`POOL_PLANE`] Poisson radii. Visits
    /// cells in a fixed order, so sums over it are deterministic.
    fn coplanar_lit_points(&self, i: usize, reach: f32, mut f: impl FnMut(usize, f32)) {
        let Some(light) = self.points.light.as_ref() else {
            return;
        };
        let layout = self.layout();
        let (x, n) = (self.points.position[i], self.points.normal[i]);
        let plane = POOL_PLANE * self.poisson_radius;
        let cell = |p: Vec3| {
            let c = ((p - layout.origin) / layout.cell_size).floor();
            c.clamp(Vec3::ZERO, (layout.dims - 1).as_vec3()).as_uvec3()
        };
        let (lo, hi) = (cell(x - Vec3::splat(reach)), cell(x + Vec3::splat(reach)));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for cx in lo.x..=hi.x {
                    let Some(slot) = self.alloc.find_cell(UVec3::new(cx, y, z)) else {
                        continue;
                    };
                    for &m in self.alloc.members(slot) {
                        let j = m as usize;
                        if m == NONE || j == i || light.count[j] == 0 {
                            continue;
                        }
                        let d = self.points.position[j] - x;
                        let d2 = d.length_squared();
                        if self.points.normal[j].dot(n) >= POOL_COS
                            && d.dot(n).abs() <= plane
                            && d2 <= reach * reach
                        {
                            f(j, d2);
                        }
                    }
                }
            }
        }
    }

    /// The irradiance record point `i` would be published with now: its pooled irradiance,
    /// or what was published while it has no paths (restarted); `None` without lighting.
    pub(crate) fn light_record(&self, i: usize) -> Option<u32> {
        let light = self.points.light.as_ref()?;
        Some(
            self.pooled_irradiance(i)
                .map_or(light.published[i], pack_rgb9e5),
        )
    }

    /// Whether point `i`'s pooled irradiance moved perceptibly from its published record.
    pub(crate) fn light_changed(&self, i: usize, threshold: f32) -> bool {
        let Some(light) = self.points.light.as_ref() else {
            return false;
        };
        self.pooled_irradiance(i)
            .is_some_and(|e| irradiance_changed(unpack_rgb9e5(light.published[i]), e, threshold))
    }
}

/// Rays charged to the budget for one selected point: `rays_per_point` AO rays plus, with
/// lighting, `paths × (bounces + 1) × (1 + lights)` (per path vertex one closest-hit ray
/// and one shadow ray per light: the most a path traces).
pub(crate) fn charge(rays_per_point: u32, lighting: Option<(&LightingConfig, usize)>) -> u64 {
    let light = lighting.map_or(0, |(l, lights)| {
        u64::from(l.paths_per_point) * (u64::from(l.bounces) + 1) * (1 + lights as u64)
    });
    u64::from(rays_per_point) + light
}

/// New light paths of one point in one frame.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LightSample {
    /// Sum of the paths' irradiance.
    pub sum: Vec3,
    /// Paths traced.
    pub paths: u32,
    /// Rays they traced.
    pub rays: u64,
}

/// The server's lighting: its settings, the scene (owned: the paths look up the surfaces
/// they hit, their base colours, the lights and the environment) and the lights the points'
/// paths are traced with.
pub(crate) struct Lighting {
    pub config: LightingConfig,
    scene: Scene,
    lights: Vec<Light>,
}

impl Lighting {
    /// The lighting of `scene` at scene time 0.
    pub fn new(scene: &Scene, config: LightingConfig) -> Self {
        Self {
            config,
            lights: scene.lights_at(0.0),
            scene: scene.clone(),
        }
    }

    /// The lights the paths are traced with.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// Bring the lights to scene time `time`: when a keyed sun turned by more than
    /// [`SUN_TOLERANCE_DEG`] since the lights in use, take the lights at `time` and restart
    /// the irradiance of the points the turned suns light (module docs). Returns, per
    /// instance, the restarted points (sorted; `None` when every point was), or `None` when
    /// nothing changed.
    pub fn relight(
        &mut self,
        time: f32,
        instances: &mut [InstanceState],
    ) -> Option<Vec<Option<Vec<u32>>>> {
        if !self.scene.lights_move() {
            return None;
        }
        let now = self.scene.lights_at(time);
        let cos_tolerance = SUN_TOLERANCE_DEG.to_radians().cos();
        let turned: Vec<(Vec3, Vec3)> = (self.lights.iter().zip(&now))
            .filter_map(|(a, b)| match (a.shape, b.shape) {
                (LightShape::Sun { direction: d0 }, LightShape::Sun { direction: d1 })
                    if d0.normalize_or_zero().dot(d1.normalize_or_zero()) < cos_tolerance =>
                {
                    Some((d0, d1))
                }
                _ => None,
            })
            .collect();
        // Without bounces and without their direct light, suns do not reach the points.
        if turned.is_empty() || (self.config.bounces == 0 && !self.config.sharp_direct) {
            return None;
        }
        self.lights = now;
        let everything = self.config.bounces > 0;
        let restarted = instances
            .par_iter_mut()
            .map(|inst| {
                let faces = |i: usize| {
                    let (_, n) = inst.world(i);
                    turned
                        .iter()
                        .any(|(a, b)| n.dot(*a) > 0.0 || n.dot(*b) > 0.0)
                };
                let list: Option<Vec<u32>> = (!everything).then(|| {
                    (0..inst.points.position.len())
                        .filter(|&i| faces(i))
                        .map(|i| i as u32)
                        .collect()
                });
                let Some(sums) = inst.points.light.as_mut() else {
                    return Some(Vec::new());
                };
                match &list {
                    None => sums.clear(),
                    Some(l) => l.iter().for_each(|&i| sums.keep(i as usize, 0)),
                }
                list
            })
            .collect();
        Some(restarted)
    }

    /// Trace new light paths for each of `selected` (up to `paths_per_point`, never beyond
    /// the converged count for `max_samples`) with the scene in `pose`, which `tracer` holds.
    /// Results in the order of `selected`; they do not depend on the number of threads.
    pub fn trace(
        &self,
        tracer: &Tracer,
        pose: &ScenePose,
        instances: &[InstanceState],
        selected: &[Candidate],
        max_samples: u32,
        seed: u64,
    ) -> Vec<LightSample> {
        let mut lighting =
            DiffuseLighting::with_lights(&self.scene, self.lights.clone(), self.config.bounces)
                .posed(pose);
        if !self.config.sharp_direct {
            lighting = lighting.without_sharp_direct();
        }
        // A few paths per point and frame: cap the 1/d² spikes of rectangle samples
        // (module docs, "Noise").
        lighting = lighting.with_clamped_rect_samples();
        selected
            .par_iter()
            .map(|c| {
                let inst = &instances[c.instance as usize];
                let i = c.index as usize;
                let Some(sums) = inst.points.light.as_ref() else {
                    return LightSample::default();
                };
                let first = sums.count[i];
                let paths = self.paths_for(first, sums.max_paths(max_samples));
                let (x, n) = inst.world(i);
                let key = sample_key(c.instance, c.index);
                let mut out = LightSample {
                    paths,
                    ..LightSample::default()
                };
                for k in first..first + paths {
                    let (e, rays) = lighting.sample_counted(tracer, x, n, n, seed, key, k);
                    out.sum += e;
                    out.rays += u64::from(rays);
                }
                out
            })
            .collect()
    }

    /// Paths a point with `count` of `max_paths` takes this frame.
    pub fn paths_for(&self, count: u32, max_paths: u32) -> u32 {
        self.config
            .paths_per_point
            .min(max_paths.saturating_sub(count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 m floor quad's points at 256 per m² (`publish::tests::state`), with empty irradiance accumulators pooling
    /// at least `pool_paths` paths, and the point nearest its centre.
    fn floor(pool_paths: u32) -> (InstanceState, usize) {
        let mut s = crate::publish::tests::state();
        let config = LightingConfig {
            pool_paths,
            ..LightingConfig::default()
        };
        s.points.light = Some(LightSums::new(s.points.position.len(), 16, &config));
        let centre = Vec3::new(0.5, 0.0, 0.5);
        let i = (0..s.points.position.len())
            .filter(|&i| s.points.stored.get(i))
            .min_by(|&a, &b| {
                let d = |k: usize| (s.points.position[k] - centre).length_squared();
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        (s, i)
    }

    /// Give point `j` `paths` paths of irradiance `value` (grey).
    fn set(s: &mut InstanceState, j: usize, paths: u32, value: f32) {
        let light = s.points.light.as_mut().unwrap();
        light.count[j] = paths;
        light.sum[j] = Vec3::splat(value * paths as f32);
    }

    /// The reconstruction radius and the stored points other than `i` with their squared
    /// distance from it, nearest first.
    fn by_distance(s: &InstanceState, i: usize) -> (f32, Vec<(f32, usize)>) {
        let x = s.points.position[i];
        let mut others: Vec<(f32, usize)> = (0..s.points.position.len())
            .filter(|&j| j != i && s.points.stored.get(j))
            .map(|j| ((s.points.position[j] - x).length_squared(), j))
            .collect();
        others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        (s.poisson_radius * DEFAULT_INTERPOLATION_FACTOR, others)
    }

    #[test]
    fn a_mature_neighbourhood_pools_within_the_reconstruction_radius_only() {
        let (mut s, i) = floor(64);
        let (radius, others) = by_distance(&s, i);
        set(&mut s, i, 64, 1.0);
        for &(d2, j) in &others {
            set(
                &mut s,
                j,
                64,
                if d2 <= radius * radius { 1.0 } else { 100.0 },
            );
        }
        assert_eq!(s.pooled_irradiance(i), Some(Vec3::ONE));
    }

    #[test]
    fn a_young_point_widens_its_reach_nearest_first_until_it_holds_pool_paths() {
        let (mut s, i) = floor(64);
        let (radius, others) = by_distance(&s, i);
        // Every point has 4 paths of a value of its own; 64 paths take 15 neighbours.
        set(&mut s, i, 4, 0.0);
        for &(_, j) in &others {
            set(&mut s, j, 4, j as f32);
        }
        let nearest = &others[..15];
        let reach = POOL_MAX_REACH * radius;
        assert!(nearest[14].0 > radius * radius && nearest[14].0 < reach * reach);
        assert!(nearest[14].0 < others[15].0, "a tie at the 15th neighbour");
        let expected = nearest.iter().map(|&(_, j)| j as f32).sum::<f32>() / 16.0;
        let pooled = s.pooled_irradiance(i).unwrap();
        assert!(
            (pooled.x - expected).abs() <= 1e-4 * expected,
            "{pooled} vs {expected}"
        );
        // Without widening, only the reconstruction radius.
        let (mut fixed, _) = floor(0);
        let (from, to) = (s.points.light.as_ref(), fixed.points.light.as_mut());
        let (from, to) = (from.unwrap(), to.unwrap());
        to.sum.clone_from(&from.sum);
        to.count.clone_from(&from.count);
        let within: Vec<usize> = others
            .iter()
            .take_while(|(d2, _)| *d2 <= radius * radius)
            .map(|&(_, j)| j)
            .collect();
        let expected = within.iter().map(|&j| j as f32).sum::<f32>() / (within.len() + 1) as f32;
        let pooled = fixed.pooled_irradiance(i).unwrap();
        assert!(
            (pooled.x - expected).abs() <= 1e-4 * expected,
            "{pooled} vs {expected}"
        );
    }

    #[test]
    fn the_reach_stops_at_pool_max_reach() {
        let (mut s, i) = floor(64);
        let (radius, others) = by_distance(&s, i);
        set(&mut s, i, 4, 1.0);
        let reach = POOL_MAX_REACH * radius;
        let far: Vec<usize> = others
            .iter()
            .filter(|(d2, _)| *d2 > reach * reach)
            .map(|&(_, j)| j)
            .collect();
        assert!(far.len() > 16);
        for j in far {
            set(&mut s, j, 64, 100.0);
        }
        assert_eq!(s.pooled_irradiance(i), Some(Vec3::ONE));
    }
}
