// The page served at `/`: connects to the server's WebSocket (`/ws`; the token comes from the
// URL fragment, `#token=…`, which the browser never sends to a server, and goes in the hello
// and as `Authorization: Bearer` for `/scene.glb`),
// keeps the client state current and its grids in GPU textures, draws the scene with
// per-pixel AO and, when the server sends irradiance (`psao serve --lighting gi`), lit: the
// points' irradiance plus shadow-mapped suns and point lights (keys 1/2/3/4 or the buttons:
// composited, irradiance, direct, AO), follows a
// camera path of the scene (the first one, or `?path=NAME`) so the server traces what it
// would show, or orbits the scene (bounds from `/scene.glb`) when it has no path or with
// `?orbit=1`; the user takes over from wherever the camera is; reconnects with backoff,
// and shows an overlay: fps, Mbit/s, server frame, round-trip time (a GET of `/health`
// every 2 s), updates, points, decode ms, state-hash checks (`?verify=1` asks the server for
// its hash with every update), and a clear message for a wrong token or protocol version.
//
// Test mode (`?path=NAME&frames=N&lockstep=1&res=WxH&mode=ao`; modes composited,
// irradiance, direct, ao, noao): the canvas is WxH, camera
// frame f of the path is sent only after the server answered frame f − 1 (the server runs
// with `--lockstep`), the view after the answer to frame N − 1 stays on screen and
// `window.psao.done` turns true: the same frames `psao view --frames N` renders;
// `&scale=K` rasterizes the G-buffer at K× (see `scale` below), `&shadowscale=K` the shadow
// maps.
// `?edges=HOST:PORT,…` lists further servers (edges of a scaled-out session, docs/SCALE-OUT.md)
// to use in turn, after the page's own, when a connection ends: a viewer whose edge dies
// moves to the next one.
// Against `psao serve --relight` the page relights the served characters (`relit.ts`;
// `?relit=0` leaves them unrelit); `window.psaoRelitCost(frames)` times the relighting.
// `window.psao` exposes the numbers to tests; `window.psaoCost()` measures the shader's cost.

import { Codec } from "./codec";
import { Session } from "./session";
import { sceneBounds } from "./bounds";
import { GridTextures } from "./grids";
import { MODE_AO, MODE_COMPOSITED, MODE_COST, MODE_DIRECT, MODE_IRRADIANCE, MODE_NO_AO } from "./aoshader";
import { SceneRenderer, type CameraPathDoc } from "./render";
import { RelitCharacters, type RelitIndex } from "./relit";
import type { Camera } from "./wire";

interface Status {
  connected: boolean;
  sessions: number;
  updates: number;
  verified: number;
  mismatches: number;
  serverFrame: number;
  points: number;
  hash: string | null;
  message: string | null;
  fatal: boolean;
  /// What the server said about its updates stalling (null while they flow).
  stalled: string | null;
  mbitS: number;
  fps: number;
  /// Frames drawn with WebGL2 (0 when it is unavailable).
  drawn: number;
  /// The camera drawn and sent last.
  camera: Camera | null;
  /// Whether the camera orbits by itself (until the user moves it).
  autoOrbit: boolean;
  /// The drawn view (aoshader.ts' MODE_*): 0 composited, 1 irradiance, 2 direct, 3 AO
  /// only, 4 no AO.
  mode: number;
  /// Whether the session is lit (its state holds irradiance records).
  lit: boolean;
  /// Milliseconds of the last drawn frame's shadow maps (CPU side of the calls) and of
  /// the whole draw call.
  shadowMs: number;
  drawMs: number;
  /// The server (HOST:PORT) of the current or last session, and of the last answered
  /// GET /health with its round-trip time, ms.
  edge: string;
  rttEdge: string | null;
  rttMs: number | null;
  /// The followed camera path's name and frame.
  path: string | null;
  pathFrame: number;
  /// Test mode: the last frame was answered and drawn.
  done: boolean;
  /// Decode (and apply) ms per update, and texture bytes uploaded.
  decodeMs: number;
  uploadedBytes: number;
  /// Full rebuilds of the grid textures (first update, snapshots, outgrown reserves) and
  /// their size in bytes.
  rebuilds: number;
  textureBytes: number;
  /// When (performance.now() ms) the scene was loaded, the first welcome and update
  /// arrived, and the first frame with AO (grids holding points) was drawn; null until then.
  milestones: { scene: number | null; welcome: number | null; update: number | null; ao: number | null };
  /// Relit characters: loading (models on their way), none (the server relights nothing, or
  /// `?relit=0`), ready or error (the message says why); their count, relit vertices, model
  /// bytes and the last drawn frame's relighting ms (wasm).
  relit: { state: "loading" | "none" | "ready" | "error"; characters: number; vertices: number; modelBytes: number; ms: number };
}

