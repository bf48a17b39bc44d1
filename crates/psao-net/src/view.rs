//! Viewing: a headless client. It follows a camera path at 60 Hz of scene time, sends its
//! camera, applies the server's deltas as they arrive, renders exactly as `psao run` does,
//! and reconnects with backoff when the connection drops.
//!
//! A network task owns the connection (and the simulated slow link: `--latency-ms`,
//! `--max-mbit`); the frame loop decodes and applies updates, so the codec state always
//! matches the session it belongs to.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use psao_client::ClientState;
use psao_delta::Codec;
use psao_scene::path::CameraPath;
use psao_scene::Scene;
use psao_wire::{
    capabilities, encode_frame, Ack, Bye, Delta, Hello, Message, RegionsMsg, RelightingMsg,
    Welcome, WireError, MAX_SERVER_FRAME, PROTOCOL_VERSION,
};
use serde::Serialize;
use tokio::sync::mpsc;

use crate::convert::{camera_msg, client_decoder, table_of};
use crate::corrective::{CorrectiveClient, CorrectiveClientConfig};
use crate::cpu_time::cpu_seconds;
use crate::hash_pacing::HashPacing;
use crate::pipeline::{client_time, ClientFrame, ClientRenderer, CLIENT_HZ};
use crate::transport::{connect, ReadError};
use crate::view_analyzer::Analyzer;
use crate::{NetError, Resolution};

/// How a client connects and what it runs.
#[derive(Debug, Clone)]
pub struct ViewConfig {
    /// Server address: `HOST:PORT` (TCP), `ws://HOST:PORT` or `wss://HOST:PORT` (WebSocket,
    /// over TLS); several, comma separated, are tried in turn on each reconnect.
    pub connect: String,
    /// PEM certificates to trust for `wss://` (default: the Mozilla roots).
    pub tls_ca: Option<PathBuf>,
    /// Access token.
    pub token: Option<String>,
    /// Client frames to run (default: the whole camera path).
    pub frames: Option<u32>,
    /// Image size (also the aspect of the camera sent to the server).
    pub res: Resolution,
    /// Render every frame and hand it to the caller's sink; otherwise updates are only
    /// received and applied.
    pub render: bool,
    /// Simulated one-way latency of received frames, ms.
    pub latency_ms: u64,
    /// Simulated link capacity for received frames, Mbit/s (0 = unlimited).
    pub max_mbit: f64,
    /// Give up after this many seconds without a connection.
    pub retry_secs: f64,
    /// Do not ask for the server's state hash with every update.
    pub no_verify: bool,
    /// Start this many frames into the camera path (wrapping around at its end).
    pub path_offset: u32,
    /// Fault injection: drop the connection once, at this client frame.
    pub drop_at: Option<u32>,
    /// Write the first received frames (≤ 64 KiB each) and their update payloads to this
    /// folder (seed corpus for the fuzz targets).
    pub record: Option<PathBuf>,
    /// Ask for corrective splatting: analyse the rendered frames, send the regions, splat the
    /// server's samples (frames are rendered even without `render`). In lockstep the frame
    /// loop analyses every `analyze_every` frames; otherwise an analyzer thread takes the
    /// latest shown frame every `analyze_every / 60` s of wall clock.
    pub corrective: Option<CorrectiveClientConfig>,
}

/// What the caller does with each rendered frame (e.g. write images).
pub type FrameSink<'a> =
    dyn FnMut(u32, &ClientFrame) -> Result<(), Box<dyn std::error::Error + Send + Sync>> + 'a;

/// Frames (and update payloads) `--record` writes at most.
const RECORD_MAX: u32 = 8;
/// How long a leaving client waits for the server to close after its bye.
const LEAVE_TIMEOUT: Duration = Duration::from_secs(3);
/// Longest a session goes without sending: then a keep-alive goes out (the server drops
/// clients silent for [`crate::serve::CLIENT_IDLE_TIMEOUT`]).
pub const KEEP_ALIVE: Duration = Duration::from_secs(5);

