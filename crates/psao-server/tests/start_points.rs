//! Start points stored as bytes: a server started from them is the server generated afresh,
//! and stored points that do not fit (another scene or settings, damaged bytes) are refused.

mod common;

use common::*;
use psao_delta::{Codec, PaperCodec};
use psao_server::{Server, ServerConfig, ServerError, StartPoints};

/// The snapshot bytes a new client gets after `frames` server frames over the wide view.
fn snapshot_after(mut server: Server, frames: usize) -> Vec<u8> {
    let client = server.add_client();
    for _ in 0..frames {
        server.step(&[wide_view()]);
    }
    PaperCodec::new().encode(&server.update_for(client))
}

#[test]
fn a_server_from_stored_points_equals_one_generated_afresh() {
    let (scene, config) = (scene(), config());
    let start = StartPoints::generate(&scene, &config).unwrap();
    assert!(start.point_count() > 100);
    let bytes = start.to_bytes();
    let read = StartPoints::from_bytes(&bytes, StartPoints::key(&scene, &config)).unwrap();
    assert_eq!(read, start);
    let stored = Server::with_start_points(&scene, config, None, read).unwrap();
    let fresh = Server::new(&scene, config).unwrap();
    assert_eq!(stored.point_count(), fresh.point_count());
    assert_eq!(stored.buried_points(), fresh.buried_points());
    assert_eq!(snapshot_after(stored, 4), snapshot_after(fresh, 4));
}

#[test]
fn the_key_follows_what_shapes_the_points() {
    let (scene, config) = (scene(), config());
    let key = StartPoints::key(&scene, &config);
    assert_eq!(key, StartPoints::key(&scene, &config), "deterministic");
    let denser = ServerConfig {
        density: config.density * 2.0,
        ..config
    };
    let reseeded = ServerConfig {
        seed: config.seed + 1,
        ..config
    };
    let adaptive = ServerConfig {
        adaptive_boost: 2.0,
        ..config
    };
    let mut moved = scene.clone();
    moved.meshes[0].positions[0].x += 1e-3;
    let mut flipped = scene.clone();
    flipped.materials[0].double_sided = !flipped.materials[0].double_sided;
    for other in [
        StartPoints::key(&scene, &denser),
        StartPoints::key(&scene, &reseeded),
        StartPoints::key(&scene, &adaptive),
        StartPoints::key(&moved, &config),
        StartPoints::key(&flipped, &config),
    ] {
        assert_ne!(other, key);
    }
    // The ray budget shapes tracing, not the points.
    let cheaper = ServerConfig {
        ray_budget: config.ray_budget / 2,
        ..config
    };
    assert_eq!(StartPoints::key(&scene, &cheaper), key);
}

#[test]
fn stored_points_that_do_not_fit_are_refused() {
    let (scene, config) = (scene(), config());
    let key = StartPoints::key(&scene, &config);
    let start = StartPoints::generate(&scene, &config).unwrap();
    let bytes = start.to_bytes();
    let refused = |b: &[u8], key: u64| {
        matches!(
            StartPoints::from_bytes(b, key),
            Err(ServerError::StartPoints(_))
        )
    };
    assert!(refused(&bytes, key ^ 1), "another key");
    assert!(refused(&bytes[..bytes.len() / 2], key), "truncated");
    assert!(refused(&[], key), "empty");
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x40;
    assert!(refused(&flipped, key), "damaged");
    let mut version = bytes.clone();
    version[4] = 99;
    assert!(refused(&version, key), "another version");
    // A point count past the end, with a checksum that matches: refused, not allocated.
    let mut absurd = bytes[..bytes.len() - 4].to_vec();
    let count_at = 28 + 4 * 4 + 1 + 6 * 4 + 8 + 8;
    absurd[count_at..count_at + 8].copy_from_slice(&(u64::MAX / 2).to_le_bytes());
    let crc = crc32fast::hash(&absurd);
    absurd.extend_from_slice(&crc.to_le_bytes());
    let err = StartPoints::from_bytes(&absurd, key).unwrap_err();
    assert!(err.to_string().contains("do not fit"), "{err}");
    // Points for another scene are refused by the server too.
    let denser = ServerConfig {
        density: config.density * 2.0,
        ..config
    };
    assert!(matches!(
        Server::with_start_points(&scene, denser, None, start),
        Err(ServerError::StartPoints(_))
    ));
}

#[test]
fn adaptive_placement_keeps_the_count_and_is_deterministic() {
    let (scene, config) = (scene(), config());
    let adaptive = ServerConfig {
        adaptive_boost: 3.0,
        ..config
    };
    let uniform = StartPoints::generate(&scene, &config).unwrap();
    let a = StartPoints::generate(&scene, &adaptive).unwrap();
    assert_eq!(a, StartPoints::generate(&scene, &adaptive).unwrap());
    assert_ne!(a.instances, uniform.instances);
    // Same count before the burial test, up to the points it drops.
    let before = |s: &StartPoints| s.point_count() + s.buried;
    let (u, v) = (before(&uniform) as f64, before(&a) as f64);
    assert!((u - v).abs() <= 0.01 * u, "{u} vs {v}");
    let bad = ServerConfig {
        adaptive_boost: 0.5,
        ..config
    };
    assert!(matches!(
        StartPoints::generate(&scene, &bad),
        Err(ServerError::InvalidConfig(_))
    ));
}
