//! Streaming over real loopback connections: `psao serve` and `psao view` processes, plus
//! hand-made hostile peers. A tiny OBJ scene keeps every server start well under a second.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{free_port, json, stderr, BIN};
use psao_wire::{
    capabilities, encode_frame, frame_payload, CameraMsg, Delta, ErrorCode, Hello, InstanceEntry,
    Message, Welcome, HEADER_LEN, MAGIC, PROTOCOL_VERSION,
};

/// Server settings of every test: few points, small budget.
const SERVER: &[&str] = &["--points", "96", "--ray-budget", "40000"];

/// A small room (floor, two walls, a box) and a 2-second camera path through it.
struct Fixture {
    dir: tempfile::TempDir,
    scene: &'static str,
}

impl Fixture {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let mut obj = String::new();
        let quads: [[[f32; 3]; 4]; 8] = [
            [[-4., 0., -4.], [4., 0., -4.], [4., 0., 4.], [-4., 0., 4.]],
            [[-4., 0., -4.], [-4., 3., -4.], [4., 3., -4.], [4., 0., -4.]],
            [[-4., 0., -4.], [-4., 0., 4.], [-4., 3., 4.], [-4., 3., -4.]],
            [[-1., 0., -1.], [-1., 1., -1.], [1., 1., -1.], [1., 0., -1.]],
            [[-1., 0., 1.], [1., 0., 1.], [1., 1., 1.], [-1., 1., 1.]],
            [[-1., 0., -1.], [-1., 0., 1.], [-1., 1., 1.], [-1., 1., -1.]],
            [[1., 0., -1.], [1., 1., -1.], [1., 1., 1.], [1., 0., 1.]],
            [[-1., 1., -1.], [-1., 1., 1.], [1., 1., 1.], [1., 1., -1.]],
        ];
        for (i, q) in quads.iter().enumerate() {
            for v in q {
                obj += &format!("v {} {} {}\n", v[0], v[1], v[2]);
            }
            let b = i * 4 + 1;
            obj += &format!("f {} {} {}\nf {} {} {}\n", b, b + 1, b + 2, b, b + 2, b + 3);
        }
        std::fs::write(dir.path().join("room.obj"), obj).unwrap();
        let path = "name = \"room\"\nfov_y_deg = 60.0\n\
            [[key]]\ntime = 0.0\nposition = [3.0, 1.6, 3.0]\nlook_at = [0.0, 0.5, 0.0]\n\
            [[key]]\ntime = 2.0\nposition = [-3.0, 1.6, 3.0]\nlook_at = [0.0, 0.5, -1.0]\n";
        std::fs::write(dir.path().join("path.toml"), path).unwrap();
        Self {
            dir,
            scene: "room.obj",
        }
    }

    /// The room under a sun and a point light (their direct light is the clients' to render).
    fn lit() -> Self {
        let mut fx = Self::new();
        let scene = "ao_radius = 0.6\n\
            [[asset]]\nfile = \"room.obj\"\n\
            [[light]]\nkind = \"sun\"\ndirection = [0.5, 1.0, 0.3]\npower = 2.0\n\
            [[light]]\nkind = \"point\"\nposition = [2.0, 2.0, 2.0]\npower = 3.0\n";
        std::fs::write(fx.dir.path().join("lit.toml"), scene).unwrap();
        fx.scene = "lit.toml";
        fx
    }

    /// The room with a box sliding over its floor and back (a 1.5 s loop).
    fn animated() -> Self {
        let mut fx = Self::new();
        let scene = "ao_radius = 0.6\n\
            [[asset]]\nfile = \"room.obj\"\n\
            [[asset]]\nfile = \"builtin:box\"\nscale = 0.5\n\
            keys = { times = [0.0, 0.75, 1.5], translation = [[-2.5, 0.25, 2.0], [2.5, 0.25, 2.0], [-2.5, 0.25, 2.0]] }\n";
        std::fs::write(fx.dir.path().join("moving.toml"), scene).unwrap();
        fx.scene = "moving.toml";
        fx
    }

    fn scene(&self) -> String {
        self.dir
            .path()
            .join(self.scene)
            .to_string_lossy()
            .into_owned()
    }

    fn path(&self) -> String {
        self.dir
            .path()
            .join("path.toml")
            .to_string_lossy()
            .into_owned()
    }

    fn file(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

/// A `psao serve` child, killed on drop.
struct Serve {
    child: Child,
    addr: String,
}

impl Serve {
    fn start(fx: &Fixture, listen: &str, extra: &[&str]) -> Serve {
        let mut child = Command::new(BIN)
            .args([
                "--log",
                "warn",
                "serve",
                "--scene",
                &fx.scene(),
                "--listen",
                listen,
            ])
            .args(SERVER)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        out.read_line(&mut line).unwrap();
        let addr = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected serve output {line:?}"))
            .to_string();
        Serve { child, addr }
    }

    /// Wait for the server to exit by itself (`--once`) within `secs`.
    fn wait(mut self, secs: u64) -> std::process::ExitStatus {
        let end = Instant::now() + Duration::from_secs(secs);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(Instant::now() < end, "psao serve did not exit");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn view_cmd(fx: &Fixture, addr: &str, frames: u32, extra: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args([
        "--log",
        "warn",
        "view",
        "--connect",
        addr,
        "--scene",
        &fx.scene(),
    ])
    .args([
        "--path",
        &fx.path(),
        "--frames",
        &frames.to_string(),
        "--res",
        "48x32",
    ])
    .args(extra);
    c
}

/// A view's JSON must show a final state equal to the server's at its last update.
/// `psao run` of the fixture's first `frames` frames at the settings the net tests' servers
/// use (and `extra`), writing frames into `out`.
fn run_in_process(fx: &Fixture, frames: u32, out: &Path, extra: &[&str]) {
    let o = Command::new(BIN)
        .args([
            "--log",
            "warn",
            "run",
            "--scene",
            &fx.scene(),
            "--path",
            &fx.path(),
        ])
        .args(SERVER)
        .args(["--server-hz", "30", "--res", "48x32"])
        .args(["--frames", &format!("0..{frames}")])
        .args(["--out", out.to_str().unwrap()])
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The composited and AO-only PNGs of the first `frames` frames in `got` are byte-identical
/// to those in `want`.
fn assert_same_frames(want: &Path, got: &Path, frames: u32, label: &str) {
    for f in 0..frames {
        for kind in ["frame", "ao"] {
            let name = format!("{kind}_{f:05}.png");
            assert_eq!(
                std::fs::read(want.join(&name)).unwrap(),
                std::fs::read(got.join(&name)).unwrap(),
                "{label} {name}"
            );
        }
    }
}

fn assert_exact(stats: &serde_json::Value) {
    assert_eq!(stats["hash_mismatches"], 0, "{stats}");
    assert_eq!(
        stats["state_hash"].as_str(),
        stats["server_state_hash"].as_str(),
        "{stats}"
    );
}

#[test]
fn lockstep_serve_and_two_views_reproduce_run() {
    let fx = Fixture::new();
    let server = Serve::start(
        &fx,
        "127.0.0.1:0",
        &["--hz", "30", "--lockstep", "--wait-clients", "2", "--once"],
    );
    let (a, b) = (fx.file("a"), fx.file("b"));
    let ws = format!("ws://{}", server.addr);
    let mut va = view_cmd(&fx, &server.addr, 5, &["--out", a.to_str().unwrap()])
        .spawn()
        .unwrap();
    let vb = view_cmd(&fx, &ws, 5, &["--out", b.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(vb.status.success(), "{}", stderr(&vb));
    assert!(va.wait().unwrap().success());
    assert!(server.wait(10).success());
    let r = fx.file("r");
    run_in_process(&fx, 5, &r, &[]);
    assert_same_frames(&r, &a, 5, "tcp view");
    assert_same_frames(&r, &b, 5, "ws view");
}

#[test]
fn animated_scene_lockstep_view_matches_run_and_the_server_state() {
    let fx = Fixture::animated();
    let server = Serve::start(
        &fx,
        "127.0.0.1:0",
        &["--hz", "30", "--lockstep", "--wait-clients", "1", "--once"],
    );
    let (a, r) = (fx.file("a"), fx.file("r"));
    let json_a = fx.file("a.json");
    let o = view_cmd(
        &fx,
        &server.addr,
        8,
        &[
            "--out",
            a.to_str().unwrap(),
            "--json",
            json_a.to_str().unwrap(),
        ],
    )
    .output()
    .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(server.wait(10).success());
    let view = json(&json_a);
    assert_exact(&view);
    // In lockstep every update carries the server's hash and every one is compared.
    assert!(view["updates"].as_u64().unwrap() > 0, "{view}");
    assert_eq!(view["hash_checks"], view["updates"], "{view}");
    run_in_process(&fx, 8, &r, &[]);
    let stats = json(&r.join("stats.json"));
    let invalidated: u64 = stats["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["invalidated_points"].as_u64().unwrap())
        .sum();
    assert!(invalidated > 0, "the sliding box invalidates floor points");
    assert_eq!(stats["state_hash"], json(&json_a)["state_hash"]);
    assert_same_frames(&r, &a, 8, "view");
}

#[test]
fn lit_lockstep_view_matches_run_and_the_server_state() {
    let fx = Fixture::lit();
    let lit = ["--lighting", "gi"];
    let server = Serve::start(
        &fx,
        "127.0.0.1:0",
        &[
            &["--hz", "30", "--lockstep", "--wait-clients", "1", "--once"][..],
            &lit,
        ]
        .concat(),
    );
    let (a, r, ao) = (fx.file("a"), fx.file("r"), fx.file("ao"));
    let json_a = fx.file("a.json");
    let o = view_cmd(
        &fx,
        &server.addr,
        5,
        &[
            "--out",
            a.to_str().unwrap(),
            "--json",
            json_a.to_str().unwrap(),
        ],
    )
    .output()
    .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(server.wait(10).success());
    // The server's hash covers its published irradiance records, the view's its received ones.
    assert_exact(&json(&json_a));
    run_in_process(&fx, 5, &r, &lit);
    let stats = json(&r.join("stats.json"));
    assert!(stats["light_paths"].as_u64().unwrap() > 0, "{stats}");
    assert_eq!(stats["state_hash"], json(&json_a)["state_hash"]);
    assert_same_frames(&r, &a, 5, "lit view");
    // The same session without lighting hashes and looks otherwise.
    run_in_process(&fx, 5, &ao, &["--lighting", "ao"]);
    assert_ne!(
        json(&ao.join("stats.json"))["state_hash"],
        stats["state_hash"]
    );
    let frame = |dir: &Path| std::fs::read(dir.join("frame_00004.png")).unwrap();
    assert_ne!(frame(&ao), frame(&r));
}

#[test]
fn dropped_client_reconnects_with_a_snapshot_and_matches_the_server() {
    let fx = Fixture::new();
    // No --once: the server must outlive the moment its only client is gone.
    let server = Serve::start(&fx, "127.0.0.1:0", &["--hz", "30"]);
    let stats = fx.file("v.json");
    let o = view_cmd(&fx, &server.addr, 60, &["--drop-at", "25"])
        .args(["--json", stats.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let s = json(&stats);
    assert_eq!(s["reconnects"], 1, "{s}");
    assert!(s["snapshots"].as_u64().unwrap() >= 2, "{s}");
    assert_eq!(s["frames"], 60);
    assert!(s["mbit_s"].as_f64().unwrap() > 0.0);
    assert_exact(&s);
    drop(server);
}

#[test]
fn server_restart_makes_the_client_reconnect_with_backoff() {
    let fx = Fixture::new();
    let listen = format!("127.0.0.1:{}", free_port());
    let first = Serve::start(&fx, &listen, &["--hz", "30"]);
    let stats = fx.file("v.json");
    let view = view_cmd(&fx, &listen, 120, &["--json", stats.to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(600));
    drop(first); // killed: no bye, the connection just breaks
    std::thread::sleep(Duration::from_millis(300));
    let _second = Serve::start(&fx, &listen, &["--hz", "30"]);
    let o = view.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let s = json(&stats);
    assert!(s["reconnects"].as_u64().unwrap() >= 1, "{s}");
    assert_exact(&s);
}

#[test]
fn slow_client_is_coalesced_without_stalling_the_others() {
    let fx = Fixture::new();
    let server = Serve::start(
        &fx,
        "127.0.0.1:0",
        &["--hz", "30", "--once", "--wait-clients", "2"],
    );
    let (fast, slow) = (fx.file("fast.json"), fx.file("slow.json"));
    let mut slow_view = view_cmd(&fx, &server.addr, 90, &["--max-mbit", "0.3"])
        .args(["--latency-ms", "50", "--json", slow.to_str().unwrap()])
        .spawn()
        .unwrap();
    let o = view_cmd(&fx, &server.addr, 90, &["--json", fast.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(slow_view.wait().unwrap().success());
    let (f, s) = (json(&fast), json(&slow));
    assert_exact(&f);
    assert_exact(&s);
    // 1.5 s at 30 Hz: the fast client gets (nearly) every server frame, the slow one far fewer
    // but coalesced updates that still leave it exact.
    let (fu, su) = (
        f["updates"].as_u64().unwrap(),
        s["updates"].as_u64().unwrap(),
    );
    assert!(fu >= 30, "fast client got only {fu} updates: {f}");
    assert!(su < fu, "slow client was not coalesced: {s} vs {f}");
    drop(server);
}

#[test]
fn ctrl_c_shuts_the_server_down_cleanly() {
    let fx = Fixture::new();
    let stats = fx.file("serve.json");
    let mut server = Serve::start(&fx, "127.0.0.1:0", &["--json", stats.to_str().unwrap()]);
    let o = view_cmd(&fx, &server.addr, 20, &[]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let pid = server.child.id().to_string();
    assert!(Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap()
        .success());
    let end = Instant::now() + Duration::from_secs(5);
    let status = loop {
        if let Some(s) = server.child.try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < end, "no exit after SIGINT");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success());
    let s = json(&stats);
    assert!(s["frames"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["clients"].as_array().unwrap().len(), 1, "{s}");
}

/// Raw frame with a correct header for `payload`.
fn raw_frame(payload: &[u8]) -> Vec<u8> {
    frame_payload(payload).unwrap()
}

fn hello(version: u16, token: Option<&str>) -> Vec<u8> {
    encode_frame(&Message::Hello(Hello {
        version,
        capabilities: capabilities::ALL,
        token: token.map(str::to_string),
        name: "test".into(),
    }))
    .unwrap()
}

/// [`common::exchange`] with the 8 s read deadline of these small sessions.
fn exchange(addr: &str, bytes: &[u8]) -> Vec<Message> {
    common::exchange(addr, bytes, Duration::from_secs(8))
}

fn error_code(messages: &[Message]) -> Option<ErrorCode> {
    messages.iter().find_map(|m| match m {
        Message::Error(e) => Some(e.code),
        _ => None,
    })
}

#[test]
fn hostile_clients_get_a_clear_error_and_the_server_keeps_serving() {
    let fx = Fixture::new();
    let server = Serve::start(
        &fx,
        "127.0.0.1:0",
        &["--hz", "30", "--token", "sesame", "--max-clients", "1"],
    );
    let addr = server.addr.as_str();
    let good = hello(PROTOCOL_VERSION, Some("sesame"));

    let m = exchange(addr, &hello(PROTOCOL_VERSION, Some("wrong")));
    assert_eq!(error_code(&m), Some(ErrorCode::Token), "{m:?}");
    let m = exchange(addr, &hello(PROTOCOL_VERSION, None));
    assert_eq!(error_code(&m), Some(ErrorCode::Token), "{m:?}");
    let m = exchange(addr, &hello(PROTOCOL_VERSION + 1, Some("sesame")));
    assert_eq!(error_code(&m), Some(ErrorCode::Version), "{m:?}");
    // A client that cannot decode the server's codec.
    let mut no_codec = Hello {
        version: PROTOCOL_VERSION,
        capabilities: capabilities::STATE_HASH,
        token: Some("sesame".into()),
        name: "test".into(),
    };
    let m = exchange(
        addr,
        &encode_frame(&Message::Hello(no_codec.clone())).unwrap(),
    );
    assert_eq!(error_code(&m), Some(ErrorCode::Protocol), "{m:?}");
    no_codec.capabilities = capabilities::ALL;
    let m = exchange(addr, &encode_frame(&Message::Hello(no_codec)).unwrap());
    assert!(matches!(m.first(), Some(Message::Welcome(_))), "{m:?}");

    // Truncated: half a hello, then the client stops sending.
    let m = exchange(addr, &good[..good.len() / 2]);
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");
    // Oversized: a header announcing 1 GiB.
    let mut big = MAGIC.to_vec();
    big.extend_from_slice(&(1u32 << 30).to_le_bytes());
    big.extend_from_slice(&[0; 4]);
    let m = exchange(addr, &big);
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");
    // Garbage without a frame header.
    let m = exchange(addr, b"\x00\x01garbage garbage garbage");
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");
    // A correct header and checksum over bytes that are no message.
    let m = exchange(addr, &raw_frame(&[0xff; 40]));
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");
    // Checksum failure.
    let mut bad = good.clone();
    *bad.last_mut().unwrap() ^= 0x55;
    let m = exchange(addr, &bad);
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");
    // After a good hello: a bad camera (NaN) and a server-only message.
    let mut seq = good.clone();
    let cam = CameraMsg {
        frame: 0,
        position: [f32::NAN, 1.0, 0.0],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y: 1.0,
        near: 0.1,
        far: 10.0,
        aspect: 1.0,
    };
    let mut payload = vec![2u8]; // Camera variant, encoded without validation
    payload.push(0);
    for v in cam.position.iter().chain(&cam.target).chain(&cam.up) {
        payload.extend_from_slice(&v.to_le_bytes());
    }
    for v in [cam.fov_y, cam.near, cam.far, cam.aspect] {
        payload.extend_from_slice(&v.to_le_bytes());
    }
    seq.extend_from_slice(&raw_frame(&payload));
    let m = exchange(addr, &seq);
    assert!(matches!(m.first(), Some(Message::Welcome(_))), "{m:?}");
    assert_eq!(error_code(&m), Some(ErrorCode::Frame), "{m:?}");

    // The server is still fine: a real client with the token gets exact state.
    let stats = fx.file("v.json");
    let o = view_cmd(&fx, addr, 20, &["--token", "sesame"])
        .args(["--json", stats.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_exact(&json(&stats));
    let o = view_cmd(&fx, addr, 5, &["--token", "nope"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("token"), "{}", stderr(&o));
    // --max-clients 1: a second client at the same time is refused.
    let mut first = view_cmd(&fx, addr, 90, &["--token", "sesame"])
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(400));
    let o = view_cmd(&fx, addr, 5, &["--token", "sesame"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("server full"), "{}", stderr(&o));
    assert!(first.wait().unwrap().success());
}

/// A fake server: accepts one client, answers its hello with a welcome for a one-instance
/// table, then sends `after` and keeps the connection open briefly.
fn fake_server(after: Vec<u8>) -> (String, std::thread::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let handle = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut header = [0u8; HEADER_LEN];
        s.read_exact(&mut header).unwrap();
        let len = u32::from_le_bytes(header[4..8].try_into().unwrap()) as usize;
        let mut payload = vec![0u8; len];
        s.read_exact(&mut payload).unwrap();
        let welcome = Message::Welcome(Welcome {
            version: PROTOCOL_VERSION,
            client_id: 0,
            codec: "compact".into(),
            server_hz: 30,
            client_hz: 60,
            lockstep: false,
            scene: "room".into(),
            frame: 0,
            scene_time: 0.0,
            instances: vec![InstanceEntry {
                origin: [-4.0, 0.0, -4.0],
                cell_size: 0.5,
                dims: [16, 6, 16],
                layout_poisson_radius: 0.1,
                bucket_count: 64,
                poisson_radius: 0.1,
                point_count: 100,
            }],
        });
        s.write_all(&encode_frame(&welcome).unwrap()).unwrap();
        let _ = s.write_all(&after);
        std::thread::sleep(Duration::from_millis(1500));
    });
    (addr, handle)
}

/// A zstd frame that claims, and really expands to, 1 GiB of zeros in about 32 KiB.
fn zstd_bomb() -> Vec<u8> {
    let mut z = vec![0x28, 0xb5, 0x2f, 0xfd, 0xe0];
    z.extend_from_slice(&(1u64 << 30).to_le_bytes());
    let blocks = (1usize << 30) / (128 << 10);
    for i in 0..blocks {
        let last = u32::from(i + 1 == blocks);
        let header = ((128u32 << 10) << 3) | (1 << 1) | last; // RLE block of 128 KiB
        z.extend_from_slice(&header.to_le_bytes()[..3]);
        z.push(0);
    }
    z
}

#[test]
fn client_refuses_bombs_and_bad_frames_from_a_server() {
    let fx = Fixture::new();
    let snapshot = Message::Snapshot(Delta {
        frame: 1,
        scene_time: 0.0,
        client_frame: None,
        state_hash: None,
        payload: zstd_bomb(),
    });
    let (addr, h) = fake_server(encode_frame(&snapshot).unwrap());
    let t = Instant::now();
    let o = view_cmd(&fx, &addr, 30, &["--retry-secs", "1"])
        .output()
        .unwrap();
    h.join().unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("exceeds the limit"), "{}", stderr(&o));
    assert!(t.elapsed() < Duration::from_secs(10));

    let mut bad = encode_frame(&snapshot).unwrap();
    bad[HEADER_LEN + 3] ^= 1; // checksum no longer matches
    let (addr, h) = fake_server(bad);
    let o = view_cmd(&fx, &addr, 30, &["--retry-secs", "1"])
        .output()
        .unwrap();
    h.join().unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("checksum"), "{}", stderr(&o));

    let (addr, h) = fake_server(b"this is not a frame at all".to_vec());
    let o = view_cmd(&fx, &addr, 30, &["--retry-secs", "1"])
        .output()
        .unwrap();
    h.join().unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("magic"), "{}", stderr(&o));
}

/// `psao bench serve` on the fixture's scene and path with `args`; its JSON report.
fn bench_serve(fx: &Fixture, args: &[&str]) -> serde_json::Value {
    let report = fx.dir.path().join("bench.json");
    let o = Command::new(BIN)
        .args(["--log", "warn", "bench", "serve", "--points", "64"])
        .args(args)
        .arg("--scene")
        .arg(fx.dir.path().join(fx.scene))
        .arg("--path")
        .arg(fx.dir.path().join("path.toml"))
        .arg("--json")
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    json(&report)
}

#[test]
fn bench_serve_runs_its_viewers_in_one_process_when_asked() {
    let fx = Fixture::new();
    let r = bench_serve(
        &fx,
        &[
            "--clients",
            "3",
            "--frames",
            "30",
            "--one-client-process",
            "--verify",
        ],
    );
    let clients = r["per_client"].as_array().unwrap();
    assert_eq!(clients.len(), 3, "{r}");
    for c in clients {
        assert!(c["updates"].as_u64().unwrap() > 0, "{r}");
        assert_eq!(
            c["exact"], true,
            "every viewer ends with the server's state: {r}"
        );
    }
    // Headless viewers in one process only: no images, no corrections.
    let o = Command::new(BIN)
        .args(["view", "--viewers", "2", "--out", "x", "--scene"])
        .arg(fx.dir.path().join(fx.scene))
        .output()
        .unwrap();
    assert!(
        !o.status.success() && stderr(&o).contains("--viewers"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bench_serve_runs_idle_priority_clients_and_reports_the_step_phases() {
    let fx = Fixture::new();
    let r = bench_serve(&fx, &["--clients", "2", "--frames", "40", "--client-idle"]);
    assert!(r["server_frames"].as_u64().unwrap() > 0, "{r}");
    let ms = |k: &str| r[k].as_f64().unwrap();
    let phases = ms("server_cull_ms") + ms("server_trace_ms") + ms("server_publish_ms");
    assert!(
        phases > 0.0 && phases <= ms("server_step_ms") * 1.01 + 0.01,
        "{r}"
    );
    for c in r["per_client"].as_array().unwrap() {
        assert!(
            c["updates"].as_u64().unwrap() > 0,
            "every client got updates: {r}"
        );
        // CPU time comes in 10 ms ticks: a short client may show none.
        let cores = c["cores"].as_f64().unwrap();
        assert!((0.0..=2.0).contains(&cores), "client CPU: {r}");
    }
}
