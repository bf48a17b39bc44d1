// The viewer's shaders. The fragment shader reconstructs AO per pixel from the grids in GPU
// textures (`grids.ts`) with the math of psao-client (crates/psao-client/src/gather.rs,
// psao-points' `reconstruct_ao`): the pixel's world position and camera-facing shading
// normal go into the instance's local space, the 2×2×2 block of cells whose centres surround
// it is looked up in the hash buckets (64-bit cell ids, Eq. 1), and every valid point that
// passes the normal, tangent-plane and direction tests and lies within r = Poisson radius ×
// interpolation factor is weighted by (r − d)/r · (n·nᵢ)^k. Without any weight, the AO of the
// nearest compatible point of the block, else of the ring of cells around it, else 1.
// In a lit session (the server sends irradiance records, `psao serve --lighting gi`) the same
// points and weights interpolate the points' irradiance (psao-client's `reconstruct_lit_into`:
// Σ w·Eᵢ / Σ w, the fallback point's record; a pixel without any compatible point, or on an
// instance without view or cells, takes psao-client's fill (crates/psao-client/src/fill.rs:
// the ((1 + n·nⱼ)/2)⁸-weighted mean irradiance of the pixels at distances 1, 2, 4, …, 128 in
// eight directions that found points in their own block, stopping after the first ring whose
// weight reaches 1; else 0), the shadow maps add the direct light of
// the suns and point lights (`shadow.ts`), and the pixel is psao-client's `composite_lit`:
// base colour / π × (direct + irradiance). Without records it composites as psao-client's
// `composite`: base colour × (ambient × AO + light × max(0, n·l)). Both sRGB-encoded. The
// other views show one term of the composite (irradiance: the points' part, ambient × AO
// without records; direct: the shadow-mapped part, the unshadowed light without records),
// AO only, the composite without AO, or the cost (cells and points visited) as exact
// integers in the red, green and blue bytes.

import { CELL_PAGE, NO_PAGE, TEX_WIDTH } from "./grids";
import { SHADOW_GLSL } from "./shadow";
import { JOINT_TEXELS } from "./skin";

/// Output modes (`u_mode`); keys 1–4 select the first four.
export const MODE_COMPOSITED = 0;
export const MODE_IRRADIANCE = 1;
export const MODE_DIRECT = 2;
export const MODE_AO = 3;
export const MODE_NO_AO = 4;
export const MODE_COST = 5;

/// The G-buffer pass: world position and instance, camera-facing shading normal and
/// material colour index, per pixel of a framebuffer `scale` times the canvas size.
export const VERTEX = `#version 300 es
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in uvec4 joints;
layout(location = 3) in vec4 weights; // renormalised as psao-scene's BindMesh
// Relit characters' values per vertex (self-shadowing per channel, self-visibility; relit.ts),
// (1, 1, 1, 1) elsewhere.
layout(location = 4) in vec4 relit;
uniform mat4 u_view_proj;
uniform mat4 u_model;
uniform mat3 u_normal_matrix;
// Skinned instances: their first joint in u_joints (JOINT_TEXELS RGBA32F texels per joint:
// the joint matrix's columns, then its normal matrix's), or -1.
uniform int u_joint_base;
uniform highp sampler2D u_joints;
out vec3 v_world;
out vec3 v_normal;
out vec4 v_relit;
invariant gl_Position;

vec4 joint_texel(int i) { return texelFetch(u_joints, ivec2(i % ${TEX_WIDTH}, i / ${TEX_WIDTH}), 0); }

void main() {
  vec3 p = position;
  vec3 n = normal;
  if (u_joint_base >= 0) {
    // Linear blend skinning in mesh-local space (psao-scene's BindMesh::skin).
    vec3 sp = vec3(0.0);
    vec3 sn = vec3(0.0);
    for (int k = 0; k < 4; k++) {
      float w = weights[k];
      if (w > 0.0) {
        int at = (u_joint_base + int(joints[k])) * ${JOINT_TEXELS};
        mat4 m = mat4(joint_texel(at), joint_texel(at + 1), joint_texel(at + 2), joint_texel(at + 3));
        mat3 nm = mat3(joint_texel(at + 4).xyz, joint_texel(at + 5).xyz, joint_texel(at + 6).xyz);
        sp += w * (m * vec4(p, 1.0)).xyz;
        sn += w * (nm * n);
      }
    }
    p = sp;
    float l = length(sn);
    n = l > 0.0 ? sn / l : n;
  }
  vec4 world = u_model * vec4(p, 1.0);
  v_normal = u_normal_matrix * n;
  v_world = world.xyz;
  v_relit = relit;
  gl_Position = u_view_proj * world;
}`;

