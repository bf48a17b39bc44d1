// WebGL2 rasterization of `/scene.glb` with per-pixel AO, deferred: every instance node
// (node i = instance i of the instance table) with its mesh, at the transform of the last
// update that carried one (its rest matrix until then), goes into a G-buffer (world
// position, instance, shading normal, base colour); a full-screen pass then reconstructs AO
// from the grids in GPU textures (`grids.ts`) once per pixel and composites as psao-client
// does (`aoshader.ts`). In a lit session (the state holds irradiance records) the pass also
// reconstructs the irradiance and adds the direct light of the scene's suns and point lights
// (`/scene.glb`'s `extras.psao_lights`, `lights.ts`) from shadow maps rendered first in the
// same pose (`shadow.ts`). Served relit characters (`relit.ts`) carry their per-vertex
// values into the G-buffer, and the full-screen pass shades their pixels with them.

import { FRAGMENT, FULLSCREEN, GBUFFER, MODE_AO, MODE_IRRADIANCE, VERTEX } from "./aoshader";
import { SceneLights } from "./lights";
import { SHADOW_FRAGMENT, ShadowMaps, settingsForImage, type MapCamera } from "./shadow";
import { TEX_WIDTH, type GridTextures } from "./grids";
import { Animation, JOINT_TEXELS, type AccessorReader, type AnimationDoc } from "./skin";
import type { RelitCharacters } from "./relit";
import type { ViewerState } from "./codec";
import type { Camera } from "./wire";

interface Primitive {
  vao: WebGLVertexArrayObject;
  count: number;
  /// Index of its base colour in the colour texture.
  colour: number;
  /// Whether it carries joints and weights (skinned when its instance is).
  skin: boolean;
}

export type GltfDoc = AnimationDoc & {
  meshes?: {
    primitives: {
      attributes: { POSITION?: number; NORMAL?: number; JOINTS_0?: number; WEIGHTS_0?: number };
      indices?: number;
      material?: number;
    }[];
  }[];
  materials?: { pbrMetallicRoughness?: { baseColorFactor?: number[] } }[];
  accessors?: { bufferView?: number; byteOffset?: number; count: number; componentType: number; type: string }[];
  bufferViews?: { byteOffset?: number; byteLength: number }[];
  extras?: { psao_camera_paths?: CameraPathDoc[]; psao_lights?: unknown };
};

const COMPONENTS: Record<string, number> = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };

/// Accessor `index` of `doc` over `bin` as a typed array of its component type (float,
/// unsigned short or unsigned int, as `psao serve` writes them), copied (aligned).
export function readAccessor(doc: GltfDoc, bin: Uint8Array, index: number): Float32Array | Uint16Array | Uint32Array {
  const a = doc.accessors?.[index];
  const bv = a?.bufferView !== undefined ? doc.bufferViews?.[a.bufferView] : undefined;
  if (!a || !bv) throw new Error(`scene.glb: accessor ${index} has no data`);
  const n = a.count * (COMPONENTS[a.type] ?? 1);
  const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
  const Kind = a.componentType === 5126 ? Float32Array : a.componentType === 5123 ? Uint16Array : Uint32Array;
  const bytes = bin.slice(start, start + n * Kind.BYTES_PER_ELEMENT);
  if (bytes.length !== n * Kind.BYTES_PER_ELEMENT) throw new Error(`scene.glb: accessor ${index} is truncated`);
  return new Kind(bytes.buffer);
}

/// psao-scene's skinning weights: clamped to ≥ 0 (non-finite: 0) and renormalised to sum to
/// 1, all-zero sets weighting the first joint alone.
function renormalisedWeights(w: Float32Array | Uint16Array | Uint32Array): Float32Array {
  const out = new Float32Array(w.length);
  for (let v = 0; v + 4 <= w.length; v += 4) {
    const x = [0, 1, 2, 3].map((k) => (Number.isFinite(w[v + k]) ? Math.max(w[v + k], 0) : 0));
    const sum = Math.fround(Math.fround(Math.fround(x[0] + x[1]) + x[2]) + x[3]);
    if (sum > 0) for (let k = 0; k < 4; k++) out[v + k] = x[k] / sum;
    else out[v] = 1;
  }
  return out;
}

/// A camera path of the scene, one camera per 60 Hz frame: position, target, up, vertical
/// FOV, near, far (12 numbers; `crates/psao-net/src/glb.rs`).
export interface CameraPathDoc {
  name: string;
  frames: number[][];
}

