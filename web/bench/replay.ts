// `REPLAY=FILE npm run bench:replay`: decodes and applies, offline, the WebSocket messages
// `RECORD=FILE npm run bench` received (a welcome, then snapshots and deltas), so that
// decoders can be compared on the same updates whatever the machine's load did to the live
// stream's coalescing. Prints, per update, the median and mean ms of decode + apply (the
// viewer's wasm decoder, dist/psao.wasm) over ROUNDS passes (default 5), and the process CPU
// ms per update.
import { readFileSync } from "node:fs";
import { Codec, ViewerState } from "../src/codec";
import { decodeFrame } from "../src/wire";

const file = readFileSync(process.env.REPLAY ?? "updates.bin");
const ROUNDS = Number(process.env.ROUNDS ?? "5");
const codec = await Codec.load(readFileSync(new URL("../../dist/psao.wasm", import.meta.url)));
const messages: Uint8Array[] = [];
for (let at = 0; at + 4 <= file.length; ) {
  const len = file.readUInt32LE(at);
  messages.push(new Uint8Array(file.buffer, file.byteOffset + at + 4, len));
  at += 4 + len;
}
const times: number[] = [];
let bytes = 0;
const cpu0 = process.cpuUsage();
for (let round = 0; round < ROUNDS; round++) {
  let state: ViewerState | null = null;
  for (const frame of messages) {
    const m = decodeFrame(frame);
    if (m.kind === "welcome") {
      state?.free();
      state = new ViewerState(codec, m.welcome.instances);
    } else if ((m.kind === "delta" || m.kind === "snapshot") && state) {
      const t = performance.now();
      state.apply(m.delta.payload, m.kind === "snapshot");
      times.push(performance.now() - t);
      if (round === 0) bytes += frame.length;
    }
  }
  state?.free();
}
const cpu = process.cpuUsage(cpu0);
const n = Math.max(times.length, 1);
const sorted = [...times].sort((a, b) => a - b);
console.log(
  `${n / ROUNDS} updates (${(bytes / (n / ROUNDS) / 1024).toFixed(1)} KiB mean) × ${ROUNDS}: decode + apply median ` +
    `${sorted[Math.floor(n / 2)].toFixed(2)} ms, mean ${(times.reduce((a, b) => a + b, 0) / n).toFixed(2)} ms per update; ` +
    `process CPU ${((cpu.user + cpu.system) / 1000 / n).toFixed(2)} ms per update`,
);
