//! Scale-out over a real `nats-server -js` started on a free loopback port
//! (docs/SCALE-OUT.md): trace nodes and edges in lockstep end with the client state of
//! `psao serve` alone; a dead trace node's partition is adopted; a late edge catches up.
//! Every test skips with a note when `nats-server` is not installed.

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{free_port, json, listening_addr, start_role, stderr, Proc, BIN};

/// Server settings of every process: few points, small budget.
const SERVER: &[&str] = &["--points", "96", "--ray-budget", "20000", "--hz", "30"];

/// A small room (floor, wall, box) and a camera path that moves for 1 s, then stays still
/// until 10 s (so a clocked session converges).
fn fixture(dir: &Path) -> (String, String) {
    let quads: [[[f32; 3]; 4]; 5] = [
        [[-4., 0., -4.], [4., 0., -4.], [4., 0., 4.], [-4., 0., 4.]],
        [[-4., 0., -4.], [-4., 3., -4.], [4., 3., -4.], [4., 0., -4.]],
        [[-1., 0., -1.], [-1., 1., -1.], [1., 1., -1.], [1., 0., -1.]],
        [[-1., 0., 1.], [1., 0., 1.], [1., 1., 1.], [-1., 1., 1.]],
        [[-1., 1., -1.], [-1., 1., 1.], [1., 1., 1.], [1., 1., -1.]],
    ];
    let mut obj = String::new();
    for (i, q) in quads.iter().enumerate() {
        for v in q {
            obj += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        }
        let b = i * 4 + 1;
        obj += &format!("f {} {} {}\nf {} {} {}\n", b, b + 1, b + 2, b, b + 2, b + 3);
    }
    std::fs::write(dir.join("room.obj"), obj).unwrap();
    let path = "name = \"room\"\nfov_y_deg = 60.0\n\
        [[key]]\ntime = 0.0\nposition = [3.0, 1.6, 3.0]\nlook_at = [0.0, 0.5, 0.0]\n\
        [[key]]\ntime = 1.0\nposition = [-3.0, 1.6, 3.0]\nlook_at = [0.0, 0.5, -1.0]\n\
        [[key]]\ntime = 10.0\nposition = [-3.0, 1.6, 3.0]\nlook_at = [0.0, 0.5, -1.0]\n";
    std::fs::write(dir.join("path.toml"), path).unwrap();
    let s = |n: &str| dir.join(n).to_string_lossy().into_owned();
    (s("room.obj"), s("path.toml"))
}

impl Proc {
    /// Ask it to stop as Ctrl-C does, and wait for it to exit (successfully).
    fn interrupt(mut self, secs: u64) {
        let pid = self.0.id().to_string();
        Command::new("kill").args(["-INT", &pid]).status().unwrap();
        self.wait(secs);
    }

