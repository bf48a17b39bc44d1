// WebGL2 rasterization of `/scene.glb`: every instance node (node i = instance i of the
// instance table) with its mesh, at the transform of the last update that carried one (its
// rest matrix until then), shaded by its material's base colour and a fixed head light. This
// is the no-AO view; skinning and the per-pixel AO reconstruction are not here yet.

import type { Camera } from "./wire";

interface Primitive {
  vao: WebGLVertexArrayObject;
  count: number;
  colour: [number, number, number];
}

interface GltfDoc {
  nodes?: { mesh?: number; matrix?: number[] }[];
  meshes?: { primitives: { attributes: { POSITION?: number; NORMAL?: number }; indices?: number; material?: number }[] }[];
  materials?: { pbrMetallicRoughness?: { baseColorFactor?: number[] } }[];
  accessors?: { bufferView?: number; byteOffset?: number; count: number; componentType: number; type: string }[];
  bufferViews?: { byteOffset?: number; byteLength: number }[];
}

const VERTEX = `#version 300 es
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
uniform mat4 view_proj;
uniform mat4 model;
out vec3 world_normal;
void main() {
  world_normal = mat3(model) * normal;
  gl_Position = view_proj * model * vec4(position, 1.0);
}`;

const FRAGMENT = `#version 300 es
precision highp float;
in vec3 world_normal;
uniform vec3 colour;
uniform vec3 light;
out vec4 out_colour;
void main() {
  float d = abs(dot(normalize(world_normal), light));
  out_colour = vec4(pow(colour * (0.25 + 0.75 * d), vec3(1.0 / 2.2)), 1.0);
}`;

function compile(gl: WebGL2RenderingContext, type: number, source: string): WebGLShader {
  const s = gl.createShader(type)!;
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
  return s;
}

/// The scene uploaded to the GPU.
export class SceneRenderer {
  private program: WebGLProgram;
  private meshes: Primitive[][] = [];
  private instances: { mesh: number; matrix: Float32Array }[] = [];
  private uViewProj: WebGLUniformLocation;
  private uModel: WebGLUniformLocation;
  private uColour: WebGLUniformLocation;
  private uLight: WebGLUniformLocation;

  constructor(
    private gl: WebGL2RenderingContext,
    glb: Uint8Array,
  ) {
    const p = gl.createProgram()!;
    gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, VERTEX));
    gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
    this.program = p;
    this.uViewProj = gl.getUniformLocation(p, "view_proj")!;
    this.uModel = gl.getUniformLocation(p, "model")!;
    this.uColour = gl.getUniformLocation(p, "colour")!;
    this.uLight = gl.getUniformLocation(p, "light")!;
    this.load(glb);
  }

  private load(glb: Uint8Array) {
    const gl = this.gl;
    const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
    const jsonLen = view.getUint32(12, true);
    const doc: GltfDoc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
    const binAt = 20 + jsonLen + 8;
    const bin = glb.subarray(binAt, binAt + view.getUint32(20 + jsonLen, true));
    const data = (index: number): { bytes: Uint8Array; count: number } => {
      const a = doc.accessors![index];
      const bv = doc.bufferViews![a.bufferView!];
      const width = { SCALAR: 1, VEC3: 3, VEC4: 4 }[a.type as "SCALAR" | "VEC3" | "VEC4"] ?? 1;
      const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
      return { bytes: bin.subarray(start, start + a.count * width * 4), count: a.count };
    };
    for (const mesh of doc.meshes ?? []) {
      const prims: Primitive[] = [];
      for (const prim of mesh.primitives) {
        if (prim.attributes.POSITION === undefined || prim.attributes.NORMAL === undefined || prim.indices === undefined) continue;
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
        const idx = data(prim.indices);
        const ibo = gl.createBuffer();
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ibo);
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx.bytes, gl.STATIC_DRAW);
        gl.bindVertexArray(null);
        const c = doc.materials?.[prim.material ?? 0]?.pbrMetallicRoughness?.baseColorFactor ?? [0.8, 0.8, 0.8, 1];
        prims.push({ vao, count: idx.count, colour: [c[0], c[1], c[2]] });
      }
      this.meshes.push(prims);
    }
    for (const node of doc.nodes ?? []) {
      if (node.mesh === undefined || !node.matrix) break;
      this.instances.push({ mesh: node.mesh, matrix: new Float32Array(node.matrix) });
    }
  }

  /// Draws the scene from `camera`; `transforms[i]`, when set, is instance i's Affine3A from
  /// the last update (12 floats: matrix columns, then translation).
  draw(camera: Camera, transforms: (Float32Array | null)[]) {
    const gl = this.gl;
    gl.viewport(0, 0, gl.drawingBufferWidth, gl.drawingBufferHeight);
    gl.clearColor(0.07, 0.07, 0.07, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(this.program);
    gl.uniformMatrix4fv(this.uViewProj, false, viewProj(camera));
    const [px, py, pz] = camera.position;
    const [tx, ty, tz] = camera.target;
    const l = Math.hypot(tx - px, ty - py, tz - pz) || 1;
    gl.uniform3f(this.uLight, (tx - px) / l, (ty - py) / l, (tz - pz) / l);
    const model = new Float32Array(16);
    for (const [i, inst] of this.instances.entries()) {
      const t = transforms[i];
      if (t) {
        model.set([t[0], t[1], t[2], 0, t[3], t[4], t[5], 0, t[6], t[7], t[8], 0, t[9], t[10], t[11], 1]);
      } else {
        model.set(inst.matrix);
      }
      gl.uniformMatrix4fv(this.uModel, false, model);
      for (const p of this.meshes[inst.mesh] ?? []) {
        gl.uniform3f(this.uColour, p.colour[0], p.colour[1], p.colour[2]);
        gl.bindVertexArray(p.vao);
        gl.drawElements(gl.TRIANGLES, p.count, gl.UNSIGNED_INT, 0);
      }
    }
    gl.bindVertexArray(null);
  }
}

/// Perspective (OpenGL clip space) × look-at of `c`, column-major.
function viewProj(c: Camera): Float32Array {
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
  const proj = [f / c.aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (fr + n) / (n - fr), -1, 0, 0, (2 * fr * n) / (n - fr), 0];
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