const status: Status = {
  connected: false,
  sessions: 0,
  updates: 0,
  verified: 0,
  mismatches: 0,
  serverFrame: 0,
  points: 0,
  hash: null,
  message: null,
  fatal: false,
  stalled: null,
  mbitS: 0,
  fps: 0,
  drawn: 0,
  camera: null,
  autoOrbit: true,
  mode: MODE_COMPOSITED,
  lit: false,
  shadowMs: 0,
  drawMs: 0,
  edge: location.host,
  rttEdge: null,
  rttMs: null,
  path: null,
  pathFrame: 0,
  done: false,
  decodeMs: 0,
  uploadedBytes: 0,
  rebuilds: 0,
  textureBytes: 0,
  milestones: { scene: null, welcome: null, update: null, ao: null },
  relit: { state: "loading", characters: 0, vertices: 0, modelBytes: 0, ms: 0 },
};
(window as unknown as { psao: Status }).psao = status;

const params = new URLSearchParams(location.search);
/// The access token: `#token=…` in the URL (never sent in a request line, kept out of the
/// server's logs); removed from the address bar once read.
const token = new URLSearchParams(location.hash.slice(1)).get("token");
if (token !== null) history.replaceState(null, "", location.pathname + location.search);
const verify = params.get("verify") === "1";
const pathName = params.get("path");
/// `?orbit=1`: orbit the scene from outside instead of following its first camera path.
const orbitOnly = params.get("orbit") === "1";
const testFrames = params.has("frames") ? Math.max(1, Number(params.get("frames"))) : null;
const lockstep = params.get("lockstep") === "1";
const fixedRes = /^(\d+)x(\d+)$/.exec(params.get("res") ?? "");
/// G-buffer samples per pixel and axis (`?scale=K`, odd): with K > 1 the rasterizer's
/// 4-bit sub-pixel snapping (SwiftShader's) moves edges by 1/(16·K) pixel instead of 1/16, so
/// which surface covers a pixel centre agrees with psao-raster's 12-bit edges far more often.
const scale = Math.max(1, Math.floor(Number(params.get("scale") ?? "1")) | 1);
/// Shadow-map samples per texel and axis (`?shadowscale=K`, odd), for the same reason.
const shadowScale = Math.max(1, Math.floor(Number(params.get("shadowscale") ?? "1")) | 1);
const MODES: Record<string, number> = {
  composited: MODE_COMPOSITED,
  irradiance: MODE_IRRADIANCE,
  direct: MODE_DIRECT,
  ao: MODE_AO,
  noao: MODE_NO_AO,
};
status.mode = MODES[params.get("mode") ?? ""] ?? MODE_COMPOSITED;
/// The page's own server, then those of `?edges=` (HOST:PORT, malformed ones left out).
const edges = [location.host];
for (const e of (params.get("edges") ?? "").split(",").map((e) => e.trim())) {
  if (/^[\w.-]+:\d+$|^\[[0-9a-fA-F:.]+\]:\d+$/.test(e) && !edges.includes(e)) edges.push(e);
}
let edgeIndex = 0;
const wsUrl = (host: string) => `${location.protocol === "https:" ? "wss" : "ws"}://${host}/ws`;

