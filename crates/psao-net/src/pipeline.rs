//! The in-process split pipeline: a server and one client exchanging encoded bytes.
//!
//! Nothing goes around the codec: the client's state is built only from decoded updates.

use crate::corrective::{BaseFrame, CorrectiveClient, CorrectiveConfig, InProcessCorrections};
use crate::{NetError, Resolution};
use glam::Vec3;
use psao_client::{ClientState, DetailSettings, ReconstructSettings, Shading};
use psao_delta::Codec;
use psao_eval::AoImage;
use psao_raster::{GBuffer, InstancePose, RasterOptions, Rasterizer, ShadowMaps, ShadowSettings};
use psao_scene::{Animator, Camera, Motion, Scene, ScenePose};
use psao_server::{ClientId, Server, ServerConfig, View};
use psao_trace::ao::Medium;
use psao_wire::RelightingMsg;

use crate::relit::RelitCharacters;
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// Client frames per second of scene time (camera paths are sampled at this rate).
pub const CLIENT_HZ: u32 = 60;

/// The scene time of client frame `frame` (a client plays its scene at [`CLIENT_HZ`]).
pub fn client_time(frame: u32) -> f32 {
    frame as f32 / CLIENT_HZ as f32
}

/// Settings of one pipeline run.
#[derive(Clone, Debug)]
pub struct PipelineConfig {
    /// Server settings (density, budget, thresholds, backend, seed).
    pub server: ServerConfig,
    /// Server frames per second of scene time (divides into the 60 Hz client clock).
    pub server_hz: u32,
    /// Codec name (`paper`).
    pub codec: String,
    /// Client image size.
    pub res: Resolution,
    /// The participating medium the server's AO rays pass through (the scene's volume).
    pub medium: Option<Arc<dyn Medium>>,
    /// Folder of stored start points ([`crate::start_cache`]); `None` generates them afresh.
    pub points_cache: Option<std::path::PathBuf>,
    /// The client's screen-space contact term below the point spacing
    /// ([`psao_client::apply_detail`]); `None` (the default) leaves it out.
    pub detail: Option<DetailSettings>,
    /// The client's reconstruction settings (default: [`ReconstructSettings::default`]).
    pub reconstruct: ReconstructSettings,
    /// Corrective splatting ([`crate::corrective`]), when wanted.
    pub corrective: Option<CorrectiveConfig>,
}

/// What happened in one client frame.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FrameRecord {
    /// Client frame number on the camera path.
    pub frame: u32,
    /// Whether the server ran a frame (and sent an update) at this client frame.
    pub server_frame: bool,
    /// Bytes the client received in this frame.
    pub bytes: usize,
    /// Points whose published value changed on the server in this frame.
    pub changed_points: usize,
    /// Cells sent in this frame.
    pub changed_cells: usize,
    /// Rays the server traced in this frame.
    pub rays: u64,
    /// Light paths the server traced in this frame (with lighting, docs/LIGHTING.md), and
    /// their rays (not included in `rays`).
    pub light_paths: u64,
    pub light_rays: u64,
    /// Points the server restarted because geometry near them moved.
    pub invalidated_points: usize,
    /// Restarted points the server traced in this frame, and their rays.
    pub retraced_points: usize,
    pub retrace_rays: u64,
    /// Part of `server_ms` spent posing the scene and invalidating points.
    pub animate_ms: f64,
    /// Server time (step + delta + encode) in ms.
    pub server_ms: f64,
    /// Part of `server_ms` spent encoding the update.
    pub encode_ms: f64,
    /// Client time (decode + apply + rasterize + reconstruct) in ms; 0 when nothing was rendered.
    pub client_ms: f64,
    /// Correction samples received in this frame.
    pub samples: usize,
    /// Bytes of the correction messages (both ways) in this frame.
    pub sample_bytes: usize,
    /// Server time tracing corrections, ms.
    pub corrective_ms: f64,
}

