//! One evaluation along one camera path: corrected frames at several sample budgets and
//! orderings against the reference, and a static-view convergence run per ordering.
//!
//! Budgets are samples per frame (deterministic per seed) or milliseconds of tracing per
//! frame (the paper's 1/f: jobs are traced, all threads at once, until the frame's time is
//! spent, so the result depends on the machine and its load). The scene is frozen by the
//! caller. Every analysis period the ordering assigns region priorities:
//! `saliency` (bottom-up saliency of the frame as shown blended with task importance),
//! `uniform` (all equal) or `random` (hashed from the seed, frame, object and region).
//! Regions are the objects' parts in the tiles of [`analyze_tiles`].

use std::ops::Range;
use std::str::FromStr;
use std::time::Instant;

use psao_corrective::attention::{analyze_tiles, ObjectRegion, DEFAULT_SALIENCY_WEIGHT};
use psao_corrective::base::{diffuse_keep, view_tolerances, GiShade, TracedAoShade};
use psao_corrective::cache::CacheConfig;
use psao_corrective::saliency::{saliency, Map};
use psao_corrective::schedule::{RegionOrder, DEFAULT_JOB_SIZE};
use psao_corrective::session::Corrector;
use psao_corrective::splat::{Sample, SplatTarget};
use psao_corrective::sqrt5::Hierarchy;
use psao_corrective::trace::{CorrectionTracer, DiffuseShade, TraceSettings};
use psao_scene::{CameraPath, Scene};
use psao_trace::ao::hash64;
use psao_trace::gi::DiffuseLighting;
use psao_trace::{Backend, GeometryMode, Tracer};
use rayon::prelude::*;
use serde::Serialize;

use super::dump::{dump_frame, DumpOf, FrameDump};
use super::frame::{frame_images, rgb_image, trace_sample, FrameImages, ReferenceShading};
use super::metrics::{centre_bias, frame_error, ErrorSums, FrameError, MeanError, Truth};
use super::worse::{error_change, Compared, ErrorChange};
use super::EvalError;

/// Mixed into the seed of the reference's paths, so they are independent of the base's.
const REFERENCE_SEED: u64 = 0x5245_4645_5245_4e43;

/// How regions are ordered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Order {
    /// Saliency blended with task importance (the paper).
    Saliency,
    /// Equal priorities.
    Uniform,
    /// Random priorities per analysis.
    Random,
}

impl FromStr for Order {
    type Err = EvalError;
    fn from_str(s: &str) -> Result<Self, EvalError> {
        match s.trim() {
            "saliency" => Ok(Order::Saliency),
            "uniform" => Ok(Order::Uniform),
            "random" => Ok(Order::Random),
            other => Err(EvalError::Config(format!(
                "unknown order '{other}' (saliency, uniform, random)"
            ))),
        }
    }
}

impl Order {
    /// The ordering's name.
    pub fn name(self) -> &'static str {
        match self {
            Order::Saliency => "saliency",
            Order::Uniform => "uniform",
            Order::Random => "random",
        }
    }
}

/// What a simulated viewer may trace per frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Budget {
    /// Samples (positions examined) per frame.
    Samples(usize),
    /// Milliseconds of tracing per frame.
    Ms(f64),
}

impl std::fmt::Display for Budget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Budget::Samples(n) => write!(f, "{n}"),
            Budget::Ms(ms) => write!(f, "{ms} ms"),
        }
    }
}

/// Settings of an evaluation.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Frames of the path evaluated (`None`: the first 48, or fewer on a shorter path).
    pub frames: Option<Range<u32>>,
    /// Budgets per frame.
    pub budgets: Vec<Budget>,
    /// Orderings.
    pub orders: Vec<Order>,
    /// Priority reduction per finished √5 level, in [0, 1).
    pub decay: f32,
    /// Frames between analyses.
    pub analyze_every: u32,
    /// AO rays per point of the base shading.
    pub ao_spp: u32,
    /// Frames of the static-view convergence run (0: none).
    pub static_frames: u32,
    /// Seed of every random choice.
    pub seed: u64,
    /// Largest turn of a mirror sample's view direction before it is dropped, in radians
    /// ([`psao_corrective::cache::view_tolerance`]; infinite: the paper's aging only).
    pub mirror_turn: f32,
    /// The lit session's base and the full reference (`None`: the AO composite, whose
    /// shading the reference shares on diffuse pixels).
    pub lighting: Option<GiEval>,
    /// Path frames whose corrected images and caches are dumped per ordering and budget
    /// ([`PathEval::dumps`]).
    pub dump_frames: Vec<u32>,
    /// Whether samples carry their full radiance, as corrections relative to the base at
    /// the pixel they land on (the splatting before view-dependent samples, kept to
    /// compare); false: the view-dependent part only, over the base of which each pixel
    /// keeps its material's diffuse share, as in the split
    /// ([`psao_corrective::splat::SplatTarget::keep`]), over either base.
    pub full_samples: bool,
}

