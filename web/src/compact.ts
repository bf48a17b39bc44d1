// The `compact` codec's decoder (crates/psao-delta/src/compact.rs; its module documentation
// describes the payload): zstd (fzstd) around a header, an index stream of delta-coded
// varints, per-record counts and choices, and byte planes of residuals against the decoder's
// reference (what it last received for the same slot). Every check of the Rust decoder that
// guards against a malformed payload is made here too, with the same decoded result.

import { decompress } from "fzstd";

/// Entries per hash bucket, points per cell (psao-points).
export const BUCKET_ENTRIES = 8;
export const CELL_POINTS = 7;
/// The valid bit of a packed point.
export const VALID_BIT = 0x80000000;

const TAG = 0x32435350; // "PSC2" little-endian
const FLAG_SNAPSHOT = 1;
const HEADER_BYTES = 28;
const TRANSFORM_WORDS = 12;
const POINT_CHOICES = 2 * CELL_POINTS;
const RANK_CHOICE = BUCKET_ENTRIES;
const ENTRY_BYTES = 12;
const POINT_BYTES = 4;
/// (shift, bits) of the point record's fields below the valid bit.
const FIELDS: [number, number][] = [
  [26, 5],
  [21, 5],
  [16, 5],
  [12, 4],
  [8, 4],
  [0, 8],
];
/// Most decompressed bytes of one update by default (psao-delta's MAX_DECODED_BYTES).
export const MAX_DECODED_BYTES = 256 << 20;
/// The ceiling of any decode limit (psao-delta's MAX_DECODE_LIMIT, 4 GiB).
export const MAX_DECODE_LIMIT = 4 * 2 ** 30;

/// A payload that does not decode.
export class DeltaError extends Error {}

/// One instance's changed buckets and cells, in flat typed arrays (no object per bucket,
/// cell or point). Bucket `bucketIds[k]`'s 8 entries are `keyLo`, `keyHi` (the 64-bit key:
/// cell id + 1, 0 = empty, as 32-bit halves) and `slots` at `8k .. 8k + 8`, used entries
/// first; cell slot `cellSlots[k]`'s 7 points are `points[7k .. 7k + 7]`.
export interface InstanceDelta {
  instance: number;
  bucketIds: Uint32Array;
  keyLo: Uint32Array;
  keyHi: Uint32Array;
  slots: Uint32Array;
  cellSlots: Uint32Array;
  points: Uint32Array;
}

/// A decoded update.
export interface Update {
  frame: bigint;
  snapshot: boolean;
  /// Instance and its Affine3A as 12 floats (matrix columns x, y, z, then translation).
  transforms: [number, Float32Array][];
  instances: InstanceDelta[];
  /// Whether its buckets and cells are already in the client state it was decoded against
  /// (a decoder given the state as its `ReferenceStore`); `ClientState.apply` then only
  /// checks them and takes the transforms and slot counts.
  inPlace: boolean;
}

/// The decompressed size a zstd frame header records, or an error when it records none
/// (psao's encoders always record it), read before anything is allocated.
export function zstdContentSize(bytes: Uint8Array): number {
  if (bytes.length < 5) throw new DeltaError("corrupt compressed data: too short");
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (view.getUint32(0, true) !== 0xfd2fb528) throw new DeltaError("corrupt compressed data: bad zstd magic");
  const fhd = bytes[4];
  const fcsFlag = fhd >> 6;
  const single = (fhd >> 5) & 1;
  const dictBytes = [0, 1, 2, 4][fhd & 3];
  const fcsBytes = fcsFlag === 0 ? single : [0, 2, 4, 8][fcsFlag];
  if (fcsBytes === 0) throw new DeltaError("compressed data does not record its decompressed size");
  const at = 5 + (single ? 0 : 1) + dictBytes;
  if (bytes.length < at + fcsBytes) throw new DeltaError("corrupt compressed data: truncated header");
  switch (fcsBytes) {
    case 1:
      return bytes[at];
    case 2:
      return view.getUint16(at, true) + 256;
    case 4:
      return view.getUint32(at, true);
    default: {
      const v = view.getBigUint64(at, true);
      return v > BigInt(Number.MAX_SAFE_INTEGER) ? Number.MAX_SAFE_INTEGER : Number(v);
    }
  }
}

