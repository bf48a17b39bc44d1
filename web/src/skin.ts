// Animation playback and skinning matrices for `/scene.glb`, as psao-scene's `Animator`
// poses a scene (crates/psao-scene/src/anim/): the playing clips (`extras.psao_playing`),
// each looping over its own duration, sample their channels (step, linear with slerp for
// rotations, cubic spline; clamped to the first and last keys) into the nodes' local
// translation, rotation and scale; world transforms follow parents first; a skinned
// instance's joint matrices are `to_local · world(joint) · inverse_bind`, `to_local` the
// inverse of the instance's own node (its stored transform without one). The vertex shader
// blends them with the mesh's renormalised weights (`render.ts`). Walkers (procedural motion)
// have no glTF form: a skinned instance moved by one is posed without it, which is exact
// when the walker drives a node above both the instance's node and its joints.

/// Texels (RGBA32F) per joint in the joint texture: the joint matrix's four columns, then
/// the three columns of its normal matrix (inverse transpose of the linear part).
export const JOINT_TEXELS = 7;

/// A glTF accessor's numbers.
export type AccessorReader = (index: number) => Float32Array | Uint16Array | Uint32Array;

interface NodeDoc {
  mesh?: number;
  skin?: number;
  matrix?: number[];
  children?: number[];
  translation?: number[];
  rotation?: number[];
  scale?: number[];
  extras?: { psao_skinned?: boolean; psao_node?: number | null };
}

/// The parts of the glTF document playback reads.
export interface AnimationDoc {
  nodes?: NodeDoc[];
  skins?: { joints: number[]; inverseBindMatrices?: number }[];
  animations?: {
    samplers: { input: number; output: number; interpolation?: string }[];
    channels: { sampler: number; target: { node?: number; path: string } }[];
  }[];
  extras?: { psao_playing?: number[] };
}

interface Channel {
  node: number;
  path: "translation" | "rotation" | "scale";
  interpolation: "STEP" | "LINEAR" | "CUBICSPLINE";
  times: Float32Array;
  values: Float32Array;
}

interface Rig {
  instance: number;
  joints: number[];
  inverseBind: Float64Array[];
  /// The node whose world transform is the instance's own, or null (its stored matrix).
  node: number | null;
  rest: Float64Array;
  /// Its first joint in the joint texture.
  base: number;
}

type Mat = Float64Array; // 4×4, column-major

/// The scene's playing animation and its skinned instances.
export class Animation {
  private rest: { t: number[]; r: number[]; s: number[] }[];
  private parents: (number | null)[];
  private order: number[];
  private clips: { duration: number; channels: Channel[] }[] = [];
  private rigs: Rig[] = [];
  /// Per instance: its first joint in the joint texture, or -1 (not skinned).
  readonly jointBase: Int32Array;
  /// Joints of all rigs.
  readonly jointCount: number;

  constructor(doc: AnimationDoc, instances: number, read: AccessorReader) {
    const nodes = doc.nodes ?? [];
    this.rest = nodes.map((n) => ({ t: n.translation ?? [0, 0, 0], r: n.rotation ?? [0, 0, 0, 1], s: n.scale ?? [1, 1, 1] }));
    this.parents = nodes.map(() => null);
    nodes.forEach((n, p) => n.children?.forEach((c) => (this.parents[c] = p)));
    this.order = parentsFirst(this.parents);
    for (const a of (doc.extras?.psao_playing ?? []).map((k) => doc.animations?.[k])) {
      if (!a) continue;
      const channels: Channel[] = [];
      for (const ch of a.channels) {
        const s = a.samplers[ch.sampler];
        if (!s || ch.target.node === undefined || !["translation", "rotation", "scale"].includes(ch.target.path)) continue;
        channels.push({
          node: ch.target.node,
          path: ch.target.path as Channel["path"],
          interpolation: (s.interpolation ?? "LINEAR") as Channel["interpolation"],
          times: Float32Array.from(read(s.input)),
          values: Float32Array.from(read(s.output)),
        });
      }
      const duration = channels.reduce((d, c) => Math.max(d, c.times.length ? c.times[c.times.length - 1] : 0), 0);
      this.clips.push({ duration, channels });
    }
    this.jointBase = new Int32Array(instances).fill(-1);
    let base = 0;
    for (let i = 0; i < Math.min(instances, nodes.length); i++) {
      const n = nodes[i];
      const skin = n.skin !== undefined ? doc.skins?.[n.skin] : undefined;
      if (!n.extras?.psao_skinned || !skin) continue;
      const ibm = skin.inverseBindMatrices !== undefined ? read(skin.inverseBindMatrices) : null;
      const inverseBind = skin.joints.map((_, j) =>
        ibm ? Float64Array.from(ibm.subarray(16 * j, 16 * j + 16)) : identity(),
      );
      this.rigs.push({
        instance: i,
        joints: skin.joints,
        inverseBind,
        node: n.extras.psao_node ?? null,
        rest: Float64Array.from(n.matrix ?? identity()),
        base,
      });
      this.jointBase[i] = base;
      base += skin.joints.length;
    }
    this.jointCount = base;
  }

