// The bundled viewer in Debian's headless chromium (puppeteer-core; CHROMIUM overrides
// /usr/bin/chromium) against a real `psao serve`: it reaches the server's state hash on every
// update, shows a clear message for a wrong token, and reconnects to a restarted server and
// converges again; WebGL2 (SwiftShader) draws the scene.
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn, type ChildProcess } from "node:child_process";
import { createInterface } from "node:readline";
import { createServer } from "node:net";
import { mkdtempSync, rmSync } from "node:fs";
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
type Status = { autoOrbit: boolean; camera: Cam | null; drawn: number; sessions: number; updates: number; verified: number; mismatches: number; message: string | null; fatal: boolean };

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
    await page.goto(`http://${addr}/?verify=1`);
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
    // Dragging takes the camera over from the auto-orbit; W flies it forward.
    assert.equal((await statusOf(page)).autoOrbit, true);
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
    await page.screenshot({ path: join(fileURLToPath(new URL(".", import.meta.url)), "viewer.png") });
  } finally {
    await page.close();
    child.kill();
  }
});

test("in chromium a wrong token shows the message and is not retried", { timeout: 60_000 }, async () => {
  const { child, addr } = await serve("127.0.0.1:0", ["--token", "sesame"]);
  const page = await browser.newPage();
  try {
    await page.goto(`http://${addr}/?token=wrong`);
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
    await page.goto(`http://${server.addr}/?verify=1`);
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
