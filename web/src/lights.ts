// The lights the viewer shadow-maps, from `/scene.glb`'s `extras.psao_lights`
// (crates/psao-net/src/glb.rs): suns (optionally turning along time keys, as psao-scene's
// `SunKeys`: slerp between consecutive keys, looping over the last key time, held before the
// first) and point lights. Rectangle lights are not served: their soft light is in the
// points' irradiance. Everything is checked as psao-scene's `Light::check` and
// `SunKeys::new` check it; a bad entry is an error naming it.

type V3 = [number, number, number];

/// A sun at some time: unit direction towards it and its irradiance (colour × power).
export interface Sun {
  direction: V3;
  irradiance: V3;
}

/// A point light: position and radiant intensity (colour × power).
export interface PointLight {
  position: V3;
  intensity: V3;
}

/// Most suns and point lights the shader takes.
export const MAX_SUNS = 4;
export const MAX_POINT_LIGHTS = 8;

interface SunKeys {
  times: number[];
  directions: V3[];
}

interface SunDoc {
  direction: V3;
  irradiance: V3;
  keys: SunKeys | null;
}

const f = Math.fround;

function vec3(v: unknown, what: string): V3 {
  if (!Array.isArray(v) || v.length !== 3 || !v.every((x) => typeof x === "number" && Number.isFinite(x))) {
    throw new Error(`${what} must be 3 finite numbers`);
  }
  return [v[0], v[1], v[2]];
}

function normalize(v: V3, what: string): V3 {
  const l = Math.hypot(v[0], v[1], v[2]);
  if (!(l * l >= 1e-12)) throw new Error(`${what} must be non-zero`);
  return [f(v[0] / l), f(v[1] / l), f(v[2] / l)];
}

const dot = (a: V3, b: V3) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

/// Spherical linear interpolation of unit vectors `a` and `b` (not opposite) at `s`.
function slerp(a: V3, b: V3, s: number): V3 {
  const angle = Math.acos(Math.min(1, Math.max(-1, dot(a, b))));
  if (angle < 1e-7) return a;
  const sa = Math.sin((1 - s) * angle) / Math.sin(angle);
  const sb = Math.sin(s * angle) / Math.sin(angle);
  return normalize([sa * a[0] + sb * b[0], sa * a[1] + sb * b[1], sa * a[2] + sb * b[2]], "sun direction");
}

/// The unit direction of a turning sun at scene time `t` seconds (psao-scene's
/// `SunKeys::direction_at`).
export function directionAt(keys: SunKeys, t: number): V3 {
  const last = keys.times[keys.times.length - 1];
  if (last > 0 && Number.isFinite(t)) t = ((t % last) + last) % last;
  let k = 0;
  while (k < keys.times.length && keys.times[k] <= t) k++;
  if (k === 0) return keys.directions[0];
  if (k === keys.times.length) return keys.directions[k - 1];
  const [t0, t1] = [keys.times[k - 1], keys.times[k]];
  return slerp(keys.directions[k - 1], keys.directions[k], t1 > t0 ? (t - t0) / (t1 - t0) : 1);
}

function keysOf(v: unknown, what: string): SunKeys {
  const k = v as { times?: unknown; directions?: unknown };
  if (typeof k !== "object" || k === null || !Array.isArray(k.times) || !Array.isArray(k.directions)) {
    throw new Error(`${what}: keys need times and directions`);
  }
  const times = k.times as unknown[];
  if (times.length === 0 || !times.every((t) => typeof t === "number" && Number.isFinite(t))) {
    throw new Error(`${what}: key times must be a non-empty list of finite seconds`);
  }
  const ts = times as number[];
  if (ts.some((t, i) => i > 0 && t < ts[i - 1])) throw new Error(`${what}: key times must not decrease`);
  if (k.directions.length !== ts.length) throw new Error(`${what}: ${k.directions.length} key directions for ${ts.length} times`);
  const directions = (k.directions as unknown[]).map((d, i) => normalize(vec3(d, `${what} key ${i}`), `${what} key ${i}`));
  if (directions.some((d, i) => i > 0 && dot(d, directions[i - 1]) < -0.9999)) {
    throw new Error(`${what}: consecutive key directions are opposite`);
  }
  return { times: ts, directions };
}

/// The served lights, checked; `at(t)` gives them at scene time `t`.
export class SceneLights {
  private suns: SunDoc[] = [];
  readonly points: PointLight[] = [];

  /// Parses `extras.psao_lights` (absent: no lights); throws on a malformed entry or more
  /// lights than the shader takes.
  constructor(doc: unknown) {
    if (doc === undefined) return;
    if (!Array.isArray(doc)) throw new Error("extras.psao_lights must be a list");
    doc.forEach((entry: unknown, i: number) => {
      const what = `light ${i}`;
      const l = entry as { kind?: unknown; color?: unknown; power?: unknown; direction?: unknown; position?: unknown; keys?: unknown };
      if (typeof l !== "object" || l === null) throw new Error(`${what} is not an object`);
      const colour = vec3(l.color, `${what} colour`);
      if (colour.some((c) => c < 0 || c > 1)) throw new Error(`${what}: colour must be in [0, 1]`);
      const power = l.power;
      if (typeof power !== "number" || !Number.isFinite(power) || power < 0) throw new Error(`${what}: power must be a non-negative number`);
      const strength: V3 = [f(colour[0] * power), f(colour[1] * power), f(colour[2] * power)];
      if (l.kind === "sun") {
        const direction = normalize(vec3(l.direction, `${what} direction`), `${what} direction`);
        const keys = l.keys === undefined ? null : keysOf(l.keys, what);
        this.suns.push({ direction, irradiance: strength, keys });
      } else if (l.kind === "point") {
        this.points.push({ position: vec3(l.position, `${what} position`), intensity: strength });
      } else {
        throw new Error(`${what}: unknown kind ${JSON.stringify(l.kind)}`);
      }
    });
    if (this.suns.length > MAX_SUNS) throw new Error(`${this.suns.length} suns: the viewer draws at most ${MAX_SUNS}`);
    if (this.points.length > MAX_POINT_LIGHTS) {
      throw new Error(`${this.points.length} point lights: the viewer draws at most ${MAX_POINT_LIGHTS}`);
    }
  }

  /// The suns at scene time `t` seconds.
  sunsAt(t: number): Sun[] {
    return this.suns.map((s) => ({ direction: s.keys ? directionAt(s.keys, t) : s.direction, irradiance: s.irradiance }));
  }
}
