// The client's mirror of the server's point grids (crates/psao-client/src/state.rs) and its
// state hash (crates/psao-client/src/hash.rs), computed the same way so that the browser's
// hash equals psao-client's and the server's for the same state.

import { BUCKET_ENTRIES, CELL_POINTS, DeltaError, VALID_BIT, type Reference, type ReferenceStore, type Update } from "./compact";
import type { InstanceEntry } from "./wire";

/// Largest grid side (psao-points' MAX_DIM).
const MAX_DIM = 1 << 21;

/// An update the state cannot take (the session must restart with a snapshot).
export class ApplyError extends Error {}

/// One instance's grid: buckets (keys and slots, 8 per bucket) and cells (7 points each).
/// It is also the `compact` decoder's reference for the instance (one copy of the grids).
export class Grid implements Reference {
  /// Keys (cell id + 1, 0 = empty) as low and high 32-bit halves.
  keyLo: Uint32Array;
  keyHi: Uint32Array;
  slots: Uint32Array;
  /// Points, 7 per cell slot; grows with the highest slot touched (the decoder may grow it
  /// further before `ClientState.apply` counts the slots).
  points: Uint32Array;
  /// Cell slots in use (at most the length `points` covers).
  slotCount = 0;
  readonly maxBucketWords: number;
  readonly maxPointWords: number;

  constructor(readonly entry: InstanceEntry) {
    this.maxBucketWords = entry.bucketCount * BUCKET_ENTRIES;
    this.maxPointWords = this.maxBucketWords * CELL_POINTS;
    this.keyLo = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
    this.keyHi = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
    this.slots = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
    this.points = new Uint32Array(0);
  }

  /// Empties the grid (a snapshot follows), keeping its memory.
  clear() {
    this.keyLo.fill(0);
    this.keyHi.fill(0);
    this.slots.fill(0);
    this.points.fill(0);
    this.slotCount = 0;
  }

  /// Most cell slots the layout allows.
  maxCells(): number {
    return this.entry.bucketCount * BUCKET_ENTRIES;
  }

  ensureSlot(slot: number) {
    if (slot < this.slotCount) return;
    this.slotCount = slot + 1;
    if (this.points.length < this.slotCount * CELL_POINTS) {
      const cells = Math.min(Math.max(this.slotCount, 2 * Math.floor(this.points.length / CELL_POINTS)), Math.max(this.slotCount, this.maxCells()));
      const grown = new Uint32Array(cells * CELL_POINTS);
      grown.set(this.points);
      this.points = grown;
    }
  }

  /// Whether cell id `hi · 2^32 + lo` lies in the grid (psao-points' `coord_of_id`): in
  /// doubles below 2^53 (exact), else in BigInt.
  idIsValid(hi: number, lo: number): boolean {
    const [dx, dy, dz] = this.entry.dims;
    const slice = dx * dy * 31;
    const row = dx * 17;
    if (hi < 1 << 21 && slice < 2 ** 52) {
      const id = hi * 2 ** 32 + lo;
      let z = Math.floor(id / slice);
      if (z * slice > id) z--;
      const rem = id - z * slice;
      let y = Math.floor(rem / row);
      if (y * row > rem) y--;
      const x = rem - y * row;
      return x < dx && y < dy && z < dz;
    }
    return this.idIsValidBig((BigInt(hi) << 32n) | BigInt(lo));
  }

  private idIsValidBig(id: bigint): boolean {
    const [dx, dy, dz] = this.entry.dims.map(BigInt);
    const slice = dx * dy * 31n;
    const row = dx * 17n;
    const z = id / slice;
    const rem = id % slice;
    return rem % row < dx && rem / row < dy && z < dz;
  }
}

/// Whether a layout can hold a grid (psao-client's `layout_is_usable`).
function usable(e: InstanceEntry): boolean {
  const ids = 31n * e.dims.reduce((a, d) => a * BigInt(d), 1n);
  return (
    e.origin.every(Number.isFinite) &&
    Number.isFinite(e.cellSize) &&
    e.cellSize > 0 &&
    Number.isFinite(e.layoutPoissonRadius) &&
    e.layoutPoissonRadius >= 0 &&
    e.dims.every((d) => d >= 1 && d <= MAX_DIM) &&
    ids < 0xffffffffffffffffn &&
    e.bucketCount > 0 &&
    (e.bucketCount & (e.bucketCount - 1)) === 0
  );
}

