//! Broken inputs, made at test time: every one must give an `Err` naming the file, never
//! a panic.

mod common;

use std::fs;
use std::path::{Path, PathBuf};

use psao_scene::{load, CameraPath, SceneError};

/// Asserts `load(path)` fails and the message names `names` (a file name).
fn assert_fails(path: &Path, names: &str) -> SceneError {
    match load(path) {
        Ok(_) => panic!("{} loaded but should fail", path.display()),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains(names), "message does not name {names}: {msg}");
            e
        }
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    fs::write(&p, bytes).unwrap();
    p
}

/// Deterministic xorshift generator for byte corruption.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

#[test]
fn truncated_glb_fails_at_every_cut() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let bytes = fs::read(data.join("characters/Fox.glb")).unwrap();
    let n = bytes.len();
    for cut in [
        0,
        3,
        4,
        11,
        12,
        19,
        20,
        100,
        1000,
        n / 3,
        n / 2,
        n - 100,
        n - 4,
        n - 1,
    ] {
        let p = write(tmp.path(), &format!("fox_cut{cut}.glb"), &bytes[..cut]);
        assert_fails(&p, &format!("fox_cut{cut}.glb"));
    }
}

#[test]
fn glb_whose_bin_chunk_is_shorter_than_declared_buffer() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let bytes = fs::read(data.join("characters/RiggedSimple.glb")).unwrap();
    // Shrink the BIN chunk consistently (header and chunk lengths updated) so only the
    // declared buffer length disagrees.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let bin_at = 20 + json_len;
    let bin_len = u32::from_le_bytes(bytes[bin_at..bin_at + 4].try_into().unwrap()) as usize;
    let new_len = bin_len / 2 / 4 * 4;
    let mut cut = bytes[..bin_at + 8 + new_len].to_vec();
    cut[bin_at..bin_at + 4].copy_from_slice(&(new_len as u32).to_le_bytes());
    let total = cut.len() as u32;
    cut[8..12].copy_from_slice(&total.to_le_bytes());
    let p = write(tmp.path(), "short_bin.glb", &cut);
    let e = assert_fails(&p, "short_bin.glb");
    assert!(matches!(e, SceneError::MissingBuffer { .. }), "{e}");
}

#[test]
fn truncated_or_missing_arcade_bin() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let gltf = fs::read(data.join("scenes/arcade/arcade_with_animated_things4.gltf")).unwrap();
    let bin = fs::read(data.join("scenes/arcade/arcade_with_animated_things4.bin")).unwrap();
    let p = write(tmp.path(), "arcade_with_animated_things4.gltf", &gltf);
    // No .bin at all: an I/O error naming the .bin.
    let e = assert_fails(&p, "arcade_with_animated_things4.bin");
    assert!(matches!(e, SceneError::Io { .. }), "{e}");
    for keep in [0, 1000, bin.len() / 2, bin.len() - 1] {
        write(tmp.path(), "arcade_with_animated_things4.bin", &bin[..keep]);
        let e = assert_fails(&p, "arcade_with_animated_things4.gltf");
        assert!(matches!(e, SceneError::MissingBuffer { .. }), "{e}");
    }
}

/// A named in-place change to a glTF JSON document.
type Edit = Box<dyn Fn(&mut serde_json::Value)>;

#[test]
fn targeted_json_corruptions() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let src = data.join("characters/CesiumMan");
    let text = fs::read_to_string(src.join("CesiumMan.gltf")).unwrap();
    fs::copy(
        src.join("CesiumMan_data.bin"),
        tmp.path().join("CesiumMan_data.bin"),
    )
    .unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let edits: Vec<(&str, Edit)> = vec![
        (
            "accessor_oob",
            Box::new(|j| j["meshes"][0]["primitives"][0]["indices"] = 9999.into()),
        ),
        (
            "count_huge",
            Box::new(|j| j["accessors"][0]["count"] = 3_000_000_000u64.into()),
        ),
        (
            "count_past_view",
            Box::new(|j| j["accessors"][0]["count"] = 2_000_000.into()),
        ),
        (
            "offset_past_buffer",
            Box::new(|j| j["bufferViews"][0]["byteOffset"] = 10_000_000.into()),
        ),
        (
            "stride_small",
            Box::new(|j| j["bufferViews"][1]["byteStride"] = 4.into()),
        ),
        (
            "child_cycle",
            Box::new(|j| j["nodes"][1]["children"] = serde_json::json!([0])),
        ),
        (
            "buffer_uri",
            Box::new(|j| j["buffers"][0]["uri"] = "http://example.com/x.bin".into()),
        ),
        (
            "big_length",
            Box::new(|j| j["buffers"][0]["byteLength"] = 999_999_999.into()),
        ),
        (
            "bad_mode",
            Box::new(|j| j["meshes"][0]["primitives"][0]["mode"] = 42.into()),
        ),
        (
            "no_position",
            Box::new(|j| {
                j["meshes"][0]["primitives"][0]["attributes"]
                    .as_object_mut()
                    .unwrap()
                    .remove("POSITION");
            }),
        ),
    ];
    for (name, edit) in &edits {
        let mut j = json.clone();
        edit(&mut j);
        let file = format!("cesium_{name}.gltf");
        let p = write(
            tmp.path(),
            &file,
            serde_json::to_string(&j).unwrap().as_bytes(),
        );
        assert_fails(&p, &file);
    }
    // Syntax damage.
    for (i, at) in [0, 1, text.len() / 2, text.len() - 2]
        .into_iter()
        .enumerate()
    {
        let mut bytes = text.clone().into_bytes();
        bytes[at] = b'#';
        let file = format!("cesium_syntax{i}.gltf");
        let p = write(tmp.path(), &file, &bytes);
        assert_fails(&p, &file);
    }
}