/// A lit evaluation (`psao corrective eval --lighting gi`): the base frame is the lit
/// composite `base colour / π × E` with E path-traced per pixel with `base_paths` paths
/// (standing in for the client's shadow-mapped direct light plus the points' irradiance),
/// and the correction tracer shades the diffuse surfaces it reaches the same way; the
/// reference is `psao reference --lighting gi`'s diffuse lighting with `reference_paths`
/// paths (an independent seed) on diffuse pixels, and the correction tracer shading the
/// diffuse surfaces it reaches with that lighting on non-diffuse pixels (the reflected and
/// refracted paths), so diffuse pixels have an error of their own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GiEval {
    /// Indirect diffuse bounces (a fixed depth, as `psao_trace::gi`).
    pub bounces: u32,
    /// Paths per point of the base frame and of the samples' diffuse shading.
    pub base_paths: u32,
    /// Paths per point of the reference.
    pub reference_paths: u32,
}

impl EvalConfig {
    fn check(&self) -> Result<(), EvalError> {
        let bad = |m: &str| Err(EvalError::Config(m.into()));
        if self.width == 0 || self.height == 0 {
            return bad("the image size must be positive");
        }
        let positive = |b: &Budget| match *b {
            Budget::Samples(n) => n > 0,
            Budget::Ms(ms) => ms.is_finite() && ms > 0.0,
        };
        if self.budgets.is_empty() || !self.budgets.iter().all(positive) {
            return bad("the budgets must be positive sample counts or milliseconds");
        }
        if self.orders.is_empty() {
            return bad("at least one ordering is needed");
        }
        if self.analyze_every == 0 {
            return bad("the analysis period must be at least 1 frame");
        }
        if self.mirror_turn.is_nan() || self.mirror_turn < 0.0 {
            return bad("the mirror turn must be a non-negative angle");
        }
        if self
            .lighting
            .is_some_and(|g| g.base_paths == 0 || g.reference_paths == 0)
        {
            return bad("the lit base and reference need at least one path per point");
        }
        if !(0.0..1.0).contains(&self.decay) {
            return Err(EvalError::Config(format!(
                "the decay must be in [0, 1), got {}",
                self.decay
            )));
        }
        Ok(())
    }

    /// The frames evaluated on a path of `count` frames.
    pub fn frame_range(&self, count: u32) -> Result<Range<u32>, EvalError> {
        let range = self.frames.clone().unwrap_or(0..48.min(count));
        if range.is_empty() || range.end > count {
            return Err(EvalError::Config(format!(
                "the camera path has {count} frames (0..{count}); asked for {}..{}",
                range.start, range.end
            )));
        }
        Ok(range)
    }
}

/// The ray tracers an evaluation needs, built once per scene.
pub struct Tracers {
    /// Primary rays (and the path generator's casts).
    pub primary: Tracer,
    /// AO rays.
    pub occlusion: Tracer,
}

impl Tracers {
    /// The tracers of `scene` with the first compiled backend.
    pub fn new(scene: &Scene) -> Result<Self, EvalError> {
        let backend = Backend::compiled()[0];
        Ok(Self {
            primary: Tracer::new(backend, scene, GeometryMode::Primary)?,
            occlusion: Tracer::new(backend, scene, GeometryMode::Occlusion)?,
        })
    }
}

/// Average errors of one ordering and budget (0 samples: the base frame).
#[derive(Serialize, Clone, Debug)]
pub struct Row {
    /// Ordering (`base` for the base frame).
    pub order: String,
    /// Budget per frame.
    pub budget: Budget,
    /// Samples traced per frame, on average.
    pub traced_per_frame: f64,
    /// Share of the frames in which this frame has a lower PSNR than the base frame.
    pub worse_psnr_share: f64,
    /// Share of the frames in which this frame has a higher FLIP than the base frame.
    pub worse_flip_share: f64,
    /// The averages over the frames.
    #[serde(flatten)]
    pub error: MeanError,
}

