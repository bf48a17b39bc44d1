//! A bare model (an OBJ with no camera path) gets the default orbit in every command.

mod common;

use common::{json, stderr, BIN};
use std::path::Path;
use std::process::Command;

/// A 4 m × 4 m ground quad with a 1 m cube standing on it: contact shadows where they meet.
const MODEL: &str = "\
v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2
v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5
v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5
f 1 3 2\nf 1 4 3
f 9 11 10\nf 9 12 11
f 5 6 10\nf 5 10 9\nf 6 7 11\nf 6 11 10
f 7 8 12\nf 7 12 11\nf 8 5 9\nf 8 9 12
";

fn psao_info(args: &[&str]) -> std::process::Output {
    Command::new(BIN)
        .args(["--log", "info"])
        .args(args)
        .output()
        .expect("the psao binary runs")
}

fn write_model(dir: &Path) -> String {
    let file = dir.join("bare.obj");
    std::fs::write(&file, MODEL).unwrap();
    file.to_str().unwrap().to_string()
}

#[test]
fn reference_of_a_bare_obj_orbits_it_and_sees_its_contact_shadows() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_model(dir.path());
    let out = dir.path().join("ref");
    let o = psao_info(&[
        "reference",
        "--scene",
        &scene,
        "--frame",
        "0",
        "--spp",
        "16",
        "--res",
        "128x72",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stderr(&o);
    assert!(
        log.contains("names no camera path") && log.contains("orbit"),
        "the default path is not logged: {log}"
    );
    let img = image::open(out.join("ao_00000.png")).unwrap().to_luma16();
    let occluded = img.pixels().filter(|p| p.0[0] < 52_000).count();
    assert!(
        occluded > 4,
        "no occluded pixel: the orbit does not look at the cube's foot ({occluded})"
    );
}

#[test]
fn run_of_a_bare_obj_uses_the_same_orbit_every_time() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_model(dir.path());
    let mut hashes = Vec::new();
    for k in 0..2 {
        let summary = dir.path().join(format!("run{k}.json"));
        let o = psao_info(&[
            "run",
            "--scene",
            &scene,
            "--frames",
            "0..2",
            "--points",
            "64",
            "--res",
            "48x27",
            "--ray-budget",
            "20000",
            "--out",
            dir.path().join(format!("run{k}")).to_str().unwrap(),
            "--json",
            summary.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        hashes.push(json(&summary)["state_hash"].as_str().unwrap().to_string());
    }
    assert_eq!(hashes[0], hashes[1]);
}
