// `npm run bench:startup`: the README's promise, measured. Starts headless chromium (Debian's,
// WebGL2 on SwiftShader, as `npm test`; CHROMIUM overrides), then `psao serve` with no
// arguments but a free port (the built-in scene at default settings, as `cargo run --release
// -- serve`; the binary is used as built, nothing is rebuilt), opens the page at `/` as soon
// as the server prints its address, and reports the seconds from starting the server to: its
// address printed, the scene loaded in the page, the welcome, the first update and the first
// frame drawn with AO (the grids holding points). RUNS (default 3) repetitions, median last.
// CACHE=cold (default) gives every run an empty start-point cache (PSAO_CACHE_DIR), as on a
// fresh clone, so the server generates its points; CACHE=warm keeps one cache for all runs
// (the first run fills it).
import { spawn } from "node:child_process";
import { createInterface } from "node:readline";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { BIN, launchChromium, sleep } from "./chromium";

const RUNS = Number(process.env.RUNS ?? "3");
const RES = process.env.RES ?? "1280x720";
const COLD = (process.env.CACHE ?? "cold") === "cold";

interface Milestones {
  scene: number | null;
  welcome: number | null;
  update: number | null;
  ao: number | null;
}

const chromium = await launchChromium();
const browser = chromium.browser;
const [w, h] = RES.split("x").map(Number);
const warmCache = mkdtempSync(join(tmpdir(), "psao-cache-"));
const totals: number[] = [];
try {
  for (let run = 0; run < RUNS; run++) {
    const cache = COLD ? mkdtempSync(join(tmpdir(), "psao-cache-")) : warmCache;
    const t0 = Date.now();
    const serve = spawn(BIN, ["--log", "warn", "serve", "--listen", "127.0.0.1:0"], {
      stdio: ["ignore", "pipe", "inherit"],
      env: { ...process.env, PSAO_CACHE_DIR: cache },
    });
    try {
      const line: string = await new Promise((resolve, reject) => {
        createInterface({ input: serve.stdout! }).once("line", resolve);
        serve.once("exit", (code) => reject(new Error(`psao serve exited (${code})`)));
      });
      const listening = Date.now() - t0;
      const page = await browser.newPage();
      await page.setViewport({ width: w, height: h });
      await page.goto(`http://${line.replace("listening on ", "").trim()}/`);
      const read = () =>
        page.evaluate(() => {
          const s = (window as unknown as { psao: { milestones: Milestones } }).psao;
          return { origin: performance.timeOrigin, m: s.milestones };
        });
      let r = await read();
      for (let k = 0; k < 1200 && r.m.ao === null; k++) {
        await new Promise((res) => setTimeout(res, 100));
        r = await read();
      }
      if (r.m.ao === null) throw new Error(`no frame with AO within 120 s: ${JSON.stringify(r.m)}`);
      const at = (ms: number | null) => (ms === null ? "-" : ((r.origin + ms - t0) / 1000).toFixed(2));
      const total = (r.origin + r.m.ao - t0) / 1000;
      totals.push(total);
      console.log(
        `run ${run + 1}: listening ${(listening / 1000).toFixed(2)} s, scene loaded ${at(r.m.scene)} s, welcome ${at(r.m.welcome)} s, ` +
          `first update ${at(r.m.update)} s, first frame with AO ${total.toFixed(2)} s (page ${RES})`,
      );
      await page.close();
    } finally {
      serve.kill();
      await new Promise((res) => (serve.exitCode !== null ? res(null) : serve.once("exit", res)));
      if (COLD) rmSync(cache, { recursive: true, force: true });
    }
  }
} finally {
  await chromium.close();
  rmSync(warmCache, { recursive: true, force: true });
}
totals.sort((a, b) => a - b);
console.log(
  `serve start → first frame with AO: median ${totals[Math.floor(totals.length / 2)].toFixed(2)} s over ${RUNS} runs (${COLD ? "cold" : "warm"} start-point cache)`,
);