/// The mirror of every instance's grid and latest transform; the `compact` decoder's
/// reference store when given to it (updates are then decoded into the grids).
export class ClientState implements ReferenceStore {
  readonly isClientState = true;
  readonly grids: (Grid | null)[];
  readonly transforms: (Float32Array | null)[];
  lastFrame: bigint | null = null;

  constructor(table: InstanceEntry[]) {
    this.grids = table.map((e) => (usable(e) ? new Grid(e) : null));
    this.transforms = table.map(() => null);
  }

  /// Instance `instance`'s grid as the decoder's reference.
  referenceOf(instance: number): Reference {
    if (instance >= this.grids.length) throw new DeltaError(`instance ${instance} out of range (${this.grids.length} instances)`);
    const g = this.grids[instance];
    if (!g) throw new DeltaError(`instance ${instance} has no grid`);
    return g;
  }

  /// Empties every grid and forgets the transforms (a snapshot follows).
  clear() {
    for (const g of this.grids) g?.clear();
    this.transforms.fill(null);
  }

  /// Applies a decoded update after checking all of it. An update decoded elsewhere changes
  /// nothing on an error; one decoded into this state (`inPlace`) is already in the grids,
  /// so after an error the state is undefined and the session must restart.
  apply(u: Update) {
    this.validate(u);
    if (u.snapshot && !u.inPlace) this.clear();
    for (const [instance, t] of u.transforms) this.transforms[instance] = t;
    for (const d of u.instances) {
      const g = this.grids[d.instance]!;
      if (u.inPlace) {
        for (let i = 0; i < d.keyLo.length; i++) {
          if (d.keyLo[i] !== 0 || d.keyHi[i] !== 0) g.ensureSlot(d.slots[i]);
        }
        for (let k = 0; k < d.cellSlots.length; k++) g.ensureSlot(d.cellSlots[k]);
        continue;
      }
      for (let k = 0; k < d.bucketIds.length; k++) {
        const base = d.bucketIds[k] * BUCKET_ENTRIES;
        const src = k * BUCKET_ENTRIES;
        // Entries this bucket held stop naming their slots (as InstanceGrid::set_bucket).
        for (let i = 0; i < BUCKET_ENTRIES; i++) {
          const lo = d.keyLo[src + i];
          const hi = d.keyHi[src + i];
          g.keyLo[base + i] = lo;
          g.keyHi[base + i] = hi;
          g.slots[base + i] = d.slots[src + i];
          if (lo !== 0 || hi !== 0) g.ensureSlot(d.slots[src + i]);
        }
      }
      for (let k = 0; k < d.cellSlots.length; k++) {
        const slot = d.cellSlots[k];
        g.ensureSlot(slot);
        g.points.set(d.points.subarray(k * CELL_POINTS, (k + 1) * CELL_POINTS), slot * CELL_POINTS);
      }
    }
    this.lastFrame = u.frame;
  }

  private validate(u: Update) {
    const count = this.grids.length;
    const inRange = (i: number) => {
      if (i >= count) throw new ApplyError(`instance ${i} out of range (${count} instances)`);
    };
    for (const [i, t] of u.transforms) {
      inRange(i);
      if (!t.every(Number.isFinite)) throw new ApplyError(`instance ${i}: transform is not finite`);
    }
    for (const d of u.instances) {
      inRange(d.instance);
      const g = this.grids[d.instance];
      if (!g) throw new ApplyError(`instance ${d.instance} has no grid`);
      const max = g.maxCells();
      const mask = g.entry.bucketCount - 1;
      for (let k = 0; k < d.bucketIds.length; k++) {
        const b = d.bucketIds[k];
        if (b >= g.entry.bucketCount) throw new ApplyError(`instance ${d.instance}: bucket ${b} out of range`);
        for (let i = k * BUCKET_ENTRIES; i < (k + 1) * BUCKET_ENTRIES; i++) {
          const lo = d.keyLo[i];
          const hi = d.keyHi[i];
          if (lo === 0 && hi === 0) continue;
          if (d.slots[i] >= max) throw new ApplyError(`instance ${d.instance}: cell slot ${d.slots[i]} out of range`);
          // id = key − 1
          const idLo = lo === 0 ? 0xffffffff : lo - 1;
          const idHi = lo === 0 ? hi - 1 : hi;
          if (!g.idIsValid(idHi, idLo) || ((idLo & mask) >>> 0) !== b) {
            throw new ApplyError(`instance ${d.instance}: bucket ${b} has an invalid cell key`);
          }
        }
      }
      for (const slot of d.cellSlots) {
        if (slot >= max) throw new ApplyError(`instance ${d.instance}: cell slot ${slot} out of range`);
      }
    }
  }