export const GBUFFER = `#version 300 es
precision highp float;
in vec3 v_world;
in vec3 v_normal;
in vec4 v_relit;
uniform vec3 u_eye;
uniform float u_instance;
uniform float u_colour_index;
layout(location = 0) out vec4 out_position;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_relit;

void main() {
  // The face normal turned towards the eye, and the shading normal in its hemisphere
  // (psao-raster's resolve).
  vec3 g = cross(dFdx(v_world), dFdy(v_world));
  float glen = length(g);
  vec3 to_eye = u_eye - v_world;
  g = glen > 0.0 ? g / glen : normalize(to_eye);
  if (dot(g, to_eye) < 0.0) g = -g;
  float sl = length(v_normal);
  vec3 n = sl > 0.0 ? v_normal / sl : g;
  if (dot(n, g) < 0.0) n = -n;
  out_position = vec4(v_world, u_instance);
  out_normal = vec4(n, u_colour_index);
  out_relit = v_relit;
}`;

/// The full-screen pass: a triangle over the canvas.
export const FULLSCREEN = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;

export const FRAGMENT = `#version 300 es
precision highp float;
precision highp int;
precision highp usampler2D;
out vec4 out_colour;

uniform int u_mode;
uniform int u_scale;
uniform highp sampler2D u_gposition;
uniform highp sampler2D u_gnormal;
// Relit characters' interpolated values (1 elsewhere): self-shadowing o, self-visibility a.
uniform highp sampler2D u_grelit;
uniform highp sampler2D u_colours; // base colour by index
uniform vec3 u_sky;
uniform vec3 u_light_dir;
uniform float u_light;
uniform float u_ambient;
// A lit session: irradiance records beside the cells, direct light from the shadow maps.
uniform bool u_lit;
uniform usampler2D u_lights; // RGB9E5 records, laid out as u_cells
${SHADOW_GLSL}

// Per instance (one row each, see grids.ts' instanceRows): its view (has_view false: AO 1,
// as psao-client without a grid or an invertible transform) and grid layout.
uniform highp sampler2D u_instf;
uniform usampler2D u_instu;
bool u_has_view;
bool u_has_cells; // false: the grid holds no cell yet (every lookup would miss: AO 1)
mat4 u_to_local;
mat3 u_normal_to_local;
vec3 u_origin;
float u_cell;
float u_inv_cell;
ivec3 u_dims;
float u_poisson;
uint u_bucket_mask;
uint u_bucket_base;
uint u_cell_page_base;
uint u_cell_capacity;
uvec2 u_row;   // Dx·17 as (low, high) 32-bit halves
uvec2 u_slice; // Dx·Dy·31
uniform usampler2D u_directory;  // per bucket: used entries | first pool texel << 4
uniform usampler2D u_entries;    // (key low, key high, slot, 0) per used entry
uniform usampler2D u_page_table; // per page of cell slots: its page in u_cells, or NO_PAGE
uniform usampler2D u_cells;
uniform highp sampler2D u_normals; // the 256 decoded normal codes

// Reconstruction settings (psao-client's ReconstructSettings, psao-points' thresholds).
uniform float u_factor;
uniform float u_plane_tolerance;
uniform float u_normal_threshold;
uniform float u_direction_threshold;
uniform int u_exponent;
uniform bool u_fallback;

const uint WIDTH = ${TEX_WIDTH}u;
const uint CELL_PAGE = ${CELL_PAGE}u;
const uint NO_PAGE = ${NO_PAGE}u;

ivec2 at(uint i) { return ivec2(int(i % WIDTH), int(i / WIDTH)); }

// The 64-bit product of two 32-bit words, from 16-bit limbs, as (low, high).
uvec2 mul32(uint a, uint b) {
  uint a0 = a & 0xFFFFu, a1 = a >> 16, b0 = b & 0xFFFFu, b1 = b >> 16;
  uint p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
  uint mid = (p00 >> 16) + (p01 & 0xFFFFu) + (p10 & 0xFFFFu);
  return uvec2((mid << 16) | (p00 & 0xFFFFu), p11 + (p01 >> 16) + (p10 >> 16) + (mid >> 16));
}
uvec2 add64(uvec2 a, uvec2 b) {
  uint lo = a.x + b.x;
  return uvec2(lo, a.y + b.y + (lo < a.x ? 1u : 0u));
}
uvec2 mul64(uint s, uvec2 v) { return add64(mul32(s, v.x), uvec2(0u, s * v.y)); }

// Per pixel: the shaded point and the running sums.
vec3 P, N;
float R, R2, INV_R, PLANE;
float w_sum, ao_sum, nearest_d2, nearest_ao;
vec3 e_sum, nearest_e, E;
int cells_visited, points_visited;

// The slot of allocated cell c (InstanceGrid::find_cell), or -1.
int find_cell(ivec3 c) {
  if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, u_dims))) return -1;
  uvec3 u = uvec3(c);
  uvec2 id = add64(add64(uvec2(u.x, 0u), mul64(u.y, u_row)), mul64(u.z, u_slice));
  uvec2 key = add64(id, uvec2(1u, 0u));
  uint dir = texelFetch(u_directory, at(u_bucket_base + (id.x & u_bucket_mask)), 0).x;
  uint first = dir >> 4;
  uint count = dir & 15u;
  for (uint e = 0u; e < count; e++) {
    uvec4 t = texelFetch(u_entries, at(first + e), 0);
    if (t.x == key.x && t.y == key.y) return t.z < u_cell_capacity ? int(t.z) : -1;
  }
  return -1;
}

float pow_k(float x) {
  float y = 1.0;
  for (int i = 0; i < u_exponent; i++) y *= x;
  return y;
}

// psao-points' RGB9E5 record: three 9-bit mantissas and a 5-bit exponent (bias 15).
vec3 rgb9e5(uint r) {
  // 2^(exponent − 15 − 9), built from its bits (exact; GLSL ES 3.0 has no ldexp).
  float step = uintBitsToFloat(((r >> 27) + 103u) << 23);
  return vec3(float(r & 511u), float((r >> 9) & 511u), float((r >> 18) & 511u)) * step;
}

// One packed point of cell c with its irradiance record: the block pass weights it and
// tracks the nearest compatible point; the ring pass only tracks the nearest.
void point(uint bits, uint record, vec3 cell_min, bool weigh) {
  if ((bits & 0x80000000u) == 0u) return;
  points_visited++;
  vec3 frac = (vec3((uvec3(bits >> 26, bits >> 21, bits >> 16)) & 31u) + 0.5) * (1.0 / 32.0);
  vec3 delta = (u_origin + (cell_min + frac) * u_cell) - P;
  vec3 ni = texelFetch(u_normals, ivec2(int((bits >> 8) & 255u), 0), 0).xyz;
  float d2 = dot(delta, delta);
  float c = dot(ni, delta) / sqrt(d2);
  float nn = dot(ni, N);
  bool compatible = nn > u_normal_threshold && abs(dot(N, delta)) <= PLANE &&
                    (d2 == 0.0 || c * c < u_direction_threshold);
  if (!compatible) return;
  float ao = float(bits & 255u) * (1.0 / 255.0);
  vec3 e = u_lit ? rgb9e5(record) : vec3(0.0);
  if (weigh && d2 < R2) {
    float w = (R - sqrt(d2)) * INV_R * pow_k(nn);
    w_sum += w;
    ao_sum += w * ao;
    e_sum += w * e;
  }
  if (d2 < nearest_d2) {
    nearest_d2 = d2;
    nearest_ao = ao;
    nearest_e = e;
  }
}

void cell(ivec3 c, bool weigh) {
  int slot = find_cell(c);
  if (slot < 0) return;
  cells_visited++;
  uint page = texelFetch(u_page_table, at(u_cell_page_base + uint(slot) / CELL_PAGE), 0).x;
  if (page == NO_PAGE) return;
  uint t = 2u * (page * CELL_PAGE + uint(slot) % CELL_PAGE);
  uvec4 a = texelFetch(u_cells, at(t), 0);
  uvec4 b = texelFetch(u_cells, at(t + 1u), 0);
  uvec4 la = u_lit ? texelFetch(u_lights, at(t), 0) : uvec4(0u);
  uvec4 lb = u_lit ? texelFetch(u_lights, at(t + 1u), 0) : uvec4(0u);
  vec3 m = vec3(c);
  point(a.x, la.x, m, weigh); point(a.y, la.y, m, weigh); point(a.z, la.z, m, weigh);
  point(a.w, la.w, m, weigh); point(b.x, lb.x, m, weigh); point(b.y, lb.y, m, weigh);
  point(b.z, lb.z, m, weigh);
}

void load_instance(int i) {
  vec4 f[9];
  for (int k = 0; k < 9; k++) f[k] = texelFetch(u_instf, ivec2(k, i), 0);
  u_to_local = mat4(f[0], f[1], f[2], f[3]);
  u_normal_to_local = mat3(f[4].xyz, f[5].xyz, f[6].xyz);
  u_origin = f[7].xyz;
  u_cell = f[7].w;
  u_inv_cell = f[8].x;
  u_poisson = f[8].y;
  u_has_view = f[8].z > 0.5;
  uvec4 a = texelFetch(u_instu, ivec2(0, i), 0);
  uvec4 b = texelFetch(u_instu, ivec2(1, i), 0);
  uvec4 c = texelFetch(u_instu, ivec2(2, i), 0);
  u_dims = ivec3(a.xyz);
  u_bucket_mask = a.w;
  u_bucket_base = b.x;
  u_cell_page_base = b.y;
  u_cell_capacity = b.z;
  u_has_cells = b.w != 0u;
  u_row = c.xy;
  u_slice = c.zw;
}

// The block pass of the loaded instance at a world position and normal: the sums over the
// 2×2×2 block of cells around it and its nearest compatible point. Returns the block's base
// cell, or false in ok when the instance has no view or cells or a degenerate radius.
ivec3 block_pass(vec3 world, vec3 normal, out bool ok) {
  ok = false;
  // Without cells psao-client finds no point in the block nor in the ring: AO 1, decided
  // here without the 64 lookups (which made every frame cost the most before any points).
  if (!u_has_view || !u_has_cells) return ivec3(0);
  P = (u_to_local * vec4(world, 1.0)).xyz;
  vec3 n = u_normal_to_local * normal;
  float l = length(n);
  N = l > 0.0 ? n / l : vec3(0.0);
  R = u_poisson * u_factor;
  if (!(R > 0.0)) return ivec3(0);
  R2 = R * R;
  INV_R = 1.0 / R;
  PLANE = u_plane_tolerance * u_poisson;
  w_sum = 0.0;
  ao_sum = 0.0;
  nearest_d2 = 3.4e38;
  nearest_ao = -1.0;
  e_sum = vec3(0.0);
  nearest_e = vec3(0.0);
  ivec3 base = ivec3(floor((P - u_origin) * u_inv_cell - 0.5));
  for (int k = 0; k < 8; k++) cell(base + ivec3(k & 1, (k >> 1) & 1, k >> 2), true);
  ok = true;
  return base;
}

// Whether the last reconstruct() found no compatible point (psao-client's Found::Nothing).
bool FOUND_NOTHING;

// AO at the pixel; the irradiance goes into E (0 where there is no compatible point).
float reconstruct(vec3 world, vec3 normal) {
  E = vec3(0.0);
  FOUND_NOTHING = true;
  bool ok;
  ivec3 base = block_pass(world, normal, ok);
  if (!ok) return 1.0;
  if (w_sum > 0.0) {
    E = e_sum / w_sum;
    FOUND_NOTHING = false;
    return ao_sum / w_sum;
  }
  if (!u_fallback) return 1.0;
  if (nearest_ao >= 0.0) {
    E = nearest_e;
    FOUND_NOTHING = false;
    return nearest_ao;
  }
  for (int k = 0; k < 64; k++) {
    ivec3 o = ivec3(k & 3, (k >> 2) & 3, k >> 4) - 1;
    if (all(greaterThanEqual(o, ivec3(0))) && all(lessThanEqual(o, ivec3(1)))) continue;
    cell(base + o, false);
  }
  if (nearest_ao < 0.0) return 1.0;
  E = nearest_e;
  FOUND_NOTHING = false;
  return nearest_ao;
}

// A fill donor (psao-client's fill.rs): the canvas pixel q's irradiance when its
// reconstruction finds points in its own block (the kernel or the block's nearest point),
// with its normal; false otherwise (uncovered, no view or cells, nothing in the block).
bool donor(ivec2 q, out vec3 nq, out vec3 e) {
  nq = vec3(0.0);
  e = vec3(0.0);
  ivec2 at_g = q * u_scale + u_scale / 2;
  vec4 gp = texelFetch(u_gposition, at_g, 0);
  if (gp.w < 0.0) return false;
  nq = texelFetch(u_gnormal, at_g, 0).xyz;
  load_instance(int(gp.w));
  bool ok;
  block_pass(gp.xyz, nq, ok);
  if (!ok) return false;
  if (w_sum > 0.0) {
    e = e_sum / w_sum;
    return true;
  }
  if (u_fallback && nearest_ao >= 0.0) {
    e = nearest_e;
    return true;
  }
  return false;
}

const ivec2 FILL_DIRECTIONS[8] = ivec2[8](ivec2(1, 0), ivec2(1, 1), ivec2(0, 1), ivec2(-1, 1),
                                          ivec2(-1, 0), ivec2(-1, -1), ivec2(0, -1), ivec2(1, -1));

// psao-client's fill for canvas pixel px with normal n: the donors of the rings at 1, 2, 4, …,
// 128 pixels weighted ((1 + n·nⱼ)/2)⁸, stopping after the first ring whose weight reaches 1.
vec3 fill(ivec2 px, vec3 n) {
  ivec2 size = textureSize(u_gposition, 0) / u_scale;
  float ws = 0.0;
  vec3 es = vec3(0.0);
  for (int r = 0; r < 8; r++) {
    int d = 1 << r;
    for (int k = 0; k < 8; k++) {
      ivec2 q = px + FILL_DIRECTIONS[k] * d;
      if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
      vec3 nq, e;
      if (!donor(q, nq, e)) continue;
      float s = max(0.0, 0.5 * (1.0 + dot(n, nq)));
      float s2 = s * s;
      float s4 = s2 * s2;
      float w = s4 * s4;
      ws += w;
      es += w * e;
    }
    if (ws >= 1.0) break;
  }
  return ws > 0.0 ? es / ws : vec3(0.0);
}

float srgb(float linear) {
  float c = clamp(linear, 0.0, 1.0);
  return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

void main() {
  // This pixel's centre sample of the (scaled) G-buffer.
  ivec2 at_g = ivec2(gl_FragCoord.xy) * u_scale + u_scale / 2;
  vec4 gp = texelFetch(u_gposition, at_g, 0);
  vec4 gn = texelFetch(u_gnormal, at_g, 0);
  cells_visited = 0;
  points_visited = 0;
  if (gp.w < 0.0) {
    // Nothing covers the pixel: AO 1, no cost, the sky.
    out_colour = u_mode == ${MODE_AO} ? vec4(1.0) : u_mode == ${MODE_COST} ? vec4(0.0) : vec4(u_sky, 1.0);
    return;
  }
  vec3 n = gn.xyz;
  load_instance(int(gp.w));
  // The direct view of a lit session needs no points.
  bool points = u_mode != ${MODE_NO_AO} && !(u_lit && u_mode == ${MODE_DIRECT});
  E = vec3(0.0);
  float ao = points ? reconstruct(gp.xyz, n) : 1.0;
  // Irradiance for a pixel without a compatible point (it replaces black), where shown.
  bool shows_e = u_mode == ${MODE_COMPOSITED} || u_mode == ${MODE_IRRADIANCE};
  if (points && u_lit && shows_e && FOUND_NOTHING) E = fill(ivec2(gl_FragCoord.xy), n);
  if (u_mode == ${MODE_AO}) {
    out_colour = vec4(vec3(ao), 1.0);
  } else if (u_mode == ${MODE_COST}) {
    out_colour = vec4(float(cells_visited), float(points_visited & 255), float(points_visited >> 8), 255.0) / 255.0;
  } else {
    vec3 colour = texelFetch(u_colours, ivec2(int(gn.w), 0), 0).rgb;
    // A relit character's pixel: its AO or irradiance from the points times psao-prt's
    // pixel_factor o / max(AO, a) (1 off relit characters, where o = a = 1).
    vec4 relit = texelFetch(u_grelit, at_g, 0);
    vec3 m = relit.rgb / max(max(ao, relit.a), 1e-3);
    vec3 rgb;
    if (u_lit) {
      // psao-client's composite_lit: base colour / π × (direct + irradiance).
      vec3 direct = u_mode == ${MODE_IRRADIANCE} ? vec3(0.0) : direct_light(gp.xyz, n);
      E *= m;
      vec3 e = u_mode == ${MODE_DIRECT} ? direct : u_mode == ${MODE_IRRADIANCE} ? E : direct + E;
      rgb = colour * e / 3.14159265358979;
    } else {
      vec3 ambient = u_mode == ${MODE_DIRECT} ? vec3(0.0) : u_ambient * ao * m;
      float light = u_mode == ${MODE_IRRADIANCE} ? 0.0 : u_light * max(0.0, dot(n, u_light_dir));
      rgb = colour * (ambient + light);
    }
    out_colour = vec4(srgb(rgb.r), srgb(rgb.g), srgb(rgb.b), 1.0);
  }
}`;
