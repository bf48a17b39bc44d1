// Decodes the golden frames psao-wire wrote (crates/psao-net/tests/golden_frames.rs) with the
// viewer's decoder, re-encodes the client's messages byte for byte, and feeds it broken frames.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import {
  decodeFrame,
  helloFrame,
  cameraFrame,
  ackFrame,
  byeFrame,
  WireError,
  type Message,
} from "../src/wire";

// Run from build/test/ (bundled by esbuild): the golden file is in test/golden/.
const golden: { frames: { frame: string; expect: any }[] } = JSON.parse(
  readFileSync(new URL("../../test/golden/frames.json", import.meta.url), "utf8"),
);

const bytes = (hex: string) => Uint8Array.from(hex.match(/../g) ?? [], (h) => parseInt(h, 16));
const hex = (b: Uint8Array) => Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");

/// The decoded message in the golden file's JSON shape (f32 fields compared as f32).
function plain(v: unknown): unknown {
  if (typeof v === "bigint") return v.toString(16).padStart(16, "0");
  if (v instanceof Uint8Array) return hex(v);
  if (Array.isArray(v)) return v.map(plain);
  if (v && typeof v === "object")
    return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, plain(x)]));
  return v;
}

function f32ify(v: unknown): unknown {
  if (typeof v === "number") return Math.fround(v);
  if (Array.isArray(v)) return v.map(f32ify);
  if (v && typeof v === "object")
    return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, f32ify(x)]));
  return v;
}

test("golden frames from the Rust encoder decode to their values", () => {
  assert.equal(golden.frames.length, 10);
  for (const { frame, expect } of golden.frames) {
    const m = decodeFrame(bytes(frame));
    // Every number the golden messages carry is exact in f32 or an integer, so rounding both
    // sides to f32 compares f32 fields exactly and leaves the others unchanged.
    assert.deepEqual(f32ify(plain(m)), f32ify(expect), `${expect.kind}`);
  }
});

test("client messages encode to the Rust encoder's bytes", () => {
  const byKind = new Map(golden.frames.map((f) => [f.expect.kind, f]));
  const hello = decodeFrame(bytes(byKind.get("hello")!.frame)) as Extract<Message, { kind: "hello" }>;
  assert.equal(hex(helloFrame(hello.hello)), byKind.get("hello")!.frame);
  const cam = decodeFrame(bytes(byKind.get("camera")!.frame)) as Extract<Message, { kind: "camera" }>;
  assert.equal(hex(cameraFrame(cam.camera)), byKind.get("camera")!.frame);
  assert.equal(hex(ackFrame(2 ** 40)), byKind.get("ack")!.frame);
  assert.equal(hex(byeFrame("done")), byKind.get("bye")!.frame);
});

test("broken frames are refused with a WireError, never anything else", () => {
  const good = bytes(golden.frames[1].frame);
  const cases: [string, Uint8Array][] = [
    ["empty", new Uint8Array()],
    ["short header", good.subarray(0, 7)],
    ["truncated payload", good.subarray(0, good.length - 1)],
    ["trailing byte", Uint8Array.from([...good, 0])],
    ["bad magic", Uint8Array.from(good, (b, i) => (i === 0 ? 0x51 : b))],
    ["checksum", Uint8Array.from(good, (b, i) => (i === good.length - 1 ? b ^ 0x55 : b))],
  ];
  for (const [name, frame] of cases) {
    assert.throws(() => decodeFrame(frame), WireError, name);
  }
  // Over the limit: refused from the header alone.
  assert.throws(() => decodeFrame(good, 8), /exceeds the limit/);
  // Every single-byte corruption of every golden frame: a WireError or a message, no crash.
  for (const { frame } of golden.frames) {
    const b = bytes(frame);
    for (let i = 0; i < b.length; i++) {
      for (const x of [0x01, 0x80, 0xff]) {
        const c = b.slice();
        c[i] ^= x;
        try {
          decodeFrame(c);
        } catch (e) {
          assert.ok(e instanceof WireError, `${e}`);
        }
      }
    }
  }
});
