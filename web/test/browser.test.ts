// The bundled viewer in Debian's headless chromium (puppeteer-core; CHROMIUM overrides
// /usr/bin/chromium) against a real `psao serve`: it reaches the server's state hash on every
// update, shows a clear message for a wrong token, reconnects to a restarted server and
// converges again, and moves to the next server of `?edges=` when its own dies; WebGL2
// (SwiftShader) draws the scene.
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn, type ChildProcess } from "node:child_process";
import { createInterface } from "node:readline";
import { createServer } from "node:net";
import { existsSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { fileURLToPath } from "node:url";
import puppeteer, { type Browser, type Page } from "puppeteer-core";

const BIN = process.env.PSAO_BIN ?? fileURLToPath(new URL("../../../target/release/psao", import.meta.url));
const CHROMIUM = process.env.CHROMIUM ?? "/usr/bin/chromium";
const SERVER = ["--points", "96", "--ray-budget", "40000", "--hz", "30"];

let browser: Browser;
let profile: string;

before(async () => {
  profile = mkdtempSync(join(tmpdir(), "psao-chromium-"));
  browser = await puppeteer.launch({
    executablePath: CHROMIUM,
    args: [
      "--headless",
      "--no-sandbox",
      "--disable-gpu",
      "--disable-quic",
      "--no-first-run",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
      "--use-angle=swiftshader",
      "--enable-unsafe-swiftshader",
      `--user-data-dir=${profile}`,
    ],
  });
});

after(async () => {
  await browser?.close();
  rmSync(profile, { recursive: true, force: true });
});

async function serve(listen: string, extra: string[] = []): Promise<{ child: ChildProcess; addr: string }> {
  const child = spawn(BIN, ["--log", "warn", "serve", "--listen", listen, ...SERVER, ...extra], {
    stdio: ["ignore", "pipe", "inherit"],
  });
  const line: string = await new Promise((resolve, reject) => {
    createInterface({ input: child.stdout! }).once("line", resolve);
    child.once("exit", (code) => reject(new Error(`psao serve exited (${code})`)));
  });
  return { child, addr: line.replace("listening on ", "").trim() };
}

function drive(addr: string, frames: number): Promise<number> {
  return new Promise((resolve) => {
    const c = spawn(BIN, ["--log", "warn", "view", "--connect", addr, "--frames", `${frames}`, "--res", "64x36"], {
      stdio: ["ignore", "ignore", "inherit"],
    });
    c.once("exit", (code) => resolve(code ?? -1));
  });
}

type Cam = { position: number[]; target: number[] };
type Status = {
  autoOrbit: boolean;
  path: string | null;
  camera: Cam | null;
  drawn: number;
  sessions: number;
  connected: boolean;
  edge: string;
  rttEdge: string | null;
  updates: number;
  verified: number;
  mismatches: number;
  message: string | null;
  fatal: boolean;
  mode: number;
};

async function statusOf(page: Page): Promise<Status> {
  return page.evaluate(() => (window as unknown as { psao: Status }).psao);
}

async function until(page: Page, what: string, ok: (s: Status) => boolean, ms = 60_000): Promise<Status> {
  const end = Date.now() + ms;
  for (;;) {
    const s = await statusOf(page);
    if (ok(s)) return s;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}: ${JSON.stringify(s)}`);
    await new Promise((r) => setTimeout(r, 100));
  }
}

function freePort(): Promise<number> {
  return new Promise((resolve) => {
    const s = createServer();
    s.listen(0, "127.0.0.1", () => {
      const port = (s.address() as { port: number }).port;
      s.close(() => resolve(port));
    });
  });
}

test("in chromium the viewer's state hash equals the server's", { timeout: 120_000 }, async () => {
  const { child, addr } = await serve("127.0.0.1:0");
  const page = await browser.newPage();
  try {
    // The AO view (`mode=ao`) shows the geometry whatever the lighting: the composite of a
    // lit session is dark where no irradiance record has arrived yet (the hall has no direct
    // light), and its fill of such pixels re-runs the block pass at up to 64 neighbours, which
    // software WebGL (SwiftShader) draws at seconds per full-window frame (docs/LIGHTING.md).
    await page.goto(`http://${addr}/?verify=1&mode=ao`);
    await until(page, "the welcome", (s) => s.sessions === 1);
    assert.equal(await drive(addr, 120), 0);
    const s = await until(page, "verified updates", (s) => s.verified >= 3);
    assert.equal(s.mismatches, 0);
    await until(page, "a WebGL2 frame", (s) => s.drawn > 0);
    // Share of the canvas the scene covers (pixels far from the clear colour).
    const covered = await page.evaluate(() => {
      const view = document.getElementById("view") as HTMLCanvasElement;
      const c = document.createElement("canvas");
      c.width = view.width;
      c.height = view.height;
      const ctx = c.getContext("2d")!;
      ctx.drawImage(view, 0, 0);
      const px = ctx.getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let i = 0; i < px.length; i += 4) if (Math.max(px[i], px[i + 1], px[i + 2]) > 40) n++;
      return n / (c.width * c.height);
    });
    assert.ok(covered > 0.05, `the scene covers ${covered} of the canvas`);
    // The viewer opens on the scene's first camera path; dragging takes the camera over from
    // it, W flies it forward and Space gives it back to the path.
    const opened = await statusOf(page);
    assert.equal(opened.autoOrbit, true);
    assert.equal(opened.path, "default_a", "the viewer follows the scene's first camera path");
    await page.mouse.move(400, 300);
    await page.mouse.down();
    await page.mouse.move(500, 320, { steps: 5 });
    await page.mouse.up();
    const held = await until(page, "the drag", (s) => !s.autoOrbit);
    await page.keyboard.down("w");
    await new Promise((r) => setTimeout(r, 500));
    await page.keyboard.up("w");
    const flown = await statusOf(page);
    const moved = Math.hypot(...[0, 1, 2].map((i) => flown.camera!.target[i] - held.camera!.target[i]));
    assert.ok(moved > 0, "W did not move the camera");
    assert.equal(flown.autoOrbit, false);
    assert.equal(flown.path, null);
    await page.keyboard.press(" ");
    await until(page, "Space to give the camera back to the path", (s) => s.path === "default_a");
    await page.screenshot({ path: join(fileURLToPath(new URL(".", import.meta.url)), "viewer.png") });
  } finally {
    await page.close();
    child.kill();
  }
});