/// psao-client's reconstruction settings and shading (`ReconstructSettings`, `Shading`,
/// psao-points' thresholds), as f32.
const SETTINGS = {
  factor: Math.fround(2 * Math.SQRT2),
  planeTolerance: 0.5,
  normalThreshold: Math.fround(0.1),
  directionThreshold: Math.fround(0.7),
  exponent: 8,
  fallback: true,
  ambient: Math.fround(0.6),
  light: 0.5,
};
/// psao-client's SKY_GREY (linear), drawn where nothing is covered.
const SKY_GREY = [0.62, 0.66, 0.72];
/// Smallest |det| of an instance transform that psao-client inverts.
const MIN_DETERMINANT = 1e-12;

/// psao-client's `encode_srgb` (8-bit).
export function encodeSrgb(linear: number): number {
  const c = Math.min(Math.max(linear, 0), 1);
  const s = c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
  return Math.round(s * 255);
}

/// The 256 decoded normals of psao-points' 8-bit octahedral codes (`decode_normal`), in f32
/// arithmetic step by step as the Rust code computes them.
export function normalTable(): Float32Array {
  const f = Math.fround;
  const step = f(2 / 14);
  const level = (q: number) => f(f(Math.min(q, 14) * step) - 1);
  const sign = (x: number) => (x >= 0 ? 1 : -1);
  const out = new Float32Array(256 * 4);
  for (let code = 0; code < 256; code++) {
    const ox = level(code >> 4);
    const oy = level(code & 15);
    const z = f(f(1 - Math.abs(ox)) - Math.abs(oy));
    let v: number[];
    if (z >= 0) v = [ox, oy, z];
    else v = [f(f(1 - Math.abs(oy)) * sign(ox)), f(f(1 - Math.abs(ox)) * sign(oy)), z];
    const len = f(Math.sqrt(f(f(f(v[0] * v[0]) + f(v[1] * v[1])) + f(v[2] * v[2]))));
    const inv = f(1 / len);
    out.set([f(v[0] * inv), f(v[1] * inv), f(v[2] * inv), 0], code * 4);
  }
  return out;
}

function compile(gl: WebGL2RenderingContext, type: number, source: string): WebGLShader {
  const s = gl.createShader(type)!;
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
  return s;
}

/// An instance's grid view for the shader: world → local, world normal → local normal.
interface InstanceView {
  toLocal: Float32Array; // mat4, column-major
  normalToLocal: Float32Array; // mat3
}

/// psao-client's `InstanceView::new`: the inverse of an Affine3A (12 floats: columns, then
/// translation) and the transpose of its linear part; null when not invertible.
function instanceView(t: Float32Array): InstanceView | null {
  const [a, b, c, d, e, f, g, h, i] = t; // columns (a b c), (d e f), (g h i)
  const det = a * (e * i - f * h) - d * (b * i - c * h) + g * (b * f - c * e);
  if (!(Math.abs(det) > MIN_DETERMINANT)) return null;
  // Inverse of the column-major 3×3 [a d g; b e h; c f i].
  const inv = [
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
  const [tx, ty, tz] = [t[9], t[10], t[11]];
  const ix = -(inv[0] * tx + inv[3] * ty + inv[6] * tz);
  const iy = -(inv[1] * tx + inv[4] * ty + inv[7] * tz);
  const iz = -(inv[2] * tx + inv[5] * ty + inv[8] * tz);
  const toLocal = new Float32Array([inv[0], inv[1], inv[2], 0, inv[3], inv[4], inv[5], 0, inv[6], inv[7], inv[8], 0, ix, iy, iz, 1]);
  if (!toLocal.every(Number.isFinite)) return null;
  return { toLocal, normalToLocal: new Float32Array([a, d, g, b, e, h, c, f, i]) };
}

/// What a frame draws.
export interface DrawOptions {
  mode: number;
  state: ViewerState | null;
  grids: GridTextures | null;
  /// G-buffer samples per canvas pixel and axis (odd; default 1).
  scale?: number;
  /// Scene time (seconds) at which skinned instances are posed and suns turned (default 0).
  time?: number;
  /// Shadow-map samples per texel and axis (odd; default 1), as `scale` for the G-buffer.
  shadowScale?: number;
}

type Program = ReturnType<typeof program>;

/// World bounds of an instance's mesh vertices at one transform.
interface InstanceBounds {
  key: string;
  lo: [number, number, number];
  hi: [number, number, number];
}

/// A G-buffer: world position + instance, shading normal + colour index, relit values
/// (RGBA32F each) and depth, `scale` times the canvas size.
class GBufferTargets {
  fbo: WebGLFramebuffer;
  position: WebGLTexture | null = null;
  normal: WebGLTexture | null = null;
  relit: WebGLTexture | null = null;
  depth: WebGLRenderbuffer | null = null;
  width = 0;
  height = 0;

  constructor(private gl: WebGL2RenderingContext) {
    this.fbo = gl.createFramebuffer()!;
  }

  resize(width: number, height: number) {
    if (width === this.width && height === this.height) return;
    const gl = this.gl;
    this.width = width;
    this.height = height;
    for (const t of [this.position, this.normal, this.relit]) if (t) gl.deleteTexture(t);
    if (this.depth) gl.deleteRenderbuffer(this.depth);
    const target = () => {
      const t = gl.createTexture()!;
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, width, height);
      return t;
    };
    this.position = target();
    this.normal = target();
    this.relit = target();
    this.depth = gl.createRenderbuffer()!;
    gl.bindRenderbuffer(gl.RENDERBUFFER, this.depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, width, height);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, this.position, 0);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT1, gl.TEXTURE_2D, this.normal, 0);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT2, gl.TEXTURE_2D, this.relit, 0);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, this.depth);
    gl.drawBuffers([gl.COLOR_ATTACHMENT0, gl.COLOR_ATTACHMENT1, gl.COLOR_ATTACHMENT2]);
    const status = gl.checkFramebufferStatus(gl.FRAMEBUFFER);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    if (status !== gl.FRAMEBUFFER_COMPLETE) throw new Error(`G-buffer framebuffer incomplete (${status})`);
  }
}