/// One rendered client frame.
pub struct ClientFrame {
    /// The G-buffer it was reconstructed on.
    pub gbuffer: GBuffer,
    /// Reconstructed AO.
    pub ao: AoImage,
    /// With corrections: the client's frame (linear RGB, [`Self::base`]) with the cached
    /// samples' corrections added.
    pub corrected: Option<Vec<[f32; 3]>>,
    /// With lighting (the client state holds irradiance records): the lit composite, linear
    /// RGB radiance ([`psao_client::composite_lit`]).
    pub lit: Option<Vec<[f32; 3]>>,
    /// With relit characters and without lighting: per pixel, the factor of the ambient
    /// term ([`psao_prt::served::pixel_factor`]; with lighting it is applied to `lit` already).
    pub ambient_tint: Option<Vec<Vec3>>,
}

impl ClientFrame {
    /// The frame corrections are added to: the lit composite when there is one, else the
    /// AO composite.
    pub fn base(&self) -> BaseFrame<'_> {
        match &self.lit {
            Some(lit) => BaseFrame::Lit {
                ao: &self.ao.data,
                lit,
            },
            None => BaseFrame::Ao(&self.ao.data),
        }
    }
}

/// A server and one client in one process.
pub struct Pipeline<'a> {
    scene: &'a Scene,
    server: Server,
    client_id: ClientId,
    encoder: Box<dyn Codec>,
    decoder: Box<dyn Codec>,
    client: ClientState,
    renderer: ClientRenderer,
    server_hz: u32,
    last_tick: Option<u64>,
    res: Resolution,
    /// Both ends of corrective splatting, when on.
    corrective: Option<InProcessCorrections>,
    /// Bytes received so far.
    pub total_bytes: u64,
}

impl<'a> Pipeline<'a> {
    /// Generates the points, builds the server and connects the client.
    pub fn new(scene: &'a Scene, config: &PipelineConfig) -> Result<Self, NetError> {
        if config.server_hz == 0 || config.server_hz > CLIENT_HZ {
            return Err(NetError::Config(format!(
                "--server-hz must be in 1..={CLIENT_HZ}, got {}",
                config.server_hz
            )));
        }
        let mut server = crate::start_cache::start_server(
            scene,
            config.server,
            config.medium.clone(),
            config.points_cache.as_deref(),
        )?;
        let client_id = server.add_client();
        let table = server.instance_table();
        let client = ClientState::new(&table);
        // Limited as a networked client's.
        let decoder = crate::convert::client_decoder(&config.codec, &table)?;
        let corrective = match &config.corrective {
            Some(c) => Some(InProcessCorrections::new(
                scene,
                config.server.backend,
                config.server.seed,
                config.res.width,
                config.res.height,
                c,
                config.server.lighting.as_ref(),
            )?),
            None => None,
        };
        Ok(Self {
            scene,
            server,
            client_id,
            encoder: psao_delta::codec_by_name(&config.codec)
                .map_err(NetError::codec("the server's codec"))?,
            decoder,
            client,
            renderer: ClientRenderer::new(scene)?
                .with_detail(config.detail)
                .with_reconstruct(config.reconstruct),
            server_hz: config.server_hz,
            last_tick: None,
            res: config.res,
            corrective,
            total_bytes: 0,
        })
    }

    /// The server (for point counts and overflow statistics).
    pub fn server(&self) -> &Server {
        &self.server
    }

    /// The client relights a character with a served model from now on, as a networked
    /// client does with a relighting message ([`ClientRenderer::relight`]).
    pub fn relight(&mut self, msg: &RelightingMsg) -> Result<(), NetError> {
        self.renderer.relight(self.scene, msg)
    }

    /// The client's state.
    pub fn client(&self) -> &ClientState {
        &self.client
    }

    /// The client's correction state, when corrections are on.
    pub fn corrective_client(&self) -> Option<&CorrectiveClient> {
        self.corrective.as_ref().map(|c| &c.client)
    }

    /// The server clock's tick at client frame `frame`.
    fn tick_of(&self, frame: u32) -> u64 {
        frame as u64 * self.server_hz as u64 / CLIENT_HZ as u64
    }