test("in chromium the token comes from the fragment; a wrong one shows the message and is not retried", { timeout: 60_000 }, async () => {
  const { child, addr } = await serve("127.0.0.1:0", ["--token", "sesame"]);
  const page = await browser.newPage();
  try {
    // The right token: the scene loads (it needs the token) and a session starts; the token
    // leaves the address bar.
    // The AO view, as in the first test: this one tests the token, not the lighting.
    await page.goto(`http://${addr}/?mode=ao#token=sesame`);
    await until(page, "the welcome", (s) => s.sessions === 1);
    const loaded = await page.evaluate(() => {
      const p = (window as unknown as { psao: { milestones: { scene: number | null } } }).psao;
      return { scene: p.milestones.scene, url: location.href };
    });
    assert.notEqual(loaded.scene, null, "the scene did not load with the token");
    assert.doesNotMatch(loaded.url, /sesame/);
    // A query unlike the first forces a new document (a fragment alone would not reload).
    await page.goto(`http://${addr}/?mode=ao&again=1#token=wrong`);
    const s = await until(page, "the refusal", (s) => s.fatal);
    assert.match(s.message ?? "", /wrong or missing token/);
    const shown = await page.$eval("#message", (e) => e.textContent ?? "");
    assert.match(shown, /error: wrong or missing token/);
    await new Promise((r) => setTimeout(r, 1000));
    assert.equal((await statusOf(page)).sessions, 0);
  } finally {
    await page.close();
    child.kill();
  }
});

test("in chromium the viewer reconnects to a restarted server and converges", { timeout: 120_000 }, async () => {
  const listen = `127.0.0.1:${await freePort()}`;
  let server = await serve(listen);
  const page = await browser.newPage();
  try {
    // The AO view, as in the first test: these sessions test the connection, not the lighting.
    await page.goto(`http://${server.addr}/?verify=1&mode=ao`);
    await until(page, "the first session", (s) => s.sessions === 1 && s.updates >= 1);
    server.child.kill();
    await new Promise((r) => server.child.once("exit", r));
    server = await serve(listen);
    const before = (await statusOf(page)).verified;
    await until(page, "the second session", (s) => s.sessions === 2);
    assert.equal(await drive(server.addr, 60), 0);
    const s = await until(page, "verified updates after the restart", (s) => s.verified >= before + 2);
    assert.equal(s.mismatches, 0);
  } finally {
    await page.close();
    server.child.kill();
  }
});