/// Decompresses `bytes`, refusing (before allocating) more than `limit` bytes.
export function decompressLimited(bytes: Uint8Array, limit: number): Uint8Array {
  const size = zstdContentSize(bytes);
  if (size > limit) {
    throw new DeltaError(`decompressed size ${size} bytes exceeds the limit of ${limit} bytes`);
  }
  let out: Uint8Array;
  try {
    out = decompress(bytes, new Uint8Array(size));
  } catch (e) {
    throw new DeltaError(`corrupt compressed data: ${e}`);
  }
  if (out.length !== size) {
    throw new DeltaError(`corrupt compressed data: expanded to ${out.length} bytes, ${size} recorded`);
  }
  return out;
}

/// Reads LEB128 varints with bounds and overflow checks.
class VarReader {
  at = 0;
  constructor(private bytes: Uint8Array) {}
  left(): number {
    return this.bytes.length - this.at;
  }
  /// A varint as a number: exact up to 7 bytes (49 bits); longer ones (which no count or
  /// u32 delta can be) go through [`VarReader.varint`] for its checks and come back large.
  num(what: string): number {
    const start = this.at;
    let v = 0;
    for (let k = 0; k < 7; k++) {
      if (this.at >= this.bytes.length) throw new DeltaError(`truncated ${what}`);
      const b = this.bytes[this.at++];
      v += (b & 0x7f) * 2 ** (7 * k);
      if ((b & 0x80) === 0) return v;
    }
    this.at = start;
    return Number(this.varint(what));
  }
  varint(what: string): bigint {
    let v = 0n;
    for (let shift = 0n; shift < 64n; shift += 7n) {
      if (this.at >= this.bytes.length) throw new DeltaError(`truncated ${what}`);
      const b = this.bytes[this.at++];
      const bits = BigInt(b & 0x7f);
      if (shift === 63n && bits > 1n) throw new DeltaError(`bad varint in ${what}`);
      v |= bits << shift;
      if ((b & 0x80) === 0) return v;
    }
    throw new DeltaError(`bad varint in ${what}`);
  }
  /// A count of entries that each take at least one more byte.
  count(what: string): number {
    const n = this.num(what);
    if (n > this.left()) throw new DeltaError(`truncated ${what}`);
    return n;
  }
  /// A zigzag delta against `prev.v`; the result must be a u32.
  delta(prev: { v: number }, what: string): number {
    const z = this.num(what);
    // Zigzag: even z = 2d, odd z = 2|d| − 1 for negative d (exact in doubles below 2^53).
    const d = z % 2 === 0 ? z / 2 : -(z + 1) / 2;
    const v = prev.v + d;
    if (!(v >= 0 && v <= 0xffffffff)) throw new DeltaError(`bad varint in ${what}`);
    prev.v = v;
    return v;
  }
}

function unshuffle(planes: Uint8Array): Uint32Array {
  const n = planes.length / 4;
  const words = new Uint32Array(n);
  for (let plane = 0; plane < 4; plane++) {
    const base = plane * n;
    const shift = 8 * plane;
    for (let i = 0; i < n; i++) words[i] |= planes[base + i] << shift;
  }
  return words;
}


/// Inverse of the encoder's point residual: the valid point `residual` codes against
/// `reference`.
export function applyPointResidual(residual: number, reference: number): number {
  let acc = VALID_BIT;
  for (const [shift, bits] of FIELDS) {
    const mask = (1 << bits) - 1;
    const z = (residual >>> shift) & mask;
    const d = ((z >>> 1) ^ (-(z & 1) & mask)) >>> 0;
    acc = (acc | ((((reference >>> shift) + d) & mask) << shift)) >>> 0;
  }
  return acc >>> 0;
}

function usedEntries(lo: Uint32Array, hi: Uint32Array, base: number): number {
  let n = 0;
  while (n < BUCKET_ENTRIES && (lo[base + n] !== 0 || hi[base + n] !== 0)) n++;
  return n;
}

function usedPoints(points: Uint32Array, base: number): number {
  let n = 0;
  while (n < CELL_POINTS && points[base + n] !== 0) n++;
  return n;
}

/// `a` grown (doubling, zero-filled) to hold at least `words`, refused beyond `max`.
function grown(a: Uint32Array, words: number, max: number, what: string): Uint32Array {
  if (words <= a.length) return a;
  if (words > max) throw new DeltaError(`${what} out of range`);
  const b = new Uint32Array(Math.min(Math.max(words, 2 * a.length, 64), max));
  b.set(a);
  return b;
}

