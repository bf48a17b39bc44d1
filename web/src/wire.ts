// psao-wire in the browser: frames (magic `PSW1`, payload length, CRC-32 of the payload)
// carrying postcard-encoded messages (docs/PROTOCOL.md). Decoding checks everything the Rust
// decoder checks that a server could get wrong: magic, size limit, checksum, truncation,
// trailing bytes, and the message validation rules a client relies on.

/// First four bytes of every frame.
export const MAGIC = [0x50, 0x53, 0x57, 0x31]; // "PSW1"
/// Header bytes: magic, payload length (u32 LE), CRC-32 (u32 LE).
export const HEADER_LEN = 12;
/// Protocol version spoken here.
export const PROTOCOL_VERSION = 2;
/// Largest payload accepted from a server (as psao-wire's MAX_SERVER_FRAME).
export const MAX_SERVER_FRAME = 256 << 20;
/// Capability bits of a hello.
export const CAP_CODEC_PAPER = 1;
export const CAP_CODEC_COMPACT = 2;
export const CAP_STATE_HASH = 4;
export const CAP_STATUS = 16;

/// Error codes of an error message, in wire order.
export const ERROR_CODES = ["Version", "Token", "Frame", "Protocol", "Update", "Server"] as const;
export type ErrorCode = (typeof ERROR_CODES)[number];

export interface InstanceEntry {
  origin: [number, number, number];
  cellSize: number;
  dims: [number, number, number];
  layoutPoissonRadius: number;
  bucketCount: number;
  poissonRadius: number;
  pointCount: number;
}

export interface Welcome {
  version: number;
  clientId: number;
  codec: string;
  serverHz: number;
  clientHz: number;
  lockstep: boolean;
  scene: string;
  frame: number;
  sceneTime: number;
  instances: InstanceEntry[];
}

export interface Delta {
  frame: number;
  sceneTime: number;
  clientFrame: number | null;
  stateHash: bigint | null;
  payload: Uint8Array;
}

export interface Camera {
  frame: number;
  position: [number, number, number];
  target: [number, number, number];
  up: [number, number, number];
  fovY: number;
  near: number;
  far: number;
  aspect: number;
}

export interface Hello {
  version: number;
  capabilities: number;
  token: string | null;
  name: string;
}

export type Message =
  | { kind: "hello"; hello: Hello }
  | { kind: "welcome"; welcome: Welcome }
  | { kind: "camera"; camera: Camera }
  | { kind: "scene_time"; frame: number; seconds: number; clientFrame: number | null }
  | { kind: "ack"; frame: number }
  | { kind: "delta"; delta: Delta }
  | { kind: "snapshot"; delta: Delta }
  | { kind: "error"; code: ErrorCode; message: string }
  | { kind: "bye"; reason: string }
  | { kind: "status"; stalled: boolean; text: string };

/// A frame or message that is not valid.
export class WireError extends Error {}

// CRC-32 (IEEE, reflected 0xEDB88320) as crc32fast computes it: eight lines with a table,
// written here rather than pulling in an npm package for them.
const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