test("in chromium the viewer moves to the next server of ?edges= when its own dies", { timeout: 120_000 }, async () => {
  // Two `psao serve` stand in for two edges of a session (they serve with the same code).
  const a = await serve("127.0.0.1:0");
  const b = await serve("127.0.0.1:0");
  const page = await browser.newPage();
  try {
    // The AO view, as in the first test: these sessions test the connection, not the lighting.
    await page.goto(`http://${a.addr}/?verify=1&mode=ao&edges=${b.addr},not%20a%20host`);
    await until(page, "the first session", (s) => s.sessions === 1 && s.updates >= 1 && s.edge === a.addr);
    a.child.kill();
    const before = (await statusOf(page)).verified;
    await until(page, "the session on the other server", (s) => s.sessions === 2 && s.connected && s.edge === b.addr);
    assert.equal(await drive(b.addr, 60), 0);
    const s = await until(page, "verified updates from the other server", (s) => s.verified >= before + 2);
    assert.equal(s.mismatches, 0);
    // Its /health answers the page, which another server loaded (cross-origin).
    await until(page, "a round trip to the other server", (s) => s.rttEdge === b.addr, 10_000);
  } finally {
    await page.close();
    a.child.kill();
    b.child.kill();
  }
});

/// Path, frames and size of the deterministic comparison with `psao view`.
const AO_PATH = "default_a";
const AO_FRAMES = 40;
const AO_RES = "160x90";
/// G-buffer samples per pixel and axis: SwiftShader snaps vertices to 1/16 pixel, psao-raster
/// to 1/4096, so at 1× the surface seen at thin detail (grout lines, grille bars) differs on
/// ~50 of the 14 400 pixels (29.6 dB); at 15× edges move by 1/240 pixel at most (44.1 dB).
const AO_SCALE = 15;

function run(args: string[]): Promise<number> {
  return new Promise((resolve) => {
    const c = spawn(BIN, ["--log", "warn", ...args], { stdio: ["ignore", "ignore", "inherit"] });
    c.once("exit", (code) => resolve(code ?? -1));
  });
}

function output(args: string[]): Promise<string> {
  return new Promise((resolve, reject) => {
    const c = spawn(BIN, ["--log", "warn", ...args], { stdio: ["ignore", "pipe", "inherit"] });
    let out = "";
    c.stdout!.on("data", (d) => (out += d));
    c.once("exit", (code) => (code === 0 ? resolve(out) : reject(new Error(`psao ${args[0]} exited (${code})`))));
  });
}

/// The canvas as a PNG file.
async function savePng(page: Page, file: string) {
  const url: string = await page.evaluate(() => (document.getElementById("view") as HTMLCanvasElement).toDataURL("image/png"));
  writeFileSync(file, Buffer.from(url.replace(/^data:image\/png;base64,/, ""), "base64"));
}

test("in chromium the AO-only view of a lockstep run matches psao view's (≥ 40 dB, same state hash)", { timeout: 180_000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), "psao-ao-"));
  const lockstep = ["--lockstep", "--lighting", "ao"];
  // psao view's frames against one server…
  const cpu = await serve("127.0.0.1:0", lockstep);
  try {
    const args = ["view", "--connect", cpu.addr, "--frames", `${AO_FRAMES}`, "--res", AO_RES, "--out", dir, "--json", join(dir, "view.json")];
    assert.equal(await run(args), 0);
  } finally {
    cpu.child.kill();
  }
  const viewHash = JSON.parse(readFileSync(join(dir, "view.json"), "utf8")).state_hash as string;
  // …and the browser's against another, started the same way.
  const gpu = await serve("127.0.0.1:0", lockstep);
  const page = await browser.newPage();
  try {
    await page.goto(`http://${gpu.addr}/?verify=1&path=${AO_PATH}&frames=${AO_FRAMES}&lockstep=1&res=${AO_RES}&mode=ao&scale=${AO_SCALE}`);
    const s = await until(page, "the last lockstep frame", (s) => (s as Status & { done: boolean }).done, 120_000);
    assert.equal(s.mismatches, 0);
    assert.equal((s as Status & { hash: string }).hash, viewHash, "the browser's state hash differs from psao view's");
    const ours = join(dir, "browser_ao.png");
    await savePng(page, ours);
    const ref = join(dir, `ao_${String(AO_FRAMES - 1).padStart(5, "0")}.png`);
    const m = JSON.parse(await output(["compare", ref, ours, "--json"]));
    console.log(`AO-only ${AO_RES} frame ${AO_FRAMES - 1}: PSNR ${m.psnr.toFixed(2)} dB, SSIM ${m.ssim.toFixed(4)} against psao view`);
    assert.ok(m.psnr >= 40, `PSNR ${m.psnr} dB < 40 dB`);
    // The shader's cost, and the composited view (README screenshot with PSAO_SCREENSHOT).
    const cost = await page.evaluate(() => (window as unknown as { psaoCost: () => unknown }).psaoCost());
    console.log(`AO shader cost per covered pixel: ${JSON.stringify(cost)}`);
    await page.keyboard.press("1");
    await new Promise((r) => setTimeout(r, 200));
    if (process.env.PSAO_SCREENSHOT) await savePng(page, process.env.PSAO_SCREENSHOT);
  } finally {
    await page.close();
    gpu.child.kill();
    // PSAO_KEEP=1 keeps both images for a look.
    if (process.env.PSAO_KEEP) console.log(`images in ${dir}`);
    else rmSync(dir, { recursive: true, force: true });
  }
});

