// Decodes, in order, a session of `compact` payloads written by psao-delta's encoder
// (crates/psao-net/tests/golden_compact.rs) and compares every update with what the Rust
// decoder read; corrupted payloads and a too-small limit give a DeltaError, nothing else.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { CompactDecoder, DeltaError, type Update } from "../src/compact";

// Run from build/test/ (bundled by esbuild): the golden file is in test/golden/.
const golden: { updates: { payload: string; expect: unknown }[] } = JSON.parse(
  readFileSync(new URL("../../test/golden/compact.json", import.meta.url), "utf8"),
);

const bytes = (hex: string) => Uint8Array.from(hex.match(/../g) ?? [], (h) => parseInt(h, 16));

/// An update in the golden file's JSON shape.
function shape(u: Update): unknown {
  return {
    frame: Number(u.frame),
    snapshot: u.snapshot,
    transforms: u.transforms.map(([i, t]) => [i, Array.from(t)]),
    instances: u.instances.map((d) => ({
      instance: d.instance,
      buckets: Array.from(d.bucketIds, (b, k) => [
        b,
        Array.from(d.slots.subarray(8 * k, 8 * k + 8), (slot, i) => [
          ((BigInt(d.keyHi[8 * k + i]) << 32n) | BigInt(d.keyLo[8 * k + i])).toString(16).padStart(16, "0"),
          slot,
        ]),
      ]),
      cells: Array.from(d.cellSlots, (s, k) => [s, Array.from(d.points.subarray(7 * k, 7 * k + 7))]),
    })),
  };
}

/// Rounds the golden file's f32 numbers (printed shortest) back to f32.
function f32ify(v: unknown): unknown {
  if (typeof v === "number") return Math.fround(v);
  if (Array.isArray(v)) return v.map(f32ify);
  if (v && typeof v === "object") return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, f32ify(x)]));
  return v;
}

test("a session of compact payloads from the Rust encoder decodes like the Rust decoder", () => {
  assert.equal(golden.updates.length, 7);
  const d = new CompactDecoder();
  for (const [k, { payload, expect }] of golden.updates.entries()) {
    assert.deepEqual(f32ify(shape(d.decode(bytes(payload)))), f32ify(expect), `update ${k}`);
  }
});

test("corrupted payloads and decompression bombs give a DeltaError", () => {
  const first = bytes(golden.updates[0].payload);
  assert.throws(() => new CompactDecoder(1000).decode(first), /exceeds the limit/);
  let errors = 0;
  for (let i = 0; i < first.length; i += 3) {
    for (const x of [0x01, 0xff]) {
      const c = first.slice();
      c[i] ^= x;
      try {
        new CompactDecoder().decode(c);
      } catch (e) {
        assert.ok(e instanceof DeltaError, `byte ${i}: ${e}`);
        errors++;
      }
    }
  }
  assert.ok(errors > 0);
});
