//! End-to-end tests of `psao volume …` on the shared OpenVDB files (skipped when missing).

mod common;

use common::{psao, stderr};
use std::path::PathBuf;

fn data(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/volumes"
    ))
    .join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} missing, test skipped", p.display());
        None
    }
}

#[test]
fn info_convert_and_render_a_psv() {
    let Some(dragon) = data("dragon_sergeneren.vdb") else {
        return;
    };
    let dragon = dragon.to_str().unwrap();
    let out = psao(&["volume", "info", dragon]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("19660 active voxels"), "{text}");
    assert!(text.contains("UniformScaleMap"), "{text}");

    let dir = tempfile::tempdir().unwrap();
    let psv = dir.path().join("d.psv");
    let json = dir.path().join("d.json");
    let out = psao(&[
        "volume",
        "convert",
        dragon,
        "--format",
        "bc7",
        "--cluster",
        "8,5,0.05",
        "--out",
        psv.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in [
        "bits_per_voxel_bricks",
        "bits_per_voxel_total",
        "bits_per_active_voxel",
        "rmse",
        "max_error",
    ] {
        assert!(j[key].as_f64().is_some(), "{key} missing in {j}");
    }
    let bricks_bpv = j["bits_per_voxel_bricks"].as_f64().unwrap();
    assert!((2.0..2.1).contains(&bricks_bpv), "{bricks_bpv}");
    assert!(j["bits_per_voxel_total"].as_f64().unwrap() > 2.0);
    assert!(j["rmse"].as_f64().unwrap() < 0.05);
    assert!(j["bricks_after"].as_u64().unwrap() <= j["bricks_before"].as_u64().unwrap());

    let out = psao(&["volume", "info", psv.to_str().unwrap()]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("format bc7"));

    for mode in ["fog", "deltatrack"] {
        let png = dir.path().join(format!("{mode}.png"));
        let out = psao(&[
            "volume",
            "render",
            psv.to_str().unwrap(),
            "--mode",
            mode,
            "--res",
            "40x30",
            "--spp",
            "2",
            "--out",
            png.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        let img = image::open(&png).unwrap();
        assert_eq!((img.width(), img.height()), (40, 30));
        assert!(
            img.to_luma8().pixels().any(|p| p.0[0] > 0),
            "{mode} image is black"
        );
    }
    // A fog volume cannot be rendered as a level set.
    let out = psao(&[
        "volume",
        "render",
        psv.to_str().unwrap(),
        "--mode",
        "levelset",
        "--res",
        "8x8",
        "--out",
        dir.path().join("x.png").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("level-set"));
}

#[test]
fn level_set_render_from_vdb() {
    let Some(sphere) = data("sphere.vdb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("s.png");
    let out = psao(&[
        "volume",
        "render",
        sphere.to_str().unwrap(),
        "--res",
        "32x32",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let img = image::open(&png).unwrap().to_luma8();
    // The sphere covers the centre, not the corners.
    assert!(img.get_pixel(16, 16).0[0] > 0);
    assert_eq!(img.get_pixel(0, 0).0[0], 0);
}

#[test]
fn broken_files_fail_with_a_clear_message() {
    let Some(sphere) = data("sphere.vdb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(&sphere).unwrap();
    let truncated = dir.path().join("truncated.vdb");
    std::fs::write(&truncated, &bytes[..bytes.len() / 3]).unwrap();
    let garbage = dir.path().join("garbage.vdb");
    std::fs::write(&garbage, b"this is not a volume at all, just some text").unwrap();
    let bad_psv = dir.path().join("bad.psv");
    std::fs::write(&bad_psv, b"PSVOLUME\x01\x00\x00\x00garbage").unwrap();
    for (file, expect) in [
        (&truncated, "truncated.vdb"),
        (&garbage, "magic"),
        (&bad_psv, ".psv"),
    ] {
        for cmd in ["info", "render"] {
            let out = psao(
                &["volume", cmd, file.to_str().unwrap(), "--out", "/dev/null"]
                    [..if cmd == "info" { 3 } else { 5 }],
            );
            let err = stderr(&out);
            assert!(!out.status.success(), "{cmd} {file:?} succeeded");
            assert!(err.contains(expect), "{cmd} {file:?}: {err}");
            assert!(!err.contains("panicked"), "{err}");
        }
    }
    let out = psao(&[
        "volume",
        "convert",
        sphere.to_str().unwrap(),
        "--format",
        "bc9",
        "--out",
        "x.psv",
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("unknown brick format"));
}

/// A scene file: the built-in scene plus, when `volume` is given, that `[[volume]]` body
/// (a homogeneous fog `.psv` covering the whole hall is written next to it as `fog.psv`).
fn volume_scene(dir: &std::path::Path, name: &str, volume: Option<&str>) -> PathBuf {
    use psao_volume::{psv, BrickFormat, SparseGrid, Volume};
    let grid = SparseGrid::constant_fog(glam::IVec3::ONE, 12.5, 1.0);
    let (vol, _) = Volume::build(&[grid], BrickFormat::F32, None).unwrap();
    psv::write_file(&vol, &dir.join("fog.psv")).unwrap();
    let paths = concat!(env!("CARGO_MANIFEST_DIR"), "/../../paths/default_a.toml");
    let mut text = format!("camera_paths = [\"{paths}\"]\n[[asset]]\nfile = \"builtin:default\"\n");
    if let Some(v) = volume {
        text += &format!("[[volume]]\nfile = \"fog.psv\"\ntranslation = [-50, -50, -50]\n{v}\n");
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn mean_png(path: &std::path::Path) -> f64 {
    let img = image::open(path).unwrap().to_luma16();
    img.pixels().map(|p| p.0[0] as f64 / 65535.0).sum::<f64>() / img.pixels().len() as f64
}

#[test]
fn a_scene_volume_darkens_reference_ao_and_keys_the_eval_cache() {
    let dir = tempfile::tempdir().unwrap();
    let plain = volume_scene(dir.path(), "plain.toml", None);
    let fog = volume_scene(dir.path(), "fog.toml", Some("density_scale = 2.0"));
    let mut means = Vec::new();
    for scene in [&plain, &fog] {
        let out = dir.path().join(scene.file_stem().unwrap());
        let o = psao(&[
            "reference",
            "--scene",
            scene.to_str().unwrap(),
            "--spp",
            "8",
            "--res",
            "64x36",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        means.push(mean_png(&out.join("ao_00000.png")));
    }
    // Every covered pixel's rays run through extinction 2/m: AO ≤ (1 − e^(−1.2)) / 1.2 ≈ 0.58.
    assert!(means[1] < means[0] - 0.1, "{means:?}");

    let cache = dir.path().join("cache");
    for scene in [&plain, &fog] {
        let o = psao(&[
            "eval",
            "--scene",
            scene.to_str().unwrap(),
            "--frames",
            "0..1",
            "--points",
            "32",
            "--spp",
            "4",
            "--rtao-spp",
            "1",
            "--res",
            "32x18",
            "--ray-budget",
            "20000",
            "--cache",
            cache.to_str().unwrap(),
            "--out",
            dir.path().join("eval").to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let keys: Vec<_> = std::fs::read_dir(&cache).unwrap().collect();
    assert_eq!(
        keys.len(),
        2,
        "the volume is part of the reference cache key"
    );
}

#[test]
fn bad_scene_volumes_fail_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    for (body, needles) in [
        (
            "format = \"f16\"",
            vec!["fog.toml", "volume format", "fog.psv", ".psv"],
        ),
        ("density_scale = -2.0", vec!["fog.toml", "density_scale"]),
        (
            "densty_scale = 2.0",
            vec!["fog.toml", "unknown field `densty_scale`"],
        ),
    ] {
        let scene = volume_scene(dir.path(), "fog.toml", Some(body));
        let o = psao(&[
            "reference",
            "--scene",
            scene.to_str().unwrap(),
            "--spp",
            "1",
            "--res",
            "8x8",
            "--out",
            dir.path().join("x").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{e}");
        for n in needles {
            assert!(e.contains(n), "`{n}` not in: {e}");
        }
    }
    // A .vdb that is not one: the error names the scene and the volume file.
    std::fs::write(dir.path().join("bad.vdb"), b"not a vdb").unwrap();
    std::fs::write(
        dir.path().join("bad.toml"),
        "[[asset]]\nfile = \"builtin:box\"\n[[volume]]\nfile = \"bad.vdb\"\nformat = \"bc9\"\n",
    )
    .unwrap();
    let o = psao(&[
        "reference",
        "--scene",
        dir.path().join("bad.toml").to_str().unwrap(),
        "--path",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../paths/default_a.toml"),
        "--out",
        dir.path().join("y").to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("bad.toml") && e.contains("bc9"),
        "{e}"
    );
}

#[test]
fn bench_prints_one_row_per_volume_and_mode_with_the_worst_ratios_last() {
    let out = psao(&[
        "volume",
        "bench",
        "--generated",
        "box,cloud",
        "--size",
        "32",
        "--res",
        "24x16",
        "--reps",
        "1",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("| box") || l.starts_with("| cloud"))
        .collect();
    assert_eq!(rows.len(), 3, "{text}");
    assert!(rows[0].contains("fog bc7/f32") && rows[1].contains("level set HDDA/dense"));
    assert!(rows[2].starts_with("| cloud") && rows[2].contains("fog bc7/f32"));
    let last: Vec<&str> = text.lines().rev().take(2).collect();
    assert!(last[1].starts_with("worst fog bc7/f32:"), "{text}");
    assert!(last[0].starts_with("worst level set HDDA/dense:"), "{text}");

    let out = psao(&["volume", "bench", "--generated", "cube"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("unknown generated volume `cube`"),
        "{}",
        stderr(&out)
    );
    let out = psao(&["volume", "bench"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no volume to measure"),
        "{}",
        stderr(&out)
    );
    let out = psao(&["volume", "bench", "--generated", "torus", "--size", "5000"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("16..=512"), "{}", stderr(&out));
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.vdb");
    std::fs::write(&bad, b"not a vdb file at all").unwrap();
    let out = psao(&["volume", "bench", bad.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("bad.vdb"), "{}", stderr(&out));
}