    fn wait(&mut self, secs: u64) {
        let end = Instant::now() + Duration::from_secs(secs);
        loop {
            if let Some(status) = self.0.try_wait().unwrap() {
                assert!(status.success(), "exited with {status}");
                return;
            }
            assert!(Instant::now() < end, "process did not exit in {secs} s");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// A `nats-server -js` on a free port, or `None` (with a note) when it is not installed.
fn nats(dir: &Path) -> Option<(Proc, String)> {
    if Command::new("nats-server")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("note: nats-server is not installed: scale-out test skipped");
        return None;
    }
    let port = free_port();
    Some((nats_on(dir, port), format!("nats://127.0.0.1:{port}")))
}

/// A `nats-server -js` on `port` keeping its streams under `dir/js`, once it accepts
/// connections.
fn nats_on(dir: &Path, port: u16) -> Proc {
    let child = Command::new("nats-server")
        .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
        .arg(dir.join("js"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let end = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < end, "nats-server did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    Proc(child)
}

/// `psao <role> --scene SCENE <SERVER> <extra>`, its stdout's first line awaited.
fn start(role: &str, scene: &str, extra: &[&str]) -> (Proc, String) {
    start_role(role, scene, SERVER, extra)
}

/// A `psao view` of `frames` frames writing its statistics to `out`.
fn view(connect: &str, scene: &str, path: &str, frames: u32, out: &Path) -> Child {
    view_with(connect, scene, path, frames, out, &[])
}

/// [`view`] with `extra` arguments.
fn view_with(
    connect: &str,
    scene: &str,
    path: &str,
    frames: u32,
    out: &Path,
    extra: &[&str],
) -> Child {
    Command::new(BIN)
        .args([
            "--log",
            "warn",
            "view",
            "--connect",
            connect,
            "--scene",
            scene,
        ])
        .args([
            "--path",
            path,
            "--frames",
            &frames.to_string(),
            "--res",
            "32x24",
        ])
        .args(extra)
        .arg("--json")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn finished(child: Child) {
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The final state hashes of `viewers` lockstep views of `psao serve` alone (files `s{i}.json`
/// in `dir`), each following `frames` frames of `path` with `view_args`; the server gets
/// `server_args` besides [`SERVER`].
fn serve_alone(
    dir: &Path,
    scene: &str,
    path: &str,
    viewers: usize,
    frames: u32,
    view_args: &[&str],
    server_args: &[&str],
) -> Vec<String> {
    let clients = viewers.to_string();
    // Scale-out carries no irradiance: the single server it is compared with is AO-only too.
    let mut args = vec![
        "--listen",
        "127.0.0.1:0",
        "--lockstep",
        "--wait-clients",
        &clients,
        "--once",
        "--lighting",
        "ao",
    ];
    args.extend(server_args);
    let (mut serve, line) = start("serve", scene, &args);
    let at = listening_addr(&line);
    let files: Vec<PathBuf> = (0..viewers)
        .map(|i| dir.join(format!("s{i}.json")))
        .collect();
    let views: Vec<Child> = files
        .iter()
        .map(|f| view_with(&at, scene, path, frames, f, view_args))
        .collect();
    views.into_iter().for_each(finished);
    serve.wait(20);
    view_hashes(&files)
}

/// Two processes of `role`, `0` and `1`, with `args(i)` and `extra` arguments; with
/// `reports`, process `i` writes its report to `reports/{prefix}{i}.json`. Returns each one
/// and the first line it printed.
fn pair(
    role: &str,
    scene: &str,
    args: impl Fn(u32) -> Vec<String>,
    extra: &[&str],
    reports: Option<(&Path, &str)>,
) -> Vec<(Proc, String)> {
    (0..2)
        .map(|i| {
            let mut all = args(i);
            all.extend(extra.iter().map(|a| a.to_string()));
            if let Some((dir, prefix)) = reports {
                let report = dir.join(format!("{prefix}{i}.json"));
                all.extend(["--json".into(), report.to_string_lossy().into_owned()]);
            }
            let all: Vec<&str> = all.iter().map(String::as_str).collect();
            start(role, scene, &all)
        })
        .collect()
}

/// A trace node for partition `k/2` waiting for two lockstep edges, with `extra`
/// arguments; with `reports`, it writes its report to `reports/t{k}.json` when it stops.
fn lockstep_trace_node(
    url: &str,
    scene: &str,
    k: u32,
    reports: Option<&Path>,
    extra: &[&str],
) -> Proc {
    let partition = format!("{k}/2");
    let mut args = vec!["--nats", url, "--partition", &partition];
    args.extend(["--lockstep-edges", "2"]);
    args.extend(extra);
    let report = reports.map(|d| d.join(format!("t{k}.json")));
    if let Some(r) = &report {
        args.extend(["--json", r.to_str().unwrap()]);
    }
    let (p, line) = start("trace-node", scene, &args);
    assert!(line.starts_with("trace node"), "{line}");
    p
}

/// Trace nodes for partitions 0/2 and 1/2 ([`lockstep_trace_node`]).
fn lockstep_trace_nodes(
    url: &str,
    scene: &str,
    reports: Option<&Path>,
    extra: &[&str],
) -> Vec<Proc> {
    (0..2)
        .map(|k| lockstep_trace_node(url, scene, k, reports, extra))
        .collect()
}

/// Edges `e0` and `e1` in lockstep, serving once, with `extra` arguments; with `reports`,
/// edge `e` writes its report to `reports/e{e}.json`. Returns each one and its address.
fn lockstep_edges(
    url: &str,
    scene: &str,
    reports: Option<&Path>,
    extra: &[&str],
) -> Vec<(Proc, String)> {
    let args = |e| {
        let id = format!("e{e}");
        let listen = [
            "--listen",
            "127.0.0.1:0",
            "--lockstep",
            "--once",
            "--partitions",
            "2",
        ];
        ["--nats", url, "--edge-id", &id]
            .into_iter()
            .chain(listen)
            .map(String::from)
            .collect()
    };
    let edges = pair("edge", scene, args, extra, reports.map(|d| (d, "e")));
    edges
        .into_iter()
        .map(|(p, line)| (p, listening_addr(&line)))
        .collect()
}

/// Every view's final state hash, after checking it matched the server's all along.
fn view_hashes(files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|f| {
            let s = json(f);
            assert_eq!(s["hash_mismatches"], 0, "{s}");
            assert_eq!(
                s["state_hash"].as_str(),
                s["server_state_hash"].as_str(),
                "{s}"
            );
            s["state_hash"].as_str().unwrap().to_string()
        })
        .collect()
}

const FRAMES: u32 = 8;

#[test]
fn two_trace_nodes_and_two_edges_equal_one_serve_and_a_late_edge_catches_up() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);

    // psao serve alone, four lockstep viewers.
    let alone = serve_alone(dir.path(), &scene, &path, 4, FRAMES, &[], &[]);

    // Two trace nodes, two edges with two viewers each. Node 1 starts after node 0 traced
    // frame 1 (the edges then wait for partition 1's batch of it): it steps on from its own
    // partition's frame, not from the latest.
    let every = ["--snapshot-every", "3"];
    let node0 = lockstep_trace_node(&url, &scene, 0, None, &every);
    let edges = lockstep_edges(&url, &scene, Some(dir.path()), &["--wait-clients", "2"]);
    let files: Vec<PathBuf> = (0..4).map(|i| out(&format!("v{i}.json"))).collect();
    let views: Vec<Child> = files
        .iter()
        .enumerate()
        .map(|(i, f)| view(&edges[i % 2].1, &scene, &path, FRAMES, f))
        .collect();
    std::thread::sleep(Duration::from_millis(1500));
    let node1 = lockstep_trace_node(&url, &scene, 1, Some(dir.path()), &every);
    views.into_iter().for_each(finished);
    for (mut p, _) in edges {
        p.wait(20);
    }
    let split = view_hashes(&files);
    assert_eq!(split, alone, "same client states as psao serve alone");
    let edge_hash = |n: &str| json(&out(n))["state_hash"].as_str().unwrap().to_string();
    assert_eq!(edge_hash("e0.json"), edge_hash("e1.json"));
    for e in ["e0.json", "e1.json"] {
        let s = json(&out(e));
        assert_eq!(s["edge"]["malformed"], 0, "{s}");
        assert_eq!(s["edge"]["sequence_gaps"], 0, "{s}");
        assert!(s["edge"]["frames"].as_u64().unwrap() > 0, "{s}");
    }
    for n in [node0, node1] {
        n.interrupt(20);
    }
    let t1 = json(&out("t1.json"));
    // It read partition 0's records of frame 1, and stepped frame 1 itself.
    assert_eq!(t1["restored"]["frame"], 0, "{t1}");
    assert!(t1["restored"]["records"].as_u64().unwrap() > 0, "{t1}");

    // A late edge (clocked) starts from the latest snapshot and reads only the batches
    // after it: the same state as the lockstep edges.
    let late = late_edge(dir.path(), &url, &scene, &path);
    assert_eq!(
        late["state_hash"].as_str(),
        Some(edge_hash("e0.json").as_str())
    );
    let e0 = json(&out("e0.json"));
    let started = late["edge"]["snapshot_frame"].as_u64().unwrap();
    assert!(started >= 3 && started.is_multiple_of(3), "{late}");
    assert!(
        late["edge"]["snapshot_bytes"].as_u64().unwrap() > 0,
        "{late}"
    );
    let (read, all) = (&late["edge"]["batches"], &e0["edge"]["batches"]);
    assert!(read.as_u64() < all.as_u64(), "{read} of {all} batches read");
}

/// A clocked edge joining the session at `url` after its trace nodes stopped, serving one
/// viewer 30 frames of `path` (its report `late.json`, the viewer's `lv.json` in `dir`);
/// returns the edge's report, after checking the viewer ended with the edge's state.
fn late_edge(dir: &Path, url: &str, scene: &str, path: &str) -> serde_json::Value {
    let report = dir.join("late.json");
    let (mut late, line) = start(
        "edge",
        scene,
        &[
            "--nats",
            url,
            "--listen",
            "127.0.0.1:0",
            "--once",
            "--partitions",
            "2",
            "--json",
            report.to_str().unwrap(),
        ],
    );
    let v = view(
        &listening_addr(&line),
        scene,
        path,
        30,
        &dir.join("lv.json"),
    );
    finished(v);
    late.wait(20);
    let late = json(&report);
    let hash = late["state_hash"].as_str().unwrap().to_string();
    assert_eq!(view_hashes(&[dir.join("lv.json")]), vec![hash]);
    late
}

/// Few samples per point: a clocked session's state converges within a second of the path.
const QUICK: &[&str] = &["--max-samples", "16"];

/// A clocked trace node for partition `k/2` writing its report to `dir/t{k}.json`.
fn clocked_trace_node(url: &str, scene: &str, dir: &Path, k: u32) -> Proc {
    let partition = format!("{k}/2");
    let json = dir.join(format!("t{k}.json"));
    let mut args = vec!["--nats", url, "--partition", &partition];
    args.extend(QUICK);
    args.extend(["--json", json.to_str().unwrap()]);
    start("trace-node", scene, &args).0
}

/// A clocked edge `e` serving once, writing its report to `dir/e{e}.json`; returns it and
/// its address.
fn clocked_edge(url: &str, scene: &str, dir: &Path, e: u32) -> (Proc, String) {
    let json = dir.join(format!("e{e}.json"));
    let mut args = vec!["--nats", url, "--listen", "127.0.0.1:0", "--once"];
    args.extend(["--partitions", "2"]);
    args.extend(QUICK);
    args.extend(["--json", json.to_str().unwrap()]);
    let (p, line) = start("edge", scene, &args);
    (p, listening_addr(&line))
}

#[test]
fn clocked_trace_nodes_started_apart_serve_an_edge_that_came_first() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    let (mut edge, at) = clocked_edge(&url, &scene, dir.path(), 0);
    let t0 = clocked_trace_node(&url, &scene, dir.path(), 0);
    // Partition 1 has no node for a second of frames: the edge holds partition 0's
    // batches of them, and takes partition 1 to start with its node's first batch.
    std::thread::sleep(Duration::from_millis(1000));
    let t1 = clocked_trace_node(&url, &scene, dir.path(), 1);
    let v = view(&at, &scene, &path, 150, &out("v0.json"));
    finished(v);
    edge.wait(20);
    t0.interrupt(20);
    t1.interrupt(20);
    let hash = view_hashes(&[out("v0.json")]);
    let e0 = json(&out("e0.json"));
    assert_eq!(e0["state_hash"].as_str(), Some(hash[0].as_str()), "{e0}");
    let started = json(&out("t1.json"))["restored"]["frame"].as_u64().unwrap();
    assert!(started >= 15, "node 1 started at frame {started}");
    let v0 = json(&out("v0.json"));
    let reached = v0["last_server_frame"].as_u64().unwrap();
    assert!(reached > started, "{v0}");
    assert!(v0["updates"].as_u64().unwrap() > 0, "{v0}");
}

#[test]
fn a_dead_trace_node_and_a_dead_edge_are_survived() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    let node = |k: u32| clocked_trace_node(&url, &scene, dir.path(), k);
    let (t0, t1) = (node(0), node(1));
    let edge = |e: u32| clocked_edge(&url, &scene, dir.path(), e);
    let ((e0, a0), (mut e1, a1)) = (edge(0), edge(1));
    let v0 = view(&format!("{a0},{a1}"), &scene, &path, 600, &out("v0.json"));
    let v1 = view(&format!("{a1},{a0}"), &scene, &path, 600, &out("v1.json"));
    std::thread::sleep(Duration::from_millis(1500));
    drop(t1);
    std::thread::sleep(Duration::from_millis(1000));
    drop(e0);
    finished(v0);
    finished(v1);
    e1.wait(20);
    t0.interrupt(20);
    let hashes = view_hashes(&[out("v0.json"), out("v1.json")]);
    assert_eq!(hashes[0], hashes[1], "both viewers converged to one state");
    let e1 = json(&out("e1.json"));
    assert_eq!(e1["state_hash"].as_str(), Some(hashes[0].as_str()), "{e1}");
    assert!(json(&out("v0.json"))["reconnects"].as_u64().unwrap() >= 1);
    let t0 = json(&out("t0.json"));
    assert_eq!(t0["partitions"], serde_json::json!([0, 1]), "{t0}");
    let adoption = &t0["adopted"][0];
    assert_eq!(adoption["partition"], 1, "{t0}");
    let after = adoption["after_s"].as_f64().unwrap();
    assert!(after <= 5.0, "partition taken over after {after} s");
}

/// How the NATS server goes away mid-path in [`nats_outage`].
#[derive(Clone, Copy, PartialEq)]
enum Outage {
    /// Killed and started again on its port and store.
    Restart,
    /// As if killed hard before it wrote the last 0.4 s of messages to disk: its store is
    /// copied while it is frozen (SIGSTOP: what a kill then would leave on disk), it runs on
    /// for 0.4 s, then it is killed and started again on the copy. It has lost messages it
    /// acknowledged, and hands their sequence numbers to new ones.
    LoseMessages,
}

/// 2 lockstep trace nodes, 2 edges and 2 viewers, the NATS server going away mid-path as
/// `outage` says: every frame is applied and both viewers end with the state of
/// `psao serve` alone. Returns the edges' and the trace nodes' reports.
fn nats_outage(outage: Outage) -> Option<(Vec<serde_json::Value>, Vec<serde_json::Value>)> {
    let dir = tempfile::tempdir().unwrap();
    let (nats_server, url) = nats(dir.path())?;
    let port: u16 = url.rsplit(':').next().unwrap().parse().unwrap();
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    // Simulated latency makes each lockstep round last 30 ms: the path takes a few seconds.
    const STEPS: u32 = 60;
    let slow = ["--latency-ms", "30"];

    let alone = serve_alone(dir.path(), &scene, &path, 2, STEPS, &slow, &[]);

    let nodes = lockstep_trace_nodes(&url, &scene, Some(dir.path()), &["--snapshot-every", "4"]);
    let edges = lockstep_edges(&url, &scene, Some(dir.path()), &[]);
    let files: Vec<PathBuf> = (0..2).map(|i| out(&format!("v{i}.json"))).collect();
    let views: Vec<Child> = files
        .iter()
        .enumerate()
        .map(|(i, f)| view_with(&edges[i].1, &scene, &path, STEPS, f, &slow))
        .collect();
    std::thread::sleep(Duration::from_millis(700));
    let (store, copy) = (out("js"), out("js-copy"));
    if outage == Outage::LoseMessages {
        let pid = nats_server.0.id().to_string();
        Command::new("kill").args(["-STOP", &pid]).status().unwrap();
        copy_dir(&store, &copy);
        Command::new("kill").args(["-CONT", &pid]).status().unwrap();
        std::thread::sleep(Duration::from_millis(400));
    }
    drop(nats_server);
    if outage == Outage::LoseMessages {
        std::fs::remove_dir_all(&store).unwrap();
        std::fs::rename(&copy, &store).unwrap();
    }
    std::thread::sleep(Duration::from_millis(500));
    let _nats_again = nats_on(dir.path(), port);
    views.into_iter().for_each(finished);
    for (mut p, _) in edges {
        p.wait(30);
    }
    for n in nodes {
        n.interrupt(20);
    }
    // A late edge joins from the snapshots published after the outage and the batches.
    let late = late_edge(dir.path(), &url, &scene, &path);
    // On a mismatch, the reports say where the state went apart.
    let edge_reports = vec![json(&out("e0.json")), json(&out("e1.json"))];
    let node_reports = vec![json(&out("t0.json")), json(&out("t1.json"))];
    assert_eq!(
        view_hashes(&files),
        alone,
        "the state of psao serve alone; edges: {edge_reports:?}; nodes: {node_reports:?}"
    );
    for s in edge_reports.iter().chain([&late]) {
        assert_eq!(s["state_hash"].as_str(), Some(alone[0].as_str()), "{s}");
        assert_eq!(s["edge"]["malformed"], 0, "{s}");
        assert_eq!(s["edge"]["sequence_gaps"], 0, "{s}");
    }
    for s in &edge_reports {
        // Every server frame applied, none skipped: one per two client frames at --hz 30.
        assert_eq!(s["edge"]["frames"], STEPS / 2, "{s}");
    }
    assert!(late["edge"]["snapshot_frame"].as_u64() > Some(0), "{late}");
    Some((edge_reports, node_reports))
}

/// Copy directory `from` to `to`, recursively.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

#[test]
fn a_nats_restart_is_survived_by_trace_nodes_and_edges() {
    nats_outage(Outage::Restart);
}

#[test]
fn a_nats_server_that_lost_acknowledged_messages_is_survived() {
    let Some((edges, nodes)) = nats_outage(Outage::LoseMessages) else {
        return;
    };
    // The loss was noticed: both nodes published batches again, both edges read again
    // after the last record the stream still held.
    for n in &nodes {
        assert!(n["republished"].as_u64().unwrap() > 0, "{n}");
    }
    for e in &edges {
        assert!(e["edge"]["rewinds"].as_u64().unwrap() >= 1, "{e}");
    }
}

#[test]
fn a_trace_node_starting_late_restarts_from_the_published_state() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    // 52 server frames; the path stops moving at frame 30, the state converges after it.
    // The fresh node steps the last two: one restarting from zero would trace and publish
    // other records in them.
    const STEPS: u32 = 104;
    // The first two nodes trace this many frames and stop, releasing their leases.
    const FIRST: &str = "50";

    let alone = serve_alone(dir.path(), &scene, &path, 2, STEPS, &[], QUICK);

    let node = |k: u32, extra: &[&str]| {
        let partition = format!("{k}/2");
        let mut args = vec![
            "--nats",
            &url,
            "--partition",
            &partition,
            "--lockstep-edges",
            "2",
            "--snapshot-every",
            "5",
        ];
        args.extend(QUICK);
        args.extend(extra);
        start("trace-node", &scene, &args).0
    };
    let first_json: Vec<PathBuf> = (0..2).map(|k| out(&format!("t{k}.json"))).collect();
    let mut first: Vec<Proc> = (0..2)
        .map(|k| {
            let json = first_json[k as usize].to_str().unwrap();
            node(k, &["--frames", FIRST, "--json", json])
        })
        .collect();
    let edges: Vec<(Proc, String)> = (0..2)
        .map(|e| {
            let json = out(&format!("e{e}.json"));
            let id = format!("e{e}");
            let mut args = vec![
                "--nats",
                &url,
                "--listen",
                "127.0.0.1:0",
                "--lockstep",
                "--once",
                "--partitions",
                "2",
                "--edge-id",
                &id,
                "--json",
                json.to_str().unwrap(),
            ];
            args.extend(QUICK);
            let (p, line) = start("edge", &scene, &args);
            (p, listening_addr(&line))
        })
        .collect();
    let files: Vec<PathBuf> = (0..2).map(|i| out(&format!("v{i}.json"))).collect();
    let views: Vec<Child> = files
        .iter()
        .enumerate()
        .map(|(i, f)| view(&edges[i].1, &scene, &path, STEPS, f))
        .collect();
    // Both nodes gone: a fresh node (started after them, knowing nothing) takes partition
    // 0, adopts partition 1 and continues from the published state.
    for p in &mut first {
        p.wait(60);
    }
    let late_json = out("late.json");
    let late = node(0, &["--json", late_json.to_str().unwrap()]);
    views.into_iter().for_each(finished);
    for (mut p, _) in edges {
        p.wait(30);
    }
    late.interrupt(20);
    assert_eq!(view_hashes(&files), alone, "the state of psao serve alone");
    for e in ["e0.json", "e1.json"] {
        let s = json(&out(e));
        assert_eq!(s["edge"]["malformed"], 0, "{s}");
        assert_eq!(s["edge"]["sequence_gaps"], 0, "{s}");
        assert_eq!(s["edge"]["frames"], STEPS / 2, "{s}");
    }
    // The state converged before frame 50: the last rounds republished no chunk.
    for f in &first_json {
        let t = json(f);
        let (sent, full) = (&t["snapshot_bytes"], &t["snapshot_full_bytes"]);
        assert!(
            sent.as_u64() < full.as_u64(),
            "{sent} of {full} snapshot bytes"
        );
    }
    let late = json(&late_json);
    assert_eq!(late["partitions"], serde_json::json!([0, 1]), "{late}");
    assert_eq!(late["adopted"][0]["partition"], 1, "{late}");
    let restored = &late["restored"];
    assert_eq!(restored["frame"], 50, "{late}");
    assert_eq!(restored["snapshot_frame"], 50, "{late}");
    assert!(restored["records"].as_u64().unwrap() > 0, "{late}");
    // Sample counts restored: a node starting from zero would have none, and would trace
    // the converged points again.
    assert!(restored["samples"].as_u64().unwrap() > 0, "{late}");
    assert_eq!(late["rays"], 0, "nothing left to trace: {late}");
}

/// The room with a box sliding over its floor (instance transforms) and, when the shared
/// data is there, the skinned `RiggedSimple` playing its clip (skinned refits).
fn animated_fixture(dir: &Path) -> (String, String) {
    let (_, path) = fixture(dir);
    let mut scene = "ao_radius = 0.6\n\
        [[asset]]\nfile = \"room.obj\"\n\
        [[asset]]\nfile = \"builtin:box\"\nscale = 0.5\n\
        keys = { times = [0.0, 0.75, 1.5], translation = [[-2.5, 0.25, 2.0], [2.5, 0.25, 2.0], [-2.5, 0.25, 2.0]] }\n"
        .to_string();
    let rigged = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/characters/RiggedSimple.glb"
    ));
    if rigged.exists() {
        scene += &format!(
            "[[asset]]\nfile = \"{}\"\nscale = 0.3\ntranslation = [0.0, 0.0, -2.5]\n",
            rigged.display()
        );
    } else {
        eprintln!("note: ../shared/data is not there: the animated scene has no skinned mesh");
    }
    std::fs::write(dir.join("moving.toml"), scene).unwrap();
    (dir.join("moving.toml").to_string_lossy().into_owned(), path)
}