function program(gl: WebGL2RenderingContext, vertex: string, fragment: string) {
  const p = gl.createProgram()!;
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, vertex));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fragment));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
  const u: Record<string, WebGLUniformLocation | null> = {};
  const count = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS) as number;
  for (let i = 0; i < count; i++) {
    const name = gl.getActiveUniform(p, i)!.name;
    u[name] = gl.getUniformLocation(p, name);
  }
  return { p, u };
}

function dataTexture(gl: WebGL2RenderingContext): WebGLTexture {
  const t = gl.createTexture()!;
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  return t;
}

/// Texels per instance row of the float and integer instance textures.
const INST_F = 9;
const INST_U = 3;

/// The scene uploaded to the GPU, drawn deferred: the G-buffer pass rasterizes every
/// instance (at `scale` × the canvas size), the full-screen pass reconstructs AO and
/// composites each canvas pixel from its centre sample.
export class SceneRenderer {
  private gbuffer: Program;
  private shade: Program;
  private depth: Program;
  private shadows: ShadowMaps;
  /// Vertex positions of each mesh (all primitives), for the posed scene's bounds.
  private meshPositions: Float32Array[][] = [];
  /// Per mesh, per primitive: its joints and renormalised weights when skinned (for the
  /// skinned instances' bounds), else null.
  private meshSkins: ({ joints: Uint16Array; weights: Float32Array } | null)[][] = [];
  /// The joint texels of the frame drawn last (skinned instances' bounds), or null.
  private lastJointTexels: Float32Array | null = null;
  private boundsCache: (InstanceBounds | null)[] = [];
  private targets: GBufferTargets;
  private meshes: Primitive[][] = [];
  private instances: { mesh: number; matrix: Float32Array }[] = [];
  private normals: WebGLTexture;
  private colours: WebGLTexture;
  private instF: WebGLTexture;
  private instU: WebGLTexture;
  private emptyU: WebGLTexture;
  private joints: WebGLTexture;
  /// The scene's animation (skinned instances), when anything is skinned.
  animation: Animation | null = null;
  /// The scene's camera paths (from the glb's extras).
  paths: CameraPathDoc[] = [];
  /// The scene's suns and point lights (from the glb's extras).
  lights: SceneLights = new SceneLights(undefined);
  /// Milliseconds of the last frame's shadow maps (0 when none were drawn).
  shadowMs = 0;
  /// The served relit characters, once loaded (`relit.ts`).
  relit: RelitCharacters | null = null;
  /// Why relighting stopped, when a frame's relighting failed.
  relitError: string | null = null;
  /// Per relit instance: the vertex buffer of its values.
  private relitBuffers = new Map<number, WebGLBuffer>();
  /// What relit characters are built from: the glb's document, its accessors, the instances.
  source: { doc: GltfDoc; read: AccessorReader; instances: number } | null = null;