    /// Scene time (seconds) of server tick `tick`.
    fn server_time(&self, tick: u64) -> f32 {
        (tick as f64 / self.server_hz as f64) as f32
    }

    /// The server's view of `camera` at the client's image aspect.
    fn view(&self, camera: &Camera) -> View {
        View {
            camera: *camera,
            aspect: self.res.width as f32 / self.res.height as f32,
        }
    }

    /// The client decodes and applies one encoded update.
    fn receive(&mut self, encoded: &[u8]) -> Result<(), NetError> {
        let update = self.decoder.decode(encoded).map_err(NetError::codec(
            "the client could not decode the server's update",
        ))?;
        Ok(self.client.apply(&update)?)
    }

    /// Runs `server_frames` server frames at the scene time of client frame `frame`, seen
    /// from `camera`, and applies their updates to the client without counting their bytes:
    /// the state of a server that has been running for a while before the measured frames.
    pub fn warm_up(
        &mut self,
        frame: u32,
        camera: &Camera,
        server_frames: u32,
    ) -> Result<(), NetError> {
        let time = self.server_time(self.tick_of(frame));
        let view = self.view(camera);
        for _ in 0..server_frames {
            self.server.step_at(&[view], time)?;
            let encoded = self.encoder.encode(&self.server.update_for(self.client_id));
            self.receive(&encoded)?;
        }
        Ok(())
    }

    /// Runs client frame `frame` with `camera`: a server frame first when the server clock ticks
    /// (at server scene time `tick / server_hz`), then (when `render`) the client's G-buffer
    /// and AO reconstruction at client time `frame / 60` (see [`ClientRenderer`]).
    pub fn frame(
        &mut self,
        frame: u32,
        camera: &Camera,
        render: bool,
    ) -> Result<(FrameRecord, Option<ClientFrame>), NetError> {
        let mut record = FrameRecord {
            frame,
            ..Default::default()
        };
        let tick = self.tick_of(frame);
        let mut bytes = None;
        if self.last_tick != Some(tick) {
            self.last_tick = Some(tick);
            let t = Instant::now();
            let (view, time) = (self.view(camera), self.server_time(tick));
            let stats = self.server.step_at(&[view], time)?;
            record.invalidated_points = stats.invalidated_points;
            record.animate_ms = stats.animate_ms;
            record.retraced_points = stats.retraced_points;
            record.retrace_rays = stats.retrace_rays;
            let update = self.server.update_for(self.client_id);
            let t_encode = Instant::now();
            let encoded = self.encoder.encode(&update);
            record.encode_ms = t_encode.elapsed().as_secs_f64() * 1e3;
            record.server_ms = t.elapsed().as_secs_f64() * 1e3;
            record.server_frame = true;
            record.rays = stats.rays;
            record.light_paths = stats.light_paths;
            record.light_rays = stats.light_rays;
            record.changed_points = stats.published_points;
            record.changed_cells = update.changed_cells();
            record.bytes = encoded.len();
            self.total_bytes += encoded.len() as u64;
            bytes = Some(encoded);
        }
        if let Some(c) = &mut self.corrective {
            let t = Instant::now();
            let aspect = self.res.width as f32 / self.res.height as f32;
            let exchanged = c.exchange(&crate::convert::camera_msg(frame, camera, aspect))?;
            record.corrective_ms = t.elapsed().as_secs_f64() * 1e3;
            record.samples = exchanged.samples;
            record.sample_bytes = exchanged.bytes;
        }
        let t = Instant::now();
        if let Some(encoded) = bytes {
            self.receive(&encoded)?;
        }
        let mut out = None;
        // The client analyses every frame it shows when it corrects them.
        if render || self.corrective.is_some() {
            let time = client_time(frame);
            let mut img = self
                .renderer
                .render(self.scene, &self.client, camera, self.res, time)?;
            if let Some(c) = &mut self.corrective {
                let corrected = c.correct(self.scene, frame, &img.gbuffer, img.base());
                img.corrected = Some(corrected.image);
            }
            out = render.then_some(img);
        }
        record.client_ms = t.elapsed().as_secs_f64() * 1e3;
        Ok((record, out))
    }
}

