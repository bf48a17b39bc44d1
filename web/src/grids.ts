// The client's grids on the GPU, sparse: only the buckets that hold entries and the pages of
// cell slots that hold points take texture memory (the grids' hash tables are sized for every
// cell of an instance, four times over, while a viewer receives the cells it sees). Kept
// equal to the client state (the wasm's, `codec.ts`) by patching in the records of what each
// update changed (crates/psao-wasm/src/changes.rs); only the texture rows they touched are
// uploaded (texSubImage2D). The AO fragment
// shader (`aoshader.ts`) reads four textures with texelFetch (texel index i at
// (i % TEX_WIDTH, i / TEX_WIDTH)):
// * bucket directory (R32UI): one texel per bucket of every instance, instance k's bucket b
//   at `bucketBase[k] + b`: `count | first << 4`, the bucket's used entries (0–8) and where
//   they start in the entry pool.
// * entry pool (RGBA32UI): (key low, key high, cell slot, 0) per used entry, in chunks of 1,
//   2, 4 or 8 entries (the count rounded up to a power of two; freed chunks are reused).
// * cell page table (R32UI): one texel per page of `CELL_PAGE` cell slots of every instance,
//   instance k's page p at `cellPageBase[k] + p`: the page's index in the cell pool, or
//   `NO_PAGE` (no points there yet).
// * cell pool (RGBA32UI): two texels per cell slot of each allocated page, points 0–3 and
//   4–6 (the eighth word is 0): slot s of page q is texels `2·(CELL_PAGE·q + s % CELL_PAGE)`.
// * irradiance pool (RGBA32UI), laid out as the cell pool: the RGB9E5 records of the cell's
//   points; allocated once a record arrives (lit sessions), zeros where none.
// A snapshot's records start with a reset: the pools empty, then every bucket and cell.

import type { ViewerState } from "./codec";

/// Points per cell.
const CELL_POINTS = 7;
/// Change record tags (crates/psao-wasm/src/changes.rs).
const BUCKET = 0;
const CELL = 1;
const RESET = 2;

/// Texels per texture row.
export const TEX_WIDTH = 1024;
/// Cell slots per page of the cell pool.
export const CELL_PAGE = 32;
/// A cell page without storage.
export const NO_PAGE = 0xffffffff;
/// Most texels the entry pool can address (28 bits of a directory word).
const MAX_POOL_TEXELS = 1 << 28;

/// Where one instance's grid lives in the textures.
export interface GridSlot {
  /// Its first bucket in the directory.
  bucketBase: number;
  /// Its first page in the cell page table.
  cellPageBase: number;
  /// Cell slots its layout allows (larger slots are never looked up).
  maxCells: number;
}

/// One R32UI or RGBA32UI texture with its CPU mirror and dirty rows; it grows (doubling its
/// rows, contents kept) on demand.
class DataTexture {
  /// The texture (immutable storage: growing makes a new one).
  texture: WebGLTexture | null = null;
  mirror = new Uint32Array(0);
  rows = 0;
  private dirty = new Uint8Array(0);
  private anyDirty = false;
  private stale = true;

  constructor(
    private gl: WebGL2RenderingContext,
    private channels: 1 | 4,
  ) {}

  /// Words per texel.
  get words(): number {
    return this.channels;
  }

  /// Makes room for `texels` (rows doubling), keeping the contents; `fill` initialises new words.
  ensure(texels: number, fill = 0) {
    const rows = Math.max(1, Math.ceil(texels / TEX_WIDTH));
    if (rows <= this.rows) return;
    const grown = Math.max(rows, 2 * this.rows);
    const mirror = new Uint32Array(grown * TEX_WIDTH * this.channels);
    mirror.set(this.mirror);
    if (fill !== 0) mirror.fill(fill, this.mirror.length);
    this.mirror = mirror;
    this.rows = grown;
    this.dirty = new Uint8Array(grown).fill(1);
    this.anyDirty = true;
    this.stale = true;
  }

  /// Sets every word to `value` (rows kept, all dirty).
  reset(value: number) {
    this.mirror.fill(value);
    this.dirty.fill(1);
    this.anyDirty = true;
  }

  /// Marks the rows of texels `first..first + count` for upload.
  touch(first: number, count: number) {
    const last = Math.floor((first + count - 1) / TEX_WIDTH);
    for (let r = Math.floor(first / TEX_WIDTH); r <= last; r++) this.dirty[r] = 1;
    this.anyDirty = true;
  }

  /// Bytes of texture storage.
  bytes(): number {
    return this.mirror.byteLength;
  }

