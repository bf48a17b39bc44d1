//! The sample cache (paper §4.5): samples of earlier frames, kept per level, reprojected and
//! splatted (finer levels over coarser ones), and aged by how much `n·v` changed since they were traced.
//!
//! Aging runs when the camera changed: the camera age goes up by one; for every object the
//! first level `ℓ₀` holding at least `N_min` of its samples is tested — a level-`ℓ₀` sample is
//! invalid when `|n·v_now − n·v_then| > δ`; all samples of an object and camera-age difference
//! `j` are deleted when more than half of that object's level-`ℓ₀` samples of age difference
//! `j` are invalid, and every sample with `j > MAX_AGE` is deleted. An object without a level
//! of `N_min` samples is only aged by `MAX_AGE`.
//!
//! On top of the paper's rule each sample is aged by how far its view direction turned: the
//! cache keeps the eye of every camera age ([`SampleCache::set_view`]), and a sample whose
//! direction to the eye now differs from its direction to the eye it was traced from by more
//! than its object's tolerance ([`SampleCache::set_view_tolerances`], from the material's
//! roughness: [`view_tolerance`]) is deleted, since what it reflects or refracts has moved by
//! about that angle. A highlight sample (brighter than white, [`is_highlight`]) shows a light
//! reflected in a direction that only its own view has, and slides over a curved surface as
//! the eye moves: it is deleted at the first camera change. The paper's test only sees the part of the turn that changes `n·v`; a
//! sideways walk past a mirror keeps `n·v` and changes the reflection entirely.

use crate::screen::ScreenView;
use crate::splat::{is_highlight, splat, Sample, SplatTarget};
use crate::sqrt5::Hierarchy;
use glam::Vec3;
use std::collections::HashMap;
use thiserror::Error;

/// Errors of the cache configuration and insertion.
#[derive(Debug, Error, PartialEq)]
pub enum CacheError {
    /// δ outside [0, 1] or not a number.
    #[error("aging threshold δ must be in [0, 1], got {0}")]
    Delta(f32),
    /// A capacity of zero samples.
    #[error("the sample cache needs a capacity of at least one sample")]
    Capacity,
    /// A negative or NaN mirror turn.
    #[error("the mirror turn must be a non-negative angle, got {0}")]
    MirrorTurn(f32),
    /// A sample of a level the hierarchy does not have.
    #[error("sample of level {level} for a hierarchy of {levels} levels")]
    Level {
        /// The sample's level.
        level: u8,
        /// Levels of the hierarchy.
        levels: u8,
    },
}

/// Aging and size settings of the cache.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CacheConfig {
    /// Largest tolerated change of `n·v` (δ, in [0, 1]).
    pub delta: f32,
    /// Samples a level needs to be the object's test level (`N_min`).
    pub n_min: usize,
    /// Camera-age difference above which samples are deleted (`MAX_AGE`).
    pub max_age: u32,
    /// Most samples kept; beyond it the oldest camera ages are evicted first.
    pub capacity: usize,
    /// Largest turn of a mirror sample's view direction, in radians (see [`view_tolerance`]).
    pub mirror_turn: f32,
}

/// The largest turn (radians) of a sample's view direction before what it shows has moved:
/// `mirror_turn` plus the GGX width `α = roughness²` of the surface's reflection lobe (a view
/// turn well inside the lobe leaves the glossy average nearly unchanged).
pub fn view_tolerance(mirror_turn: f32, roughness: f32) -> f32 {
    mirror_turn + roughness.clamp(0.0, 1.0).powi(2)
}

impl Default for CacheConfig {
    /// δ = 0.1, `N_min` = 10, `MAX_AGE` = 60 camera changes, 500 000 samples, a mirror
    /// turn of 1° (about a pixel at 160×90 and a 60° field of view).
    fn default() -> Self {
        Self {
            delta: 0.1,
            n_min: 10,
            max_age: 60,
            capacity: 500_000,
            mirror_turn: 1f32.to_radians(),
        }
    }
}

/// Samples of earlier frames, per level.
#[derive(Clone, Debug)]
pub struct SampleCache {
    config: CacheConfig,
    hierarchy: Hierarchy,
    /// `levels[ℓ − 1]`: the samples of level ℓ in insertion order.
    levels: Vec<Vec<Sample>>,
    camera_age: u32,
    /// The eye of each camera age within `MAX_AGE` of the current one.
    eyes: HashMap<u32, Vec3>,
    /// Per object, the largest turn of a sample's view direction (radians); objects not
    /// listed are aged by the paper's rule only.
    tolerances: HashMap<u32, f32>,
}