/// The client's frame: rasterize, reconstruct AO from the mirrored grids.
pub struct ClientRenderer {
    rasterizer: Rasterizer,
    /// The client's own animation (posed at client time), for animated scenes.
    animation: Option<(Animator, ScenePose)>,
    /// The contact term applied after reconstruction, if any.
    detail: Option<DetailSettings>,
    /// Reconstruction settings.
    reconstruct: ReconstructSettings,
    /// Shadow maps of the suns and point lights, made on the first lit frame.
    shadows: Option<ShadowMaps>,
    /// The characters relit with served models (none until a model arrives).
    relit: RelitCharacters,
}

impl ClientRenderer {
    /// A renderer for `scene` (errors when its animation data cannot be played).
    pub fn new(scene: &Scene) -> Result<Self, NetError> {
        let animator = Animator::new(scene)?;
        Ok(Self {
            rasterizer: Rasterizer::new(),
            animation: animator
                .is_dynamic()
                .then(|| (animator, ScenePose::default())),
            detail: None,
            reconstruct: ReconstructSettings::default(),
            shadows: None,
            relit: RelitCharacters::default(),
        })
    }

    /// Relights a character of `scene` with a served model from now on
    /// ([`RelitCharacters::insert`]).
    pub fn relight(&mut self, scene: &Scene, msg: &RelightingMsg) -> Result<(), NetError> {
        self.relit.insert(scene, msg)
    }

    /// The same renderer reconstructing with `settings`.
    pub fn with_reconstruct(mut self, settings: ReconstructSettings) -> Self {
        self.reconstruct = settings;
        self
    }

    /// The same renderer applying `detail` after reconstruction (`None`: not at all).
    pub fn with_detail(mut self, detail: Option<DetailSettings>) -> Self {
        self.detail = detail;
        self
    }

    /// One client frame at client scene time `time`. A static scene is rasterized as stored.
    /// On an animated scene every instance is rasterized at the transform of the last server
    /// update `state` applied (so AO lags with the update instead of ghosting) and skinned
    /// instances deformed by the client's own animation at `time` (see [`client_poses`]).
    ///
    /// When `state` holds irradiance records (the server computes lighting), the frame also
    /// gets the lit composite: the irradiance reconstructed with the AO kernel plus the
    /// direct light of the scene's suns and point lights at `time`, shadow-mapped in the
    /// same pose ([`ShadowSettings::for_image`] of the image size).
    pub fn render(
        &mut self,
        scene: &Scene,
        state: &ClientState,
        camera: &Camera,
        res: Resolution,
        time: f32,
    ) -> Result<ClientFrame, NetError> {
        let mut gbuffer = GBuffer::empty(res.width, res.height);
        let opts = RasterOptions::new(res.width, res.height);
        let poses = match &mut self.animation {
            None => {
                self.rasterizer
                    .rasterize(scene, camera, &opts, &mut gbuffer);
                if !self.relit.is_empty() {
                    let rest: Vec<_> = scene.instances.iter().map(InstancePose::rest).collect();
                    let nodes = scene.pose_at(time)?.nodes;
                    self.relit.relight(scene, &nodes, &rest, camera.position)?;
                }
                None
            }
            Some((animator, pose)) => {
                animator.pose_into(time, pose);
                let poses = client_poses(scene, animator, pose, state);
                self.rasterizer
                    .rasterize_posed(scene, &poses, camera, &opts, &mut gbuffer)?;
                if !self.relit.is_empty() {
                    self.relit
                        .relight(scene, &pose.nodes, &poses, camera.position)?;
                }
                Some(poses)
            }
        };
        let (mut ao, mut irradiance) = (Vec::new(), Vec::new());
        let has_lights = state.has_lights();
        if has_lights {
            psao_client::reconstruct_lit_into(
                state,
                &gbuffer,
                &self.reconstruct,
                &mut ao,
                &mut irradiance,
            );
        } else {
            psao_client::reconstruct_into(state, &gbuffer, &self.reconstruct, &mut ao);
        }
        if let Some(detail) = &self.detail {
            psao_client::apply_detail(state, &gbuffer, camera, detail, &mut ao);
        }
        let factors = self.relit.pixel_factors(scene, &gbuffer, &ao);
        if let (Some(f), true) = (&factors, has_lights) {
            irradiance.iter_mut().zip(f).for_each(|(e, f)| *e *= *f);
        }
        let lit = if has_lights {
            let poses =
                poses.unwrap_or_else(|| scene.instances.iter().map(InstancePose::rest).collect());
            let shadows = self.shadows.get_or_insert_with(|| {
                ShadowMaps::new(ShadowSettings::for_image(res.width, res.height))
            });
            let aspect = res.width as f32 / res.height.max(1) as f32;
            shadows.render(scene, &poses, &scene.lights_at(time), camera, aspect)?;
            let direct: Vec<Vec3> = psao_client::direct_light(shadows, &gbuffer);
            Some(psao_client::composite_lit(
                scene,
                &gbuffer,
                &irradiance,
                &direct,
            ))
        } else {
            None
        };
        Ok(ClientFrame {
            ao: AoImage {
                width: gbuffer.width,
                height: gbuffer.height,
                data: ao,
            },
            gbuffer,
            corrected: None,
            lit,
            ambient_tint: factors.filter(|_| !has_lights),
        })
    }
}