/// Shadow-map samples per texel and axis in the lit comparison (as AO_SCALE for the G-buffer).
const SHADOW_SCALE = 5;

/// The canvas in `mode` (key `key`) once a frame was drawn in it, as a PNG file.
async function saveMode(page: Page, key: "2" | "3", mode: number, file: string) {
  await page.keyboard.press(key);
  const drawn = (await until(page, `mode ${mode}`, (s) => s.mode === mode)).drawn;
  await until(page, `a frame in mode ${mode}`, (s) => s.drawn >= drawn + 2);
  await savePng(page, file);
}

/// The committed open box (scenes/open_box.toml) lit by a sun turning along keys (at the
/// compared frame it has turned a third of the way) and a point light in a corner: hard
/// shadows of the block from both, sky light and bounces in the points. Returns the scene file.
function writeLitScene(dir: string): string {
  const scenes = fileURLToPath(new URL("../../../scenes/", import.meta.url));
  writeFileSync(
    join(dir, "lit.toml"),
    `camera_paths = ["${scenes}open_box_path.toml"]
sky = [0.35, 0.45, 0.6]

[[asset]]
file = "${scenes}open_box/open_box.obj"

[[light]]
kind = "sun"
keys = { times = [0, 2], direction = [[0.45, 1.0, 0.35], [-0.5, 1.0, 0.6]] }
color = [1.0, 0.95, 0.85]
power = 3.0

[[light]]
kind = "point"
position = [1.2, 1.6, 0.8]
color = [1.0, 0.8, 0.6]
power = 1.5
`,
  );
  return join(dir, "lit.toml");
}

test("in chromium the lit composite of a lockstep run matches psao view's (≥ 40 dB, same state hash); its terms alone do not", { timeout: 240_000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), "psao-lit-"));
  const scene = writeLitScene(dir);
  const lit = ["--scene", scene, "--lockstep", "--lighting", "gi"];
  const cpu = await serve("127.0.0.1:0", lit);
  try {
    const args = ["view", "--scene", scene, "--connect", cpu.addr, "--frames", `${AO_FRAMES}`, "--res", AO_RES, "--out", dir, "--json", join(dir, "view.json")];
    assert.equal(await run(args), 0);
  } finally {
    cpu.child.kill();
  }
  const viewHash = JSON.parse(readFileSync(join(dir, "view.json"), "utf8")).state_hash as string;
  const gpu = await serve("127.0.0.1:0", lit);
  const page = await browser.newPage();
  try {
    const query = `verify=1&path=open_box&frames=${AO_FRAMES}&lockstep=1&res=${AO_RES}&mode=composited&scale=${AO_SCALE}&shadowscale=${SHADOW_SCALE}`;
    await page.goto(`http://${gpu.addr}/?${query}`);
    const s = await until(page, "the last lockstep frame", (s) => (s as Status & { done: boolean }).done, 180_000);
    assert.equal(s.mismatches, 0);
    assert.equal((s as Status & { lit: boolean }).lit, true, "the session is not lit");
    assert.equal((s as Status & { hash: string }).hash, viewHash, "the browser's lit state hash differs from psao view's");
    const ref = join(dir, `frame_${String(AO_FRAMES - 1).padStart(5, "0")}.png`);
    const psnr = async (file: string) => JSON.parse(await output(["compare", ref, file, "--json"])).psnr as number;
    const composited = join(dir, "browser_lit.png");
    await savePng(page, composited);
    const ours = await psnr(composited);
    const irradiance = join(dir, "browser_irradiance.png");
    await saveMode(page, "2", 1, irradiance);
    const direct = join(dir, "browser_direct.png");
    await saveMode(page, "3", 2, direct);
    const [e, d] = [await psnr(irradiance), await psnr(direct)];
    const timing = await statusOf(page);
    console.log(
      `lit ${AO_RES} frame ${AO_FRAMES - 1}: composited PSNR ${ours.toFixed(2)} dB against psao view; irradiance alone ${e.toFixed(2)} dB, direct alone ${d.toFixed(2)} dB; ${JSON.stringify(timing)}`,
    );
    assert.ok(ours >= 40, `composited PSNR ${ours} dB < 40 dB`);
    assert.ok(e < 30 && d < 30, `a term alone is as close as the composite (irradiance ${e} dB, direct ${d} dB): the test cannot fail`);
    await page.keyboard.press("1");
  } finally {
    await page.close();
    gpu.child.kill();
    if (process.env.PSAO_KEEP) console.log(`images in ${dir}`);
    else rmSync(dir, { recursive: true, force: true });
  }
});

