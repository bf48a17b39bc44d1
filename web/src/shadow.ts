// Shadow maps of the suns and point lights in WebGL2, laid out and looked up as
// psao-raster's `ShadowMaps` (crates/psao-raster/src/shadow.rs) does on the CPU, so that the
// browser's direct light agrees with `psao view`'s:
//
// * per sun `cascades` maps, each fitted to the bounding sphere of one slice of the view
//   frustum (split 90 % logarithmically, 10 % uniformly, from the camera's near distance to
//   the farthest point of the posed scene's bounds; the scene's sphere when that is smaller),
//   rendered as a perspective view from 256 scene reaches away along the sun;
// * per point light six 90° faces (+x −x +y −y +z −z), widened by the filter's reach;
// * every map stores the view depth (along the map camera's axis) of the nearest surface per
//   texel, rendered with the G-buffer's vertex shader (skinning included) into an R32F layer;
// * a lookup (`SHADOW_GLSL`) moves the point off its surface by the filter's reach times the
//   sine of the light's angle, compares against the (2·pcf + 1)² texels around it with a bias
//   of one texel, and counts taps outside the map as lit; a sun uses its first cascade that
//   holds all taps.
//
// Sizes follow `ShadowSettings::for_image`: sun cascades of the image's larger side (256 to
// 2048 texels), point faces of half of it (64 to 512), 3 cascades, 3×3 taps. `scale` renders
// each map at scale× and reads the texel centre's sample, as `?scale=` does for the G-buffer
// (SwiftShader's 4-bit sub-pixel snapping otherwise moves shadow edges against the CPU's).

import type { PointLight, Sun } from "./lights";
import { MAX_POINT_LIGHTS, MAX_SUNS } from "./lights";

type V3 = [number, number, number];

/// A camera of a map (what psao-scene's `Camera` holds).
export interface MapCamera {
  position: V3;
  target: V3;
  up: V3;
  fovY: number;
  near: number;
  far: number;
}

/// Resolutions and filter of the maps.
export interface ShadowSettings {
  sunResolution: number;
  cascades: number;
  pointResolution: number;
  pcf: number;
}

/// psao-raster's `ShadowSettings::for_image`.
export function settingsForImage(width: number, height: number): ShadowSettings {
  const side = Math.max(width, height);
  const clamp = (v: number, lo: number, hi: number) => Math.min(Math.max(v, lo), hi);
  return { sunResolution: clamp(side, 256, 2048), cascades: 3, pointResolution: clamp(Math.floor(side / 2), 64, 512), pcf: 1 };
}

/// Distance of a sun's map camera, in scene reaches; the logarithmic share of the splits.
const SUN_DISTANCE = 256;
const LOG_SPLIT = 0.9;

const sub = (a: V3, b: V3): V3 => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a: V3, b: V3): V3 => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const mul = (a: V3, s: number): V3 => [a[0] * s, a[1] * s, a[2] * s];
const len = (a: V3) => Math.hypot(a[0], a[1], a[2]);
const cross = (a: V3, b: V3): V3 => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
function normalizeOrZero(a: V3): V3 {
  const l = len(a);
  return l > 0 && Number.isFinite(l) ? mul(a, 1 / l) : [0, 0, 0];
}

type Sphere = { centre: V3; radius: number };

/// A box's bounding sphere, radius at least a millimetre.
function boxSphere(lo: V3, hi: V3): Sphere {
  return { centre: mul(add(lo, hi), 0.5), radius: Math.max(len(sub(hi, lo)) * 0.5, 1e-3) };
}