/// What the client rasterizes on an animated scene: every instance at the transform of the
/// last applied server update (its own pose's transform until one arrived), skinned instances
/// with the vertices of the client's own `pose` (the server sends no vertices; its AO points
/// are interpolated onto the client's deformation).
pub fn client_poses<'p>(
    scene: &Scene,
    animator: &Animator,
    pose: &'p ScenePose,
    client: &ClientState,
) -> Vec<InstancePose<'p>> {
    (0..scene.instances.len())
        .map(|i| {
            let own = pose.instance(i);
            let transform = client
                .transform(i)
                .or(own.map(|p| p.transform))
                .unwrap_or(scene.instances[i].transform);
            match (animator.motion()[i], own) {
                (Motion::Skinned, Some(p)) => InstancePose {
                    transform,
                    positions: p.positions,
                    normals: p.normals,
                },
                _ => InstancePose::rigid(transform),
            }
        })
        .collect()
}

/// The client's composited image as 8-bit sRGB RGB: the lit composite when the frame has one,
/// else base shading × AO ([`composite_rgb8`]), its ambient term tinted on relit characters.
pub fn frame_rgb8(scene: &Scene, frame: &ClientFrame) -> Vec<u8> {
    match (&frame.lit, &frame.ambient_tint) {
        (Some(lit), _) => psao_client::composite_srgb8(lit),
        (None, Some(tint)) => psao_client::composite_srgb8(&psao_client::composite_tinted(
            scene,
            &frame.gbuffer,
            &frame.ao.data,
            tint,
            &Shading::default(),
        )),
        (None, None) => composite_rgb8(scene, &frame.gbuffer, &frame.ao),
    }
}

/// The composited client image (base shading × AO) as 8-bit sRGB RGB.
pub fn composite_rgb8(scene: &Scene, gbuffer: &GBuffer, ao: &AoImage) -> Vec<u8> {
    let linear = psao_client::composite(scene, gbuffer, &ao.data, &Shading::default());
    psao_client::composite_srgb8(&linear)
}

/// Luma of an 8-bit sRGB RGB image as an [`AoImage`] (for metrics on composited frames).
pub fn luma(width: u32, height: u32, rgb: &[u8]) -> AoImage {
    let data = rgb
        .chunks_exact(3)
        .map(|p| (0.2126 * p[0] as f32 + 0.7152 * p[1] as f32 + 0.0722 * p[2] as f32) / 255.0)
        .collect();
    AoImage {
        width,
        height,
        data,
    }
}