#[test]
fn an_animated_scene_replicates_like_one_serve() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = animated_fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    const STEPS: u32 = 24;

    let alone = serve_alone(dir.path(), &scene, &path, 2, STEPS, &[], &[]);

    let nodes = lockstep_trace_nodes(&url, &scene, None, &[]);
    let edges = lockstep_edges(&url, &scene, None, &[]);
    let files: Vec<PathBuf> = (0..2).map(|i| out(&format!("v{i}.json"))).collect();
    let views: Vec<Child> = files
        .iter()
        .enumerate()
        .map(|(i, f)| view(&edges[i].1, &scene, &path, STEPS, f))
        .collect();
    views.into_iter().for_each(finished);
    for (mut p, _) in edges {
        p.wait(20);
    }
    assert_eq!(view_hashes(&files), alone, "the state of psao serve alone");
    for n in nodes {
        n.interrupt(20);
    }
}

/// What a lockstep viewer of a session at the default ray budget got ([`at_defaults`]).
struct Session {
    /// The viewer's final state hash (checked against its server's all along), and the
    /// bytes it received.
    hash: String,
    bytes: u64,
}

/// One lockstep viewer following `frames` frames of `scene`'s path `path` from `psao serve`
/// alone with the default ray budget and `server` settings; then from `nodes` trace nodes
/// and one lockstep edge. Returns both sessions, after checking that the edge ended with
/// the state of `psao serve`, and the trace nodes' reports.
fn at_defaults(
    scene: &str,
    path: &str,
    server: &[&str],
    nodes: u32,
    frames: u32,
) -> Option<(Session, Session, Vec<serde_json::Value>)> {
    let dir = tempfile::tempdir().unwrap();
    let (_nats, url) = nats(dir.path())?;
    let out = |n: &str| dir.path().join(n);
    let session = |file: &str| {
        let v = json(&out(file));
        Session {
            hash: view_hashes(&[out(file)]).remove(0),
            bytes: v["bytes"].as_u64().unwrap(),
        }
    };
    let lockstep = ["--listen", "127.0.0.1:0", "--lockstep", "--once"];
    // The edge serves no irradiance: compared with the AO-only server.
    let (mut serve, line) = start_role(
        "serve",
        scene,
        server,
        &[&lockstep[..], &["--lighting", "ao"]].concat(),
    );
    finished(view(
        &listening_addr(&line),
        scene,
        path,
        frames,
        &out("s.json"),
    ));
    serve.wait(60);
    let alone = session("s.json");

    let count = nodes.to_string();
    let mut tracers: Vec<Proc> = (0..nodes)
        .map(|k| {
            let partition = format!("{k}/{count}");
            let report = out(&format!("t{k}.json"));
            let args = [
                "--nats",
                &url,
                "--partition",
                &partition,
                "--lockstep-edges",
                "1",
                "--json",
                report.to_str().unwrap(),
            ];
            let (p, line) = start_role("trace-node", scene, server, &args);
            assert!(line.starts_with("trace node"), "{line}");
            p
        })
        .collect();
    let report = out("e.json");
    let mut args = vec!["--nats", &url, "--json", report.to_str().unwrap()];
    args.extend(["--partitions", &count]);
    args.extend(lockstep);
    let (mut edge, line) = start_role("edge", scene, server, &args);
    finished(view(
        &listening_addr(&line),
        scene,
        path,
        frames,
        &out("v.json"),
    ));
    edge.wait(60);
    let split = session("v.json");
    let e = json(&report);
    assert_eq!(e["state_hash"].as_str(), Some(alone.hash.as_str()), "{e}");
    assert_eq!(e["edge"]["malformed"], 0, "{e}");
    assert_eq!(e["edge"]["sequence_gaps"], 0, "{e}");
    let reports = tracers
        .drain(..)
        .enumerate()
        .map(|(k, p)| {
            p.interrupt(30);
            json(&out(&format!("t{k}.json")))
        })
        .collect();
    Some((alone, split, reports))
}

