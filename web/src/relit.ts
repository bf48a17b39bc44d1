// Relit characters (docs/RELIGHTING.md, "Served characters"): `psao serve --relight` serves
// each skinned character's relighting model at `/characters/N.prt` and the scene's lighting
// as SH in `/characters/index.json` (both behind the token, as `/scene.glb`). The page hands
// `/scene.glb`'s nodes, meshes, skins, instances and playing clips to the wasm
// (crates/psao-wasm/src/relit_abi.rs), which rebuilds the scene, poses it with psao-scene's
// `Animator` and relights every character with psao-prt's served relighter, as `psao view`
// does. Per frame it gives, per relit instance, four numbers per mesh vertex: self-shadowing
// per colour channel and self-visibility; the renderer uploads them as a vertex attribute and
// the full-screen pass multiplies the pixel's AO (or irradiance) by psao-prt's
// `pixel_factor`, o / max(AO, a).
import type { Codec } from "./codec";
import type { AccessorReader, AnimationDoc } from "./skin";

/// The module's relit exports (pointers and lengths are numbers).
interface RelitExports {
  memory: WebAssembly.Memory;
  psao_alloc(len: number): number;
  psao_free(ptr: number, len: number): void;
  psao_relit_new(): number;
  psao_relit_free(h: number): void;
  psao_relit_node(h: number, parent: number, trs: number): void;
  psao_relit_mesh(h: number, vertices: number, positions: number, normals: number, indices: number, indicesLen: number, joints: number, weights: number): number;
  psao_relit_skin(h: number, count: number, joints: number, inverseBind: number): number;
  psao_relit_instance(h: number, mesh: number, node: number, skin: number, matrix: number): void;
  psao_relit_channel(h: number, clip: number, node: number, property: number, interpolation: number, times: number, timesLen: number, values: number, valuesLen: number): number;
  psao_relit_play(h: number, clip: number): number;
  psao_relit_finish(h: number): number;
  psao_relit_count(h: number): number;
  psao_relit_vertices(h: number): number;
  psao_relit_character(h: number, index: number, model: number, modelLen: number, lighting: number, lightingLen: number): number;
  psao_relit_frame(h: number, time: number, count: number, transforms: number, given: number, ex: number, ey: number, ez: number): number;
  psao_relit_values_ptr(h: number, instance: number): number;
  psao_relit_values_len(h: number, instance: number): number;
  psao_relit_error_ptr(h: number): number;
  psao_relit_error_len(h: number): number;
}

/// `/characters/index.json`.
export interface RelitIndex {
  count: number;
  lighting: number[];
}

/// The parts of `/scene.glb` the relit scene is built from.
export type RelitDoc = AnimationDoc & {
  meshes?: { primitives: { attributes: { POSITION?: number; NORMAL?: number; JOINTS_0?: number; WEIGHTS_0?: number }; indices?: number }[] }[];
};

const PROPERTIES: Record<string, number> = { translation: 0, rotation: 1, scale: 2 };
const INTERPOLATIONS: Record<string, number> = { STEP: 0, LINEAR: 1, CUBICSPLINE: 2 };

function bytesOf(a: ArrayBufferView): Uint8Array {
  return new Uint8Array(a.buffer, a.byteOffset, a.byteLength);
}

/// The served characters of one scene, relit in wasm.
export class RelitCharacters {
  private handle: number;
  private x: RelitExports;
  /// Milliseconds the last frame's relighting took in wasm (posing, synthesis, shading).
  ms = 0;
  /// Vertices relit per frame.
  vertices = 0;

  /// The scene of `doc` (its first `instances` nodes are the instance table's) with the
  /// served `models` (`/characters/N.prt`, in order) under `index.lighting`; throws with the
  /// Rust error's text when the scene or a model is refused.
  constructor(
    codec: Codec,
    doc: RelitDoc,
    read: AccessorReader,
    instances: number,
    index: RelitIndex,
    models: Uint8Array[],
  ) {
    this.x = codec.exports as unknown as RelitExports;
    this.handle = this.x.psao_relit_new();
    try {
      this.build(doc, read, instances);
      this.check(this.x.psao_relit_finish(this.handle));
      const count = this.x.psao_relit_count(this.handle);
      if (count !== models.length) throw new Error(`the server relights ${models.length} characters, the scene has ${count}`);
      const lighting = bytesOf(Float32Array.from(index.lighting));
      models.forEach((m, i) =>
        this.withBytes([m, lighting], ([mp, lp]) =>
          this.check(this.x.psao_relit_character(this.handle, i, mp, m.length, lp, lighting.length)),
        ),
      );
      this.vertices = this.x.psao_relit_vertices(this.handle);
    } catch (e) {
      this.free();
      throw e;
    }
  }

