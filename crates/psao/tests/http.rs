//! HTTP on the serve port: the viewer, `/scene.glb`, `/health`, the WebSocket at `/ws`, and
//! 4xx answers to bad requests that leave the server serving.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

mod common;

use common::{stderr, BIN};

/// A `psao serve` of the built-in scene at few points, killed on drop.
struct Serve {
    child: Child,
    addr: String,
}

impl Serve {
    fn start(extra: &[&str]) -> Serve {
        let mut child = Command::new(BIN)
            .args(["--log", "warn", "serve", "--listen", "127.0.0.1:0"])
            .args(["--points", "48", "--ray-budget", "20000"])
            .args(extra)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let addr = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected serve output {line:?}"))
            .to_string();
        Serve { child, addr }
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
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

    let (status, health) = request(addr, "GET", "/health", "");
    assert_eq!(status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health).unwrap();
    assert_eq!(h["status"], "ok");
    assert_eq!(h["protocol"], psao_wire::PROTOCOL_VERSION);
    assert_eq!(h["scene"], "default");

    let (status, glb) = request(addr, "GET", "/scene.glb", "");
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
    let (status, health) = request(addr, "GET", "/health", "");
    assert_eq!(status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health).unwrap();
    assert!(h["server_frame"].as_u64().unwrap() > 0, "{h}");
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