/// A tiny skinned scene written by the test: a 4 m ground square and a 0.1 × 1.2 × 1 m plate
/// on two joints (the root, and one 0.2 m up that carries the upper 1 m), whose clip turns
/// the upper joint 165° about Z in 1 s, so that at 0.48 s the plate's upper part lies nearly
/// flat 0.2–0.4 m over the ground and darkens it; a scene file (AO radius 0.5 m) and a
/// fixed camera path looking at it. Returns the scene file.
function writeSkinnedScene(dir: string): string {
  const positions: number[] = [];
  const normals: number[] = [];
  const joints: number[] = [];
  const weights: number[] = [];
  const indices: number[] = [];
  const vertex = (p: number[], n: number[], upper: number) => {
    positions.push(...p);
    normals.push(...n);
    joints.push(0, 1, 0, 0);
    weights.push(1 - upper, upper, 0, 0);
    return positions.length / 3 - 1;
  };
  // Ground: mesh 0.
  const g = [[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]].map((p) => vertex(p, [0, 1, 0], 0));
  indices.push(g[0], g[2], g[1], g[0], g[3], g[2]);
  const groundVertices = 4;
  const groundIndices = 6;
  // Plate: rings every 0.2 m, each side face with its own vertices (flat normals).
  const hx = 0.05;
  const hz = 0.5;
  const levels = [0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2];
  const weight = (y: number) => (y < 0.2 ? 0 : y > 0.2 ? 1 : 0.5);
  const sides: [number[], number[], number[]][] = [
    [[hx, 0, -hz], [hx, 0, hz], [1, 0, 0]],
    [[hx, 0, hz], [-hx, 0, hz], [0, 0, 1]],
    [[-hx, 0, hz], [-hx, 0, -hz], [-1, 0, 0]],
    [[-hx, 0, -hz], [hx, 0, -hz], [0, 0, -1]],
  ];
  for (const [a, b, n] of sides) {
    const ring = levels.map((y) => [vertex([a[0], y, a[2]], n, weight(y)), vertex([b[0], y, b[2]], n, weight(y))]);
    for (let k = 0; k + 1 < ring.length; k++) {
      const [p, q] = ring[k];
      const [r, s] = ring[k + 1];
      indices.push(p, q, s, p, s, r);
    }
  }
  const top = [[hx, 1.2, -hz], [-hx, 1.2, -hz], [-hx, 1.2, hz], [hx, 1.2, hz]].map((p) => vertex(p, [0, 1, 0], 1));
  indices.push(top[0], top[1], top[2], top[0], top[2], top[3]);
  const barVertices = positions.length / 3 - groundVertices;
  // Buffer: positions, normals, weights, inverse binds, key times, key rotations (floats),
  // then joints (u16) and indices (u32).
  const views: { byteOffset: number; byteLength: number }[] = [];
  const accessors: Record<string, unknown>[] = [];
  const chunks: Buffer[] = [];
  let at = 0;
  const add = (bytes: Buffer, accessor: Record<string, unknown>) => {
    views.push({ byteOffset: at, byteLength: bytes.length });
    chunks.push(bytes);
    at += bytes.length;
    accessors.push({ bufferView: views.length - 1, ...accessor });
    return accessors.length - 1;
  };
  const floats = (v: number[]) => Buffer.from(new Float32Array(v).buffer);
  const sub = <T>(a: T[], from: number, count: number, width: number) => a.slice(from * width, (from + count) * width);
  const range = (v: number[], n: number) => {
    const min = [0, 1, 2].map((k) => Math.min(...v.filter((_, i) => i % 3 === k)));
    const max = [0, 1, 2].map((k) => Math.max(...v.filter((_, i) => i % 3 === k)));
    return { count: n, min, max };
  };
  const gPos = add(floats(sub(positions, 0, groundVertices, 3)), { componentType: 5126, type: "VEC3", ...range(sub(positions, 0, groundVertices, 3), groundVertices) });
  const gNrm = add(floats(sub(normals, 0, groundVertices, 3)), { componentType: 5126, type: "VEC3", count: groundVertices });
  const bPos = add(floats(sub(positions, groundVertices, barVertices, 3)), { componentType: 5126, type: "VEC3", ...range(sub(positions, groundVertices, barVertices, 3), barVertices) });
  const bNrm = add(floats(sub(normals, groundVertices, barVertices, 3)), { componentType: 5126, type: "VEC3", count: barVertices });
  const bWgt = add(floats(sub(weights, groundVertices, barVertices, 4)), { componentType: 5126, type: "VEC4", count: barVertices });
  const ibm = add(floats([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -0.2, 0, 1]), { componentType: 5126, type: "MAT4", count: 2 });
  const times = add(floats([0, 1]), { componentType: 5126, type: "SCALAR", count: 2, min: [0], max: [1] });
  const half = ((165 / 180) * Math.PI) / 2;
  const rots = add(floats([0, 0, 0, 1, 0, 0, Math.sin(half), Math.cos(half)]), { componentType: 5126, type: "VEC4", count: 2 });
  const bJnt = add(Buffer.from(new Uint16Array(sub(joints, groundVertices, barVertices, 4)).buffer), { componentType: 5123, type: "VEC4", count: barVertices });
  const gIdx = add(Buffer.from(new Uint32Array(indices.slice(0, groundIndices)).buffer), { componentType: 5125, type: "SCALAR", count: groundIndices });
  const bIdx = add(Buffer.from(new Uint32Array(indices.slice(groundIndices).map((i) => i - groundVertices)).buffer), { componentType: 5125, type: "SCALAR", count: indices.length - groundIndices });
  writeFileSync(join(dir, "skinned.bin"), Buffer.concat(chunks));
  const gltf = {
    asset: { version: "2.0" },
    scene: 0,
    scenes: [{ nodes: [0, 2, 3] }],
    nodes: [
      { name: "root joint", children: [1] },
      { name: "upper joint", translation: [0, 0.2, 0] },
      { name: "bar", mesh: 1, skin: 0 },
      { name: "ground", mesh: 0 },
    ],
    meshes: [
      { primitives: [{ attributes: { POSITION: gPos, NORMAL: gNrm }, indices: gIdx, material: 0 }] },
      { primitives: [{ attributes: { POSITION: bPos, NORMAL: bNrm, JOINTS_0: bJnt, WEIGHTS_0: bWgt }, indices: bIdx, material: 1 }] },
    ],
    materials: [
      { pbrMetallicRoughness: { baseColorFactor: [0.7, 0.7, 0.7, 1] } },
      { pbrMetallicRoughness: { baseColorFactor: [0.8, 0.3, 0.2, 1] } },
    ],
    skins: [{ joints: [0, 1], inverseBindMatrices: ibm }],
    animations: [{ name: "bend", samplers: [{ input: times, output: rots, interpolation: "LINEAR" }], channels: [{ sampler: 0, target: { node: 1, path: "rotation" } }] }],
    buffers: [{ uri: "skinned.bin", byteLength: at }],
    bufferViews: views.map((v) => ({ buffer: 0, ...v })),
    accessors,
  };
  writeFileSync(join(dir, "skinned.gltf"), JSON.stringify(gltf));
  const key = (time: number) => `[[key]]\ntime = ${time}\nposition = [0.0, 2.2, 3.0]\nlook_at = [-0.3, 0.3, 0.0]\n`;
  writeFileSync(join(dir, "path.toml"), `name = "skin_test"\nfov_y_deg = 60.0\n\n${key(0)}\n${key(2)}`);
  writeFileSync(join(dir, "scene.toml"), `ao_radius = 0.5\ncamera_paths = ["path.toml"]\n\n[[asset]]\nfile = "skinned.gltf"\n`);
  return join(dir, "scene.toml");
}

