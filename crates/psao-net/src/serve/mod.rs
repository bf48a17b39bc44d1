//! Serving: one shared point set streamed to many clients over TCP and WebSocket.
//!
//! A simulation thread owns the [`Server`]: each server frame it steps once for the union of
//! the clients' latest views, then hands every client whose queue has room the update since
//! what *it* last received (a client that falls behind gets one coalesced update later).
//! Connection tasks (tokio) do the handshake, read cameras and acks, and write the queued
//! frames. With `--lockstep` the server steps once per round of camera messages instead of
//! on a clock, which makes a session reproduce `psao run` exactly.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use psao_delta::Codec;
use psao_server::{ClientId, Server, StepStats, View};
use psao_wire::{
    capabilities, encode_frame, Bye, Delta, ErrorCode, ErrorMsg, Message, SceneTime, StatusMsg,
    Welcome, MAX_CLIENT_FRAME, PROTOCOL_VERSION,
};
use rayon::prelude::*;
use serde::Serialize;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};

mod corrective;

pub use corrective::{Corrections, DEFAULT_WORKERS as DEFAULT_CORRECTION_WORKERS};

use crate::access::Access;
use crate::admission::{Admission, MAX_CONNECTIONS};
use crate::characters::ServedCharacters;
use crate::convert::{entry_of, view_of};
use crate::cpu_time::cpu_seconds;
use crate::deadline::{Deadlined, SERVER_DEADLINES};
use crate::hash_pacing::HashPacing;
use crate::http::{serve_http, Health, HttpContext};
use crate::io::BoxIo;
use crate::pipeline::CLIENT_HZ;
use crate::process_memory::SlackTrimmer;
use crate::transport::{accept, Accepted, FrameReader, FrameWriter, ReadError};
use crate::NetError;

/// Frames queued per client before its updates are coalesced.
const QUEUE_FRAMES: usize = 4;
/// Updates sent but not yet acknowledged before a client's updates are coalesced.
const ACK_WINDOW: usize = 3;
/// Time a new connection has to send its hello.
const HELLO_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest a joined client may send nothing: viewers send a camera or, when they have none
/// to send, a keep-alive at least every [`crate::view::KEEP_ALIVE`].
pub const CLIENT_IDLE_TIMEOUT: Duration = Duration::from_secs(30);

/// How a [`Serve`] listens and runs (the [`Server`] itself is built by the caller).
#[derive(Clone)]
pub struct ServeConfig {
    /// Address to listen on (TCP and WebSocket on the same port); port 0 picks a free one.
    pub listen: SocketAddr,
    /// Access token clients must present.
    pub token: Option<String>,
    /// Web origins (`http(s)://host[:port]`) allowed besides the server's own and loopback.
    pub allow_origins: Vec<String>,
    /// Most connections open at once from one source (see [`crate::admission`]).
    pub max_per_source: usize,
    /// Name of the scene, told to clients in the welcome.
    pub scene_name: String,
    /// Update codec name.
    pub codec: String,
    /// Server frames per second of scene time (1..=[`CLIENT_HZ`]).
    pub hz: u32,
    /// Step once per round of client camera messages (deterministic; see docs/STREAMING.md).
    pub lockstep: bool,
    /// Wait for this many clients before the first server frame.
    pub wait_clients: usize,
    /// Most clients at once; later ones are refused with a `Server` error.
    pub max_clients: usize,
    /// Return once every client has left (after at least one joined).
    pub once: bool,
    /// Stop on Ctrl-C (SIGINT).
    pub stop_on_ctrl_c: bool,
    /// What `/scene.glb` serves (see [`crate::glb::scene_glb`]).
    pub scene_glb: Vec<u8>,
    /// The relit characters: `/characters/N.prt`, and the relighting messages after the
    /// welcome (empty: none).
    pub characters: Arc<ServedCharacters>,
    /// Serve every connection over TLS (https, wss, and raw frames inside TLS); see
    /// [`crate::tls::acceptor`].
    pub tls: Option<tokio_rustls::TlsAcceptor>,
}

/// Per-client statistics.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ClientStats {
    /// Session id.
    pub id: u32,
    /// Bytes of frames queued for the client (headers included).
    pub bytes: u64,
    /// Deltas and snapshots sent.
    pub updates: u64,
    /// Snapshots among them.
    pub snapshots: u64,
    /// Server frames at which the client had no room, so its changes were coalesced into a
    /// later update.
    pub coalesced: u64,
    /// Server frames stepped while the client was connected.
    pub frames: u64,
    /// Correction samples sent.
    pub samples: u64,
    /// Correction positions the client's sample budget paid for (one sample each).
    pub correction_budget: u64,
    /// Correction positions examined (a primary ray each, whether or not it gave a sample):
    /// at most `correction_budget`.
    pub correction_examined: u64,
    /// Regions dropped on arrival because the scene has no such object.
    pub regions_dropped: u64,
    /// Correction samples the workers traced per second of their tracing time (threaded
    /// serving; 0 in lockstep, where the simulation thread traces).
    pub correction_samples_per_s: f64,
}

