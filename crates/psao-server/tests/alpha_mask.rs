//! End to end: a glTF quad with an alpha-checkerboard `MASK` texture gets points only on its
//! opaque texels, about half as many as the same quad unmasked.

#[path = "../../psao-scene/tests/fixtures/masked_quad.rs"]
mod masked_quad;

use masked_quad::{checker_png, opaque_at, write, ImageSource};
use psao_server::{Server, ServerConfig};

fn points(alpha_mode: &str) -> Vec<glam::Vec3> {
    let tmp = tempfile::tempdir().unwrap();
    let path = write(
        tmp.path(),
        "quad",
        &checker_png(),
        ImageSource::BufferView,
        alpha_mode,
    );
    let scene = psao_scene::load(&path).unwrap().scene;
    let server = Server::new(&scene, ServerConfig::default()).unwrap();
    assert_eq!(server.instance_count(), 1);
    server.points(0).map(|p| p.position).collect()
}

#[test]
fn points_lie_on_opaque_texels_only() {
    let masked = points("MASK");
    let unmasked = points("OPAQUE");
    let on_clear = unmasked.iter().filter(|p| !opaque_at(**p)).count();
    assert!(
        on_clear > unmasked.len() / 3,
        "the unmasked quad has points everywhere ({on_clear} of {} on clear texels)",
        unmasked.len()
    );
    assert!(!masked.is_empty());
    for p in &masked {
        assert!(opaque_at(*p), "point {p} on a masked-out texel");
    }
    // Half the area is opaque: about half the points survive (the candidates are spawned
    // for the whole area and halved by elimination after the alpha test).
    let ratio = masked.len() as f64 / unmasked.len() as f64;
    assert!(
        (0.45..=0.55).contains(&ratio),
        "kept {ratio:.3} of the unmasked count"
    );
}
