//! `psao corrective …` end to end on small images.

mod common;

use common::{json, psao, stderr};

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/corrective.toml");

#[test]
fn eval_converges_on_a_static_view_and_beats_the_base_frame() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let o = psao(&[
        "corrective",
        "eval",
        "--scene",
        SCENE,
        "--res",
        "96x54",
        "--frames",
        "0..2",
        "--budget",
        "400",
        "--order",
        "saliency,uniform",
        "--static-frames",
        "6",
        "--ao-spp",
        "2",
        "--out",
        out,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = json(&dir.path().join("report.json"));
    let rows = r["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0]["order"], "base");
    let base_flip = rows[0]["flip"].as_f64().unwrap();
    for row in &rows[1..] {
        assert!(row["flip"].as_f64().unwrap() < base_flip, "{row}");
        assert!(row["saliency_flip"].as_f64().is_some() && row["psnr"].as_f64().is_some());
    }
    for c in r["convergence"].as_array().unwrap() {
        let pixels = c["non_diffuse_pixels"].as_u64().unwrap();
        assert!(pixels > 0);
        // As many samples as non-diffuse pixels, then bit-identical to the reference.
        assert_eq!(c["samples_traced"].as_u64().unwrap(), pixels, "{c}");
        assert_eq!(c["bit_identical"], true, "{c}");
    }
    for f in [
        "report.md",
        "convergence.svg",
        "base.png",
        "corrected.png",
        "reference.png",
    ] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
}

#[test]
fn bad_arguments_and_scenes_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let o = psao(&["corrective", "eval", "--budget", "0", "--out", out]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--budget"), "{}", stderr(&o));
    let o = psao(&["corrective", "eval", "--order", "loudest", "--out", out]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("loudest"), "{}", stderr(&o));
    let scene = dir.path().join("bad.toml");
    std::fs::write(
        &scene,
        "[[asset]]\nfile = \"builtin:sphere\"\n[[light]]\nkind = \"point\"\nposition = [0.0, 1.0, 0.0]\npower = -1.0\n",
    )
    .unwrap();
    let o = psao(&["corrective", "bench", "--scene", scene.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("non-negative"), "{}", stderr(&o));
}

#[test]
fn bench_reports_the_cache_costs() {
    let o = psao(&[
        "corrective",
        "bench",
        "--res",
        "64x36",
        "--samples",
        "500",
        "--repeat",
        "2",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["samples"], 500);
    assert!(v["splat_ms"].as_f64().unwrap() >= 0.0);
    assert!(v["drawn"].as_u64().unwrap() > 0);
}