/// What `psao serve --json` writes.
#[derive(Debug, Default, Serialize)]
pub struct ServeStats {
    /// Server frames stepped.
    pub frames: u64,
    /// Mean step + encode time per server frame, ms.
    pub mean_ms: f64,
    /// 95th percentile of it, ms.
    pub p95_ms: f64,
    /// Median of it, ms.
    pub median_ms: f64,
    /// Mean of the step alone, ms.
    pub mean_step_ms: f64,
    /// Mean of the step's culling, ms.
    pub mean_cull_ms: f64,
    /// Mean of the step's selection, tracing and accumulation, ms.
    pub mean_trace_ms: f64,
    /// Mean of the step's publishing, ms.
    pub mean_publish_ms: f64,
    /// Mean rays traced per server frame.
    pub mean_rays: f64,
    /// CPU time of the whole server process (all threads) per server frame, ms: unlike the
    /// wall times it is not inflated by other processes on a shared machine.
    pub cpu_ms: f64,
    /// Mean per server frame of collecting the clients' updates (`update_for`), ms.
    pub mean_update_ms: f64,
    /// Mean per server frame of encoding them (codec + framing), ms.
    pub mean_encode_ms: f64,
    /// Mean per server frame of hashing the server state for verifying clients, ms.
    pub mean_hash_ms: f64,
    /// Server frames whose updates carried a state hash (every frame in lockstep; outside
    /// it as often as [`crate::hash_pacing::HASH_SHARE`] allows).
    pub hashed_frames: u64,
    /// Server frames that started late because the previous one overran the period.
    pub late_frames: u64,
    /// Wall-clock seconds from the first server frame to the end of the loop.
    pub seconds: f64,
    /// Server frames per wall-clock second over `seconds` (the `--hz` rate unless frames
    /// overran their period).
    pub fps: f64,
    /// Hash of the server's final buckets + cells.
    pub state_hash: String,
    /// Every client session, in order of joining.
    pub clients: Vec<ClientStats>,
}

/// How a [`Serve`] advances its [`Server`] by one server frame: [`LocalStep`] traces in
/// this process (`psao serve`); an edge applies what trace nodes published
/// ([`crate::scale::edge`]).
pub trait Stepper: Send {
    /// One server frame for the union of the clients' `views` at scene time `seconds`.
    fn step(
        &mut self,
        server: &mut Server,
        views: &[View],
        seconds: f32,
    ) -> Result<StepStats, NetError>;

    /// [`Stepper::step`] with `beside` running on the rayon pool at the same time; by
    /// default beside the whole step.
    fn step_beside(
        &mut self,
        server: &mut Server,
        views: &[View],
        seconds: f32,
        beside: Beside<'_>,
    ) -> Result<StepStats, NetError> {
        rayon::join(|| self.step(server, views, seconds), beside).0
    }

    /// Why updates are stalled, when they are (an edge waiting for its trace nodes); sent
    /// to the clients that understand status messages whenever it changes.
    fn stalled(&self) -> Option<String> {
        None
    }
}

/// Work a [`Stepper`] overlaps with a server frame: the previous frame's encoding and sending.
pub type Beside<'a> = Box<dyn FnOnce() + Send + 'a>;

/// Tracing in this process: [`Server::step_at`].
pub struct LocalStep;

impl Stepper for LocalStep {
    fn step(
        &mut self,
        server: &mut Server,
        views: &[View],
        seconds: f32,
    ) -> Result<StepStats, NetError> {
        server.step_at(views, seconds).map_err(NetError::from)
    }

    /// `beside` runs beside the publishing phase, not the tracing ([`Server::step_beside`]).
    fn step_beside(
        &mut self,
        server: &mut Server,
        views: &[View],
        seconds: f32,
        beside: Beside<'_>,
    ) -> Result<StepStats, NetError> {
        server
            .step_beside(views, seconds, beside)
            .0
            .map_err(NetError::from)
    }
}

/// A connection's request to join, answered with its session.
struct Join {
    capabilities: u32,
    out: mpsc::Sender<Vec<u8>>,
    reply: oneshot::Sender<Result<Welcome, ErrorMsg>>,
}

/// What connections tell the simulation.
enum Event {
    Join(Join),
    Camera(u32, psao_wire::CameraMsg),
    Ack(u32, u64),
    Regions(u32, psao_wire::RegionsMsg),
    Leave(u32),
}

/// The simulation's record of one client.
struct Session {
    id: ClientId,
    codec: Box<dyn Codec>,
    out: mpsc::Sender<Vec<u8>>,
    want_hash: bool,
    /// Whether the client understands status messages.
    want_status: bool,
    view: Option<View>,
    /// Lockstep: the camera frame awaiting an answer.
    pending: Option<u32>,
    unacked: VecDeque<u64>,
    stats: ClientStats,
    /// Corrective splatting state, when both ends want it.
    corrective: Option<corrective::SessionCorrections>,
}

/// A bound server: listening, not yet stepping.
pub struct Serve {
    server: Server,
    config: ServeConfig,
    rt: tokio::runtime::Runtime,
    listener: TcpListener,
    local: SocketAddr,
    stop: Arc<AtomicBool>,
    stepper: Box<dyn Stepper>,
    corrections: Option<Corrections>,
    access: Arc<Access>,
    health: Arc<Health>,
}

impl Serve {
    /// Checks `config` and binds its listen address (`server` steps for the clients).
    pub fn bind(server: Server, config: ServeConfig) -> Result<Self, NetError> {
        if config.hz == 0 || config.hz > CLIENT_HZ {
            return Err(NetError::Config(format!(
                "--hz must be in 1..={CLIENT_HZ}, got {}",
                config.hz
            )));
        }
        psao_delta::codec_by_name(&config.codec).map_err(NetError::codec("the server's codec"))?;
        let access = Arc::new(Access::new(config.token.clone(), &config.allow_origins)?);
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(NetError::io("cannot start the async runtime"))?;
        let listener = rt
            .block_on(TcpListener::bind(config.listen))
            .map_err(NetError::io(format!("cannot listen on {}", config.listen)))?;
        let local = listener
            .local_addr()
            .map_err(NetError::io("cannot read the listening address"))?;
        Ok(Self {
            server,
            config,
            rt,
            listener,
            local,
            stop: Arc::new(AtomicBool::new(false)),
            stepper: Box::new(LocalStep),
            corrections: None,
            access,
            health: Arc::new(Health::default()),
        })
    }