/// The decoder (`/psao.wasm`), loaded before the first connection.
let codec: Codec | null = null;
let session: Session | null = null;
let backoff = 200;
let received: { t: number; bytes: number }[] = [];

function connect() {
  status.edge = edges[edgeIndex];
  session?.release();
  session = new Session(
    codec!,
    { url: wsUrl(status.edge), token, verify, name: "psao browser viewer" },
    {
      welcome: () => {
        status.milestones.welcome ??= performance.now();
        status.connected = true;
        status.sessions++;
        status.message = null;
        status.stalled = null;
        backoff = 200;
        if (session?.state) grids?.reset(session.state);
        // A new session (also after a restart) starts the path again.
        pathFrame = 0;
        answered = -1;
        sent = -1;
      },
      sceneTime: (_frame, clientFrame, seconds) => {
        if (clientFrame !== null) answered = Math.max(answered, clientFrame);
        serverTime = { seconds, at: performance.now() };
      },
      update: (frame, bytes, verified) => {
        status.milestones.update ??= performance.now();
        if (session?.state) grids?.apply(session.state.changes());
        status.updates++;
        if (verified) status.verified++;
        status.mismatches = session?.mismatches ?? status.mismatches;
        status.serverFrame = frame;
        received.push({ t: performance.now(), bytes });
        if (session?.lastHash != null) status.hash = session.lastHash.toString(16).padStart(16, "0");
      },
      status: (text) => (status.stalled = text),
      closed: (reason, fatal) => {
        status.connected = false;
        status.message = reason;
        status.fatal = fatal;
        if (!fatal) {
          edgeIndex = (edgeIndex + 1) % edges.length;
          setTimeout(connect, backoff);
          backoff = Math.min(backoff * 2, 5000);
        }
      },
    },
  );
}

const overlay = document.getElementById("overlay")!;
const message = document.getElementById("message")!;
let frames: number[] = [];
let cameraFrame = 0;
let orbit: { centre: [number, number, number]; radius: number } | null = null;


const canvas = document.getElementById("view") as HTMLCanvasElement;
// Kept after compositing so that tests (and screenshots) can read the frame back.
const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
let renderer: SceneRenderer | null = null;
/// Why the scene could not be loaded or drawn, or null.
let sceneError: string | null = null;
const grids = gl ? new GridTextures(gl) : null;
/// The followed path, its current frame, and (lockstep) the frames sent and answered.
let path: CameraPathDoc | null = null;
let pathFrame = 0;
let sent = -1;
let answered = -1;
let pathStart = 0;
/// The server's latest scene time and when it arrived (skinned instances are posed at it,
/// advanced by the wall time since).
let serverTime: { seconds: number; at: number } | null = null;

/// The scene time to pose skinned instances at: in lockstep test runs the client clock of
/// the drawn path frame (frame / 60 s, as `psao view`), else the server's.
function sceneTime(now: number): number {
  if (lockstep && testFrames !== null) return Math.max(answered, 0) / 60;
  return serverTime ? serverTime.seconds + (now - serverTime.at) / 1000 : 0;
}

for (const [id, mode] of [
  ["mode-composited", MODE_COMPOSITED],
  ["mode-irradiance", MODE_IRRADIANCE],
  ["mode-direct", MODE_DIRECT],
  ["mode-ao", MODE_AO],
] as const) {
  document.getElementById(id)?.addEventListener("click", () => (status.mode = mode));
}

/// The camera: it follows the path (or orbits the scene) by itself until the user drags
/// (orbit), scrolls (zoom) or flies (W/A/S/D forward/left/back/right, Q/E down/up); Space
/// gives the camera back to the path (or the auto-orbit).
const control = { auto: true, yaw: 0, pitch: 0.3, distance: 0, keys: new Set<string>(), last: 0 };

