//! HTTP on the serve port: the viewer, `/scene.glb`, `/health`, the WebSocket at `/ws`, and
//! 4xx answers to bad requests that leave the server serving.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::time::Duration;

mod common;

use common::{listening_addr, start_role, stderr, Proc, BIN};

/// A `psao serve` of the built-in scene at few points, killed on drop.
struct Serve {
    child: Proc,
    addr: String,
}

impl Serve {
    fn start(extra: &[&str]) -> Serve {
        let server = [
            "--listen",
            "127.0.0.1:0",
            "--points",
            "48",
            "--ray-budget",
            "20000",
        ];
        let (child, line) = start_role("serve", "default", &server, extra);
        let addr = listening_addr(&line);
        Serve { child, addr }
    }
}

/// Sends `request` as is and reads the whole answer (the request asks to close).
fn raw(addr: &str, request: &[u8]) -> Vec<u8> {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).unwrap();
    let mut all = Vec::new();
    let _ = s.read_to_end(&mut all);
    all
}

/// Status code and body of `GET path` (or another method).
fn request(addr: &str, method: &str, path: &str, extra_headers: &str) -> (u16, Vec<u8>) {
    let req = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n{extra_headers}\r\n"
    );
    let all = raw(addr, req.as_bytes());
    status_and_body(&all)
}

fn status_and_body(all: &[u8]) -> (u16, Vec<u8>) {
    let end = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no HTTP head in {:?}", String::from_utf8_lossy(all)));
    let head = String::from_utf8_lossy(&all[..end]);
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("bad status line in {head}"));
    (status, all[end + 4..].to_vec())
}

#[test]
fn http_endpoints_answer_and_bad_requests_get_4xx() {
    let server = Serve::start(&["--token", "sesame"]);
    let addr = server.addr.as_str();

    let (status, body) = request(addr, "GET", "/", "");
    assert_eq!(status, 200);
    let page = String::from_utf8_lossy(&body);
    assert!(page.contains("viewer.js"), "{page}");
    let (status, js) = request(addr, "GET", "/viewer.js", "");
    assert_eq!(status, 200);
    assert!(!js.is_empty());
    // The decoder: a WebAssembly module, served without the token like the script.
    let (status, wasm) = request(addr, "GET", "/psao.wasm", "");
    assert_eq!(status, 200);
    assert!(
        wasm.starts_with(b"\0asm"),
        "{:?}",
        &wasm[..wasm.len().min(8)]
    );

    // Without the token /health says only that the server is up, and /scene.glb is refused.
    let (status, health) = request(addr, "GET", "/health", "");
    assert_eq!(status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health).unwrap();
    assert_eq!(h, serde_json::json!({ "status": "ok" }));
    assert_eq!(request(addr, "GET", "/scene.glb", "").0, 401);
    assert_eq!(
        request(addr, "GET", "/scene.glb", "Authorization: Bearer nope\r\n").0,
        401
    );

    let (status, health) = request(addr, "GET", "/health", AUTH);
    assert_eq!(status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health).unwrap();
    assert_eq!(h["status"], "ok");
    assert_eq!(h["protocol"], psao_wire::PROTOCOL_VERSION);
    assert_eq!(h["scene"], "default");

    let (status, glb) = request(addr, "GET", "/scene.glb", AUTH);
    assert_eq!(status, 200);
    assert_eq!(&glb[..4], b"glTF");
    let length = u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize;
    assert_eq!(length, glb.len());

    // Bad requests: wrong method, unknown path, /ws without an upgrade, an oversized head,
    // a request line that is no HTTP.
    assert_eq!(request(addr, "POST", "/health", "").0, 405);
    assert_eq!(request(addr, "DELETE", "/scene.glb", "").0, 405);
    assert_eq!(request(addr, "GET", "/etc/passwd", "").0, 404);
    assert_eq!(request(addr, "GET", "/ws", "").0, 400);
    let bad_upgrade = "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 8\r\n";
    assert_eq!(request(addr, "GET", "/ws", bad_upgrade).0, 400);
    let huge = format!("X-Filler: {}\r\n", "a".repeat(64 << 10));
    let answer = raw(
        addr,
        format!("GET / HTTP/1.1\r\nHost: x\r\n{huge}\r\n").as_bytes(),
    );
    if !answer.is_empty() {
        let (status, _) = status_and_body(&answer);
        assert!((400..500).contains(&status), "oversized head: {status}");
    }
    let (status, _) = status_and_body(&raw(addr, b"GET \x00\x01\x02 garbage\r\n\r\n"));
    assert_eq!(status, 400);
    // The largest legitimate head a browser sends is a few KiB: 6 KiB of headers pass.
    let cookies = format!("Cookie: {}\r\n", "c".repeat(6 << 10));
    assert_eq!(request(addr, "GET", "/health", &cookies).0, 200);

    // Still serving: a WebSocket client with the token (at /ws by default) and one without.
    let view = |token: Option<&str>| {
        let mut c = Command::new(BIN);
        c.args(["--log", "warn", "view", "--connect"])
            .arg(format!("ws://{addr}"))
            .args(["--frames", "20", "--res", "32x18", "--retry-secs", "5"]);
        if let Some(t) = token {
            c.args(["--token", t]);
        }
        c.output().unwrap()
    };
    let o = view(Some("sesame"));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = view(Some("wrong"));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("token"), "{}", stderr(&o));
    let (status, health) = request(addr, "GET", "/health", AUTH);
    assert_eq!(status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health).unwrap();
    assert!(h["server_frame"].as_u64().unwrap() > 0, "{h}");
}