/// Samples removed by one aging pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AgingStats {
    /// Deleted because their object's test level was mostly invalid at their age.
    pub invalid: usize,
    /// Deleted because they were older than `MAX_AGE`.
    pub too_old: usize,
    /// Deleted because their view direction turned past their object's tolerance, or
    /// because they were highlights ([`is_highlight`]) of an earlier view.
    pub turned: usize,
}

impl SampleCache {
    /// An empty cache for `hierarchy`'s levels.
    pub fn new(config: CacheConfig, hierarchy: Hierarchy) -> Result<Self, CacheError> {
        if !(0.0..=1.0).contains(&config.delta) {
            return Err(CacheError::Delta(config.delta));
        }
        if config.capacity == 0 {
            return Err(CacheError::Capacity);
        }
        if config.mirror_turn.is_nan() || config.mirror_turn < 0.0 {
            return Err(CacheError::MirrorTurn(config.mirror_turn));
        }
        Ok(Self {
            config,
            hierarchy,
            levels: vec![Vec::new(); hierarchy.levels() as usize],
            camera_age: 0,
            eyes: HashMap::new(),
            tolerances: HashMap::new(),
        })
    }

    /// The view of the current camera age (its eye is what later ages compare samples of
    /// this age with); the first view of an age counts.
    pub fn set_view(&mut self, view: &ScreenView) {
        self.eyes.entry(self.camera_age).or_insert(view.eye);
    }

    /// The largest turn of the view direction (radians) per object's samples, e.g. from
    /// [`view_tolerance`] of its material; replaces the previous ones.
    pub fn set_view_tolerances(&mut self, tolerances: HashMap<u32, f32>) {
        self.tolerances = tolerances;
    }

    /// The configuration.
    pub fn config(&self) -> &CacheConfig {
        &self.config
    }

    /// The current camera age (camera changes so far).
    pub fn camera_age(&self) -> u32 {
        self.camera_age
    }

    /// Number of cached samples.
    pub fn len(&self) -> usize {
        self.levels.iter().map(Vec::len).sum()
    }

    /// True when no sample is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cached samples of one level (1 = coarsest); empty for a level outside the hierarchy.
    pub fn level(&self, level: u8) -> &[Sample] {
        level
            .checked_sub(1)
            .and_then(|l| self.levels.get(l as usize))
            .map_or(&[], Vec::as_slice)
    }

    /// Store samples; beyond the capacity the samples of the oldest camera ages go first.
    pub fn insert(&mut self, samples: &[Sample]) -> Result<(), CacheError> {
        let levels = self.hierarchy.levels();
        if let Some(s) = samples.iter().find(|s| s.level == 0 || s.level > levels) {
            return Err(CacheError::Level {
                level: s.level,
                levels,
            });
        }
        for s in samples {
            self.levels[s.level as usize - 1].push(*s);
        }
        self.evict_over_capacity();
        Ok(())
    }

    fn evict_over_capacity(&mut self) {
        let len = self.len();
        if len <= self.config.capacity {
            return;
        }
        // Count samples per age difference, then cut the oldest ages until the rest fits.
        let age = self.camera_age;
        let mut per_age: std::collections::BTreeMap<u32, usize> = Default::default();
        for s in self.levels.iter().flatten() {
            *per_age.entry(age.saturating_sub(s.age)).or_default() += 1;
        }
        let mut keep = len;
        let mut oldest_kept = u32::MAX;
        for (&j, &n) in per_age.iter().rev() {
            if keep <= self.config.capacity {
                break;
            }
            keep -= n;
            oldest_kept = j.saturating_sub(1);
        }
        for level in &mut self.levels {
            level.retain(|s| age.saturating_sub(s.age) <= oldest_kept);
        }
        // One age can hold more than the capacity (a static view): drop the newest samples of
        // the finest levels first, as a coarse sample covers the most pixels.
        let mut excess = self.len().saturating_sub(self.config.capacity);
        for level in self.levels.iter_mut().rev() {
            let cut = excess.min(level.len());
            level.truncate(level.len() - cut);
            excess -= cut;
        }
    }

