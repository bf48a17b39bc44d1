//! Corrective splatting over the split (DESIGN §8, `docs/CORRECTIVE.md`, `docs/PROTOCOL.md`).
//!
//! The client analyses its frames (saliency and task importance per non-diffuse object) and
//! sends the regions and their priorities ([`RegionsMsg`]) with its camera; the server's
//! [`RemoteCorrections`] keeps each client's region queue, traces samples for the client's
//! camera within the client's sample budget per second, and streams them back
//! ([`SamplesMsg`]) on the same connection as the AO updates. The client's
//! [`CorrectiveClient`] keeps the sample cache, ages it on camera changes and splats it over
//! its frame. `psao run --corrective` ([`crate::pipeline`]), `psao serve --corrective`
//! ([`crate::serve`]) and `psao view --corrective` ([`crate::view`]) use these same parts.

use std::sync::{Arc, PoisonError, RwLock, RwLockReadGuard};

use glam::{Affine3A, Vec3};
use psao_client::Shading;
use psao_corrective::attention::{analyze_tiles, ObjectRegion, DEFAULT_SALIENCY_WEIGHT};
use psao_corrective::base::{
    diffuse_keep, is_object, object_ids, view_tolerances, GiShade, TracedAoShade,
};
use psao_corrective::cache::{CacheConfig, SampleCache};
use psao_corrective::saliency::{saliency, RgbImage};
use psao_corrective::schedule::{DEFAULT_DECAY, DEFAULT_JOB_SIZE};
use psao_corrective::screen::ScreenView;
use psao_corrective::session::Planner;
use psao_corrective::splat::{Sample, SplatTarget};
use psao_corrective::sqrt5::{Hierarchy, PixelRect};
use psao_corrective::trace::{CorrectionTracer, DiffuseShade, TraceSettings};
use psao_raster::GBuffer;
use psao_scene::{Animator, Camera, Motion, Scene, ScenePose};
use psao_trace::ao::hash64;
use psao_trace::gi::DiffuseLighting;
use psao_trace::{Backend, GeometryMode, Tracer};
use psao_wire::{CameraMsg, Message, Region, RegionsMsg, SampleMsg, SamplesMsg, MAX_SAMPLES};
use rayon::prelude::*;

use crate::convert::view_of;
use crate::pipeline::{client_time, CLIENT_HZ};
use crate::NetError;

/// Default sample budget per client and second (the paper: 10 000–50 000 per second on 2–6
/// processors; our tracer does about 10 000 per second on 2 cores).
pub const DEFAULT_SAMPLES_PER_SECOND: u32 = 6000;
/// Default client frames between analyses (0.3 s at 60 Hz).
pub const DEFAULT_ANALYZE_EVERY: u32 = 18;

/// The √5 hierarchy both ends use for a `width × height` image: the coarsest spacing about a
/// quarter of the shorter side.
pub fn hierarchy_for(width: u32, height: u32) -> Hierarchy {
    Hierarchy::for_spacing(width.min(height) as f32 / 4.0)
}

/// Default light paths per diffuse point a lit session's correction rays reach.
pub const DEFAULT_LIGHT_PATHS: u32 = 8;

/// How a lit session's correction tracer shades the diffuse surfaces its rays reach: with
/// the diffuse lighting the clients show ([`psao_trace::gi`]: the scene's lights with shadow
/// rays, its environment and `bounces` bounces; the clients' shadow-mapped direct light plus
/// the points' irradiance estimate the same), path-traced with `paths` paths per point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LitCorrections {
    /// Indirect bounces (the server's).
    pub bounces: u32,
    /// Light paths per diffuse point reached.
    pub paths: u32,
}

impl LitCorrections {
    /// The corrections of a server with `lighting` (`None`: AO only, no lit corrections) and
    /// `config`'s paths per point.
    pub fn of(
        lighting: Option<&psao_server::LightingConfig>,
        config: &CorrectiveConfig,
    ) -> Option<Self> {
        lighting.map(|l| Self {
            bounces: l.bounces,
            paths: config.light_paths.max(1),
        })
    }
}

/// What the server traces with: the scene, its animation, and its tracers at the pose last
/// asked for.
///
/// Samples are what the client's base lacks. AO sessions: the full radiance, the diffuse
/// surfaces reached shaded as the AO composite (the client subtracts its AO composite at the
/// sample's pixel). Lit sessions ([`Self::with_lighting`]): the view-dependent part only
/// (reflection, refraction, highlights, with the diffuse surfaces they reach lit as the
/// client's lit composite is), added over the client's lit composite, of which each pixel
/// keeps its material's diffuse share ([`psao_corrective::splat::SplatTarget::keep`]).
pub struct CorrectionEngine {
    scene: Arc<Scene>,
    /// The scene's animation, when anything moves.
    animator: Option<Animator>,
    geometry: RwLock<PosedGeometry>,
    ao_spp: u32,
    /// Lit corrections (`None`: the AO composite is the base).
    lighting: Option<LitCorrections>,
    seed: u64,
}

/// The correction tracers and the pose they hold (`None`: the stored one).
struct PosedGeometry {
    pose: Option<ScenePose>,
    primary: Tracer,
    occlusion: Tracer,
}

impl CorrectionEngine {
    /// Tracers over `scene` on `backend`, posed at each traced frame's time when the scene is
    /// animated (a frozen scene stays at its stored transforms); `ao_spp` AO rays per diffuse
    /// point reached, `seed` for every random choice.
    pub fn new(
        scene: Arc<Scene>,
        backend: Backend,
        ao_spp: u32,
        seed: u64,
    ) -> Result<Self, NetError> {
        let tracer = |mode| {
            Tracer::new(backend, &scene, mode)
                .map_err(|e| NetError::Config(format!("cannot build the correction tracer: {e}")))
        };
        let geometry = PosedGeometry {
            pose: None,
            primary: tracer(GeometryMode::Primary)?,
            occlusion: tracer(GeometryMode::Occlusion)?,
        };
        let animator = Animator::new(&scene)
            .map_err(|e| NetError::Config(format!("the scene's animation cannot play: {e}")))?;
        Ok(Self {
            animator: animator.is_dynamic().then_some(animator),
            scene,
            geometry: RwLock::new(geometry),
            ao_spp: ao_spp.max(1),
            lighting: None,
            seed,
        })
    }