#[test]
fn random_byte_flips_never_panic() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let glb = fs::read(data.join("characters/RiggedSimple.glb")).unwrap();
    let json_end = 20 + u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let mut failures = 0;
    for round in 0..300 {
        let mut bytes = glb.clone();
        for _ in 0..1 + rng.below(4) {
            // Mostly hit the JSON chunk (where structure lives), sometimes anywhere.
            let at = if rng.below(4) == 0 {
                rng.below(bytes.len())
            } else {
                rng.below(json_end)
            };
            bytes[at] = rng.next() as u8;
        }
        let file = format!("flip{round}.glb");
        let p = write(tmp.path(), &file, &bytes);
        if let Err(e) = load(&p) {
            failures += 1;
            assert!(e.to_string().contains(&file), "{e}");
        }
    }
    assert!(failures > 30, "only {failures} of 300 corruptions detected");
}

/// Replaces the `k`-th JSON value (pre-order) by one of a few troublesome values, or drops
/// a key of it when it is an object. Returns true once done.
fn mutate_json(v: &mut serde_json::Value, k: &mut usize, rng: &mut Rng) -> bool {
    use serde_json::{json, Value};
    if *k == 0 {
        let choices = [
            json!(0),
            json!(1),
            json!(3),
            json!(-1),
            json!(9),
            json!(65535),
            json!(4_000_000_000u64),
            json!(5.5),
            json!(5121),
            json!(5126),
            json!("VEC4"),
            json!("MAT4"),
            json!([]),
            json!({}),
            Value::Null,
        ];
        match v {
            Value::Object(o) if !o.is_empty() && rng.below(3) == 0 => {
                let key = o.keys().nth(rng.below(o.len())).unwrap().clone();
                o.remove(&key);
            }
            _ => *v = choices[rng.below(choices.len())].clone(),
        }
        return true;
    }
    *k -= 1;
    match v {
        Value::Array(a) => a.iter_mut().any(|x| mutate_json(x, k, rng)),
        Value::Object(o) => o.values_mut().any(|x| mutate_json(x, k, rng)),
        _ => false,
    }
}

fn json_size(v: &serde_json::Value) -> usize {
    match v {
        serde_json::Value::Array(a) => 1 + a.iter().map(json_size).sum::<usize>(),
        serde_json::Value::Object(o) => 1 + o.values().map(json_size).sum::<usize>(),
        _ => 1,
    }
}

#[test]
fn structural_json_mutations_never_panic() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let src = data.join("characters/CesiumMan");
    fs::copy(
        src.join("CesiumMan_data.bin"),
        tmp.path().join("CesiumMan_data.bin"),
    )
    .unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(src.join("CesiumMan.gltf")).unwrap()).unwrap();
    let size = json_size(&json);
    let mut rng = Rng(777);
    let mut failures = 0;
    for round in 0..400 {
        let mut j = json.clone();
        for _ in 0..1 + rng.below(3) {
            let mut k = rng.below(size);
            mutate_json(&mut j, &mut k, &mut rng);
        }
        let file = format!("mutant{round}.gltf");
        let p = write(tmp.path(), &file, &serde_json::to_vec(&j).unwrap());
        if let Err(e) = load(&p) {
            failures += 1;
            assert!(e.to_string().contains(&file), "{e}");
        }
    }
    assert!(failures > 100, "only {failures} of 400 mutations detected");
}

#[test]
fn garbage_and_empty_files() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = Rng(42);
    let garbage: Vec<u8> = (0..4096).map(|_| rng.next() as u8).collect();
    for ext in ["glb", "gltf", "obj", "toml"] {
        let p = write(tmp.path(), &format!("garbage.{ext}"), &garbage);
        assert_fails(&p, &format!("garbage.{ext}"));
        let p = write(tmp.path(), &format!("empty.{ext}"), b"");
        assert_fails(&p, &format!("empty.{ext}"));
    }
    let p = write(tmp.path(), "scene.fbx", b"whatever");
    let e = assert_fails(&p, "scene.fbx");
    assert!(e.to_string().contains("extension"), "{e}");
    assert_fails(&tmp.path().join("nope.glb"), "nope.glb");
}

