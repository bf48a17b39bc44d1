//! Generated camera paths: walks at eye height through a scene's free space, deterministic
//! per seed, for evaluations on views nobody tuned on.
//!
//! A path is a Catmull-Rom spline ([`CameraPath`]) through waypoints. Each waypoint stands
//! at eye height above a floor (a surface whose top side a downward ray meets, at least the
//! eye height below the top of the scene's bounds, so not a roof), clear of
//! every surface by `clearance` in 26 directions, where every ray that meets a surface meets
//! its front side (so the eye is not inside a closed solid); consecutive waypoints see each
//! other along five parallel rays (the segment and four offsets by `clearance`), so a walk
//! never passes through geometry. Keys are timed by walking speed. At a waypoint the camera
//! looks, with probability `non_diffuse_look`, towards a non-diffuse surface it sees ahead,
//! else along its direction of travel. The sampled path is then checked frame by frame at
//! [`PATH_HZ`](crate::PATH_HZ): every eye free, every step between frames unobstructed, no view straight up
//! or down; a path failing the check is drawn again.
//!
//! Geometry is queried through [`RayCaster`], so this module needs no ray tracer; the
//! callers implement it with theirs.

use glam::Vec3;

use crate::path::{CameraKey, CameraPath};
use crate::Scene;

/// What a cast ray met first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CastHit {
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Whether the ray met the triangle's front (counter-clockwise) side.
    pub front: bool,
    /// Whether the surface's material is non-diffuse (`Material::is_non_diffuse`).
    pub non_diffuse: bool,
}

/// Closest-hit ray queries against a scene.
pub trait RayCaster {
    /// The first surface along `origin + t·dir` (`dir` unit) with `0 < t < max`, if any.
    fn cast(&self, origin: Vec3, dir: Vec3, max: f32) -> Option<CastHit>;
}

/// Settings of the generator (distances in scene units, metres for psao's scenes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathGenConfig {
    /// Length of each path in seconds.
    pub duration_s: f32,
    /// Eye height above the floor (lowered to half the headroom under low ceilings).
    pub eye_height: f32,
    /// Least distance from the eye to any surface, along the walk too.
    pub clearance: f32,
    /// Walking speed.
    pub speed: f32,
    /// Probability that the camera looks at a non-diffuse surface at a waypoint.
    pub non_diffuse_look: f32,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

impl Default for PathGenConfig {
    fn default() -> Self {
        Self {
            duration_s: 8.0,
            eye_height: 1.6,
            clearance: 0.3,
            speed: 1.2,
            non_diffuse_look: 0.5,
            fov_y_deg: 60.0,
        }
    }
}

/// Why no paths could be generated.
#[derive(Debug, thiserror::Error)]
pub enum PathGenError {
    /// A setting is out of range.
    #[error("path generator: {0}")]
    Config(String),
    /// The scene has no geometry (empty or non-finite bounds).
    #[error("path generator: the scene has no geometry to walk through")]
    Empty,
    /// No candidate eye position was clear of the geometry.
    #[error(
        "path generator: no free space: none of {tried} eye positions above a floor is clear \
         of the geometry by {clearance}"
    )]
    NoFreeSpace {
        /// Candidates tried.
        tried: usize,
        /// The clearance asked for.
        clearance: f32,
    },
    /// Free space exists but no walk of the asked length passed the frame-by-frame check.
    #[error("path generator: no {duration_s} s walk through the free space found in {attempts} attempts (path {path})")]
    NoWalk {
        /// Index of the path.
        path: usize,
        /// Requested duration.
        duration_s: f32,
        /// Walks drawn.
        attempts: usize,
    },
}