  /// Whether any instance is skinned.
  get skinned(): boolean {
    return this.rigs.length > 0;
  }

  /// Every rig's joint matrices at scene time `time` (seconds), `JOINT_TEXELS` RGBA texels
  /// per joint from `jointBase[instance]`.
  jointTexels(time: number): Float32Array {
    const world = this.worlds(time);
    const out = new Float32Array(Math.max(1, this.jointCount) * JOINT_TEXELS * 4);
    for (const rig of this.rigs) {
      const own = rig.node !== null && world[rig.node] ? world[rig.node] : rig.rest;
      const toLocal = invertOrIdentity(own);
      rig.joints.forEach((j, k) => {
        const m = mul(mul(toLocal, world[j] ?? identity()), rig.inverseBind[k]);
        const at = (rig.base + k) * JOINT_TEXELS * 4;
        out.set(m, at);
        out.set(normalMatrix(m), at + 16);
      });
    }
    return out;
  }

  /// World transforms of all nodes at `time` (psao-scene's `node_worlds`, without walkers).
  private worlds(time: number): Mat[] {
    const local = this.rest.map((n) => ({ t: n.t.slice(), r: n.r.slice(), s: n.s.slice() }));
    for (const clip of this.clips) {
      const t = clip.duration > 0 ? remEuclid(time, clip.duration) : 0;
      for (const ch of clip.channels) {
        const slot = local[ch.node];
        if (!slot) continue;
        const v = sample(ch, t);
        if (ch.path === "rotation") slot.r = v;
        else if (ch.path === "scale") slot.s = v;
        else slot.t = v;
      }
    }
    const world: Mat[] = new Array(local.length);
    for (const n of this.order) {
      const l = trs(local[n].t, local[n].r, local[n].s);
      const p = this.parents[n];
      world[n] = p === null ? l : mul(world[p], l);
    }
    return world;
  }
}

function remEuclid(a: number, b: number): number {
  const r = a % b;
  return r < 0 ? r + b : r;
}

/// Node indices with every parent before its children (nodes in a cycle are left out).
function parentsFirst(parents: (number | null)[]): number[] {
  const children: number[][] = parents.map(() => []);
  parents.forEach((p, i) => p !== null && children[p]?.push(i));
  const order = parents.flatMap((p, i) => (p === null ? [i] : []));
  for (let k = 0; k < order.length; k++) order.push(...children[order[k]]);
  return order;
}

/// A channel's value at clip time `t` (psao-scene's `sample`): 3 numbers, or a unit
/// quaternion (x, y, z, w) for rotations.
export function sample(ch: Channel, t: number): number[] {
  const w = ch.path === "rotation" ? 4 : 3;
  const cubic = ch.interpolation === "CUBICSPLINE";
  const valueAt = (k: number, part = 1) => {
    const start = cubic ? (3 * k + part) * w : k * w;
    return Array.from(ch.values.subarray(start, start + w));
  };
  const times = ch.times;
  let next = 0;
  while (next < times.length && times[next] <= t) next++;
  let raw: number[];
  if (next === 0) raw = valueAt(0);
  else if (next === times.length) raw = valueAt(times.length - 1);
  else {
    const k = next - 1;
    const dt = times[k + 1] - times[k];
    const s = (t - times[k]) / dt;
    if (ch.interpolation === "STEP") raw = valueAt(k);
    else if (ch.interpolation === "LINEAR") {
      if (ch.path === "rotation") return normalize(slerp(normalize(valueAt(k)), normalize(valueAt(k + 1)), s));
      const a = valueAt(k);
      const b = valueAt(k + 1);
      raw = a.map((x, i) => x + (b[i] - x) * s);
    } else {
      const p0 = valueAt(k);
      const m0 = valueAt(k, 2);
      const p1 = valueAt(k + 1);
      const m1 = valueAt(k + 1, 0);
      const s2 = s * s;
      const s3 = s2 * s;
      raw = p0.map(
        (_, i) =>
          p0[i] * (2 * s3 - 3 * s2 + 1) + m0[i] * (dt * (s3 - 2 * s2 + s)) + p1[i] * (-2 * s3 + 3 * s2) + m1[i] * (dt * (s3 - s2)),
      );
    }
  }
  if (ch.path !== "rotation") return raw;
  const len = Math.hypot(...raw);
  return len > 0 && Number.isFinite(len) ? raw.map((x) => x / len) : [0, 0, 0, 1];
}