/// psao-raster's `cascade_spheres`.
export function cascadeSpheres(camera: MapCamera, aspect: number, lo: V3, hi: V3, count: number): Sphere[] {
  const scene = boxSphere(lo, hi);
  const forward = normalizeOrZero(sub(camera.target, camera.position));
  const right = normalizeOrZero(cross(forward, camera.up));
  const up = cross(right, forward);
  const near = Math.max(camera.near, 1e-3);
  const reach = len(sub(scene.centre, camera.position)) + scene.radius;
  const far = Math.max(Math.min(camera.far, reach), near * 1.001);
  const tanY = Math.tan(camera.fovY * 0.5);
  const tanX = tanY * aspect;
  if (len(right) === 0 || !Number.isFinite(tanX) || !Number.isFinite(tanY)) return [scene];
  const split = (k: number) => {
    const f = k / count;
    return (1 - LOG_SPLIT) * (near + (far - near) * f) + LOG_SPLIT * near * Math.pow(far / near, f);
  };
  const out: Sphere[] = [];
  for (let k = 0; k < count; k++) {
    const corners: V3[] = [];
    for (const d of [split(k), split(k + 1)]) {
      for (const [sx, sy] of [[-1, -1], [1, -1], [-1, 1], [1, 1]]) {
        corners.push(add(camera.position, mul(add(forward, add(mul(right, sx * tanX), mul(up, sy * tanY))), d)));
      }
    }
    const centre = mul(corners.reduce(add, [0, 0, 0] as V3), 1 / corners.length);
    const radius = Math.max(0, ...corners.map((c) => len(sub(c, centre))));
    out.push(radius < scene.radius ? { centre, radius } : scene);
  }
  return out;
}

/// psao-raster's `sun_camera`: far along `direction`, just wide enough for the sphere.
export function sunCamera(direction: V3, s: Sphere, lo: V3, hi: V3): MapCamera {
  const scene = boxSphere(lo, hi);
  const reach = Math.max(len(sub(scene.centre, s.centre)) + scene.radius, s.radius);
  const distance = SUN_DISTANCE * reach;
  return {
    position: add(s.centre, mul(direction, distance)),
    target: s.centre,
    up: Math.abs(direction[1]) < 0.9 ? [0, 1, 0] : [1, 0, 0],
    fovY: 2 * Math.asin(s.radius / distance),
    near: distance - 1.01 * reach,
    far: distance + 1.01 * reach,
  };
}

/// psao-raster's `face_cameras`: the six faces of a point light, widened by `pcf + 1` texels.
export function faceCameras(position: V3, lo: V3, hi: V3, res: number, pcf: number): MapCamera[] {
  const scene = boxSphere(lo, hi);
  const far = (len(sub(scene.centre, position)) + scene.radius) * 1.01;
  const near = Math.max(far * 1e-5, 1e-4);
  const fovY = 2 * Math.atan(1 + (2 * (pcf + 1)) / res);
  const face = (axis: V3, up: V3): MapCamera => ({ position, target: add(position, axis), up, fovY, near, far });
  return [
    face([1, 0, 0], [0, 1, 0]),
    face([-1, 0, 0], [0, 1, 0]),
    face([0, 1, 0], [0, 0, 1]),
    face([0, -1, 0], [0, 0, 1]),
    face([0, 0, 1], [0, 1, 0]),
    face([0, 0, -1], [0, 1, 0]),
  ];
}

/// Texels per map in the map table (view-projection columns, origin + texel size per unit
/// depth, forward + resolution).
const MAP_TEXELS = 6;

/// Draws the posed scene into the bound framebuffer with a program whose vertex shader is
/// the G-buffer's, from the view-projection given.
export type DrawScene = (program: { p: WebGLProgram; u: Record<string, WebGLUniformLocation | null> }, viewProj: Float32Array) => void;

/// One R32F array texture of square layers with its depth buffer.
class MapArray {
  texture: WebGLTexture | null = null;
  depth: WebGLRenderbuffer | null = null;
  size = 0;
  layers = 0;

  constructor(private gl: WebGL2RenderingContext) {}