/// Candidate eye positions drawn before the scene counts as having no free space.
const EYE_TRIES: usize = 2000;
/// Candidate next waypoints drawn per step of a walk.
const STEP_TRIES: usize = 64;
/// Walks drawn per path before giving up.
const WALK_TRIES: usize = 24;
/// Rays cast from a waypoint to find non-diffuse surfaces to look at.
const LOOK_RAYS: usize = 64;
/// Distance of the look-at point from the eye (only its direction matters).
const LOOK_DISTANCE: f32 = 4.0;
/// Largest turn between two walk segments, in degrees (sharper turns make the spline swing).
const MAX_TURN_DEG: f32 = 100.0;
/// Largest |y| of a view direction (about 11.5° from vertical), within `CameraPath`'s rule.
const MAX_VIEW_Y: f32 = 0.98;

/// `count` camera paths through `scene`'s free space, deterministic per `seed`; path `k` of
/// a seed does not depend on `count`.
pub fn generate_paths(
    scene: &Scene,
    caster: &dyn RayCaster,
    config: &PathGenConfig,
    count: usize,
    seed: u64,
) -> Result<Vec<CameraPath>, PathGenError> {
    check(config)?;
    let (lo, hi) = scene.bounds();
    if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
        return Err(PathGenError::Empty);
    }
    let walker = Walker {
        caster,
        config,
        lo,
        hi,
        reach: 2.0 * (hi - lo).length() + 1.0,
    };
    (0..count)
        .map(|k| walker.path(k, &mut Rng::new(seed, k as u64)))
        .collect()
}

fn check(c: &PathGenConfig) -> Result<(), PathGenError> {
    let positive = [
        ("duration_s", c.duration_s),
        ("eye_height", c.eye_height),
        ("clearance", c.clearance),
        ("speed", c.speed),
    ];
    for (name, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return Err(PathGenError::Config(format!(
                "{name} must be positive, got {v}"
            )));
        }
    }
    if !(0.0..=1.0).contains(&c.non_diffuse_look) {
        return Err(PathGenError::Config(format!(
            "non_diffuse_look must be in [0, 1], got {}",
            c.non_diffuse_look
        )));
    }
    if !(c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0) {
        return Err(PathGenError::Config(format!(
            "fov_y_deg must be in (0, 180), got {}",
            c.fov_y_deg
        )));
    }
    Ok(())
}

/// The 26 directions to the neighbours of a cell in a 3×3×3 grid.
fn probe_directions() -> impl Iterator<Item = Vec3> {
    (0..27).filter(|&i| i != 13).map(|i| {
        Vec3::new(
            (i % 3) as f32 - 1.0,
            ((i / 3) % 3) as f32 - 1.0,
            (i / 9) as f32 - 1.0,
        )
        .normalize()
    })
}

/// Whether `p` is clear of every surface by `clearance` and outside every closed solid
/// (every ray from it that meets a surface meets its front side).
pub fn is_free(caster: &dyn RayCaster, p: Vec3, clearance: f32, reach: f32) -> bool {
    probe_directions().all(|d| {
        caster
            .cast(p, d, reach)
            .is_none_or(|h| h.front && h.t >= clearance)
    })
}

/// Whether the straight step from `a` to `b` meets no surface (cast both ways).
pub fn step_is_clear(caster: &dyn RayCaster, a: Vec3, b: Vec3) -> bool {
    let d = b - a;
    let len = d.length();
    if len <= 1e-6 {
        return true;
    }
    let dir = d / len;
    caster.cast(a, dir, len).is_none() && caster.cast(b, -dir, len).is_none()
}

/// Walks through one scene.
struct Walker<'a> {
    caster: &'a dyn RayCaster,
    config: &'a PathGenConfig,
    lo: Vec3,
    hi: Vec3,
    /// A ray length beyond the scene.
    reach: f32,
}

