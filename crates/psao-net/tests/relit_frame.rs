//! Relit characters through the in-process pipeline (docs/RELIGHTING.md, "Served
//! characters"): a skinned square standing on a floor, relit with a hand-made model, changes
//! the client's composited frame on the square's pixels only (the AO image and every other
//! pixel stay the same), and a model of a character that does not shadow itself leaves the
//! frame as it was.

use glam::{Mat4, Quat, Vec3};
use psao_net::pipeline::{frame_rgb8, ClientFrame, Pipeline, PipelineConfig};
use psao_net::Resolution;
use psao_prt::limits::PoseLimits;
use psao_prt::model::{PoseModel, LOBE_DIM};
use psao_prt::model_file;
use psao_scene::{Camera, Mesh, Node, Scene, Skin};
use psao_server::ServerConfig;
use psao_wire::RelightingMsg;

/// The square's instance.
const SQUARE: u32 = 1;

/// A 4 m floor facing +y and a 1 m square standing on it facing +z, skinned to one joint.
fn scene() -> Scene {
    let quad = |corners: [Vec3; 4], normal: Vec3| Mesh {
        positions: corners.to_vec(),
        normals: vec![normal; 4],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    };
    let floor = quad(
        [
            Vec3::new(-2.0, 0.0, 2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(-2.0, 0.0, -2.0),
        ],
        Vec3::Y,
    );
    let mut square = quad(
        [
            Vec3::new(-0.5, 0.02, 0.0),
            Vec3::new(0.5, 0.02, 0.0),
            Vec3::new(0.5, 1.02, 0.0),
            Vec3::new(-0.5, 1.02, 0.0),
        ],
        Vec3::Z,
    );
    square.joints = vec![[0; 4]; 4];
    square.weights = vec![[1.0, 0.0, 0.0, 0.0]; 4];
    let mut scene = Scene::of_meshes(vec![floor, square]);
    scene.nodes = vec![Node {
        name: "joint".into(),
        parent: None,
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    }];
    scene.skins = vec![Skin {
        name: "skin".into(),
        joints: vec![0],
        inverse_bind: vec![Mat4::IDENTITY],
    }];
    scene.instances[SQUARE as usize].skin = Some(0);
    scene
}

/// A one-lobe model of the square whose every vertex has visibility `coeffs` (zonal, about
/// its normal), whatever the pose.
fn model(coeffs: [f32; 4]) -> PoseModel {
    let n = 4 * LOBE_DIM;
    let mut weights = vec![0.0f32; 4 * n];
    for v in 0..4 {
        let c = v * LOBE_DIM;
        weights[c + 2] = 1.0;
        weights[c + 3..c + 7].copy_from_slice(&coeffs);
    }
    PoseModel {
        character: "square".into(),
        vertices: 4,
        joints: 1,
        lobes: 1,
        active: vec![0],
        weights,
        limits: PoseLimits::default(),
    }
}

/// A sky brighter above than below, bluish, as order-4 SH per channel.
fn lighting() -> Vec<f32> {
    let two_sqrt_pi = 2.0 * std::f32::consts::PI.sqrt();
    [0.8f32, 0.9, 1.1]
        .iter()
        .flat_map(|&level| {
            let mut sh = [0.0f32; 16];
            sh[0] = two_sqrt_pi * level;
            sh[1] = 0.6 * level; // band 1, y
            sh
        })
        .collect()
}

/// The second client frame, relit with `coeffs` when given.
fn frame(coeffs: Option<[f32; 4]>) -> ClientFrame {
    let scene = scene();
    let config = PipelineConfig {
        server: ServerConfig {
            density: 256.0,
            ray_budget: 100_000_000,
            ..ServerConfig::default()
        },
        server_hz: 60,
        codec: "compact".into(),
        res: Resolution {
            width: 64,
            height: 48,
        },
        medium: None,
        points_cache: None,
        detail: None,
        reconstruct: Default::default(),
        corrective: None,
    };
    let mut pipeline = Pipeline::new(&scene, &config).unwrap();
    if let Some(coeffs) = coeffs {
        pipeline
            .relight(&RelightingMsg {
                character: 0,
                model: model_file::to_bytes(&model(coeffs)),
                lighting: lighting(),
            })
            .unwrap();
    }
    let camera = Camera::look_at(Vec3::new(0.6, 1.4, 2.2), Vec3::new(0.0, 0.4, 0.0), 50.0);
    pipeline.frame(0, &camera, false).unwrap();
    pipeline.frame(1, &camera, true).unwrap().1.unwrap()
}

/// Pixels (index, instance) whose composited colours differ between `a` and `b`, and the
/// largest difference of a byte.
fn differences(a: &ClientFrame, b: &ClientFrame) -> (Vec<(usize, u32)>, u8) {
    let scene = scene();
    let (x, y) = (frame_rgb8(&scene, a), frame_rgb8(&scene, b));
    let mut pixels = Vec::new();
    let mut most = 0;
    for (i, (p, q)) in x.chunks_exact(3).zip(y.chunks_exact(3)).enumerate() {
        let d = p.iter().zip(q).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        if d > 0 {
            pixels.push((i, a.gbuffer.instance[i]));
            most = most.max(d);
        }
    }
    (pixels, most)
}

#[test]
fn relighting_changes_the_characters_pixels_only() {
    let plain = frame(None);
    // Visibility half of the sky's, less towards the horizon.
    let relit = frame(Some([
        0.5 * 2.0 * std::f32::consts::PI.sqrt(),
        0.8,
        0.0,
        0.0,
    ]));
    assert_eq!(plain.ao.data, relit.ao.data, "the AO image is the points'");
    let square_pixels = (0..plain.gbuffer.instance.len())
        .filter(|&i| plain.gbuffer.instance[i] == SQUARE)
        .count();
    assert!(square_pixels > 100, "{square_pixels} pixels of the square");
    let (changed, most) = differences(&plain, &relit);
    assert!(
        changed.iter().all(|&(_, inst)| inst == SQUARE),
        "only the square's pixels change: {changed:?}"
    );
    assert!(
        changed.len() > square_pixels / 2 && most > 8,
        "{} of {square_pixels} square pixels changed, by up to {most}",
        changed.len()
    );
    assert!(relit.ambient_tint.is_some() && relit.lit.is_none());
    assert_eq!(relit.gbuffer.instance, plain.gbuffer.instance);
}

#[test]
fn a_character_that_does_not_shadow_itself_keeps_the_points_shading() {
    let plain = frame(None);
    // Visibility 1 everywhere: the SH of a constant 1.
    let open = frame(Some([2.0 * std::f32::consts::PI.sqrt(), 0.0, 0.0, 0.0]));
    let (changed, most) = differences(&plain, &open);
    // The transfer table's interpolation may move a byte by one.
    assert!(
        most <= 1,
        "{} pixels changed, by up to {most}",
        changed.len()
    );
}

#[test]
fn a_model_of_another_character_is_refused() {
    let scene = scene();
    let config = PipelineConfig {
        server: ServerConfig {
            density: 16.0,
            ..ServerConfig::default()
        },
        server_hz: 60,
        codec: "compact".into(),
        res: Resolution {
            width: 8,
            height: 8,
        },
        medium: None,
        points_cache: None,
        detail: None,
        reconstruct: Default::default(),
        corrective: None,
    };
    let mut pipeline = Pipeline::new(&scene, &config).unwrap();
    let mut wrong = model([1.0, 0.0, 0.0, 0.0]);
    wrong.vertices = 3;
    wrong.weights.truncate(4 * 3 * LOBE_DIM);
    for (character, bytes) in [
        (0, model_file::to_bytes(&wrong)),
        (1, model_file::to_bytes(&model([1.0, 0.0, 0.0, 0.0]))),
        (0, b"not a model".to_vec()),
    ] {
        let err = pipeline
            .relight(&RelightingMsg {
                character,
                model: bytes,
                lighting: lighting(),
            })
            .unwrap_err();
        assert!(
            err.to_string()
                .starts_with(&format!("relit character {character}")),
            "{err}"
        );
    }
}