/// What the decoder last received for one instance, its reference: the buckets' entries
/// (`keyLo`, `keyHi`, `slots`: bucket b at 8b) and the cells (`points`: slot s at 7s) in flat
/// arrays indexed like the grid, which the decoder grows on demand up to the two bounds.
export interface Reference {
  keyLo: Uint32Array;
  keyHi: Uint32Array;
  slots: Uint32Array;
  points: Uint32Array;
  readonly maxBucketWords: number;
  readonly maxPointWords: number;
}

/// Where the decoder keeps its references: its own (`OwnReferences`), or the client state
/// itself (`ClientState`), so that the grids exist once and updates are decoded into them.
export interface ReferenceStore {
  /// Instance `instance`'s reference (a `DeltaError` when there is none).
  referenceOf(instance: number): Reference;
  /// Forgets everything (a snapshot follows).
  clear(): void;
  /// Whether decoding writes into the client state (`Update.inPlace`).
  readonly isClientState: boolean;
}

/// The decoder's own references, kept in a map until a snapshot clears them.
class OwnReferences implements ReferenceStore {
  readonly isClientState = false;
  private received = new Map<number, Reference>();
  constructor(
    private limit: number,
    private bucketCounts: number[] | null,
  ) {}
  clear() {
    this.received.clear();
  }
  referenceOf(instance: number): Reference {
    let r = this.received.get(instance);
    if (!r) {
      let buckets = Math.floor(this.limit / 4 / BUCKET_ENTRIES);
      if (this.bucketCounts) {
        if (instance >= this.bucketCounts.length) throw new DeltaError(`instance ${instance} out of range`);
        buckets = this.bucketCounts[instance];
      }
      const maxPoints = this.bucketCounts ? buckets * BUCKET_ENTRIES * CELL_POINTS : Math.floor(this.limit / 4);
      const empty = new Uint32Array(0);
      r = { keyLo: empty, keyHi: empty, slots: empty, points: empty, maxBucketWords: buckets * BUCKET_ENTRIES, maxPointWords: maxPoints };
      this.received.set(instance, r);
    }
    return r;
  }
}

function decodeCount(code: number, old: number, capacity: number, at: number, plane: number, what: string): number {
  if (code > capacity) throw new DeltaError(`${what} ${code} exceeds ${capacity}`);
  const n = (code + old) % (capacity + 1);
  if (at + n > plane) throw new DeltaError(`byte planes hold ${plane} records, the index stream implies ${at + n}`);
  return n;
}

const EMPTY_CELL = new Uint32Array(CELL_POINTS);

/// The decoder: its reference state lives between updates of one session.
export class CompactDecoder {
  private transforms = new Map<number, Uint32Array>();
  private references: ReferenceStore;

  /// Most decompressed bytes accepted per update (a client sets it from its instance table),
  /// and the instances' bucket counts when known (indices beyond them are refused; without
  /// them the reference arrays are bounded by the limit). With `store` (the client state),
  /// the references are the client's grids and every update is decoded into them.
  constructor(
    private limit = MAX_DECODED_BYTES,
    bucketCounts: number[] | null = null,
    store: ReferenceStore | null = null,
  ) {
    this.limit = Math.min(limit, MAX_DECODE_LIMIT);
    this.references = store ?? new OwnReferences(this.limit, bucketCounts);
  }

  private clear() {
    this.transforms.clear();
    this.references.clear();
  }

  /// Decodes one update. After an error the state is undefined: the session must restart.
  decode(bytes: Uint8Array): Update {
    const payload = decompressLimited(bytes, this.limit);
    if (payload.length < HEADER_BYTES) throw new DeltaError("truncated compact header");
    const view = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
    const word = (i: number) => view.getUint32(i, true);
    if (word(0) !== TAG) throw new DeltaError(`bad format tag ${word(0).toString(16)}`);
    const flags = word(4);
    if ((flags & ~FLAG_SNAPSHOT) !== 0) throw new DeltaError(`unknown flag bits ${flags}`);
    const frame = BigInt(word(8)) | (BigInt(word(12)) << 32n);
    const indexLen = word(16);
    const rest = payload.subarray(HEADER_BYTES);
    if (indexLen > rest.length) throw new DeltaError("truncated index stream");
    const layout = parseIndex(rest.subarray(0, indexLen));
    const entries = word(20);
    const points = word(24);
    const s = split(layout, entries, points, rest.subarray(indexLen));
    const snapshot = (flags & FLAG_SNAPSHOT) !== 0;
    if (snapshot) this.clear();
    return this.assemble(layout, s, frame, snapshot);
  }

