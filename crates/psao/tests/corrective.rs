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

/// A small room with a chrome ball, a glossy box and a sun, and a 1-second camera path.
fn split_fixture() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let mut obj = String::new();
    let quads: [[[f32; 3]; 4]; 3] = [
        [[-4., 0., -4.], [4., 0., -4.], [4., 0., 4.], [-4., 0., 4.]],
        [[-4., 0., -4.], [-4., 3., -4.], [4., 3., -4.], [4., 0., -4.]],
        [[-4., 0., -4.], [-4., 0., 4.], [-4., 3., 4.], [-4., 3., -4.]],
    ];
    for (i, q) in quads.iter().enumerate() {
        for v in q {
            obj += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        }
        let b = i * 4 + 1;
        obj += &format!("f {} {} {}\nf {} {} {}\n", b, b + 1, b + 2, b, b + 2, b + 3);
    }
    std::fs::write(dir.path().join("room.obj"), obj).unwrap();
    let scene = "ao_radius = 0.6\n\
        camera_paths = [\"path.toml\"]\n\
        [[asset]]\nfile = \"room.obj\"\n\
        [[asset]]\nfile = \"builtin:sphere\"\ntranslation = [-0.6, 0.5, 0.0]\n\
        [[asset]]\nfile = \"builtin:box\"\ntranslation = [0.9, 0.0, -0.5]\nscale = 0.8\n\
        [[material]]\nname = \"sphere\"\npreset = \"chrome\"\n\
        [[material]]\nname = \"box\"\npreset = \"glossy\"\n\
        [[light]]\nkind = \"sun\"\ndirection = [0.35, 1.0, 0.6]\npower = 2.0\n";
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap();
    let path = "name = \"orbit\"\nfov_y_deg = 60.0\n\
        [[key]]\ntime = 0.0\nposition = [2.5, 1.5, 2.5]\nlook_at = [0.0, 0.5, 0.0]\n\
        [[key]]\ntime = 1.0\nposition = [-1.5, 1.5, 3.0]\nlook_at = [0.0, 0.5, 0.0]\n";
    std::fs::write(dir.path().join("path.toml"), path).unwrap();
    dir
}

/// Server settings of the split test (`run` and `serve`).
const SPLIT_SERVER: &[&str] = &[
    "--points",
    "64",
    "--ray-budget",
    "20000",
    "--no-points-cache",
    "--corrective",
    "--samples-per-second",
    "3000",
    "--corrective-ao-spp",
    "2",
];

/// Client settings of the split test (`run` and `view`).
const SPLIT_CLIENT: &[&str] = &["--corrective", "--analyze-every", "3"];

/// A child process killed on drop (a failing client must not leave its server waiting).
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn serve_and_view_with_corrections_end_in_the_same_state_as_run() {
    let fx = split_fixture();
    let scene = fx.path().join("scene.toml");
    let scene = scene.to_str().unwrap();
    let frames = "12";
    // In process: server and client through the encoder.
    let run_out = fx.path().join("run");
    let o = psao(
        &[
            &[
                "run", "--scene", scene, "--res", "64x36", "--frames", "0..12",
            ],
            SPLIT_SERVER,
            &["--analyze-every", "3"],
            &["--server-hz", "30", "--out", run_out.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let run = json(&run_out.join("stats.json"));
    let received: u64 = run["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["samples"].as_u64().unwrap())
        .sum();
    // 3000 samples per second: at most 50 per 60 Hz frame, and some did arrive.
    assert!(received > 50 && received <= 12 * 50, "{received} samples");
    let run_hash = run["corrective_state_hash"].as_str().unwrap().to_string();
    assert!(run_out.join("corrected_00011.png").is_file());

    // Over a connection, lockstep.
    let mut server = Child(
        std::process::Command::new(common::BIN)
            .args([
                "--log",
                "warn",
                "serve",
                "--scene",
                scene,
                "--listen",
                "127.0.0.1:0",
            ])
            .args(SPLIT_SERVER)
            .args(["--hz", "30", "--lockstep", "--once"])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(server.0.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap()
        .to_string();
    let view_json = fx.path().join("view.json");
    let o = psao(
        &[
            &[
                "view",
                "--connect",
                &addr,
                "--scene",
                scene,
                "--res",
                "64x36",
                "--frames",
                frames,
            ],
            SPLIT_CLIENT,
            &["--json", view_json.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(server.0.wait().unwrap().success());
    let view = json(&view_json);
    assert_eq!(view["samples"].as_u64().unwrap(), received);
    assert_eq!(view["corrective_state_hash"].as_str().unwrap(), run_hash);
    assert_eq!(view["state_hash"], run["state_hash"]);
}