function normalize(q: number[]): number[] {
  const len = Math.hypot(...q);
  return q.map((x) => x / len);
}

/// glam's `Quat::slerp` (shortest arc; linear above a dot of 1 − ε; its `acos_approx`).
function slerp(a: number[], b: number[], s: number): number[] {
  let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  let e = b;
  if (dot < 0) {
    e = b.map((x) => -x);
    dot = -dot;
  }
  if (dot > 1 - 2 ** -23) return normalize(a.map((x, i) => x * (1 - s) + e[i] * s));
  const theta = acosApprox(dot);
  const s1 = Math.sin(theta * (1 - s));
  const s2 = Math.sin(theta * s);
  const inv = 1 / Math.sin(theta);
  return a.map((x, i) => (x * s1 + e[i] * s2) * inv);
}

/// glam's `acos_approx` (DirectXMath's 7-degree minimax).
function acosApprox(v: number): number {
  const x = Math.abs(v);
  const root = Math.sqrt(Math.max(1 - x, 0));
  const r =
    ((((((-0.0012624911 * x + 0.00667009) * x - 0.017088126) * x + 0.03089188) * x - 0.050174303) * x + 0.08897899) * x -
      0.2145988) *
      x +
    1.5707963;
  return v >= 0 ? r * root : Math.PI - r * root;
}

function identity(): Mat {
  const m = new Float64Array(16);
  m[0] = m[5] = m[10] = m[15] = 1;
  return m;
}

/// T · R · S (glam's `from_scale_rotation_translation`).
function trs(t: number[], q: number[], s: number[]): Mat {
  const [x, y, z, w] = q;
  const m = identity();
  const cols = [
    [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)],
    [2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)],
    [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)],
  ];
  for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) m[4 * c + r] = cols[c][r] * s[c];
  m[12] = t[0];
  m[13] = t[1];
  m[14] = t[2];
  return m;
}

function mul(a: Mat, b: Mat): Mat {
  const out = new Float64Array(16);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[4 * k + r] * b[4 * c + k];
      out[4 * c + r] = s;
    }
  }
  return out;
}

function det3(m: Mat): number {
  return (
    m[0] * (m[5] * m[10] - m[6] * m[9]) - m[4] * (m[1] * m[10] - m[2] * m[9]) + m[8] * (m[1] * m[6] - m[2] * m[5])
  );
}

/// The 3×3 inverse of `m`'s linear part, column-major (9 numbers), or null when singular.
function inverse3(m: Mat): number[] | null {
  const det = det3(m);
  if (!(det !== 0 && Number.isFinite(det))) return null;
  const [a, b, c, d, e, f, g, h, i] = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
  // Columns (a b c), (d e f), (g h i): inverse = adjugate / det.
  return [
    (e * i - f * h) / det,
    (c * h - b * i) / det,
    (b * f - c * e) / det,
    (f * g - d * i) / det,
    (a * i - c * g) / det,
    (c * d - a * f) / det,
    (d * h - e * g) / det,
    (b * g - a * h) / det,
    (a * e - b * d) / det,
  ];
}

/// psao-scene's `invert_or_identity` for an affine matrix.
function invertOrIdentity(m: Mat): Mat {
  const det = det3(m);
  if (!(m.every(Number.isFinite) && det !== 0 && Math.abs(det) >= 2 ** -126)) return identity();
  const inv = inverse3(m)!;
  const out = identity();
  for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) out[4 * c + r] = inv[3 * c + r];
  for (let r = 0; r < 3; r++) out[12 + r] = -(inv[r] * m[12] + inv[3 + r] * m[13] + inv[6 + r] * m[14]);
  return out;
}

/// The normal matrix of a joint (psao-scene's skinning): the inverse transpose of its linear
/// part, else the linear part itself; three RGBA columns.
function normalMatrix(m: Mat): number[] {
  const inv = inverse3(m);
  if (!inv || !inv.every(Number.isFinite)) return [m[0], m[1], m[2], 0, m[4], m[5], m[6], 0, m[8], m[9], m[10], 0];
  // Transpose of the inverse, column-major: column c = row c of the inverse.
  return [inv[0], inv[3], inv[6], 0, inv[1], inv[4], inv[7], 0, inv[2], inv[5], inv[8], 0];
}