impl Walker<'_> {
    /// A free eye position at eye height above a floor, drawn uniformly over the bounds.
    fn eye(&self, rng: &mut Rng) -> Option<Vec3> {
        let c = self.config;
        let p = self.lo + (self.hi - self.lo) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
        let floor = self.caster.cast(p, Vec3::NEG_Y, self.reach)?;
        if !floor.front {
            return None;
        }
        let ground = p - Vec3::Y * floor.t;
        // A floor at the top of the bounds is a roof, not a place to walk.
        if ground.y > self.hi.y - c.eye_height {
            return None;
        }
        let headroom = self
            .caster
            .cast(ground + Vec3::Y * 1e-3, Vec3::Y, self.reach)
            .map_or(f32::INFINITY, |h| h.t);
        let eye = ground + Vec3::Y * c.eye_height.min(0.5 * headroom);
        is_free(self.caster, eye, c.clearance, self.reach).then_some(eye)
    }

    /// A free eye position, or `None` after [`EYE_TRIES`] candidates.
    fn any_eye(&self, rng: &mut Rng) -> Option<Vec3> {
        (0..EYE_TRIES).find_map(|_| self.eye(rng))
    }

    /// Whether a walker of half-width `clearance` passes from `a` to `b`: the segment and
    /// its four offsets sideways and up/down are unobstructed.
    fn passes(&self, a: Vec3, b: Vec3) -> bool {
        let d = (b - a).normalize_or_zero();
        let side = d.cross(Vec3::Y).normalize_or(Vec3::X) * self.config.clearance;
        let up = side.cross(d).normalize_or(Vec3::Y) * self.config.clearance;
        [Vec3::ZERO, side, -side, up, -up]
            .iter()
            .all(|&o| step_is_clear(self.caster, a + o, b + o))
    }

    /// Path `index`: up to [`WALK_TRIES`] walks until one passes the frame check.
    fn path(&self, index: usize, rng: &mut Rng) -> Result<CameraPath, PathGenError> {
        let start = self.any_eye(rng).ok_or(PathGenError::NoFreeSpace {
            tried: EYE_TRIES,
            clearance: self.config.clearance,
        })?;
        for _ in 0..WALK_TRIES {
            let Some(waypoints) = self.walk(start, rng) else {
                continue;
            };
            let path = self.keyed(&waypoints, rng, index);
            if self.frames_ok(&path) {
                return Ok(path);
            }
        }
        Err(PathGenError::NoWalk {
            path: index,
            duration_s: self.config.duration_s,
            attempts: WALK_TRIES,
        })
    }

    /// Waypoints from `start` until the walk lasts the configured duration.
    fn walk(&self, start: Vec3, rng: &mut Rng) -> Option<Vec<Vec3>> {
        let c = self.config;
        let min_step = 4.0 * c.clearance;
        let need = c.duration_s * c.speed;
        let mut points = vec![start];
        let mut walked = 0.0;
        while walked < need {
            let here = *points.last()?;
            let heading =
                (points.len() >= 2).then(|| (here - points[points.len() - 2]).normalize_or_zero());
            let next = (0..STEP_TRIES).find_map(|_| {
                let b = self.eye(rng)?;
                let d = b - here;
                let turn_ok = heading.is_none_or(|h| {
                    h.dot(d.normalize_or_zero()) >= MAX_TURN_DEG.to_radians().cos()
                });
                (d.length() >= min_step && turn_ok && self.passes(here, b)).then_some(b)
            })?;
            walked += here.distance(next);
            points.push(next);
        }
        Some(points)
    }

    /// Keys at walking speed through `points`, each looking along the travel direction or
    /// at a non-diffuse surface ahead.
    fn keyed(&self, points: &[Vec3], rng: &mut Rng, index: usize) -> CameraPath {
        let c = self.config;
        let mut time = 0.0;
        let keys = (0..points.len())
            .map(|i| {
                if i > 0 {
                    time += points[i - 1].distance(points[i]) / c.speed;
                }
                let prev = points[i.saturating_sub(1)];
                let next = points[(i + 1).min(points.len() - 1)];
                let travel = flat(next - prev).unwrap_or(Vec3::X);
                let look = if rng.f32() < c.non_diffuse_look {
                    self.non_diffuse_direction(points[i], travel, rng)
                        .unwrap_or(travel)
                } else {
                    travel
                };
                CameraKey {
                    time,
                    position: points[i],
                    look_at: points[i] + look * LOOK_DISTANCE,
                    fov_y_deg: c.fov_y_deg,
                }
            })
            .collect();
        CameraPath {
            name: format!("generated_{index}"),
            keys,
        }
    }

    /// The direction of a random non-diffuse surface seen from `eye` within 75° of `travel`
    /// and between 40° below and 20° above the horizon, farther than the clearance.
    fn non_diffuse_direction(&self, eye: Vec3, travel: Vec3, rng: &mut Rng) -> Option<Vec3> {
        let cos_cone = 75f32.to_radians().cos();
        let found: Vec<Vec3> = (0..LOOK_RAYS)
            .filter_map(|_| {
                let yaw = std::f32::consts::TAU * rng.f32();
                let pitch = (-40.0 + 60.0 * rng.f32()).to_radians();
                let d = Vec3::new(
                    pitch.cos() * yaw.cos(),
                    pitch.sin(),
                    pitch.cos() * yaw.sin(),
                );
                let h = self.caster.cast(eye, d, self.reach)?;
                let ahead = flat(d).is_some_and(|f| f.dot(travel) >= cos_cone);
                (h.non_diffuse && h.front && h.t > self.config.clearance && ahead).then_some(d)
            })
            .collect();
        (!found.is_empty()).then(|| found[(rng.f32() * found.len() as f32) as usize % found.len()])
    }

    /// The frame-by-frame check of a sampled path (see the module documentation).
    fn frames_ok(&self, path: &CameraPath) -> bool {
        let mut previous: Option<Vec3> = None;
        (0..path.frame_count()).all(|i| {
            let cam = path.camera_at_frame(i);
            let view = (cam.target - cam.position).normalize_or_zero();
            let ok = view != Vec3::ZERO
                && view.y.abs() <= MAX_VIEW_Y
                && is_free(self.caster, cam.position, self.config.clearance, self.reach)
                && previous.is_none_or(|p| step_is_clear(self.caster, p, cam.position));
            previous = Some(cam.position);
            ok
        })
    }
}