    /// The same engine for the clients of a lit server (`Some`), or of an AO-only one.
    pub fn with_lighting(mut self, lighting: Option<LitCorrections>) -> Self {
        self.lighting = lighting.map(|l| LitCorrections {
            paths: l.paths.max(1),
            ..l
        });
        self
    }

    /// Runs `f` with the correction tracer of the scene at `time` (diffuse surfaces shaded as
    /// the client shades them: AO traced with the DESIGN §2 estimator, or the diffuse lighting
    /// at `time` when lit). An animated scene is
    /// posed at `time` first unless the tracers hold it already; callers at the same time
    /// trace side by side.
    pub(crate) fn with_tracer<R>(
        &self,
        time: f32,
        f: impl FnOnce(&CorrectionTracer<'_>) -> R,
    ) -> Result<R, NetError> {
        let Some(animator) = &self.animator else {
            return Ok(self.trace_in(&read(&self.geometry), time, f));
        };
        {
            let geometry = read(&self.geometry);
            if geometry.pose.as_ref().is_some_and(|p| p.time == time) {
                return Ok(self.trace_in(&geometry, time, f));
            }
        }
        let mut geometry = self
            .geometry
            .write()
            .unwrap_or_else(PoisonError::into_inner);
        if !geometry.pose.as_ref().is_some_and(|p| p.time == time) {
            // The pose counts as held only once both tracers hold it.
            let g = &mut *geometry;
            let mut pose = g.pose.take().unwrap_or_default();
            animator.pose_into(time, &mut pose);
            for tracer in [&mut g.primary, &mut g.occlusion] {
                tracer
                    .apply_pose(&self.scene, animator.motion(), &pose)
                    .map_err(|e| {
                        NetError::Config(format!("cannot pose the scene at {time} s: {e}"))
                    })?;
            }
            g.pose = Some(pose);
        }
        Ok(self.trace_in(&geometry, time, f))
    }

    /// `f` with the correction tracer over `geometry` at scene time `time`.
    fn trace_in<R>(
        &self,
        geometry: &PosedGeometry,
        time: f32,
        f: impl FnOnce(&CorrectionTracer<'_>) -> R,
    ) -> R {
        let settings = TraceSettings {
            sky: Vec3::from_array(psao_client::SKY_GREY),
            seed: self.seed,
            own_diffuse: self.lighting.is_none(),
            ..TraceSettings::default()
        };
        match self.lighting {
            None => {
                let shade = TracedAoShade {
                    tracer: &geometry.occlusion,
                    shading: Shading::default(),
                    radius: self.scene.ao_radius,
                    spp: self.ao_spp,
                    seed: self.seed,
                };
                self.trace_with(geometry, &shade, settings, f)
            }
            Some(lit) => {
                let lighting = DiffuseLighting::new(&self.scene, time, lit.bounces);
                let shade = GiShade {
                    tracer: &geometry.occlusion,
                    lighting: match &geometry.pose {
                        Some(pose) => lighting.posed(pose),
                        None => lighting,
                    },
                    paths: lit.paths,
                    seed: self.seed,
                };
                self.trace_with(geometry, &shade, settings, f)
            }
        }
    }

    /// `f` with the correction tracer over `geometry` shading diffuse surfaces with `shade`.
    fn trace_with<R>(
        &self,
        geometry: &PosedGeometry,
        shade: &dyn DiffuseShade,
        settings: TraceSettings,
        f: impl FnOnce(&CorrectionTracer<'_>) -> R,
    ) -> R {
        let tracer = CorrectionTracer::new(&self.scene, &geometry.primary, shade, settings);
        match &geometry.pose {
            Some(pose) => f(&tracer.posed(pose)),
            None => f(&tracer),
        }
    }
}

/// A read guard of `lock`, also after a panic elsewhere (a pose counts as held only once it
/// is fully applied).
fn read<T>(lock: &RwLock<T>) -> RwLockReadGuard<'_, T> {
    lock.read().unwrap_or_else(PoisonError::into_inner)
}

/// A client's latest camera, the frame it was sent for, and its camera age (how many times
/// the camera changed).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ClientCamera {
    pub(crate) latest: Option<(Camera, u32)>,
    pub(crate) age: u32,
}

impl ClientCamera {
    /// Take the client's camera message: a camera different from the last one (all fields but
    /// `frame` and `aspect`) advances the age.
    pub(crate) fn update(&mut self, msg: &CameraMsg) {
        let camera = view_of(msg).camera;
        if self.latest.is_some_and(|(c, _)| c != camera) {
            self.age = self.age.wrapping_add(1);
        }
        self.latest = Some((camera, msg.frame));
    }
}

/// The server's correction state of one client: its camera and camera age, its region queue
/// and its sample budget clock.
pub struct RemoteCorrections {
    samples_per_second: u32,
    /// The planner and the image size it was made for.
    planner: Option<(Planner, u32, u32)>,
    camera: ClientCamera,
    /// Budget ticks so far.
    ticks: u64,
    /// Samples sent so far.
    pub samples_sent: u64,
    /// What the client's corrections cost so far.
    pub counters: CorrectionCounters,
}

/// What a client's corrections cost on the server.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CorrectionCounters {
    /// Positions the client's sample budget paid for.
    pub budget: u64,
    /// Positions examined (a primary ray each, whether or not it showed the region's object
    /// and gave a sample): never more than `budget`.
    pub examined: u64,
    /// Regions dropped on arrival because the scene has no such object.
    pub regions_dropped: u64,
}

impl RemoteCorrections {
    /// A fresh state with a budget of `samples_per_second`.
    pub fn new(samples_per_second: u32) -> Self {
        Self {
            samples_per_second,
            planner: None,
            camera: ClientCamera::default(),
            ticks: 0,
            samples_sent: 0,
            counters: CorrectionCounters::default(),
        }
    }

