//! The CLI on a glTF whose alpha mask is broken: a clear error naming the image, no panic.

mod common;
#[path = "../../psao-scene/tests/fixtures/masked_quad.rs"]
mod masked_quad;

use common::{psao, stderr};
use masked_quad::{checker_png, write, ImageSource};

#[test]
fn broken_mask_image_fails_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let png = checker_png();
    let truncated = write(
        dir.path(),
        "truncated",
        &png[..png.len() / 2],
        ImageSource::BufferView,
        "MASK",
    );
    let missing = write(
        dir.path(),
        "missing",
        &png,
        ImageSource::File("leaf.png"),
        "MASK",
    );
    std::fs::remove_file(dir.path().join("leaf.png")).unwrap();
    for (scene, needle) in [(truncated, "corrupt PNG"), (missing, "cannot read")] {
        let out = dir.path().join("out");
        let o = psao(&[
            "run",
            "--scene",
            scene.to_str().unwrap(),
            "--frames",
            "0..1",
            "--res",
            "32x18",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{scene:?} should fail");
        for n in [needle, "image 0", "alpha-masked material 'checker'"] {
            assert!(err.contains(n), "'{n}' not in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
    }
}