    /// Delete every sample of the objects `moving` selects (their world positions are stale).
    pub fn drop_objects(&mut self, moving: impl Fn(u32) -> bool) -> usize {
        let before = self.len();
        for level in &mut self.levels {
            level.retain(|s| !moving(s.object));
        }
        before - self.len()
    }

    /// The camera changed: advance the camera age, record `view` as its view and age the
    /// samples against it.
    pub fn camera_changed(&mut self, view: &ScreenView) -> AgingStats {
        self.camera_age = self.camera_age.wrapping_add(1);
        let age = self.camera_age;
        let max_age = self.config.max_age;
        self.eyes.retain(|&a, _| age.wrapping_sub(a) <= max_age);
        self.set_view(view);
        let slots = max_age as usize + 1;
        // Per object: samples per level, to find its test level ℓ₀.
        let mut counts: HashMap<u32, Vec<usize>> = HashMap::new();
        for (l, level) in self.levels.iter().enumerate() {
            for s in level {
                counts
                    .entry(s.object)
                    .or_insert_with(|| vec![0; self.levels.len()])[l] += 1;
            }
        }
        let test_level: HashMap<u32, usize> = counts
            .into_iter()
            .filter_map(|(o, c)| {
                c.iter()
                    .position(|&n| n >= self.config.n_min)
                    .map(|l| (o, l))
            })
            .collect();
        // Per object and age difference: (invalid, total) among level-ℓ₀ samples.
        let mut tally: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
        for (&o, &l) in &test_level {
            let t = tally.entry(o).or_insert_with(|| vec![(0, 0); slots]);
            for s in self.levels[l].iter().filter(|s| s.object == o) {
                let j = age.wrapping_sub(s.age) as usize;
                if j >= slots {
                    continue;
                }
                let v = (view.eye - s.position).normalize_or_zero();
                let d_new = s.normal.dot(v);
                t[j].1 += 1;
                if (d_new - s.ndotv).abs() > self.config.delta {
                    t[j].0 += 1;
                }
            }
        }
        let mut stats = AgingStats::default();
        let (eyes, tolerances) = (&self.eyes, &self.tolerances);
        for level in &mut self.levels {
            level.retain(|s| {
                let j = age.wrapping_sub(s.age);
                if j > max_age {
                    stats.too_old += 1;
                    return false;
                }
                if turned(s, view.eye, eyes, tolerances) {
                    stats.turned += 1;
                    return false;
                }
                let mostly_invalid = tally
                    .get(&s.object)
                    .map(|t| t[j as usize])
                    .is_some_and(|(bad, total)| 2 * bad > total);
                if mostly_invalid {
                    stats.invalid += 1;
                }
                !mostly_invalid
            });
        }
        stats
    }

    /// Reproject the cached samples to `view` and splat them ([`crate::splat`]: finer levels
    /// take precedence; a pixel that several samples of one level have as their own pixel
    /// shows their mean); returns how many were drawn.
    pub fn splat(&self, view: &ScreenView, target: &mut SplatTarget<'_>) -> usize {
        let batches: Vec<&[Sample]> = self.levels.iter().map(Vec::as_slice).collect();
        splat(&batches, &self.hierarchy, view, self.camera_age, target)
    }
}