    /// The client's new analysis of the scene `engine` traces (regions of objects it does not
    /// have are dropped); a new image size starts a new queue.
    pub fn regions(&mut self, msg: &RegionsMsg, engine: &CorrectionEngine) {
        let fresh =
            !matches!(&self.planner, Some((_, w, h)) if (*w, *h) == (msg.width, msg.height));
        if fresh {
            self.planner = Some((new_planner(msg.width, msg.height), msg.width, msg.height));
        }
        let (regions, dropped) = object_regions(msg, engine);
        self.counters.regions_dropped += dropped;
        if let Some((planner, _, _)) = &mut self.planner {
            planner.set_camera_age(self.camera.age);
            planner.analyze(&regions, self.camera.age);
        }
    }

    /// The client's camera; a camera different from the last one advances the camera age.
    pub fn camera(&mut self, msg: &CameraMsg) {
        self.camera.update(msg);
        if let Some((planner, _, _)) = &mut self.planner {
            planner.set_camera_age(self.camera.age);
        }
    }

    /// The budget of the next tick of a clock at `hz` ticks per second (the ticks' budgets
    /// add up to exactly `samples_per_second` per second).
    pub fn next_budget(&mut self, hz: u32) -> usize {
        let budget = budget_of_tick(self.samples_per_second, hz, &mut self.ticks);
        self.counters.budget += budget as u64;
        budget
    }

    /// Plan and trace up to `budget` samples for the current camera, in the scene at its
    /// frame's time (in parallel), examining at most `budget` positions (a position off its
    /// object costs its primary ray like one that gives a sample); `None` when there is
    /// nothing to do yet (no camera, no regions, or the queue is dry) or the scene cannot be
    /// posed (logged).
    pub fn trace(
        &mut self,
        engine: &CorrectionEngine,
        budget: usize,
        client_frame: Option<u32>,
    ) -> Option<SamplesMsg> {
        let (planner, w, h) = self.planner.as_mut()?;
        let (w, h) = (*w, *h);
        let (camera, frame) = self.camera.latest?;
        let age = self.camera.age;
        let budget = budget.min(MAX_SAMPLES);
        let examined = &mut self.counters.examined;
        let traced = engine.with_tracer(client_time(frame), |tracer| {
            let planned = planner.plan(budget, budget, |x, y, object| {
                *examined += 1;
                tracer.object_at(&camera, w, h, x, y) == object
            });
            planned
                .par_iter()
                .filter_map(|p| {
                    tracer.camera_sample(&camera, w, h, p.x, p.y, p.object, p.level, age)
                })
                .map(|s| sample_msg(&s))
                .collect::<Vec<_>>()
        });
        let samples = match traced {
            Ok(samples) => samples,
            Err(e) => {
                tracing::warn!("no corrections traced: {e}");
                return None;
            }
        };
        if samples.is_empty() {
            return None;
        }
        self.samples_sent += samples.len() as u64;
        Some(SamplesMsg {
            client_frame,
            camera_age: age,
            samples,
        })
    }
}

/// The budget of tick `*ticks` (then counted) of a clock at `hz` ticks per second for
/// `samples_per_second` (the ticks of a second add up to exactly the rate), at most
/// [`MAX_SAMPLES`].
pub(crate) fn budget_of_tick(samples_per_second: u32, hz: u32, ticks: &mut u64) -> usize {
    let (rate, hz) = (u64::from(samples_per_second), u64::from(hz.max(1)));
    let t = *ticks;
    *ticks += 1;
    (((t + 1) * rate / hz - t * rate / hz) as usize).min(MAX_SAMPLES)
}

/// The server's region queue for a client's `width × height` frames.
pub(crate) fn new_planner(width: u32, height: u32) -> Planner {
    Planner::new(
        hierarchy_for(width, height),
        DEFAULT_JOB_SIZE,
        DEFAULT_DECAY,
    )
}

/// The regions of a (validated) analysis as the planner takes them, without those of objects
/// that `engine`'s scene does not have (no pixel can show them: see [`is_object`]), and how
/// many were dropped (logged at debug level).
///
/// Nothing else needs dropping: the wire's validation keeps every rectangle inside the
/// message's image of at most [`psao_wire::MAX_REGION_IMAGE_SIDE`]² pixels (the largest
/// resolution `psao view` takes, [`crate::MAX_IMAGE_SIDE`]) and one object's regions from
/// overlapping, so a client's regions cover at most that area once per object of the scene:
/// the largest legitimate analysis, every object covering the whole image. Their area does
/// not bound the work they cause; the budget does (every examined position costs one sample
/// of it, [`RemoteCorrections::trace`] and [`psao_corrective::workers`]).
pub(crate) fn object_regions(
    msg: &RegionsMsg,
    engine: &CorrectionEngine,
) -> (Vec<ObjectRegion>, u64) {
    let (known, unknown): (Vec<&Region>, Vec<&Region>) = msg
        .regions
        .iter()
        .partition(|r| is_object(&engine.scene, r.object));
    if let Some(r) = unknown.first() {
        tracing::debug!(
            "dropped {} of {} regions: objects the scene does not have (e.g. {})",
            unknown.len(),
            msg.regions.len(),
            r.object
        );
    }
    let regions = known
        .into_iter()
        .map(|r| ObjectRegion {
            id: r.object,
            rect: PixelRect {
                x0: r.x0 as i32,
                y0: r.y0 as i32,
                x1: r.x1 as i32,
                y1: r.y1 as i32,
            },
            pixels: 0,
            saliency: 0.0,
            importance: 0.0,
            priority: r.priority,
        })
        .collect();
    (regions, unknown.len() as u64)
}

/// The wire form of a sample.
pub fn sample_msg(s: &Sample) -> SampleMsg {
    SampleMsg {
        object: s.object,
        level: s.level,
        position: s.position.to_array(),
        normal: s.normal.to_array(),
        ndotv: s.ndotv,
        color: s.color,
    }
}