/// What a client run measured (`psao view --json` writes it).
#[derive(Debug, Default, Serialize)]
pub struct ViewStats {
    /// Client frames run.
    pub frames: u32,
    /// Received Mbit per second of scene time (frames on the wire, headers included).
    pub mbit_s: f64,
    /// Connections after the first.
    pub reconnects: u32,
    /// Hash of the client's final buckets + cells.
    pub state_hash: String,
    /// The server's hash at the last applied update (when it carried one).
    pub server_state_hash: Option<String>,
    /// Updates whose server hash differed from the client's after applying.
    pub hash_mismatches: u32,
    /// Server hashes compared: every one in lockstep; outside it as often as the
    /// comparison's cost allows (`crate::hash_pacing`), and the last update's at the end.
    pub hash_checks: u32,
    /// Bytes received.
    pub bytes: u64,
    /// Deltas and snapshots applied.
    pub updates: u32,
    /// Snapshots among them.
    pub snapshots: u32,
    /// Server frame of the last applied update.
    pub last_server_frame: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// CPU seconds of this process (all threads) over those (0 where unknown).
    pub cpu_seconds: f64,
    /// The server's id of every session, in order.
    pub client_ids: Vec<u32>,
    /// With corrections: hash of the final correction state
    /// ([`CorrectiveClient::state_hash`]).
    pub corrective_state_hash: Option<String>,
    /// With corrections: samples received (over every session).
    pub samples: u64,
    /// The server's last status text while updates were stalled (a scale-out edge waiting
    /// for its trace nodes), and status messages received.
    pub stalled: Option<String>,
    pub status_messages: u32,
}

/// From the network task to the frame loop.
enum NetEvent {
    /// A (new) session started.
    Welcome(Welcome),
    /// A message after the welcome and its size on the wire.
    Message(Message, usize),
    /// The session ended; the task reconnects.
    Lost(String),
    /// The task gave up.
    Fatal(NetError),
}

/// From the frame loop to the network task.
enum Outgoing {
    Send(Message),
    /// Drop the connection (fault injection).
    Drop,
}