canvas.addEventListener("mousedown", (e) => {
  control.auto = false;
  const move = (m: MouseEvent) => {
    control.yaw += m.movementX * 0.005;
    control.pitch = Math.max(-1.5, Math.min(1.5, control.pitch + m.movementY * 0.005));
  };
  const up = () => {
    window.removeEventListener("mousemove", move);
    window.removeEventListener("mouseup", up);
  };
  window.addEventListener("mousemove", move);
  window.addEventListener("mouseup", up);
  e.preventDefault();
});
canvas.addEventListener(
  "wheel",
  (e) => {
    control.auto = false;
    const r = orbit?.radius ?? 1;
    control.distance = Math.max(r * 0.01, Math.min(r * 20, control.distance * Math.exp(e.deltaY * 0.001)));
    e.preventDefault();
  },
  { passive: false },
);
window.addEventListener("keydown", (e) => {
  if (e.key === "1") status.mode = MODE_COMPOSITED;
  else if (e.key === "2") status.mode = MODE_IRRADIANCE;
  else if (e.key === "3") status.mode = MODE_DIRECT;
  else if (e.key === "4") status.mode = MODE_AO;
  else if (e.key === " ") control.auto = true;
  else control.keys.add(e.key.toLowerCase());
});
window.addEventListener("keyup", (e) => control.keys.delete(e.key.toLowerCase()));

function orbitCamera(now: number): Camera | null {
  if (!orbit) return null;
  const dt = control.last ? Math.min((now - control.last) / 1000, 0.1) : 0;
  control.last = now;
  if (control.distance === 0) control.distance = orbit.radius * 1.5;
  if (control.auto) control.yaw += dt * ((2 * Math.PI) / 20);
  const dir = [
    -Math.cos(control.pitch) * Math.cos(control.yaw),
    -Math.sin(control.pitch),
    -Math.cos(control.pitch) * Math.sin(control.yaw),
  ];
  const speed = orbit.radius * 0.5 * dt;
  const k = control.keys;
  const fwd = (k.has("w") ? 1 : 0) - (k.has("s") ? 1 : 0);
  const side = (k.has("d") ? 1 : 0) - (k.has("a") ? 1 : 0);
  const lift = (k.has("e") ? 1 : 0) - (k.has("q") ? 1 : 0);
  if (fwd || side || lift) control.auto = false;
  const c = orbit.centre;
  const right = [-dir[2], 0, dir[0]];
  const rl = Math.hypot(right[0], right[2]) || 1;
  for (let i = 0; i < 3; i++) c[i] += speed * (fwd * dir[i] + (side * right[i]) / rl + (i === 1 ? lift : 0));
  const d = control.distance;
  return {
    frame: cameraFrame,
    position: [c[0] - d * dir[0], c[1] - d * dir[1], c[2] - d * dir[2]],
    target: [c[0], c[1], c[2]],
    up: [0, 1, 0],
    fovY: Math.PI / 3,
    near: Math.max(d * 1e-3, 1e-3),
    far: (d + orbit.radius) * 4,
    aspect: canvas.width / Math.max(canvas.height, 1),
  };
}

/// Camera `frame` of the followed path (wrapping around), as sent to the server.
function pathCamera(p: CameraPathDoc, frame: number, index: number): Camera {
  const f = p.frames[index % p.frames.length];
  return {
    frame,
    position: [f[0], f[1], f[2]],
    target: [f[3], f[4], f[5]],
    up: [f[6], f[7], f[8]],
    fovY: f[9],
    near: f[10],
    far: f[11],
    aspect: canvas.width / Math.max(canvas.height, 1),
  };
}

/// The camera of this tick and whether to send it: the lockstep test path, the followed path
/// (60 Hz of wall time, until the user takes over), or the orbit.
function currentCamera(now: number): { cam: Camera | null; send: boolean } {
  if (path && lockstep && testFrames !== null) {
    if (!session?.state) return { cam: null, send: false };
    if (answered === sent && sent < testFrames - 1) {
      sent++;
      return { cam: pathCamera(path, sent, sent), send: true };
    }
    return { cam: pathCamera(path, Math.max(answered, 0), Math.max(answered, 0)), send: false };
  }
  if (path && control.auto) {
    if (!pathStart) pathStart = now;
    pathFrame = Math.floor(((now - pathStart) / 1000) * 60);
    pathShown = pathCamera(path, cameraFrame, pathFrame);
    return { cam: pathShown, send: true };
  }
  if (pathShown) {
    takeOverFrom(pathShown);
    pathShown = null;
  }
  return { cam: orbitCamera(now), send: true };
}

