// Animation playback of `/scene.glb` (src/skin.ts) against values worked out by hand from
// psao-scene's rules: slerp between keys, clamping outside them, looping over the clip's
// duration, and joint matrices relative to the skinned instance's own node.
import { test } from "node:test";
import assert from "node:assert/strict";
import { Animation, JOINT_TEXELS, sample } from "../src/skin";

const close = (a: ArrayLike<number>, b: number[], what: string) =>
  b.forEach((x, i) => assert.ok(Math.abs(a[i] - x) < 1e-5, `${what}[${i}]: ${a[i]} vs ${x}`));

test("a linear rotation channel slerps between keys and clamps outside them", () => {
  const s = Math.SQRT1_2;
  const ch = {
    node: 0,
    path: "rotation" as const,
    interpolation: "LINEAR" as const,
    times: new Float32Array([1, 3]),
    values: new Float32Array([0, 0, 0, 1, 0, 0, s, s]), // identity, then 90° about Z
  };
  close(sample(ch, 0), [0, 0, 0, 1], "before");
  close(sample(ch, 2), [0, 0, Math.sin(Math.PI / 8), Math.cos(Math.PI / 8)], "middle");
  close(sample(ch, 5), [0, 0, s, s], "after");
});

test("joint matrices loop with the clip and are relative to the instance's node", () => {
  // Node 0: the skinned instance (at its node 1); node 1 its own node, 2 m up; node 2 a joint
  // under node 1 whose translation goes (0,0,0) → (4,0,0) over 2 s; inverse bind: identity.
  const floats: Record<number, Float32Array> = {
    0: new Float32Array([0, 2]),
    1: new Float32Array([0, 0, 0, 4, 0, 0]),
  };
  const doc = {
    nodes: [
      { mesh: 0, skin: 0, matrix: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], extras: { psao_skinned: true, psao_node: 1 } },
      { translation: [0, 2, 0], children: [2] },
      {},
    ],
    skins: [{ joints: [2] }],
    animations: [{ samplers: [{ input: 0, output: 1 }], channels: [{ sampler: 0, target: { node: 2, path: "translation" } }] }],
    extras: { psao_playing: [0] },
  };
  const a = new Animation(doc, 1, (i) => floats[i]);
  assert.equal(a.jointBase[0], 0);
  // At 2.5 s the 2 s clip is at 0.5 s: the joint is 1 m along x from the instance's node,
  // whose own 2 m lift cancels.
  const m = a.jointTexels(2.5);
  assert.equal(m.length, JOINT_TEXELS * 4);
  close(m, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1], "joint matrix");
  close(m.subarray(16), [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], "normal matrix");
});