  ensure(size: number, layers: number) {
    if (size === this.size && layers <= this.layers) return;
    const gl = this.gl;
    if (this.texture) gl.deleteTexture(this.texture);
    if (this.depth) gl.deleteRenderbuffer(this.depth);
    this.size = size;
    this.layers = Math.max(layers, 1);
    this.texture = gl.createTexture()!;
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, this.texture);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texStorage3D(gl.TEXTURE_2D_ARRAY, 1, gl.R32F, size, size, this.layers);
    this.depth = gl.createRenderbuffer()!;
    gl.bindRenderbuffer(gl.RENDERBUFFER, this.depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, size, size);
  }
}

/// The maps of one frame on the GPU and what the lookup needs.
export class ShadowMaps {
  readonly suns: MapArray;
  readonly points: MapArray;
  /// Per map (suns' cascades first, then point faces): MAP_TEXELS RGBA32F texels.
  readonly table: WebGLTexture;
  private fbo: WebGLFramebuffer;
  /// The lights drawn this frame.
  sunLights: Sun[] = [];
  pointLights: PointLight[] = [];
  settings: ShadowSettings = settingsForImage(1, 1);
  /// Maps rendered at scale× (odd), the lookup reading each texel's centre sample.
  scale = 1;

  constructor(private gl: WebGL2RenderingContext) {
    this.suns = new MapArray(gl);
    this.points = new MapArray(gl);
    this.table = gl.createTexture()!;
    gl.bindTexture(gl.TEXTURE_2D, this.table);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, MAP_TEXELS, 1, 0, gl.RGBA, gl.FLOAT, new Float32Array(MAP_TEXELS * 4));
    this.fbo = gl.createFramebuffer()!;
  }

  /// Renders the maps of `suns` and `points` for the scene within bounds (`lo`, `hi`), the
  /// cascades fitted to `camera` at `aspect`; `viewProj` makes a map camera's matrix and
  /// `draw` draws the scene with the depth program.
  render(
    program: { p: WebGLProgram; u: Record<string, WebGLUniformLocation | null> },
    draw: DrawScene,
    viewProj: (c: MapCamera) => Float32Array,
    frame: { suns: Sun[]; points: PointLight[]; camera: MapCamera; aspect: number; bounds: [V3, V3] | null; settings: ShadowSettings; scale: number },
  ) {
    const gl = this.gl;
    const { settings, bounds } = frame;
    this.settings = settings;
    this.scale = Math.max(1, Math.floor(frame.scale) | 1);
    this.sunLights = bounds ? frame.suns.filter((s) => len(s.direction) > 0).slice(0, MAX_SUNS) : [];
    this.pointLights = bounds ? frame.points.slice(0, MAX_POINT_LIGHTS) : [];
    if (!bounds) return;
    const [lo, hi] = bounds;
    const maps: { camera: MapCamera; res: number; array: MapArray; layer: number }[] = [];
    this.sunLights.forEach((s, i) => {
      cascadeSpheres(frame.camera, frame.aspect, lo, hi, settings.cascades).forEach((sphere, k) => {
        maps.push({ camera: sunCamera(s.direction, sphere, lo, hi), res: settings.sunResolution, array: this.suns, layer: i * settings.cascades + k });
      });
    });
    this.pointLights.forEach((p, i) => {
      faceCameras(p.position, lo, hi, settings.pointResolution, settings.pcf).forEach((camera, f) => {
        maps.push({ camera, res: settings.pointResolution, array: this.points, layer: i * 6 + f });
      });
    });
    this.suns.ensure(settings.sunResolution * this.scale, this.sunLights.length * settings.cascades);
    this.points.ensure(settings.pointResolution * this.scale, this.pointLights.length * 6);
    const table = new Float32Array(Math.max(maps.length, 1) * MAP_TEXELS * 4);
    gl.useProgram(program.p);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.fbo);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LESS);
    maps.forEach((m, i) => {
      const vp = viewProj(m.camera);
      const forward = normalizeOrZero(sub(m.camera.target, m.camera.position));
      table.set(vp, i * MAP_TEXELS * 4);
      table.set([...m.camera.position, (2 * Math.tan(m.camera.fovY * 0.5)) / m.res, ...forward, m.res], i * MAP_TEXELS * 4 + 16);
      const size = m.res * this.scale;
      gl.framebufferTextureLayer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, m.array.texture, 0, m.layer);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, m.array.depth);
      gl.drawBuffers([gl.COLOR_ATTACHMENT0]);
      gl.viewport(0, 0, size, size);
      gl.clearBufferfv(gl.COLOR, 0, [3e38, 0, 0, 0]);
      gl.clearBufferfi(gl.DEPTH_STENCIL, 0, 1, 0);
      gl.uniform3fv(program.u.u_origin, m.camera.position);
      gl.uniform3fv(program.u.u_forward, forward);
      draw(program, vp);
    });
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.disable(gl.DEPTH_TEST);
    gl.bindTexture(gl.TEXTURE_2D, this.table);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, MAP_TEXELS, Math.max(maps.length, 1), 0, gl.RGBA, gl.FLOAT, table);
  }

  /// The lookup's uniforms, set on the bound lit program.
  setUniforms(u: Record<string, WebGLUniformLocation | null>) {
    const gl = this.gl;
    const flat = (vs: V3[], n: number) => {
      const a = new Float32Array(n * 3);
      vs.forEach((v, i) => a.set(v, i * 3));
      return a;
    };
    gl.uniform1i(u.u_sun_count, this.sunLights.length);
    gl.uniform3fv(u["u_sun_dir[0]"], flat(this.sunLights.map((s) => s.direction), MAX_SUNS));
    gl.uniform3fv(u["u_sun_irr[0]"], flat(this.sunLights.map((s) => s.irradiance), MAX_SUNS));
    gl.uniform1i(u.u_point_count, this.pointLights.length);
    gl.uniform3fv(u["u_point_pos[0]"], flat(this.pointLights.map((p) => p.position), MAX_POINT_LIGHTS));
    gl.uniform3fv(u["u_point_int[0]"], flat(this.pointLights.map((p) => p.intensity), MAX_POINT_LIGHTS));
    gl.uniform1i(u.u_cascades, this.settings.cascades);
    gl.uniform1i(u.u_pcf, this.settings.pcf);
    gl.uniform1i(u.u_shadow_scale, this.scale);
  }
}