/// Frames of the skinned comparison: at frame 29 (0.48 s) the plate's upper part has turned 80°.
const SKIN_FRAMES = 30;

test("in chromium a skinned character moves as in psao view (AO-only ≥ 40 dB where the rest pose is not)", { timeout: 180_000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), "psao-skin-"));
  const scene = writeSkinnedScene(dir);
  const server = ["--scene", scene, "--lockstep", "--lighting", "ao"];
  const frame = `ao_${String(SKIN_FRAMES - 1).padStart(5, "0")}.png`;
  try {
    // psao view's frames, posed (the reference) and in the rest pose (what a viewer that does
    // not skin would draw), each against its own server…
    for (const [out, extra] of [["posed", []], ["rest", ["--static"]]] as const) {
      const cpu = await serve("127.0.0.1:0", server);
      try {
        const args = ["view", "--scene", scene, "--connect", cpu.addr, "--frames", `${SKIN_FRAMES}`, "--res", AO_RES, "--out", join(dir, out), ...extra];
        if (out === "posed") args.push("--json", join(dir, "view.json"));
        assert.equal(await run(args), 0);
      } finally {
        cpu.child.kill();
      }
    }
    const viewHash = JSON.parse(readFileSync(join(dir, "view.json"), "utf8")).state_hash as string;
    // …and the browser's.
    const gpu = await serve("127.0.0.1:0", server);
    const page = await browser.newPage();
    try {
      await page.goto(`http://${gpu.addr}/?verify=1&path=skin_test&frames=${SKIN_FRAMES}&lockstep=1&res=${AO_RES}&mode=ao&scale=${AO_SCALE}`);
      const s = await until(page, "the last lockstep frame", (s) => (s as Status & { done: boolean }).done, 120_000);
      assert.equal(s.mismatches, 0);
      assert.equal((s as Status & { hash: string }).hash, viewHash, "the browser's state hash differs from psao view's");
      const ours = join(dir, "browser_ao.png");
      await savePng(page, ours);
      const posed = JSON.parse(await output(["compare", join(dir, "posed", frame), ours, "--json"]));
      const rest = JSON.parse(await output(["compare", join(dir, "rest", frame), ours, "--json"]));
      console.log(`skinned AO-only ${AO_RES} frame ${SKIN_FRAMES - 1}: PSNR ${posed.psnr.toFixed(2)} dB against psao view, ${rest.psnr.toFixed(2)} dB against its rest pose`);
      assert.ok(posed.psnr >= 40, `PSNR ${posed.psnr} dB < 40 dB`);
      assert.ok(rest.psnr < 40, `the rest pose is as close (${rest.psnr} dB): the test does not see the motion`);
    } finally {
      await page.close();
      gpu.child.kill();
    }
  } finally {
    if (process.env.PSAO_KEEP) console.log(`images in ${dir}`);
    else rmSync(dir, { recursive: true, force: true });
  }
});