/// One frame's errors of one ordering and budget.
#[derive(Serialize)]
pub struct FrameRow {
    /// Path frame.
    pub frame: u32,
    /// Ordering.
    pub order: String,
    /// Budget per frame.
    pub budget: Budget,
    /// The errors.
    #[serde(flatten)]
    pub error: FrameError,
    /// Cached samples after the frame.
    pub cache_size: usize,
    /// When the corrected frame is worse than the base frame (lower PSNR or higher FLIP):
    /// where its squared error changed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worse_pixels: Option<ErrorChange>,
}

/// The static-view run of one ordering.
#[derive(Serialize)]
pub struct Convergence {
    /// Ordering.
    pub order: String,
    /// Budget per frame.
    pub budget: Budget,
    /// Non-diffuse pixels of the view.
    pub non_diffuse_pixels: usize,
    /// Samples traced in all.
    pub samples_traced: usize,
    /// Whether every non-diffuse pixel equals the reference bit for bit at the end.
    pub bit_identical: bool,
    /// (samples so far, FLIP, saliency-weighted FLIP) after each frame.
    pub curve: Vec<(usize, f64, f64)>,
}

/// Timings of the run.
#[derive(Serialize)]
pub struct Timing {
    /// Samples traced per second of tracing.
    pub worker_samples_per_s: f64,
    /// Threads of the tracing pool.
    pub threads: usize,
    /// Mean aging time per camera change (ms).
    pub aging_ms: f64,
    /// Mean reprojection + splatting time per frame (ms).
    pub splat_ms: f64,
    /// Mean time of one saliency analysis (ms).
    pub analysis_ms: f64,
    /// Mean cache size.
    pub mean_cache_size: f64,
    /// Largest cache size.
    pub max_cache_size: usize,
}

/// The 8-bit sRGB images of the middle frame.
pub struct MiddleFrame {
    /// The base frame.
    pub base: Vec<u8>,
    /// The first ordering at the largest sample budget (else the first budget).
    pub corrected: Vec<u8>,
    /// The reference.
    pub reference: Vec<u8>,
}

/// The result of [`evaluate_path`].
#[derive(Serialize)]
pub struct PathEval {
    /// Path name.
    pub path: String,
    /// Frames evaluated.
    pub frames: Range<u32>,
    /// √5 levels.
    pub levels: u8,
    /// Averages per ordering and budget, base first.
    pub rows: Vec<Row>,
    /// Per-frame errors.
    pub per_frame: Vec<FrameRow>,
    /// Static-view runs (empty when `static_frames` is 0).
    pub convergence: Vec<Convergence>,
    /// Timings.
    pub timing: Timing,
    /// Images of the middle frame.
    #[serde(skip)]
    pub middle: Option<MiddleFrame>,
    /// The frames of [`EvalConfig::dump_frames`], per ordering and budget.
    #[serde(skip)]
    pub dumps: Vec<FrameDump>,
}

/// One simulated viewer.
struct Sim {
    order: Order,
    budget: Budget,
    corrector: Corrector,
    sums: ErrorSums,
    /// Samples traced on the path.
    traced: usize,
    /// Frames with a lower PSNR than the base frame.
    worse_psnr: usize,
    /// Frames with a higher FLIP than the base frame.
    worse_flip: usize,
}

/// Accumulated timings.
#[derive(Default)]
struct Clock {
    traced: usize,
    trace_s: f64,
    aging_ms: Vec<f64>,
    splat_ms: Vec<f64>,
    analysis_ms: Vec<f64>,
    cache_sizes: Vec<usize>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// What one evaluation shares across frames.
struct Context<'a> {
    config: &'a EvalConfig,
    scene: &'a Scene,
    base: &'a dyn DiffuseShade,
    tracer: &'a CorrectionTracer<'a>,
    reference: ReferenceShading<'a>,
    hierarchy: Hierarchy,
    centre: Vec<f32>,
}

