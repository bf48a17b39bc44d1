//! `psao eval --lighting gi`: the composited columns measured against the reference diffuse
//! lighting, with rows for the lit composite and the same session's AO-only composite.

mod common;

use common::{json, psao, stderr};

/// Runs a tiny evaluation with `extra` arguments into `out`; returns its rows.
fn eval(out: &std::path::Path, cache: &std::path::Path, extra: &[&str]) -> Vec<serde_json::Value> {
    let mut args = vec![
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
        "48x27",
        "--ray-budget",
        "50000",
        "--out",
        out.to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = psao(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    json(&out.join("report.json")).as_array().unwrap().clone()
}

#[test]
fn eval_with_lighting_measures_the_lit_and_the_ao_only_composites() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let gi = eval(&dir.path().join("gi"), &cache, &["--lighting", "gi"]);
    let methods: Vec<&str> = gi.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(methods, ["psao", "psao-ao", "ssao", "rtao"]);
    let (lit, ao_only) = (&gi[0], &gi[1]);
    // One session: the same AO, bandwidth and work; only the composite differs.
    for key in [
        "psnr_ao",
        "ssim_ao",
        "flip_ao",
        "mbit_s",
        "points",
        "server_hz",
    ] {
        assert_eq!(lit[key], ao_only[key], "{key}");
    }
    assert_ne!(lit["psnr_comp"], ao_only["psnr_comp"]);
    for row in &gi {
        for key in ["psnr_comp", "ssim_comp", "flip_comp"] {
            assert!(row[key].as_f64().unwrap().is_finite(), "{key} of {row}");
        }
    }

    // Without lighting: one PSAO row; SSAO's AO columns unchanged (same references, same
    // AO), its composited ones against the AO composite instead.
    let ao = eval(&dir.path().join("ao"), &cache, &[]);
    let methods: Vec<&str> = ao.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(methods, ["psao", "ssao", "rtao"]);
    assert_eq!(ao[1]["psnr_ao"], gi[2]["psnr_ao"], "SSAO's AO");
    assert_ne!(
        ao[1]["psnr_comp"], gi[2]["psnr_comp"],
        "SSAO's composite, other reference"
    );

    // A second lit run reads the cached references and gives the same figures.
    let again = eval(&dir.path().join("gi2"), &cache, &["--lighting", "gi"]);
    for (a, b) in gi.iter().zip(&again) {
        for key in [
            "psnr_ao",
            "ssim_ao",
            "flip_ao",
            "psnr_comp",
            "ssim_comp",
            "flip_comp",
            "mbit_s",
        ] {
            assert_eq!(a[key], b[key], "{key} of {}", a["method"]);
        }
    }
}

#[test]
fn eval_refuses_too_many_bounces() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = psao(&[
        "eval",
        "--lighting",
        "gi",
        "--bounces",
        "99",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--bounces"), "{}", stderr(&o));
}