  constructor(
    private gl: WebGL2RenderingContext,
    glb: Uint8Array,
  ) {
    if (!gl.getExtension("EXT_color_buffer_float")) throw new Error("WebGL2 without EXT_color_buffer_float");
    this.gbuffer = program(gl, VERTEX, GBUFFER);
    this.shade = program(gl, FULLSCREEN, FRAGMENT);
    this.depth = program(gl, VERTEX, SHADOW_FRAGMENT);
    this.shadows = new ShadowMaps(gl);
    this.targets = new GBufferTargets(gl);
    this.normals = dataTexture(gl);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, 256, 1, 0, gl.RGBA, gl.FLOAT, normalTable());
    this.instF = dataTexture(gl);
    this.instU = dataTexture(gl);
    this.emptyU = dataTexture(gl);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32UI, 1, 1, 0, gl.RGBA_INTEGER, gl.UNSIGNED_INT, new Uint32Array(4));
    this.joints = dataTexture(gl);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, 1, 1, 0, gl.RGBA, gl.FLOAT, new Float32Array(4));
    // Unskinned primitives leave the joints attribute disabled: its generic value must be
    // unsigned like the shader's input, or WebGL refuses the draw.
    gl.vertexAttribI4ui(2, 0, 0, 0, 0);
    // Instances that are not relit leave the relit attribute disabled: nothing shadowed.
    gl.vertexAttrib4f(4, 1, 1, 1, 1);
    const colours = this.load(glb);
    this.colours = dataTexture(gl);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, Math.max(1, colours.length / 4), 1, 0, gl.RGBA, gl.FLOAT, colours.length ? colours : new Float32Array(4));
  }

  /// Uploads the meshes; returns the primitives' base colours (RGBA per colour index).
  private load(glb: Uint8Array): Float32Array {
    const gl = this.gl;
    const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
    const jsonLen = view.getUint32(12, true);
    const doc: GltfDoc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
    this.paths = doc.extras?.psao_camera_paths ?? [];
    this.lights = new SceneLights(doc.extras?.psao_lights);
    const binAt = 20 + jsonLen + 8;
    const bin = glb.subarray(binAt, binAt + view.getUint32(20 + jsonLen, true));
    const data = (index: number): { bytes: Uint8Array; count: number } => {
      const a = doc.accessors![index];
      const bv = doc.bufferViews![a.bufferView!];
      const width = { SCALAR: 1, VEC3: 3, VEC4: 4 }[a.type as "SCALAR" | "VEC3" | "VEC4"] ?? 1;
      const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
      return { bytes: bin.subarray(start, start + a.count * width * 4), count: a.count };
    };
    const instanceCount = (doc.nodes ?? []).findIndex((n) => n.mesh === undefined || !n.matrix);
    const instances = instanceCount < 0 ? (doc.nodes ?? []).length : instanceCount;
    const read = (i: number) => readAccessor(doc, bin, i);
    this.source = { doc, read, instances };
    const animation = new Animation(doc, instances, read);
    this.animation = animation.skinned ? animation : null;
    const colours: number[] = [];
    for (const mesh of doc.meshes ?? []) {
      const prims: Primitive[] = [];
      const positions: Float32Array[] = [];
      const skins: ({ joints: Uint16Array; weights: Float32Array } | null)[] = [];
      this.meshPositions.push(positions);
      this.meshSkins.push(skins);
      for (const prim of mesh.primitives) {
        if (prim.attributes.POSITION === undefined || prim.attributes.NORMAL === undefined || prim.indices === undefined) continue;
        positions.push(readAccessor(doc, bin, prim.attributes.POSITION) as Float32Array);
        const vao = gl.createVertexArray()!;
        gl.bindVertexArray(vao);
        for (const [loc, acc] of [
          [0, prim.attributes.POSITION],
          [1, prim.attributes.NORMAL],
        ]) {
          const buf = gl.createBuffer();
          gl.bindBuffer(gl.ARRAY_BUFFER, buf);
          gl.bufferData(gl.ARRAY_BUFFER, data(acc).bytes, gl.STATIC_DRAW);
          gl.enableVertexAttribArray(loc);
          gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
        }
        const { JOINTS_0: joints, WEIGHTS_0: weights } = prim.attributes;
        const skin = joints !== undefined && weights !== undefined;
        skins.push(null);
        if (skin) {
          const jointData = Uint16Array.from(readAccessor(doc, bin, joints));
          const weightData = renormalisedWeights(readAccessor(doc, bin, weights));
          skins[skins.length - 1] = { joints: jointData, weights: weightData };
          const jbuf = gl.createBuffer();
          gl.bindBuffer(gl.ARRAY_BUFFER, jbuf);
          gl.bufferData(gl.ARRAY_BUFFER, jointData, gl.STATIC_DRAW);
          gl.enableVertexAttribArray(2);
          gl.vertexAttribIPointer(2, 4, gl.UNSIGNED_SHORT, 0, 0);
          const wbuf = gl.createBuffer();
          gl.bindBuffer(gl.ARRAY_BUFFER, wbuf);
          gl.bufferData(gl.ARRAY_BUFFER, weightData, gl.STATIC_DRAW);
          gl.enableVertexAttribArray(3);
          gl.vertexAttribPointer(3, 4, gl.FLOAT, false, 0, 0);
        }
        const idx = data(prim.indices);
        const ibo = gl.createBuffer();
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ibo);
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx.bytes, gl.STATIC_DRAW);
        gl.bindVertexArray(null);
        const c = doc.materials?.[prim.material ?? 0]?.pbrMetallicRoughness?.baseColorFactor ?? [0.8, 0.8, 0.8, 1];
        prims.push({ vao, count: idx.count, colour: colours.length / 4, skin });
        colours.push(c[0], c[1], c[2], 1);
      }
      this.meshes.push(prims);
    }
    for (const node of doc.nodes ?? []) {
      if (node.mesh === undefined || !node.matrix) break;
      this.instances.push({ mesh: node.mesh, matrix: new Float32Array(node.matrix) });
    }
    return new Float32Array(colours);
  }

  /// Draws the scene from `camera` in `opts.mode`; instance i is drawn at
  /// `state.transforms[i]` when set (else its rest matrix), and its AO reconstructed from
  /// its grid when the state has its transform (as psao-client). The G-buffer is `scale`
  /// times the canvas size (1 by default; odd scales put a sample on every pixel centre).
  draw(camera: Camera, opts: DrawOptions) {
    const gl = this.gl;
    const grids = opts.grids && !opts.grids.problem ? opts.grids : null;
    const state = opts.state;
    const scale = Math.max(1, Math.floor(opts.scale ?? 1));
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    this.targets.resize(w * scale, h * scale);

    // G-buffer pass.
    const g = this.gbuffer.u;
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.targets.fbo);
    gl.viewport(0, 0, w * scale, h * scale);
    gl.clearBufferfv(gl.COLOR, 0, [0, 0, 0, -1]);
    gl.clearBufferfv(gl.COLOR, 1, [0, 0, 0, 0]);
    gl.clearBufferfv(gl.COLOR, 2, [1, 1, 1, 1]);
    gl.clearBufferfi(gl.DEPTH_STENCIL, 0, 1, 0);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LESS);
    gl.useProgram(this.gbuffer.p);
    const animation = this.animation;
    // The joint matrices at the scene time (a float texture stays bound for the sampler
    // also without skinned instances).
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.joints);
    if (animation) {
      const texels = animation.jointTexels(opts.time ?? 0);
      this.lastJointTexels = texels;
      const rows = Math.ceil(texels.length / 4 / TEX_WIDTH);
      const padded = new Float32Array(rows * TEX_WIDTH * 4);
      padded.set(texels);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, TEX_WIDTH, rows, 0, gl.RGBA, gl.FLOAT, padded);
    }
    gl.uniform3fv(g.u_eye, camera.position);
    if (this.relit) {
      try {
        this.relight(camera, state, opts.time ?? 0);
      } catch (e) {
        // Relighting refused the frame: the characters are drawn unrelit from now on.
        this.relitError = `relit characters: ${e instanceof Error ? e.message : e}`;
        this.relit.free();
        this.relit = null;
        this.relitBuffers.forEach((b) => gl.deleteBuffer(b));
        this.relitBuffers.clear();
      }
    }
    gl.useProgram(this.gbuffer.p);
    this.drawInstances(this.gbuffer, viewProj(camera), state);
    const instF = new Float32Array(this.instances.length * INST_F * 4);
    const instU = new Uint32Array(this.instances.length * INST_U * 4);
    for (let i = 0; i < this.instances.length; i++) {
      this.instanceRow(i, state?.transforms[i] ?? null, state, grids, instF, instU);
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.disable(gl.DEPTH_TEST);

    // Shadow maps, when the session is lit and the view shows direct light.
    const lit = state?.hasLights() ?? false;
    const needsDirect = lit && opts.mode !== MODE_AO && opts.mode !== MODE_IRRADIANCE;
    this.shadowMs = 0;
    if (needsDirect) {
      const t0 = performance.now();
      const time = opts.time ?? 0;
      const mapCamera: MapCamera = { ...camera };
      this.shadows.render(this.depth, (prog, vp) => this.drawInstances(prog, vp, state), viewProj, {
        suns: this.lights.sunsAt(time),
        points: this.lights.points,
        camera: mapCamera,
        aspect: w / Math.max(h, 1),
        bounds: this.posedBounds(state),
        settings: settingsForImage(w, h),
        scale: opts.shadowScale ?? 1,
      });
      this.shadowMs = performance.now() - t0;
    }

    // Full-screen pass.
    const u = this.shade.u;
    gl.viewport(0, 0, w, h);
    gl.useProgram(this.shade.p);
    const rows = Math.max(1, this.instances.length);
    gl.bindTexture(gl.TEXTURE_2D, this.instF);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, INST_F, rows, 0, gl.RGBA, gl.FLOAT, instF.length ? instF : new Float32Array(INST_F * 4));
    gl.bindTexture(gl.TEXTURE_2D, this.instU);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32UI, INST_U, rows, 0, gl.RGBA_INTEGER, gl.UNSIGNED_INT, instU.length ? instU : new Uint32Array(INST_U * 4));
    const textures: [string, WebGLTexture | null][] = [
      ["u_directory", grids?.directory.texture ?? this.emptyU],
      ["u_entries", grids?.entries.texture ?? this.emptyU],
      ["u_page_table", grids?.pageTable.texture ?? this.emptyU],
      ["u_cells", grids?.cells.texture ?? this.emptyU],
      ["u_normals", this.normals],
      ["u_gposition", this.targets.position],
      ["u_gnormal", this.targets.normal],
      ["u_grelit", this.targets.relit],
      ["u_colours", this.colours],
      ["u_instf", this.instF],
      ["u_instu", this.instU],
      ["u_lights", (lit ? grids?.lights.texture : null) ?? this.emptyU],
      ["u_map_table", this.shadows.table],
    ];
    textures.forEach(([name, t], unit) => {
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.uniform1i(u[name], unit);
    });
    const arrays: [string, WebGLTexture | null][] = [
      ["u_sun_maps", this.shadows.suns.texture],
      ["u_point_maps", this.shadows.points.texture],
    ];
    arrays.forEach(([name, t], k) => {
      gl.activeTexture(gl.TEXTURE0 + textures.length + k);
      gl.bindTexture(gl.TEXTURE_2D_ARRAY, t);
      gl.uniform1i(u[name], textures.length + k);
    });
    gl.uniform1i(u.u_lit, lit ? 1 : 0);
    this.shadows.setUniforms(u);
    gl.activeTexture(gl.TEXTURE0);
    gl.uniform1i(u.u_mode, opts.mode);
    gl.uniform1i(u.u_scale, scale);
    gl.uniform3f(u.u_sky, ...(SKY_GREY.map((c) => encodeSrgb(c) / 255) as [number, number, number]));
    const l = [0.35, 1.0, 0.6];
    const ll = Math.hypot(l[0], l[1], l[2]);
    gl.uniform3f(u.u_light_dir, l[0] / ll, l[1] / ll, l[2] / ll);
    gl.uniform1f(u.u_light, SETTINGS.light);
    gl.uniform1f(u.u_ambient, SETTINGS.ambient);
    gl.uniform1f(u.u_factor, SETTINGS.factor);
    gl.uniform1f(u.u_plane_tolerance, SETTINGS.planeTolerance);
    gl.uniform1f(u.u_normal_threshold, SETTINGS.normalThreshold);
    gl.uniform1f(u.u_direction_threshold, SETTINGS.directionThreshold);
    gl.uniform1i(u.u_exponent, SETTINGS.exponent);
    gl.uniform1i(u.u_fallback, SETTINGS.fallback ? 1 : 0);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }

  /// Draws every instance with `prog` (the G-buffer's vertex shader) from `vp`: at the
  /// transform of the state's last update carrying one, else its rest matrix, skinned with
  /// the joint texture bound to unit 0.
  private drawInstances(prog: Program, vp: Float32Array, state: ViewerState | null) {
    const gl = this.gl;
    const g = prog.u;
    gl.useProgram(prog.p);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.joints);
    gl.uniform1i(g.u_joints, 0);
    gl.uniformMatrix4fv(g.u_view_proj, false, vp);
    const animation = this.animation;
    const model = new Float32Array(16);
    for (const [i, inst] of this.instances.entries()) {
      model.set(this.modelOf(i, state));
      gl.uniformMatrix4fv(g.u_model, false, model);
      gl.uniformMatrix3fv(g.u_normal_matrix, false, normalMatrixOf(model));
      gl.uniform1f(g.u_instance, i);
      const jointBase = animation ? animation.jointBase[i] : -1;
      const relit = this.relitBuffers.get(i);
      for (const p of this.meshes[inst.mesh] ?? []) {
        gl.uniform1f(g.u_colour_index, p.colour);
        gl.uniform1i(g.u_joint_base, p.skin ? jointBase : -1);
        gl.bindVertexArray(p.vao);
        if (relit) {
          gl.bindBuffer(gl.ARRAY_BUFFER, relit);
          gl.enableVertexAttribArray(4);
          gl.vertexAttribPointer(4, 4, gl.FLOAT, false, 0, 0);
        } else {
          gl.disableVertexAttribArray(4);
        }
        gl.drawElements(gl.TRIANGLES, p.count, gl.UNSIGNED_INT, 0);
      }
    }
    gl.bindVertexArray(null);
  }

  /// Relights the served characters at scene time `time` (their instances at the transforms
  /// drawn) and uploads each relit instance's values.
  private relight(camera: Camera, state: ViewerState | null, time: number) {
    const gl = this.gl;
    const relit = this.relit!;
    const transforms = this.instances.map((_, i) => state?.transforms[i] ?? null);
    relit.frame(time, transforms, camera.position);
    for (let i = 0; i < this.instances.length; i++) {
      const values = relit.values(i);
      if (!values) continue;
      let buf = this.relitBuffers.get(i);
      if (!buf) {
        buf = gl.createBuffer()!;
        this.relitBuffers.set(i, buf);
      }
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, values, gl.DYNAMIC_DRAW);
    }
  }

  /// Instance i's model matrix (column-major 4×4): the state's transform, else its rest matrix.
  private modelOf(i: number, state: ViewerState | null): Float32Array {
    const t = state?.transforms[i] ?? null;
    if (!t) return this.instances[i].matrix;
    return new Float32Array([t[0], t[1], t[2], 0, t[3], t[4], t[5], 0, t[6], t[7], t[8], 0, t[9], t[10], t[11], 1]);
  }

  /// World bounds of every instance's mesh vertices at the drawn transforms, as psao-raster's
  /// shadow maps take them (skinned instances: their vertices skinned with the joint
  /// matrices of the frame, as the vertex shader skins them); null without vertices. Each
  /// unskinned instance's bounds are kept until its transform changes.
  private posedBounds(state: ViewerState | null): [[number, number, number], [number, number, number]] | null {
    const lo: [number, number, number] = [Infinity, Infinity, Infinity];
    const hi: [number, number, number] = [-Infinity, -Infinity, -Infinity];
    for (const [i, inst] of this.instances.entries()) {
      const m = this.modelOf(i, state);
      const jointBase = this.animation?.jointBase[i] ?? -1;
      const texels = jointBase >= 0 ? this.lastJointTexels : null;
      const key = m.join(",");
      let b = this.boundsCache[i];
      if (!b || b.key !== key || texels) {
        b = { key, lo: [Infinity, Infinity, Infinity], hi: [-Infinity, -Infinity, -Infinity] };
        for (const [k, rest] of (this.meshPositions[inst.mesh] ?? []).entries()) {
          const skin = texels ? (this.meshSkins[inst.mesh]?.[k] ?? null) : null;
          const positions = texels && skin ? skinned(rest, skin, texels, jointBase) : rest;
          for (let v = 0; v + 3 <= positions.length; v += 3) {
            const [x, y, z] = [positions[v], positions[v + 1], positions[v + 2]];
            for (let r = 0; r < 3; r++) {
              const w = Math.fround(m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r]);
              if (!Number.isFinite(w)) continue;
              b.lo[r] = Math.min(b.lo[r], w);
              b.hi[r] = Math.max(b.hi[r], w);
            }
          }
        }
        this.boundsCache[i] = b;
      }
      for (let r = 0; r < 3; r++) {
        lo[r] = Math.min(lo[r], b.lo[r]);
        hi[r] = Math.max(hi[r], b.hi[r]);
      }
    }
    return lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2] ? [lo, hi] : null;
  }

  /// Instance i's row of the instance textures: its view and grid layout.
  private instanceRow(
    i: number,
    t: Float32Array | null,
    state: ViewerState | null,
    grids: GridTextures | null,
    f: Float32Array,
    u: Uint32Array,
  ) {
    const slot = grids?.slots[i] ?? null;
    const view = t && state && slot ? instanceView(t) : null;
    if (!view || !state || !slot) return; // has_view stays 0
    const e = state.table[i];
    const fo = i * INST_F * 4;
    f.set(view.toLocal, fo);
    const n = view.normalToLocal;
    f.set([n[0], n[1], n[2], 0, n[3], n[4], n[5], 0, n[6], n[7], n[8], 0], fo + 16);
    f.set([e.origin[0], e.origin[1], e.origin[2], e.cellSize, Math.fround(1 / e.cellSize), e.layoutPoissonRadius, 1, 0], fo + 28);
    const row = BigInt(e.dims[0]) * 17n;
    const slice = BigInt(e.dims[0]) * BigInt(e.dims[1]) * 31n;
    u.set(
      [
        e.dims[0], e.dims[1], e.dims[2], e.bucketCount - 1,
        slot.bucketBase, slot.cellPageBase, slot.maxCells, state.slotCount(i) > 0 ? 1 : 0,
        Number(row & 0xffffffffn), Number(row >> 32n), Number(slice & 0xffffffffn), Number(slice >> 32n),
      ],
      i * INST_U * 4,
    );
  }
}