/// Client frames of the tests at the default ray budget.
const DEFAULT_FRAMES: u32 = 12;

/// Checks the sessions of [`at_defaults`]: the same final state, the viewer's bytes within
/// 5 % of `psao serve`'s, batches compressed, and (`over`) some batch larger than NATS's
/// default 1 MiB payload limit before compression, so that the test needs the parts.
fn check_defaults(alone: &Session, split: &Session, nodes: &[serde_json::Value], over: bool) {
    assert_eq!(split.hash, alone.hash, "same state as psao serve alone");
    let ratio = split.bytes as f64 / alone.bytes as f64;
    assert!(
        (0.95..=1.05).contains(&ratio),
        "viewer bytes {} against {} from psao serve",
        split.bytes,
        alone.bytes
    );
    for t in nodes {
        let (sent, raw) = (&t["batch_bytes"], &t["batch_raw_bytes"]);
        assert!(sent.as_u64() < raw.as_u64(), "compressed: {t}");
    }
    let largest = nodes
        .iter()
        .filter_map(|t| t["largest_batch_raw_bytes"].as_u64())
        .max();
    if over {
        assert!(largest > Some(1 << 20), "{largest:?}");
    }
}

#[test]
fn one_and_two_trace_nodes_at_the_default_ray_budget_equal_one_serve() {
    if Command::new("nats-server")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("note: nats-server is not installed: scale-out test skipped");
        return;
    }
    let path = "../../paths/default_a.toml";
    for nodes in [1, 2] {
        let Some((alone, split, reports)) =
            at_defaults("default", path, &[], nodes, DEFAULT_FRAMES)
        else {
            return;
        };
        check_defaults(&alone, &split, &reports, nodes == 1);
    }
}

