// One session with `psao serve` over a WebSocket: hello, welcome, then updates decoded into
// the client state (the Rust decoder and state in wasm, `codec.ts`) and acknowledged; every update that carries the server's state hash is
// checked against the client's (as `psao view` does). Runs in the browser and in Node (whose
// global WebSocket has the same interface).

import { DecodeError, ViewerState, type Codec } from "./codec";
import {
  ackFrame,
  byeFrame,
  CAP_CODEC_COMPACT,
  CAP_STATE_HASH,
  CAP_STATUS,
  cameraFrame,
  decodeFrame,
  helloFrame,
  PROTOCOL_VERSION,
  type Camera,
  type InstanceEntry,
  type Message,
  type Welcome,
} from "./wire";

/// Longest a session goes without sending (psao-net's `KEEP_ALIVE`); the server drops clients
/// silent for 30 s.
const KEEP_ALIVE_MS = 5000;

/// What a session reports to its owner.
export interface SessionHandler {
  welcome(w: Welcome): void;
  /// An update of server frame `frame` was applied (its changes are `state.changes()`);
  /// `verified` is whether it carried the server's hash (it matched).
  update(frame: number, frameBytes: number, verified: boolean): void;
  /// The server's frame and scene time (seconds) with every update and scene-time message;
  /// `clientFrame` is the lockstep client frame answered, if any.
  sceneTime?(frame: number, clientFrame: number | null, seconds: number): void;
  /// The server's updates stalled (`text` says why; a scale-out edge waiting for its trace
  /// nodes), or flow again (`null`).
  status?(text: string | null): void;
  /// The session ended: `fatal` when reconnecting cannot help (wrong token or version).
  closed(reason: string, fatal: boolean): void;
}

/// Share of the page's time that checking the server's state hash may take, as in
/// `psao view` (`psao_net::hash_pacing`, docs/PROTOCOL.md): a hash reads the whole state,
/// so on a large scene an update's hash is checked only once the last check's cost is this
/// share of the time since it started; a small scene's is checked at every update, and in
/// lockstep every one is.
const HASH_SHARE = 0.1;

/// Settings of a session.
export interface SessionOptions {
  url: string;
  token: string | null;
  /// Ask for the server's state hash with every update and check it.
  verify: boolean;
  name: string;
}

/// A live session.
export class Session {
  state: ViewerState | null = null;
  welcomeMsg: Welcome | null = null;
  bytes = 0;
  updates = 0;
  mismatches = 0;
  lastHash: bigint | null = null;
  /// Milliseconds spent decoding and applying updates (hash checks excluded).
  decodeMs = 0;
  private ws: WebSocket;
  private done = false;
  /// When the last frame went to the server (ms, `performance.now()`).
  private lastSent = 0;
  private lastAck = 0;
  private keepAlive: ReturnType<typeof setInterval> | null = null;
  /// When the next hash check is due (ms, `performance.now()`).
  private nextCheck = 0;

  constructor(
    private codec: Codec,
    private opts: SessionOptions,
    private handler: SessionHandler,
  ) {
    this.ws = new WebSocket(opts.url);
    this.ws.binaryType = "arraybuffer";
    this.ws.onopen = () => {
      const caps = CAP_CODEC_COMPACT | CAP_STATUS | (opts.verify ? CAP_STATE_HASH : 0);
      this.send(helloFrame({ version: PROTOCOL_VERSION, capabilities: caps, token: opts.token, name: opts.name }));
      // The server drops a client silent for 30 s: when no camera went out for KEEP_ALIVE_MS
      // (a hidden tab draws no frames), an ack of the last acknowledged frame says we are here.
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
        this.fail(`${what} from the server: ${(e as Error).message}`, true);
      }
    };
    this.ws.onclose = () => this.end("the connection closed", false);
    this.ws.onerror = () => this.end("the connection failed", false);
  }

  private handle(m: Message, size: number) {
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
        // In lockstep every hash is checked, as `psao view` does: each round waits anyway.
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
        const text =
          m.code === "Token"
            ? `wrong or missing token: ${m.message}`
            : m.code === "Version"
              ? `protocol version mismatch: ${m.message}`
              : `server error (${m.code}): ${m.message}`;
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
  sendCamera(c: Camera) {
    if (!this.done && this.ws.readyState === WebSocket.OPEN) this.send(cameraFrame(c));
  }

  private send(frame: Uint8Array<ArrayBuffer>) {
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

  private fail(reason: string, fatal: boolean) {
    this.end(reason, fatal);
    this.ws.close();
  }

  private end(reason: string, fatal: boolean) {
    if (this.done) return;
    this.done = true;
    if (this.keepAlive !== null) clearInterval(this.keepAlive);
    this.handler.closed(reason, fatal);
  }
}