/// CRC-32 of `bytes`.
export function crc32(bytes: Uint8Array): number {
  let c = 0xffffffff;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

/// Reads postcard values from a payload.
class Reader {
  private at = 0;
  private view: DataView;
  constructor(private bytes: Uint8Array) {
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  }
  private need(n: number, what: string) {
    if (this.at + n > this.bytes.length) throw new WireError(`truncated ${what}`);
  }
  done(): boolean {
    return this.at === this.bytes.length;
  }
  rest(): number {
    return this.bytes.length - this.at;
  }
  varint(what: string, maxBits: number): bigint {
    let v = 0n;
    for (let shift = 0n; ; shift += 7n) {
      this.need(1, what);
      const b = this.bytes[this.at++];
      v |= BigInt(b & 0x7f) << shift;
      if ((b & 0x80) === 0) break;
      if (shift + 7n >= BigInt(maxBits + 7)) throw new WireError(`varint too long in ${what}`);
    }
    if (v >> BigInt(maxBits) !== 0n) throw new WireError(`${what} out of range`);
    return v;
  }
  u16(what: string): number {
    return Number(this.varint(what, 16));
  }
  u32(what: string): number {
    return Number(this.varint(what, 32));
  }
  /// A u64 that must fit a JS number exactly (frame counters).
  u64n(what: string): number {
    const v = this.varint(what, 64);
    if (v > BigInt(Number.MAX_SAFE_INTEGER)) throw new WireError(`${what} too large`);
    return Number(v);
  }
  u64(what: string): bigint {
    return this.varint(what, 64);
  }
  bool(what: string): boolean {
    this.need(1, what);
    const b = this.bytes[this.at++];
    if (b > 1) throw new WireError(`bad bool in ${what}`);
    return b === 1;
  }
  f32(what: string): number {
    this.need(4, what);
    const v = this.view.getFloat32(this.at, true);
    this.at += 4;
    return v;
  }
  f64(what: string): number {
    this.need(8, what);
    const v = this.view.getFloat64(this.at, true);
    this.at += 8;
    return v;
  }
  bytesField(what: string): Uint8Array {
    const n = this.u32(what);
    this.need(n, what);
    const out = this.bytes.subarray(this.at, this.at + n);
    this.at += n;
    return out;
  }
  string(what: string): string {
    try {
      return new TextDecoder("utf-8", { fatal: true }).decode(this.bytesField(what));
    } catch (e) {
      if (e instanceof WireError) throw e;
      throw new WireError(`${what} is not UTF-8`);
    }
  }
  option<T>(what: string, read: () => T): T | null {
    return this.bool(what) ? read() : null;
  }
  vec3(what: string): [number, number, number] {
    return [this.f32(what), this.f32(what), this.f32(what)];
  }
}

/// Writes postcard values.
class Writer {
  out: number[] = [];
  varint(v: number | bigint) {
    let x = BigInt(v);
    do {
      let b = Number(x & 0x7fn);
      x >>= 7n;
      if (x !== 0n) b |= 0x80;
      this.out.push(b);
    } while (x !== 0n);
  }
  bool(b: boolean) {
    this.out.push(b ? 1 : 0);
  }
  f32(v: number) {
    const b = new Uint8Array(4);
    new DataView(b.buffer).setFloat32(0, v, true);
    this.out.push(...b);
  }
  string(s: string) {
    const b = new TextEncoder().encode(s);
    this.varint(b.length);
    this.out.push(...b);
  }
}

function finite(what: string, values: number[]) {
  if (!values.every(Number.isFinite)) throw new WireError(`${what} is not finite`);
}

function readInstance(r: Reader): InstanceEntry {
  const e: InstanceEntry = {
    origin: r.vec3("origin"),
    cellSize: r.f32("cell size"),
    dims: [r.u32("dims"), r.u32("dims"), r.u32("dims")],
    layoutPoissonRadius: r.f32("layout poisson radius"),
    bucketCount: r.u32("bucket count"),
    poissonRadius: r.f32("poisson radius"),
    pointCount: r.u32("point count"),
  };
  finite("instance entry", [...e.origin, e.cellSize, e.layoutPoissonRadius, e.poissonRadius]);
  return e;
}

function readDelta(r: Reader): Delta {
  return {
    frame: r.u64n("frame"),
    sceneTime: r.f64("scene time"),
    clientFrame: r.option("client frame", () => r.u32("client frame")),
    stateHash: r.option("state hash", () => r.u64("state hash")),
    payload: r.bytesField("payload"),
  };
}

/// Decodes one message payload (no frame header).
export function decodePayload(payload: Uint8Array): Message {
  const r = new Reader(payload);
  const variant = r.u32("message kind");
  let m: Message;
  switch (variant) {
    case 0:
      m = {
        kind: "hello",
        hello: {
          version: r.u16("version"),
          capabilities: r.u32("capabilities"),
          token: r.option("token", () => r.string("token")),
          name: r.string("name"),
        },
      };
      break;
    case 1: {
      const w: Welcome = {
        version: r.u16("version"),
        clientId: r.u32("client id"),
        codec: r.string("codec"),
        serverHz: r.u32("server hz"),
        clientHz: r.u32("client hz"),
        lockstep: r.bool("lockstep"),
        scene: r.string("scene"),
        frame: r.u64n("frame"),
        sceneTime: r.f64("scene time"),
        instances: [],
      };
      const n = r.u32("instance count");
      // Each entry takes at least 27 bytes: a count beyond the payload is refused before
      // allocating.
      if (n > r.rest() / 27) throw new WireError(`instance count ${n} exceeds the payload`);
      for (let i = 0; i < n; i++) w.instances.push(readInstance(r));
      finite("scene time", [w.sceneTime]);
      m = { kind: "welcome", welcome: w };
      break;
    }
    case 2: {
      const c: Camera = {
        frame: r.u32("frame"),
        position: r.vec3("position"),
        target: r.vec3("target"),
        up: r.vec3("up"),
        fovY: r.f32("fov"),
        near: r.f32("near"),
        far: r.f32("far"),
        aspect: r.f32("aspect"),
      };
      m = { kind: "camera", camera: c };
      break;
    }
    case 3:
      m = {
        kind: "scene_time",
        frame: r.u64n("frame"),
        seconds: r.f64("seconds"),
        clientFrame: r.option("client frame", () => r.u32("client frame")),
      };
      break;
    case 4:
      m = { kind: "ack", frame: r.u64n("frame") };
      break;
    case 5:
      m = { kind: "delta", delta: readDelta(r) };
      break;
    case 6:
      m = { kind: "snapshot", delta: readDelta(r) };
      break;
    case 7: {
      const code = r.u32("error code");
      if (code >= ERROR_CODES.length) throw new WireError(`unknown error code ${code}`);
      m = { kind: "error", code: ERROR_CODES[code], message: r.string("error message") };
      break;
    }
    case 8:
      m = { kind: "bye", reason: r.string("reason") };
      break;
    case 11:
      m = { kind: "status", stalled: r.bool("stalled"), text: r.string("status text") };
      break;
    default:
      throw new WireError(`unknown message kind ${variant}`);
  }
  if (!r.done()) throw new WireError(`${r.rest()} bytes after the message`);
  return m;
}

/// Decodes one whole frame (header + payload, nothing after) with payload ≤ `limit`.
export function decodeFrame(frame: Uint8Array, limit = MAX_SERVER_FRAME): Message {
  if (frame.length < HEADER_LEN) throw new WireError(`truncated frame header (${frame.length} bytes)`);
  for (let i = 0; i < 4; i++) {
    if (frame[i] !== MAGIC[i]) throw new WireError("bad magic: not a psao frame");
  }
  const view = new DataView(frame.buffer, frame.byteOffset, frame.byteLength);
  const len = view.getUint32(4, true);
  const crc = view.getUint32(8, true);
  if (len > limit) throw new WireError(`payload of ${len} bytes exceeds the limit of ${limit}`);
  if (frame.length - HEADER_LEN < len) throw new WireError("truncated frame");
  if (frame.length - HEADER_LEN > len) throw new WireError("trailing bytes after the frame");
  const payload = frame.subarray(HEADER_LEN);
  if (crc32(payload) !== crc) throw new WireError("checksum mismatch");
  return decodePayload(payload);
}

function frameOf(payload: number[]): Uint8Array<ArrayBuffer> {
  const p = new Uint8Array(payload);
  const out = new Uint8Array(HEADER_LEN + p.length);
  out.set(MAGIC, 0);
  const view = new DataView(out.buffer);
  view.setUint32(4, p.length, true);
  view.setUint32(8, crc32(p), true);
  out.set(p, HEADER_LEN);
  return out;
}

/// The frame of a hello.
export function helloFrame(h: Hello): Uint8Array<ArrayBuffer> {
  const w = new Writer();
  w.varint(0);
  w.varint(h.version);
  w.varint(h.capabilities);
  w.bool(h.token !== null);
  if (h.token !== null) w.string(h.token);
  w.string(h.name);
  return frameOf(w.out);
}

/// The frame of a camera message.
export function cameraFrame(c: Camera): Uint8Array<ArrayBuffer> {
  const w = new Writer();
  w.varint(2);
  w.varint(c.frame);
  for (const v of [...c.position, ...c.target, ...c.up, c.fovY, c.near, c.far, c.aspect]) w.f32(v);
  return frameOf(w.out);
}

/// The frame of an ack of server frame `frame`.
export function ackFrame(frame: number): Uint8Array<ArrayBuffer> {
  const w = new Writer();
  w.varint(4);
  w.varint(frame);
  return frameOf(w.out);
}

/// The frame of a bye.
export function byeFrame(reason: string): Uint8Array<ArrayBuffer> {
  const w = new Writer();
  w.varint(8);
  w.string(reason);
  return frameOf(w.out);
}
