//! Scene-file `[[volume]]` entries: placement and fields, and clear errors naming the field.

use std::fs;

use glam::Vec3;
use psao_scene::load;

/// Writes `volume_toml` after one built-in asset into a scene file next to an (empty) volume
/// file `smoke.vdb`; returns the load result's error text or the loaded scene.
fn scene_with(volume_toml: &str) -> (tempfile::TempDir, Result<psao_scene::LoadedScene, String>) {
    let tmp = tempfile::tempdir().unwrap();
    fs::write(tmp.path().join("smoke.vdb"), b"").unwrap();
    fs::write(tmp.path().join("b.vdb"), b"").unwrap();
    let path = tmp.path().join("s.toml");
    fs::write(
        &path,
        format!("[[asset]]\nfile = \"builtin:box\"\n\n{volume_toml}"),
    )
    .unwrap();
    let r = load(&path).map_err(|e| e.to_string());
    (tmp, r)
}

#[test]
fn a_volume_entry_is_placed_and_resolved() {
    let (tmp, r) = scene_with(
        "[[volume]]\nfile = [\"smoke.vdb\", \"b.vdb\"]\ntranslation = [1, 2, 3]\nrotation_deg = [0, 90, 0]\nscale = 0.5\ndensity_scale = 4.0\nformat = \"bc7\"\nframe = 1\n",
    );
    let loaded = r.unwrap();
    assert_eq!(loaded.volumes.len(), 1);
    let v = &loaded.volumes[0];
    assert_eq!(
        v.files,
        vec![tmp.path().join("smoke.vdb"), tmp.path().join("b.vdb")]
    );
    assert_eq!(v.translation, Vec3::new(1.0, 2.0, 3.0));
    assert!((v.rotation * Vec3::Z - Vec3::X).length() < 1e-6);
    assert_eq!(v.scale, Vec3::splat(0.5));
    assert_eq!(
        (v.density_scale, v.format.as_deref(), v.frame),
        (4.0, Some("bc7"), 1)
    );
    // Defaults.
    let (_tmp, r) = scene_with("[[volume]]\nfile = \"smoke.vdb\"\n");
    let v = r.unwrap().volumes.remove(0);
    assert_eq!(
        (v.scale, v.density_scale, v.format, v.frame),
        (Vec3::ONE, 1.0, None, 0)
    );
    // No entry, no volume.
    assert!(scene_with("").1.unwrap().volumes.is_empty());
}

#[test]
fn bad_volume_entries_name_the_file_and_field() {
    for (toml, needles) in [
        (
            "[[volume]]\nfile = \"missing.vdb\"\n",
            vec!["volume 0", "file", "missing.vdb", "not found"],
        ),
        (
            "[[volume]]\nfile = \"smoke.vdb\"\ndensity = 2.0\n",
            vec!["s.toml", "unknown field `density`"],
        ),
        (
            "[[volume]]\nfile = \"smoke.vdb\"\ndensity_scale = -1.0\n",
            vec!["density_scale", "-1"],
        ),
        (
            "[[volume]]\nfile = \"smoke.vdb\"\nscale = [1, 0, 1]\n",
            vec!["volume 0", "scale"],
        ),
        (
            "[[volume]]\nfile = \"smoke.vdb\"\nframe = 1\n",
            vec!["frame", "1 file"],
        ),
        ("[[volume]]\nfile = []\n", vec!["file", "empty"]),
        (
            "[[volume]]\nfile = \"smoke.vdb\"\n[[volume]]\nfile = \"smoke.vdb\"\n",
            vec!["at most one"],
        ),
        (
            "[[volume]]\ntranslation = [0, 0, 0]\n",
            vec!["missing field `file`"],
        ),
    ] {
        let (_tmp, r) = scene_with(toml);
        let e = r.err().unwrap_or_else(|| panic!("{toml} loaded"));
        assert!(e.contains("s.toml"), "{e}");
        for n in needles {
            assert!(e.contains(n), "`{n}` not in: {e}");
        }
    }
}