/// The followed path's camera last shown, until the user takes over from it.
let pathShown: Camera | null = null;

/// Puts the user's orbit camera where `cam` is: centred on its target, at its distance,
/// looking the same way.
function takeOverFrom(cam: Camera) {
  if (!orbit) return;
  const look = [0, 1, 2].map((i) => cam.target[i] - cam.position[i]);
  const d = Math.hypot(look[0], look[1], look[2]) || 1;
  control.pitch = Math.max(-1.5, Math.min(1.5, Math.asin(Math.max(-1, Math.min(1, -look[1] / d)))));
  control.yaw = Math.atan2(-look[2], -look[0]);
  control.distance = d;
  orbit.centre = [cam.target[0], cam.target[1], cam.target[2]];
}

/// Draws one frame in the cost mode and reads it back: per covered pixel, the mean and
/// largest number of cells and points the AO shader visited.
function measureCost() {
  const cam = status.camera;
  if (!gl || !renderer || !cam) return null;
  const time = sceneTime(performance.now());
  renderer.draw(cam, { mode: MODE_COST, state: session?.state ?? null, grids, scale, shadowScale, time });
  const w = gl.drawingBufferWidth;
  const h = gl.drawingBufferHeight;
  const px = new Uint8Array(w * h * 4);
  gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let covered = 0;
  let cells = 0;
  let points = 0;
  let maxCells = 0;
  let maxPoints = 0;
  for (let i = 0; i < px.length; i += 4) {
    if (px[i + 3] !== 255) continue;
    covered++;
    const p = px[i + 1] + 256 * px[i + 2];
    cells += px[i];
    points += p;
    maxCells = Math.max(maxCells, px[i]);
    maxPoints = Math.max(maxPoints, p);
  }
  renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, shadowScale, time });
  return {
    width: w,
    height: h,
    covered,
    cellsPerPixel: covered ? cells / covered : 0,
    pointsPerPixel: covered ? points / covered : 0,
    maxCells,
    maxPoints,
  };
}
(window as unknown as { psaoCost: typeof measureCost }).psaoCost = measureCost;

let lastCamera = 0;
let lastPointCount = 0;
let lastPing = 0;
let cost: ReturnType<typeof measureCost> = null;
function ping(now: number) {
  if (now - lastPing < 2000) return;
  lastPing = now;
  const t0 = performance.now();
  const edge = status.edge;
  fetch(`${location.protocol}//${edge}/health`, { cache: "no-store" })
    .then((r) => r.arrayBuffer())
    .then(() => {
      status.rttMs = performance.now() - t0;
      status.rttEdge = edge;
    })
    .catch(() => (status.rttMs = null));
}

