// The client's grids on the GPU: every instance's hash buckets and cells in two RGBA32UI data
// textures, kept equal to the client state (`state.ts`) by writing each update's changed
// buckets and cells into a CPU mirror and uploading only the texture rows they touched
// (texSubImage2D). The AO fragment shader (`aoshader.ts`) reads them with texelFetch.
//
// Layout (`TEX_WIDTH` texels per row, texel index i at (i % TEX_WIDTH, i / TEX_WIDTH)):
// * buckets: one texel per bucket entry, (key low, key high, cell slot, 0); instance k's
//   bucket b entry e is texel `bucketBase[k] + 8·b + e`.
// * cells: two texels per cell slot, points 0–3 and 4–6 (the eighth word is 0); instance k's
//   slot s is texels `2·(cellBase[k] + s)` and the next. Each instance reserves a power of
//   two of slots (at least its highest slot + 1); when one outgrows its reserve, the layout
//   is recomputed and everything re-uploaded from the state.

import { BUCKET_ENTRIES, CELL_POINTS, type Update } from "./compact";
import type { ClientState } from "./state";

/// Texels per texture row.
export const TEX_WIDTH = 1024;
/// Smallest cell reserve per instance.
const MIN_CELLS = 64;

/// Where one instance's grid lives in the textures.
export interface GridSlot {
  bucketBase: number;
  cellBase: number;
  cellCapacity: number;
}

/// One RGBA32UI texture with its CPU mirror and dirty rows.
class DataTexture {
  /// The texture (immutable storage: a resize makes a new one).
  texture: WebGLTexture | null = null;
  mirror = new Uint32Array(0);
  rows = 0;
  private dirty = new Uint8Array(0);
  private anyDirty = false;

  constructor(private gl: WebGL2RenderingContext) {}

  /// Resizes to hold `texels` (contents zeroed, all rows dirty).
  resize(texels: number) {
    const gl = this.gl;
    this.rows = Math.max(1, Math.ceil(texels / TEX_WIDTH));
    this.mirror = new Uint32Array(this.rows * TEX_WIDTH * 4);
    this.dirty = new Uint8Array(this.rows).fill(1);
    this.anyDirty = true;
    if (this.texture) gl.deleteTexture(this.texture);
    this.texture = gl.createTexture()!;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32UI, TEX_WIDTH, this.rows);
  }

  /// Marks the rows of texels `first..first + count` for upload.
  touch(first: number, count: number) {
    const last = Math.floor((first + count - 1) / TEX_WIDTH);
    for (let r = Math.floor(first / TEX_WIDTH); r <= last; r++) this.dirty[r] = 1;
    this.anyDirty = true;
  }

  /// Uploads runs of dirty rows; returns the bytes uploaded.
  upload(): number {
    if (!this.anyDirty) return 0;
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    let bytes = 0;
    for (let r = 0; r < this.rows; ) {
      if (!this.dirty[r]) {
        r++;
        continue;
      }
      let end = r;
      while (end < this.rows && this.dirty[end]) this.dirty[end++] = 0;
      const data = this.mirror.subarray(r * TEX_WIDTH * 4, end * TEX_WIDTH * 4);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, r, TEX_WIDTH, end - r, gl.RGBA_INTEGER, gl.UNSIGNED_INT, data);
      bytes += data.byteLength;
      r = end;
    }
    this.anyDirty = false;
    return bytes;
  }
}

/// The grids of one session in GPU textures.
export class GridTextures {
  readonly buckets: DataTexture;
  readonly cells: DataTexture;
  slots: (GridSlot | null)[] = [];
  /// Why AO cannot be drawn (textures too large), or null.
  problem: string | null = null;
  /// Bytes uploaded so far and full rebuilds.
  uploadedBytes = 0;
  rebuilds = 0;
  private state: ClientState | null = null;
  private stale = true;

  constructor(private gl: WebGL2RenderingContext) {
    this.buckets = new DataTexture(gl);
    this.cells = new DataTexture(gl);
  }

  /// Follows a new session's (empty) state.
  reset(state: ClientState) {
    this.state = state;
    this.stale = true;
  }

  /// Mirrors one applied update (call after `state.apply(u)`).
  apply(u: Update) {
    const state = this.state;
    if (!state || this.stale || u.snapshot) {
      this.stale = true;
      return;
    }
    for (const d of u.instances) {
      const slot = this.slots[d.instance];
      const grid = state.grids[d.instance];
      if (!slot || !grid || grid.slotCount > slot.cellCapacity) {
        this.stale = true;
        return;
      }
      const bm = this.buckets.mirror;
      for (let k = 0; k < d.bucketIds.length; k++) {
        const first = slot.bucketBase + d.bucketIds[k] * BUCKET_ENTRIES;
        for (let e = 0; e < BUCKET_ENTRIES; e++) {
          const o = (first + e) * 4;
          const src = k * BUCKET_ENTRIES + e;
          bm[o] = d.keyLo[src];
          bm[o + 1] = d.keyHi[src];
          bm[o + 2] = d.slots[src];
        }
        this.buckets.touch(first, BUCKET_ENTRIES);
      }
      const cm = this.cells.mirror;
      for (let k = 0; k < d.cellSlots.length; k++) {
        const first = 2 * (slot.cellBase + d.cellSlots[k]);
        cm.set(d.points.subarray(k * CELL_POINTS, (k + 1) * CELL_POINTS), first * 4);
        this.cells.touch(first, 2);
      }
    }
  }

  /// Brings the textures up to date (a full rebuild when needed) and binds nothing.
  upload() {
    if (this.stale && this.state) this.rebuild(this.state);
    this.uploadedBytes += this.buckets.upload() + this.cells.upload();
  }

  private rebuild(state: ClientState) {
    this.stale = false;
    this.rebuilds++;
    const gl = this.gl;
    const maxRows = gl.getParameter(gl.MAX_TEXTURE_SIZE) as number;
    let bucketTexels = 0;
    let cellSlots = 0;
    this.slots = state.grids.map((g) => {
      if (!g) return null;
      let capacity = MIN_CELLS;
      while (capacity < g.slotCount) capacity *= 2;
      capacity = Math.min(capacity, Math.max(g.maxCells(), g.slotCount));
      const s = { bucketBase: bucketTexels, cellBase: cellSlots, cellCapacity: capacity };
      bucketTexels += g.entry.bucketCount * BUCKET_ENTRIES;
      cellSlots += capacity;
      return s;
    });
    const rows = Math.max(bucketTexels, 2 * cellSlots) / TEX_WIDTH;
    if (rows > maxRows) {
      this.problem = `the grids need ${Math.ceil(rows)} texture rows, this GPU allows ${maxRows}: AO not drawn`;
      this.slots = state.grids.map(() => null);
      return;
    }
    this.problem = null;
    this.buckets.resize(bucketTexels);
    this.cells.resize(2 * cellSlots);
    const bm = this.buckets.mirror;
    const cm = this.cells.mirror;
    state.grids.forEach((g, k) => {
      const slot = this.slots[k];
      if (!g || !slot) return;
      const n = g.entry.bucketCount * BUCKET_ENTRIES;
      for (let e = 0; e < n; e++) {
        const o = (slot.bucketBase + e) * 4;
        bm[o] = g.keyLo[e];
        bm[o + 1] = g.keyHi[e];
        bm[o + 2] = g.slots[e];
      }
      for (let s = 0; s < g.slotCount; s++) {
        cm.set(g.points.subarray(s * CELL_POINTS, (s + 1) * CELL_POINTS), 8 * (slot.cellBase + s));
      }
    });
  }
}
