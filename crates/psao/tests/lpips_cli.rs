//! LPIPS in `psao compare` and `psao eval`: present with weights, left out with a note
//! without them, and a clear error for a missing or broken `--lpips-weights` file.

mod common;

use common::{json, psao, stderr, BIN};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The weights in psao's default location, if `scripts/lpips_weights.py` has put them there.
fn default_weights() -> Option<PathBuf> {
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cache")))?;
    Some(cache.join("psao/lpips_alex_v0.1.safetensors")).filter(|p| p.exists())
}

/// Two 64×36 AO images of frame 0: 64 spp and 2 spp.
fn two_images(dir: &Path) -> (String, String) {
    let mut files = Vec::new();
    for spp in ["64", "2"] {
        let out = dir.join(format!("spp{spp}"));
        let o = psao(&[
            "reference",
            "--frame",
            "0",
            "--spp",
            spp,
            "--res",
            "64x36",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        files.push(out.join("ao_00000.png").to_str().unwrap().to_string());
    }
    (files[0].clone(), files[1].clone())
}

#[test]
fn compare_reports_lpips_with_weights_and_leaves_it_out_without() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = two_images(dir.path());
    // No weights anywhere: no `lpips` key, a note, success.
    let empty = dir.path().join("empty-cache");
    let o = Command::new(BIN)
        .args(["compare", &a, &b, "--json"])
        .env("XDG_CACHE_HOME", &empty)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(m.get("lpips").is_none() && m.get("psnr").is_some(), "{m}");
    assert!(stderr(&o).contains("LPIPS left out"), "{}", stderr(&o));

    let Some(weights) = default_weights() else {
        eprintln!("note: no LPIPS weights (scripts/lpips_weights.py): skipping the LPIPS values");
        return;
    };
    let w = weights.to_str().unwrap();
    let o = psao(&["compare", &a, &a, "--json", "--lpips-weights", w]);
    assert!(o.status.success(), "{}", stderr(&o));
    let same: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(same["lpips"].as_f64(), Some(0.0));
    let o = psao(&["compare", &a, &b, "--json", "--lpips-weights", w]);
    assert!(o.status.success(), "{}", stderr(&o));
    let diff: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let d = diff["lpips"].as_f64().unwrap();
    assert!(d > 0.01 && d < 1.0, "LPIPS of 2 spp against 64 spp: {d}");
    let o = psao(&["compare", &a, &b, "--lpips-weights", w]);
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("LPIPS "));
}

#[test]
fn missing_or_broken_weights_given_on_the_command_line_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = two_images(dir.path());
    let broken = dir.path().join("broken.safetensors");
    std::fs::write(&broken, b"\x10\x00\x00\x00\x00\x00\x00\x00{\"a\":").unwrap();
    let missing = dir.path().join("missing.safetensors");
    for (file, needle) in [(&missing, "cannot read"), (&broken, "unusable")] {
        let o = psao(&["compare", &a, &b, "--lpips-weights", file.to_str().unwrap()]);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert!(
            err.contains(needle) && err.contains(file.file_name().unwrap().to_str().unwrap()),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn eval_puts_lpips_first_when_weights_are_found() {
    let Some(weights) = default_weights() else {
        eprintln!("note: no LPIPS weights (scripts/lpips_weights.py): skipping");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval");
    let o = psao(&[
        "eval",
        "--frames",
        "0..2",
        "--every",
        "1",
        "--points",
        "32",
        "--spp",
        "4",
        "--rtao-spp",
        "1",
        "--res",
        "64x36",
        "--ray-budget",
        "50000",
        "--lpips-weights",
        weights.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--cache",
        dir.path().join("cache").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = json(&out.join("report.json"));
    for row in rows.as_array().unwrap() {
        for key in ["lpips_ao", "lpips_comp"] {
            let v = row[key].as_f64().unwrap_or(-1.0);
            assert!((0.0..1.0).contains(&v), "{key} = {v} in {row}");
        }
    }
    let table = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        table.contains("| method | points | server Hz | codec | LPIPS AO | LPIPS comp | PSNR AO"),
        "{table}"
    );
}