function tick(now: number) {
  frames.push(now);
  frames = frames.filter((t) => now - t < 1000);
  received = received.filter((r) => now - r.t < 1000);
  status.fps = frames.length;
  status.mbitS = (received.reduce((a, r) => a + r.bytes, 0) * 8) / 1e6;
  const w0 = fixedRes ? Number(fixedRes[1]) : Math.round(window.innerWidth * devicePixelRatio);
  const h0 = fixedRes ? Number(fixedRes[2]) : Math.round(window.innerHeight * devicePixelRatio);
  if (canvas.width !== w0 || canvas.height !== h0) {
    canvas.width = w0;
    canvas.height = h0;
    if (fixedRes) {
      canvas.style.width = `${w0}px`;
      canvas.style.height = `${h0}px`;
    }
  }
  if (!lockstep) ping(now);
  const { cam, send } = currentCamera(now);
  status.camera = cam;
  status.autoOrbit = control.auto;
  status.path = path && (control.auto || lockstep) ? path.name : null;
  status.pathFrame = lockstep ? Math.max(answered, 0) : pathFrame;
  if (cam && send && (lockstep || now - lastCamera > 1000 / 30)) {
    lastCamera = now;
    session?.sendCamera(cam);
    cameraFrame++;
  }
  // Lockstep test runs draw only the last frame (what is compared), so that stepping
  // through the path does not wait for frames nobody looks at.
  const drawNow = !(lockstep && testFrames !== null) || answered === testFrames - 1;
  if (cam && renderer && drawNow) {
    grids?.upload();
    const t0 = performance.now();
    renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, shadowScale, time: sceneTime(now) });
    status.drawMs = performance.now() - t0;
    status.shadowMs = renderer.shadowMs;
    status.lit = session?.state?.hasLights() ?? false;
    status.drawn++;
    if (status.milestones.ao === null && status.mode !== MODE_NO_AO && grids && grids.cellPages > 0 && !grids.problem) {
      status.milestones.ao = performance.now();
    }
    status.relit.ms = renderer.relit?.ms ?? 0;
    if (renderer.relitError && status.relit.state === "ready") {
      status.relit.state = "error";
      status.message = renderer.relitError;
    }
    // A test run's last frame counts once the relit characters (if any) are loaded.
    if (lockstep && testFrames !== null && answered === testFrames - 1 && status.relit.state !== "loading") status.done = true;
  }
  if (now - lastPointCount > 500) {
    lastPointCount = now;
    status.points = session?.state?.pointCount() ?? 0;
  }
  status.decodeMs = session && session.updates > 0 ? session.decodeMs / session.updates : 0;
  status.uploadedBytes = grids?.uploadedBytes ?? 0;
  status.rebuilds = grids?.rebuilds ?? 0;
  status.textureBytes = grids ? grids.textureBytes() : 0;
  const w = session?.welcomeMsg;
  const modeName = ["composited", "irradiance", "direct light", "AO only", "no AO"][status.mode] ?? "";
  overlay.textContent = [
    `psao viewer — ${
      status.connected ? `connected to ${status.edge}, scene ${w?.scene}, ${w?.instances.length} instances` : "not connected"
    }${edges.length > 1 ? ` (server ${edgeIndex + 1} of ${edges.length})` : ""}`,
    `${status.fps} fps · ${status.mbitS.toFixed(2)} Mbit/s · server frame ${status.serverFrame} · round trip ${
      status.rttMs === null ? "-" : `${status.rttMs.toFixed(1)} ms`
    }`,
    `${status.updates} updates · ${status.points} points received · ${
      status.decodeMs ? status.decodeMs.toFixed(2) : "-"
    } ms decode per update`,
    !renderer
      ? (sceneError ?? (gl ? "loading the scene" : "WebGL2 unavailable: nothing drawn"))
      : grids?.problem
        ? grids.problem
        : `view: ${modeName}, ${status.lit ? "lit (points' irradiance + shadow-mapped lights)" : "AO only"} (keys 1 2 3 4)${
            cost ? ` · AO shader ${cost.cellsPerPixel.toFixed(1)} cells, ${cost.pointsPerPixel.toFixed(1)} points per pixel (C)` : " · C: shader cost"
          }`,
    status.path
      ? `camera path ${status.path}, frame ${status.pathFrame} (drag, wheel or W A S D Q E to take over)`
      : `camera: ${path ? "yours" : "orbit"} (drag, wheel, W A S D Q E; Space: ${path ? "back to the path" : "auto"})`,
    verify
      ? `state hash ${status.hash ?? "-"}: ${status.verified} updates match the server, ${status.mismatches} differ`
      : "state hash not checked (add ?verify=1)",
  ].join("\n");
  message.textContent = status.message
    ? status.fatal
      ? `error: ${status.message}`
      : `${status.message}; reconnecting`
    : status.stalled
      ? `updates stalled: ${status.stalled}`
      : "";
  requestAnimationFrame(tick);
}