  /// (Re)creates the texture when it grew, then uploads runs of dirty rows; returns the
  /// bytes uploaded.
  upload(): number {
    const gl = this.gl;
    if (this.rows === 0) return 0; // nothing stored yet: no texture (the renderer binds an empty one)
    if (this.stale) {
      this.stale = false;
      if (this.texture) gl.deleteTexture(this.texture);
      this.texture = gl.createTexture()!;
      gl.bindTexture(gl.TEXTURE_2D, this.texture);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texStorage2D(gl.TEXTURE_2D, 1, this.channels === 1 ? gl.R32UI : gl.RGBA32UI, TEX_WIDTH, this.rows);
    }
    if (!this.anyDirty) return 0;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    const format = this.channels === 1 ? gl.RED_INTEGER : gl.RGBA_INTEGER;
    const rowWords = TEX_WIDTH * this.channels;
    let bytes = 0;
    for (let r = 0; r < this.rows; ) {
      if (!this.dirty[r]) {
        r++;
        continue;
      }
      let end = r;
      while (end < this.rows && this.dirty[end]) this.dirty[end++] = 0;
      const data = this.mirror.subarray(r * rowWords, end * rowWords);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, r, TEX_WIDTH, end - r, format, gl.UNSIGNED_INT, data);
      bytes += data.byteLength;
      r = end;
    }
    this.anyDirty = false;
    return bytes;
  }
}

/// Chunks of 1, 2, 4 and 8 texels in one growing pool, with a free list per size.
class ChunkPool {
  private end = 0;
  private free: number[][] = [[], [], [], []];

  /// Forgets every chunk.
  clear() {
    this.end = 0;
    for (const f of this.free) f.length = 0;
  }

  /// A chunk of size class `c` (2^c texels); returns its first texel.
  alloc(c: number): number {
    const reused = this.free[c].pop();
    if (reused !== undefined) return reused;
    const first = this.end;
    this.end += 1 << c;
    return first;
  }

  release(first: number, c: number) {
    this.free[c].push(first);
  }

  /// Texels in use or free (the pool's high-water mark).
  get texels(): number {
    return this.end;
  }
}

/// Size class of a chunk holding `count` (1–8) entries.
function sizeClass(count: number): number {
  return count <= 1 ? 0 : count <= 2 ? 1 : count <= 4 ? 2 : 3;
}

/// The grids of one session in GPU textures.
export class GridTextures {
  readonly directory: DataTexture;
  readonly entries: DataTexture;
  readonly pageTable: DataTexture;
  readonly cells: DataTexture;
  readonly lights: DataTexture;
  slots: (GridSlot | null)[] = [];
  /// Why AO cannot be drawn (textures too large), or null.
  problem: string | null = null;
  /// Bytes uploaded so far and full rebuilds.
  uploadedBytes = 0;
  rebuilds = 0;
  private pool = new ChunkPool();
  /// Pages of cells allocated (0 until the grids hold points).
  cellPages = 0;
  /// Whether an irradiance record arrived in this session (the irradiance pool exists).
  lit = false;

  constructor(private gl: WebGL2RenderingContext) {
    this.directory = new DataTexture(gl, 1);
    this.entries = new DataTexture(gl, 4);
    this.pageTable = new DataTexture(gl, 1);
    this.cells = new DataTexture(gl, 4);
    this.lights = new DataTexture(gl, 4);
  }

  /// Follows a new session's (empty) state: lays out its directory and page table.
  reset(state: ViewerState) {
    let buckets = 0;
    let pages = 0;
    this.slots = Array.from({ length: state.instanceCount() }, (_, k) => {
      const bucketCount = state.bucketCount(k);
      if (bucketCount === 0) return null;
      const maxCells = state.maxCells(k);
      const s = { bucketBase: buckets, cellPageBase: pages, maxCells };
      buckets += bucketCount;
      pages += Math.ceil(maxCells / CELL_PAGE);
      return s;
    });
    const maxRows = this.gl.getParameter(this.gl.MAX_TEXTURE_SIZE) as number;
    const rows = Math.ceil(Math.max(buckets, pages) / TEX_WIDTH);
    this.problem = rows > maxRows ? `the grids need ${rows} texture rows, this GPU allows ${maxRows}: AO not drawn` : null;
    if (this.problem) {
      this.slots = this.slots.map(() => null);
      return;
    }
    this.directory.ensure(buckets);
    this.pageTable.ensure(pages, NO_PAGE);
    this.lit = false;
    this.lights.reset(0);
    this.clear();
  }