/// The `Authorization` header with the tests' token.
const AUTH: &str = "Authorization: Bearer sesame\r\n";

/// The head of the answer to `request` (as is), lowercase.
fn head_of(addr: &str, request: &str) -> String {
    let all = raw(addr, request.as_bytes());
    let end = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or(all.len());
    String::from_utf8_lossy(&all[..end]).to_lowercase()
}

#[test]
fn hosts_and_origins_other_than_the_servers_own_and_loopback_are_refused() {
    let server = Serve::start(&["--allow-origin", "https://viewer.example.org"]);
    let addr = server.addr.as_str();
    let upgrade = "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n\
        Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
    let get = |path: &str, host: &str, extra: &str| {
        head_of(
            addr,
            &format!("GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n{extra}\r\n"),
        )
    };
    // DNS rebinding: a name the operator did not allow, on any route.
    for path in ["/", "/health", "/scene.glb", "/ws"] {
        let head = get(path, "rebind.attacker.example:7878", upgrade);
        assert!(head.starts_with("http/1.1 403"), "{path}: {head}");
    }
    assert!(get("/health", "viewer.example.org", "").starts_with("http/1.1 200"));
    // WebSocket upgrades: pages of another origin are refused, the own, loopback and allowed
    // origins (and clients that send no Origin) are taken.
    let with_origin = |origin: &str| get("/ws", addr, &format!("{upgrade}Origin: {origin}\r\n"));
    assert!(with_origin("http://evil.example.com").starts_with("http/1.1 403"));
    assert!(with_origin("null").starts_with("http/1.1 403"));
    for ok in [
        format!("http://{addr}"),
        "http://localhost:3000".into(),
        "https://viewer.example.org".into(),
    ] {
        assert!(with_origin(&ok).starts_with("http/1.1 101"), "{ok}");
    }
    assert!(get("/ws", addr, upgrade).starts_with("http/1.1 101"));
    // /health is readable cross-origin by allowed origins only.
    let cors = |origin: &str| get("/health", addr, &format!("Origin: {origin}\r\n"));
    assert!(cors("http://127.0.0.1:9").contains("access-control-allow-origin: http://127.0.0.1:9"));
    assert!(!cors("http://evil.example.com").contains("access-control-allow-origin"));
}