  private assemble(layout: IndexLayout, s: Sections, frame: bigint, snapshot: boolean): Update {
    const transforms: [number, Float32Array][] = layout.transforms.map((instance, k) => {
      const old = this.transforms.get(instance) ?? new Uint32Array(TRANSFORM_WORDS);
      const words = new Uint32Array(TRANSFORM_WORDS);
      for (let i = 0; i < TRANSFORM_WORDS; i++) words[i] = (s.transforms[k * TRANSFORM_WORDS + i] ^ old[i]) >>> 0;
      this.transforms.set(instance, words);
      return [instance, new Float32Array(words.buffer.slice(0))];
    });
    let entryCount = 0;
    let cellCount = 0;
    let entry = 0;
    let point = 0;
    const instances: InstanceDelta[] = [];
    for (const { instance, buckets: bucketIds, cells: slotIds } of layout.instances) {
      const r = this.references.referenceOf(instance);
      const nb = bucketIds.length;
      const lo = new Uint32Array(nb * BUCKET_ENTRIES);
      const hi = new Uint32Array(nb * BUCKET_ENTRIES);
      const slots = new Uint32Array(nb * BUCKET_ENTRIES);
      for (let k = 0; k < nb; k++) {
        const b = bucketIds[k];
        const base = b * BUCKET_ENTRIES;
        const end = base + BUCKET_ENTRIES;
        r.keyLo = grown(r.keyLo, end, r.maxBucketWords, `bucket ${b}`);
        r.keyHi = grown(r.keyHi, end, r.maxBucketWords, `bucket ${b}`);
        r.slots = grown(r.slots, end, r.maxBucketWords, `bucket ${b}`);
        const code = s.entryCounts[entryCount++];
        const n = decodeCount(code, usedEntries(r.keyLo, r.keyHi, base), BUCKET_ENTRIES, entry, s.entryChoices.length, "bucket entry count");
        const out = k * BUCKET_ENTRIES;
        for (let i = 0; i < n; i++) {
          const c = s.entryChoices[entry];
          let tLo = s.keyLo[entry];
          let tHi = s.keyHi[entry];
          const sr = s.slots[entry];
          entry++;
          let slot: number;
          if (c === RANK_CHOICE) {
            if (sr >= slotIds.length) throw new DeltaError("bad reference choice for a bucket entry");
            slot = slotIds[sr];
          } else if (c < RANK_CHOICE) {
            // XOR with the reference's `(key − 1) XOR b` (0 for an empty entry).
            const o = base + ((i + c) % BUCKET_ENTRIES);
            const rLo = r.keyLo[o];
            const rHi = r.keyHi[o];
            if (rLo !== 0 || rHi !== 0) {
              const mLo = rLo === 0 ? 0xffffffff : rLo - 1;
              const mHi = rLo === 0 ? rHi - 1 : rHi;
              tLo = (tLo ^ mLo ^ b) >>> 0;
              tHi = (tHi ^ mHi) >>> 0;
            }
            slot = (sr ^ r.slots[o]) >>> 0;
          } else {
            throw new DeltaError("bad reference choice for a bucket entry");
          }
          // key = (t XOR b) + 1, refused when it overflows 64 bits.
          const xLo = (tLo ^ b) >>> 0;
          if (xLo === 0xffffffff && tHi === 0xffffffff) throw new DeltaError("bad bucket key");
          lo[out + i] = xLo === 0xffffffff ? 0 : xLo + 1;
          hi[out + i] = xLo === 0xffffffff ? tHi + 1 : tHi;
          slots[out + i] = slot;
        }
        // Copied word by word (a subarray per bucket costs more in allocation than the copy).
        const rLo = r.keyLo;
        const rHi = r.keyHi;
        const rSlots = r.slots;
        for (let i = 0; i < BUCKET_ENTRIES; i++) {
          rLo[base + i] = lo[out + i];
          rHi[base + i] = hi[out + i];
          rSlots[base + i] = slots[out + i];
        }
      }
      const nc = slotIds.length;
      const pts = new Uint32Array(nc * CELL_POINTS);
      for (let k = 0; k < nc; k++) {
        const slot = slotIds[k];
        const base = slot * CELL_POINTS;
        r.points = grown(r.points, base + CELL_POINTS, r.maxPointWords, `cell slot ${slot}`);
        const old = r.points;
        const code = s.cellLengths[cellCount++];
        const n = decodeCount(code, usedPoints(old, base), CELL_POINTS, point, s.pointChoices.length, "cell length");
        const out = k * CELL_POINTS;
        for (let i = 0; i < n; i++) {
          const c = s.pointChoices[point];
          const residual = s.points[point];
          point++;
          if (c >= POINT_CHOICES) throw new DeltaError("bad reference choice for a point");
          if ((residual & VALID_BIT) !== 0) throw new DeltaError("bad point residual");
          // References: this cell as last received, or the previous cell of this update.
          const reference =
            c < CELL_POINTS ? old[base + ((i + c) % CELL_POINTS)] : k > 0 ? pts[out - CELL_POINTS + c - CELL_POINTS] : EMPTY_CELL[0];
          pts[out + i] = applyPointResidual(residual, reference);
        }
        for (let i = 0; i < CELL_POINTS; i++) old[base + i] = pts[out + i];
      }
      instances.push({
        instance,
        bucketIds: Uint32Array.from(bucketIds),
        keyLo: lo,
        keyHi: hi,
        slots,
        cellSlots: Uint32Array.from(slotIds),
        points: pts,
      });
    }
    if (entry !== s.entryChoices.length || point !== s.pointChoices.length) {
      throw new DeltaError(`${s.entryChoices.length - entry + s.pointChoices.length - point} trailing records`);
    }
    return { frame, snapshot, transforms, instances, inPlace: this.references.isClientState };
  }
}