/// Client-side settings of corrections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrectiveClientConfig {
    /// Client frames between analyses.
    pub analyze_every: u32,
    /// The sample cache's aging and size.
    pub cache: CacheConfig,
}

impl Default for CorrectiveClientConfig {
    fn default() -> Self {
        Self {
            analyze_every: DEFAULT_ANALYZE_EVERY,
            cache: CacheConfig::default(),
        }
    }
}

/// The client's frame that corrections are added to; it must match the server's engine
/// ([`CorrectionEngine::with_lighting`]), as it does when both follow the server's lighting
/// (a lit server sends irradiance records, and its clients show the lit composite).
///
/// - AO: the correction tracer shades the diffuse surfaces its rays reach as the AO
///   composite does (`base colour × (ambient × AO + sun)`), so a sample's correction is its
///   radiance minus the AO composite at its pixel.
/// - Lit: samples are the view-dependent part of the radiance, added over the lit composite,
///   of which each pixel they reach keeps its material's diffuse share
///   ([`psao_corrective::base::diffuse_keep`]).
#[derive(Clone, Copy, Debug)]
pub enum BaseFrame<'a> {
    /// The AO composite of the reconstructed AO per pixel, shown as it is.
    Ao(&'a [f32]),
    /// A lit composite (linear RGB, [`psao_client::composite_lit`]) is shown; `ao` is the
    /// reconstructed AO of the same frame.
    Lit {
        /// Reconstructed AO per pixel.
        ao: &'a [f32],
        /// The lit composite per pixel.
        lit: &'a [[f32; 3]],
    },
}

impl<'a> BaseFrame<'a> {
    /// The reconstructed AO per pixel.
    pub fn ao(&self) -> &'a [f32] {
        match *self {
            Self::Ao(ao) | Self::Lit { ao, .. } => ao,
        }
    }
}

/// One corrected client frame.
pub struct CorrectedFrame {
    /// Linear RGB: the client's frame with the cached samples splatted over it.
    pub image: Vec<[f32; 3]>,
    /// Samples drawn.
    pub drawn: usize,
    /// Cached samples dropped because their object moved into this frame.
    pub dropped: usize,
    /// A new analysis to send with the next camera, when one was due.
    pub regions: Option<RegionsMsg>,
    /// What an analysis of this frame reads (besides the image).
    shown: ShownFrame,
}

/// A shown frame's number, size, object id per pixel and moving objects.
struct ShownFrame {
    frame: u32,
    width: u32,
    height: u32,
    ids: Vec<u32>,
    moving: Vec<u32>,
}

impl CorrectedFrame {
    /// A copy of what an analysis of this frame reads, to analyse elsewhere (e.g. on another
    /// thread).
    pub fn analysis(&self) -> FrameAnalysis {
        FrameAnalysis {
            image: self.image.clone(),
            shown: ShownFrame {
                frame: self.shown.frame,
                width: self.shown.width,
                height: self.shown.height,
                ids: self.shown.ids.clone(),
                moving: self.shown.moving.clone(),
            },
        }
    }
}

/// A shown frame to analyse: its image, object ids and moving objects.
pub struct FrameAnalysis {
    image: Vec<[f32; 3]>,
    shown: ShownFrame,
}

impl FrameAnalysis {
    /// The regions and priorities of the frame (saliency and task importance per object,
    /// moving objects left out), as sent to the server.
    pub fn regions(&self) -> RegionsMsg {
        analysis_of(&self.image, &self.shown)
    }
}

/// The regions of a shown frame with `image` (see [`FrameAnalysis::regions`]).
fn analysis_of(image: &[[f32; 3]], shown: &ShownFrame) -> RegionsMsg {
    let (w, h) = (shown.width as usize, shown.height as usize);
    let map = saliency(&RgbImage {
        width: w,
        height: h,
        pixels: image.to_vec(),
    });
    let regions = analyze_tiles(
        &shown.ids,
        w,
        h,
        &map,
        DEFAULT_SALIENCY_WEIGHT,
        psao_wire::MAX_REGIONS,
    );
    RegionsMsg {
        frame: shown.frame,
        width: shown.width,
        height: shown.height,
        regions: regions
            .iter()
            .filter(|r| shown.moving.binary_search(&r.id).is_err())
            .map(|r| Region {
                object: r.id,
                x0: r.rect.x0 as u32,
                y0: r.rect.y0 as u32,
                x1: r.rect.x1 as u32,
                y1: r.rect.y1 as u32,
                priority: r.priority.clamp(0.0, 1.0),
            })
            .collect(),
    }
}

/// Which objects move, from the client's own animation of its scene at its frame times.
struct MotionWatch {
    animator: Animator,
    pose: ScenePose,
    /// Instance transforms at the last frame looked at.
    last: Vec<Affine3A>,
    /// That frame.
    frame: Option<u32>,
    /// Object ids (instance + 1), ascending, that moved into that frame.
    moving: Vec<u32>,
}

impl MotionWatch {
    /// A watch over `scene`'s animation; `None` for a static scene (or one whose animation
    /// cannot play, which the client's renderer reports).
    fn new(scene: &Scene) -> Option<Self> {
        let animator = Animator::new(scene).ok()?;
        animator.is_dynamic().then(|| Self {
            animator,
            pose: ScenePose::default(),
            last: Vec::new(),
            frame: None,
            moving: Vec::new(),
        })
    }

    /// Look at client frame `frame` (at `frame / 60` s): an object moves when its transform
    /// differs from the previous frame's, or when it deforms (skinned). The same frame twice
    /// changes nothing.
    fn look(&mut self, frame: u32) {
        if self.frame == Some(frame) {
            return;
        }
        self.animator.pose_into(client_time(frame), &mut self.pose);
        let motion = self.animator.motion();
        self.moving = (0..self.pose.transforms.len())
            .filter(|&i| {
                motion.get(i) == Some(&Motion::Skinned)
                    || self
                        .last
                        .get(i)
                        .is_some_and(|t| *t != self.pose.transforms[i])
            })
            .map(|i| i as u32 + 1)
            .collect();
        self.last.clone_from(&self.pose.transforms);
        self.frame = Some(frame);
    }

