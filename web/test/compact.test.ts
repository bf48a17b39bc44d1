// Applies, in order, a session of `compact` payloads written by psao-delta's encoder
// (crates/psao-net/tests/golden_compact.rs) with the viewer's decoder, dist/psao.wasm (the
// Rust decoder and client state): after every update the state hash is psao-client's, the
// change records hold the update's buckets (used entries) and cells as the Rust decoder read
// them, and the transforms are the update's; corrupted payloads and a table whose decode
// limit is too small give a DecodeError, nothing else.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { Codec, DecodeError, ViewerState } from "../src/codec";
import type { InstanceEntry } from "../src/wire";

interface Expect {
  snapshot: boolean;
  transforms: [number, number[]][];
  instances: { instance: number; buckets: [number, [string, number][]][]; cells: [number, number[]][] }[];
}

// Run from build/test/ (bundled by esbuild): the golden file is in test/golden/, the wasm in dist/.
const golden: { table: InstanceEntry[]; updates: { payload: string; expect: Expect; state_hash: string }[] } =
  JSON.parse(readFileSync(new URL("../../test/golden/compact.json", import.meta.url), "utf8"));
const codec = await Codec.load(readFileSync(new URL("../../dist/psao.wasm", import.meta.url)));

const bytes = (hex: string) => Uint8Array.from(hex.match(/../g) ?? [], (h) => parseInt(h, 16));

/// The change records (crates/psao-wasm/src/changes.rs) of an update as the golden file has it.
function records(u: Expect): number[] {
  const out: number[] = u.snapshot ? [2] : [];
  for (const d of u.instances) {
    for (const [b, entries] of d.buckets) {
      const used = entries.filter(([key]) => BigInt("0x" + key) !== 0n);
      out.push(0, d.instance, b, used.length);
      for (const [key, slot] of used) {
        const k = BigInt("0x" + key);
        out.push(Number(k & 0xffffffffn), Number(k >> 32n), slot);
      }
    }
    // Each cell's 7 irradiance records follow its points: zeros in this AO-only session.
    for (const [s, points] of d.cells) out.push(1, d.instance, s, ...points, 0, 0, 0, 0, 0, 0, 0);
  }
  return out;
}

test("a session of compact payloads from the Rust encoder applies like psao-client", () => {
  assert.equal(golden.updates.length, 7);
  const state = new ViewerState(codec, golden.table);
  for (const [k, { payload, expect, state_hash }] of golden.updates.entries()) {
    state.apply(bytes(payload), expect.snapshot);
    assert.equal(state.stateHash().toString(16).padStart(16, "0"), state_hash, `update ${k}`);
    assert.deepEqual(Array.from(state.changes()), records(expect), `update ${k}`);
    for (const [i, t] of expect.transforms) {
      assert.deepEqual(Array.from(state.transforms[i]!), t.map(Math.fround), `update ${k}`);
    }
  }
  state.free();
});

test("corrupted payloads, wrong snapshot flags and too-small limits give a DecodeError", () => {
  const first = bytes(golden.updates[0].payload);
  // One bucket per instance: a decode limit far below the snapshot's size.
  const small = new ViewerState(codec, golden.table.map((e) => ({ ...e, bucketCount: 1 })));
  assert.throws(() => small.apply(first, true), (e) => e instanceof DecodeError && e.code === 2 && /limit/.test(e.message));
  small.free();
  const flag = new ViewerState(codec, golden.table);
  assert.throws(() => flag.apply(first, false), (e) => e instanceof DecodeError && e.code === 3);
  flag.free();
  let errors = 0;
  for (let i = 0; i < first.length; i += 3) {
    for (const x of [0x01, 0xff]) {
      const c = first.slice();
      c[i] ^= x;
      const state = new ViewerState(codec, golden.table);
      try {
        state.apply(c, true);
      } catch (e) {
        assert.ok(e instanceof DecodeError, `byte ${i}: ${e}`);
        errors++;
      }
      state.free();
    }
  }
  assert.ok(errors > 0);
});