window.addEventListener("keydown", (e) => {
  if (e.key === "c") cost = measureCost();
});

const authHeaders: Record<string, string> = token === null ? {} : { Authorization: `Bearer ${token}` };

/// Loads the served relit characters into the renderer (`/characters/index.json`, then each
/// model) once the scene and the decoder are there.
async function loadRelit(r: SceneRenderer, c: Codec) {
  const source = r.source;
  const index = await fetch("/characters/index.json", { headers: authHeaders });
  // A server without the route (or relighting nothing): no relit characters.
  const served: RelitIndex = index.ok ? await index.json() : { count: 0, lighting: [] };
  if (params.get("relit") === "0" || served.count === 0 || !source) {
    status.relit.state = "none";
    return;
  }
  const models = await Promise.all(
    Array.from({ length: served.count }, async (_, i) => {
      const m = await fetch(`/characters/${i}.prt`, { headers: authHeaders });
      if (!m.ok) throw new Error(`/characters/${i}.prt: HTTP ${m.status}`);
      return new Uint8Array(await m.arrayBuffer());
    }),
  );
  r.relit = new RelitCharacters(c, source.doc, source.read, source.instances, served, models);
  status.relit = {
    state: "ready",
    characters: served.count,
    vertices: r.relit.vertices,
    modelBytes: models.reduce((a, m) => a + m.length, 0),
    ms: 0,
  };
}

/// Times the relighting of `frames` frames along the first playing seconds of the scene (at
/// the drawn camera and transforms): the mean wasm ms per frame over the whole run (the
/// page's clock is too coarse for one frame), the slowest frame, and the vertices.
function measureRelit(frames = 60) {
  const relit = renderer?.relit;
  if (!relit || !status.camera) return null;
  const state = session?.state ?? null;
  const transforms = Array.from({ length: state?.instanceCount() ?? 0 }, (_, i) => state?.transforms[i] ?? null);
  let maxMs = 0;
  const t0 = performance.now();
  for (let f = 0; f < frames; f++) {
    relit.frame(f / 60, transforms, status.camera.position);
    maxMs = Math.max(maxMs, relit.ms);
  }
  return { frames, vertices: relit.vertices, meanMs: (performance.now() - t0) / frames, maxMs };
}
(window as unknown as { psaoRelitCost: typeof measureRelit }).psaoRelitCost = measureRelit;

let sceneLoaded: (r: SceneRenderer) => void = () => {};
const sceneReady = new Promise<SceneRenderer>((resolve) => (sceneLoaded = resolve));
fetch("/scene.glb", { headers: authHeaders })
  .then((r) => {
    if (r.status === 401) throw new Error("wrong or missing token (open the page with #token=…)");
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return r.arrayBuffer();
  })
  .then((b) => {
    const glb = new Uint8Array(b);
    orbit = sceneBounds(glb);
    if (gl) {
      renderer = new SceneRenderer(gl, glb);
      sceneLoaded(renderer);
      status.milestones.scene = performance.now();
      if (pathName !== null) {
        path = renderer.paths.find((p) => p.name === pathName) ?? null;
        if (!path) status.message = `the scene has no camera path named ${pathName}`;
      } else if (!orbitOnly) {
        path = renderer.paths[0] ?? null;
      }
    } else {
      status.relit.state = "none";
    }
  })
  .catch((e) => {
    // Kept in the overlay: a session's welcome clears status.message.
    sceneError = `cannot load /scene.glb: ${e}`;
    status.relit.state = "none";
    status.message = sceneError;
    console.error(sceneError);
  });
Codec.load(fetch("/psao.wasm"))
  .then((c) => {
    codec = c;
    connect();
    sceneReady
      .then((r) => loadRelit(r, c))
      .catch((e) => {
        status.relit.state = "error";
        status.message = `relit characters: ${e instanceof Error ? e.message : e}`;
        console.error(status.message);
      });
  })
  .catch((e) => {
    status.message = `cannot load the decoder /psao.wasm: ${e}`;
  });
requestAnimationFrame(tick);