    fn is_moving(&self, object: u32) -> bool {
        self.moving.binary_search(&object).is_ok()
    }
}

/// The client's correction state: the sample cache and the analysis of its frames. Objects
/// that move are left out: their cached samples are dropped when they move, samples for them
/// are not stored while they move, and the analysis does not ask for them.
pub struct CorrectiveClient {
    config: CorrectiveClientConfig,
    width: u32,
    height: u32,
    cache: SampleCache,
    camera: Option<Camera>,
    /// The scene's motion, once a frame was seen (`None` inside: a static scene).
    motion: Option<Option<MotionWatch>>,
    /// Samples received so far.
    pub samples_received: u64,
    /// Samples received for moving objects and not stored.
    pub samples_discarded: u64,
}

impl CorrectiveClient {
    /// A fresh state for `width × height` frames.
    pub fn new(width: u32, height: u32, config: CorrectiveClientConfig) -> Result<Self, NetError> {
        if config.analyze_every == 0 {
            return Err(NetError::Config(
                "the analysis period must be at least 1 frame".into(),
            ));
        }
        let cache = SampleCache::new(config.cache, hierarchy_for(width, height))
            .map_err(|e| NetError::Config(format!("sample cache: {e}")))?;
        Ok(Self {
            config,
            width,
            height,
            cache,
            camera: None,
            motion: None,
            samples_received: 0,
            samples_discarded: 0,
        })
    }

    /// The camera of the next frame (as sent): a change ages the cache.
    pub fn camera(&mut self, msg: &CameraMsg) {
        let camera = view_of(msg).camera;
        let view = ScreenView::new(&camera, self.width, self.height);
        if self.camera.is_some_and(|c| c != camera) {
            self.cache.camera_changed(&view);
        }
        self.cache.set_view(&view);
        self.camera = Some(camera);
    }

    /// Store the server's samples (except those of objects moving at the last frame); a level
    /// the client's hierarchy lacks is an error.
    pub fn receive(&mut self, msg: &SamplesMsg) -> Result<(), NetError> {
        let moving = |object| matches!(&self.motion, Some(Some(m)) if m.is_moving(object));
        let samples: Vec<Sample> = msg
            .samples
            .iter()
            .filter(|s| !moving(s.object))
            .map(|s| Sample {
                position: Vec3::from_array(s.position),
                normal: Vec3::from_array(s.normal),
                ndotv: s.ndotv,
                color: s.color,
                object: s.object,
                level: s.level,
                age: msg.camera_age,
            })
            .collect();
        self.cache
            .insert(&samples)
            .map_err(|e| NetError::Protocol(format!("bad samples from the server: {e}")))?;
        self.samples_received += samples.len() as u64;
        self.samples_discarded += (msg.samples.len() - samples.len()) as u64;
        Ok(())
    }

    /// The cache.
    pub fn cache(&self) -> &SampleCache {
        &self.cache
    }

    /// Correct client frame `frame` (its G-buffer and AO, rasterized with the camera last
    /// given to [`Self::camera`], at `frame / 60` s): drop the cached samples of objects that
    /// moved into it, splat the cache over it, and analyse the result when an analysis is due
    /// (every `analyze_every` frames; moving objects left out).
    pub fn frame(
        &mut self,
        scene: &Scene,
        frame: u32,
        gbuffer: &GBuffer,
        base: BaseFrame<'_>,
    ) -> CorrectedFrame {
        let mut corrected = self.correct(scene, frame, gbuffer, base);
        if frame.is_multiple_of(self.config.analyze_every) {
            corrected.regions = Some(analysis_of(&corrected.image, &corrected.shown));
        }
        corrected
    }

    /// [`Self::frame`] without the analysis (the caller analyses [`CorrectedFrame::analysis`]
    /// when it wants to).
    pub fn correct(
        &mut self,
        scene: &Scene,
        frame: u32,
        gbuffer: &GBuffer,
        base: BaseFrame<'_>,
    ) -> CorrectedFrame {
        if self.motion.is_none() {
            let turn = self.cache.config().mirror_turn;
            self.cache.set_view_tolerances(view_tolerances(scene, turn));
        }
        let motion = self.motion.get_or_insert_with(|| MotionWatch::new(scene));
        let mut dropped = 0;
        if let Some(m) = motion {
            m.look(frame);
            if !m.moving.is_empty() {
                dropped = self.cache.drop_objects(|o| m.is_moving(o));
            }
        }
        let moving = motion
            .as_ref()
            .map(|m| m.moving.clone())
            .unwrap_or_default();
        let ids = object_ids(scene, gbuffer);
        let (mut image, keep) = match base {
            BaseFrame::Ao(ao) => (
                psao_client::composite(scene, gbuffer, ao, &Shading::default()),
                None,
            ),
            BaseFrame::Lit { lit, .. } => (
                lit.to_vec(),
                self.camera
                    .map(|c| diffuse_keep(scene, gbuffer, c.position)),
            ),
        };
        let diffuse = match keep {
            Some(_) => Vec::new(),
            None => image.clone(),
        };
        let drawn = match self.camera {
            Some(camera) => self.cache.splat(
                &ScreenView::new(&camera, gbuffer.width, gbuffer.height),
                &mut SplatTarget {
                    color: &mut image,
                    diffuse: &diffuse,
                    keep: keep.as_deref(),
                    ids: &ids,
                    gbuffer,
                },
            ),
            None => 0,
        };
        CorrectedFrame {
            image,
            drawn,
            dropped,
            regions: None,
            shown: ShownFrame {
                frame,
                width: gbuffer.width,
                height: gbuffer.height,
                ids,
                moving,
            },
        }
    }

