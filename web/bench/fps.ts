// `npm run bench:fps`: the viewer in the test browser (Debian's headless chromium, WebGL2 on
// SwiftShader, as `npm test`; CHROMIUM overrides /usr/bin/chromium) against `psao serve` on
// the built-in scene (POINTS per m², default 1024 as `psao serve`). For each canvas size it
// follows the camera path `default_a` live for SECONDS (default 20) once 3 updates arrived
// and a frame was drawn after them (the snapshot's upload is behind) and prints the frames drawn
// per second (composited view), the AO shader's cells and points visited per covered pixel,
// the in-page decode + apply ms per update and the grid texture bytes uploaded per update.
import { spawn } from "node:child_process";
import { createInterface } from "node:readline";
import { BIN, launchChromium, sleep } from "./chromium";

const SECONDS = Number(process.env.SECONDS ?? "20");
const POINTS = process.env.POINTS ?? "1024";
const SIZES = (process.env.SIZES ?? "640x360,1280x720").split(",");

interface Status {
  drawn: number;
  updates: number;
  decodeMs: number;
  uploadedBytes: number;
  textureBytes: number;
}

const serve = spawn(BIN, ["--log", "warn", "serve", "--listen", "127.0.0.1:0", "--points", POINTS], { stdio: ["ignore", "pipe", "inherit"] });
const line: string = await new Promise((r) => createInterface({ input: serve.stdout! }).once("line", r));
const addr = line.replace("listening on ", "").trim();
const chromium = await launchChromium();
const browser = chromium.browser;
try {
  for (const size of SIZES) {
    const [w, h] = size.split("x").map(Number);
    const page = await browser.newPage();
    await page.setViewport({ width: w, height: h });
    await page.goto(`http://${addr}/?path=default_a&res=${size}`);
    const status = () => page.evaluate(() => (window as unknown as { psao: Status }).psao);
    for (let t = 0; t < 120 && (await status()).updates < 3; t++) await sleep(1000);
    const drawn = (await status()).drawn;
    for (let t = 0; t < 120 && (await status()).drawn < drawn + 2; t++) await sleep(1000);
    const a = await status();
    const t0 = Date.now();
    await sleep(SECONDS * 1000);
    const b = await status();
    const seconds = (Date.now() - t0) / 1000;
    const cost = (await page.evaluate(() => (window as unknown as { psaoCost: () => unknown }).psaoCost())) as {
      cellsPerPixel: number;
      pointsPerPixel: number;
    };
    const updates = Math.max(b.updates - a.updates, 1);
    console.log(
      `${size}, ${POINTS} points/m²: ${((b.drawn - a.drawn) / seconds).toFixed(1)} fps (composited, ${b.drawn - a.drawn} frames in ${seconds.toFixed(1)} s); ` +
        `AO shader ${cost.cellsPerPixel.toFixed(2)} cells, ${cost.pointsPerPixel.toFixed(1)} points per covered pixel; ` +
        `${b.updates - a.updates} updates in the window (${b.updates} in all), decode + apply ${b.decodeMs.toFixed(2)} ms per update (in the page), ` +
        `${((b.uploadedBytes - a.uploadedBytes) / updates / 1024).toFixed(1)} KiB of textures uploaded per update, ` +
        `${(b.textureBytes / 2 ** 20).toFixed(1)} MiB of grid textures`,
    );
    await page.close();
  }
} finally {
  await chromium.close();
  serve.kill();
}