/// Mesh-local positions skinned with the joint matrices in `texels` (`JOINT_TEXELS` RGBA
/// texels per joint from `base`: the matrix's columns first) and the renormalised weights,
/// as the G-buffer's vertex shader (and psao-scene's skinning) blend them.
function skinned(
  positions: Float32Array,
  skin: { joints: Uint16Array; weights: Float32Array },
  texels: Float32Array,
  base: number,
): Float32Array {
  const out = new Float32Array(positions.length);
  for (let v = 0; 3 * v + 3 <= positions.length; v++) {
    const [x, y, z] = [positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]];
    for (let k = 0; k < 4; k++) {
      const w = skin.weights[4 * v + k];
      if (!(w > 0)) continue;
      const at = (base + skin.joints[4 * v + k]) * JOINT_TEXELS * 4;
      if (at + 16 > texels.length) continue;
      for (let r = 0; r < 3; r++) {
        out[3 * v + r] += w * (texels[at + r] * x + texels[at + 4 + r] * y + texels[at + 8 + r] * z + texels[at + 12 + r]);
      }
    }
  }
  return out;
}

/// The inverse transpose of a column-major mat4's linear part (psao-raster's normal matrix).
function normalMatrixOf(m: Float32Array): number[] {
  const [a, b, c] = [m[0], m[1], m[2]];
  const [d, e, f] = [m[4], m[5], m[6]];
  const [g, h, i] = [m[8], m[9], m[10]];
  const det = a * (e * i - f * h) - d * (b * i - c * h) + g * (b * f - c * e) || 1;
  // Cofactor matrix / det = inverse transpose, column-major.
  return [
    (e * i - f * h) / det,
    (f * g - d * i) / det,
    (d * h - e * g) / det,
    (c * h - b * i) / det,
    (a * i - c * g) / det,
    (b * g - a * h) / det,
    (b * f - c * e) / det,
    (c * d - a * f) / det,
    (a * e - b * d) / det,
  ];
}

