// `npm run bench:relit`: the cost of relighting served characters in the test browser
// (Debian's headless chromium, as `npm test`; CHROMIUM overrides /usr/bin/chromium). For each
// count in COUNTS (default 1,10) it writes a scene of a floor and that many copies of the shared
// CesiumMan (CESIUM_MAN overrides the file) side by side, starts `psao serve --relight` on it
// (models cached in a temporary folder), opens the page and, once the models are loaded and a
// frame was drawn, times FRAMES (default 60) frames of the page's relighting
// (`window.psaoRelitCost`: posing, lobe synthesis and shading of every relit vertex in wasm,
// on the page's one thread; wall-clock ms per frame) and prints the vertices relit, the mean
// ms per frame over the run, the slowest frame and the models' bytes on the wire.
import { spawn } from "node:child_process";
import { createInterface } from "node:readline";
import { mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { fileURLToPath } from "node:url";
import puppeteer from "puppeteer-core";

// Bundled into build/bench/: the workspace's target/ is three levels up, the shared data four.
const BIN = process.env.PSAO_BIN ?? fileURLToPath(new URL("../../../target/release/psao", import.meta.url));
const CHROMIUM = process.env.CHROMIUM ?? "/usr/bin/chromium";
const CESIUM_MAN =
  process.env.CESIUM_MAN ?? fileURLToPath(new URL("../../../../shared/data/characters/CesiumMan/CesiumMan.gltf", import.meta.url));
const COUNTS = (process.env.COUNTS ?? "1,10").split(",").map(Number);
const FRAMES = Number(process.env.FRAMES ?? "60");

interface Status {
  drawn: number;
  relit: { state: string; characters: number; vertices: number; modelBytes: number };
  message: string | null;
}

const dir = mkdtempSync(join(tmpdir(), "psao-bench-relit-"));
const profile = mkdtempSync(join(tmpdir(), "psao-chromium-"));
const browser = await puppeteer.launch({
  executablePath: CHROMIUM,
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", `--user-data-dir=${profile}`],
});
const sleep = (ms: number) => new Promise((r) => setTimeout(r, ms));
try {
  for (const count of COUNTS) {
    const assets = Array.from({ length: count }, (_, k) => `[[asset]]\nfile = ${JSON.stringify(CESIUM_MAN)}\ntranslation = [${k * 1.2}, 0.0, 0.0]\n`);
    const scene = join(dir, `scene${count}.toml`);
    writeFileSync(scene, `[[asset]]\nfile = "builtin:box"\nscale = [${4 + 1.2 * count}, 0.1, 4.0]\ntranslation = [0.0, -0.1, 0.0]\n\n${assets.join("\n")}`);
    const serve = spawn(BIN, ["--log", "warn", "serve", "--scene", scene, "--listen", "127.0.0.1:0", "--points", "48", "--relight", "--points-cache", join(dir, "cache")], {
      stdio: ["ignore", "pipe", "inherit"],
    });
    try {
      const line: string = await new Promise((r) => createInterface({ input: serve.stdout! }).once("line", r));
      const addr = line.replace("listening on ", "").trim();
      const page = await browser.newPage();
      await page.goto(`http://${addr}/?orbit=1&res=320x180`);
      const status = () => page.evaluate(() => (window as unknown as { psao: Status }).psao);
      for (let t = 0; t < 300 && (await status()).relit.state === "loading"; t++) await sleep(1000);
      const s = await status();
      if (s.relit.state !== "ready") throw new Error(`relit characters: ${s.relit.state} (${s.message})`);
      for (let t = 0; t < 120 && (await status()).drawn < 2; t++) await sleep(1000);
      const cost = (await page.evaluate((n) => (window as unknown as { psaoRelitCost: (n: number) => unknown }).psaoRelitCost(n), FRAMES)) as {
        vertices: number;
        meanMs: number;
        maxMs: number;
      };
      console.log(
        `${count} × CesiumMan: ${cost.vertices} vertices relit, ${cost.meanMs.toFixed(2)} ms per frame over ${FRAMES} frames (slowest ${cost.maxMs.toFixed(1)} ms), models ${s.relit.modelBytes} bytes`,
      );
      await page.close();
    } finally {
      serve.kill();
    }
  }
} finally {
  await browser.close();
  rmSync(dir, { recursive: true, force: true });
  rmSync(profile, { recursive: true, force: true });
}