/// Runs a client on `scene` along `path` (see the module documentation); rendered frames go
/// to `sink` when `args.render`. Returns the statistics (also when some updates left the
/// state different from the server's: see [`ViewStats::hash_mismatches`]).
pub fn view(
    scene: &Scene,
    path: &CameraPath,
    args: &ViewConfig,
    sink: &mut FrameSink<'_>,
) -> Result<ViewStats, NetError> {
    let total = path.frame_count() as u32;
    let frames = args.frames.unwrap_or(total).min(total);
    if frames == 0 {
        return Err(NetError::Config("nothing to do: 0 frames".into()));
    }
    if !(args.max_mbit.is_finite() && args.max_mbit >= 0.0) {
        return Err(NetError::Config("--max-mbit must be >= 0".into()));
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(NetError::io("cannot start the async runtime"))?;
    let (event_tx, mut events) = mpsc::channel::<NetEvent>(8);
    let (out_tx, out_rx) = mpsc::unbounded_channel::<Outgoing>();
    rt.spawn(network(args.clone(), event_tx, out_rx));

    let mut client = Client {
        record: args.record.clone(),
        corrective_config: args.corrective,
        res: args.res,
        relight: args.render,
        ..Client::default()
    };
    if let Some(dir) = &args.record {
        std::fs::create_dir_all(dir)
            .map_err(NetError::io(format!("cannot create {}", dir.display())))?;
    }
    let aspect = args.res.width as f32 / args.res.height as f32;
    let mut renderer = ClientRenderer::new(scene)?;
    let mut start = Instant::now();
    let mut cpu_start = cpu_seconds();
    let mut lockstep = None;
    // Without lockstep the analysis runs on its own thread, every `analyze_every` / 60 s.
    let mut analyzer = match &args.corrective {
        Some(c) => Some(Analyzer::new(Duration::from_secs_f64(
            f64::from(c.analyze_every) / f64::from(CLIENT_HZ),
        ))?),
        None => None,
    };
    for frame in 0..frames {
        let camera = path.camera_at_frame(((frame + args.path_offset) % total) as usize);
        if args.drop_at == Some(frame) {
            let _ = out_tx.send(Outgoing::Drop);
        }
        // Before a session exists nothing can be sent: wait for the welcome.
        while lockstep.is_none() {
            let e = events.blocking_recv().ok_or_else(network_ended)?;
            lockstep = client.handle(e, &out_tx)?;
            // The 60 Hz clock starts with the first session.
            start = Instant::now();
            cpu_start = cpu_seconds();
        }
        let camera_message = camera_msg(frame, &camera, aspect);
        if let (Some(a), Some(false)) = (&mut analyzer, lockstep) {
            if let Some(regions) = a.take(client.sessions) {
                client.regions = Some(regions);
            }
        }
        if let Some(c) = &mut client.corrective {
            if let Some(regions) = client.regions.take() {
                let _ = out_tx.send(Outgoing::Send(Message::Regions(regions)));
            }
            c.camera(&camera_message);
        }
        let _ = out_tx.send(Outgoing::Send(Message::Camera(camera_message)));
        if lockstep == Some(true) {
            // Wait for the server's answer to this frame; resend after a reconnect.
            loop {
                let e = events.blocking_recv().ok_or_else(network_ended)?;
                let reconnected = matches!(e, NetEvent::Welcome(_));
                if let Some(l) = client.handle(e, &out_tx)? {
                    lockstep = Some(l);
                }
                if reconnected {
                    let msg = camera_msg(frame, &camera, aspect);
                    if let Some(c) = &mut client.corrective {
                        c.camera(&msg);
                    }
                    let _ = out_tx.send(Outgoing::Send(Message::Camera(msg)));
                }
                if client.answered == Some(frame) {
                    break;
                }
            }
        } else {
            let due = start + Duration::from_secs_f64(f64::from(frame) / f64::from(CLIENT_HZ));
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            while let Ok(e) = events.try_recv() {
                if let Some(l) = client.handle(e, &out_tx)? {
                    lockstep = Some(l);
                }
            }
        }
        for msg in client.relighting.drain(..) {
            renderer.relight(scene, &msg)?;
        }
        if args.render || client.corrective.is_some() {
            // The client's clock: frame / 60 s (equal to the server's in lockstep).
            let time = client_time(frame);
            let mut img = renderer.render(scene, &client.state, &camera, args.res, time)?;
            if let Some(c) = &mut client.corrective {
                let corrected = match (&mut analyzer, lockstep) {
                    // Threaded: the analyzer thread takes the frame when it is due.
                    (Some(a), Some(false)) => {
                        let corrected = c.correct(scene, frame, &img.gbuffer, img.base());
                        a.offer(client.sessions, &corrected);
                        corrected
                    }
                    _ => {
                        let mut corrected = c.frame(scene, frame, &img.gbuffer, img.base());
                        client.regions = corrected.regions.take();
                        corrected
                    }
                };
                img.corrected = Some(corrected.image);
            }
            if args.render {
                sink(frame, &img).map_err(NetError::Sink)?;
            }
        }
    }
    let _ = out_tx.send(Outgoing::Send(Message::Bye(Bye {
        reason: "done".into(),
    })));
    // What the server sent before it read the bye is still on its way: take it until the
    // server closes (bounded, in case the server never does), so nothing it counted as sent
    // goes missing here.
    let leave_by = Instant::now() + LEAVE_TIMEOUT;
    while let Ok(Some(e)) = rt.block_on(async {
        tokio::time::timeout(
            leave_by.saturating_duration_since(Instant::now()),
            events.recv(),
        )
        .await
    }) {
        client.handle(e, &out_tx)?;
    }
    rt.shutdown_timeout(Duration::from_millis(200));
    let seconds = f64::from(frames) / f64::from(CLIENT_HZ);
    let stats = ViewStats {
        frames,
        mbit_s: client.bytes as f64 * 8.0 / seconds / 1e6,
        reconnects: client.sessions.saturating_sub(1),
        state_hash: format!("{:016x}", client.check_last_hash()),
        server_state_hash: client.server_hash.map(|h| format!("{h:016x}")),
        hash_mismatches: client.mismatches,
        hash_checks: client.hash_checks,
        bytes: client.bytes,
        updates: client.updates,
        snapshots: client.snapshots,
        last_server_frame: client.last_frame,
        seconds: start.elapsed().as_secs_f64(),
        cpu_seconds: match (cpu_start, cpu_seconds()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        },
        client_ids: client.ids.clone(),
        corrective_state_hash: client
            .corrective
            .as_ref()
            .map(|c| format!("{:016x}", c.state_hash())),
        samples: client.samples,
        stalled: client.stalled.clone(),
        status_messages: client.status_messages,
    };
    Ok(stats)
}

fn network_ended() -> NetError {
    NetError::Protocol("network task ended".into())
}

/// The frame loop's session state.
struct Client {
    state: ClientState,
    codec: Option<Box<dyn Codec>>,
    sessions: u32,
    bytes: u64,
    updates: u32,
    snapshots: u32,
    mismatches: u32,
    /// Server hashes compared with this state's.
    hash_checks: u32,
    last_frame: u64,
    /// The server's hash of the last applied update's state (when it carried one).
    server_hash: Option<u64>,
    /// Whether that hash is not compared yet.
    unchecked: bool,
    /// Whether the session is in lockstep (every server hash is then compared).
    lockstep: bool,
    /// When the next comparison is due outside lockstep.
    hash_pacing: HashPacing,
    /// Lockstep: the latest client frame the server answered.
    answered: Option<u32>,
    record: Option<PathBuf>,
    recorded: u32,
    ids: Vec<u32>,
    /// Corrections wanted, and the image size they are for.
    corrective_config: Option<CorrectiveClientConfig>,
    res: Resolution,
    /// This session's correction state.
    corrective: Option<CorrectiveClient>,
    /// The latest analysis, sent with the next camera.
    regions: Option<RegionsMsg>,
    /// Samples received over every session.
    samples: u64,
    /// The last stall the server told of, and status messages received.
    stalled: Option<String>,
    status_messages: u32,
    /// Whether relighting models were asked for ([`capabilities::RELIGHT`]: when rendering).
    relight: bool,
    /// Relighting models received and not yet handed to the renderer.
    relighting: Vec<RelightingMsg>,
}

impl Default for Client {
    fn default() -> Self {
        Self {
            state: ClientState::new(&[]),
            codec: None,
            sessions: 0,
            bytes: 0,
            updates: 0,
            snapshots: 0,
            mismatches: 0,
            hash_checks: 0,
            last_frame: 0,
            server_hash: None,
            unchecked: false,
            lockstep: false,
            hash_pacing: HashPacing::default(),
            answered: None,
            record: None,
            recorded: 0,
            ids: Vec::new(),
            corrective_config: None,
            res: Resolution {
                width: 1,
                height: 1,
            },
            corrective: None,
            regions: None,
            samples: 0,
            stalled: None,
            status_messages: 0,
            relight: false,
            relighting: Vec::new(),
        }
    }
}

impl Client {
    /// Handle one network event; returns the session's lockstep flag on a welcome.
    fn handle(
        &mut self,
        event: NetEvent,
        out: &mpsc::UnboundedSender<Outgoing>,
    ) -> Result<Option<bool>, NetError> {
        match event {
            NetEvent::Welcome(w) => {
                let table = table_of(&w.instances)?;
                let codec = client_decoder(&w.codec, &table)?;
                self.state = ClientState::new(&table);
                self.codec = Some(codec);
                self.sessions += 1;
                self.ids.push(w.client_id);
                self.answered = None;
                self.lockstep = w.lockstep;
                // A new session starts corrections afresh (the server's state is new too).
                self.corrective = match self.corrective_config {
                    Some(c) => Some(CorrectiveClient::new(self.res.width, self.res.height, c)?),
                    None => None,
                };
                self.regions = None;
                tracing::info!(
                    "session {} with the server: client {}, codec {}, {} Hz, lockstep {}",
                    self.sessions,
                    w.client_id,
                    w.codec,
                    w.server_hz,
                    w.lockstep
                );
                return Ok(Some(w.lockstep));
            }
            NetEvent::Message(m, size) => {
                self.bytes += size as u64;
                self.record(&m)?;
                match m {
                    Message::Delta(d) => self.apply(d, false, out)?,
                    Message::Snapshot(d) => self.apply(d, true, out)?,
                    Message::SceneTime(t) => {
                        if t.client_frame.is_some() {
                            self.answered = t.client_frame;
                        }
                    }
                    Message::Error(e) => {
                        return Err(NetError::Refused {
                            code: e.code,
                            message: e.message,
                        })
                    }
                    Message::Bye(b) => tracing::info!("server said bye: {}", b.reason),
                    Message::Status(s) => {
                        self.status_messages += 1;
                        if s.stalled {
                            tracing::warn!("the server's updates stalled: {}", s.text);
                            self.stalled = Some(s.text);
                        } else {
                            tracing::info!("the server's updates flow again");
                        }
                    }
                    Message::Relighting(r) if self.relight => self.relighting.push(r),
                    Message::Samples(samples) => {
                        let c = self.corrective.as_mut().ok_or_else(|| {
                            NetError::Protocol("samples from the server without asking".into())
                        })?;
                        c.receive(&samples)?;
                        self.samples += samples.samples.len() as u64;
                    }
                    other => {
                        return Err(NetError::Protocol(format!(
                            "unexpected {} from the server",
                            other.kind()
                        )))
                    }
                }
            }
            NetEvent::Lost(why) => tracing::warn!("connection lost: {why}; reconnecting"),
            NetEvent::Fatal(why) => return Err(why),
        }
        Ok(None)
    }

    /// `--record`: keep small frames and update payloads as fuzzing seeds.
    fn record(&mut self, m: &Message) -> Result<(), NetError> {
        let Some(dir) = &self.record else {
            return Ok(());
        };
        let frame = encode_frame(m)?;
        if self.recorded >= RECORD_MAX || frame.len() > 64 << 10 {
            return Ok(());
        }
        let n = self.recorded;
        self.recorded += 1;
        let write = |name: String, bytes: &[u8]| {
            let file = dir.join(name);
            std::fs::write(&file, bytes)
                .map_err(NetError::io(format!("cannot write {}", file.display())))
        };
        write(format!("frame_{n:03}.bin"), &frame)?;
        if let Message::Delta(d) | Message::Snapshot(d) = m {
            write(format!("delta_{n:03}.bin"), &d.payload)?;
        }
        Ok(())
    }

    fn compare_hash(&mut self, server: u64, mine: u64, frame: u64) {
        self.hash_checks += 1;
        if server != mine {
            self.mismatches += 1;
            tracing::error!("state differs from the server's after frame {frame}");
        }
    }

    /// The final state's hash, compared with the server's hash of the last applied update
    /// when that one was left unchecked.
    fn check_last_hash(&mut self) -> u64 {
        let mine = self.state.state_hash();
        if let (true, Some(server)) = (self.unchecked, self.server_hash) {
            self.unchecked = false;
            self.compare_hash(server, mine, self.last_frame);
        }
        mine
    }

    fn apply(
        &mut self,
        d: Delta,
        snapshot: bool,
        out: &mpsc::UnboundedSender<Outgoing>,
    ) -> Result<(), NetError> {
        let codec = self
            .codec
            .as_mut()
            .ok_or_else(|| NetError::Protocol("update before the welcome".into()))?;
        let update = codec
            .decode(&d.payload)
            .map_err(NetError::codec("cannot decode the server's update"))?;
        if update.snapshot != snapshot {
            return Err(NetError::Protocol(
                "the update's snapshot flag does not match its message".into(),
            ));
        }
        self.state.apply(&update)?;
        self.updates += 1;
        self.snapshots += u32::from(snapshot);
        self.last_frame = d.frame;
        // The server's hash of this update's state, checked as often as its cost allows
        // outside lockstep (crate::hash_pacing); one left unchecked at the end of the view
        // is checked then ([`Client::check_last_hash`]).
        self.server_hash = d.state_hash;
        self.unchecked = false;
        if let Some(h) = d.state_hash {
            let state = &self.state;
            match self
                .hash_pacing
                .hash_if_due(self.lockstep, || state.state_hash())
            {
                Some(mine) => self.compare_hash(h, mine, d.frame),
                None => self.unchecked = true,
            }
        }
        if d.client_frame.is_some() {
            self.answered = d.client_frame;
        }
        let _ = out.send(Outgoing::Send(Message::Ack(Ack { frame: d.frame })));
        Ok(())
    }
}

/// Connect, handshake, pump frames both ways; reconnect with backoff until `retry_secs`
/// pass without a session.
async fn network(
    args: ViewConfig,
    events: mpsc::Sender<NetEvent>,
    mut outgoing: mpsc::UnboundedReceiver<Outgoing>,
) {
    let mut backoff = Duration::from_millis(100);
    let mut last_ok = Instant::now();
    // A list of servers (edges, docs/SCALE-OUT.md) is tried in turn, one per attempt.
    let servers: Vec<&str> = args.connect.split(',').map(str::trim).collect();
    for attempt in 0.. {
        let server = servers[attempt % servers.len()];
        match session(&args, server, &events, &mut outgoing).await {
            Ok(SessionEnd::Closed) => return,
            Ok(SessionEnd::Reconnect(why)) => {
                last_ok = Instant::now();
                backoff = Duration::from_millis(100);
                if events.send(NetEvent::Lost(why)).await.is_err() {
                    return;
                }
            }
            Err(SessionError::Fatal(why)) => {
                let _ = events.send(NetEvent::Fatal(why)).await;
                return;
            }
            Err(SessionError::Retry(why)) => {
                if last_ok.elapsed().as_secs_f64() > args.retry_secs {
                    let _ = events
                        .send(NetEvent::Fatal(NetError::Unreachable {
                            seconds: args.retry_secs,
                            last: why,
                        }))
                        .await;
                    return;
                }
                tracing::debug!("connect failed ({why}); retrying in {backoff:?}");
            }
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(Duration::from_secs(2));
    }
}

enum SessionEnd {
    /// The frame loop is done.
    Closed,
    /// The session ended after a welcome; connect again.
    Reconnect(String),
}

enum SessionError {
    /// Could not establish a session; try again.
    Retry(String),
    /// The server refused us for good.
    Fatal(NetError),
}

async fn session(
    args: &ViewConfig,
    server: &str,
    events: &mpsc::Sender<NetEvent>,
    outgoing: &mut mpsc::UnboundedReceiver<Outgoing>,
) -> Result<SessionEnd, SessionError> {
    let retry = |e: NetError| SessionError::Retry(e.to_string());
    let (mut reader, mut writer) = connect(server, MAX_SERVER_FRAME, args.tls_ca.as_deref())
        .await
        .map_err(retry)?;
    let hello = Message::Hello(Hello {
        version: PROTOCOL_VERSION,
        capabilities: {
            let verify = if args.no_verify {
                0
            } else {
                capabilities::STATE_HASH
            };
            let corrective = if args.corrective.is_some() {
                capabilities::CORRECTIVE
            } else {
                0
            };
            // A client that renders relights the characters it is sent models of.
            let relight = if args.render {
                capabilities::RELIGHT
            } else {
                0
            };
            capabilities::CODEC_PAPER
                | capabilities::CODEC_COMPACT
                | capabilities::STATUS
                | verify
                | corrective
                | relight
        },
        token: args.token.clone(),
        name: format!("psao view {}", std::process::id()),
    });
    let frame = encode_frame(&hello).map_err(|e| SessionError::Fatal(e.into()))?;
    writer.send(frame).await.map_err(retry)?;
    let welcome = match reader.next(MAX_SERVER_FRAME).await {
        Ok(Some((Message::Welcome(w), _))) => w,
        Ok(Some((Message::Error(e), _))) => {
            return Err(SessionError::Fatal(NetError::Refused {
                code: e.code,
                message: e.message,
            }))
        }
        Ok(Some((m, _))) => {
            return Err(SessionError::Fatal(NetError::Protocol(format!(
                "expected welcome, got {}",
                m.kind()
            ))))
        }
        Ok(None) => return Err(SessionError::Retry("closed before the welcome".into())),
        Err(ReadError::Wire(w)) => {
            return Err(SessionError::Fatal(NetError::Protocol(bad_frame(&w))))
        }
        Err(e) => return Err(SessionError::Retry(e.to_string())),
    };
    if welcome.version != PROTOCOL_VERSION {
        return Err(SessionError::Fatal(NetError::Protocol(format!(
            "the server speaks protocol version {}",
            welcome.version
        ))));
    }
    if events.send(NetEvent::Welcome(welcome)).await.is_err() {
        return Ok(SessionEnd::Closed);
    }
    // Received frames pass through a delay line (latency) after a rate limiter (capacity).
    let latency = Duration::from_millis(args.latency_ms);
    let max_mbit = args.max_mbit;
    let (delay_tx, mut delay_rx) = mpsc::channel::<(Instant, Message, usize)>(64);
    let reader_task = tokio::spawn(async move {
        loop {
            match reader.next(MAX_SERVER_FRAME).await {
                Ok(Some((m, size))) => {
                    if max_mbit > 0.0 {
                        let secs = size as f64 * 8.0 / (max_mbit * 1e6);
                        tokio::time::sleep(Duration::from_secs_f64(secs)).await;
                    }
                    if delay_tx
                        .send((Instant::now() + latency, m, size))
                        .await
                        .is_err()
                    {
                        return Ok(());
                    }
                }
                Ok(None) => return Ok(()),
                // A malformed frame, a frame cut short by the end of the stream included,
                // ends the client; a failed connection (reset, WebSocket closed without
                // its handshake) reconnects.
                Err(ReadError::Wire(w)) => return Err((true, bad_frame(&w))),
                Err(e) => return Err((false, e.to_string())),
            }
        }
    });
    let mut reader_task = reader_task;
    // The server drops a client that sends nothing for a while: when no camera or ack went
    // out for KEEP_ALIVE (a lockstep client waiting for the others), an ack of the last
    // acknowledged frame (a no-op for the server) says this one is still there.
    let mut last_ack = 0u64;
    let mut keep_alive =
        tokio::time::interval_at(tokio::time::Instant::now() + KEEP_ALIVE, KEEP_ALIVE);
    keep_alive.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = keep_alive.tick() => {
                let frame = encode_frame(&Message::Ack(Ack { frame: last_ack }));
                let sent = match frame {
                    Ok(f) => writer.send(f).await.is_ok(),
                    Err(_) => false,
                };
                if !sent {
                    reader_task.abort();
                    return Ok(SessionEnd::Reconnect("send failed".into()));
                }
            }
            item = delay_rx.recv() => {
                let Some((due, m, size)) = item else {
                    let why = match (&mut reader_task).await {
                        Ok(Err((true, e))) => {
                            return Err(SessionError::Fatal(NetError::Protocol(e)))
                        }
                        Ok(Err((false, e))) => e,
                        _ => "the server closed the connection".into(),
                    };
                    return Ok(SessionEnd::Reconnect(why));
                };
                tokio::time::sleep_until(due.into()).await;
                let fatal = matches!(m, Message::Error(_));
                if events.send(NetEvent::Message(m, size)).await.is_err() {
                    return Ok(SessionEnd::Closed);
                }
                if fatal {
                    return Ok(SessionEnd::Closed);
                }
            }
            out = outgoing.recv() => {
                match out {
                    None => {
                        writer.close().await;
                        return Ok(SessionEnd::Closed);
                    }
                    Some(Outgoing::Drop) => {
                        reader_task.abort();
                        writer.close().await;
                        return Ok(SessionEnd::Reconnect("dropped on purpose".into()));
                    }
                    Some(Outgoing::Send(m)) => {
                        keep_alive.reset();
                        if let Message::Ack(a) = &m {
                            last_ack = a.frame;
                        }
                        let bye = matches!(m, Message::Bye(_));
                        let sent = match encode_frame(&m) {
                            Ok(f) => writer.send(f).await.is_ok(),
                            Err(_) => false,
                        };
                        if bye {
                            if sent {
                                forward_until_closed(&mut delay_rx, events).await;
                            }
                            reader_task.abort();
                            writer.close().await;
                            return Ok(SessionEnd::Closed);
                        }
                        if !sent {
                            reader_task.abort();
                            return Ok(SessionEnd::Reconnect("send failed".into()));
                        }
                    }
                }
            }
        }
    }
}

/// After the bye: passes on what the server still sends until it closes the connection or
/// [`LEAVE_TIMEOUT`] passes.
async fn forward_until_closed(
    delay_rx: &mut mpsc::Receiver<(Instant, Message, usize)>,
    events: &mpsc::Sender<NetEvent>,
) {
    let leave_by = tokio::time::Instant::now() + LEAVE_TIMEOUT;
    while let Ok(Some((due, m, size))) = tokio::time::timeout_at(leave_by, delay_rx.recv()).await {
        tokio::time::sleep_until(due.into()).await;
        if events.send(NetEvent::Message(m, size)).await.is_err() {
            return;
        }
    }
}

/// The error text of a malformed frame from the server.
fn bad_frame(w: &WireError) -> String {
    match w {
        WireError::Truncated { .. } => {
            format!("the server's frame was cut short: {w}")
        }
        _ => format!("bad frame from the server: {w}"),
    }
}