    /// Hash of the correction state: the camera age and every cached sample, level by level
    /// in cache order (equal on two clients that received the same samples for the same
    /// cameras).
    pub fn state_hash(&self) -> u64 {
        let mut h = hash64(u64::from(self.cache.camera_age()) ^ 0x636f_7272);
        for level in 1..=self.cache_levels() {
            for s in self.cache.level(level) {
                let words = [
                    s.position.x,
                    s.position.y,
                    s.position.z,
                    s.normal.x,
                    s.normal.y,
                    s.normal.z,
                    s.ndotv,
                    s.color[0],
                    s.color[1],
                    s.color[2],
                ];
                for w in words {
                    h = hash64(h ^ u64::from(w.to_bits()));
                }
                h = hash64(h ^ (u64::from(s.object) << 32 | u64::from(s.level) << 24));
                h = hash64(h ^ u64::from(s.age));
            }
        }
        h
    }

    fn cache_levels(&self) -> u8 {
        hierarchy_for(self.width, self.height).levels()
    }
}

/// Settings of corrections in one place: the server's budget and tracer, the client's analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrectiveConfig {
    /// Samples per second per client.
    pub samples_per_second: u32,
    /// Milliseconds of worker tracing per server frame per client, when limited (threaded
    /// serving only).
    pub frame_ms: Option<f32>,
    /// AO rays per diffuse point the correction rays reach.
    pub ao_spp: u32,
    /// Light paths per diffuse point the correction rays reach, when the server is lit.
    pub light_paths: u32,
    /// The client's side.
    pub client: CorrectiveClientConfig,
}

impl Default for CorrectiveConfig {
    fn default() -> Self {
        Self {
            samples_per_second: DEFAULT_SAMPLES_PER_SECOND,
            frame_ms: None,
            ao_spp: 8,
            light_paths: DEFAULT_LIGHT_PATHS,
            client: CorrectiveClientConfig::default(),
        }
    }
}

/// Both ends of corrections in one process (`psao run --corrective`): every message between
/// them goes through the wire encoder and the hardened decoder, as over a connection.
pub struct InProcessCorrections {
    engine: CorrectionEngine,
    remote: RemoteCorrections,
    /// The client's half.
    pub client: CorrectiveClient,
    /// The client's latest analysis, sent with its next camera.
    pending: Option<RegionsMsg>,
}

/// What one frame's exchange moved.
#[derive(Clone, Copy, Debug, Default)]
pub struct Exchanged {
    /// Samples the client received.
    pub samples: usize,
    /// Bytes of the frames both ways (headers included).
    pub bytes: usize,
}

/// `message` through [`encode_frame`](psao_wire::encode_frame) and
/// [`decode_frame`](psao_wire::decode_frame) with `limit`; returns it and its frame's size.
fn over_the_wire(message: &Message, limit: u32) -> Result<(Message, usize), NetError> {
    let bytes = psao_wire::encode_frame(message)?;
    Ok((psao_wire::decode_frame(&bytes, limit)?, bytes.len()))
}

impl InProcessCorrections {
    /// Both halves for `width × height` frames of `scene` (the server half traces a clone of
    /// it, posed at each client frame's time), for a server with `lighting` (`None`: AO
    /// only).
    pub fn new(
        scene: &Scene,
        backend: Backend,
        seed: u64,
        width: u32,
        height: u32,
        config: &CorrectiveConfig,
        lighting: Option<&psao_server::LightingConfig>,
    ) -> Result<Self, NetError> {
        let engine = CorrectionEngine::new(Arc::new(scene.clone()), backend, config.ao_spp, seed)?
            .with_lighting(LitCorrections::of(lighting, config));
        Ok(Self {
            engine,
            remote: RemoteCorrections::new(config.samples_per_second),
            client: CorrectiveClient::new(width, height, config.client)?,
            pending: None,
        })
    }

    /// Client frame `frame` with `camera`: the client sends its pending regions and its
    /// camera, the server traces within the client's budget for one 60 Hz tick and sends the
    /// samples, the client stores them.
    pub fn exchange(&mut self, camera: &CameraMsg) -> Result<Exchanged, NetError> {
        let mut out = Exchanged::default();
        let limit = psao_wire::MAX_CLIENT_FRAME;
        if let Some(regions) = self.pending.take() {
            let (m, size) = over_the_wire(&Message::Regions(regions), limit)?;
            out.bytes += size;
            if let Message::Regions(r) = m {
                self.remote.regions(&r, &self.engine);
            }
        }
        let (m, size) = over_the_wire(&Message::Camera(*camera), limit)?;
        out.bytes += size;
        if let Message::Camera(c) = m {
            self.remote.camera(&c);
            self.client.camera(&c);
        }
        let budget = self.remote.next_budget(CLIENT_HZ);
        if let Some(samples) = self.remote.trace(&self.engine, budget, Some(camera.frame)) {
            let (m, size) = over_the_wire(&Message::Samples(samples), psao_wire::MAX_SERVER_FRAME)?;
            out.bytes += size;
            if let Message::Samples(s) = m {
                out.samples = s.samples.len();
                self.client.receive(&s)?;
            }
        }
        Ok(out)
    }

