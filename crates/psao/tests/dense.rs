//! The densest point set we evaluate, on the real Sponza: 2048 points/m² (15 M points). A
//! client's decode limit follows from the welcome's instance table, so such a stream decodes,
//! in process (`psao run`) and over loopback (`psao serve` + `psao view`), to the same state.
//! Each part starts a server on 15 M points: the slowest tests of the suite.

use std::path::Path;
use std::process::Command;

mod common;

use common::{json, listening_addr, start_role, stderr, BIN};

/// The scene file and camera path, from the workspace root.
const SCENE: &str = "../../scenes/sponza.toml";
const PATH: &str = "../../paths/sponza_a.toml";
/// Server settings shared by both runs: the densest evaluated density, a small ray budget.
/// AO only: the dense point set is the subject, not the lighting.
const SERVER: &[&str] = &[
    "--points",
    "2048",
    "--ray-budget",
    "40000",
    "--lighting",
    "ao",
];
const FRAMES: u32 = 2;

fn sponza_present() -> bool {
    let present = Path::new("../../../shared/data/scenes/dabrovic_sponza.obj").exists();
    if !present {
        eprintln!("skipped: ../shared/data/scenes/dabrovic_sponza.obj is not there");
    }
    present
}

#[test]
fn sponza_at_2048_points_decodes_in_process_and_over_serve_view() {
    if !sponza_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let run_out = dir.path().join("run");
    let o = Command::new(BIN)
        .args(["--log", "warn", "run", "--scene", SCENE, "--path", PATH])
        .args(SERVER)
        .args(["--server-hz", "30", "--res", "32x18"])
        .args(["--frames", &format!("0..{FRAMES}")])
        .args(["--out", run_out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "psao run: {}", stderr(&o));
    let run = json(&run_out.join("stats.json"));
    let points = run["points"].as_u64().unwrap_or(0);
    assert!(points > 12_000_000, "a dense point set: {run}");

    let lockstep = ["--listen", "127.0.0.1:0", "--hz", "30", "--lockstep"];
    let once = [&["--wait-clients", "1", "--once"][..], SERVER].concat();
    let (mut server, line) = start_role("serve", SCENE, &lockstep, &once);
    let addr = listening_addr(&line);
    let view_json = dir.path().join("view.json");
    let o = Command::new(BIN)
        .args([
            "--log",
            "warn",
            "view",
            "--connect",
            &addr,
            "--scene",
            SCENE,
        ])
        .args([
            "--path",
            PATH,
            "--frames",
            &FRAMES.to_string(),
            "--res",
            "32x18",
        ])
        .args(["--json", view_json.to_str().unwrap()])
        .output()
        .unwrap();
    let served = server.0.wait().unwrap();
    assert!(o.status.success(), "psao view: {}", stderr(&o));
    assert!(served.success());
    assert_eq!(json(&view_json)["state_hash"], run["state_hash"]);
}
