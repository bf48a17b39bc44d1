//! The on-disk start points: stored on the first start, read back on the next (same server),
//! a damaged file replaced, files other builds stored for the same key removed.

use glam::Vec3;
use psao_net::start_cache::{build_id, file_for, start_server};
use psao_scene::{Mesh, Scene};
use psao_server::{ServerConfig, StartPoints};

/// A floor with a box on it: enough points to tell servers apart, quick to generate.
fn scene() -> Scene {
    let quad = |o: Vec3, u: Vec3, v: Vec3| Mesh {
        name: "quad".into(),
        positions: vec![o, o + u, o + u + v, o + v],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    };
    Scene::of_meshes(vec![
        quad(Vec3::new(-2.0, 0.0, 2.0), Vec3::X * 4.0, -Vec3::Z * 4.0),
        quad(Vec3::new(-0.5, 0.0, 0.5), Vec3::X, Vec3::Y),
        quad(Vec3::new(-0.5, 1.0, 0.5), Vec3::X, -Vec3::Z),
    ])
}

fn config() -> ServerConfig {
    ServerConfig {
        density: 200.0,
        ..ServerConfig::default()
    }
}

fn points(server: &psao_server::Server) -> Vec<Vec3> {
    (0..server.instance_count())
        .flat_map(|i| server.points(i).map(|p| p.position).collect::<Vec<_>>())
        .collect()
}

#[test]
fn stored_points_are_read_back_and_bad_or_foreign_files_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, config) = (scene(), config());
    let key = StartPoints::key(&scene, &config);
    let build = build_id();
    assert_ne!(build, 0, "the test binary has an identity");
    let file = file_for(dir.path(), key, build);
    // Another build's file for the same key, and another key's file.
    let other_build = file_for(dir.path(), key, build ^ 2);
    let other_key = file_for(dir.path(), key ^ 1, build);
    std::fs::write(&other_build, b"old").unwrap();
    std::fs::write(&other_key, b"other").unwrap();

    let fresh = start_server(&scene, config, None, Some(dir.path())).unwrap();
    let stored = std::fs::read(&file).unwrap();
    assert!(!other_build.exists(), "another build's file is forgotten");
    assert!(other_key.exists(), "another key's file stays");

    let again = start_server(&scene, config, None, Some(dir.path())).unwrap();
    assert_eq!(points(&again), points(&fresh));
    assert_eq!(std::fs::read(&file).unwrap(), stored, "read, not rewritten");

    // A damaged file is replaced by a sound one and the server is the same.
    let mut damaged = stored.clone();
    let mid = damaged.len() / 2;
    damaged[mid] ^= 0x10;
    std::fs::write(&file, &damaged).unwrap();
    let repaired = start_server(&scene, config, None, Some(dir.path())).unwrap();
    assert_eq!(points(&repaired), points(&fresh));
    assert_eq!(std::fs::read(&file).unwrap(), stored);

    // Without a folder nothing is stored.
    let none = start_server(&scene, config, None, None).unwrap();
    assert_eq!(points(&none), points(&fresh));
}
