//! The compact codec against the paper codec end to end (`psao run`): same decoded client
//! state, at most 0.6× the bytes, on the first frames of a committed camera path.

mod common;

use common::{json, psao, stderr};

fn run(codec: &str, dir: &std::path::Path) -> serde_json::Value {
    let json_file = dir.join(format!("{codec}.json"));
    let out = dir.join(codec);
    let o = psao(&[
        "run",
        "--scene",
        "default",
        "--points",
        "256",
        "--frames",
        "0..12",
        "--res",
        "32x18",
        "--every",
        "1000",
        "--codec",
        codec,
        // The AO codecs' claim: the irradiance records are not part of it.
        "--lighting",
        "ao",
        "--out",
        out.to_str().unwrap(),
        "--json",
        json_file.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    json(&json_file)
}

#[test]
fn compact_needs_at_most_six_tenths_of_the_paper_bytes_for_the_same_state() {
    let dir = tempfile::tempdir().unwrap();
    let paper = run("paper", dir.path());
    let compact = run("compact", dir.path());
    assert_eq!(paper["state_hash"], compact["state_hash"]);
    assert_eq!(paper["codec"], "paper");
    assert_eq!(compact["codec"], "compact");
    let (p, c) = (
        paper["total_bytes"].as_f64().unwrap(),
        compact["total_bytes"].as_f64().unwrap(),
    );
    assert!(p > 0.0);
    let ratio = c / p;
    println!("compact/paper = {ratio:.3} ({c} / {p} bytes)");
    assert!(ratio <= 0.6, "compact/paper = {ratio:.3}");
}

#[test]
fn unknown_codecs_are_refused_with_the_known_names() {
    let dir = tempfile::tempdir().unwrap();
    let o = psao(&[
        "run",
        "--frames",
        "0..1",
        "--res",
        "8x8",
        "--codec",
        "nope",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("compact") && err.contains("paper"), "{err}");
}