impl Context<'_> {
    fn sim(&self, order: Order, budget: Budget) -> Result<Sim, EvalError> {
        let cache = CacheConfig {
            mirror_turn: self.config.mirror_turn,
            ..CacheConfig::default()
        };
        let mut corrector =
            Corrector::new(self.hierarchy, cache, DEFAULT_JOB_SIZE, self.config.decay)?;
        corrector.set_view_tolerances(view_tolerances(self.scene, cache.mirror_turn));
        corrector.set_order(match order {
            Order::Uniform => RegionOrder::Uniform,
            Order::Saliency | Order::Random => RegionOrder::Priority,
        });
        Ok(Sim {
            order,
            budget,
            corrector,
            sums: ErrorSums::default(),
            traced: 0,
            worse_psnr: 0,
            worse_flip: 0,
        })
    }

    fn frame(&self, camera: psao_scene::Camera, camera_age: u32) -> FrameImages {
        let c = self.config;
        let mut f = frame_images(
            self.scene,
            camera,
            camera_age,
            (c.width, c.height),
            self.base,
            &self.reference,
        );
        if !c.full_samples {
            f.keep = Some(diffuse_keep(self.scene, &f.gbuffer, camera.position));
        }
        f
    }

    fn error(&self, f: &FrameImages, test: &[[f32; 3]]) -> FrameError {
        frame_error(
            &Truth {
                reference_srgb: &f.reference_srgb,
                ids: &f.ids,
                saliency: &f.reference_saliency.values,
                centre: &self.centre,
                width: self.config.width,
                height: self.config.height,
            },
            test,
        )
    }
}