/// CesiumMan from the shared data (the relit test is skipped without it).
const CESIUM_MAN = fileURLToPath(new URL("../../../../shared/data/characters/CesiumMan/CesiumMan.gltf", import.meta.url));
/// Frames of the relit comparison (CesiumMan walks; the path closes in on him).
const RELIT_FRAMES = 20;

/// A floor box and CesiumMan (as crates/psao/tests/relit_serve.rs) with a camera path close
/// to him. Returns the scene file.
function writeRelitScene(dir: string): string {
  const key = (t: number, x: number) => `[[key]]\ntime = ${t}\nposition = [${x}, 1.2, 3.3]\nlook_at = [-2.0, 0.7, 0.6]\n`;
  writeFileSync(join(dir, "close.toml"), `name = "close"\nfov_y_deg = 40.0\n\n${key(0, -1.0)}\n${key(1, -0.6)}`);
  writeFileSync(
    join(dir, "scene.toml"),
    `camera_paths = ["close.toml"]\n\n[[asset]]\nfile = "builtin:box"\nscale = [4.0, 0.1, 4.0]\ntranslation = [0.0, -0.1, 0.0]\n\n[[asset]]\nfile = ${JSON.stringify(CESIUM_MAN)}\n`,
  );
  return join(dir, "scene.toml");
}

/// The RGBA pixels of a PNG file, decoded by the browser.
async function pngPixels(page: Page, file: string): Promise<number[]> {
  const url = `data:image/png;base64,${readFileSync(file).toString("base64")}`;
  return page.evaluate(async (u) => {
    const img = new Image();
    img.src = u;
    await img.decode();
    const c = document.createElement("canvas");
    c.width = img.width;
    c.height = img.height;
    const g = c.getContext("2d")!;
    g.drawImage(img, 0, 0);
    return Array.from(g.getImageData(0, 0, img.width, img.height).data);
  }, url);
}