#[test]
fn obj_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, &str); 5] = [
        ("oob.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
        ("negative_oob.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -7\n"),
        ("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"),
        ("no_faces.obj", "v 0 0 0\nv 1 0 0\n"),
        ("bad_vertex.obj", "v 0 zero 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    ];
    for (name, text) in cases {
        let p = write(tmp.path(), name, text.as_bytes());
        assert_fails(&p, name);
    }
    // A valid OBJ with a missing .mtl still loads, with flat normals.
    let p = write(
        tmp.path(),
        "quad.obj",
        b"mtllib missing.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl red\nf 1 2 3 4\n",
    );
    let scene = load(&p).unwrap().scene;
    assert_eq!(scene.instanced_triangle_count(), 2);
    assert_eq!(
        scene.meshes[0].positions.len(),
        6,
        "flat shading unshares vertices"
    );
    assert!(scene.meshes[0]
        .normals
        .iter()
        .all(|n| (*n - glam::Vec3::Z).length() < 1e-6));
}

#[test]
fn scene_file_errors() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let fox = data.join("characters/Fox.glb");
    let fox = fox.to_str().unwrap();
    let cases = [
        (
            "missing_asset.toml",
            "[[asset]]\nfile = \"does_not_exist.glb\"\n".to_string(),
            "does_not_exist.glb",
        ),
        (
            "bad_field.toml",
            format!("[[asset]]\nfile = \"{fox}\"\nscael = 2.0\n"),
            "scael",
        ),
        (
            "bad_type.toml",
            format!("[[asset]]\nfile = \"{fox}\"\ntranslation = [1.0, 2.0]\n"),
            "line 3",
        ),
        (
            "zero_scale.toml",
            format!("[[asset]]\nfile = \"{fox}\"\nscale = 0.0\n"),
            "scale",
        ),
        (
            "bad_clip.toml",
            format!("[[asset]]\nfile = \"{fox}\"\nanimations = [\"Dance\"]\n"),
            "Dance",
        ),
        (
            "bad_radius.toml",
            format!("ao_radius = -1.0\n[[asset]]\nfile = \"{fox}\"\n"),
            "ao_radius",
        ),
        ("no_assets.toml", "ao_radius = 0.5\n".to_string(), "asset"),
        (
            "missing_path.toml",
            format!("camera_paths = [\"nope.toml\"]\n[[asset]]\nfile = \"{fox}\"\n"),
            "nope.toml",
        ),
        (
            "nested.toml",
            "[[asset]]\nfile = \"other.toml\"\n".to_string(),
            "other.toml",
        ),
    ];
    for (name, text, detail) in cases {
        let p = write(tmp.path(), name, text.as_bytes());
        let e = assert_fails(&p, name);
        assert!(e.to_string().contains(detail), "{name}: {e}");
    }
}

#[test]
fn camera_path_file_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let key =
        |t: f32, p: &str, l: &str| format!("[[key]]\ntime = {t}\nposition = {p}\nlook_at = {l}\n");
    let ok = key(0.0, "[0.0, 1.0, 0.0]", "[1.0, 1.0, 0.0]");
    let cases = [
        ("one_key.toml", ok.clone()),
        (
            "same_time.toml",
            ok.clone() + &key(0.0, "[1.0, 1.0, 0.0]", "[2.0, 1.0, 0.0]"),
        ),
        (
            "backwards.toml",
            key(1.0, "[0.0, 1.0, 0.0]", "[1.0, 1.0, 0.0]") + &ok,
        ),
        (
            "nan.toml",
            ok.clone() + &key(1.0, "[nan, 1.0, 0.0]", "[2.0, 1.0, 0.0]"),
        ),
        (
            "inf_time.toml",
            ok.clone() + &key(f32::INFINITY, "[1.0, 1.0, 0.0]", "[2.0, 1.0, 0.0]"),
        ),
        (
            "same_point.toml",
            ok.clone() + &key(1.0, "[1.0, 1.0, 0.0]", "[1.0, 1.0, 0.0]"),
        ),
        (
            "straight_down.toml",
            ok.clone() + &key(1.0, "[1.0, 1.0, 0.0]", "[1.0, 0.0, 0.0]"),
        ),
        (
            "bad_fov.toml",
            format!("fov_y_deg = 190.0\n{ok}") + &key(1.0, "[1.0, 1.0, 0.0]", "[2.0, 1.0, 0.0]"),
        ),
        (
            "unknown_field.toml",
            format!("speed = 2\n{ok}") + &key(1.0, "[1.0, 1.0, 0.0]", "[2.0, 1.0, 0.0]"),
        ),
        ("garbage.toml", "\u{1}\u{2} not toml [[[".to_string()),
    ];
    for (name, text) in cases {
        let p = write(tmp.path(), name, text.as_bytes());
        let e = CameraPath::load(&p).expect_err(name);
        assert!(e.to_string().contains(name), "{e}");
    }
    let e = CameraPath::load(&tmp.path().join("absent.toml")).unwrap_err();
    assert!(e.to_string().contains("absent.toml"));
}
