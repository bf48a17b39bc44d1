// `npm run bench`: the viewer's decoding cost on a live stream. Starts `psao serve` on the
// built-in scene (default settings) and a `psao view` along its first camera path for FRAMES
// client frames (default 600), follows the stream with the viewer's session code in Node
// (without hash checks, as the page runs by default), and prints the mean wall ms per update
// spent decoding and applying, this process's CPU ms per update over the session (an upper
// bound of the decoding's CPU that a loaded machine does not inflate), the mean update size,
// and the ms of one full state hash. RECORD=FILE also writes every received WebSocket
// message to FILE (u32 little-endian length, then the bytes) for `bench/replay.ts`.
import { spawn } from "node:child_process";
import { appendFileSync, readFileSync, writeFileSync } from "node:fs";
import { createInterface } from "node:readline";
import { fileURLToPath } from "node:url";
import { Codec } from "../src/codec";
import { Session } from "../src/session";

// Bundled into build/bench/: the workspace's target/ is three levels up.
const BIN = process.env.PSAO_BIN ?? fileURLToPath(new URL("../../../target/release/psao", import.meta.url));
const FRAMES = process.env.FRAMES ?? "600";

const serve = spawn(BIN, ["--log", "warn", "serve", "--listen", "127.0.0.1:0"], { stdio: ["ignore", "pipe", "inherit"] });
const line: string = await new Promise((r) => createInterface({ input: serve.stdout! }).once("line", r));
const addr = line.replace("listening on ", "").trim();
if (process.env.RECORD) {
  const file = process.env.RECORD;
  writeFileSync(file, new Uint8Array(0));
  const Base = globalThis.WebSocket;
  globalThis.WebSocket = class extends Base {
    constructor(url: string | URL, protocols?: string | string[]) {
      super(url, protocols);
      this.addEventListener("message", (ev) => {
        const data = new Uint8Array(ev.data as ArrayBuffer);
        const len = new Uint8Array(4);
        new DataView(len.buffer).setUint32(0, data.length, true);
        appendFileSync(file, len);
        appendFileSync(file, data);
      });
    }
  } as typeof WebSocket;
}
let bytes = 0;
const cpuStart = process.cpuUsage();
const codec = await Codec.load(readFileSync(new URL("../../dist/psao.wasm", import.meta.url)));
const session = new Session(
  codec,
  { url: `ws://${addr}/ws`, token: null, verify: false, name: "bench" },
  { welcome: () => {}, update: (_frame, size) => (bytes += size), closed: () => {} },
);
const view = spawn(BIN, ["--log", "warn", "view", "--connect", addr, "--frames", FRAMES, "--res", "640x360"], {
  stdio: ["ignore", "ignore", "inherit"],
});
await new Promise((r) => view.once("exit", r));
await new Promise((r) => setTimeout(r, 500));
const cpu = process.cpuUsage(cpuStart);
const hashMs: number[] = [];
for (let k = 0; k < 5; k++) {
  const t = performance.now();
  session.state?.stateHash();
  hashMs.push(performance.now() - t);
}
hashMs.sort((a, b) => a - b);
const n = Math.max(session.updates, 1);
console.log(
  `${session.updates} updates over ${FRAMES} client frames: ${(session.decodeMs / n).toFixed(2)} ms decode + apply per update ` +
    `(mean ${(bytes / n / 1024).toFixed(1)} KiB per update), process CPU ${((cpu.user + cpu.system) / 1000 / n).toFixed(1)} ms ` +
    `per update; state hash ${hashMs[2].toFixed(1)} ms (median of 5)`,
);
session.close();
serve.kill();