/// The depth pass's fragment shader: view depth along the map camera's axis.
export const SHADOW_FRAGMENT = `#version 300 es
precision highp float;
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_origin;
uniform vec3 u_forward;
layout(location = 0) out float out_depth;
void main() {
  out_depth = dot(v_world - u_origin, u_forward);
}`;

/// The lookup (psao-raster's `ShadowMaps::direct`), for the full-screen pass.
export const SHADOW_GLSL = `
uniform highp sampler2DArray u_sun_maps;
uniform highp sampler2DArray u_point_maps;
uniform highp sampler2D u_map_table;
uniform int u_sun_count;
uniform vec3 u_sun_dir[${MAX_SUNS}];
uniform vec3 u_sun_irr[${MAX_SUNS}];
uniform int u_point_count;
uniform vec3 u_point_pos[${MAX_POINT_LIGHTS}];
uniform vec3 u_point_int[${MAX_POINT_LIGHTS}];
uniform int u_cascades;
uniform int u_pcf;
uniform int u_shadow_scale;

struct ShadowMap { mat4 vp; vec3 origin; float texel_per_depth; vec3 forward; float res; };

ShadowMap map_of(int m) {
  ShadowMap s;
  s.vp = mat4(texelFetch(u_map_table, ivec2(0, m), 0), texelFetch(u_map_table, ivec2(1, m), 0),
              texelFetch(u_map_table, ivec2(2, m), 0), texelFetch(u_map_table, ivec2(3, m), 0));
  vec4 a = texelFetch(u_map_table, ivec2(4, m), 0);
  vec4 b = texelFetch(u_map_table, ivec2(5, m), 0);
  s.origin = a.xyz;
  s.texel_per_depth = a.w;
  s.forward = b.xyz;
  s.res = b.w;
  return s;
}

// Continuous texel coordinates from the top-left corner, or false behind the view.
bool project(ShadowMap s, vec3 p, out vec2 uv) {
  vec4 clip = s.vp * vec4(p, 1.0);
  if (!(clip.w > 0.0)) return false;
  uv = vec2(clip.x / clip.w * 0.5 + 0.5, 0.5 - clip.y / clip.w * 0.5) * s.res;
  return true;
}

bool covers(ShadowMap s, vec3 p) {
  vec2 uv;
  float reach = float(u_pcf) + 1.0;
  return project(s, p, uv) && uv.x >= reach && uv.y >= reach && uv.x < s.res - reach && uv.y < s.res - reach;
}

float map_depth(bool sun, int layer, int x, int y, int res) {
  ivec3 at = ivec3(x * u_shadow_scale + u_shadow_scale / 2, (res - 1 - y) * u_shadow_scale + u_shadow_scale / 2, layer);
  return sun ? texelFetch(u_sun_maps, at, 0).x : texelFetch(u_point_maps, at, 0).x;
}

float visibility(ShadowMap s, bool sun, int layer, vec3 p, vec3 n, vec3 l) {
  vec2 uv;
  if (!project(s, p, uv)) return 1.0;
  float texel = dot(p - s.origin, s.forward) * s.texel_per_depth;
  float c = clamp(dot(n, l), 0.0, 1.0);
  float sn = sqrt(1.0 - c * c);
  vec3 moved = p + n * (texel * (float(u_pcf) + 1.5) * sn);
  if (!project(s, moved, uv)) return 1.0;
  float z = dot(moved - s.origin, s.forward);
  float bias = texel;
  int cx = int(floor(uv.x));
  int cy = int(floor(uv.y));
  int res = int(s.res);
  int lit = 0;
  for (int y = cy - u_pcf; y <= cy + u_pcf; y++) {
    for (int x = cx - u_pcf; x <= cx + u_pcf; x++) {
      bool inside = x >= 0 && x < res && y >= 0 && y < res;
      if (!inside || z - bias <= map_depth(sun, layer, x, y, res)) lit++;
    }
  }
  int side = 2 * u_pcf + 1;
  return float(lit) / float(side * side);
}

int face_of(vec3 d) {
  vec3 a = abs(d);
  if (a.x >= a.y && a.x >= a.z) return d.x < 0.0 ? 1 : 0;
  if (a.y >= a.z) return d.y < 0.0 ? 3 : 2;
  return d.z < 0.0 ? 5 : 4;
}

vec3 direct_light(vec3 p, vec3 n) {
  vec3 e = vec3(0.0);
  for (int i = 0; i < u_sun_count; i++) {
    vec3 d = u_sun_dir[i];
    float c = dot(n, d);
    if (c <= 0.0) continue;
    float vis = 1.0;
    for (int k = 0; k < u_cascades; k++) {
      ShadowMap s = map_of(i * u_cascades + k);
      if (covers(s, p)) {
        vis = visibility(s, true, i * u_cascades + k, p, n, d);
        break;
      }
    }
    e += u_sun_irr[i] * (c * vis);
  }
  for (int i = 0; i < u_point_count; i++) {
    vec3 d = u_point_pos[i] - p;
    float dist2 = dot(d, d);
    if (!(dist2 > 0.0)) continue;
    vec3 l = d / sqrt(dist2);
    float c = dot(n, l);
    if (c <= 0.0) continue;
    int face = i * 6 + face_of(-d);
    float vis = visibility(map_of(u_sun_count * u_cascades + face), false, face, p, n, l);
    e += u_point_int[i] * (c * vis / dist2);
  }
  return e;
}
`;
