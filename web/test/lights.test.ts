// The served lights (`extras.psao_lights`): turning suns as psao-scene's `SunKeys` (values
// worked out by hand, as its own test), shadow settings as psao-raster's `for_image`, and
// malformed entries refused with their name.
import { test } from "node:test";
import assert from "node:assert/strict";
import { SceneLights, directionAt, MAX_POINT_LIGHTS } from "../src/lights";
import { cascadeSpheres, settingsForImage } from "../src/shadow";

const close = (a: number[], b: number[], eps = 1e-5) => a.every((v, i) => Math.abs(v - b[i]) < eps);

test("a keyed sun turns on the sphere and loops over its last key time", () => {
  const keys = { times: [0, 10, 20], directions: [[1, 0, 0], [0, 1, 0], [-1, 0, 0]] as [number, number, number][] };
  const half = [Math.SQRT1_2, Math.SQRT1_2, 0];
  assert.ok(close(directionAt(keys, 0), [1, 0, 0]));
  assert.ok(close(directionAt(keys, 10), [0, 1, 0]));
  assert.ok(close(directionAt(keys, 5), half));
  assert.ok(close(directionAt(keys, 25), half), "25 s is 5 s");
  assert.ok(close(directionAt(keys, -15), half));
  assert.ok(close(directionAt(keys, 15), [-Math.SQRT1_2, Math.SQRT1_2, 0]));
});

test("served lights are read with their strength and checked", () => {
  const lights = new SceneLights([
    { kind: "sun", direction: [0, 2, 0], color: [1, 0.5, 0], power: 2, keys: { times: [0, 10], directions: [[0, 1, 0], [1, 0, 0]] } },
    { kind: "point", position: [1, 2, 3], color: [1, 1, 1], power: 4 },
  ]);
  const [sun] = lights.sunsAt(5);
  assert.ok(close(sun.direction, [Math.SQRT1_2, Math.SQRT1_2, 0]));
  assert.deepEqual(sun.irradiance, [2, 1, 0]);
  assert.deepEqual(lights.points, [{ position: [1, 2, 3], intensity: [4, 4, 4] }]);
  assert.deepEqual(new SceneLights(undefined).sunsAt(0), []);
  const bad: [unknown, RegExp][] = [
    [{}, /must be a list/],
    [[{ kind: "sun", direction: [0, 0, 0], color: [1, 1, 1], power: 1 }], /light 0 direction must be non-zero/],
    [[{ kind: "sun", direction: [0, 1, 0], color: [2, 1, 1], power: 1 }], /colour must be in \[0, 1\]/],
    [[{ kind: "point", position: [0, "x", 0], color: [1, 1, 1], power: 1 }], /position must be 3 finite numbers/],
    [[{ kind: "point", position: [0, 0, 0], color: [1, 1, 1], power: -1 }], /non-negative/],
    [[{ kind: "rect", color: [1, 1, 1], power: 1 }], /unknown kind/],
    [[{ kind: "sun", direction: [0, 1, 0], color: [1, 1, 1], power: 1, keys: { times: [1, 0], directions: [[0, 1, 0], [1, 0, 0]] } }], /must not decrease/],
    [[{ kind: "sun", direction: [0, 1, 0], color: [1, 1, 1], power: 1, keys: { times: [0, 1], directions: [[0, 1, 0], [0, -1, 0]] } }], /opposite/],
    [Array.from({ length: MAX_POINT_LIGHTS + 1 }, () => ({ kind: "point", position: [0, 0, 0], color: [1, 1, 1], power: 1 })), /at most/],
  ];
  for (const [doc, message] of bad) assert.throws(() => new SceneLights(doc), message);
});

test("shadow settings and cascades follow psao-raster's", () => {
  assert.deepEqual(settingsForImage(160, 90), { sunResolution: 256, cascades: 3, pointResolution: 80, pcf: 1 });
  assert.deepEqual(settingsForImage(4000, 100), { sunResolution: 2048, cascades: 3, pointResolution: 512, pcf: 1 });
  // A viewer at the centre of a 200 m ground: slices growing with distance, the last one
  // (wider than the scene) replaced by the scene's sphere.
  const camera = { position: [0, 2, 0] as [number, number, number], target: [0, 2, -1] as [number, number, number], up: [0, 1, 0] as [number, number, number], fovY: Math.PI / 3, near: 0.1, far: 1000 };
  const spheres = cascadeSpheres(camera, 16 / 9, [-100, 0, -100], [100, 0, 100], 3);
  assert.equal(spheres.length, 3);
  assert.ok(spheres[0].radius < spheres[1].radius && spheres[1].radius < spheres[2].radius);
  assert.ok(spheres[1].radius < 100 * Math.SQRT2, "the middle slice is smaller than the scene");
  assert.ok(Math.abs(spheres[2].radius - 100 * Math.SQRT2) < 1e-6, "the far slice is the scene's sphere");
  assert.ok(spheres[0].centre[2] < 0, "the first slice lies before the viewer");
});