  /// Patches in the change records of one applied update (`state.changes()`).
  apply(changes: Uint32Array) {
    if (this.problem) return;
    for (let at = 0; at < changes.length && !this.problem; ) {
      const tag = changes[at];
      if (tag === RESET) {
        this.clear();
        at += 1;
        continue;
      }
      const slot = this.slots[changes[at + 1]];
      const index = changes[at + 2];
      if (tag === BUCKET) {
        const count = changes[at + 3];
        if (slot) this.setBucket(slot, index, changes.subarray(at + 4, at + 4 + 3 * count));
        at += 4 + 3 * count;
      } else if (tag === CELL) {
        if (slot) this.setCell(slot, index, changes.subarray(at + 3, at + 3 + 2 * CELL_POINTS));
        at += 3 + 2 * CELL_POINTS;
      } else {
        this.problem = `unknown change record ${tag}: AO not drawn`;
      }
    }
  }

  /// Uploads the texture rows changed since the last upload; binds nothing.
  upload() {
    if (this.problem) return;
    this.uploadedBytes +=
      this.directory.upload() + this.entries.upload() + this.pageTable.upload() + this.cells.upload() + this.lights.upload();
  }

  /// Bytes of texture storage in use.
  textureBytes(): number {
    return this.directory.bytes() + this.entries.bytes() + this.pageTable.bytes() + this.cells.bytes() + this.lights.bytes();
  }

  /// Bucket `b` of an instance: its used entries (key low, key high, cell slot each) into a
  /// chunk of the pool.
  private setBucket(slot: GridSlot, b: number, entries: Uint32Array) {
    const at = slot.bucketBase + b;
    const dir = this.directory.mirror;
    const old = dir[at];
    const oldCount = old & 15;
    const count = entries.length / 3;
    let first = old >>> 4;
    if (oldCount > 0 && (count === 0 || sizeClass(count) !== sizeClass(oldCount))) {
      this.pool.release(first, sizeClass(oldCount));
    }
    if (count > 0 && (oldCount === 0 || sizeClass(count) !== sizeClass(oldCount))) {
      first = this.pool.alloc(sizeClass(count));
      if (this.pool.texels > MAX_POOL_TEXELS) {
        this.problem = "the bucket entries outgrew the entry pool: AO not drawn";
        return;
      }
      this.entries.ensure(this.pool.texels);
    }
    const m = this.entries.mirror;
    for (let e = 0; e < count; e++) {
      const o = (first + e) * 4;
      m[o] = entries[3 * e];
      m[o + 1] = entries[3 * e + 1];
      m[o + 2] = entries[3 * e + 2];
    }
    if (count > 0) this.entries.touch(first, count);
    dir[at] = count === 0 ? 0 : ((first << 4) | count) >>> 0;
    this.directory.touch(at, 1);
  }

  /// Cell slot `s` of an instance (its point words, then their irradiance records), into its
  /// page (allocated when it first holds points or records).
  private setCell(slot: GridSlot, s: number, words: Uint32Array) {
    if (s >= slot.maxCells) return;
    const at = slot.cellPageBase + Math.floor(s / CELL_PAGE);
    const table = this.pageTable.mirror;
    let page = table[at];
    if (page === NO_PAGE) {
      let any = false;
      for (let i = 0; i < 2 * CELL_POINTS; i++) if (words[i] !== 0) any = true;
      if (!any) return;
      page = this.cellPages++;
      table[at] = page;
      this.pageTable.touch(at, 1);
      this.cells.ensure(2 * CELL_PAGE * this.cellPages);
    }
    const texel = 2 * (page * CELL_PAGE + (s % CELL_PAGE));
    const m = this.cells.mirror;
    for (let i = 0; i < CELL_POINTS; i++) m[texel * 4 + i] = words[i];
    m[texel * 4 + 7] = 0;
    this.cells.touch(texel, 2);
    if (!this.lit) this.lit = words.subarray(CELL_POINTS).some((w) => w !== 0);
    if (this.lit) {
      this.lights.ensure(2 * CELL_PAGE * this.cellPages);
      const l = this.lights.mirror;
      for (let i = 0; i < CELL_POINTS; i++) l[texel * 4 + i] = words[CELL_POINTS + i];
      this.lights.touch(texel, 2);
    }
  }

  /// Empties the directory, page table and pools (a new state or a snapshot).
  private clear() {
    this.rebuilds++;
    this.pool.clear();
    this.cellPages = 0;
    this.directory.reset(0);
    this.pageTable.reset(NO_PAGE);
  }
}
