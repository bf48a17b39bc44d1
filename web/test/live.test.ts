// The viewer's session code against a real `psao serve` (the release binary; PSAO_BIN
// overrides its path): its state hash equals the server's at every update that carries it while a
// `psao view` drives the server along the built-in camera path; a wrong token ends the session
// with a clear message; garbage on a WebSocket leaves the server serving the others.
// Node runs it with --experimental-websocket (Node 20) for the global WebSocket.
import { test } from "node:test";
import assert from "node:assert/strict";
import { spawn, type ChildProcess } from "node:child_process";
import { createInterface } from "node:readline";
import { fileURLToPath } from "node:url";
import { readFileSync } from "node:fs";
import { Codec } from "../src/codec";
import { Session } from "../src/session";

// Bundled into build/test/: the workspace's target/ is three levels up.
const BIN = process.env.PSAO_BIN ?? fileURLToPath(new URL("../../../target/release/psao", import.meta.url));
// The decoder as the page loads it (web/dist/psao.wasm, two levels up from build/test/).
const codec = await Codec.load(readFileSync(new URL("../../dist/psao.wasm", import.meta.url)));
const SERVER = ["--points", "96", "--ray-budget", "40000", "--hz", "30"];

async function serve(extra: string[]): Promise<{ child: ChildProcess; addr: string }> {
  const child = spawn(BIN, ["--log", "warn", "serve", "--listen", "127.0.0.1:0", ...SERVER, ...extra], {
    stdio: ["ignore", "pipe", "inherit"],
  });
  const lines = createInterface({ input: child.stdout! });
  const line: string = await new Promise((resolve, reject) => {
    lines.once("line", resolve);
    child.once("exit", (code) => reject(new Error(`psao serve exited (${code})`)));
  });
  const addr = line.replace("listening on ", "").trim();
  return { child, addr };
}

function run(args: string[]): Promise<number> {
  return new Promise((resolve) => {
    const c = spawn(BIN, ["--log", "warn", ...args], { stdio: ["ignore", "ignore", "inherit"] });
    c.once("exit", (code) => resolve(code ?? -1));
  });
}

interface Outcome {
  session: Session;
  welcomed: Promise<void>;
  closed: Promise<{ reason: string; fatal: boolean }>;
  verified: () => number;
}

function open(addr: string, token: string | null): Outcome {
  let verifiedCount = 0;
  let welcomed!: () => void;
  let closed!: (v: { reason: string; fatal: boolean }) => void;
  const w = new Promise<void>((r) => (welcomed = r));
  const c = new Promise<{ reason: string; fatal: boolean }>((r) => (closed = r));
  const session = new Session(
    codec,
    { url: `ws://${addr}/ws`, token, verify: true, name: "node test" },
    {
      welcome: () => welcomed(),
      update: (_frame, _size, verified) => {
        if (verified) verifiedCount++;
      },
      closed: (reason, fatal) => closed({ reason, fatal }),
    },
  );
  return { session, welcomed: w, closed: c, verified: () => verifiedCount };
}

test("the viewer's state hash equals the server's at every update that carries it", { timeout: 120_000 }, async () => {
  const { child, addr } = await serve([]);
  try {
    const o = open(addr, null);
    await o.welcomed;
    o.session.sendCamera({
      frame: 0,
      position: [4, 2, 6],
      target: [0, 0.5, 0],
      up: [0, 1, 0],
      fovY: 1.0,
      near: 0.05,
      far: 100,
      aspect: 16 / 9,
    });
    const code = await run(["view", "--connect", addr, "--frames", "180", "--res", "64x36"]);
    assert.equal(code, 0, "psao view failed");
    await new Promise((r) => setTimeout(r, 300));
    const s = o.session;
    assert.equal(s.mismatches, 0, "updates left the viewer's state different from the server's");
    // Outside lockstep the server hashes its state, and the viewer checks a hash, only as
    // often as the hash's cost allows (docs/PROTOCOL.md, "State hash"), and the server
    // coalesces what the viewer cannot take in time: the counts vary, but hashes keep coming
    // and every one checked matched.
    assert.ok(s.updates >= 3, `only ${s.updates} updates`);
    assert.ok(o.verified() >= 3, `only ${o.verified()} of ${s.updates} updates checked against the server's hash`);
    const points = s.state!.pointCount();
    assert.ok(points > 1000, `only ${points} points received`);
    s.close();
  } finally {
    child.kill();
  }
});

test("a wrong token ends the session with a clear message", { timeout: 60_000 }, async () => {
  const { child, addr } = await serve(["--token", "sesame"]);
  try {
    const wrong = open(addr, "open sesame");
    const end = await wrong.closed;
    assert.ok(end.fatal);
    assert.match(end.reason, /wrong or missing token/);
    const right = open(addr, "sesame");
    await right.welcomed;
    right.session.close();
  } finally {
    child.kill();
  }
});

test("garbage on a WebSocket leaves the server serving the others", { timeout: 60_000 }, async () => {
  const { child, addr } = await serve([]);
  try {
    const good = open(addr, null);
    await good.welcomed;
    for (const junk of [new Uint8Array([1, 2, 3]), new TextEncoder().encode("PSW1 garbage garbage")]) {
      const ws = new WebSocket(`ws://${addr}/ws`);
      ws.binaryType = "arraybuffer";
      await new Promise((r) => (ws.onopen = r));
      ws.send(junk);
      ws.send("text is no frame");
      await new Promise((r) => ((ws.onclose = r), setTimeout(r, 3000)));
    }
    const later = open(addr, null);
    await later.welcomed;
    later.session.sendCamera({
      frame: 0,
      position: [4, 2, 6],
      target: [0, 0.5, 0],
      up: [0, 1, 0],
      fovY: 1.0,
      near: 0.05,
      far: 100,
      aspect: 16 / 9,
    });
    const start = Date.now();
    while (later.session.updates < 3 && Date.now() - start < 20_000) await new Promise((r) => setTimeout(r, 50));
    assert.ok(later.session.updates >= 3, "the server stopped serving");
    assert.equal(later.session.mismatches, 0);
    assert.ok(good.session.updates >= 1, "the first client was dropped");
    good.session.close();
    later.session.close();
  } finally {
    child.kill();
  }
});
