"use strict";
(() => {
  // src/codec.ts
  var TABLE_WORDS = 11;
  var DecodeError = class extends Error {
    constructor(message2, code) {
      super(message2);
      this.code = code;
    }
  };
  var Codec = class _Codec {
    constructor(exports) {
      this.exports = exports;
    }
    /// Instantiates the module from its bytes or a fetch of them.
    static async load(source) {
      const { instance } = source instanceof Promise ? await WebAssembly.instantiateStreaming(source) : await WebAssembly.instantiate(source);
      return new _Codec(instance.exports);
    }
    /// Copies `bytes` into a fresh wasm buffer; the caller frees it.
    put(bytes) {
      const ptr = this.exports.psao_alloc(bytes.length);
      new Uint8Array(this.exports.memory.buffer, ptr, bytes.length).set(bytes);
      return ptr;
    }
  };
  var ViewerState = class {
    /// An empty state for the welcome's table; a table the Rust client refuses throws.
    constructor(codec2, table) {
      this.codec = codec2;
      this.table = table;
      this.cached = [];
      this.transformsStale = true;
      const words = new Float64Array(table.length * TABLE_WORDS);
      table.forEach(
        (e, k) => words.set(
          [...e.origin, e.cellSize, ...e.dims, e.layoutPoissonRadius, e.bucketCount, e.poissonRadius, e.pointCount],
          k * TABLE_WORDS
        )
      );
      const bytes = new Uint8Array(words.buffer);
      const x = codec2.exports;
      const ptr = codec2.put(bytes);
      this.handle = x.psao_viewer_new(ptr, bytes.length);
      x.psao_free(ptr, bytes.length);
      const status2 = x.psao_table_status(this.handle);
      if (status2 !== 0) {
        const text = this.error();
        this.free();
        throw new DecodeError(text, status2);
      }
    }
    /// Decodes and applies one update payload (`snapshot`: its message was a snapshot); throws
    /// a DecodeError (the session must then end).
    apply(payload, snapshot) {
      const x = this.codec.exports;
      const ptr = this.codec.put(payload);
      const status2 = x.psao_apply(this.handle, ptr, payload.length, snapshot ? 1 : 0);
      x.psao_free(ptr, payload.length);
      this.transformsStale = true;
      if (status2 !== 0) throw new DecodeError(this.error(), status2);
    }
    /// Every instance's transform from the latest update carrying one (Affine3A: columns x, y,
    /// z, then translation, 12 floats), or null; read from the wasm once per applied update.
    get transforms() {
      if (this.transformsStale) {
        this.transformsStale = false;
        this.cached = Array.from({ length: this.instanceCount() }, (_, i) => this.transform(i));
      }
      return this.cached;
    }
    /// psao-client's state hash (compared with the server's).
    stateHash() {
      return BigInt.asUintN(64, this.codec.exports.psao_state_hash(this.handle));
    }
    /// Whether the state holds irradiance records (the server computes lighting).
    hasLights() {
      return this.codec.exports.psao_has_lights(this.handle) !== 0;
    }
    /// What the last update changed, as crates/psao-wasm/src/changes.rs lays it out: a view of
    /// wasm memory, valid until the next call on this state.
    changes() {
      const x = this.codec.exports;
      return new Uint32Array(x.memory.buffer, x.psao_changes_ptr(this.handle), x.psao_changes_len(this.handle));
    }
    /// Instances in the table.
    instanceCount() {
      return this.codec.exports.psao_instance_count(this.handle);
    }
    /// Hash buckets of an instance's grid, 0 when it has none (an unusable layout).
    bucketCount(instance) {
      return this.codec.exports.psao_bucket_count(this.handle, instance);
    }
    /// Cell slots an instance's layout addresses (0 without a grid).
    maxCells(instance) {
      return this.codec.exports.psao_max_cells(this.handle, instance);
    }
    /// Cell slots an instance's grid has allocated (0 without a grid).
    slotCount(instance) {
      return this.codec.exports.psao_slot_count(this.handle, instance);
    }
    /// Valid points over all grids.
    pointCount() {
      return this.codec.exports.psao_point_count(this.handle);
    }
    transform(instance) {
      const x = this.codec.exports;
      const ptr = x.psao_transform(this.handle, instance);
      return ptr === 0 ? null : new Float32Array(x.memory.buffer, ptr, 12).slice();
    }
    /// Frees the wasm side (the state is unusable afterwards).
    free() {
      if (this.handle !== 0) this.codec.exports.psao_viewer_free(this.handle);
      this.handle = 0;
    }
    error() {
      const x = this.codec.exports;
      const bytes = new Uint8Array(x.memory.buffer, x.psao_error_ptr(this.handle), x.psao_error_len(this.handle));
      return new TextDecoder().decode(bytes);
    }
  };

  // src/wire.ts
  var MAGIC = [80, 83, 87, 49];
  var HEADER_LEN = 12;
  var PROTOCOL_VERSION = 2;
  var MAX_SERVER_FRAME = 256 << 20;
  var CAP_CODEC_COMPACT = 2;
  var CAP_STATE_HASH = 4;
  var CAP_STATUS = 16;
  var ERROR_CODES = ["Version", "Token", "Frame", "Protocol", "Update", "Server"];
  var WireError = class extends Error {
  };
  var CRC_TABLE = (() => {
    const t = new Uint32Array(256);
    for (let n = 0; n < 256; n++) {
      let c = n;
      for (let k = 0; k < 8; k++) c = c & 1 ? 3988292384 ^ c >>> 1 : c >>> 1;
      t[n] = c >>> 0;
    }
    return t;
  })();
  function crc32(bytes) {
    let c = 4294967295;
    for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 255] ^ c >>> 8;
    return (c ^ 4294967295) >>> 0;
  }
  var Reader = class {
    constructor(bytes) {
      this.bytes = bytes;
      this.at = 0;
      this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    }
    need(n, what) {
      if (this.at + n > this.bytes.length) throw new WireError(`truncated ${what}`);
    }
    done() {
      return this.at === this.bytes.length;
    }
    rest() {
      return this.bytes.length - this.at;
    }
    varint(what, maxBits) {
      let v = 0n;
      for (let shift = 0n; ; shift += 7n) {
        this.need(1, what);
        const b = this.bytes[this.at++];
        v |= BigInt(b & 127) << shift;
        if ((b & 128) === 0) break;
        if (shift + 7n >= BigInt(maxBits + 7)) throw new WireError(`varint too long in ${what}`);
      }
      if (v >> BigInt(maxBits) !== 0n) throw new WireError(`${what} out of range`);
      return v;
    }
    u16(what) {
      return Number(this.varint(what, 16));
    }
    u32(what) {
      return Number(this.varint(what, 32));
    }
    /// A u64 that must fit a JS number exactly (frame counters).
    u64n(what) {
      const v = this.varint(what, 64);
      if (v > BigInt(Number.MAX_SAFE_INTEGER)) throw new WireError(`${what} too large`);
      return Number(v);
    }
    u64(what) {
      return this.varint(what, 64);
    }
    bool(what) {
      this.need(1, what);
      const b = this.bytes[this.at++];
      if (b > 1) throw new WireError(`bad bool in ${what}`);
      return b === 1;
    }
    f32(what) {
      this.need(4, what);
      const v = this.view.getFloat32(this.at, true);
      this.at += 4;
      return v;
    }
    f64(what) {
      this.need(8, what);
      const v = this.view.getFloat64(this.at, true);
      this.at += 8;
      return v;
    }
    bytesField(what) {
      const n = this.u32(what);
      this.need(n, what);
      const out = this.bytes.subarray(this.at, this.at + n);
      this.at += n;
      return out;
    }
    string(what) {
      try {
        return new TextDecoder("utf-8", { fatal: true }).decode(this.bytesField(what));
      } catch (e) {
        if (e instanceof WireError) throw e;
        throw new WireError(`${what} is not UTF-8`);
      }
    }
    option(what, read) {
      return this.bool(what) ? read() : null;
    }
    vec3(what) {
      return [this.f32(what), this.f32(what), this.f32(what)];
    }
  };
  var Writer = class {
    constructor() {
      this.out = [];
    }
    varint(v) {
      let x = BigInt(v);
      do {
        let b = Number(x & 0x7fn);
        x >>= 7n;
        if (x !== 0n) b |= 128;
        this.out.push(b);
      } while (x !== 0n);
    }
    bool(b) {
      this.out.push(b ? 1 : 0);
    }
    f32(v) {
      const b = new Uint8Array(4);
      new DataView(b.buffer).setFloat32(0, v, true);
      this.out.push(...b);
    }
    string(s) {
      const b = new TextEncoder().encode(s);
      this.varint(b.length);
      this.out.push(...b);
    }
  };
  function finite(what, values) {
    if (!values.every(Number.isFinite)) throw new WireError(`${what} is not finite`);
  }
  function readInstance(r) {
    const e = {
      origin: r.vec3("origin"),
      cellSize: r.f32("cell size"),
      dims: [r.u32("dims"), r.u32("dims"), r.u32("dims")],
      layoutPoissonRadius: r.f32("layout poisson radius"),
      bucketCount: r.u32("bucket count"),
      poissonRadius: r.f32("poisson radius"),
      pointCount: r.u32("point count")
    };
    finite("instance entry", [...e.origin, e.cellSize, e.layoutPoissonRadius, e.poissonRadius]);
    return e;
  }
  function readDelta(r) {
    return {
      frame: r.u64n("frame"),
      sceneTime: r.f64("scene time"),
      clientFrame: r.option("client frame", () => r.u32("client frame")),
      stateHash: r.option("state hash", () => r.u64("state hash")),
      payload: r.bytesField("payload")
    };
  }
  function decodePayload(payload) {
    const r = new Reader(payload);
    const variant = r.u32("message kind");
    let m;
    switch (variant) {
      case 0:
        m = {
          kind: "hello",
          hello: {
            version: r.u16("version"),
            capabilities: r.u32("capabilities"),
            token: r.option("token", () => r.string("token")),
            name: r.string("name")
          }
        };
        break;
      case 1: {
        const w = {
          version: r.u16("version"),
          clientId: r.u32("client id"),
          codec: r.string("codec"),
          serverHz: r.u32("server hz"),
          clientHz: r.u32("client hz"),
          lockstep: r.bool("lockstep"),
          scene: r.string("scene"),
          frame: r.u64n("frame"),
          sceneTime: r.f64("scene time"),
          instances: []
        };
        const n = r.u32("instance count");
        if (n > r.rest() / 27) throw new WireError(`instance count ${n} exceeds the payload`);
        for (let i = 0; i < n; i++) w.instances.push(readInstance(r));
        finite("scene time", [w.sceneTime]);
        m = { kind: "welcome", welcome: w };
        break;
      }
      case 2: {
        const c = {
          frame: r.u32("frame"),
          position: r.vec3("position"),
          target: r.vec3("target"),
          up: r.vec3("up"),
          fovY: r.f32("fov"),
          near: r.f32("near"),
          far: r.f32("far"),
          aspect: r.f32("aspect")
        };
        m = { kind: "camera", camera: c };
        break;
      }
      case 3:
        m = {
          kind: "scene_time",
          frame: r.u64n("frame"),
          seconds: r.f64("seconds"),
          clientFrame: r.option("client frame", () => r.u32("client frame"))
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
  function decodeFrame(frame, limit = MAX_SERVER_FRAME) {
    if (frame.length < HEADER_LEN) throw new WireError(`truncated frame header (${frame.length} bytes)`);
    for (let i = 0; i < 4; i++) {
      if (frame[i] !== MAGIC[i]) throw new WireError("bad magic: not a psao frame");
    }
    const view = new DataView(frame.buffer, frame.byteOffset, frame.byteLength);
    const len2 = view.getUint32(4, true);
    const crc = view.getUint32(8, true);
    if (len2 > limit) throw new WireError(`payload of ${len2} bytes exceeds the limit of ${limit}`);
    if (frame.length - HEADER_LEN < len2) throw new WireError("truncated frame");
    if (frame.length - HEADER_LEN > len2) throw new WireError("trailing bytes after the frame");
    const payload = frame.subarray(HEADER_LEN);
    if (crc32(payload) !== crc) throw new WireError("checksum mismatch");
    return decodePayload(payload);
  }
  function frameOf(payload) {
    const p = new Uint8Array(payload);
    const out = new Uint8Array(HEADER_LEN + p.length);
    out.set(MAGIC, 0);
    const view = new DataView(out.buffer);
    view.setUint32(4, p.length, true);
    view.setUint32(8, crc32(p), true);
    out.set(p, HEADER_LEN);
    return out;
  }
  function helloFrame(h) {
    const w = new Writer();
    w.varint(0);
    w.varint(h.version);
    w.varint(h.capabilities);
    w.bool(h.token !== null);
    if (h.token !== null) w.string(h.token);
    w.string(h.name);
    return frameOf(w.out);
  }
  function cameraFrame(c) {
    const w = new Writer();
    w.varint(2);
    w.varint(c.frame);
    for (const v of [...c.position, ...c.target, ...c.up, c.fovY, c.near, c.far, c.aspect]) w.f32(v);
    return frameOf(w.out);
  }
  function ackFrame(frame) {
    const w = new Writer();
    w.varint(4);
    w.varint(frame);
    return frameOf(w.out);
  }
  function byeFrame(reason) {
    const w = new Writer();
    w.varint(8);
    w.string(reason);
    return frameOf(w.out);
  }

  // src/session.ts
  var KEEP_ALIVE_MS = 5e3;
  var HASH_SHARE = 0.1;
  var Session = class {
    constructor(codec2, opts, handler) {
      this.codec = codec2;
      this.opts = opts;
      this.handler = handler;
      this.state = null;
      this.welcomeMsg = null;
      this.bytes = 0;
      this.updates = 0;
      this.mismatches = 0;
      this.lastHash = null;
      /// Milliseconds spent decoding and applying updates (hash checks excluded).
      this.decodeMs = 0;
      this.done = false;
      /// When the last frame went to the server (ms, `performance.now()`).
      this.lastSent = 0;
      this.lastAck = 0;
      this.keepAlive = null;
      /// When the next hash check is due (ms, `performance.now()`).
      this.nextCheck = 0;
      this.ws = new WebSocket(opts.url);
      this.ws.binaryType = "arraybuffer";
      this.ws.onopen = () => {
        const caps = CAP_CODEC_COMPACT | CAP_STATUS | (opts.verify ? CAP_STATE_HASH : 0);
        this.send(helloFrame({ version: PROTOCOL_VERSION, capabilities: caps, token: opts.token, name: opts.name }));
        this.keepAlive = setInterval(() => {
          if (performance.now() - this.lastSent >= KEEP_ALIVE_MS) this.send(ackFrame(this.lastAck));
        }, KEEP_ALIVE_MS);
      };
      this.ws.onmessage = (ev) => {
        if (this.done) return;
        if (!(ev.data instanceof ArrayBuffer)) return this.fail("text WebSocket message (frames are binary)", true);
        const bytes = new Uint8Array(ev.data);
        this.bytes += bytes.length;
        try {
          this.handle(decodeFrame(bytes), bytes.length);
        } catch (e) {
          const what = e instanceof DecodeError ? "bad update" : "bad frame";
          this.fail(`${what} from the server: ${e.message}`, true);
        }
      };
      this.ws.onclose = () => this.end("the connection closed", false);
      this.ws.onerror = () => this.end("the connection failed", false);
    }
    handle(m, size) {
      switch (m.kind) {
        case "welcome": {
          const w = m.welcome;
          if (w.version !== PROTOCOL_VERSION) {
            return this.fail(`the server speaks protocol version ${w.version}, this viewer ${PROTOCOL_VERSION}`, true);
          }
          if (w.codec !== "compact") return this.fail(`the server's codec \`${w.codec}\` is not supported`, true);
          this.welcomeMsg = w;
          this.state?.free();
          this.state = new ViewerState(this.codec, w.instances);
          this.handler.welcome(w);
          return;
        }
        case "delta":
        case "snapshot": {
          if (!this.state) return this.fail("update before the welcome", true);
          const t0 = performance.now();
          this.state.apply(m.delta.payload, m.kind === "snapshot");
          this.decodeMs += performance.now() - t0;
          this.updates++;
          let verified = false;
          const start = performance.now();
          const due = this.welcomeMsg?.lockstep === true || start >= this.nextCheck;
          if (m.delta.stateHash !== null && due) {
            this.lastHash = this.state.stateHash();
            this.nextCheck = start + (performance.now() - start) / HASH_SHARE;
            verified = this.lastHash === m.delta.stateHash;
            if (!verified) this.mismatches++;
          }
          this.lastAck = m.delta.frame;
          this.send(ackFrame(m.delta.frame));
          this.handler.update(m.delta.frame, size, verified);
          this.handler.sceneTime?.(m.delta.frame, m.delta.clientFrame, m.delta.sceneTime);
          return;
        }
        case "scene_time":
          this.handler.sceneTime?.(m.frame, m.clientFrame, m.seconds);
          return;
        case "error": {
          const fatal = m.code === "Token" || m.code === "Version";
          const text = m.code === "Token" ? `wrong or missing token: ${m.message}` : m.code === "Version" ? `protocol version mismatch: ${m.message}` : `server error (${m.code}): ${m.message}`;
          return this.fail(text, fatal);
        }
        case "bye":
          return this.end(`the server said bye: ${m.reason}`, false);
        case "status":
          this.handler.status?.(m.stalled ? m.text : null);
          return;
        default:
          return this.fail(`unexpected ${m.kind} from the server`, true);
      }
    }
    /// Sends the client's camera.
    sendCamera(c) {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.send(cameraFrame(c));
    }
    send(frame) {
      this.lastSent = performance.now();
      this.ws.send(frame);
    }
    /// Frees the session's state in wasm memory (when a new session replaces this one).
    release() {
      this.state?.free();
      this.state = null;
    }
    /// Ends the session with a bye.
    close() {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.send(byeFrame("done"));
      this.end("closed by the viewer", true);
      this.ws.close();
    }
    fail(reason, fatal) {
      this.end(reason, fatal);
      this.ws.close();
    }
    end(reason, fatal) {
      if (this.done) return;
      this.done = true;
      if (this.keepAlive !== null) clearInterval(this.keepAlive);
      this.handler.closed(reason, fatal);
    }
  };

  // src/bounds.ts
  function sceneBounds(glb) {
    const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
    if (glb.length < 20 || view.getUint32(0, true) !== 1179937895) return null;
    const jsonLen = view.getUint32(12, true);
    if (view.getUint32(16, true) !== 1313821514 || 20 + jsonLen > glb.length) return null;
    const doc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (const node of doc.nodes ?? []) {
      if (node.mesh === void 0 || !node.matrix) continue;
      const m = node.matrix;
      for (const prim of doc.meshes?.[node.mesh]?.primitives ?? []) {
        const acc = prim.attributes.POSITION !== void 0 ? doc.accessors?.[prim.attributes.POSITION] : void 0;
        if (!acc?.min || !acc.max) continue;
        for (let corner = 0; corner < 8; corner++) {
          const p = [0, 1, 2].map((k) => corner >> k & 1 ? acc.max[k] : acc.min[k]);
          for (let r = 0; r < 3; r++) {
            const v = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r];
            lo[r] = Math.min(lo[r], v);
            hi[r] = Math.max(hi[r], v);
          }
        }
      }
    }
    if (!(lo[0] <= hi[0])) return null;
    const centre = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
    const radius = Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2, 1e-3);
    return { centre, radius };
  }

  // src/grids.ts
  var CELL_POINTS = 7;
  var BUCKET = 0;
  var CELL = 1;
  var RESET = 2;
  var TEX_WIDTH = 1024;
  var CELL_PAGE = 32;
  var NO_PAGE = 4294967295;
  var MAX_POOL_TEXELS = 1 << 28;
  var DataTexture = class {
    constructor(gl2, channels) {
      this.gl = gl2;
      this.channels = channels;
      /// The texture (immutable storage: growing makes a new one).
      this.texture = null;
      this.mirror = new Uint32Array(0);
      this.rows = 0;
      this.dirty = new Uint8Array(0);
      this.anyDirty = false;
      this.stale = true;
    }
    /// Words per texel.
    get words() {
      return this.channels;
    }
    /// Makes room for `texels` (rows doubling), keeping the contents; `fill` initialises new words.
    ensure(texels, fill = 0) {
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
    reset(value) {
      this.mirror.fill(value);
      this.dirty.fill(1);
      this.anyDirty = true;
    }
    /// Marks the rows of texels `first..first + count` for upload.
    touch(first, count) {
      const last = Math.floor((first + count - 1) / TEX_WIDTH);
      for (let r = Math.floor(first / TEX_WIDTH); r <= last; r++) this.dirty[r] = 1;
      this.anyDirty = true;
    }
    /// Bytes of texture storage.
    bytes() {
      return this.mirror.byteLength;
    }
    /// (Re)creates the texture when it grew, then uploads runs of dirty rows; returns the
    /// bytes uploaded.
    upload() {
      const gl2 = this.gl;
      if (this.rows === 0) return 0;
      if (this.stale) {
        this.stale = false;
        if (this.texture) gl2.deleteTexture(this.texture);
        this.texture = gl2.createTexture();
        gl2.bindTexture(gl2.TEXTURE_2D, this.texture);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
        gl2.texStorage2D(gl2.TEXTURE_2D, 1, this.channels === 1 ? gl2.R32UI : gl2.RGBA32UI, TEX_WIDTH, this.rows);
      }
      if (!this.anyDirty) return 0;
      gl2.bindTexture(gl2.TEXTURE_2D, this.texture);
      const format = this.channels === 1 ? gl2.RED_INTEGER : gl2.RGBA_INTEGER;
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
        gl2.texSubImage2D(gl2.TEXTURE_2D, 0, 0, r, TEX_WIDTH, end - r, format, gl2.UNSIGNED_INT, data);
        bytes += data.byteLength;
        r = end;
      }
      this.anyDirty = false;
      return bytes;
    }
  };
  var ChunkPool = class {
    constructor() {
      this.end = 0;
      this.free = [[], [], [], []];
    }
    /// Forgets every chunk.
    clear() {
      this.end = 0;
      for (const f2 of this.free) f2.length = 0;
    }
    /// A chunk of size class `c` (2^c texels); returns its first texel.
    alloc(c) {
      const reused = this.free[c].pop();
      if (reused !== void 0) return reused;
      const first = this.end;
      this.end += 1 << c;
      return first;
    }
    release(first, c) {
      this.free[c].push(first);
    }
    /// Texels in use or free (the pool's high-water mark).
    get texels() {
      return this.end;
    }
  };
  function sizeClass(count) {
    return count <= 1 ? 0 : count <= 2 ? 1 : count <= 4 ? 2 : 3;
  }
  var GridTextures = class {
    constructor(gl2) {
      this.gl = gl2;
      this.slots = [];
      /// Why AO cannot be drawn (textures too large), or null.
      this.problem = null;
      /// Bytes uploaded so far and full rebuilds.
      this.uploadedBytes = 0;
      this.rebuilds = 0;
      this.pool = new ChunkPool();
      /// Pages of cells allocated (0 until the grids hold points).
      this.cellPages = 0;
      /// Whether an irradiance record arrived in this session (the irradiance pool exists).
      this.lit = false;
      this.directory = new DataTexture(gl2, 1);
      this.entries = new DataTexture(gl2, 4);
      this.pageTable = new DataTexture(gl2, 1);
      this.cells = new DataTexture(gl2, 4);
      this.lights = new DataTexture(gl2, 4);
    }
    /// Follows a new session's (empty) state: lays out its directory and page table.
    reset(state) {
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
      const maxRows = this.gl.getParameter(this.gl.MAX_TEXTURE_SIZE);
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
    apply(changes) {
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
      this.uploadedBytes += this.directory.upload() + this.entries.upload() + this.pageTable.upload() + this.cells.upload() + this.lights.upload();
    }
    /// Bytes of texture storage in use.
    textureBytes() {
      return this.directory.bytes() + this.entries.bytes() + this.pageTable.bytes() + this.cells.bytes() + this.lights.bytes();
    }
    /// Bucket `b` of an instance: its used entries (key low, key high, cell slot each) into a
    /// chunk of the pool.
    setBucket(slot, b, entries) {
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
      dir[at] = count === 0 ? 0 : (first << 4 | count) >>> 0;
      this.directory.touch(at, 1);
    }
    /// Cell slot `s` of an instance (its point words, then their irradiance records), into its
    /// page (allocated when it first holds points or records).
    setCell(slot, s, words) {
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
      const texel = 2 * (page * CELL_PAGE + s % CELL_PAGE);
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
    clear() {
      this.rebuilds++;
      this.pool.clear();
      this.cellPages = 0;
      this.directory.reset(0);
      this.pageTable.reset(NO_PAGE);
    }
  };

  // src/lights.ts
  var MAX_SUNS = 4;
  var MAX_POINT_LIGHTS = 8;
  var f = Math.fround;
  function vec3(v, what) {
    if (!Array.isArray(v) || v.length !== 3 || !v.every((x) => typeof x === "number" && Number.isFinite(x))) {
      throw new Error(`${what} must be 3 finite numbers`);
    }
    return [v[0], v[1], v[2]];
  }
  function normalize(v, what) {
    const l = Math.hypot(v[0], v[1], v[2]);
    if (!(l * l >= 1e-12)) throw new Error(`${what} must be non-zero`);
    return [f(v[0] / l), f(v[1] / l), f(v[2] / l)];
  }
  var dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  function slerp(a, b, s) {
    const angle = Math.acos(Math.min(1, Math.max(-1, dot(a, b))));
    if (angle < 1e-7) return a;
    const sa = Math.sin((1 - s) * angle) / Math.sin(angle);
    const sb = Math.sin(s * angle) / Math.sin(angle);
    return normalize([sa * a[0] + sb * b[0], sa * a[1] + sb * b[1], sa * a[2] + sb * b[2]], "sun direction");
  }
  function directionAt(keys, t) {
    const last = keys.times[keys.times.length - 1];
    if (last > 0 && Number.isFinite(t)) t = (t % last + last) % last;
    let k = 0;
    while (k < keys.times.length && keys.times[k] <= t) k++;
    if (k === 0) return keys.directions[0];
    if (k === keys.times.length) return keys.directions[k - 1];
    const [t0, t1] = [keys.times[k - 1], keys.times[k]];
    return slerp(keys.directions[k - 1], keys.directions[k], t1 > t0 ? (t - t0) / (t1 - t0) : 1);
  }
  function keysOf(v, what) {
    const k = v;
    if (typeof k !== "object" || k === null || !Array.isArray(k.times) || !Array.isArray(k.directions)) {
      throw new Error(`${what}: keys need times and directions`);
    }
    const times = k.times;
    if (times.length === 0 || !times.every((t) => typeof t === "number" && Number.isFinite(t))) {
      throw new Error(`${what}: key times must be a non-empty list of finite seconds`);
    }
    const ts = times;
    if (ts.some((t, i) => i > 0 && t < ts[i - 1])) throw new Error(`${what}: key times must not decrease`);
    if (k.directions.length !== ts.length) throw new Error(`${what}: ${k.directions.length} key directions for ${ts.length} times`);
    const directions = k.directions.map((d, i) => normalize(vec3(d, `${what} key ${i}`), `${what} key ${i}`));
    if (directions.some((d, i) => i > 0 && dot(d, directions[i - 1]) < -0.9999)) {
      throw new Error(`${what}: consecutive key directions are opposite`);
    }
    return { times: ts, directions };
  }
  var SceneLights = class {
    /// Parses `extras.psao_lights` (absent: no lights); throws on a malformed entry or more
    /// lights than the shader takes.
    constructor(doc) {
      this.suns = [];
      this.points = [];
      if (doc === void 0) return;
      if (!Array.isArray(doc)) throw new Error("extras.psao_lights must be a list");
      doc.forEach((entry, i) => {
        const what = `light ${i}`;
        const l = entry;
        if (typeof l !== "object" || l === null) throw new Error(`${what} is not an object`);
        const colour = vec3(l.color, `${what} colour`);
        if (colour.some((c) => c < 0 || c > 1)) throw new Error(`${what}: colour must be in [0, 1]`);
        const power = l.power;
        if (typeof power !== "number" || !Number.isFinite(power) || power < 0) throw new Error(`${what}: power must be a non-negative number`);
        const strength = [f(colour[0] * power), f(colour[1] * power), f(colour[2] * power)];
        if (l.kind === "sun") {
          const direction = normalize(vec3(l.direction, `${what} direction`), `${what} direction`);
          const keys = l.keys === void 0 ? null : keysOf(l.keys, what);
          this.suns.push({ direction, irradiance: strength, keys });
        } else if (l.kind === "point") {
          this.points.push({ position: vec3(l.position, `${what} position`), intensity: strength });
        } else {
          throw new Error(`${what}: unknown kind ${JSON.stringify(l.kind)}`);
        }
      });
      if (this.suns.length > MAX_SUNS) throw new Error(`${this.suns.length} suns: the viewer draws at most ${MAX_SUNS}`);
      if (this.points.length > MAX_POINT_LIGHTS) {
        throw new Error(`${this.points.length} point lights: the viewer draws at most ${MAX_POINT_LIGHTS}`);
      }
    }
    /// The suns at scene time `t` seconds.
    sunsAt(t) {
      return this.suns.map((s) => ({ direction: s.keys ? directionAt(s.keys, t) : s.direction, irradiance: s.irradiance }));
    }
  };

  // src/shadow.ts
  function settingsForImage(width, height) {
    const side = Math.max(width, height);
    const clamp = (v, lo, hi) => Math.min(Math.max(v, lo), hi);
    return { sunResolution: clamp(side, 256, 2048), cascades: 3, pointResolution: clamp(Math.floor(side / 2), 64, 512), pcf: 1 };
  }
  var SUN_DISTANCE = 256;
  var LOG_SPLIT = 0.9;
  var sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  var add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  var mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  var len = (a) => Math.hypot(a[0], a[1], a[2]);
  var cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  function normalizeOrZero(a) {
    const l = len(a);
    return l > 0 && Number.isFinite(l) ? mul(a, 1 / l) : [0, 0, 0];
  }
  function boxSphere(lo, hi) {
    return { centre: mul(add(lo, hi), 0.5), radius: Math.max(len(sub(hi, lo)) * 0.5, 1e-3) };
  }
  function cascadeSpheres(camera, aspect, lo, hi, count) {
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
    const split = (k) => {
      const f2 = k / count;
      return (1 - LOG_SPLIT) * (near + (far - near) * f2) + LOG_SPLIT * near * Math.pow(far / near, f2);
    };
    const out = [];
    for (let k = 0; k < count; k++) {
      const corners = [];
      for (const d of [split(k), split(k + 1)]) {
        for (const [sx, sy] of [[-1, -1], [1, -1], [-1, 1], [1, 1]]) {
          corners.push(add(camera.position, mul(add(forward, add(mul(right, sx * tanX), mul(up, sy * tanY))), d)));
        }
      }
      const centre = mul(corners.reduce(add, [0, 0, 0]), 1 / corners.length);
      const radius = Math.max(0, ...corners.map((c) => len(sub(c, centre))));
      out.push(radius < scene.radius ? { centre, radius } : scene);
    }
    return out;
  }
  function sunCamera(direction, s, lo, hi) {
    const scene = boxSphere(lo, hi);
    const reach = Math.max(len(sub(scene.centre, s.centre)) + scene.radius, s.radius);
    const distance = SUN_DISTANCE * reach;
    return {
      position: add(s.centre, mul(direction, distance)),
      target: s.centre,
      up: Math.abs(direction[1]) < 0.9 ? [0, 1, 0] : [1, 0, 0],
      fovY: 2 * Math.asin(s.radius / distance),
      near: distance - 1.01 * reach,
      far: distance + 1.01 * reach
    };
  }
  function faceCameras(position, lo, hi, res, pcf) {
    const scene = boxSphere(lo, hi);
    const far = (len(sub(scene.centre, position)) + scene.radius) * 1.01;
    const near = Math.max(far * 1e-5, 1e-4);
    const fovY = 2 * Math.atan(1 + 2 * (pcf + 1) / res);
    const face = (axis, up) => ({ position, target: add(position, axis), up, fovY, near, far });
    return [
      face([1, 0, 0], [0, 1, 0]),
      face([-1, 0, 0], [0, 1, 0]),
      face([0, 1, 0], [0, 0, 1]),
      face([0, -1, 0], [0, 0, 1]),
      face([0, 0, 1], [0, 1, 0]),
      face([0, 0, -1], [0, 1, 0])
    ];
  }
  var MAP_TEXELS = 6;
  var MapArray = class {
    constructor(gl2) {
      this.gl = gl2;
      this.texture = null;
      this.depth = null;
      this.size = 0;
      this.layers = 0;
    }
    ensure(size, layers) {
      if (size === this.size && layers <= this.layers) return;
      const gl2 = this.gl;
      if (this.texture) gl2.deleteTexture(this.texture);
      if (this.depth) gl2.deleteRenderbuffer(this.depth);
      this.size = size;
      this.layers = Math.max(layers, 1);
      this.texture = gl2.createTexture();
      gl2.bindTexture(gl2.TEXTURE_2D_ARRAY, this.texture);
      gl2.texParameteri(gl2.TEXTURE_2D_ARRAY, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
      gl2.texParameteri(gl2.TEXTURE_2D_ARRAY, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
      gl2.texStorage3D(gl2.TEXTURE_2D_ARRAY, 1, gl2.R32F, size, size, this.layers);
      this.depth = gl2.createRenderbuffer();
      gl2.bindRenderbuffer(gl2.RENDERBUFFER, this.depth);
      gl2.renderbufferStorage(gl2.RENDERBUFFER, gl2.DEPTH_COMPONENT24, size, size);
    }
  };
  var ShadowMaps = class {
    constructor(gl2) {
      this.gl = gl2;
      /// The lights drawn this frame.
      this.sunLights = [];
      this.pointLights = [];
      this.settings = settingsForImage(1, 1);
      /// Maps rendered at scale× (odd), the lookup reading each texel's centre sample.
      this.scale = 1;
      this.suns = new MapArray(gl2);
      this.points = new MapArray(gl2);
      this.table = gl2.createTexture();
      gl2.bindTexture(gl2.TEXTURE_2D, this.table);
      gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
      gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, MAP_TEXELS, 1, 0, gl2.RGBA, gl2.FLOAT, new Float32Array(MAP_TEXELS * 4));
      this.fbo = gl2.createFramebuffer();
    }
    /// Renders the maps of `suns` and `points` for the scene within bounds (`lo`, `hi`), the
    /// cascades fitted to `camera` at `aspect`; `viewProj` makes a map camera's matrix and
    /// `draw` draws the scene with the depth program.
    render(program2, draw, viewProj2, frame) {
      const gl2 = this.gl;
      const { settings, bounds } = frame;
      this.settings = settings;
      this.scale = Math.max(1, Math.floor(frame.scale) | 1);
      this.sunLights = bounds ? frame.suns.filter((s) => len(s.direction) > 0).slice(0, MAX_SUNS) : [];
      this.pointLights = bounds ? frame.points.slice(0, MAX_POINT_LIGHTS) : [];
      if (!bounds) return;
      const [lo, hi] = bounds;
      const maps = [];
      this.sunLights.forEach((s, i) => {
        cascadeSpheres(frame.camera, frame.aspect, lo, hi, settings.cascades).forEach((sphere, k) => {
          maps.push({ camera: sunCamera(s.direction, sphere, lo, hi), res: settings.sunResolution, array: this.suns, layer: i * settings.cascades + k });
        });
      });
      this.pointLights.forEach((p, i) => {
        faceCameras(p.position, lo, hi, settings.pointResolution, settings.pcf).forEach((camera, f2) => {
          maps.push({ camera, res: settings.pointResolution, array: this.points, layer: i * 6 + f2 });
        });
      });
      this.suns.ensure(settings.sunResolution * this.scale, this.sunLights.length * settings.cascades);
      this.points.ensure(settings.pointResolution * this.scale, this.pointLights.length * 6);
      const table = new Float32Array(Math.max(maps.length, 1) * MAP_TEXELS * 4);
      gl2.useProgram(program2.p);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, this.fbo);
      gl2.enable(gl2.DEPTH_TEST);
      gl2.depthFunc(gl2.LESS);
      maps.forEach((m, i) => {
        const vp = viewProj2(m.camera);
        const forward = normalizeOrZero(sub(m.camera.target, m.camera.position));
        table.set(vp, i * MAP_TEXELS * 4);
        table.set([...m.camera.position, 2 * Math.tan(m.camera.fovY * 0.5) / m.res, ...forward, m.res], i * MAP_TEXELS * 4 + 16);
        const size = m.res * this.scale;
        gl2.framebufferTextureLayer(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT0, m.array.texture, 0, m.layer);
        gl2.framebufferRenderbuffer(gl2.FRAMEBUFFER, gl2.DEPTH_ATTACHMENT, gl2.RENDERBUFFER, m.array.depth);
        gl2.drawBuffers([gl2.COLOR_ATTACHMENT0]);
        gl2.viewport(0, 0, size, size);
        gl2.clearBufferfv(gl2.COLOR, 0, [3e38, 0, 0, 0]);
        gl2.clearBufferfi(gl2.DEPTH_STENCIL, 0, 1, 0);
        gl2.uniform3fv(program2.u.u_origin, m.camera.position);
        gl2.uniform3fv(program2.u.u_forward, forward);
        draw(program2, vp);
      });
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, null);
      gl2.disable(gl2.DEPTH_TEST);
      gl2.bindTexture(gl2.TEXTURE_2D, this.table);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, MAP_TEXELS, Math.max(maps.length, 1), 0, gl2.RGBA, gl2.FLOAT, table);
    }
    /// The lookup's uniforms, set on the bound lit program.
    setUniforms(u) {
      const gl2 = this.gl;
      const flat = (vs, n) => {
        const a = new Float32Array(n * 3);
        vs.forEach((v, i) => a.set(v, i * 3));
        return a;
      };
      gl2.uniform1i(u.u_sun_count, this.sunLights.length);
      gl2.uniform3fv(u["u_sun_dir[0]"], flat(this.sunLights.map((s) => s.direction), MAX_SUNS));
      gl2.uniform3fv(u["u_sun_irr[0]"], flat(this.sunLights.map((s) => s.irradiance), MAX_SUNS));
      gl2.uniform1i(u.u_point_count, this.pointLights.length);
      gl2.uniform3fv(u["u_point_pos[0]"], flat(this.pointLights.map((p) => p.position), MAX_POINT_LIGHTS));
      gl2.uniform3fv(u["u_point_int[0]"], flat(this.pointLights.map((p) => p.intensity), MAX_POINT_LIGHTS));
      gl2.uniform1i(u.u_cascades, this.settings.cascades);
      gl2.uniform1i(u.u_pcf, this.settings.pcf);
      gl2.uniform1i(u.u_shadow_scale, this.scale);
    }
  };
  var SHADOW_FRAGMENT = `#version 300 es
precision highp float;
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_origin;
uniform vec3 u_forward;
layout(location = 0) out float out_depth;
void main() {
  out_depth = dot(v_world - u_origin, u_forward);
}`;
  var SHADOW_GLSL = `
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

  // src/skin.ts
  var JOINT_TEXELS = 7;
  var Animation = class {
    constructor(doc, instances, read) {
      this.clips = [];
      this.rigs = [];
      const nodes = doc.nodes ?? [];
      this.rest = nodes.map((n) => ({ t: n.translation ?? [0, 0, 0], r: n.rotation ?? [0, 0, 0, 1], s: n.scale ?? [1, 1, 1] }));
      this.parents = nodes.map(() => null);
      nodes.forEach((n, p) => n.children?.forEach((c) => this.parents[c] = p));
      this.order = parentsFirst(this.parents);
      for (const a of (doc.extras?.psao_playing ?? []).map((k) => doc.animations?.[k])) {
        if (!a) continue;
        const channels = [];
        for (const ch of a.channels) {
          const s = a.samplers[ch.sampler];
          if (!s || ch.target.node === void 0 || !["translation", "rotation", "scale"].includes(ch.target.path)) continue;
          channels.push({
            node: ch.target.node,
            path: ch.target.path,
            interpolation: s.interpolation ?? "LINEAR",
            times: Float32Array.from(read(s.input)),
            values: Float32Array.from(read(s.output))
          });
        }
        const duration = channels.reduce((d, c) => Math.max(d, c.times.length ? c.times[c.times.length - 1] : 0), 0);
        this.clips.push({ duration, channels });
      }
      this.jointBase = new Int32Array(instances).fill(-1);
      let base = 0;
      for (let i = 0; i < Math.min(instances, nodes.length); i++) {
        const n = nodes[i];
        const skin = n.skin !== void 0 ? doc.skins?.[n.skin] : void 0;
        if (!n.extras?.psao_skinned || !skin) continue;
        const ibm = skin.inverseBindMatrices !== void 0 ? read(skin.inverseBindMatrices) : null;
        const inverseBind = skin.joints.map(
          (_, j) => ibm ? Float64Array.from(ibm.subarray(16 * j, 16 * j + 16)) : identity()
        );
        this.rigs.push({
          instance: i,
          joints: skin.joints,
          inverseBind,
          node: n.extras.psao_node ?? null,
          rest: Float64Array.from(n.matrix ?? identity()),
          base
        });
        this.jointBase[i] = base;
        base += skin.joints.length;
      }
      this.jointCount = base;
    }
    /// Whether any instance is skinned.
    get skinned() {
      return this.rigs.length > 0;
    }
    /// Every rig's joint matrices at scene time `time` (seconds), `JOINT_TEXELS` RGBA texels
    /// per joint from `jointBase[instance]`.
    jointTexels(time) {
      const world = this.worlds(time);
      const out = new Float32Array(Math.max(1, this.jointCount) * JOINT_TEXELS * 4);
      for (const rig of this.rigs) {
        const own = rig.node !== null && world[rig.node] ? world[rig.node] : rig.rest;
        const toLocal = invertOrIdentity(own);
        rig.joints.forEach((j, k) => {
          const m = mul2(mul2(toLocal, world[j] ?? identity()), rig.inverseBind[k]);
          const at = (rig.base + k) * JOINT_TEXELS * 4;
          out.set(m, at);
          out.set(normalMatrix(m), at + 16);
        });
      }
      return out;
    }
    /// World transforms of all nodes at `time` (psao-scene's `node_worlds`, without walkers).
    worlds(time) {
      const local = this.rest.map((n) => ({ t: n.t.slice(), r: n.r.slice(), s: n.s.slice() }));
      for (const clip of this.clips) {
        const t = clip.duration > 0 ? remEuclid(time, clip.duration) : 0;
        for (const ch of clip.channels) {
          const slot = local[ch.node];
          if (!slot) continue;
          const v = sample(ch, t);
          if (ch.path === "rotation") slot.r = v;
          else if (ch.path === "scale") slot.s = v;
          else slot.t = v;
        }
      }
      const world = new Array(local.length);
      for (const n of this.order) {
        const l = trs(local[n].t, local[n].r, local[n].s);
        const p = this.parents[n];
        world[n] = p === null ? l : mul2(world[p], l);
      }
      return world;
    }
  };
  function remEuclid(a, b) {
    const r = a % b;
    return r < 0 ? r + b : r;
  }
  function parentsFirst(parents) {
    const children = parents.map(() => []);
    parents.forEach((p, i) => p !== null && children[p]?.push(i));
    const order = parents.flatMap((p, i) => p === null ? [i] : []);
    for (let k = 0; k < order.length; k++) order.push(...children[order[k]]);
    return order;
  }
  function sample(ch, t) {
    const w = ch.path === "rotation" ? 4 : 3;
    const cubic = ch.interpolation === "CUBICSPLINE";
    const valueAt = (k, part = 1) => {
      const start = cubic ? (3 * k + part) * w : k * w;
      return Array.from(ch.values.subarray(start, start + w));
    };
    const times = ch.times;
    let next = 0;
    while (next < times.length && times[next] <= t) next++;
    let raw;
    if (next === 0) raw = valueAt(0);
    else if (next === times.length) raw = valueAt(times.length - 1);
    else {
      const k = next - 1;
      const dt = times[k + 1] - times[k];
      const s = (t - times[k]) / dt;
      if (ch.interpolation === "STEP") raw = valueAt(k);
      else if (ch.interpolation === "LINEAR") {
        if (ch.path === "rotation") return normalize2(slerp2(normalize2(valueAt(k)), normalize2(valueAt(k + 1)), s));
        const a = valueAt(k);
        const b = valueAt(k + 1);
        raw = a.map((x, i) => x + (b[i] - x) * s);
      } else {
        const p0 = valueAt(k);
        const m0 = valueAt(k, 2);
        const p1 = valueAt(k + 1);
        const m1 = valueAt(k + 1, 0);
        const s2 = s * s;
        const s3 = s2 * s;
        raw = p0.map(
          (_, i) => p0[i] * (2 * s3 - 3 * s2 + 1) + m0[i] * (dt * (s3 - 2 * s2 + s)) + p1[i] * (-2 * s3 + 3 * s2) + m1[i] * (dt * (s3 - s2))
        );
      }
    }
    if (ch.path !== "rotation") return raw;
    const len2 = Math.hypot(...raw);
    return len2 > 0 && Number.isFinite(len2) ? raw.map((x) => x / len2) : [0, 0, 0, 1];
  }
  function normalize2(q) {
    const len2 = Math.hypot(...q);
    return q.map((x) => x / len2);
  }
  function slerp2(a, b, s) {
    let dot2 = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    let e = b;
    if (dot2 < 0) {
      e = b.map((x) => -x);
      dot2 = -dot2;
    }
    if (dot2 > 1 - 2 ** -23) return normalize2(a.map((x, i) => x * (1 - s) + e[i] * s));
    const theta = acosApprox(dot2);
    const s1 = Math.sin(theta * (1 - s));
    const s2 = Math.sin(theta * s);
    const inv = 1 / Math.sin(theta);
    return a.map((x, i) => (x * s1 + e[i] * s2) * inv);
  }
  function acosApprox(v) {
    const x = Math.abs(v);
    const root = Math.sqrt(Math.max(1 - x, 0));
    const r = ((((((-0.0012624911 * x + 667009e-8) * x - 0.017088126) * x + 0.03089188) * x - 0.050174303) * x + 0.08897899) * x - 0.2145988) * x + 1.5707963;
    return v >= 0 ? r * root : Math.PI - r * root;
  }
  function identity() {
    const m = new Float64Array(16);
    m[0] = m[5] = m[10] = m[15] = 1;
    return m;
  }
  function trs(t, q, s) {
    const [x, y, z, w] = q;
    const m = identity();
    const cols = [
      [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)],
      [2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)],
      [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)]
    ];
    for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) m[4 * c + r] = cols[c][r] * s[c];
    m[12] = t[0];
    m[13] = t[1];
    m[14] = t[2];
    return m;
  }
  function mul2(a, b) {
    const out = new Float64Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[4 * k + r] * b[4 * c + k];
        out[4 * c + r] = s;
      }
    }
    return out;
  }
  function det3(m) {
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[4] * (m[1] * m[10] - m[2] * m[9]) + m[8] * (m[1] * m[6] - m[2] * m[5]);
  }
  function inverse3(m) {
    const det = det3(m);
    if (!(det !== 0 && Number.isFinite(det))) return null;
    const [a, b, c, d, e, f2, g, h, i] = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
    return [
      (e * i - f2 * h) / det,
      (c * h - b * i) / det,
      (b * f2 - c * e) / det,
      (f2 * g - d * i) / det,
      (a * i - c * g) / det,
      (c * d - a * f2) / det,
      (d * h - e * g) / det,
      (b * g - a * h) / det,
      (a * e - b * d) / det
    ];
  }
  function invertOrIdentity(m) {
    const det = det3(m);
    if (!(m.every(Number.isFinite) && det !== 0 && Math.abs(det) >= 2 ** -126)) return identity();
    const inv = inverse3(m);
    const out = identity();
    for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) out[4 * c + r] = inv[3 * c + r];
    for (let r = 0; r < 3; r++) out[12 + r] = -(inv[r] * m[12] + inv[3 + r] * m[13] + inv[6 + r] * m[14]);
    return out;
  }
  function normalMatrix(m) {
    const inv = inverse3(m);
    if (!inv || !inv.every(Number.isFinite)) return [m[0], m[1], m[2], 0, m[4], m[5], m[6], 0, m[8], m[9], m[10], 0];
    return [inv[0], inv[3], inv[6], 0, inv[1], inv[4], inv[7], 0, inv[2], inv[5], inv[8], 0];
  }

  // src/aoshader.ts
  var MODE_COMPOSITED = 0;
  var MODE_IRRADIANCE = 1;
  var MODE_DIRECT = 2;
  var MODE_AO = 3;
  var MODE_NO_AO = 4;
  var MODE_COST = 5;
  var VERTEX = `#version 300 es
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
  var GBUFFER = `#version 300 es
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
  var FULLSCREEN = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;
  var FRAGMENT = `#version 300 es
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
uvec2 u_row;   // Dx\xB717 as (low, high) 32-bit halves
uvec2 u_slice; // Dx\xB7Dy\xB731
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
  // 2^(exponent \u2212 15 \u2212 9), built from its bits (exact; GLSL ES 3.0 has no ldexp).
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
// 2\xD72\xD72 block of cells around it and its nearest compatible point. Returns the block's base
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

// psao-client's fill for canvas pixel px with normal n: the donors of the rings at 1, 2, 4, \u2026,
// 128 pixels weighted ((1 + n\xB7n\u2C7C)/2)\u2078, stopping after the first ring whose weight reaches 1.
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
      // psao-client's composite_lit: base colour / \u03C0 \xD7 (direct + irradiance).
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

  // src/render.ts
  var COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };
  function readAccessor(doc, bin, index) {
    const a = doc.accessors?.[index];
    const bv = a?.bufferView !== void 0 ? doc.bufferViews?.[a.bufferView] : void 0;
    if (!a || !bv) throw new Error(`scene.glb: accessor ${index} has no data`);
    const n = a.count * (COMPONENTS[a.type] ?? 1);
    const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
    const Kind = a.componentType === 5126 ? Float32Array : a.componentType === 5123 ? Uint16Array : Uint32Array;
    const bytes = bin.slice(start, start + n * Kind.BYTES_PER_ELEMENT);
    if (bytes.length !== n * Kind.BYTES_PER_ELEMENT) throw new Error(`scene.glb: accessor ${index} is truncated`);
    return new Kind(bytes.buffer);
  }
  function renormalisedWeights(w) {
    const out = new Float32Array(w.length);
    for (let v = 0; v + 4 <= w.length; v += 4) {
      const x = [0, 1, 2, 3].map((k) => Number.isFinite(w[v + k]) ? Math.max(w[v + k], 0) : 0);
      const sum = Math.fround(Math.fround(Math.fround(x[0] + x[1]) + x[2]) + x[3]);
      if (sum > 0) for (let k = 0; k < 4; k++) out[v + k] = x[k] / sum;
      else out[v] = 1;
    }
    return out;
  }
  var SETTINGS = {
    factor: Math.fround(2 * Math.SQRT2),
    planeTolerance: 0.5,
    normalThreshold: Math.fround(0.1),
    directionThreshold: Math.fround(0.7),
    exponent: 8,
    fallback: true,
    ambient: Math.fround(0.6),
    light: 0.5
  };
  var SKY_GREY = [0.62, 0.66, 0.72];
  var MIN_DETERMINANT = 1e-12;
  function encodeSrgb(linear) {
    const c = Math.min(Math.max(linear, 0), 1);
    const s = c <= 31308e-7 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
    return Math.round(s * 255);
  }
  function normalTable() {
    const f2 = Math.fround;
    const step = f2(2 / 14);
    const level = (q) => f2(f2(Math.min(q, 14) * step) - 1);
    const sign = (x) => x >= 0 ? 1 : -1;
    const out = new Float32Array(256 * 4);
    for (let code = 0; code < 256; code++) {
      const ox = level(code >> 4);
      const oy = level(code & 15);
      const z = f2(f2(1 - Math.abs(ox)) - Math.abs(oy));
      let v;
      if (z >= 0) v = [ox, oy, z];
      else v = [f2(f2(1 - Math.abs(oy)) * sign(ox)), f2(f2(1 - Math.abs(ox)) * sign(oy)), z];
      const len2 = f2(Math.sqrt(f2(f2(f2(v[0] * v[0]) + f2(v[1] * v[1])) + f2(v[2] * v[2]))));
      const inv = f2(1 / len2);
      out.set([f2(v[0] * inv), f2(v[1] * inv), f2(v[2] * inv), 0], code * 4);
    }
    return out;
  }
  function compile(gl2, type, source) {
    const s = gl2.createShader(type);
    gl2.shaderSource(s, source);
    gl2.compileShader(s);
    if (!gl2.getShaderParameter(s, gl2.COMPILE_STATUS)) throw new Error(`shader: ${gl2.getShaderInfoLog(s)}`);
    return s;
  }
  function instanceView(t) {
    const [a, b, c, d, e, f2, g, h, i] = t;
    const det = a * (e * i - f2 * h) - d * (b * i - c * h) + g * (b * f2 - c * e);
    if (!(Math.abs(det) > MIN_DETERMINANT)) return null;
    const inv = [
      (e * i - f2 * h) / det,
      (c * h - b * i) / det,
      (b * f2 - c * e) / det,
      (f2 * g - d * i) / det,
      (a * i - c * g) / det,
      (c * d - a * f2) / det,
      (d * h - e * g) / det,
      (b * g - a * h) / det,
      (a * e - b * d) / det
    ];
    const [tx, ty, tz] = [t[9], t[10], t[11]];
    const ix = -(inv[0] * tx + inv[3] * ty + inv[6] * tz);
    const iy = -(inv[1] * tx + inv[4] * ty + inv[7] * tz);
    const iz = -(inv[2] * tx + inv[5] * ty + inv[8] * tz);
    const toLocal = new Float32Array([inv[0], inv[1], inv[2], 0, inv[3], inv[4], inv[5], 0, inv[6], inv[7], inv[8], 0, ix, iy, iz, 1]);
    if (!toLocal.every(Number.isFinite)) return null;
    return { toLocal, normalToLocal: new Float32Array([a, d, g, b, e, h, c, f2, i]) };
  }
  var GBufferTargets = class {
    constructor(gl2) {
      this.gl = gl2;
      this.position = null;
      this.normal = null;
      this.relit = null;
      this.depth = null;
      this.width = 0;
      this.height = 0;
      this.fbo = gl2.createFramebuffer();
    }
    resize(width, height) {
      if (width === this.width && height === this.height) return;
      const gl2 = this.gl;
      this.width = width;
      this.height = height;
      for (const t of [this.position, this.normal, this.relit]) if (t) gl2.deleteTexture(t);
      if (this.depth) gl2.deleteRenderbuffer(this.depth);
      const target = () => {
        const t = gl2.createTexture();
        gl2.bindTexture(gl2.TEXTURE_2D, t);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
        gl2.texStorage2D(gl2.TEXTURE_2D, 1, gl2.RGBA32F, width, height);
        return t;
      };
      this.position = target();
      this.normal = target();
      this.relit = target();
      this.depth = gl2.createRenderbuffer();
      gl2.bindRenderbuffer(gl2.RENDERBUFFER, this.depth);
      gl2.renderbufferStorage(gl2.RENDERBUFFER, gl2.DEPTH_COMPONENT24, width, height);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, this.fbo);
      gl2.framebufferTexture2D(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT0, gl2.TEXTURE_2D, this.position, 0);
      gl2.framebufferTexture2D(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT1, gl2.TEXTURE_2D, this.normal, 0);
      gl2.framebufferTexture2D(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT2, gl2.TEXTURE_2D, this.relit, 0);
      gl2.framebufferRenderbuffer(gl2.FRAMEBUFFER, gl2.DEPTH_ATTACHMENT, gl2.RENDERBUFFER, this.depth);
      gl2.drawBuffers([gl2.COLOR_ATTACHMENT0, gl2.COLOR_ATTACHMENT1, gl2.COLOR_ATTACHMENT2]);
      const status2 = gl2.checkFramebufferStatus(gl2.FRAMEBUFFER);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, null);
      if (status2 !== gl2.FRAMEBUFFER_COMPLETE) throw new Error(`G-buffer framebuffer incomplete (${status2})`);
    }
  };
  function program(gl2, vertex, fragment) {
    const p = gl2.createProgram();
    gl2.attachShader(p, compile(gl2, gl2.VERTEX_SHADER, vertex));
    gl2.attachShader(p, compile(gl2, gl2.FRAGMENT_SHADER, fragment));
    gl2.linkProgram(p);
    if (!gl2.getProgramParameter(p, gl2.LINK_STATUS)) throw new Error(`program: ${gl2.getProgramInfoLog(p)}`);
    const u = {};
    const count = gl2.getProgramParameter(p, gl2.ACTIVE_UNIFORMS);
    for (let i = 0; i < count; i++) {
      const name = gl2.getActiveUniform(p, i).name;
      u[name] = gl2.getUniformLocation(p, name);
    }
    return { p, u };
  }
  function dataTexture(gl2) {
    const t = gl2.createTexture();
    gl2.bindTexture(gl2.TEXTURE_2D, t);
    gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
    gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
    return t;
  }
  var INST_F = 9;
  var INST_U = 3;
  var SceneRenderer = class {
    constructor(gl2, glb) {
      this.gl = gl2;
      /// Vertex positions of each mesh (all primitives), for the posed scene's bounds.
      this.meshPositions = [];
      /// Per mesh, per primitive: its joints and renormalised weights when skinned (for the
      /// skinned instances' bounds), else null.
      this.meshSkins = [];
      /// The joint texels of the frame drawn last (skinned instances' bounds), or null.
      this.lastJointTexels = null;
      this.boundsCache = [];
      this.meshes = [];
      this.instances = [];
      /// The scene's animation (skinned instances), when anything is skinned.
      this.animation = null;
      /// The scene's camera paths (from the glb's extras).
      this.paths = [];
      /// The scene's suns and point lights (from the glb's extras).
      this.lights = new SceneLights(void 0);
      /// Milliseconds of the last frame's shadow maps (0 when none were drawn).
      this.shadowMs = 0;
      /// The served relit characters, once loaded (`relit.ts`).
      this.relit = null;
      /// Why relighting stopped, when a frame's relighting failed.
      this.relitError = null;
      /// Per relit instance: the vertex buffer of its values.
      this.relitBuffers = /* @__PURE__ */ new Map();
      /// What relit characters are built from: the glb's document, its accessors, the instances.
      this.source = null;
      if (!gl2.getExtension("EXT_color_buffer_float")) throw new Error("WebGL2 without EXT_color_buffer_float");
      this.gbuffer = program(gl2, VERTEX, GBUFFER);
      this.shade = program(gl2, FULLSCREEN, FRAGMENT);
      this.depth = program(gl2, VERTEX, SHADOW_FRAGMENT);
      this.shadows = new ShadowMaps(gl2);
      this.targets = new GBufferTargets(gl2);
      this.normals = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, 256, 1, 0, gl2.RGBA, gl2.FLOAT, normalTable());
      this.instF = dataTexture(gl2);
      this.instU = dataTexture(gl2);
      this.emptyU = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32UI, 1, 1, 0, gl2.RGBA_INTEGER, gl2.UNSIGNED_INT, new Uint32Array(4));
      this.joints = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, 1, 1, 0, gl2.RGBA, gl2.FLOAT, new Float32Array(4));
      gl2.vertexAttribI4ui(2, 0, 0, 0, 0);
      gl2.vertexAttrib4f(4, 1, 1, 1, 1);
      const colours = this.load(glb);
      this.colours = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, Math.max(1, colours.length / 4), 1, 0, gl2.RGBA, gl2.FLOAT, colours.length ? colours : new Float32Array(4));
    }
    /// Uploads the meshes; returns the primitives' base colours (RGBA per colour index).
    load(glb) {
      const gl2 = this.gl;
      const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
      const jsonLen = view.getUint32(12, true);
      const doc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
      this.paths = doc.extras?.psao_camera_paths ?? [];
      this.lights = new SceneLights(doc.extras?.psao_lights);
      const binAt = 20 + jsonLen + 8;
      const bin = glb.subarray(binAt, binAt + view.getUint32(20 + jsonLen, true));
      const data = (index) => {
        const a = doc.accessors[index];
        const bv = doc.bufferViews[a.bufferView];
        const width = { SCALAR: 1, VEC3: 3, VEC4: 4 }[a.type] ?? 1;
        const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
        return { bytes: bin.subarray(start, start + a.count * width * 4), count: a.count };
      };
      const instanceCount = (doc.nodes ?? []).findIndex((n) => n.mesh === void 0 || !n.matrix);
      const instances = instanceCount < 0 ? (doc.nodes ?? []).length : instanceCount;
      const read = (i) => readAccessor(doc, bin, i);
      this.source = { doc, read, instances };
      const animation = new Animation(doc, instances, read);
      this.animation = animation.skinned ? animation : null;
      const colours = [];
      for (const mesh of doc.meshes ?? []) {
        const prims = [];
        const positions = [];
        const skins = [];
        this.meshPositions.push(positions);
        this.meshSkins.push(skins);
        for (const prim of mesh.primitives) {
          if (prim.attributes.POSITION === void 0 || prim.attributes.NORMAL === void 0 || prim.indices === void 0) continue;
          positions.push(readAccessor(doc, bin, prim.attributes.POSITION));
          const vao = gl2.createVertexArray();
          gl2.bindVertexArray(vao);
          for (const [loc, acc] of [
            [0, prim.attributes.POSITION],
            [1, prim.attributes.NORMAL]
          ]) {
            const buf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, buf);
            gl2.bufferData(gl2.ARRAY_BUFFER, data(acc).bytes, gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(loc);
            gl2.vertexAttribPointer(loc, 3, gl2.FLOAT, false, 0, 0);
          }
          const { JOINTS_0: joints, WEIGHTS_0: weights } = prim.attributes;
          const skin = joints !== void 0 && weights !== void 0;
          skins.push(null);
          if (skin) {
            const jointData = Uint16Array.from(readAccessor(doc, bin, joints));
            const weightData = renormalisedWeights(readAccessor(doc, bin, weights));
            skins[skins.length - 1] = { joints: jointData, weights: weightData };
            const jbuf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, jbuf);
            gl2.bufferData(gl2.ARRAY_BUFFER, jointData, gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(2);
            gl2.vertexAttribIPointer(2, 4, gl2.UNSIGNED_SHORT, 0, 0);
            const wbuf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, wbuf);
            gl2.bufferData(gl2.ARRAY_BUFFER, weightData, gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(3);
            gl2.vertexAttribPointer(3, 4, gl2.FLOAT, false, 0, 0);
          }
          const idx = data(prim.indices);
          const ibo = gl2.createBuffer();
          gl2.bindBuffer(gl2.ELEMENT_ARRAY_BUFFER, ibo);
          gl2.bufferData(gl2.ELEMENT_ARRAY_BUFFER, idx.bytes, gl2.STATIC_DRAW);
          gl2.bindVertexArray(null);
          const c = doc.materials?.[prim.material ?? 0]?.pbrMetallicRoughness?.baseColorFactor ?? [0.8, 0.8, 0.8, 1];
          prims.push({ vao, count: idx.count, colour: colours.length / 4, skin });
          colours.push(c[0], c[1], c[2], 1);
        }
        this.meshes.push(prims);
      }
      for (const node of doc.nodes ?? []) {
        if (node.mesh === void 0 || !node.matrix) break;
        this.instances.push({ mesh: node.mesh, matrix: new Float32Array(node.matrix) });
      }
      return new Float32Array(colours);
    }
    /// Draws the scene from `camera` in `opts.mode`; instance i is drawn at
    /// `state.transforms[i]` when set (else its rest matrix), and its AO reconstructed from
    /// its grid when the state has its transform (as psao-client). The G-buffer is `scale`
    /// times the canvas size (1 by default; odd scales put a sample on every pixel centre).
    draw(camera, opts) {
      const gl2 = this.gl;
      const grids2 = opts.grids && !opts.grids.problem ? opts.grids : null;
      const state = opts.state;
      const scale2 = Math.max(1, Math.floor(opts.scale ?? 1));
      const w = gl2.drawingBufferWidth;
      const h = gl2.drawingBufferHeight;
      this.targets.resize(w * scale2, h * scale2);
      const g = this.gbuffer.u;
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, this.targets.fbo);
      gl2.viewport(0, 0, w * scale2, h * scale2);
      gl2.clearBufferfv(gl2.COLOR, 0, [0, 0, 0, -1]);
      gl2.clearBufferfv(gl2.COLOR, 1, [0, 0, 0, 0]);
      gl2.clearBufferfv(gl2.COLOR, 2, [1, 1, 1, 1]);
      gl2.clearBufferfi(gl2.DEPTH_STENCIL, 0, 1, 0);
      gl2.enable(gl2.DEPTH_TEST);
      gl2.depthFunc(gl2.LESS);
      gl2.useProgram(this.gbuffer.p);
      const animation = this.animation;
      gl2.activeTexture(gl2.TEXTURE0);
      gl2.bindTexture(gl2.TEXTURE_2D, this.joints);
      if (animation) {
        const texels = animation.jointTexels(opts.time ?? 0);
        this.lastJointTexels = texels;
        const rows2 = Math.ceil(texels.length / 4 / TEX_WIDTH);
        const padded = new Float32Array(rows2 * TEX_WIDTH * 4);
        padded.set(texels);
        gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, TEX_WIDTH, rows2, 0, gl2.RGBA, gl2.FLOAT, padded);
      }
      gl2.uniform3fv(g.u_eye, camera.position);
      if (this.relit) {
        try {
          this.relight(camera, state, opts.time ?? 0);
        } catch (e) {
          this.relitError = `relit characters: ${e instanceof Error ? e.message : e}`;
          this.relit.free();
          this.relit = null;
          this.relitBuffers.forEach((b) => gl2.deleteBuffer(b));
          this.relitBuffers.clear();
        }
      }
      gl2.useProgram(this.gbuffer.p);
      this.drawInstances(this.gbuffer, viewProj(camera), state);
      const instF = new Float32Array(this.instances.length * INST_F * 4);
      const instU = new Uint32Array(this.instances.length * INST_U * 4);
      for (let i = 0; i < this.instances.length; i++) {
        this.instanceRow(i, state?.transforms[i] ?? null, state, grids2, instF, instU);
      }
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, null);
      gl2.disable(gl2.DEPTH_TEST);
      const lit = state?.hasLights() ?? false;
      const needsDirect = lit && opts.mode !== MODE_AO && opts.mode !== MODE_IRRADIANCE;
      this.shadowMs = 0;
      if (needsDirect) {
        const t0 = performance.now();
        const time = opts.time ?? 0;
        const mapCamera = { ...camera };
        this.shadows.render(this.depth, (prog, vp) => this.drawInstances(prog, vp, state), viewProj, {
          suns: this.lights.sunsAt(time),
          points: this.lights.points,
          camera: mapCamera,
          aspect: w / Math.max(h, 1),
          bounds: this.posedBounds(state),
          settings: settingsForImage(w, h),
          scale: opts.shadowScale ?? 1
        });
        this.shadowMs = performance.now() - t0;
      }
      const u = this.shade.u;
      gl2.viewport(0, 0, w, h);
      gl2.useProgram(this.shade.p);
      const rows = Math.max(1, this.instances.length);
      gl2.bindTexture(gl2.TEXTURE_2D, this.instF);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, INST_F, rows, 0, gl2.RGBA, gl2.FLOAT, instF.length ? instF : new Float32Array(INST_F * 4));
      gl2.bindTexture(gl2.TEXTURE_2D, this.instU);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32UI, INST_U, rows, 0, gl2.RGBA_INTEGER, gl2.UNSIGNED_INT, instU.length ? instU : new Uint32Array(INST_U * 4));
      const textures = [
        ["u_directory", grids2?.directory.texture ?? this.emptyU],
        ["u_entries", grids2?.entries.texture ?? this.emptyU],
        ["u_page_table", grids2?.pageTable.texture ?? this.emptyU],
        ["u_cells", grids2?.cells.texture ?? this.emptyU],
        ["u_normals", this.normals],
        ["u_gposition", this.targets.position],
        ["u_gnormal", this.targets.normal],
        ["u_grelit", this.targets.relit],
        ["u_colours", this.colours],
        ["u_instf", this.instF],
        ["u_instu", this.instU],
        ["u_lights", (lit ? grids2?.lights.texture : null) ?? this.emptyU],
        ["u_map_table", this.shadows.table]
      ];
      textures.forEach(([name, t], unit) => {
        gl2.activeTexture(gl2.TEXTURE0 + unit);
        gl2.bindTexture(gl2.TEXTURE_2D, t);
        gl2.uniform1i(u[name], unit);
      });
      const arrays = [
        ["u_sun_maps", this.shadows.suns.texture],
        ["u_point_maps", this.shadows.points.texture]
      ];
      arrays.forEach(([name, t], k) => {
        gl2.activeTexture(gl2.TEXTURE0 + textures.length + k);
        gl2.bindTexture(gl2.TEXTURE_2D_ARRAY, t);
        gl2.uniform1i(u[name], textures.length + k);
      });
      gl2.uniform1i(u.u_lit, lit ? 1 : 0);
      this.shadows.setUniforms(u);
      gl2.activeTexture(gl2.TEXTURE0);
      gl2.uniform1i(u.u_mode, opts.mode);
      gl2.uniform1i(u.u_scale, scale2);
      gl2.uniform3f(u.u_sky, ...SKY_GREY.map((c) => encodeSrgb(c) / 255));
      const l = [0.35, 1, 0.6];
      const ll = Math.hypot(l[0], l[1], l[2]);
      gl2.uniform3f(u.u_light_dir, l[0] / ll, l[1] / ll, l[2] / ll);
      gl2.uniform1f(u.u_light, SETTINGS.light);
      gl2.uniform1f(u.u_ambient, SETTINGS.ambient);
      gl2.uniform1f(u.u_factor, SETTINGS.factor);
      gl2.uniform1f(u.u_plane_tolerance, SETTINGS.planeTolerance);
      gl2.uniform1f(u.u_normal_threshold, SETTINGS.normalThreshold);
      gl2.uniform1f(u.u_direction_threshold, SETTINGS.directionThreshold);
      gl2.uniform1i(u.u_exponent, SETTINGS.exponent);
      gl2.uniform1i(u.u_fallback, SETTINGS.fallback ? 1 : 0);
      gl2.drawArrays(gl2.TRIANGLES, 0, 3);
    }
    /// Draws every instance with `prog` (the G-buffer's vertex shader) from `vp`: at the
    /// transform of the state's last update carrying one, else its rest matrix, skinned with
    /// the joint texture bound to unit 0.
    drawInstances(prog, vp, state) {
      const gl2 = this.gl;
      const g = prog.u;
      gl2.useProgram(prog.p);
      gl2.activeTexture(gl2.TEXTURE0);
      gl2.bindTexture(gl2.TEXTURE_2D, this.joints);
      gl2.uniform1i(g.u_joints, 0);
      gl2.uniformMatrix4fv(g.u_view_proj, false, vp);
      const animation = this.animation;
      const model = new Float32Array(16);
      for (const [i, inst] of this.instances.entries()) {
        model.set(this.modelOf(i, state));
        gl2.uniformMatrix4fv(g.u_model, false, model);
        gl2.uniformMatrix3fv(g.u_normal_matrix, false, normalMatrixOf(model));
        gl2.uniform1f(g.u_instance, i);
        const jointBase = animation ? animation.jointBase[i] : -1;
        const relit = this.relitBuffers.get(i);
        for (const p of this.meshes[inst.mesh] ?? []) {
          gl2.uniform1f(g.u_colour_index, p.colour);
          gl2.uniform1i(g.u_joint_base, p.skin ? jointBase : -1);
          gl2.bindVertexArray(p.vao);
          if (relit) {
            gl2.bindBuffer(gl2.ARRAY_BUFFER, relit);
            gl2.enableVertexAttribArray(4);
            gl2.vertexAttribPointer(4, 4, gl2.FLOAT, false, 0, 0);
          } else {
            gl2.disableVertexAttribArray(4);
          }
          gl2.drawElements(gl2.TRIANGLES, p.count, gl2.UNSIGNED_INT, 0);
        }
      }
      gl2.bindVertexArray(null);
    }
    /// Relights the served characters at scene time `time` (their instances at the transforms
    /// drawn) and uploads each relit instance's values.
    relight(camera, state, time) {
      const gl2 = this.gl;
      const relit = this.relit;
      const transforms = this.instances.map((_, i) => state?.transforms[i] ?? null);
      relit.frame(time, transforms, camera.position);
      for (let i = 0; i < this.instances.length; i++) {
        const values = relit.values(i);
        if (!values) continue;
        let buf = this.relitBuffers.get(i);
        if (!buf) {
          buf = gl2.createBuffer();
          this.relitBuffers.set(i, buf);
        }
        gl2.bindBuffer(gl2.ARRAY_BUFFER, buf);
        gl2.bufferData(gl2.ARRAY_BUFFER, values, gl2.DYNAMIC_DRAW);
      }
    }
    /// Instance i's model matrix (column-major 4×4): the state's transform, else its rest matrix.
    modelOf(i, state) {
      const t = state?.transforms[i] ?? null;
      if (!t) return this.instances[i].matrix;
      return new Float32Array([t[0], t[1], t[2], 0, t[3], t[4], t[5], 0, t[6], t[7], t[8], 0, t[9], t[10], t[11], 1]);
    }
    /// World bounds of every instance's mesh vertices at the drawn transforms, as psao-raster's
    /// shadow maps take them (skinned instances: their vertices skinned with the joint
    /// matrices of the frame, as the vertex shader skins them); null without vertices. Each
    /// unskinned instance's bounds are kept until its transform changes.
    posedBounds(state) {
      const lo = [Infinity, Infinity, Infinity];
      const hi = [-Infinity, -Infinity, -Infinity];
      for (const [i, inst] of this.instances.entries()) {
        const m = this.modelOf(i, state);
        const jointBase = this.animation?.jointBase[i] ?? -1;
        const texels = jointBase >= 0 ? this.lastJointTexels : null;
        const key = m.join(",");
        let b = this.boundsCache[i];
        if (!b || b.key !== key || texels) {
          b = { key, lo: [Infinity, Infinity, Infinity], hi: [-Infinity, -Infinity, -Infinity] };
          for (const [k, rest] of (this.meshPositions[inst.mesh] ?? []).entries()) {
            const skin = texels ? this.meshSkins[inst.mesh]?.[k] ?? null : null;
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
    instanceRow(i, t, state, grids2, f2, u) {
      const slot = grids2?.slots[i] ?? null;
      const view = t && state && slot ? instanceView(t) : null;
      if (!view || !state || !slot) return;
      const e = state.table[i];
      const fo = i * INST_F * 4;
      f2.set(view.toLocal, fo);
      const n = view.normalToLocal;
      f2.set([n[0], n[1], n[2], 0, n[3], n[4], n[5], 0, n[6], n[7], n[8], 0], fo + 16);
      f2.set([e.origin[0], e.origin[1], e.origin[2], e.cellSize, Math.fround(1 / e.cellSize), e.layoutPoissonRadius, 1, 0], fo + 28);
      const row = BigInt(e.dims[0]) * 17n;
      const slice = BigInt(e.dims[0]) * BigInt(e.dims[1]) * 31n;
      u.set(
        [
          e.dims[0],
          e.dims[1],
          e.dims[2],
          e.bucketCount - 1,
          slot.bucketBase,
          slot.cellPageBase,
          slot.maxCells,
          state.slotCount(i) > 0 ? 1 : 0,
          Number(row & 0xffffffffn),
          Number(row >> 32n),
          Number(slice & 0xffffffffn),
          Number(slice >> 32n)
        ],
        i * INST_U * 4
      );
    }
  };
  function skinned(positions, skin, texels, base) {
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
  function normalMatrixOf(m) {
    const [a, b, c] = [m[0], m[1], m[2]];
    const [d, e, f2] = [m[4], m[5], m[6]];
    const [g, h, i] = [m[8], m[9], m[10]];
    const det = a * (e * i - f2 * h) - d * (b * i - c * h) + g * (b * f2 - c * e) || 1;
    return [
      (e * i - f2 * h) / det,
      (f2 * g - d * i) / det,
      (d * h - e * g) / det,
      (c * h - b * i) / det,
      (a * i - c * g) / det,
      (b * g - a * h) / det,
      (b * f2 - c * e) / det,
      (c * d - a * f2) / det,
      (a * e - b * d) / det
    ];
  }
  function viewProj(c) {
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
      sx,
      ux,
      -fx,
      0,
      sy,
      uy,
      -fy,
      0,
      sz,
      uz,
      -fz,
      0,
      -(sx * px + sy * py + sz * pz),
      -(ux * px + uy * py + uz * pz),
      fx * px + fy * py + fz * pz,
      1
    ];
    const f2 = 1 / Math.tan(c.fovY / 2);
    const { near: n, far: fr } = c;
    const proj = [f2 / (c.aspect ?? 1), 0, 0, 0, 0, f2, 0, 0, 0, 0, (fr + n) / (n - fr), -1, 0, 0, 2 * fr * n / (n - fr), 0];
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

  // src/relit.ts
  var PROPERTIES = { translation: 0, rotation: 1, scale: 2 };
  var INTERPOLATIONS = { STEP: 0, LINEAR: 1, CUBICSPLINE: 2 };
  function bytesOf(a) {
    return new Uint8Array(a.buffer, a.byteOffset, a.byteLength);
  }
  var RelitCharacters = class {
    /// The scene of `doc` (its first `instances` nodes are the instance table's) with the
    /// served `models` (`/characters/N.prt`, in order) under `index.lighting`; throws with the
    /// Rust error's text when the scene or a model is refused.
    constructor(codec2, doc, read, instances, index, models) {
      /// Milliseconds the last frame's relighting took in wasm (posing, synthesis, shading).
      this.ms = 0;
      /// Vertices relit per frame.
      this.vertices = 0;
      this.x = codec2.exports;
      this.handle = this.x.psao_relit_new();
      try {
        this.build(doc, read, instances);
        this.check(this.x.psao_relit_finish(this.handle));
        const count = this.x.psao_relit_count(this.handle);
        if (count !== models.length) throw new Error(`the server relights ${models.length} characters, the scene has ${count}`);
        const lighting = bytesOf(Float32Array.from(index.lighting));
        models.forEach(
          (m, i) => this.withBytes(
            [m, lighting],
            ([mp, lp]) => this.check(this.x.psao_relit_character(this.handle, i, mp, m.length, lp, lighting.length))
          )
        );
        this.vertices = this.x.psao_relit_vertices(this.handle);
      } catch (e) {
        this.free();
        throw e;
      }
    }
    build(doc, read, instances) {
      const x = this.x;
      const h = this.handle;
      const nodes = doc.nodes ?? [];
      const parents = nodes.map(() => -1);
      nodes.forEach((n, p) => n.children?.forEach((c) => parents[c] = p));
      nodes.forEach((n, k) => {
        const trs2 = Float32Array.from([...n.translation ?? [0, 0, 0], ...n.rotation ?? [0, 0, 0, 1], ...n.scale ?? [1, 1, 1]]);
        this.withBytes([bytesOf(trs2)], ([p]) => x.psao_relit_node(h, parents[k], p));
      });
      for (const mesh of doc.meshes ?? []) {
        const prim = mesh.primitives[0];
        const a = prim?.attributes;
        if (!prim || a?.POSITION === void 0 || a.NORMAL === void 0 || prim.indices === void 0) {
          this.check(x.psao_relit_mesh(h, 0, 0, 0, 0, 0, 0, 0));
          continue;
        }
        const positions = Float32Array.from(read(a.POSITION));
        const normals = Float32Array.from(read(a.NORMAL));
        const indices = Uint32Array.from(read(prim.indices));
        const skinned2 = a.JOINTS_0 !== void 0 && a.WEIGHTS_0 !== void 0;
        const arrays = [bytesOf(positions), bytesOf(normals), bytesOf(indices)];
        if (skinned2) arrays.push(bytesOf(Uint16Array.from(read(a.JOINTS_0))), bytesOf(Float32Array.from(read(a.WEIGHTS_0))));
        this.withBytes(
          arrays,
          ([p, n, i, j, w]) => this.check(x.psao_relit_mesh(h, positions.length / 3, p, n, i, arrays[2].length, skinned2 ? j : 0, skinned2 ? w : 0))
        );
      }
      for (const skin of doc.skins ?? []) {
        const joints = bytesOf(Uint32Array.from(skin.joints));
        const ibm = skin.inverseBindMatrices !== void 0 ? bytesOf(Float32Array.from(read(skin.inverseBindMatrices))) : null;
        this.withBytes(
          ibm ? [joints, ibm] : [joints],
          ([j, m]) => this.check(x.psao_relit_skin(h, skin.joints.length, j, ibm ? m : 0))
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
          if (!s || ch.target.node === void 0 || property === void 0) continue;
          const times = bytesOf(Float32Array.from(read(s.input)));
          const values = bytesOf(Float32Array.from(read(s.output)));
          const interpolation = INTERPOLATIONS[s.interpolation ?? "LINEAR"] ?? -1;
          this.withBytes(
            [times, values],
            ([t, v]) => this.check(x.psao_relit_channel(h, clip, ch.target.node, property, interpolation, t, times.length, v, values.length))
          );
        }
      });
      for (const clip of doc.extras?.psao_playing ?? []) this.check(x.psao_relit_play(h, clip));
    }
    /// Relights every character at scene time `time` (seconds) from `eye`, instance i at
    /// `transforms[i]` (the last update's, an Affine3A's 12 floats) when set; throws on error.
    frame(time, transforms, eye) {
      const t0 = performance.now();
      const count = transforms.length;
      const t = new Float32Array(count * 12);
      const given = new Uint8Array(count);
      transforms.forEach((m, i) => {
        if (!m) return;
        t.set(m, i * 12);
        given[i] = 1;
      });
      this.withBytes(
        [bytesOf(t), given],
        ([tp, gp]) => this.check(this.x.psao_relit_frame(this.handle, time, count, tp, gp, eye[0], eye[1], eye[2]))
      );
      this.ms = performance.now() - t0;
    }
    /// Instance `instance`'s values of the last frame (4 per mesh vertex), a view of wasm
    /// memory valid until the next call; null when it is not relit.
    values(instance) {
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
    withBytes(arrays, f2) {
      const ptrs = arrays.map((a) => {
        const p = this.x.psao_alloc(a.length);
        new Uint8Array(this.x.memory.buffer, p, a.length).set(a);
        return p;
      });
      try {
        return f2(ptrs);
      } finally {
        ptrs.forEach((p, k) => this.x.psao_free(p, arrays[k].length));
      }
    }
    check(status2) {
      if (status2 === 0) return;
      const x = this.x;
      const text = new TextDecoder().decode(new Uint8Array(x.memory.buffer, x.psao_relit_error_ptr(this.handle), x.psao_relit_error_len(this.handle)));
      throw new Error(text);
    }
  };

  // src/main.ts
  var status = {
    connected: false,
    sessions: 0,
    updates: 0,
    verified: 0,
    mismatches: 0,
    serverFrame: 0,
    points: 0,
    hash: null,
    message: null,
    fatal: false,
    stalled: null,
    mbitS: 0,
    fps: 0,
    drawn: 0,
    camera: null,
    autoOrbit: true,
    mode: MODE_COMPOSITED,
    lit: false,
    shadowMs: 0,
    drawMs: 0,
    edge: location.host,
    rttEdge: null,
    rttMs: null,
    path: null,
    pathFrame: 0,
    done: false,
    decodeMs: 0,
    uploadedBytes: 0,
    rebuilds: 0,
    textureBytes: 0,
    milestones: { scene: null, welcome: null, update: null, ao: null },
    relit: { state: "loading", characters: 0, vertices: 0, modelBytes: 0, ms: 0 }
  };
  window.psao = status;
  var params = new URLSearchParams(location.search);
  var token = new URLSearchParams(location.hash.slice(1)).get("token");
  if (token !== null) history.replaceState(null, "", location.pathname + location.search);
  var verify = params.get("verify") === "1";
  var pathName = params.get("path");
  var orbitOnly = params.get("orbit") === "1";
  var testFrames = params.has("frames") ? Math.max(1, Number(params.get("frames"))) : null;
  var lockstep = params.get("lockstep") === "1";
  var fixedRes = /^(\d+)x(\d+)$/.exec(params.get("res") ?? "");
  var scale = Math.max(1, Math.floor(Number(params.get("scale") ?? "1")) | 1);
  var shadowScale = Math.max(1, Math.floor(Number(params.get("shadowscale") ?? "1")) | 1);
  var MODES = {
    composited: MODE_COMPOSITED,
    irradiance: MODE_IRRADIANCE,
    direct: MODE_DIRECT,
    ao: MODE_AO,
    noao: MODE_NO_AO
  };
  status.mode = MODES[params.get("mode") ?? ""] ?? MODE_COMPOSITED;
  var edges = [location.host];
  for (const e of (params.get("edges") ?? "").split(",").map((e2) => e2.trim())) {
    if (/^[\w.-]+:\d+$|^\[[0-9a-fA-F:.]+\]:\d+$/.test(e) && !edges.includes(e)) edges.push(e);
  }
  var edgeIndex = 0;
  var wsUrl = (host) => `${location.protocol === "https:" ? "wss" : "ws"}://${host}/ws`;
  var codec = null;
  var session = null;
  var backoff = 200;
  var received = [];
  function connect() {
    status.edge = edges[edgeIndex];
    session?.release();
    session = new Session(
      codec,
      { url: wsUrl(status.edge), token, verify, name: "psao browser viewer" },
      {
        welcome: () => {
          var _a;
          (_a = status.milestones).welcome ?? (_a.welcome = performance.now());
          status.connected = true;
          status.sessions++;
          status.message = null;
          status.stalled = null;
          backoff = 200;
          if (session?.state) grids?.reset(session.state);
          pathFrame = 0;
          answered = -1;
          sent = -1;
        },
        sceneTime: (_frame, clientFrame, seconds) => {
          if (clientFrame !== null) answered = Math.max(answered, clientFrame);
          serverTime = { seconds, at: performance.now() };
        },
        update: (frame, bytes, verified) => {
          var _a;
          (_a = status.milestones).update ?? (_a.update = performance.now());
          if (session?.state) grids?.apply(session.state.changes());
          status.updates++;
          if (verified) status.verified++;
          status.mismatches = session?.mismatches ?? status.mismatches;
          status.serverFrame = frame;
          received.push({ t: performance.now(), bytes });
          if (session?.lastHash != null) status.hash = session.lastHash.toString(16).padStart(16, "0");
        },
        status: (text) => status.stalled = text,
        closed: (reason, fatal) => {
          status.connected = false;
          status.message = reason;
          status.fatal = fatal;
          if (!fatal) {
            edgeIndex = (edgeIndex + 1) % edges.length;
            setTimeout(connect, backoff);
            backoff = Math.min(backoff * 2, 5e3);
          }
        }
      }
    );
  }
  var overlay = document.getElementById("overlay");
  var message = document.getElementById("message");
  var frames = [];
  var cameraFrame2 = 0;
  var orbit = null;
  var canvas = document.getElementById("view");
  var gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
  var renderer = null;
  var sceneError = null;
  var grids = gl ? new GridTextures(gl) : null;
  var path = null;
  var pathFrame = 0;
  var sent = -1;
  var answered = -1;
  var pathStart = 0;
  var serverTime = null;
  function sceneTime(now) {
    if (lockstep && testFrames !== null) return Math.max(answered, 0) / 60;
    return serverTime ? serverTime.seconds + (now - serverTime.at) / 1e3 : 0;
  }
  for (const [id, mode] of [
    ["mode-composited", MODE_COMPOSITED],
    ["mode-irradiance", MODE_IRRADIANCE],
    ["mode-direct", MODE_DIRECT],
    ["mode-ao", MODE_AO]
  ]) {
    document.getElementById(id)?.addEventListener("click", () => status.mode = mode);
  }
  var control = { auto: true, yaw: 0, pitch: 0.3, distance: 0, keys: /* @__PURE__ */ new Set(), last: 0 };
  canvas.addEventListener("mousedown", (e) => {
    control.auto = false;
    const move = (m) => {
      control.yaw += m.movementX * 5e-3;
      control.pitch = Math.max(-1.5, Math.min(1.5, control.pitch + m.movementY * 5e-3));
    };
    const up = () => {
      window.removeEventListener("mousemove", move);
      window.removeEventListener("mouseup", up);
    };
    window.addEventListener("mousemove", move);
    window.addEventListener("mouseup", up);
    e.preventDefault();
  });
  canvas.addEventListener(
    "wheel",
    (e) => {
      control.auto = false;
      const r = orbit?.radius ?? 1;
      control.distance = Math.max(r * 0.01, Math.min(r * 20, control.distance * Math.exp(e.deltaY * 1e-3)));
      e.preventDefault();
    },
    { passive: false }
  );
  window.addEventListener("keydown", (e) => {
    if (e.key === "1") status.mode = MODE_COMPOSITED;
    else if (e.key === "2") status.mode = MODE_IRRADIANCE;
    else if (e.key === "3") status.mode = MODE_DIRECT;
    else if (e.key === "4") status.mode = MODE_AO;
    else if (e.key === " ") control.auto = true;
    else control.keys.add(e.key.toLowerCase());
  });
  window.addEventListener("keyup", (e) => control.keys.delete(e.key.toLowerCase()));
  function orbitCamera(now) {
    if (!orbit) return null;
    const dt = control.last ? Math.min((now - control.last) / 1e3, 0.1) : 0;
    control.last = now;
    if (control.distance === 0) control.distance = orbit.radius * 1.5;
    if (control.auto) control.yaw += dt * (2 * Math.PI / 20);
    const dir = [
      -Math.cos(control.pitch) * Math.cos(control.yaw),
      -Math.sin(control.pitch),
      -Math.cos(control.pitch) * Math.sin(control.yaw)
    ];
    const speed = orbit.radius * 0.5 * dt;
    const k = control.keys;
    const fwd = (k.has("w") ? 1 : 0) - (k.has("s") ? 1 : 0);
    const side = (k.has("d") ? 1 : 0) - (k.has("a") ? 1 : 0);
    const lift = (k.has("e") ? 1 : 0) - (k.has("q") ? 1 : 0);
    if (fwd || side || lift) control.auto = false;
    const c = orbit.centre;
    const right = [-dir[2], 0, dir[0]];
    const rl = Math.hypot(right[0], right[2]) || 1;
    for (let i = 0; i < 3; i++) c[i] += speed * (fwd * dir[i] + side * right[i] / rl + (i === 1 ? lift : 0));
    const d = control.distance;
    return {
      frame: cameraFrame2,
      position: [c[0] - d * dir[0], c[1] - d * dir[1], c[2] - d * dir[2]],
      target: [c[0], c[1], c[2]],
      up: [0, 1, 0],
      fovY: Math.PI / 3,
      near: Math.max(d * 1e-3, 1e-3),
      far: (d + orbit.radius) * 4,
      aspect: canvas.width / Math.max(canvas.height, 1)
    };
  }
  function pathCamera(p, frame, index) {
    const f2 = p.frames[index % p.frames.length];
    return {
      frame,
      position: [f2[0], f2[1], f2[2]],
      target: [f2[3], f2[4], f2[5]],
      up: [f2[6], f2[7], f2[8]],
      fovY: f2[9],
      near: f2[10],
      far: f2[11],
      aspect: canvas.width / Math.max(canvas.height, 1)
    };
  }
  function currentCamera(now) {
    if (path && lockstep && testFrames !== null) {
      if (!session?.state) return { cam: null, send: false };
      if (answered === sent && sent < testFrames - 1) {
        sent++;
        return { cam: pathCamera(path, sent, sent), send: true };
      }
      return { cam: pathCamera(path, Math.max(answered, 0), Math.max(answered, 0)), send: false };
    }
    if (path && control.auto) {
      if (!pathStart) pathStart = now;
      pathFrame = Math.floor((now - pathStart) / 1e3 * 60);
      pathShown = pathCamera(path, cameraFrame2, pathFrame);
      return { cam: pathShown, send: true };
    }
    if (pathShown) {
      takeOverFrom(pathShown);
      pathShown = null;
    }
    return { cam: orbitCamera(now), send: true };
  }
  var pathShown = null;
  function takeOverFrom(cam) {
    if (!orbit) return;
    const look = [0, 1, 2].map((i) => cam.target[i] - cam.position[i]);
    const d = Math.hypot(look[0], look[1], look[2]) || 1;
    control.pitch = Math.max(-1.5, Math.min(1.5, Math.asin(Math.max(-1, Math.min(1, -look[1] / d)))));
    control.yaw = Math.atan2(-look[2], -look[0]);
    control.distance = d;
    orbit.centre = [cam.target[0], cam.target[1], cam.target[2]];
  }
  function measureCost() {
    const cam = status.camera;
    if (!gl || !renderer || !cam) return null;
    const time = sceneTime(performance.now());
    renderer.draw(cam, { mode: MODE_COST, state: session?.state ?? null, grids, scale, shadowScale, time });
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let covered = 0;
    let cells = 0;
    let points = 0;
    let maxCells = 0;
    let maxPoints = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (px[i + 3] !== 255) continue;
      covered++;
      const p = px[i + 1] + 256 * px[i + 2];
      cells += px[i];
      points += p;
      maxCells = Math.max(maxCells, px[i]);
      maxPoints = Math.max(maxPoints, p);
    }
    renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, shadowScale, time });
    return {
      width: w,
      height: h,
      covered,
      cellsPerPixel: covered ? cells / covered : 0,
      pointsPerPixel: covered ? points / covered : 0,
      maxCells,
      maxPoints
    };
  }
  window.psaoCost = measureCost;
  var lastCamera = 0;
  var lastPointCount = 0;
  var lastPing = 0;
  var cost = null;
  function ping(now) {
    if (now - lastPing < 2e3) return;
    lastPing = now;
    const t0 = performance.now();
    const edge = status.edge;
    fetch(`${location.protocol}//${edge}/health`, { cache: "no-store" }).then((r) => r.arrayBuffer()).then(() => {
      status.rttMs = performance.now() - t0;
      status.rttEdge = edge;
    }).catch(() => status.rttMs = null);
  }
  function tick(now) {
    frames.push(now);
    frames = frames.filter((t) => now - t < 1e3);
    received = received.filter((r) => now - r.t < 1e3);
    status.fps = frames.length;
    status.mbitS = received.reduce((a, r) => a + r.bytes, 0) * 8 / 1e6;
    const w0 = fixedRes ? Number(fixedRes[1]) : Math.round(window.innerWidth * devicePixelRatio);
    const h0 = fixedRes ? Number(fixedRes[2]) : Math.round(window.innerHeight * devicePixelRatio);
    if (canvas.width !== w0 || canvas.height !== h0) {
      canvas.width = w0;
      canvas.height = h0;
      if (fixedRes) {
        canvas.style.width = `${w0}px`;
        canvas.style.height = `${h0}px`;
      }
    }
    if (!lockstep) ping(now);
    const { cam, send } = currentCamera(now);
    status.camera = cam;
    status.autoOrbit = control.auto;
    status.path = path && (control.auto || lockstep) ? path.name : null;
    status.pathFrame = lockstep ? Math.max(answered, 0) : pathFrame;
    if (cam && send && (lockstep || now - lastCamera > 1e3 / 30)) {
      lastCamera = now;
      session?.sendCamera(cam);
      cameraFrame2++;
    }
    const drawNow = !(lockstep && testFrames !== null) || answered === testFrames - 1;
    if (cam && renderer && drawNow) {
      grids?.upload();
      const t0 = performance.now();
      renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, shadowScale, time: sceneTime(now) });
      status.drawMs = performance.now() - t0;
      status.shadowMs = renderer.shadowMs;
      status.lit = session?.state?.hasLights() ?? false;
      status.drawn++;
      if (status.milestones.ao === null && status.mode !== MODE_NO_AO && grids && grids.cellPages > 0 && !grids.problem) {
        status.milestones.ao = performance.now();
      }
      status.relit.ms = renderer.relit?.ms ?? 0;
      if (renderer.relitError && status.relit.state === "ready") {
        status.relit.state = "error";
        status.message = renderer.relitError;
      }
      if (lockstep && testFrames !== null && answered === testFrames - 1 && status.relit.state !== "loading") status.done = true;
    }
    if (now - lastPointCount > 500) {
      lastPointCount = now;
      status.points = session?.state?.pointCount() ?? 0;
    }
    status.decodeMs = session && session.updates > 0 ? session.decodeMs / session.updates : 0;
    status.uploadedBytes = grids?.uploadedBytes ?? 0;
    status.rebuilds = grids?.rebuilds ?? 0;
    status.textureBytes = grids ? grids.textureBytes() : 0;
    const w = session?.welcomeMsg;
    const modeName = ["composited", "irradiance", "direct light", "AO only", "no AO"][status.mode] ?? "";
    overlay.textContent = [
      `psao viewer \u2014 ${status.connected ? `connected to ${status.edge}, scene ${w?.scene}, ${w?.instances.length} instances` : "not connected"}${edges.length > 1 ? ` (server ${edgeIndex + 1} of ${edges.length})` : ""}`,
      `${status.fps} fps \xB7 ${status.mbitS.toFixed(2)} Mbit/s \xB7 server frame ${status.serverFrame} \xB7 round trip ${status.rttMs === null ? "-" : `${status.rttMs.toFixed(1)} ms`}`,
      `${status.updates} updates \xB7 ${status.points} points received \xB7 ${status.decodeMs ? status.decodeMs.toFixed(2) : "-"} ms decode per update`,
      !renderer ? sceneError ?? (gl ? "loading the scene" : "WebGL2 unavailable: nothing drawn") : grids?.problem ? grids.problem : `view: ${modeName}, ${status.lit ? "lit (points' irradiance + shadow-mapped lights)" : "AO only"} (keys 1 2 3 4)${cost ? ` \xB7 AO shader ${cost.cellsPerPixel.toFixed(1)} cells, ${cost.pointsPerPixel.toFixed(1)} points per pixel (C)` : " \xB7 C: shader cost"}`,
      status.path ? `camera path ${status.path}, frame ${status.pathFrame} (drag, wheel or W A S D Q E to take over)` : `camera: ${path ? "yours" : "orbit"} (drag, wheel, W A S D Q E; Space: ${path ? "back to the path" : "auto"})`,
      verify ? `state hash ${status.hash ?? "-"}: ${status.verified} updates match the server, ${status.mismatches} differ` : "state hash not checked (add ?verify=1)"
    ].join("\n");
    message.textContent = status.message ? status.fatal ? `error: ${status.message}` : `${status.message}; reconnecting` : status.stalled ? `updates stalled: ${status.stalled}` : "";
    requestAnimationFrame(tick);
  }
  window.addEventListener("keydown", (e) => {
    if (e.key === "c") cost = measureCost();
  });
  var authHeaders = token === null ? {} : { Authorization: `Bearer ${token}` };
  async function loadRelit(r, c) {
    const source = r.source;
    const index = await fetch("/characters/index.json", { headers: authHeaders });
    const served = index.ok ? await index.json() : { count: 0, lighting: [] };
    if (params.get("relit") === "0" || served.count === 0 || !source) {
      status.relit.state = "none";
      return;
    }
    const models = await Promise.all(
      Array.from({ length: served.count }, async (_, i) => {
        const m = await fetch(`/characters/${i}.prt`, { headers: authHeaders });
        if (!m.ok) throw new Error(`/characters/${i}.prt: HTTP ${m.status}`);
        return new Uint8Array(await m.arrayBuffer());
      })
    );
    r.relit = new RelitCharacters(c, source.doc, source.read, source.instances, served, models);
    status.relit = {
      state: "ready",
      characters: served.count,
      vertices: r.relit.vertices,
      modelBytes: models.reduce((a, m) => a + m.length, 0),
      ms: 0
    };
  }
  function measureRelit(frames2 = 60) {
    const relit = renderer?.relit;
    if (!relit || !status.camera) return null;
    const state = session?.state ?? null;
    const transforms = Array.from({ length: state?.instanceCount() ?? 0 }, (_, i) => state?.transforms[i] ?? null);
    let maxMs = 0;
    const t0 = performance.now();
    for (let f2 = 0; f2 < frames2; f2++) {
      relit.frame(f2 / 60, transforms, status.camera.position);
      maxMs = Math.max(maxMs, relit.ms);
    }
    return { frames: frames2, vertices: relit.vertices, meanMs: (performance.now() - t0) / frames2, maxMs };
  }
  window.psaoRelitCost = measureRelit;
  var sceneLoaded = () => {
  };
  var sceneReady = new Promise((resolve) => sceneLoaded = resolve);
  fetch("/scene.glb", { headers: authHeaders }).then((r) => {
    if (r.status === 401) throw new Error("wrong or missing token (open the page with #token=\u2026)");
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return r.arrayBuffer();
  }).then((b) => {
    const glb = new Uint8Array(b);
    orbit = sceneBounds(glb);
    if (gl) {
      renderer = new SceneRenderer(gl, glb);
      sceneLoaded(renderer);
      status.milestones.scene = performance.now();
      if (pathName !== null) {
        path = renderer.paths.find((p) => p.name === pathName) ?? null;
        if (!path) status.message = `the scene has no camera path named ${pathName}`;
      } else if (!orbitOnly) {
        path = renderer.paths[0] ?? null;
      }
    } else {
      status.relit.state = "none";
    }
  }).catch((e) => {
    sceneError = `cannot load /scene.glb: ${e}`;
    status.relit.state = "none";
    status.message = sceneError;
    console.error(sceneError);
  });
  Codec.load(fetch("/psao.wasm")).then((c) => {
    codec = c;
    connect();
    sceneReady.then((r) => loadRelit(r, c)).catch((e) => {
      status.relit.state = "error";
      status.message = `relit characters: ${e instanceof Error ? e.message : e}`;
      console.error(status.message);
    });
  }).catch((e) => {
    status.message = `cannot load the decoder /psao.wasm: ${e}`;
  });
  requestAnimationFrame(tick);
})();