    /// Correct the client's frame (see [`CorrectiveClient::frame`]) and keep its analysis for
    /// the next exchange.
    pub fn correct(
        &mut self,
        scene: &Scene,
        frame: u32,
        gbuffer: &GBuffer,
        base: BaseFrame<'_>,
    ) -> CorrectedFrame {
        let mut corrected = self.client.frame(scene, frame, gbuffer, base);
        if let Some(r) = corrected.regions.take() {
            self.pending = Some(r.clone());
            corrected.regions = Some(r);
        }
        corrected
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_of_one_second_add_up_to_the_rate() {
        for (rate, hz) in [(6000, 60), (3000, 30), (7, 60), (1_000_003, 45)] {
            let mut r = RemoteCorrections::new(rate);
            let total: usize = (0..hz).map(|_| r.next_budget(hz)).sum();
            assert_eq!(total, rate as usize, "rate {rate} at {hz} Hz");
        }
    }

    /// A chrome ball that holds still for 0.5 s, moves for 0.5 s and holds still for 1 s
    /// (then loops), and a glossy box that never moves.
    fn animated_scene() -> Scene {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(
            &path,
            "[[asset]]\nfile = \"builtin:sphere\"\n\
             keys = { times = [0, 0.5, 1, 2], translation = [[-0.6, 0.5, 0], [-0.6, 0.5, 0], [-0.2, 0.5, 0], [-0.2, 0.5, 0]] }\n\
             [[asset]]\nfile = \"builtin:box\"\ntranslation = [0.9, 0.0, -0.5]\nscale = 0.8\n\
             [[material]]\nname = \"sphere\"\npreset = \"chrome\"\n\
             [[material]]\nname = \"box\"\npreset = \"glossy\"\n",
        )
        .unwrap();
        psao_scene::scene_file::load(&path).unwrap().scene
    }

    /// A chrome wall (a mirror) and a diffuse ball sliding in front of it within the first
    /// second, resting there for another.
    fn mirror_scene() -> Scene {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(
            &path,
            "[[asset]]\nfile = \"builtin:box\"\ntranslation = [0, 1, -1]\nscale = [3, 2, 0.1]\n\
             [[asset]]\nfile = \"builtin:sphere\"\n\
             keys = { times = [0, 1, 2], translation = [[-8, 1, 1], [0.6, 0.6, 1], [0.6, 0.6, 1]] }\n\
             [[material]]\nname = \"box\"\npreset = \"mirror\"\n",
        )
        .unwrap();
        psao_scene::scene_file::load(&path).unwrap().scene
    }

    #[test]
    fn corrections_are_traced_in_the_scene_posed_at_the_frame_time() {
        let scene = mirror_scene();
        let motion = Animator::new(&scene).unwrap().motion().to_vec();
        let mirror = motion.iter().position(|&m| m == Motion::Static).unwrap() as u32 + 1;
        let engine = |scene: Scene| CorrectionEngine::new(Arc::new(scene), Backend::Obvhs, 2, 7);
        let animated = engine(scene.clone()).unwrap();
        // The reference: a still scene built with every instance where it is at time `t`.
        let built_at = |t: f32| {
            let pose = scene.pose_at(t).unwrap();
            let mut built = scene.clone();
            for (instance, &transform) in built.instances.iter_mut().zip(&pose.transforms) {
                instance.transform = transform;
            }
            built.freeze();
            engine(built).unwrap()
        };
        let camera = Camera::look_at(Vec3::new(0.0, 1.0, 3.0), Vec3::new(0.0, 1.0, -1.0), 60.0);
        let (w, h) = (48u32, 27u32);
        let samples = |e: &CorrectionEngine, time: f32| {
            e.with_tracer(time, |t| {
                (0..(w * h) as i32)
                    .map(|i| {
                        t.camera_sample(&camera, w, h, i % w as i32, i / w as i32, mirror, 1, 0)
                    })
                    .collect::<Vec<_>>()
            })
            .unwrap()
        };
        let late = client_time(60);
        let at_late = samples(&animated, late);
        assert_eq!(at_late, samples(&built_at(late), 0.0));
        let at_start = samples(&animated, 0.0);
        assert_eq!(at_start, samples(&built_at(0.0), 0.0));
        assert_eq!(
            samples(&animated, late),
            at_late,
            "posed back to the same time"
        );
        let shown = at_late.iter().filter(|s| s.is_some()).count();
        let changed = at_late
            .iter()
            .zip(&at_start)
            .filter(|(a, b)| a != b)
            .count();
        assert!(
            shown > 100 && changed > 10,
            "{changed} of the mirror's {shown} samples show the ball"
        );
    }

    #[test]
    fn regions_of_objects_the_scene_cannot_show_are_dropped() {
        // Object 1 is the mirror; object 2 the diffuse ball (no corrections), 3 is no instance.
        let engine = CorrectionEngine::new(Arc::new(mirror_scene()), Backend::Obvhs, 1, 1).unwrap();
        let region = |object| Region {
            object,
            x0: 0,
            y0: 0,
            x1: 8,
            y1: 8,
            priority: 0.5,
        };
        let msg = RegionsMsg {
            frame: 0,
            width: 16,
            height: 16,
            regions: [3, 1, 2, u32::MAX].map(region).to_vec(),
        };
        let (kept, dropped) = object_regions(&msg, &engine);
        assert_eq!(kept.iter().map(|r| r.id).collect::<Vec<_>>(), [1]);
        assert_eq!(dropped, 3);
    }

    #[test]
    fn samples_of_moving_objects_are_dropped_and_not_asked_for() {
        let scene = animated_scene();
        let motion = Animator::new(&scene).unwrap().motion().to_vec();
        let ball = motion.iter().position(|&m| m == Motion::Rigid).unwrap() as u32 + 1;
        let (w, h) = (64, 36);
        let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.5), Vec3::new(0.0, 0.4, 0.0), 60.0);
        let gbuffer =
            psao_raster::rasterize(&scene, &camera, &psao_raster::RasterOptions::new(w, h));
        let ao = vec![1.0; (w * h) as usize];
        let config = CorrectiveClientConfig {
            analyze_every: 1,
            ..Default::default()
        };
        let mut client = CorrectiveClient::new(w, h, config).unwrap();
        let sample = |object| SampleMsg {
            object,
            level: 1,
            position: [0.0, 0.5, 0.0],
            normal: [0.0, 0.0, 1.0],
            ndotv: 0.9,
            color: [0.5; 3],
        };
        let samples = |objects: &[u32]| SamplesMsg {
            client_frame: None,
            camera_age: 0,
            samples: objects.iter().map(|&o| sample(o)).collect(),
        };
        let frame = |client: &mut CorrectiveClient, f: u32| {
            client.camera(&crate::convert::camera_msg(f, &camera, w as f32 / h as f32));
            let c = client.frame(&scene, f, &gbuffer, BaseFrame::Ao(&ao));
            // The objects asked for (each in one region per tile it covers).
            let mut asked: Vec<u32> = c
                .regions
                .unwrap()
                .regions
                .iter()
                .map(|r| r.object)
                .collect();
            asked.dedup();
            (c.dropped, asked)
        };
        let count = |client: &CorrectiveClient, object| {
            (1..=hierarchy_for(w, h).levels())
                .flat_map(|l| client.cache().level(l))
                .filter(|s| s.object == object)
                .count()
        };
        let (dropped, asked) = frame(&mut client, 0);
        assert_eq!(dropped, 0);
        assert_eq!(asked.len(), 2, "both objects in view: {asked:?}");
        assert!(asked.contains(&ball));
        let other = *asked.iter().find(|&&o| o != ball).unwrap();
        client.receive(&samples(&[ball, other, ball])).unwrap();
        // Frame 20 (0.33 s): nothing moved, nothing dropped.
        assert_eq!(frame(&mut client, 20), (0, asked.clone()));
        assert_eq!((count(&client, ball), count(&client, other)), (2, 1));
        // Frame 45 (0.75 s): the ball moves. Its samples go, it is not asked for, and new
        // samples of it are not stored.
        assert_eq!(frame(&mut client, 45), (2, vec![other]));
        client.receive(&samples(&[ball, other])).unwrap();
        assert_eq!((count(&client, ball), count(&client, other)), (0, 2));
        assert_eq!((client.samples_received, client.samples_discarded), (4, 1));
        // Frame 80 (1.33 s): it moved since frame 45; frame 90: it rests again.
        assert_eq!(frame(&mut client, 80).1, vec![other]);
        assert_eq!(frame(&mut client, 90), (0, asked));
        client.receive(&samples(&[ball])).unwrap();
        assert_eq!(count(&client, ball), 1);
    }

    /// Over a lit base a sample is the view-dependent part: its own pixel shows the kept
    /// diffuse share of the lit composite plus the sample (none of it on chrome, one minus
    /// the Fresnel reflectance on a glossy dielectric), pixels no sample reaches keep the lit composite; over the AO
    /// composite a sample's own pixel shows its radiance.
    #[test]
    fn a_lit_client_adds_view_dependent_samples_over_its_diffuse_share() {
        let scene = animated_scene();
        let (w, h) = (64, 36);
        let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.5), Vec3::new(0.0, 0.4, 0.0), 60.0);
        let gbuffer =
            psao_raster::rasterize(&scene, &camera, &psao_raster::RasterOptions::new(w, h));
        let ids = object_ids(&scene, &gbuffer);
        let material = |i: usize| &scene.materials[gbuffer.material(&scene, i).unwrap()];
        // The centre-most pixel of each object: the chrome ball and the glossy box.
        let pixel_of = |metal: bool| {
            (0..ids.len())
                .filter(|&i| ids[i] != 0 && (material(i).metallic > 0.5) == metal)
                .min_by_key(|&i| {
                    let (x, y) = ((i as u32 % w) as i32, (i as u32 / w) as i32);
                    (x - 32).pow(2) + (y - 18).pow(2)
                })
                .unwrap()
        };
        let (chrome, glossy) = (pixel_of(true), pixel_of(false));
        let levels = hierarchy_for(w, h).levels();
        let sample = |i: usize| SampleMsg {
            object: ids[i],
            level: levels,
            position: gbuffer.position[i].to_array(),
            normal: gbuffer.normal[i].to_array(),
            ndotv: 0.9,
            color: [0.2, 0.3, 0.4],
        };
        let msg = crate::convert::camera_msg(0, &camera, w as f32 / h as f32);
        let ao = vec![1.0; (w * h) as usize];
        let lit = vec![[0.5f32; 3]; (w * h) as usize];
        let corrected = |base: BaseFrame<'_>| {
            let mut client =
                CorrectiveClient::new(w, h, CorrectiveClientConfig::default()).unwrap();
            client.camera(&msg);
            client
                .receive(&SamplesMsg {
                    client_frame: None,
                    camera_age: 0,
                    samples: vec![sample(chrome), sample(glossy)],
                })
                .unwrap();
            let c = client.frame(&scene, 1, &gbuffer, base);
            assert_eq!(c.drawn, 2);
            c.image
        };
        let img = corrected(BaseFrame::Lit { ao: &ao, lit: &lit });
        let keep = diffuse_keep(&scene, &gbuffer, camera.position);
        assert_eq!(keep[chrome], 0.0);
        // A dielectric keeps 1 − its Fresnel reflectance: below 1, far below at grazing views.
        assert!(keep[glossy] > 0.0 && keep[glossy] < 1.0, "{}", keep[glossy]);
        for (i, k) in [(chrome, 0.0), (glossy, keep[glossy])] {
            for (c, s) in [0.2, 0.3, 0.4].into_iter().enumerate() {
                assert!((img[i][c] - (k * 0.5 + s)).abs() < 1e-6, "{:?}", img[i]);
            }
        }
        let untouched = (0..ids.len()).find(|&i| ids[i] == 0).unwrap();
        assert_eq!(img[untouched], [0.5; 3]);
        // Over the AO composite a sample carries its full radiance.
        let img = corrected(BaseFrame::Ao(&ao));
        assert_eq!(img[chrome], [0.2, 0.3, 0.4]);
        assert_eq!(img[glossy], [0.2, 0.3, 0.4]);
    }

    #[test]
    fn samples_of_levels_the_client_lacks_are_refused() {
        let mut c = CorrectiveClient::new(64, 36, CorrectiveClientConfig::default()).unwrap();
        let levels = hierarchy_for(64, 36).levels();
        let sample = |level| SampleMsg {
            object: 1,
            level,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            ndotv: 0.5,
            color: [0.5; 3],
        };
        let msg = |level| SamplesMsg {
            client_frame: None,
            camera_age: 0,
            samples: vec![sample(level)],
        };
        c.receive(&msg(levels)).unwrap();
        assert!(matches!(
            c.receive(&msg(levels + 1)),
            Err(NetError::Protocol(_))
        ));
        assert_eq!(c.cache().len(), 1);
        assert!(CorrectiveClient::new(
            64,
            36,
            CorrectiveClientConfig {
                analyze_every: 0,
                ..Default::default()
            }
        )
        .is_err());
    }
}
