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

use std::sync::Arc;

use glam::Vec3;
use psao_client::Shading;
use psao_corrective::attention::{analyze, DEFAULT_SALIENCY_WEIGHT};
use psao_corrective::base::{object_ids, TracedAoShade};
use psao_corrective::cache::{CacheConfig, SampleCache};
use psao_corrective::saliency::{saliency, RgbImage};
use psao_corrective::schedule::{DEFAULT_DECAY, DEFAULT_JOB_SIZE};
use psao_corrective::screen::ScreenView;
use psao_corrective::session::Planner;
use psao_corrective::splat::{Sample, SplatTarget};
use psao_corrective::sqrt5::{Hierarchy, PixelRect};
use psao_corrective::trace::{CorrectionTracer, TraceSettings};
use psao_raster::GBuffer;
use psao_scene::{Camera, Scene};
use psao_trace::ao::hash64;
use psao_trace::{Backend, GeometryMode, Tracer};
use psao_wire::{CameraMsg, Message, Region, RegionsMsg, SampleMsg, SamplesMsg, MAX_SAMPLES};
use rayon::prelude::*;

use crate::convert::view_of;
use crate::NetError;

/// Default sample budget per client and second (the paper: 10 000–50 000 per second on 2–6
/// processors; our tracer does about 10 000 per second on 2 cores).
pub const DEFAULT_SAMPLES_PER_SECOND: u32 = 6000;
/// Default client frames between analyses (0.3 s at 60 Hz).
pub const DEFAULT_ANALYZE_EVERY: u32 = 18;
/// Positions examined per sample of the budget at most in one planning (positions off their
/// object cost one primary ray each and are not traced).
const EXAMINE_PER_SAMPLE: usize = 16;

/// The √5 hierarchy both ends use for a `width × height` image: the coarsest spacing about a
/// quarter of the shorter side.
pub fn hierarchy_for(width: u32, height: u32) -> Hierarchy {
    Hierarchy::for_spacing(width.min(height) as f32 / 4.0)
}

/// What the server traces with: the scene at rest and its tracers.
pub struct CorrectionEngine {
    scene: Arc<Scene>,
    primary: Tracer,
    occlusion: Tracer,
    ao_spp: u32,
    seed: u64,
}

impl CorrectionEngine {
    /// Tracers over `scene` (its instances at their stored transforms) on `backend`;
    /// `ao_spp` AO rays per diffuse point reached, `seed` for every random choice.
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
        let primary = tracer(GeometryMode::Primary)?;
        let occlusion = tracer(GeometryMode::Occlusion)?;
        Ok(Self {
            scene,
            primary,
            occlusion,
            ao_spp: ao_spp.max(1),
            seed,
        })
    }

    /// Runs `f` with the correction tracer (diffuse surfaces shaded as the client shades
    /// them, AO traced with the DESIGN §2 estimator).
    fn with_tracer<R>(&self, f: impl FnOnce(&CorrectionTracer<'_>) -> R) -> R {
        let shade = TracedAoShade {
            tracer: &self.occlusion,
            shading: Shading::default(),
            radius: self.scene.ao_radius,
            spp: self.ao_spp,
            seed: self.seed,
        };
        let settings = TraceSettings {
            sky: Vec3::from_array(psao_client::SKY_GREY),
            seed: self.seed,
            ..TraceSettings::default()
        };
        let tracer = CorrectionTracer::new(&self.scene, &self.primary, &shade, settings);
        f(&tracer)
    }
}

/// The server's correction state of one client: its camera and camera age, its region queue
/// and its sample budget clock.
pub struct RemoteCorrections {
    samples_per_second: u32,
    /// The planner and the image size it was made for.
    planner: Option<(Planner, u32, u32)>,
    camera: Option<Camera>,
    camera_age: u32,
    /// Budget ticks so far.
    ticks: u64,
    /// Samples sent so far.
    pub samples_sent: u64,
}

impl RemoteCorrections {
    /// A fresh state with a budget of `samples_per_second`.
    pub fn new(samples_per_second: u32) -> Self {
        Self {
            samples_per_second,
            planner: None,
            camera: None,
            camera_age: 0,
            ticks: 0,
            samples_sent: 0,
        }
    }