/// The unit horizontal part of `v`, if it has one.
fn flat(v: Vec3) -> Option<Vec3> {
    Vec3::new(v.x, 0.0, v.z).try_normalize()
}

/// A small seeded generator (splitmix64) per (seed, path index).
struct Rng(u64);

impl Rng {
    fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng(seed ^ stream.wrapping_mul(0xd1b5_4a32_d192_ed03));
        r.next();
        r
    }

    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn f32(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Free space everywhere: no surface at all.
    struct Nothing;
    impl RayCaster for Nothing {
        fn cast(&self, _: Vec3, _: Vec3, _: f32) -> Option<CastHit> {
            None
        }
    }

    #[test]
    fn a_scene_without_geometry_is_an_error() {
        let err = generate_paths(&Scene::default(), &Nothing, &PathGenConfig::default(), 1, 1)
            .unwrap_err();
        assert!(matches!(err, PathGenError::Empty), "{err}");
    }

    #[test]
    fn bad_settings_are_errors() {
        let config = PathGenConfig {
            speed: 0.0,
            ..PathGenConfig::default()
        };
        let err = generate_paths(&Scene::default(), &Nothing, &config, 1, 1).unwrap_err();
        assert!(err.to_string().contains("speed"), "{err}");
    }

    #[test]
    fn probes_cover_every_neighbour_direction_once() {
        let dirs: Vec<Vec3> = probe_directions().collect();
        assert_eq!(dirs.len(), 26);
        assert!(dirs.iter().all(|d| (d.length() - 1.0).abs() < 1e-5));
        assert!(dirs.iter().any(|d| d.y < -0.99) && dirs.iter().any(|d| d.y > 0.99));
    }
}
