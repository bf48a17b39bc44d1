//! A lit frame end to end through the in-process pipeline: on a floor open to the constant
//! sky and lit by a sun, every floor pixel shows the closed form
//! `base / π × (E_sun·cos θ + π·L_sky)`: the sky's share comes from the points' irradiance
//! records (each path of an open floor sees the sky, so their mean is exactly π·L), the sun's
//! from the client's shadow maps (the server leaves it out). Without lighting the frame has no
//! lit image.

use glam::Vec3;
use psao_net::pipeline::{Pipeline, PipelineConfig};
use psao_net::Resolution;
use psao_scene::environment::DEFAULT_SKY;
use psao_scene::{Camera, Light, LightShape, Mesh, Scene};
use psao_server::{LightingConfig, ServerConfig};

/// A 4 m floor facing +y.
fn floor() -> Scene {
    let mesh = Mesh {
        positions: vec![
            Vec3::new(-2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(-2.0, 0.0, 2.0),
        ],
        normals: vec![Vec3::Y; 4],
        indices: vec![[0, 2, 1], [0, 3, 2]],
        ..Default::default()
    };
    Scene::of_meshes(vec![mesh])
}

fn sun() -> Light {
    Light {
        shape: LightShape::Sun {
            direction: Vec3::new(0.5, 1.0, 0.3),
        },
        color: Vec3::new(1.0, 0.9, 0.7),
        power: 2.0,
    }
}

fn config(lighting: Option<LightingConfig>) -> PipelineConfig {
    PipelineConfig {
        server: ServerConfig {
            density: 64.0,
            ray_budget: 100_000_000,
            lighting,
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
    }
}

/// The last of three client frames of `scene` seen from above.
fn last_frame(scene: &Scene, lighting: Option<LightingConfig>) -> psao_net::pipeline::ClientFrame {
    let camera = Camera::look_at(Vec3::new(0.3, 2.5, 1.5), Vec3::ZERO, 50.0);
    let mut pipeline = Pipeline::new(scene, &config(lighting)).unwrap();
    let mut out = None;
    for frame in 0..3 {
        out = pipeline.frame(frame, &camera, frame == 2).unwrap().1;
    }
    out.expect("the last frame is rendered")
}

#[test]
fn an_open_floor_under_sky_and_sun_shows_the_closed_form() {
    let mut scene = floor();
    scene.lights.push(sun());
    let frame = last_frame(&scene, Some(LightingConfig::default()));
    let lit = frame.lit.as_ref().expect("a lit session has a lit image");
    let base = scene.materials[0].base_color.truncate();
    let l = sun();
    let LightShape::Sun { direction } = l.shape else {
        unreachable!()
    };
    let e_sun = l.color * l.power * Vec3::Y.dot(direction.normalize());
    let e_sky = std::f32::consts::PI * DEFAULT_SKY;
    let want = base / std::f32::consts::PI * (e_sun + e_sky);
    let g = &frame.gbuffer;
    let mut covered = 0;
    for (i, rgb) in lit.iter().enumerate() {
        if !g.covered(i) {
            assert_eq!(*rgb, psao_client::SKY_GREY);
            continue;
        }
        covered += 1;
        let got = Vec3::from(*rgb);
        // RGB9E5 keeps the sky's irradiance within 2⁻⁹ of its brightest channel.
        let err = ((got - want) / want).abs().max_element();
        assert!(err < 5e-3, "pixel {i}: {got} vs {want}");
    }
    assert!(covered > 1000, "{covered}");
    // The AO-only session of the same scene shows its AO composite instead.
    assert!(last_frame(&scene, None).lit.is_none());
}
