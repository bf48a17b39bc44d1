// `npm run screenshot`: the README's picture. Starts `psao serve --lighting gi` on the
// built-in scene (POINTS per m², default 1024 as `psao serve`) and headless chromium (Debian's,
// WebGL2 on SwiftShader, as `npm test`; CHROMIUM overrides), opens the page at `/` as a
// visitor does (its first camera path, composited), waits until the grids hold points and
// SECONDS (default 20) more, prints the page's numbers (fps, draw and shadow-map ms of the
// last frame) and writes a screenshot of the page, overlay included, to OUT (default
// ../docs/img/viewer.png) at RES (default 960x540).
import { spawn } from "node:child_process";
import { createInterface } from "node:readline";
import { fileURLToPath } from "node:url";
import { BIN, launchChromium, sleep } from "./chromium";

// Bundled into build/bench/: the workspace is three levels up.
const POINTS = process.env.POINTS ?? "1024";
const SECONDS = Number(process.env.SECONDS ?? "20");
const OUT = process.env.OUT ?? fileURLToPath(new URL("../../../docs/img/viewer.png", import.meta.url));
const [w, h] = (process.env.RES ?? "960x540").split("x").map(Number);

interface Status {
  fps: number;
  drawMs: number;
  shadowMs: number;
  lit: boolean;
  milestones: { ao: number | null };
}

const serve = spawn(BIN, ["--log", "warn", "serve", "--listen", "127.0.0.1:0", "--points", POINTS, "--lighting", "gi"], {
  stdio: ["ignore", "pipe", "inherit"],
});
const line: string = await new Promise((r) => createInterface({ input: serve.stdout! }).once("line", r));
const addr = line.replace("listening on ", "").trim();
const chromium = await launchChromium();
const browser = chromium.browser;
try {
  const page = await browser.newPage();
  await page.setViewport({ width: w, height: h });
  await page.goto(`http://${addr}/`);
  const status = () => page.evaluate(() => (window as unknown as { psao: Status }).psao);
  for (let t = 0; t < 600 && (await status()).milestones.ao === null; t++) await sleep(1000);
  await sleep(SECONDS * 1000);
  const s = await status();
  console.log(`lit ${s.lit}, ${s.fps} fps, last frame ${s.drawMs.toFixed(1)} ms draw call, ${s.shadowMs.toFixed(1)} ms of it shadow maps`);
  await page.screenshot({ path: OUT });
  console.log(`wrote ${OUT}`);
} finally {
  await chromium.close();
  serve.kill();
}