#[test]
fn one_and_two_trace_nodes_on_sponza_at_the_default_ray_budget_equal_one_serve() {
    let obj = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/scenes/dabrovic_sponza.obj"
    );
    if !Path::new(obj).exists() {
        eprintln!("note: ../shared/data is not there: the Sponza scale-out test is skipped");
        return;
    }
    let (scene, path) = ("../../scenes/sponza.toml", "../../paths/sponza_a.toml");
    for nodes in [1, 2] {
        let Some((alone, split, reports)) =
            at_defaults(scene, path, &["--points", "1024"], nodes, 4)
        else {
            return;
        };
        check_defaults(&alone, &split, &reports, nodes == 1);
    }
}

/// `GET /health` of the server at `addr`, parsed.
fn health(addr: &str) -> serde_json::Value {
    use std::io::{Read, Write};
    let mut s = TcpStream::connect(addr).unwrap();
    let request = format!("GET /health HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    s.write_all(request.as_bytes()).unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {text}"))
}

#[test]
fn an_edge_missing_a_partition_says_so_in_health_and_to_its_viewer() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_nats, url)) = nats(dir.path()) else {
        return;
    };
    let (scene, path) = fixture(dir.path());
    let out = |n: &str| dir.path().join(n);
    // Partition 1 of 2 never gets a node: the edge cannot complete a frame.
    let (mut edge, at) = clocked_edge(&url, &scene, dir.path(), 0);
    let t0 = clocked_trace_node(&url, &scene, dir.path(), 0);
    let v = view(&at, &scene, &path, 900, &out("v0.json"));
    let end = Instant::now() + Duration::from_secs(60);
    let stalled = loop {
        let h = health(&at);
        if !h["stalled"].is_null() {
            break h["stalled"].clone();
        }
        assert!(Instant::now() < end, "no stall reported: {h}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(stalled["partitions"], serde_json::json!([1]), "{stalled}");
    assert!(stalled["seconds"].as_f64().unwrap() >= 3.0, "{stalled}");
    assert!(stalled["since_unix_ms"].as_u64().unwrap() > 0, "{stalled}");
    finished(v);
    edge.wait(20);
    t0.interrupt(20);
    let v0 = json(&out("v0.json"));
    let told = v0["stalled"].as_str().unwrap_or_else(|| panic!("{v0}"));
    assert!(told.contains("partitions [1]"), "{told}");
    assert_eq!(v0["status_messages"], 1, "{v0}");
}

#[test]
fn bench_nats_stores_and_delivers_every_message_to_every_consumer() {
    if Command::new("nats-server")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("note: nats-server is not installed: bench nats test skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("nats.json");
    let o = common::psao(&[
        "bench",
        "nats",
        "--messages",
        "40",
        "--message-bytes",
        "2000",
        "--subscribers",
        "1,3",
        "--json",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let runs = json(&report)["runs"].clone();
    let counts: Vec<u64> = runs
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["subscribers"].as_u64().unwrap())
        .collect();
    assert_eq!(counts, [1, 3]);
    for r in runs.as_array().unwrap() {
        assert_eq!(r["messages"], 40, "{r}");
        let (stored, delivered) = (
            r["stored_mb_per_s"].as_f64().unwrap(),
            r["delivered_mb_per_s"].as_f64().unwrap(),
        );
        assert!(stored > 0.0 && delivered > 0.0, "{r}");
    }
    let bad = common::psao(&["bench", "nats", "--subscribers", "0"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("at least 1"), "{}", stderr(&bad));
}