  private build(doc: RelitDoc, read: AccessorReader, instances: number) {
    const x = this.x;
    const h = this.handle;
    const nodes = doc.nodes ?? [];
    const parents: number[] = nodes.map(() => -1);
    nodes.forEach((n, p) => n.children?.forEach((c) => (parents[c] = p)));
    nodes.forEach((n, k) => {
      const trs = Float32Array.from([...(n.translation ?? [0, 0, 0]), ...(n.rotation ?? [0, 0, 0, 1]), ...(n.scale ?? [1, 1, 1])]);
      this.withBytes([bytesOf(trs)], ([p]) => x.psao_relit_node(h, parents[k], p));
    });
    for (const mesh of doc.meshes ?? []) {
      const prim = mesh.primitives[0];
      const a = prim?.attributes;
      if (!prim || a?.POSITION === undefined || a.NORMAL === undefined || prim.indices === undefined) {
        this.check(x.psao_relit_mesh(h, 0, 0, 0, 0, 0, 0, 0));
        continue;
      }
      const positions = Float32Array.from(read(a.POSITION));
      const normals = Float32Array.from(read(a.NORMAL));
      const indices = Uint32Array.from(read(prim.indices));
      const skinned = a.JOINTS_0 !== undefined && a.WEIGHTS_0 !== undefined;
      const arrays = [bytesOf(positions), bytesOf(normals), bytesOf(indices)];
      if (skinned) arrays.push(bytesOf(Uint16Array.from(read(a.JOINTS_0!))), bytesOf(Float32Array.from(read(a.WEIGHTS_0!))));
      this.withBytes(arrays, ([p, n, i, j, w]) =>
        this.check(x.psao_relit_mesh(h, positions.length / 3, p, n, i, arrays[2].length, skinned ? j : 0, skinned ? w : 0)),
      );
    }
    for (const skin of doc.skins ?? []) {
      const joints = bytesOf(Uint32Array.from(skin.joints));
      const ibm = skin.inverseBindMatrices !== undefined ? bytesOf(Float32Array.from(read(skin.inverseBindMatrices))) : null;
      this.withBytes(ibm ? [joints, ibm] : [joints], ([j, m]) =>
        this.check(x.psao_relit_skin(h, skin.joints.length, j, ibm ? m : 0)),
      );
    }
    for (let i = 0; i < Math.min(instances, nodes.length); i++) {
      const n = nodes[i];
      const matrix = bytesOf(Float32Array.from(n.matrix ?? [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]));
      const node = n.extras?.psao_node ?? -1;
      this.withBytes([matrix], ([m]) => x.psao_relit_instance(h, n.mesh ?? 0, node, n.skin ?? -1, m));
    }
    (doc.animations ?? []).forEach((anim, clip) => {
      for (const ch of anim.channels) {
        const s = anim.samplers[ch.sampler];
        const property = PROPERTIES[ch.target.path];
        if (!s || ch.target.node === undefined || property === undefined) continue;
        const times = bytesOf(Float32Array.from(read(s.input)));
        const values = bytesOf(Float32Array.from(read(s.output)));
        const interpolation = INTERPOLATIONS[s.interpolation ?? "LINEAR"] ?? -1;
        this.withBytes([times, values], ([t, v]) =>
          this.check(x.psao_relit_channel(h, clip, ch.target.node!, property, interpolation, t, times.length, v, values.length)),
        );
      }
    });
    for (const clip of doc.extras?.psao_playing ?? []) this.check(x.psao_relit_play(h, clip));
  }

  /// Relights every character at scene time `time` (seconds) from `eye`, instance i at
  /// `transforms[i]` (the last update's, an Affine3A's 12 floats) when set; throws on error.
  frame(time: number, transforms: readonly (Float32Array | null)[], eye: readonly number[]) {
    const t0 = performance.now();
    const count = transforms.length;
    const t = new Float32Array(count * 12);
    const given = new Uint8Array(count);
    transforms.forEach((m, i) => {
      if (!m) return;
      t.set(m, i * 12);
      given[i] = 1;
    });
    this.withBytes([bytesOf(t), given], ([tp, gp]) =>
      this.check(this.x.psao_relit_frame(this.handle, time, count, tp, gp, eye[0], eye[1], eye[2])),
    );
    this.ms = performance.now() - t0;
  }

  /// Instance `instance`'s values of the last frame (4 per mesh vertex), a view of wasm
  /// memory valid until the next call; null when it is not relit.
  values(instance: number): Float32Array | null {
    const ptr = this.x.psao_relit_values_ptr(this.handle, instance);
    if (ptr === 0) return null;
    return new Float32Array(this.x.memory.buffer, ptr, this.x.psao_relit_values_len(this.handle, instance));
  }

  /// Frees the wasm side.
  free() {
    if (this.handle !== 0) this.x.psao_relit_free(this.handle);
    this.handle = 0;
  }

  /// Copies `arrays` into wasm buffers for the duration of `f` (given their pointers).
  private withBytes<T>(arrays: Uint8Array[], f: (ptrs: number[]) => T): T {
    const ptrs = arrays.map((a) => {
      const p = this.x.psao_alloc(a.length);
      new Uint8Array(this.x.memory.buffer, p, a.length).set(a);
      return p;
    });
    try {
      return f(ptrs);
    } finally {
      ptrs.forEach((p, k) => this.x.psao_free(p, arrays[k].length));
    }
  }

  private check(status: number) {
    if (status === 0) return;
    const x = this.x;
    const text = new TextDecoder().decode(new Uint8Array(x.memory.buffer, x.psao_relit_error_ptr(this.handle), x.psao_relit_error_len(this.handle)));
    throw new Error(text);
  }
}