    /// The client's new analysis; a new image size starts a new queue.
    pub fn regions(&mut self, msg: &RegionsMsg) {
        let fresh =
            !matches!(&self.planner, Some((_, w, h)) if (*w, *h) == (msg.width, msg.height));
        if fresh {
            let hierarchy = hierarchy_for(msg.width, msg.height);
            self.planner = Some((
                Planner::new(hierarchy, DEFAULT_JOB_SIZE, DEFAULT_DECAY),
                msg.width,
                msg.height,
            ));
        }
        let regions: Vec<_> = msg
            .regions
            .iter()
            .map(|r| psao_corrective::attention::ObjectRegion {
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
        if let Some((planner, _, _)) = &mut self.planner {
            planner.analyze(&regions, self.camera_age);
        }
    }

    /// The client's camera; a camera different from the last one advances the camera age.
    pub fn camera(&mut self, msg: &CameraMsg) {
        let camera = view_of(msg).camera;
        if self.camera.is_some_and(|c| c != camera) {
            self.camera_age = self.camera_age.wrapping_add(1);
        }
        self.camera = Some(camera);
    }

    /// The budget of the next tick of a clock at `hz` ticks per second (the ticks' budgets
    /// add up to exactly `samples_per_second` per second).
    pub fn next_budget(&mut self, hz: u32) -> usize {
        let (rate, hz) = (u64::from(self.samples_per_second), u64::from(hz.max(1)));
        let t = self.ticks;
        self.ticks += 1;
        (((t + 1) * rate / hz - t * rate / hz) as usize).min(MAX_SAMPLES)
    }

    /// Plan and trace up to `budget` samples for the current camera (in parallel); `None`
    /// when there is nothing to do yet (no camera, no regions, or the queue is dry).
    pub fn trace(
        &mut self,
        engine: &CorrectionEngine,
        budget: usize,
        client_frame: Option<u32>,
    ) -> Option<SamplesMsg> {
        let (planner, w, h) = self.planner.as_mut()?;
        let (w, h) = (*w, *h);
        let camera = self.camera?;
        let age = self.camera_age;
        let budget = budget.min(MAX_SAMPLES);
        let samples: Vec<SampleMsg> = engine.with_tracer(|tracer| {
            let examine = budget.saturating_mul(EXAMINE_PER_SAMPLE) + DEFAULT_JOB_SIZE as usize;
            let planned = planner.plan(budget, examine, |x, y, object| {
                tracer.object_at(&camera, w, h, x, y) == object
            });
            planned
                .par_iter()
                .filter_map(|p| {
                    tracer.camera_sample(&camera, w, h, p.x, p.y, p.object, p.level, age)
                })
                .map(|s| sample_msg(&s))
                .collect()
        });
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

/// One corrected client frame.
pub struct CorrectedFrame {
    /// Linear RGB: the client's frame with the cached samples splatted over it.
    pub image: Vec<[f32; 3]>,
    /// Samples drawn.
    pub drawn: usize,
    /// A new analysis to send with the next camera, when one was due.
    pub regions: Option<RegionsMsg>,
}

/// The client's correction state: the sample cache and the analysis of its frames.
pub struct CorrectiveClient {
    config: CorrectiveClientConfig,
    width: u32,
    height: u32,
    cache: SampleCache,
    camera: Option<Camera>,
    /// Samples received so far.
    pub samples_received: u64,
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
            samples_received: 0,
        })
    }

    /// The camera of the next frame (as sent): a change ages the cache.
    pub fn camera(&mut self, msg: &CameraMsg) {
        let camera = view_of(msg).camera;
        if self.camera.is_some_and(|c| c != camera) {
            self.cache
                .camera_changed(&ScreenView::new(&camera, self.width, self.height));
        }
        self.camera = Some(camera);
    }

    /// Store the server's samples; a level the client's hierarchy lacks is an error.
    pub fn receive(&mut self, msg: &SamplesMsg) -> Result<(), NetError> {
        let samples: Vec<Sample> = msg
            .samples
            .iter()
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
        Ok(())
    }

    /// The cache.
    pub fn cache(&self) -> &SampleCache {
        &self.cache
    }

    /// Correct client frame `frame` (its G-buffer and AO, rasterized with the camera last
    /// given to [`Self::camera`]): splat the cache over it, and analyse the result when an
    /// analysis is due.
    pub fn frame(
        &self,
        scene: &Scene,
        frame: u32,
        gbuffer: &GBuffer,
        ao: &[f32],
    ) -> CorrectedFrame {
        let mut image = psao_client::composite(scene, gbuffer, ao, &Shading::default());
        let ids = object_ids(scene, gbuffer);
        let mut written = vec![false; image.len()];
        let drawn = match self.camera {
            Some(camera) => self.cache.splat(
                &ScreenView::new(&camera, gbuffer.width, gbuffer.height),
                &mut SplatTarget {
                    color: &mut image,
                    written: &mut written,
                    ids: &ids,
                    depth: &gbuffer.depth,
                },
            ),
            None => 0,
        };
        let regions = frame.is_multiple_of(self.config.analyze_every).then(|| {
            let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
            let map = saliency(&RgbImage {
                width: w,
                height: h,
                pixels: image.clone(),
            });
            let regions = analyze(&ids, w, h, &map, DEFAULT_SALIENCY_WEIGHT);
            RegionsMsg {
                frame,
                width: gbuffer.width,
                height: gbuffer.height,
                regions: regions
                    .iter()
                    .take(psao_wire::MAX_REGIONS)
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
        });
        CorrectedFrame {
            image,
            drawn,
            regions,
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
    /// AO rays per diffuse point the correction rays reach.
    pub ao_spp: u32,
    /// The client's side.
    pub client: CorrectiveClientConfig,
}

impl Default for CorrectiveConfig {
    fn default() -> Self {
        Self {
            samples_per_second: DEFAULT_SAMPLES_PER_SECOND,
            ao_spp: 8,
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
    /// Both halves for `width × height` frames of `scene` (a clone of it, at rest, is traced).
    pub fn new(
        scene: &Scene,
        backend: Backend,
        seed: u64,
        width: u32,
        height: u32,
        config: &CorrectiveConfig,
    ) -> Result<Self, NetError> {
        let mut frozen = scene.clone();
        frozen.freeze();
        Ok(Self {
            engine: CorrectionEngine::new(Arc::new(frozen), backend, config.ao_spp, seed)?,
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
                self.remote.regions(&r);
            }
        }
        let (m, size) = over_the_wire(&Message::Camera(*camera), limit)?;
        out.bytes += size;
        if let Message::Camera(c) = m {
            self.remote.camera(&c);
            self.client.camera(&c);
        }
        let budget = self.remote.next_budget(crate::pipeline::CLIENT_HZ);
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
        ao: &[f32],
    ) -> CorrectedFrame {
        let mut corrected = self.client.frame(scene, frame, gbuffer, ao);
        if let Some(r) = corrected.regions.take() {
            self.pending = Some(r.clone());
            corrected.regions = Some(r);
        }
        corrected
    }
}
