//! glTF files whose buffer or image URIs try to leave their folder, name devices or lie
//! about their sizes (written into a temporary folder): each is refused with an error that
//! names the problem, and no byte outside the folder is read.

use std::fs;
use std::path::{Path, PathBuf};

use psao_scene::{gltf, load, SceneError};

/// The 36 bytes of one triangle's positions.
fn triangle() -> Vec<u8> {
    [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// A one-triangle glTF whose buffer is `uri`; `image` adds an alpha-masked material whose
/// base colour is that image URI.
fn gltf_json(uri: &str, image: Option<&str>) -> String {
    let material = match image {
        Some(img) => format!(
            r#","materials":[{{"alphaMode":"MASK","pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],
            "textures":[{{"source":0}}],"images":[{{"uri":"{img}"}}]"#
        ),
        None => String::new(),
    };
    let prim_material = if image.is_some() {
        r#","material":0"#
    } else {
        ""
    };
    format!(
        r#"{{"asset":{{"version":"2.0"}},
        "buffers":[{{"uri":"{uri}","byteLength":36}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}{prim_material}}}]}}],
        "nodes":[{{"mesh":0}}],"scenes":[{{"nodes":[0]}}],"scene":0{material}}}"#
    )
}

/// A temporary root with `scene/` (where the glTF goes) and `outside/secret.bin` (36 bytes
/// a hostile glTF would like to read).
struct Folders {
    root: tempfile::TempDir,
}

impl Folders {
    fn new() -> Self {
        let root = tempfile::tempdir().unwrap();
        fs::create_dir(root.path().join("scene")).unwrap();
        fs::create_dir(root.path().join("outside")).unwrap();
        fs::write(root.path().join("outside/secret.bin"), triangle()).unwrap();
        Folders { root }
    }

    fn scene(&self) -> PathBuf {
        self.root.path().join("scene")
    }

    fn secret(&self) -> PathBuf {
        self.root.path().join("outside/secret.bin")
    }

    /// Writes `scene/<name>` with a buffer `uri` and loads it.
    fn load(&self, name: &str, uri: &str, image: Option<&str>) -> Result<(), SceneError> {
        let path = self.scene().join(name);
        fs::write(&path, gltf_json(uri, image)).unwrap();
        load(&path).map(|_| ())
    }
}

fn assert_refused(r: Result<(), SceneError>, needle: &str) -> String {
    let msg = r.expect_err("should be refused").to_string();
    assert!(msg.contains(needle), "'{needle}' not in: {msg}");
    msg
}

#[test]
fn a_buffer_inside_the_folder_loads() {
    let f = Folders::new();
    fs::write(f.scene().join("tri.bin"), triangle()).unwrap();
    f.load("good.gltf", "tri.bin", None).unwrap();
    // A longer file is fine: only the declared 36 bytes are read.
    let mut longer = triangle();
    longer.extend_from_slice(&[7; 1000]);
    fs::write(f.scene().join("long.bin"), longer).unwrap();
    f.load("long.gltf", "long.bin", None).unwrap();
    // A link inside the folder to a file inside it is followed.
    std::os::unix::fs::symlink("tri.bin", f.scene().join("link.bin")).unwrap();
    f.load("link.gltf", "link.bin", None).unwrap();
}

#[test]
fn a_relative_uri_leaving_the_folder_is_refused() {
    let f = Folders::new();
    let msg = assert_refused(
        f.load("bad.gltf", "../outside/secret.bin", None),
        "outside the glTF's folder",
    );
    assert!(
        msg.contains("bad.gltf") && msg.contains("buffer 0"),
        "{msg}"
    );
    assert_refused(
        f.load("enc.gltf", "..%2Foutside%2Fsecret.bin", None),
        "outside the glTF's folder",
    );
}

#[test]
fn file_uris_and_absolute_paths_outside_are_refused() {
    let f = Folders::new();
    let secret = f.secret();
    let secret = secret.to_str().unwrap();
    for uri in [
        format!("file://{secret}"),
        format!("file:{secret}"),
        secret.to_owned(),
        "file:///etc/passwd".to_owned(),
    ] {
        assert_refused(f.load("bad.gltf", &uri, None), "outside the glTF's folder");
    }
}

#[test]
fn devices_are_refused_without_reading() {
    let f = Folders::new();
    for uri in ["/dev/zero", "file:///dev/zero"] {
        assert_refused(f.load("zero.gltf", uri, None), "outside the glTF's folder");
    }
    // A FIFO inside the folder is not a regular file (opening it would block).
    let fifo = f.scene().join("pipe.bin");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        assert_refused(f.load("pipe.gltf", "pipe.bin", None), "not a regular file");
    } else {
        eprintln!("note: mkfifo unavailable, FIFO case skipped");
    }
}

#[test]
fn a_symlink_pointing_outside_is_refused() {
    let f = Folders::new();
    std::os::unix::fs::symlink(f.secret(), f.scene().join("link.bin")).unwrap();
    assert_refused(
        f.load("link.gltf", "link.bin", None),
        "outside the glTF's folder",
    );
    std::os::unix::fs::symlink("/dev/zero", f.scene().join("zero.bin")).unwrap();
    assert_refused(
        f.load("zero.gltf", "zero.bin", None),
        "outside the glTF's folder",
    );
}

#[test]
fn a_file_shorter_than_its_byte_length_is_refused_before_reading() {
    let f = Folders::new();
    fs::write(f.scene().join("short.bin"), &triangle()[..20]).unwrap();
    let msg = assert_refused(
        f.load("short.gltf", "short.bin", None),
        "is a file of 20 bytes but the glTF declares 36",
    );
    assert!(msg.contains("short.gltf"), "{msg}");
}

#[test]
fn image_uris_are_confined_too() {
    let f = Folders::new();
    fs::write(f.scene().join("tri.bin"), triangle()).unwrap();
    fs::write(f.root.path().join("outside/mask.png"), b"\x89PNG\r\n\x1a\n").unwrap();
    assert_refused(
        f.load("img.gltf", "tri.bin", Some("../outside/mask.png")),
        "outside the glTF's folder",
    );
    assert_refused(
        f.load("img.gltf", "tri.bin", Some("/dev/zero")),
        "outside the glTF's folder",
    );
}

#[test]
fn a_gltf_from_memory_names_no_files() {
    let f = Folders::new();
    fs::write(f.scene().join("tri.bin"), triangle()).unwrap();
    let e = gltf::load_from_bytes(gltf_json("tri.bin", None).into_bytes(), Path::new("mem"))
        .unwrap_err();
    assert!(e.to_string().contains("not read from a folder"), "{e}");
}