    /// Step with `stepper` instead of tracing in this process ([`LocalStep`]).
    pub fn with_stepper(mut self, stepper: Box<dyn Stepper>) -> Self {
        self.stepper = stepper;
        self
    }

    /// What `/health` reports (a [`Stepper`] may add to it).
    pub fn health(&self) -> Arc<Health> {
        self.health.clone()
    }

    /// The address actually listened on (resolves port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// A flag that stops [`Serve::run`] when set (checked at least every 50 ms).
    pub fn stop_handle(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Accepts clients and steps until stopped (or, with `once`, until the last client
    /// left); returns the statistics.
    pub fn run(self) -> ServeStats {
        let Serve {
            server,
            config,
            rt,
            listener,
            local,
            stop,
            stepper,
            corrections,
            access,
            health,
        } = self;
        let scheme = if config.tls.is_some() {
            "TLS: https, wss and raw frames"
        } else {
            "raw frames, HTTP and WebSocket"
        };
        tracing::info!("listening on {local} ({scheme})");
        let (events_tx, events_rx) = mpsc::channel::<Event>(1024);
        let http = HttpShared {
            access,
            admission: Admission::new(MAX_CONNECTIONS, config.max_per_source),
            tls: config.tls.clone(),
            scene_glb: bytes::Bytes::from(config.scene_glb),
            characters: config.characters.clone(),
            scene_name: config.scene_name.clone(),
            health: health.clone(),
        };
        rt.spawn(accept_loop(listener, events_tx, http));
        if config.stop_on_ctrl_c {
            let stop_signal = stop.clone();
            rt.spawn(async move {
                if tokio::signal::ctrl_c().await.is_ok() {
                    tracing::info!("Ctrl-C: shutting down");
                    stop_signal.store(true, Ordering::SeqCst);
                }
            });
        }
        let sim = Simulation {
            server,
            stepper,
            codec: config.codec.clone(),
            scene: config.scene_name.clone(),
            hz: config.hz,
            lockstep: config.lockstep,
            sessions: BTreeMap::new(),
            stats: ServeStats::default(),
            events: events_rx,
            rt: rt.handle().clone(),
            stop,
            ever_joined: false,
            once: config.once,
            wait_clients: config.wait_clients,
            max_clients: config.max_clients,
            step_ms: Vec::new(),
            phase_ms: [0.0; 3],
            frame_ms: Vec::new(),
            rays: 0,
            cpu_start: None,
            wall_start: None,
            update_ms: 0.0,
            encode_ms: 0.0,
            unsent: None,
            hash_ms: 0.0,
            hash_pacing: HashPacing::default(),
            trimmer: SlackTrimmer::default(),
            health,
            corrections,
            status: None,
        };
        let stats = sim.run();
        rt.shutdown_timeout(Duration::from_millis(500));
        stats
    }
}

async fn accept_loop(listener: TcpListener, events: mpsc::Sender<Event>, http: HttpShared) {
    let ctx = Arc::new(HttpContext {
        scene_glb: http.scene_glb,
        characters: http.characters.clone(),
        scene_name: http.scene_name,
        health: http.health,
        access: http.access.clone(),
        on_websocket: {
            let (events, access) = (events.clone(), http.access.clone());
            let characters = http.characters.clone();
            Box::new(move |reader, writer, permit| {
                let (events, access) = (events.clone(), access.clone());
                let characters = characters.clone();
                tokio::spawn(async move {
                    let _permit = permit;
                    let ends = (events, &*access, &*characters);
                    if let Err(e) = session(reader, writer, "websocket", ends).await {
                        tracing::info!("WebSocket session ended: {e}");
                    }
                });
            })
        },
    });
    loop {
        match listener.accept().await {
            Ok((stream, peer)) => {
                let permit = match http.admission.admit(peer.ip()) {
                    Ok(p) => p,
                    Err(e) => {
                        tracing::debug!("closing {peer}'s connection: {e}");
                        continue;
                    }
                };
                let _ = stream.set_nodelay(true);
                let stream = Deadlined::new(stream, SERVER_DEADLINES);
                let (events, access, ctx) = (events.clone(), http.access.clone(), ctx.clone());
                let characters = http.characters.clone();
                let tls = http.tls.clone();
                tokio::spawn(async move {
                    let io: BoxIo = match tls {
                        None => Box::new(stream),
                        Some(tls) => {
                            match tokio::time::timeout(HELLO_TIMEOUT, tls.accept(stream)).await {
                                Ok(Ok(s)) => Box::new(s),
                                Ok(Err(e)) => {
                                    tracing::info!("TLS handshake with {peer} failed: {e}");
                                    return;
                                }
                                Err(_) => {
                                    tracing::info!("TLS handshake with {peer} timed out");
                                    return;
                                }
                            }
                        }
                    };
                    match accept(io, HELLO_TIMEOUT).await {
                        Ok(Accepted::Frames(reader, writer)) => {
                            let _permit = permit;
                            let ends = (events, &*access, &*characters);
                            if let Err(e) = session(reader, writer, "tcp", ends).await {
                                tracing::info!("session with {peer} ended: {e}");
                            }
                        }
                        Ok(Accepted::Http(io)) => {
                            if let Err(e) = serve_http(io, ctx, permit).await {
                                tracing::debug!("HTTP connection from {peer}: {e}");
                            }
                        }
                        Err(e) => tracing::info!("connection from {peer}: {e}"),
                    }
                });
            }
            Err(e) => {
                tracing::warn!("accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

/// What the HTTP side needs from the configuration.
struct HttpShared {
    access: Arc<Access>,
    admission: Arc<Admission>,
    tls: Option<tokio_rustls::TlsAcceptor>,
    scene_glb: bytes::Bytes,
    characters: Arc<ServedCharacters>,
    scene_name: String,
    health: Arc<Health>,
}

/// Sends `error`, lets the peer read it, and closes.
async fn refuse(
    reader: &mut FrameReader,
    writer: &mut FrameWriter,
    code: ErrorCode,
    message: String,
) -> NetError {
    let text = message.clone();
    if let Ok(frame) = encode_frame(&Message::Error(ErrorMsg { code, message })) {
        let _ = writer.send(frame).await;
    }
    writer.close().await;
    reader.drain(Duration::from_millis(500)).await;
    NetError::Protocol(format!("refused ({code:?}): {text}"))
}

/// One client session on a frame transport: handshake (the welcome, then the relighting
/// messages the client asked for), then cameras/acks in, queued frames out.
async fn session(
    mut reader: FrameReader,
    mut writer: FrameWriter,
    kind: &'static str,
    (events, access, characters): (mpsc::Sender<Event>, &Access, &ServedCharacters),
) -> Result<(), NetError> {
    let first = tokio::time::timeout(HELLO_TIMEOUT, reader.next(MAX_CLIENT_FRAME)).await;
    let hello = match first {
        Err(_) => {
            return Err(refuse(
                &mut reader,
                &mut writer,
                ErrorCode::Protocol,
                "no hello in time".into(),
            )
            .await)
        }
        Ok(Ok(Some((Message::Hello(h), _)))) => h,
        Ok(Ok(Some((m, _)))) => {
            let text = format!("expected hello, got {}", m.kind());
            return Err(refuse(&mut reader, &mut writer, ErrorCode::Protocol, text).await);
        }
        Ok(Ok(None)) => return Err(NetError::Protocol("closed before hello".into())),
        Ok(Err(e)) => return Err(read_failure(&mut reader, &mut writer, e).await),
    };
    if hello.version != PROTOCOL_VERSION {
        let text = format!(
            "protocol version {} not supported (server speaks {PROTOCOL_VERSION})",
            hello.version
        );
        return Err(refuse(&mut reader, &mut writer, ErrorCode::Version, text).await);
    }
    if !access.token_ok(hello.token.as_deref()) {
        return Err(refuse(
            &mut reader,
            &mut writer,
            ErrorCode::Token,
            "missing or wrong token".into(),
        )
        .await);
    }
    let (out_tx, mut out_rx) = mpsc::channel::<Vec<u8>>(QUEUE_FRAMES);
    let (reply_tx, reply_rx) = oneshot::channel();
    events
        .send(Event::Join(Join {
            capabilities: hello.capabilities,
            out: out_tx.clone(),
            reply: reply_tx,
        }))
        .await
        .map_err(|_| shutting_down())?;
    let welcome = match reply_rx.await.map_err(|_| shutting_down())? {
        Ok(w) => w,
        Err(e) => return Err(refuse(&mut reader, &mut writer, e.code, e.message).await),
    };
    let id = welcome.client_id;
    tracing::info!("client {id} ({}, {kind}) joined", hello.name);
    writer
        .send(encode_frame(&Message::Welcome(welcome))?)
        .await?;
    for m in characters.messages_for(hello.capabilities) {
        writer.send(encode_frame(&m)?).await?;
    }
    let writer_task = tokio::spawn(async move {
        while let Some(frame) = out_rx.recv().await {
            if writer.send(frame).await.is_err() {
                break;
            }
        }
        writer.close().await;
    });
    let result = read_loop(&mut reader, id, &events).await;
    if let Err(e) = &result {
        let (code, message) = match e {
            ReadError::Wire(w) => (ErrorCode::Frame, w.to_string()),
            ReadError::Io(_) => (ErrorCode::Protocol, e.to_string()),
        };
        if let Ok(frame) = encode_frame(&Message::Error(ErrorMsg { code, message })) {
            let _ = out_tx.send(frame).await;
        }
    }
    drop(out_tx);
    let _ = events.send(Event::Leave(id)).await;
    let _ = tokio::time::timeout(Duration::from_secs(2), writer_task).await;
    reader.drain(Duration::from_millis(500)).await;
    result.map_err(|e| match e {
        ReadError::Wire(w) => NetError::Wire(w),
        ReadError::Io(m) => NetError::Protocol(m),
    })
}

fn shutting_down() -> NetError {
    NetError::Protocol("server is shutting down".into())
}

async fn read_failure(
    reader: &mut FrameReader,
    writer: &mut FrameWriter,
    e: ReadError,
) -> NetError {
    let code = match e {
        ReadError::Wire(_) => ErrorCode::Frame,
        ReadError::Io(_) => ErrorCode::Protocol,
    };
    refuse(reader, writer, code, e.to_string()).await
}

/// Messages after the welcome until the client leaves.
async fn read_loop(
    reader: &mut FrameReader,
    id: u32,
    events: &mpsc::Sender<Event>,
) -> Result<(), ReadError> {
    loop {
        let next = tokio::time::timeout(CLIENT_IDLE_TIMEOUT, reader.next(MAX_CLIENT_FRAME));
        let Some((message, _)) = next.await.map_err(|_| {
            ReadError::Io(format!(
                "no message for {} s (clients send a keep-alive)",
                CLIENT_IDLE_TIMEOUT.as_secs()
            ))
        })??
        else {
            return Ok(());
        };
        let event = match message {
            Message::Camera(c) => Event::Camera(id, c),
            Message::Ack(a) => Event::Ack(id, a.frame),
            Message::Regions(r) => Event::Regions(id, r),
            Message::Bye(_) => return Ok(()),
            other => {
                return Err(ReadError::Io(format!(
                    "unexpected {} from a client",
                    other.kind()
                )))
            }
        };
        if events.send(event).await.is_err() {
            return Ok(());
        }
    }
}

/// The simulation thread's state.
struct Simulation {
    server: Server,
    stepper: Box<dyn Stepper>,
    codec: String,
    scene: String,
    hz: u32,
    lockstep: bool,
    sessions: BTreeMap<u32, Session>,
    stats: ServeStats,
    events: mpsc::Receiver<Event>,
    rt: tokio::runtime::Handle,
    stop: Arc<AtomicBool>,
    ever_joined: bool,
    once: bool,
    wait_clients: usize,
    max_clients: usize,
    step_ms: Vec<f64>,
    /// Sums of the steps' cull, trace and publish ms.
    phase_ms: [f64; 3],
    frame_ms: Vec<f64>,
    /// Rays traced, summed over frames.
    rays: u64,
    /// Process CPU seconds when the first frame started.
    cpu_start: Option<f64>,
    /// When the first frame started.
    wall_start: Option<Instant>,
    /// Summed over frames: update collection, encoding, hashing (ms).
    update_ms: f64,
    encode_ms: f64,
    hash_ms: f64,
    /// When the next state hash is due (outside lockstep).
    hash_pacing: HashPacing,
    /// Gives the frames' freed buffers back to the system as the resident size grows.
    trimmer: SlackTrimmer,
    /// The last frame's updates, sent during the next frame (not in lockstep).
    unsent: Option<FrameUpdates>,
    /// What `/health` reports.
    health: Arc<Health>,
    /// Corrective splatting, when served.
    corrections: Option<Corrections>,
    /// The stall last told to the clients ([`Stepper::stalled`]).
    status: Option<String>,
}

impl Simulation {
    /// The main loop until Ctrl-C (or, with `--once`, until the last client left).
    fn run(mut self) -> ServeStats {
        let period = Duration::from_secs_f64(1.0 / f64::from(self.hz));
        let mut next = Instant::now();
        let mut started = false;
        let mut round = 0u64;
        let mut last_tick = None;
        loop {
            if self.stop.load(Ordering::SeqCst)
                || (self.once && self.ever_joined && self.sessions.is_empty())
            {
                break;
            }
            if !started {
                started = self.sessions.len() >= self.wait_clients.max(1);
                if !started {
                    self.wait_event(Duration::from_millis(50));
                    continue;
                }
                next = Instant::now();
                self.cpu_start = cpu_seconds();
                self.wall_start = Some(Instant::now());
            }
            if self.lockstep {
                // Every client must have sent the camera of its next frame.
                let ready = !self.sessions.is_empty()
                    && self.sessions.values().all(|s| s.pending.is_some());
                if !ready {
                    self.wait_event(Duration::from_millis(50));
                    continue;
                }
                let tick = round * u64::from(self.hz) / u64::from(CLIENT_HZ);
                let seconds = round as f64 / f64::from(CLIENT_HZ);
                round += 1;
                self.corrections(CLIENT_HZ, true);
                if last_tick != Some(tick) {
                    last_tick = Some(tick);
                    self.frame(seconds, true);
                    self.trimmer.after_frame();
                } else {
                    self.answer_without_update(seconds);
                }
            } else {
                let now = Instant::now();
                if now < next {
                    self.wait_event(next - now);
                    continue;
                }
                if now > next + period {
                    self.stats.late_frames += 1;
                    next = now;
                }
                next += period;
                self.drain_events();
                self.corrections(self.hz, false);
                let seconds = (self.server.frame() + 1) as f64 / f64::from(self.hz);
                self.frame(seconds, false);
                self.trimmer.after_frame();
            }
        }
        self.shutdown()
    }

    /// Wait up to `timeout` for one event, then handle everything pending.
    fn wait_event(&mut self, timeout: Duration) {
        let got = self
            .rt
            .block_on(async { tokio::time::timeout(timeout, self.events.recv()).await });
        if let Ok(Some(e)) = got {
            self.handle(e);
        }
        self.drain_events();
    }

    fn drain_events(&mut self) {
        while let Ok(e) = self.events.try_recv() {
            self.handle(e);
        }
    }

    fn handle(&mut self, event: Event) {
        match event {
            Event::Join(join) => self.join(join),
            Event::Camera(id, cam) => {
                if let Some(s) = self.sessions.get_mut(&id) {
                    s.view = Some(view_of(&cam));
                    s.pending = Some(cam.frame);
                    if let Some(c) = &mut s.corrective {
                        c.camera(&cam);
                    }
                }
            }
            Event::Ack(id, frame) => {
                if let Some(s) = self.sessions.get_mut(&id) {
                    while s.unacked.front().is_some_and(|&f| f <= frame) {
                        s.unacked.pop_front();
                    }
                }
            }
            Event::Regions(id, regions) => {
                if let Some(s) = self.sessions.get_mut(&id) {
                    corrective::regions(s, &regions, self.corrections.as_ref());
                }
            }
            Event::Leave(id) => {
                if let Some(mut s) = self.sessions.remove(&id) {
                    self.health
                        .clients
                        .store(self.sessions.len(), Ordering::Relaxed);
                    self.server.remove_client(s.id);
                    tracing::info!("client {id} left");
                    corrective::record(s.corrective.as_ref(), &mut s.stats);
                    self.stats.clients.push(s.stats);
                }
            }
        }
    }

    fn join(&mut self, join: Join) {
        let wanted = match self.codec.as_str() {
            "paper" => capabilities::CODEC_PAPER,
            _ => capabilities::CODEC_COMPACT,
        };
        if join.capabilities & wanted == 0 {
            let _ = join.reply.send(Err(ErrorMsg {
                code: ErrorCode::Protocol,
                message: format!(
                    "the client cannot decode the server's codec `{}`",
                    self.codec
                ),
            }));
            return;
        }
        if self.sessions.len() >= self.max_clients {
            let _ = join.reply.send(Err(ErrorMsg {
                code: ErrorCode::Server,
                message: format!("server full ({} clients)", self.max_clients),
            }));
            return;
        }
        let id = self.server.add_client();
        let Ok(codec) = psao_delta::codec_by_name(&self.codec) else {
            return;
        };
        let welcome = Welcome {
            version: PROTOCOL_VERSION,
            client_id: id.0,
            codec: self.codec.clone(),
            server_hz: self.hz,
            client_hz: CLIENT_HZ,
            lockstep: self.lockstep,
            scene: self.scene.clone(),
            frame: self.server.frame(),
            scene_time: self.server.frame() as f64 / f64::from(self.hz),
            instances: self.server.instance_table().iter().map(entry_of).collect(),
        };
        if join.reply.send(Ok(welcome)).is_err() {
            self.server.remove_client(id);
            return;
        }
        self.ever_joined = true;
        self.sessions.insert(
            id.0,
            Session {
                id,
                codec,
                out: join.out,
                want_hash: join.capabilities & capabilities::STATE_HASH != 0,
                want_status: join.capabilities & capabilities::STATUS != 0,
                view: None,
                pending: None,
                unacked: VecDeque::new(),
                stats: ClientStats {
                    id: id.0,
                    ..Default::default()
                },
                corrective: corrective::session_state(
                    self.corrections.as_ref(),
                    join.capabilities,
                    self.lockstep,
                ),
            },
        );
        self.health
            .clients
            .store(self.sessions.len(), Ordering::Relaxed);
        if self.status.is_some() {
            self.send_status(id.0);
        }
    }

    /// Tell the clients when the stepper's stall ([`Stepper::stalled`]) began or ended.
    fn tell_status(&mut self) {
        let now = self.stepper.stalled();
        if now == self.status {
            return;
        }
        self.status = now;
        let ids: Vec<u32> = self.sessions.keys().copied().collect();
        for id in ids {
            self.send_status(id);
        }
    }

    /// Send the current status to client `id` if it understands status messages.
    fn send_status(&mut self, id: u32) {
        let Some(s) = self.sessions.get_mut(&id).filter(|s| s.want_status) else {
            return;
        };
        let msg = Message::Status(StatusMsg {
            stalled: self.status.is_some(),
            text: self.status.clone().unwrap_or_default(),
        });
        if let Ok(bytes) = encode_frame(&msg) {
            s.stats.bytes += bytes.len() as u64;
            let _ = self.rt.block_on(s.out.send(bytes));
        }
    }

    /// Step once for the union of the clients' views and collect the update of each client
    /// with room (lockstep: every client, waiting for room). Lockstep encodes and sends them
    /// at once; otherwise they are encoded and sent during the next frame's step, which
    /// they overlap (a server frame of latency for the use of both cores).
    fn frame(&mut self, seconds: f64, lockstep: bool) {
        let t = Instant::now();
        let mut views: Vec<View> = Vec::new();
        for v in self.sessions.values().filter_map(|s| s.view) {
            if !views.contains(&v) {
                views.push(v);
            }
        }
        let previous = self.unsent.take();
        let (server, sessions, rt) = (&mut self.server, &mut self.sessions, &self.rt);
        let stepper = &mut self.stepper;
        let mut sent = None;
        let send = Box::new(|| sent = previous.map(|u| send_updates(sessions, u, false, rt)));
        let step = stepper.step_beside(server, &views, seconds as f32, send);
        if let Some(sent) = sent {
            self.sent(sent);
        }
        self.tell_status();
        let step = match step {
            Ok(step) => step,
            Err(e) => {
                tracing::error!("server frame at {seconds:.3} s skipped: {e}");
                return;
            }
        };
        self.step_ms.push(step.ms);
        self.health
            .server_frame
            .store(self.server.frame(), Ordering::Relaxed);
        for (sum, ms) in
            self.phase_ms
                .iter_mut()
                .zip([step.cull_ms, step.trace_ms, step.publish_ms])
        {
            *sum += ms;
        }
        self.rays += step.rays;
        let th = Instant::now();
        // Outside lockstep only as often as its cost allows (crate::hash_pacing): the
        // sessions that want hashes get one with the updates of the frames that have one.
        let hash = if self.sessions.values().any(|s| s.want_hash) {
            let server = &self.server;
            let hash = self
                .hash_pacing
                .hash_if_due(self.lockstep, || state_hash(server));
            self.stats.hashed_frames += u64::from(hash.is_some());
            hash
        } else {
            None
        };
        self.hash_ms += th.elapsed().as_secs_f64() * 1e3;
        let tu = Instant::now();
        let mut due = Vec::new();
        for s in self.sessions.values_mut() {
            s.stats.frames += 1;
            let room = s.out.capacity() > 0 && s.unacked.len() < ACK_WINDOW;
            if !lockstep && !room {
                s.stats.coalesced += 1;
                continue;
            }
            due.push(s.id);
        }
        let updates = FrameUpdates {
            frame: self.server.frame(),
            seconds,
            hash,
            groups: self.server.updates_for(&due),
        };
        self.update_ms += tu.elapsed().as_secs_f64() * 1e3;
        if lockstep {
            self.send_now(updates, true);
        } else {
            self.unsent = Some(updates);
        }
        self.frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }

    /// Encode and send `updates` now (see [`send_updates`]) and drop the sessions that are
    /// gone.
    fn send_now(&mut self, updates: FrameUpdates, lockstep: bool) {
        let sent = send_updates(&mut self.sessions, updates, lockstep, &self.rt);
        self.sent(sent);
    }

    /// Account what [`send_updates`] returned: its time, and the sessions that are gone.
    fn sent(&mut self, (gone, ms): (Vec<u32>, f64)) {
        self.encode_ms += ms;
        for id in gone {
            self.handle(Event::Leave(id));
        }
    }

    /// Lockstep round without a server frame: tell each client its frame is done.
    fn answer_without_update(&mut self, seconds: f64) {
        let frame = self.server.frame();
        for s in self.sessions.values_mut() {
            let msg = Message::SceneTime(SceneTime {
                frame,
                seconds,
                client_frame: s.pending.take(),
            });
            if let Ok(bytes) = encode_frame(&msg) {
                s.stats.bytes += bytes.len() as u64;
                let _ = self.rt.block_on(s.out.send(bytes));
            }
        }
    }

    /// Say bye to everyone and collect the statistics.
    fn shutdown(mut self) -> ServeStats {
        let seconds = self.wall_start.map_or(0.0, |t| t.elapsed().as_secs_f64());
        if let Some(u) = self.unsent.take() {
            self.send_now(u, false);
        }
        let bye = encode_frame(&Message::Bye(Bye {
            reason: "server shutting down".into(),
        }));
        for s in self.sessions.values() {
            if let Ok(b) = &bye {
                let _ = s.out.try_send(b.clone());
            }
        }
        let ids: Vec<u32> = self.sessions.keys().copied().collect();
        for id in ids {
            self.handle(Event::Leave(id));
        }
        std::thread::sleep(Duration::from_millis(100));
        let mut stats = std::mem::take(&mut self.stats);
        stats.frames = self.server.frame();
        stats.seconds = seconds;
        if seconds > 0.0 {
            stats.fps = stats.frames as f64 / seconds;
        }
        stats.mean_ms = mean(&self.frame_ms);
        stats.p95_ms = percentile(&self.frame_ms, 0.95);
        stats.median_ms = percentile(&self.frame_ms, 0.5);
        stats.mean_step_ms = mean(&self.step_ms);
        let steps = self.step_ms.len().max(1) as f64;
        [
            stats.mean_cull_ms,
            stats.mean_trace_ms,
            stats.mean_publish_ms,
        ] = self.phase_ms.map(|sum| sum / steps);
        let frames = self.frame_ms.len().max(1) as f64;
        stats.mean_update_ms = self.update_ms / frames;
        stats.mean_encode_ms = self.encode_ms / frames;
        stats.mean_hash_ms = self.hash_ms / frames;
        stats.mean_rays = self.rays as f64 / frames;
        if let (Some(a), Some(b)) = (self.cpu_start, cpu_seconds()) {
            stats.cpu_ms = (b - a) * 1e3 / frames;
        }
        stats.state_hash = format!("{:016x}", state_hash(&self.server));
        stats.clients.sort_by_key(|c| c.id);
        tracing::info!(
            "{} server frames, {:.2} ms mean ({:.2} ms step), {} late",
            stats.frames,
            stats.mean_ms,
            stats.mean_step_ms,
            stats.late_frames
        );
        stats
    }
}

/// One server frame's updates, collected but not yet encoded: clients due the same update
/// share it (see [`Server::updates_for`]).
struct FrameUpdates {
    frame: u64,
    seconds: f64,
    /// The server's state hash at this frame, for clients that verify.
    hash: Option<u64>,
    groups: Vec<(Vec<ClientId>, psao_delta::Update)>,
}

/// Who codes what of `groups` for the clients `ids`, in their order: each client's group and
/// whether it encodes the group's update (the group's first client among `ids`; the others
/// only advance their codec, see [`send_updates`]); `None` for a client in no group.
pub fn coding_plan(
    ids: impl IntoIterator<Item = ClientId>,
    groups: &[(Vec<ClientId>, psao_delta::Update)],
) -> Vec<Option<(usize, bool)>> {
    let group_of: HashMap<ClientId, usize> = groups
        .iter()
        .enumerate()
        .flat_map(|(g, (members, _))| members.iter().map(move |m| (*m, g)))
        .collect();
    let mut encoders: HashSet<usize> = HashSet::new();
    ids.into_iter()
        .map(|id| {
            let g = *group_of.get(&id)?;
            Some((g, encoders.insert(g)))
        })
        .collect()
}

/// `update` through `codec`: its payload when the codec `encodes`, else only taken into the
/// codec's state ([`Codec::advance`]).
pub fn code(codec: &mut dyn Codec, update: &psao_delta::Update, encodes: bool) -> Option<Vec<u8>> {
    if encodes {
        Some(codec.encode(update))
    } else {
        codec.advance(update);
        None
    }
}

/// Encode `updates` and queue them to their sessions (lockstep: waiting for room, with the
/// camera frame each answers); returns the sessions whose connection is gone and the ms
/// taken. Each group's update is encoded once, in parallel with the others: the other
/// clients of a group only advance their codec's state (one codec for the whole server),
/// which equals the encoder's because their decoders hold the same state.
fn send_updates(
    sessions: &mut BTreeMap<u32, Session>,
    updates: FrameUpdates,
    lockstep: bool,
    rt: &tokio::runtime::Handle,
) -> (Vec<u32>, f64) {
    let te = Instant::now();
    let FrameUpdates {
        frame,
        seconds,
        hash,
        groups,
    } = updates;
    // Sessions that left since the updates were collected are in no group: skipped.
    let plan = coding_plan(sessions.values().map(|s| s.id), &groups);
    let jobs: Vec<(&mut Session, usize, bool)> = sessions
        .values_mut()
        .zip(plan)
        .filter_map(|(s, job)| job.map(|(g, encodes)| (s, g, encodes)))
        .collect();
    let payloads: Vec<(&mut Session, usize, Option<Vec<u8>>)> = jobs
        .into_par_iter()
        .map(|(s, g, encodes)| {
            let payload = code(s.codec.as_mut(), &groups[g].1, encodes);
            (s, g, payload)
        })
        .collect();
    // Copies of the encoded payloads for the other clients of groups with several.
    let shared: HashMap<usize, Vec<u8>> = payloads
        .iter()
        .filter(|(_, g, _)| groups[*g].0.len() > 1)
        .filter_map(|(_, g, payload)| Some((*g, payload.clone()?)))
        .collect();
    let encoded: Vec<(&mut Session, Option<Vec<u8>>)> = payloads
        .into_par_iter()
        .map(|(s, g, payload)| {
            let delta = Delta {
                frame,
                scene_time: seconds,
                client_frame: if lockstep { s.pending.take() } else { None },
                state_hash: if s.want_hash { hash } else { None },
                payload: payload.unwrap_or_else(|| shared[&g].clone()),
            };
            let message = if groups[g].1.snapshot {
                s.stats.snapshots += 1;
                Message::Snapshot(delta)
            } else {
                Message::Delta(delta)
            };
            let bytes = encode_frame(&message).ok();
            (s, bytes)
        })
        .collect();
    let mut gone = Vec::new();
    for (s, bytes) in encoded {
        let Some(bytes) = bytes else {
            gone.push(s.id.0);
            continue;
        };
        s.stats.bytes += bytes.len() as u64;
        s.stats.updates += 1;
        s.unacked.push_back(frame);
        let sent = if lockstep {
            rt.block_on(s.out.send(bytes)).is_ok()
        } else {
            s.out.try_send(bytes).is_ok()
        };
        if !sent {
            gone.push(s.id.0);
        }
    }
    (gone, te.elapsed().as_secs_f64() * 1e3)
}

/// The mean of `v` (0 when empty).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// The `q` quantile (0..=1) of `v` (nearest rank; 0 when empty).
pub fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// The hash a client's mirror of `server` reaches (grids and, with lighting, irradiance
/// records).
fn state_hash(server: &Server) -> u64 {
    psao_client::lit_state_hash_of(
        (0..server.instance_count()).map(|i| server.grid(i)),
        |i, s| server.light_cell(i, s),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::{accept, Accepted};

    /// A joined client that sends nothing is dropped once [`CLIENT_IDLE_TIMEOUT`] passed;
    /// one that sends keep-alives (acks) is not.
    #[tokio::test(start_paused = true)]
    async fn silent_clients_are_dropped_and_keep_alives_keep_them() {
        for keeps_alive in [false, true] {
            let (server_end, mut client_end) = tokio::io::duplex(4096);
            let (events, mut received) = mpsc::channel(64);
            let client = tokio::spawn(async move {
                use tokio::io::AsyncWriteExt;
                // The first bytes of a raw frame session, then keep-alives (or silence).
                let ack = encode_frame(&Message::Ack(psao_wire::Ack { frame: 0 })).unwrap();
                client_end.write_all(&ack).await.unwrap();
                let mut t = tokio::time::Duration::ZERO;
                while t < CLIENT_IDLE_TIMEOUT * 2 {
                    tokio::time::sleep(crate::view::KEEP_ALIVE).await;
                    t += crate::view::KEEP_ALIVE;
                    if keeps_alive && client_end.write_all(&ack).await.is_err() {
                        return;
                    }
                }
                // Closing ends a live session cleanly.
                drop(client_end);
            });
            let Ok(Accepted::Frames(mut reader, _writer)) =
                accept(Box::new(server_end), HELLO_TIMEOUT).await
            else {
                panic!("not taken for a frame session");
            };
            let t0 = tokio::time::Instant::now();
            let ended = read_loop(&mut reader, 1, &events).await;
            let lived = t0.elapsed();
            if keeps_alive {
                assert!(ended.is_ok(), "{ended:?}");
                assert!(lived >= CLIENT_IDLE_TIMEOUT * 2, "{lived:?}");
            } else {
                let err = ended.unwrap_err().to_string();
                assert!(err.contains("no message for"), "{err}");
                assert!(lived >= CLIENT_IDLE_TIMEOUT && lived < CLIENT_IDLE_TIMEOUT * 2);
            }
            client.await.unwrap();
            let mut acks = 0;
            while let Ok(Event::Ack(1, 0)) = received.try_recv() {
                acks += 1;
            }
            assert!(acks >= 1);
        }
    }
}