/// Region priorities for `order`; the saliency ordering analyses `shown`, the frame as the
/// viewer sees it now (base frame with the cached corrections splatted, as the paper's
/// analyzer reads the frame buffer).
fn priorities(
    order: Order,
    f: &FrameImages,
    shown: &[[f32; 3]],
    seed: u64,
    frame: u32,
    clock: &mut Clock,
) -> Vec<ObjectRegion> {
    let (w, h) = (f.gbuffer.width as usize, f.gbuffer.height as usize);
    let t = Instant::now();
    let sal = match order {
        Order::Saliency => saliency(&rgb_image(shown, w as u32, h as u32)),
        _ => Map {
            width: w,
            height: h,
            values: vec![0.0; w * h],
        },
    };
    let mut regions = analyze_tiles(&f.ids, w, h, &sal, DEFAULT_SALIENCY_WEIGHT, usize::MAX);
    if order == Order::Saliency {
        clock.analysis_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    for r in &mut regions {
        r.priority = match order {
            Order::Saliency => r.priority,
            Order::Uniform => 1.0,
            Order::Random => {
                let place = (r.rect.x0 as u64) << 32 | r.rect.y0 as u64;
                (hash64(seed ^ hash64(frame as u64 ^ hash64(r.id as u64 ^ hash64(place)))) >> 40)
                    as f32
                    / (1u64 << 24) as f32
            }
        };
    }
    regions
}

/// The frame as `corrector`'s viewer sees it: the base frame with the cache splatted.
fn splatted(corrector: &Corrector, f: &FrameImages) -> Vec<[f32; 3]> {
    let mut color = f.base.clone();
    corrector.splat(
        &f.view,
        &mut SplatTarget {
            color: &mut color,
            diffuse: &f.base,
            keep: f.keep.as_deref(),
            ids: &f.ids,
            gbuffer: &f.gbuffer,
        },
    );
    color
}

/// Plans `positions` of `sim`'s queue, traces them on all threads and caches the samples;
/// false when the queue had nothing to plan.
fn trace_batch(
    sim: &mut Sim,
    f: &FrameImages,
    tracer: &CorrectionTracer<'_>,
    positions: usize,
    clock: &mut Clock,
) -> Result<bool, EvalError> {
    let planned = sim
        .corrector
        .plan(&f.ids, f.gbuffer.width as usize, positions);
    let t = Instant::now();
    let samples: Vec<Sample> = planned
        .par_iter()
        .map(|p| trace_sample(tracer, f, p))
        .collect();
    clock.trace_s += t.elapsed().as_secs_f64();
    clock.traced += samples.len();
    sim.traced += samples.len();
    sim.corrector.add(&samples)?;
    Ok(!planned.is_empty())
}

/// One frame of one simulated viewer: plan and trace within its budget, cache, splat;
/// returns the corrected frame. A time budget is spent in batches of one job per thread.
fn step(
    sim: &mut Sim,
    f: &FrameImages,
    tracer: &CorrectionTracer<'_>,
    clock: &mut Clock,
) -> Result<Vec<[f32; 3]>, EvalError> {
    match sim.budget {
        Budget::Samples(n) => {
            trace_batch(sim, f, tracer, n, clock)?;
        }
        Budget::Ms(ms) => {
            let batch = DEFAULT_JOB_SIZE as usize * rayon::current_num_threads();
            let start = Instant::now();
            while start.elapsed().as_secs_f64() * 1e3 < ms
                && trace_batch(sim, f, tracer, batch, clock)?
            {}
        }
    }
    let t = Instant::now();
    let color = splatted(&sim.corrector, f);
    clock.splat_ms.push(t.elapsed().as_secs_f64() * 1e3);
    clock.cache_sizes.push(sim.corrector.cache().len());
    Ok(color)
}

/// Evaluates `config` along `path` in `scene` (frozen by the caller) with `tracers` of it;
/// `tick` is called after each path frame.
pub fn evaluate_path(
    scene: &Scene,
    tracers: &Tracers,
    path: &CameraPath,
    config: &EvalConfig,
    tick: &mut dyn FnMut(),
) -> Result<PathEval, EvalError> {
    config.check()?;
    let range = config.frame_range(path.frame_count() as u32)?;
    let ao = TracedAoShade {
        tracer: &tracers.occlusion,
        shading: psao_client::Shading::default(),
        radius: scene.ao_radius,
        spp: config.ao_spp,
        seed: config.seed,
    };
    // The lit base and the reference's lighting: the same lights and bounces, independent
    // paths.
    let lit = config.lighting.map(|g| {
        let shade = |paths, seed| GiShade {
            tracer: &tracers.occlusion,
            lighting: DiffuseLighting::new(scene, 0.0, g.bounces),
            paths,
            seed,
        };
        (
            shade(g.base_paths, config.seed),
            shade(g.reference_paths, hash64(config.seed ^ REFERENCE_SEED)),
        )
    });
    let base: &dyn DiffuseShade = match &lit {
        Some((b, _)) => b,
        None => &ao,
    };
    let settings = TraceSettings {
        sky: glam::Vec3::from_array(psao_client::SKY_GREY),
        seed: config.seed,
        ..TraceSettings::default()
    };
    // Samples are the view-dependent part (unless compared as before).
    let sample_settings = TraceSettings {
        own_diffuse: config.full_samples,
        ..settings
    };
    let tracer = CorrectionTracer::new(scene, &tracers.primary, base, sample_settings);
    // The reference is the full radiance, its diffuse surfaces shaded as the base (AO) or
    // with the reference's lighting (lit).
    let reference_shade: &dyn DiffuseShade = lit.as_ref().map_or(base, |(_, r)| r);
    let reference_tracer =
        CorrectionTracer::new(scene, &tracers.primary, reference_shade, settings);
    let cx = Context {
        config,
        scene,
        base,
        tracer: &tracer,
        reference: ReferenceShading {
            tracer: &reference_tracer,
            diffuse: lit.as_ref().map(|(_, r)| r as &dyn DiffuseShade),
        },
        hierarchy: Hierarchy::for_spacing(config.width.min(config.height) as f32 / 4.0),
        centre: centre_bias(config.width, config.height),
    };
    let mut sims = Vec::new();
    for &order in &config.orders {
        for &budget in &config.budgets {
            sims.push(cx.sim(order, budget)?);
        }
    }
    let shown_budget = (config.budgets.iter())
        .filter_map(|b| match *b {
            Budget::Samples(n) => Some(n),
            Budget::Ms(_) => None,
        })
        .max()
        .map_or(config.budgets[0], Budget::Samples);
    let mut base_sums = ErrorSums::default();
    let mut per_frame = Vec::new();
    let mut clock = Clock::default();
    let mut camera_age = 0u32;
    let mut previous = None;
    let show = range.start + (range.end - range.start) / 2;
    let mut middle = None;
    let mut dumps = Vec::new();
    for frame in range.clone() {
        let camera = path.camera_at_frame(frame as usize);
        let moved = previous.is_some_and(|p| p != camera);
        if moved {
            camera_age += 1;
        }
        previous = Some(camera);
        let f = cx.frame(camera, camera_age);
        let base_err = cx.error(&f, &f.base);
        base_sums.add(&base_err);
        per_frame.push(FrameRow {
            frame,
            order: "base".into(),
            budget: Budget::Samples(0),
            error: base_err,
            cache_size: 0,
            worse_pixels: None,
        });
        let analyze_now = (frame - range.start) % config.analyze_every == 0;
        for sim in &mut sims {
            if moved {
                let t = Instant::now();
                sim.corrector.camera_changed(&f.view);
                clock.aging_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            sim.corrector.set_view(&f.view);
            if analyze_now {
                let now = splatted(&sim.corrector, &f);
                let regions = priorities(sim.order, &f, &now, config.seed, frame, &mut clock);
                sim.corrector.analyze(&regions);
            }
            let corrected = step(sim, &f, &tracer, &mut clock)?;
            let e = cx.error(&f, &corrected);
            sim.sums.add(&e);
            sim.worse_psnr += usize::from(e.psnr < base_err.psnr);
            sim.worse_flip += usize::from(e.flip > base_err.flip);
            per_frame.push(FrameRow {
                frame,
                order: sim.order.name().into(),
                budget: sim.budget,
                error: e,
                cache_size: sim.corrector.cache().len(),
                worse_pixels: (e.psnr < base_err.psnr || e.flip > base_err.flip).then(|| {
                    error_change(&Compared {
                        reference_srgb: &f.reference_srgb,
                        reference: &f.reference,
                        base: &f.base,
                        corrected: &corrected,
                        ids: &f.ids,
                        width: config.width as usize,
                    })
                }),
            });
            if config.dump_frames.contains(&frame) {
                let what = DumpOf {
                    path: &path.name,
                    frame,
                    order: sim.order.name(),
                    budget: sim.budget,
                };
                dumps.push(dump_frame(&what, &f, &corrected, &sim.corrector));
            }
            if frame == show && sim.budget == shown_budget && sim.order == config.orders[0] {
                middle = Some(MiddleFrame {
                    base: psao_client::composite_srgb8(&f.base),
                    corrected: psao_client::composite_srgb8(&corrected),
                    reference: f.reference_srgb.clone(),
                });
            }
        }
        tick();
    }
    let frames = f64::from(range.end - range.start);
    let mut rows = vec![Row {
        order: "base".into(),
        budget: Budget::Samples(0),
        traced_per_frame: 0.0,
        worse_psnr_share: 0.0,
        worse_flip_share: 0.0,
        error: base_sums.mean(),
    }];
    rows.extend(sims.iter().map(|s| Row {
        order: s.order.name().into(),
        budget: s.budget,
        traced_per_frame: s.traced as f64 / frames,
        worse_psnr_share: s.worse_psnr as f64 / frames,
        worse_flip_share: s.worse_flip as f64 / frames,
        error: s.sums.mean(),
    }));
    let camera = path.camera_at_frame(range.start as usize);
    let convergence = static_convergence(&cx, camera, &mut clock)?;
    let timing = Timing {
        worker_samples_per_s: clock.traced as f64 / clock.trace_s.max(1e-9),
        threads: rayon::current_num_threads(),
        aging_ms: mean(&clock.aging_ms),
        splat_ms: mean(&clock.splat_ms),
        analysis_ms: mean(&clock.analysis_ms),
        mean_cache_size: clock.cache_sizes.iter().sum::<usize>() as f64
            / clock.cache_sizes.len().max(1) as f64,
        max_cache_size: clock.cache_sizes.iter().copied().max().unwrap_or(0),
    };
    Ok(PathEval {
        path: path.name.clone(),
        frames: range,
        levels: cx.hierarchy.levels(),
        rows,
        per_frame,
        convergence,
        timing,
        middle,
        dumps,
    })
}

/// The static-view run: `camera`, the first budget, per ordering.
fn static_convergence(
    cx: &Context<'_>,
    camera: psao_scene::Camera,
    clock: &mut Clock,
) -> Result<Vec<Convergence>, EvalError> {
    let config = cx.config;
    if config.static_frames == 0 {
        return Ok(Vec::new());
    }
    let f = cx.frame(camera, 0);
    let non_diffuse = f.ids.iter().filter(|&&i| i != 0).count();
    let budget = config.budgets[0];
    let mut out = Vec::new();
    for &order in &config.orders {
        let mut sim = cx.sim(order, budget)?;
        let mut curve = Vec::new();
        let mut traced = 0;
        let mut last = f.base.clone();
        sim.corrector.set_view(&f.view);
        for i in 0..config.static_frames {
            if i % config.analyze_every == 0 {
                let now = splatted(&sim.corrector, &f);
                let regions = priorities(order, &f, &now, config.seed, i, clock);
                sim.corrector.analyze(&regions);
            }
            let before = sim.corrector.cache().len();
            last = step(&mut sim, &f, cx.tracer, clock)?;
            traced += sim.corrector.cache().len() - before;
            let e = cx.error(&f, &last);
            curve.push((traced, e.flip, e.saliency_flip));
        }
        let bit_identical = (0..f.ids.len())
            .filter(|&i| f.ids[i] != 0)
            .all(|i| last[i] == f.reference[i]);
        out.push(Convergence {
            order: order.name().into(),
            budget,
            non_diffuse_pixels: non_diffuse,
            samples_traced: traced,
            bit_identical,
            curve,
        });
    }
    Ok(out)
}
