//! Scale-out on a `nats-server` with accounts and per-subject permissions (the configuration
//! of docs/SCALE-OUT.md, "Accounts and permissions"): a trace node and an edge run with their
//! own accounts and serve a viewer; an anonymous client is refused, and neither an edge's
//! account may publish records nor a trace node's views. Skips with a note when `nats-server`
//! is not installed.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{free_port, listening_addr, Proc, BIN};

/// Server settings of every process: few points, small budget.
const SERVER: &[&str] = &["--points", "96", "--ray-budget", "20000", "--hz", "30"];

/// The permissions of docs/SCALE-OUT.md, for any scene: trace nodes publish everything but
/// views; edges publish only views and JetStream API requests that do not delete or change
/// streams.
const PERMISSIONS: &str = r#"
authorization {
  users = [
    { user: trace, password: "trace-secret",
      permissions: { publish: { allow: [">"], deny: ["psao.*.views.*"] } } }
    { user: edge, password: "edge-secret",
      permissions: { publish: {
        allow: ["psao.*.views.*", "$JS.API.>", "$JS.ACK.>", "_INBOX.>"],
        deny: ["$JS.API.STREAM.DELETE.>", "$JS.API.STREAM.PURGE.>",
               "$JS.API.STREAM.MSG.DELETE.>", "$JS.API.STREAM.UPDATE.>"] } } }
  ]
}
"#;

/// What the NATS server answers a raw client that connects with `credentials` (a JSON
/// fragment), publishes to `subject` and pings: every line up to the `PONG` or the close.
fn raw_publish(port: u16, credentials: &str, subject: &str) -> String {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let connect = format!(
        "CONNECT {{\"verbose\":false,\"pedantic\":false{credentials}}}\r\n\
         PUB {subject} 5\r\nforge\r\nPING\r\n"
    );
    s.write_all(connect.as_bytes()).unwrap();
    let mut answer = String::new();
    let mut reader = BufReader::new(s);
    loop {
        let mut line = String::new();
        match reader.read_line(&mut line) {
            Ok(0) | Err(_) => break,
            Ok(_) => {
                answer += &line;
                if line.starts_with("PONG") {
                    break;
                }
            }
        }
    }
    answer
}

/// `psao <role> --scene SCENE <SERVER> <extra>`, its stdout's first line awaited.
fn start(role: &str, scene: &str, extra: &[&str]) -> (Proc, String) {
    common::start_role(role, scene, SERVER, extra)
}

fn write_scene(dir: &Path) -> String {
    let obj = "v -4 0 -4\nv 4 0 -4\nv 4 0 4\nv -4 0 4\nv -1 0 -1\nv -1 1 -1\nv 1 1 -1\nv 1 0 -1\n\
               f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n";
    let path = dir.join("room.obj");
    std::fs::write(&path, obj).unwrap();
    path.to_string_lossy().into_owned()
}

#[test]
fn accounts_serve_a_viewer_and_forbid_forged_publishing() {
    if Command::new("nats-server")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("note: nats-server is not installed: test skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = dir.path().join("nats.conf");
    let store = dir.path().join("js");
    std::fs::write(
        &conf,
        format!(
            "listen: \"127.0.0.1:{port}\"\njetstream {{ store_dir: {:?} }}\n{PERMISSIONS}",
            store.to_string_lossy()
        ),
    )
    .unwrap();
    let _nats = Proc(
        Command::new("nats-server")
            .arg("-c")
            .arg(&conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let end = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < end, "nats-server did not start");
        std::thread::sleep(Duration::from_millis(20));
    }

    // Anonymous clients are refused; each account may publish only its own subjects.
    let anonymous = raw_publish(port, "", "psao.room.rec.0");
    assert!(anonymous.contains("Authorization Violation"), "{anonymous}");
    let edge_auth = r#","user":"edge","pass":"edge-secret""#;
    let trace_auth = r#","user":"trace","pass":"trace-secret""#;
    for subject in [
        "psao.room.rec.0",
        "psao.room.snap.0.mark",
        "$KV.psao_room_leases.0",
    ] {
        let a = raw_publish(port, edge_auth, subject);
        assert!(a.contains("Permissions Violation"), "edge → {subject}: {a}");
    }
    let a = raw_publish(port, trace_auth, "psao.room.views.edge-1");
    assert!(a.contains("Permissions Violation"), "{a}");
    let a = raw_publish(port, trace_auth, "psao.room.rec.0");
    assert!(!a.contains("-ERR"), "{a}");

    // The real roles with their accounts (passwords from files) serve a viewer.
    let scene = write_scene(dir.path());
    let secret = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, format!("{text}\n")).unwrap();
        p.to_string_lossy().into_owned()
    };
    let (trace_pw, edge_pw) = (
        secret("trace.pw", "trace-secret"),
        secret("edge.pw", "edge-secret"),
    );
    let url = format!("nats://127.0.0.1:{port}");
    let (_node, ready) = start(
        "trace-node",
        &scene,
        &[
            "--nats",
            &url,
            "--nats-user",
            "trace",
            "--nats-password-file",
            &trace_pw,
        ],
    );
    assert!(ready.contains("ready"), "{ready}");
    let (_edge, listening) = start(
        "edge",
        &scene,
        &[
            "--nats",
            &url,
            "--listen",
            "127.0.0.1:0",
            "--nats-user",
            "edge",
            "--nats-password-file",
            &edge_pw,
        ],
    );
    let addr = listening_addr(&listening);
    let json = dir.path().join("view.json");
    let o = Command::new(BIN)
        .args([
            "--log",
            "warn",
            "view",
            "--connect",
            &addr,
            "--scene",
            &scene,
        ])
        .args(["--frames", "60", "--res", "32x18", "--retry-secs", "10"])
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::stderr(&o));
    let summary = common::json(&json);
    assert!(summary["updates"].as_u64().unwrap() > 0, "{summary}");
    // A wrong password is refused with the server's reason.
    let wrong = secret("wrong.pw", "nope");
    let o = Command::new(BIN)
        .args([
            "--log",
            "warn",
            "trace-node",
            "--scene",
            &scene,
            "--nats",
            &url,
        ])
        .args([
            "--nats-user",
            "trace",
            "--nats-password-file",
            &wrong,
            "--frames",
            "1",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let mut err = String::new();
    let _ = (&o.stderr[..]).read_to_string(&mut err);
    assert!(err.to_lowercase().contains("authorization"), "{err}");
}