  /// The state hash of psao-client (`state_hash_of`): every grid's compacted buckets and
  /// used cells folded into one 64-bit word.
  stateHash(): bigint {
    const h = new Hasher(0x243f6a88, 0x85a308d3);
    for (const g of this.grids) {
      if (!g) {
        h.word(NO_GRID_HI, NO_GRID_LO);
        continue;
      }
      h.word(0, g.entry.bucketCount);
      for (let b = 0; b < g.entry.bucketCount; b++) {
        const base = b * BUCKET_ENTRIES;
        let used = 0;
        for (let i = 0; i < BUCKET_ENTRIES; i++) {
          const lo = g.keyLo[base + i];
          const hi = g.keyHi[base + i];
          if (lo === 0 && hi === 0) continue;
          h.word(hi, lo);
          h.word(0, g.slots[base + i]);
          used++;
        }
        for (; used < BUCKET_ENTRIES; used++) {
          h.word(0, 0);
          h.word(0, 0);
        }
      }
      let usedCells = 0;
      for (let s = g.slotCount - 1; s >= 0; s--) {
        if (validPoints(g.points, s) > 0) {
          usedCells = s + 1;
          break;
        }
      }
      h.word(0, usedCells);
      const compact = new Uint32Array(CELL_POINTS + 1);
      for (let s = 0; s < usedCells; s++) {
        compact.fill(0);
        let n = 0;
        for (let i = 0; i < CELL_POINTS; i++) {
          const p = g.points[s * CELL_POINTS + i];
          if ((p & VALID_BIT) !== 0) compact[n++] = p;
        }
        for (let i = 0; i < CELL_POINTS; i += 2) {
          h.word(compact[i + 1], compact[i]);
        }
      }
    }
    h.word(0, this.grids.length);
    return h.finish();
  }
}

function validPoints(points: Uint32Array, slot: number): number {
  let n = 0;
  for (let i = 0; i < CELL_POINTS; i++) if ((points[slot * CELL_POINTS + i] & VALID_BIT) !== 0) n++;
  return n;
}

const NO_GRID_HI = 0x6e6f5f67;
const NO_GRID_LO = 0x72696421;
/// The multiplier 0x517c_c1b7_2722_0a95: 32-bit halves, and the low half's 16-bit limbs.
const K_HI = 0x517cc1b7;
const K_LO = 0x27220a95;
const K_LO0 = K_LO & 0xffff;
const K_LO1 = K_LO >>> 16;
const M64 = 0xffffffffffffffffn;

/// psao-client's hasher: `h = (rotl(h, 5) ^ w) · K`, SplitMix64 finaliser. The state is two
/// 32-bit halves (BigInt arithmetic is ~50× slower, too slow to hash a whole state per
/// update): the product's low half is `imul(lo, K_LO)`, its high half the high 32 bits of
/// `lo · K_LO` (from 16-bit limbs, exact in doubles) plus the two cross products.
class Hasher {
  constructor(
    private hi: number,
    private lo: number,
  ) {}
  word(wHi: number, wLo: number) {
    const xHi = ((this.hi << 5) | (this.lo >>> 27)) ^ wHi;
    const xLo = ((this.lo << 5) | (this.hi >>> 27)) ^ wLo;
    const a0 = xLo & 0xffff;
    const a1 = xLo >>> 16;
    const p00 = a0 * K_LO0;
    const p01 = a0 * K_LO1;
    const p10 = a1 * K_LO0;
    const mid = (p00 >>> 16) + (p01 & 0xffff) + (p10 & 0xffff);
    const carry = a1 * K_LO1 + (p01 >>> 16) + (p10 >>> 16) + (mid >>> 16);
    this.lo = Math.imul(xLo, K_LO) >>> 0;
    this.hi = (carry + Math.imul(xHi, K_LO) + Math.imul(xLo, K_HI)) >>> 0;
  }
  finish(): bigint {
    let z = (BigInt(this.hi) << 32n) | BigInt(this.lo);
    z = ((z ^ (z >> 30n)) * 0xbf58476d1ce4e5b9n) & M64;
    z = ((z ^ (z >> 27n)) * 0x94d049bb133111ebn) & M64;
    return z ^ (z >> 31n);
  }
}
