//! The per-pixel lighting reference against closed forms: a floor under a uniform sky shows
//! ρ·L exactly, and the inside of a closed sphere lit from its centre (the camera there too)
//! shows ρ/π · E₀ · (1 + ρ + … + ρᴺ) for N bounces.

use glam::{Vec3, Vec4};
use psao_eval::reference_gi::{reference_gi, GiSettings};
use psao_raster::{rasterize, RasterOptions};
use psao_scene::builtin::shapes::{cuboid, sphere};
use psao_scene::{Camera, Environment, Light, LightShape, Scene};
use psao_trace::gi::DiffuseLighting;
use psao_trace::{Backend, GeometryMode, Tracer};

const BACKGROUND: Vec3 = Vec3::new(0.1, 0.2, 0.3);

fn render(scene: &Scene, camera: &Camera, bounces: u32, spp: u32) -> psao_eval::RgbImage {
    let gbuffer = rasterize(scene, camera, &RasterOptions::new(32, 24));
    let tracer = Tracer::new(Backend::default(), scene, GeometryMode::Occlusion).unwrap();
    let lighting = DiffuseLighting::new(scene, 0.0, bounces);
    let settings = GiSettings {
        spp,
        seed: 5,
        background: BACKGROUND,
    };
    reference_gi(&gbuffer, scene, &lighting, &tracer, &settings, &|_| {})
}

#[test]
fn a_floor_under_a_uniform_sky_shows_albedo_times_sky() {
    // A 40 m slab, its top at y = 0, seen from above at an angle; the horizon is background.
    let mut s = Scene::of_meshes(vec![cuboid(Vec3::new(20.0, 0.5, 20.0))]);
    s.instances[0].transform = glam::Affine3A::from_translation(Vec3::new(0.0, -0.5, 0.0));
    let rho = Vec3::new(0.5, 0.25, 1.0);
    s.materials[0].base_color = rho.extend(1.0);
    let sky = Vec3::new(2.0, 1.0, 0.5);
    s.environment = Environment::Constant(sky);
    let camera = Camera::look_at(Vec3::new(0.0, 1.0, 4.0), Vec3::new(0.0, 0.8, 0.0), 60.0);
    let image = render(&s, &camera, 2, 4);
    let (mut floor, mut background) = (0, 0);
    for p in &image.data {
        let p = Vec3::from_array(*p);
        if p == BACKGROUND {
            background += 1;
        } else {
            assert!((p - rho * sky).abs().max_element() < 1e-4, "{p}");
            floor += 1;
        }
    }
    assert!(floor > 100 && background > 100, "{floor} {background}");
}

#[test]
fn a_closed_sphere_lit_from_its_centre_shows_its_bounce_series() {
    // Every pixel sees the inner wall at x; E₀(x) = cos / |x|² from a unit point light at the
    // centre, and each bounce adds a·E₀ (see psao-trace's tests/gi.rs). The image mean of
    // radiance / (a/π · E₀) is compared with 1 + a + … + aᴺ within 2 % (768 pixels × 32
    // paths; a missing or extra bounce is off by ≥ 30 %).
    let a = 0.6f32;
    let mut s = Scene::of_meshes(vec![sphere(2.0, 64)]);
    s.materials[0].base_color = Vec4::new(a, a, a, 1.0);
    s.lights.push(Light {
        shape: LightShape::Point {
            position: Vec3::ZERO,
        },
        color: Vec3::ONE,
        power: 1.0,
    });
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::new(0.3, 0.2, -1.0), 70.0);
    let gbuffer = rasterize(&s, &camera, &RasterOptions::new(32, 24));
    assert_eq!(gbuffer.covered_count(), 32 * 24);
    for (bounces, series) in [
        (0u32, 1.0f32),
        (1, 1.0 + a),
        (3, 1.0 + a + a * a + a * a * a),
    ] {
        let image = render(&s, &camera, bounces, 32);
        let mut ratio = 0.0f64;
        for (i, p) in image.data.iter().enumerate() {
            let x = gbuffer.position[i];
            let e0 = gbuffer.normal[i].dot(-x.normalize()) / x.length_squared();
            ratio += f64::from(p[0] / (a / std::f32::consts::PI * e0));
        }
        let mean = ratio / image.data.len() as f64;
        assert!(
            (mean / f64::from(series) - 1.0).abs() < 0.02,
            "{bounces} bounces: {mean} vs {series}"
        );
    }
}