/// Perspective (OpenGL clip space) × look-at of `c` (aspect 1 when it has none), column-major.
function viewProj(c: MapCamera & { aspect?: number }): Float32Array {
  const [px, py, pz] = c.position;
  let fx = c.target[0] - px;
  let fy = c.target[1] - py;
  let fz = c.target[2] - pz;
  const fl = Math.hypot(fx, fy, fz) || 1;
  fx /= fl;
  fy /= fl;
  fz /= fl;
  let sx = fy * c.up[2] - fz * c.up[1];
  let sy = fz * c.up[0] - fx * c.up[2];
  let sz = fx * c.up[1] - fy * c.up[0];
  const sl = Math.hypot(sx, sy, sz) || 1;
  sx /= sl;
  sy /= sl;
  sz /= sl;
  const ux = sy * fz - sz * fy;
  const uy = sz * fx - sx * fz;
  const uz = sx * fy - sy * fx;
  const view = [
    sx, ux, -fx, 0,
    sy, uy, -fy, 0,
    sz, uz, -fz, 0,
    -(sx * px + sy * py + sz * pz), -(ux * px + uy * py + uz * pz), fx * px + fy * py + fz * pz, 1,
  ];
  const f = 1 / Math.tan(c.fovY / 2);
  const { near: n, far: fr } = c;
  const proj = [f / (c.aspect ?? 1), 0, 0, 0, 0, f, 0, 0, 0, 0, (fr + n) / (n - fr), -1, 0, 0, (2 * fr * n) / (n - fr), 0];
  const out = new Float32Array(16);
  for (let col = 0; col < 4; col++) {
    for (let row = 0; row < 4; row++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += proj[k * 4 + row] * view[col * 4 + k];
      out[col * 4 + row] = s;
    }
  }
  return out;
}