/// Whether `s`'s direction to `eye` turned past its object's tolerance since it was traced
/// (from the eye of its camera age in `eyes`), or `s` is a highlight of an earlier view.
fn turned(
    s: &Sample,
    eye: Vec3,
    eyes: &HashMap<u32, Vec3>,
    tolerances: &HashMap<u32, f32>,
) -> bool {
    if is_highlight(s) {
        return true;
    }
    let (Some(&tolerance), Some(&then)) = (tolerances.get(&s.object), eyes.get(&s.age)) else {
        return false;
    };
    let a = (then - s.position).normalize_or_zero();
    let b = (eye - s.position).normalize_or_zero();
    a.dot(b).clamp(-1.0, 1.0).acos() > tolerance
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use psao_raster::GBuffer;
    use psao_scene::Camera;

    const W: u32 = 80;
    const H: u32 = 60;

    /// A camera over the plane z = 0; object 1 is a disc on it, object 2 a square.
    struct Setup {
        cam: Camera,
        view: ScreenView,
        ids: Vec<u32>,
        /// Depth, position and normal (+z) of the plane.
        g: GBuffer,
    }

    fn setup(eye: Vec3) -> Setup {
        let cam = Camera::look_at(eye, Vec3::ZERO, 60.0);
        let view = ScreenView::new(&cam, W, H);
        let forward = (cam.target - cam.position).normalize();
        let mut ids = vec![0; (W * H) as usize];
        let mut g = GBuffer::empty(W, H);
        for y in 0..H {
            for x in 0..W {
                let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, W, H);
                if d.z >= 0.0 {
                    continue;
                }
                let t = -cam.position.z / d.z;
                let p = cam.position + t * d;
                let i = (y * W + x) as usize;
                g.position[i] = p;
                g.normal[i] = Vec3::Z;
                g.depth[i] = (p - cam.position).dot(forward);
                ids[i] = if p.truncate().length() < 1.2 {
                    1
                } else if (p.x - 1.9).abs() < 0.4 && p.y.abs() < 0.4 {
                    2
                } else {
                    0
                };
            }
        }
        Setup { cam, view, ids, g }
    }

    /// A colour per pixel, never black (so a splatted pixel differs from the black base) and
    /// never brighter than white.
    fn colour_of(i: usize) -> [f32; 3] {
        let v = (i as u32).wrapping_mul(2_654_435_761);
        [
            (1.0 + (v & 0xff) as f32) / 256.0,
            ((v >> 8) & 0xff) as f32 / 256.0,
            ((v >> 16) & 0xff) as f32 / 256.0,
        ]
    }

    /// The samples of every level over the whole image, traced with pixel colours.
    fn all_samples(s: &Setup, h: &Hierarchy, age: u32) -> Vec<Sample> {
        let rect = crate::sqrt5::PixelRect {
            x0: 0,
            y0: 0,
            x1: W as i32,
            y1: H as i32,
        };
        let mut out = Vec::new();
        for level in 1..=h.levels() {
            for (x, y) in h.level_samples(level, rect).unwrap().iter_from(0) {
                let i = (y as u32 * W + x as u32) as usize;
                if s.ids[i] == 0 {
                    continue;
                }
                let n = Vec3::Z;
                let v = (s.cam.position - s.g.position[i]).normalize();
                out.push(Sample {
                    position: s.g.position[i],
                    normal: n,
                    ndotv: n.dot(v),
                    color: colour_of(i),
                    object: s.ids[i],
                    level,
                    age,
                });
            }
        }
        out
    }

    /// The cache splatted over a black base; also which pixels changed.
    fn render(cache: &SampleCache, s: &Setup) -> (Vec<[f32; 3]>, Vec<bool>) {
        let n = (W * H) as usize;
        let black = vec![[0.0; 3]; n];
        let mut color = black.clone();
        cache.splat(
            &s.view,
            &mut SplatTarget {
                color: &mut color,
                diffuse: &black,
                keep: None,
                ids: &s.ids,
                gbuffer: &s.g,
            },
        );
        let written = color.iter().map(|c| *c != [0.0; 3]).collect();
        (color, written)
    }

    #[test]
    fn a_static_view_converges_to_the_traced_image() {
        let s = setup(Vec3::new(0.3, -0.5, 4.0));
        let h = Hierarchy::new(5).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        let mut samples = all_samples(&s, &h, 0);
        // Insertion order must not matter: the cache splats level by level.
        samples.reverse();
        cache.insert(&samples).unwrap();
        let (color, written) = render(&cache, &s);
        for i in 0..(W * H) as usize {
            if s.ids[i] != 0 {
                assert!(written[i]);
                assert_eq!(color[i], colour_of(i), "pixel {i}");
            } else {
                assert!(!written[i]);
            }
        }
    }

    #[test]
    fn splatting_is_the_same_on_one_and_two_threads() {
        let s = setup(Vec3::new(0.3, -0.5, 4.0));
        let h = Hierarchy::new(5).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        // Only the coarse levels: the splats overlap.
        let coarse: Vec<Sample> = all_samples(&s, &h, 0)
            .into_iter()
            .filter(|x| x.level <= 3)
            .collect();
        cache.insert(&coarse).unwrap();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        assert_eq!(
            one.install(|| render(&cache, &s)),
            two.install(|| render(&cache, &s))
        );
    }

    #[test]
    fn aging_keeps_samples_under_a_small_move_and_drops_them_under_a_large_one() {
        let s = setup(Vec3::new(0.0, -3.0, 3.0));
        let h = Hierarchy::new(5).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        cache.insert(&all_samples(&s, &h, 0)).unwrap();
        let n = cache.len();
        let near = setup(Vec3::new(0.05, -3.0, 3.02));
        let st = cache.camera_changed(&near.view);
        assert_eq!(st, AgingStats::default());
        assert_eq!(cache.len(), n);
        // From straight above, n·v changes by about 0.3 everywhere.
        let above = setup(Vec3::new(0.0, 0.0, 4.2));
        let st = cache.camera_changed(&above.view);
        assert_eq!(st.invalid, n);
        assert!(cache.is_empty());
    }

    #[test]
    fn a_view_that_turns_past_the_tolerance_drops_samples_the_paper_rule_keeps() {
        // The eye circles the disc at the same distance and height: n·v stays the same, so
        // the paper's rule keeps every sample, though a mirror's reflection has changed.
        let eye = |deg: f32| {
            let a = deg.to_radians();
            Vec3::new(3.0 * a.sin(), -3.0 * a.cos(), 3.0)
        };
        let s = setup(eye(0.0));
        let h = Hierarchy::new(5).unwrap();
        let samples = all_samples(&s, &h, 0);
        let ones = samples.iter().filter(|x| x.object == 1).count();
        let run = |tolerances: HashMap<u32, f32>| {
            let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
            cache.set_view_tolerances(tolerances);
            cache.set_view(&s.view);
            cache.insert(&samples).unwrap();
            let small = cache.camera_changed(&setup(eye(1.0)).view);
            let large = cache.camera_changed(&setup(eye(25.0)).view);
            (small, large, cache)
        };
        let (small, large, cache) = run(HashMap::new());
        assert_eq!(
            (small, large),
            (AgingStats::default(), AgingStats::default())
        );
        assert_eq!(cache.len(), samples.len());
        // Object 1 turns 1° (kept, within 5°) and then 25° (dropped); object 2 has no
        // tolerance and stays.
        let (small, large, cache) = run(HashMap::from([(1, 5f32.to_radians())]));
        assert_eq!(small, AgingStats::default());
        assert_eq!(large.turned, ones);
        assert_eq!(cache.len(), samples.len() - ones);
        assert!((1..=5).all(|l| cache.level(l).iter().all(|x| x.object == 2)));
    }

    #[test]
    fn highlights_are_dropped_at_the_first_camera_change() {
        let s = setup(Vec3::new(0.0, -3.0, 3.0));
        let h = Hierarchy::new(5).unwrap();
        let mut samples = all_samples(&s, &h, 0);
        for x in samples.iter_mut().step_by(7) {
            x.color = [2.0, 0.5, 0.5];
        }
        let highlights = samples.iter().filter(|x| is_highlight(x)).count();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        cache.insert(&samples).unwrap();
        // The same eye, a new camera age (e.g. a turn in place): only the highlights go.
        let st = cache.camera_changed(&s.view);
        assert_eq!(st.turned, highlights);
        assert_eq!(cache.len(), samples.len() - highlights);
        assert!((1..=5).all(|l| cache.level(l).iter().all(|x| !is_highlight(x))));
    }

    #[test]
    fn the_tolerance_grows_with_roughness() {
        let turn = 1f32.to_radians();
        assert_eq!(view_tolerance(turn, 0.0), turn);
        assert!(view_tolerance(turn, 0.2) > view_tolerance(turn, 0.1));
        assert!((view_tolerance(turn, 0.3) - (turn + 0.09)).abs() < 1e-6);
    }

    #[test]
    fn samples_older_than_max_age_go() {
        let s = setup(Vec3::new(0.0, -0.5, 4.0));
        let h = Hierarchy::new(4).unwrap();
        let config = CacheConfig {
            max_age: 3,
            ..CacheConfig::default()
        };
        let mut cache = SampleCache::new(config, h).unwrap();
        cache.insert(&all_samples(&s, &h, 0)).unwrap();
        let n = cache.len();
        for _ in 0..3 {
            assert_eq!(cache.camera_changed(&s.view).too_old, 0);
        }
        assert_eq!(cache.len(), n);
        assert_eq!(cache.camera_changed(&s.view).too_old, n);
    }

    #[test]
    fn aging_deletes_per_object_and_age() {
        let s = setup(Vec3::new(0.0, -3.0, 3.0));
        let h = Hierarchy::new(5).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        let mut samples = all_samples(&s, &h, 0);
        // Object 2's samples claim a normal that the next view sees very differently.
        for x in samples.iter_mut().filter(|x| x.object == 2) {
            x.normal = Vec3::new(0.0, -0.6, 0.8);
            x.ndotv = x.normal.dot((s.cam.position - x.position).normalize()) + 0.5;
        }
        cache.insert(&samples).unwrap();
        let ones = samples.iter().filter(|x| x.object == 1).count();
        cache.camera_changed(&s.view);
        assert_eq!(cache.len(), ones);
        assert!((1..=5).all(|l| cache.level(l).iter().all(|x| x.object == 1)));
    }

    #[test]
    fn moving_objects_are_dropped() {
        let s = setup(Vec3::new(0.0, -0.5, 4.0));
        let h = Hierarchy::new(4).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        let samples = all_samples(&s, &h, 0);
        cache.insert(&samples).unwrap();
        let twos = samples.iter().filter(|x| x.object == 2).count();
        assert!(twos > 0);
        assert_eq!(cache.drop_objects(|o| o == 2), twos);
        assert_eq!(cache.len(), samples.len() - twos);
    }

    #[test]
    fn occluded_and_off_object_samples_are_not_splatted() {
        let s = setup(Vec3::new(0.0, -0.5, 4.0));
        let h = Hierarchy::new(1).unwrap();
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        let i = s.ids.iter().position(|&o| o == 1).unwrap();
        let base = Sample {
            position: s.g.position[i],
            normal: Vec3::Z,
            ndotv: 1.0,
            color: [1.0; 3],
            object: 1,
            level: 1,
            age: 0,
        };
        let hidden = Sample {
            position: s.g.position[i] - Vec3::Z * 0.5,
            ..base
        };
        let wrong = Sample { object: 2, ..base };
        cache.insert(&[hidden, wrong]).unwrap();
        let (_, written) = render(&cache, &s);
        assert!(written.iter().all(|&w| !w));
        cache.insert(&[base]).unwrap();
        let (_, written) = render(&cache, &s);
        assert_eq!(written.iter().filter(|&&w| w).count(), 1);
    }

    #[test]
    fn the_capacity_evicts_the_oldest_ages_first() {
        let s = setup(Vec3::new(0.0, -0.5, 4.0));
        let h = Hierarchy::new(4).unwrap();
        let one_age = all_samples(&s, &h, 0).len();
        let config = CacheConfig {
            capacity: one_age + 10,
            ..CacheConfig::default()
        };
        let mut cache = SampleCache::new(config, h).unwrap();
        cache.insert(&all_samples(&s, &h, 0)).unwrap();
        cache.camera_changed(&s.view);
        cache.insert(&all_samples(&s, &h, 1)).unwrap();
        assert_eq!(cache.len(), one_age);
        assert!((1..=4).all(|l| cache.level(l).iter().all(|x| x.age == 1)));
        // A single age over the capacity keeps its coarse levels.
        let small = CacheConfig {
            capacity: 20,
            ..CacheConfig::default()
        };
        let mut cache = SampleCache::new(small, h).unwrap();
        cache.insert(&all_samples(&s, &h, 0)).unwrap();
        assert_eq!(cache.len(), 20);
        assert!(!cache.level(1).is_empty());
    }

    #[test]
    fn bad_settings_and_levels_are_errors() {
        let h = Hierarchy::new(3).unwrap();
        let bad = CacheConfig {
            delta: 1.5,
            ..CacheConfig::default()
        };
        assert_eq!(
            SampleCache::new(bad, h).unwrap_err(),
            CacheError::Delta(1.5)
        );
        let nan = CacheConfig {
            delta: f32::NAN,
            ..CacheConfig::default()
        };
        assert!(SampleCache::new(nan, h).is_err());
        let turn = CacheConfig {
            mirror_turn: -0.1,
            ..CacheConfig::default()
        };
        assert_eq!(
            SampleCache::new(turn, h).unwrap_err(),
            CacheError::MirrorTurn(-0.1)
        );
        let empty = CacheConfig {
            capacity: 0,
            ..CacheConfig::default()
        };
        assert_eq!(
            SampleCache::new(empty, h).unwrap_err(),
            CacheError::Capacity
        );
        let mut cache = SampleCache::new(CacheConfig::default(), h).unwrap();
        let s = Sample {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            ndotv: 1.0,
            color: [0.0; 3],
            object: 1,
            level: 4,
            age: 0,
        };
        assert_eq!(
            cache.insert(&[s]),
            Err(CacheError::Level {
                level: 4,
                levels: 3
            })
        );
        assert!(cache.is_empty());
    }
}