/// PSNR (dB, RGB) of `a` against `b` over the pixels of `mask`.
function maskedPsnr(a: number[], b: number[], mask: boolean[]): number {
  let sum = 0;
  let n = 0;
  mask.forEach((m, i) => {
    if (!m) return;
    for (let c = 0; c < 3; c++) sum += (a[4 * i + c] - b[4 * i + c]) ** 2;
    n += 3;
  });
  const mse = sum / Math.max(n, 1);
  return mse === 0 ? Infinity : 10 * Math.log10((255 * 255) / mse);
}

test("in chromium a relit character matches psao view's (≥ 40 dB on its pixels; unrelit it does not)", { timeout: 300_000 }, async (t) => {
  if (!existsSync(CESIUM_MAN)) {
    t.skip(`${CESIUM_MAN} missing`);
    return;
  }
  const dir = mkdtempSync(join(tmpdir(), "psao-relit-"));
  const scene = writeRelitScene(dir);
  const cache = join(dir, "cache");
  const server = ["--scene", scene, "--lockstep", "--lighting", "ao", "--points-cache", cache];
  const frame = `frame_${String(RELIT_FRAMES - 1).padStart(5, "0")}.png`;
  try {
    // psao view's composited frames against a relighting server (the reference) and against
    // one that relights nothing (which pixels relighting changes: the character's).
    for (const [out, extra] of [["relit", ["--relight"]], ["plain", []]] as const) {
      const cpu = await serve("127.0.0.1:0", [...server, ...extra]);
      try {
        const args = ["view", "--scene", scene, "--connect", cpu.addr, "--frames", `${RELIT_FRAMES}`, "--res", AO_RES, "--out", join(dir, out)];
        assert.equal(await run(args), 0);
      } finally {
        cpu.child.kill();
      }
    }
    // The browser's, relit and with `?relit=0`, each against its own relighting server.
    const shots: Record<string, string> = {};
    let cost: unknown = null;
    for (const relit of ["1", "0"]) {
      const gpu = await serve("127.0.0.1:0", [...server, "--relight"]);
      const page = await browser.newPage();
      try {
        await page.goto(`http://${gpu.addr}/?verify=1&path=close&frames=${RELIT_FRAMES}&lockstep=1&res=${AO_RES}&mode=composited&scale=${AO_SCALE}&relit=${relit}`);
        const s = (await until(page, "the last lockstep frame", (s) => (s as Status & { done: boolean }).done, 180_000)) as Status & {
          relit: { state: string; characters: number; vertices: number; modelBytes: number };
        };
        assert.equal(s.mismatches, 0);
        assert.equal(s.relit.state, relit === "1" ? "ready" : "none", JSON.stringify(s.relit));
        if (relit === "1") {
          assert.equal(s.relit.characters, 1);
          cost = await page.evaluate(() => (window as unknown as { psaoRelitCost: (n: number) => unknown }).psaoRelitCost(60));
          console.log(`relit CesiumMan in chromium (wasm, one thread): ${JSON.stringify(cost)}, model ${s.relit.modelBytes} bytes`);
        }
        shots[relit] = join(dir, `browser_${relit}.png`);
        await savePng(page, shots[relit]);
      } finally {
        await page.close();
        gpu.child.kill();
      }
    }
    const page = await browser.newPage();
    try {
      const [view, plain, ours, unrelit] = await Promise.all(
        [join(dir, "relit", frame), join(dir, "plain", frame), shots["1"], shots["0"]].map((f) => pngPixels(page, f)),
      );
      const mask = Array.from({ length: view.length / 4 }, (_, i) => [0, 1, 2].some((c) => view[4 * i + c] !== plain[4 * i + c]));
      const pixels = mask.filter(Boolean).length;
      const relitDb = maskedPsnr(ours, view, mask);
      const unrelitDb = maskedPsnr(unrelit, view, mask);
      console.log(`relit ${AO_RES} frame ${RELIT_FRAMES - 1}, ${pixels} pixels relighting changes: PSNR ${relitDb.toFixed(2)} dB relit, ${unrelitDb.toFixed(2)} dB unrelit, against psao view`);
      assert.ok(pixels >= 200, `only ${pixels} pixels show the character's relighting`);
      assert.ok(relitDb >= 40, `relit PSNR ${relitDb} dB < 40 dB`);
      assert.ok(unrelitDb < 40 && unrelitDb < relitDb - 3, `unrelit PSNR ${unrelitDb} dB: the test does not see the relighting`);
    } finally {
      await page.close();
    }
  } finally {
    if (process.env.PSAO_KEEP) console.log(`images in ${dir}`);
    else rmSync(dir, { recursive: true, force: true });
  }
});
