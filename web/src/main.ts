// The page served at `/`: connects to the server's WebSocket (`/ws`, token from `?token=`),
// keeps the client state current, orbits a camera around the scene (bounds from
// `/scene.glb`) so the server traces what it would show, reconnects with backoff, and shows
// an overlay: fps, Mbit/s, server frame, updates, points, state-hash checks (`?verify=1`
// asks the server for its hash with every update), and a clear message for a wrong token or
// protocol version. `window.psao` exposes the same numbers to tests.

import { Session } from "./session";
import { sceneBounds } from "./bounds";
import { SceneRenderer } from "./render";
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
  mbitS: number;
  fps: number;
  /// Frames drawn with WebGL2 (0 when it is unavailable).
  drawn: number;
  /// The camera drawn and sent last.
  camera: Camera | null;
  /// Whether the camera orbits by itself (until the user moves it).
  autoOrbit: boolean;
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
  mbitS: 0,
  fps: 0,
  drawn: 0,
  camera: null,
  autoOrbit: true,
};
(window as unknown as { psao: Status }).psao = status;

const params = new URLSearchParams(location.search);
const token = params.get("token");
const verify = params.get("verify") === "1";
const wsUrl = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`;

let session: Session | null = null;
let backoff = 200;
let received: { t: number; bytes: number }[] = [];

function connect() {
  session = new Session(
    { url: wsUrl, token, verify, name: "psao browser viewer" },
    {
      welcome: () => {
        status.connected = true;
        status.sessions++;
        status.message = null;
        backoff = 200;
      },
      update: (u, bytes, verified) => {
        status.updates++;
        if (verified) status.verified++;
        status.mismatches = session?.mismatches ?? status.mismatches;
        status.serverFrame = Number(u.frame);
        received.push({ t: performance.now(), bytes });
        if (session?.lastHash != null) status.hash = session.lastHash.toString(16).padStart(16, "0");
      },
      closed: (reason, fatal) => {
        status.connected = false;
        status.message = reason;
        status.fatal = fatal;
        if (!fatal) {
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

function countPoints(): number {
  let n = 0;
  for (const g of session?.state?.grids ?? []) {
    if (!g) continue;
    const p = g.points;
    for (let i = 0; i < g.slotCount * 7; i++) if (p[i] >>> 31) n++;
  }
  return n;
}

const canvas = document.getElementById("view") as HTMLCanvasElement;
// Kept after compositing so that tests (and screenshots) can read the frame back.
const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true });
let renderer: SceneRenderer | null = null;

/// The camera: it orbits the scene by itself until the user drags (orbit), scrolls (zoom)
/// or flies (W/A/S/D forward/left/back/right, Q/E down/up); Space resumes the auto-orbit.
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
  if (e.key === " ") control.auto = true;
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

let lastCamera = 0;
let lastPointCount = 0;
function tick(now: number) {
  frames.push(now);
  frames = frames.filter((t) => now - t < 1000);
  received = received.filter((r) => now - r.t < 1000);
  status.fps = frames.length;
  status.mbitS = (received.reduce((a, r) => a + r.bytes, 0) * 8) / 1e6;
  const w0 = Math.round(window.innerWidth * devicePixelRatio);
  const h0 = Math.round(window.innerHeight * devicePixelRatio);
  if (canvas.width !== w0 || canvas.height !== h0) {
    canvas.width = w0;
    canvas.height = h0;
  }
  const cam = orbitCamera(now);
  status.camera = cam;
  status.autoOrbit = control.auto;
  if (cam && now - lastCamera > 1000 / 30) {
    lastCamera = now;
    session?.sendCamera(cam);
    cameraFrame++;
  }
  if (cam && renderer) {
    renderer.draw(cam, session?.state?.transforms ?? []);
    status.drawn++;
  }
  if (now - lastPointCount > 500) {
    lastPointCount = now;
    status.points = countPoints();
  }
  const w = session?.welcomeMsg;
  overlay.textContent = [
    `psao viewer — ${status.connected ? `connected, scene ${w?.scene}, ${w?.instances.length} instances` : "not connected"}`,
    `${status.fps} fps · ${status.mbitS.toFixed(2)} Mbit/s · server frame ${status.serverFrame}`,
    `${status.updates} updates · ${status.points} points received · ${
      session && session.updates > 0 ? (session.decodeMs / session.updates).toFixed(2) : "-"
    } ms decode per update`,
    renderer ? "WebGL2: the scene without AO (the AO shader is not here yet)" : "WebGL2 unavailable: nothing drawn",
    verify
      ? `state hash ${status.hash ?? "-"}: ${status.verified} updates match the server, ${status.mismatches} differ`
      : "state hash not checked (add ?verify=1)",
  ].join("\n");
  message.textContent = status.message ? (status.fatal ? `error: ${status.message}` : `${status.message}; reconnecting`) : "";
  requestAnimationFrame(tick);
}

fetch("/scene.glb")
  .then((r) => r.arrayBuffer())
  .then((b) => {
    const glb = new Uint8Array(b);
    orbit = sceneBounds(glb);
    if (gl) renderer = new SceneRenderer(gl, glb);
  })
  .catch((e) => {
    status.message = `cannot load /scene.glb: ${e}`;
  });
connect();
requestAnimationFrame(tick);