#[test]
fn tls_serves_https_and_wss_with_a_certificate_made_here() {
    let dir = tempfile::tempdir().unwrap();
    let made = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
    let (cert, key) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
    std::fs::write(&cert, made.cert.pem()).unwrap();
    std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
    let server = Serve::start(&[
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        key.to_str().unwrap(),
    ]);
    let port = server.addr.rsplit(':').next().unwrap();
    let wss = format!("wss://localhost:{port}");
    let view = |extra: &[&str]| {
        Command::new(BIN)
            .args(["--log", "warn", "view", "--connect", &wss])
            .args(["--frames", "20", "--res", "32x18", "--retry-secs", "3"])
            .args(extra)
            .output()
            .unwrap()
    };
    // Trusting the certificate: a full session over wss.
    let o = view(&["--tls-ca", cert.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("20 frames"));
    // Not trusting it (Mozilla roots only): refused with a certificate error.
    let o = view(&[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).to_lowercase().contains("certificate"),
        "{}",
        stderr(&o)
    );
    // Plain HTTP and raw frames on the TLS port get no answer, and the server goes on.
    let answer = raw(
        &server.addr,
        b"GET /health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
    );
    assert!(!answer.starts_with(b"HTTP/1.1 200"));
    let o = view(&["--tls-ca", cert.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn tls_refuses_files_that_are_no_certificate_or_key() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.pem");
    std::fs::write(&junk, "not a certificate\n").unwrap();
    let o = common::psao(&[
        "serve",
        "--listen",
        "127.0.0.1:0",
        "--tls-cert",
        junk.to_str().unwrap(),
        "--tls-key",
        junk.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("TLS") && err.contains("junk.pem"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let o = common::psao(&["serve", "--tls-cert", junk.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--tls-key"), "{}", stderr(&o));
}

/// Resident memory of process `pid`, bytes.
fn rss(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    kb << 10
}

/// Open file descriptors of process `pid`.
fn open_fds(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .count()
}

/// A connection from `from` (another loopback address) to `addr` with a 2 KiB receive buffer
/// that sends `request` and then never reads; `None` when the connection failed.
fn slow_reader(from: &str, addr: &str, request: &[u8]) -> Option<TcpStream> {
    use socket2::{Domain, Socket, Type};
    let socket = Socket::new(Domain::IPV4, Type::STREAM, None).ok()?;
    socket.set_recv_buffer_size(2048).ok()?;
    let local: std::net::SocketAddr = format!("{from}:0").parse().unwrap();
    socket.bind(&local.into()).ok()?;
    let remote: std::net::SocketAddr = addr.parse().unwrap();
    socket
        .connect_timeout(&remote.into(), Duration::from_secs(5))
        .ok()?;
    let mut s: TcpStream = socket.into();
    s.set_write_timeout(Some(Duration::from_secs(1))).ok()?;
    // The server may already have closed it (over its per-source cap): ignore write errors.
    let _ = s.write_all(request);
    Some(s)
}

/// `psao view` of 30 frames over `connect` (giving up after 5 s without a connection): its
/// JSON summary, or the error output.
fn view_within_5s(connect: &str) -> Result<serde_json::Value, String> {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("view.json");
    let o = Command::new(BIN)
        .args(["--log", "warn", "view", "--connect", connect])
        .args(["--frames", "30", "--res", "32x18", "--retry-secs", "5"])
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    if !o.status.success() {
        return Err(stderr(&o));
    }
    Ok(common::json(&json))
}

#[test]
fn slow_readers_from_one_address_lock_nobody_out_and_memory_stays_bounded() {
    let server = Serve::start(&[]);
    let addr = server.addr.clone();
    let pid = server.child.0.id();
    // Idle: after the first full request of each kind.
    assert_eq!(request(&addr, "GET", "/scene.glb", "").0, 200);
    assert_eq!(request(&addr, "GET", "/viewer.js", "").0, 200);
    let idle = rss(pid);
    // 1100 connections from 127.0.0.2 asking for the scene (and the script, pipelined) and
    // never reading the answers.
    let req = format!("GET /scene.glb HTTP/1.1\r\nHost: {addr}\r\n\r\n")
        + &format!("GET /viewer.js HTTP/1.1\r\nHost: {addr}\r\n\r\n").repeat(4);
    let attackers: Vec<TcpStream> = (0..1100)
        .filter_map(|_| slow_reader("127.0.0.2", &addr, req.as_bytes()))
        .collect();
    assert!(!attackers.is_empty(), "no attacking connection was made");
    // A viewer from 127.0.0.1 connects and receives frames within 5 s.
    let summary = view_within_5s(&addr).unwrap_or_else(|e| panic!("viewer locked out: {e}"));
    assert!(summary["updates"].as_u64().unwrap() > 0, "{summary}");
    let grown = rss(pid).saturating_sub(idle);
    assert!(
        grown < 200 << 20,
        "server RSS grew by {} MB with slow readers",
        grown >> 20
    );
    // WebSocket sessions hold their connection's slot: 100 upgrades from one address leave
    // at most the per-source cap (64) open on the server.
    drop(attackers);
    let before = open_fds(pid);
    let upgrade = format!(
        "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
    );
    let upgraded: Vec<TcpStream> = (0..100)
        .filter_map(|_| slow_reader("127.0.0.3", &addr, upgrade.as_bytes()))
        .collect();
    assert_eq!(upgraded.len(), 100);
    // Each connection the server kept answers 101; the others are closed unanswered.
    let mut switched = 0;
    for mut s in upgraded.iter() {
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut head = [0u8; 12];
        if s.read_exact(&mut head).is_ok() && head.starts_with(b"HTTP/1.1 101") {
            switched += 1;
        }
    }
    assert_eq!(switched, 64, "upgrades answered from one address");
    let open = open_fds(pid);
    assert!(
        open <= before + 64 + 4,
        "{open} fds open on the server with {switched} upgraded sessions (before: {before})"
    );
    let summary = view_within_5s(&format!("ws://{addr}")).unwrap_or_else(|e| panic!("{e}"));
    assert!(summary["updates"].as_u64().unwrap() > 0, "{summary}");
}
