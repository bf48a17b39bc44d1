//! End-to-end tests of `psao relight …` and `psao bench relight` on the shared characters
//! (skipped when missing), including real broken inputs.

mod common;

use common::{json, psao, stderr};
use std::path::PathBuf;

fn data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} missing, test skipped", p.display());
        None
    }
}

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn train_render_eval_and_bench_on_the_fox() {
    let (Some(fox), Some(env)) = (
        data("characters/Fox.glb"),
        data("envmaps/20050806-03_hd.hdr"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("fox.prt");
    let out = psao(&[
        "relight",
        "train",
        "--character",
        s(&fox),
        "--clip",
        "Walk",
        "--frames",
        "0..8",
        "--lobes",
        "2",
        "--rays",
        "24",
        "--out",
        s(&model),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("MB"));
    // Same seed, one thread instead of all: the same model, byte for byte.
    let again = dir.path().join("again.prt");
    let out = std::process::Command::new(common::BIN)
        .env("RAYON_NUM_THREADS", "1")
        .args([
            "--log",
            "warn",
            "relight",
            "train",
            "--character",
            s(&fox),
            "--clip",
            "Walk",
            "--frames",
            "0..8",
            "--lobes",
            "2",
            "--rays",
            "24",
            "--out",
            s(&again),
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(&model).unwrap(),
        std::fs::read(&again).unwrap()
    );

    let frames = dir.path().join("frames");
    let out = psao(&[
        "relight",
        "render",
        "--model",
        s(&model),
        "--character",
        s(&fox),
        "--clip",
        "Walk",
        "--env",
        s(&env),
        "--mode",
        "phong",
        "--alpha",
        "12",
        "--light-rotate",
        "90",
        "--res",
        "64x48",
        "--frames",
        "0..2",
        "--out",
        s(&frames),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(frames.join("frame_00000.png").exists() && frames.join("frame_00001.png").exists());

    let eval = dir.path().join("eval");
    let out = psao(&[
        "relight",
        "eval",
        "--character",
        s(&fox),
        "--clip",
        "Walk",
        "--train",
        "0..8",
        "--env",
        s(&env),
        "--lobes",
        "1,2",
        "--rays",
        "24",
        "--ref-samples",
        "32",
        "--test",
        "6..8",
        "--mode",
        "translucent",
        "--res",
        "48x48",
        "--out",
        s(&eval),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report = json(&eval.join("report.json"));
    // Frames 6 and 7 are tested (and so not trained on); the reference's noise floor is there.
    let times: Vec<f64> = report["test_times_s"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect();
    assert_eq!(times.len(), 2);
    assert!((times[0] - 6.0 / 30.0).abs() < 1e-6 && (times[1] - 7.0 / 30.0).abs() < 1e-6);
    assert_eq!(report["train_frames"].as_u64(), Some(6));
    assert!(report["mode"].as_str().unwrap().contains("Translucent"));
    assert!(report["reference_noise"]["psnr"].as_f64().unwrap() > 0.0);
    let fit = report["fit_error"].as_array().unwrap();
    assert_eq!(fit.len(), 2);
    assert!(fit.iter().all(|f| f["mean"].as_f64().unwrap() > 0.0));
    let names: Vec<&str> = report["methods"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["unshadowed", "projected", "lobes1", "lobes2"]);
    assert!(eval.join("report.md").exists() && eval.join("side_by_side.png").exists());

    let bench = dir.path().join("bench.json");
    let out = psao(&[
        "bench",
        "relight",
        "--character",
        s(&fox),
        "--clip",
        "Walk",
        "--model",
        s(&model),
        "--runs",
        "3",
        "--json",
        s(&bench),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(json(&bench)["ms_per_frame"].as_f64().unwrap() > 0.0);

    // Broken model files: truncated, and a file that is not a model at all.
    let bytes = std::fs::read(&model).unwrap();
    let truncated = dir.path().join("truncated.prt");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    for (bad, expect) in [(truncated.as_path(), "truncated"), (fox.as_path(), "magic")] {
        let out = psao(&[
            "relight",
            "render",
            "--model",
            s(bad),
            "--character",
            s(&fox),
            "--env",
            s(&env),
            "--out",
            s(&dir.path().join("x")),
        ]);
        assert!(!out.status.success());
        assert!(stderr(&out).contains(expect), "{}", stderr(&out));
    }

    // A model of another character is refused.
    if let Some(simple) = data("characters/RiggedSimple.glb") {
        let out = psao(&[
            "bench",
            "relight",
            "--character",
            s(&simple),
            "--model",
            s(&model),
            "--runs",
            "1",
        ]);
        assert!(!out.status.success());
        assert!(
            stderr(&out).contains("trained on `Fox`"),
            "{}",
            stderr(&out)
        );
    }

    // Environment maps that are not HDR images, or are cut short.
    let cut = dir.path().join("cut.hdr");
    std::fs::write(&cut, &std::fs::read(&env).unwrap()[..2000]).unwrap();
    for (bad, expect) in [
        (fox.as_path(), "not a Radiance HDR"),
        (cut.as_path(), "cut.hdr"),
    ] {
        let out = psao(&[
            "relight",
            "render",
            "--model",
            s(&model),
            "--character",
            s(&fox),
            "--clip",
            "Walk",
            "--env",
            s(bad),
            "--frames",
            "0..1",
            "--out",
            s(&dir.path().join("y")),
        ]);
        assert!(!out.status.success());
        assert!(stderr(&out).contains(expect), "{}", stderr(&out));
    }
}

#[test]
fn a_gltf_without_a_skin_and_an_unknown_clip_are_refused() {
    let (Some(fox), Some(engine)) = (
        data("characters/Fox.glb"),
        data("scenes/2CylinderEngine.glb"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("m.prt");
    let out = psao(&[
        "relight",
        "train",
        "--character",
        s(&engine),
        "--out",
        s(&m),
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("no skinned mesh"), "{}", stderr(&out));
    let out = psao(&[
        "relight",
        "train",
        "--character",
        s(&fox),
        "--clip",
        "Dance",
        "--out",
        s(&m),
    ]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("Dance") && err.contains("Survey"), "{err}");
    assert!(!m.exists());
}