interface IndexLayout {
  transforms: number[];
  instances: { instance: number; buckets: number[]; cells: number[] }[];
}

function parseIndex(bytes: Uint8Array): IndexLayout {
  const r = new VarReader(bytes);
  const transforms: number[] = [];
  let n = r.count("transform count");
  const prevT = { v: -1 };
  for (let i = 0; i < n; i++) transforms.push(r.delta(prevT, "transform instance"));
  n = r.count("instance count");
  const instances: IndexLayout["instances"] = [];
  const prevI = { v: -1 };
  for (let k = 0; k < n; k++) {
    const instance = r.delta(prevI, "instance");
    const nb = r.count("bucket count");
    const nc = r.count("cell count");
    const buckets: number[] = [];
    const prevB = { v: -1 };
    for (let i = 0; i < nb; i++) buckets.push(r.delta(prevB, "bucket index"));
    const cells: number[] = [];
    const prevC = { v: -1 };
    for (let i = 0; i < nc; i++) cells.push(r.delta(prevC, "cell slot"));
    instances.push({ instance, buckets, cells });
  }
  if (r.left() !== 0) throw new DeltaError(`${r.left()} trailing bytes after the index stream`);
  return { transforms, instances };
}

interface Sections {
  entryCounts: Uint8Array;
  cellLengths: Uint8Array;
  entryChoices: Uint8Array;
  pointChoices: Uint8Array;
  keyLo: Uint32Array;
  keyHi: Uint32Array;
  slots: Uint32Array;
  points: Uint32Array;
  transforms: Uint32Array;
}

function split(layout: IndexLayout, entries: number, points: number, bytes: Uint8Array): Sections {
  let nb = 0;
  let nc = 0;
  for (const i of layout.instances) {
    nb += i.buckets.length;
    nc += i.cells.length;
  }
  const transformBytes = layout.transforms.length * TRANSFORM_WORDS * 4;
  const expected = nb + nc + entries * (1 + ENTRY_BYTES) + points * (1 + POINT_BYTES) + transformBytes;
  if (bytes.length !== expected) {
    throw new DeltaError(`byte planes hold ${bytes.length} bytes, the index stream implies ${expected}`);
  }
  let at = 0;
  const take = (n: number) => bytes.subarray(at, (at += n));
  const entryCounts = take(nb);
  const cellLengths = take(nc);
  const entryChoices = take(entries);
  const pointChoices = take(points);
  const keyPlanes = take(entries * 8);
  const slots = unshuffle(take(entries * 4));
  const pts = unshuffle(take(points * 4));
  const transforms = unshuffle(take(transformBytes));
  const keyLo = new Uint32Array(entries);
  const keyHi = new Uint32Array(entries);
  for (let p = 0; p < 4; p++) {
    for (let i = 0; i < entries; i++) {
      keyLo[i] |= keyPlanes[p * entries + i] << (8 * p);
      keyHi[i] |= keyPlanes[(p + 4) * entries + i] << (8 * p);
    }
  }
  return { entryCounts, cellLengths, entryChoices, pointChoices, keyLo, keyHi, slots, points: pts, transforms };
}
