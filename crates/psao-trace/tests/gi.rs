//! Diffuse lighting ([`psao_trace::gi`]) against closed forms: a plane under a uniform sky and
//! a sun, a rectangle light over a point, and the furnace of a closed sphere lit from its
//! centre, whose bounces form a geometric series.

mod common;

use common::{instance, quad, scene};
use glam::{Affine3A, Vec3, Vec4};
use psao_scene::builtin::shapes::sphere;
use psao_scene::{Environment, Light, LightShape, Scene};
use psao_trace::gi::DiffuseLighting;
use psao_trace::{Backend, GeometryMode, Tracer};

fn tracer(scene: &Scene) -> Tracer {
    Tracer::new(Backend::default(), scene, GeometryMode::Occlusion).unwrap()
}

/// The mean irradiance of `spp` samples at `x` (normal `n`).
fn irradiance(lighting: &DiffuseLighting, tracer: &Tracer, x: Vec3, n: Vec3, spp: u32) -> Vec3 {
    lighting.irradiance_sum(tracer, x, n, n, 0, spp, 7, 42) / spp as f32
}

/// A 200 m floor at y = 0 under a uniform sky of radiance `sky`.
fn floor(sky: Vec3) -> Scene {
    let mut s = scene(
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 100.0)],
        vec![instance(0, Affine3A::IDENTITY)],
    );
    s.environment = Environment::Constant(sky);
    s
}

#[test]
fn an_open_plane_receives_pi_times_the_sky_and_the_sun_by_its_cosine() {
    let sky = Vec3::new(0.5, 1.0, 2.0);
    let mut s = floor(sky);
    let t = tracer(&s);
    for bounces in [0, 1, 3] {
        let e = irradiance(
            &DiffuseLighting::new(&s, 0.0, bounces),
            &t,
            Vec3::ZERO,
            Vec3::Y,
            64,
        );
        // Every hemisphere ray misses: exact up to rounding.
        assert!(
            (e - std::f32::consts::PI * sky).abs().max_element() < 1e-4,
            "{e}"
        );
    }
    // A sun at 60° from the zenith adds power · cos 60°.
    let direction = Vec3::new(3f32.sqrt() / 2.0, 0.5, 0.0);
    s.lights.push(Light {
        shape: LightShape::Sun { direction },
        color: Vec3::new(1.0, 0.5, 0.25),
        power: 4.0,
    });
    let e = irradiance(
        &DiffuseLighting::new(&s, 0.0, 1),
        &t,
        Vec3::ZERO,
        Vec3::Y,
        16,
    );
    let want = std::f32::consts::PI * sky + Vec3::new(1.0, 0.5, 0.25) * 2.0;
    assert!((e - want).abs().max_element() < 1e-4, "{e} vs {want}");
    // A wall between the point and the sun shadows it (the sky stays, less what the wall hides).
    let mut walled = s.clone();
    walled
        .meshes
        .push(quad(Vec3::new(1.0, 5.0, 0.0), Vec3::Y, Vec3::Z, 5.0));
    walled.instances.push(instance(1, Affine3A::IDENTITY));
    let t = tracer(&walled);
    let e = irradiance(
        &DiffuseLighting::new(&walled, 0.0, 0),
        &t,
        Vec3::ZERO,
        Vec3::Y,
        256,
    );
    assert!(e.x < std::f32::consts::PI * sky.x, "{e}");
    assert!(e.x > 0.5 * std::f32::consts::PI * sky.x, "{e}");
}

/// Irradiance at a point under the corner of a parallel `a × b` rectangle of unit radiance at
/// height `h`: π times the point-to-rectangle form factor (the classical closed form).
fn corner_irradiance(a: f64, b: f64, h: f64) -> f64 {
    let (x, y) = (a / h, b / h);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    0.5 * (x / sx * (y / sx).atan() + y / sy * (x / sy).atan())
}

#[test]
fn a_rectangle_light_matches_the_form_factor() {
    let mut s = floor(Vec3::ZERO);
    s.lights.push(Light {
        shape: LightShape::Rect {
            centre: Vec3::new(0.0, 2.0, 0.0),
            // x × z = −y: emitting down.
            half_u: Vec3::new(1.5, 0.0, 0.0),
            half_v: Vec3::new(0.0, 0.0, 1.0),
        },
        color: Vec3::ONE,
        power: 3.0,
    });
    let t = tracer(&s);
    let lighting = DiffuseLighting::new(&s, 0.0, 0);
    // Under the centre: four 1.5 × 1 corners.
    let want = 3.0 * 4.0 * corner_irradiance(1.5, 1.0, 2.0) as f32;
    let e = irradiance(&lighting, &t, Vec3::ZERO, Vec3::Y, 4096);
    assert!((e.x / want - 1.0).abs() < 0.01, "{} vs {want}", e.x);
    // The same rectangle turned to emit up lights nothing below it.
    if let LightShape::Rect { half_u, half_v, .. } = &mut s.lights[0].shape {
        std::mem::swap(half_u, half_v);
    }
    let e = irradiance(
        &DiffuseLighting::new(&s, 0.0, 0),
        &t,
        Vec3::ZERO,
        Vec3::Y,
        64,
    );
    assert_eq!(e, Vec3::ZERO);
}

/// Capped rectangle samples ([`DiffuseLighting::with_clamped_rect_samples`]): identical where
/// no sample can exceed `π × radiance` (far from the light), and never above it close to it,
/// where uncapped samples are.
#[test]
fn clamped_rect_samples_stay_below_pi_times_the_radiance() {
    let mut s = floor(Vec3::ZERO);
    let rect = |h: f32| Light {
        shape: LightShape::Rect {
            centre: Vec3::new(0.0, h, 0.0),
            half_u: Vec3::new(1.5, 0.0, 0.0),
            half_v: Vec3::new(0.0, 0.0, 1.0),
        },
        color: Vec3::ONE,
        power: 3.0,
    };
    s.lights.push(rect(2.0));
    let t = tracer(&s);
    let plain = DiffuseLighting::new(&s, 0.0, 0);
    let capped = DiffuseLighting::new(&s, 0.0, 0).with_clamped_rect_samples();
    // At 2 m a sample is at most 3 · 6 m² / 4 m² = 4.5 < 3π: nothing to cap.
    for i in 0..256 {
        let a = plain.sample(&t, Vec3::ZERO, Vec3::Y, Vec3::Y, 7, 42, i);
        let b = capped.sample(&t, Vec3::ZERO, Vec3::Y, Vec3::Y, 7, 42, i);
        assert!(
            (a - b).abs().max_element() <= 1e-5 * a.x,
            "sample {i}: {a} vs {b}"
        );
    }
    s.lights[0] = rect(0.05);
    let t = tracer(&s);
    let plain = DiffuseLighting::new(&s, 0.0, 0);
    let capped = DiffuseLighting::new(&s, 0.0, 0).with_clamped_rect_samples();
    let bound = 3.0 * std::f32::consts::PI;
    let (mut above, mut capped_max) = (0, 0.0f32);
    for i in 0..4096 {
        let a = plain.sample(&t, Vec3::ZERO, Vec3::Y, Vec3::Y, 7, 42, i).x;
        let b = capped.sample(&t, Vec3::ZERO, Vec3::Y, Vec3::Y, 7, 42, i).x;
        above += usize::from(a > bound);
        capped_max = capped_max.max(b);
        // The same sample, capped (up to the rounding of a different operation order).
        assert!(
            (b - a.min(bound)).abs() <= 1e-5 * bound,
            "sample {i}: {a} vs {b}"
        );
    }
    assert!(
        above > 0 && capped_max <= bound,
        "{above} above, max {capped_max}"
    );
}

/// A closed sphere of radius 2 and albedo `albedo`, lit by a point light of intensity 1 at its
/// centre, and a point on its inner wall with the inward normal.
fn furnace(albedo: f32) -> (Scene, Vec3, Vec3) {
    let mut s = Scene::of_meshes(vec![sphere(2.0, 64)]);
    s.materials[0].base_color = Vec4::new(albedo, albedo, albedo, 1.0);
    s.environment = Environment::Constant(Vec3::splat(1e3)); // never seen from inside
    s.lights.push(Light {
        shape: LightShape::Point {
            position: Vec3::ZERO,
        },
        color: Vec3::ONE,
        power: 1.0,
    });
    let m = &s.meshes[0];
    let [a, b, c] = m.indices[m.indices.len() / 3].map(|i| m.positions[i as usize]);
    let x = (a + b + c) / 3.0;
    let inward = -(b - a).cross(c - a).normalize() * (b - a).cross(c - a).dot(x).signum();
    (s, x, inward)
}

#[test]
fn a_closed_sphere_lit_from_its_centre_sums_its_bounces() {
    // Inside a closed Lambertian sphere every wall point sees only wall; when the wall's
    // radiance B is uniform the irradiance it gives is π·B. Each bounce multiplies the
    // direct irradiance E₀ by the albedo a: E = E₀ (1 + a + … + aᴺ), E₀ (1 − a)⁻¹ for all.
    // Tolerance 2 %: the tessellation moves E₀ by < 0.2 %, the noise of 2048 paths is below
    // 1 %, and a missing or extra bounce is off by ≥ 25 % (a = 0.8).
    let a = 0.8f32;
    let (s, x, n) = furnace(a);
    let t = tracer(&s);
    let l = (Vec3::ZERO - x).normalize();
    let e0 = n.dot(l) / x.length_squared();
    for (bounces, factor) in [(0, 1.0), (1, 1.0 + a), (2, 1.0 + a + a * a)] {
        let e = irradiance(&DiffuseLighting::new(&s, 0.0, bounces), &t, x, n, 2048);
        assert!(
            (e.x / (e0 * factor) - 1.0).abs() < 0.02,
            "{bounces} bounces: {} vs {}",
            e.x,
            e0 * factor
        );
        assert_eq!((e.x, e.x), (e.y, e.z), "a grey furnace stays grey");
    }
    // Many bounces at a = 0.5 approach the infinite sum 2·E₀.
    let (s, x, n) = furnace(0.5);
    let t = tracer(&s);
    let e = irradiance(&DiffuseLighting::new(&s, 0.0, 24), &t, x, n, 2048);
    assert!(
        (e.x / (2.0 * e0) - 1.0).abs() < 0.02,
        "{} vs {}",
        e.x,
        2.0 * e0
    );
}

#[test]
fn samples_are_deterministic_per_seed_and_resume_anywhere() {
    let (s, x, n) = furnace(0.7);
    let t = tracer(&s);
    let lighting = DiffuseLighting::new(&s, 0.0, 2);
    let all = lighting.irradiance_sum(&t, x, n, n, 0, 32, 3, 9);
    assert_eq!(all, lighting.irradiance_sum(&t, x, n, n, 0, 32, 3, 9));
    let split = lighting.irradiance_sum(&t, x, n, n, 0, 20, 3, 9)
        + lighting.irradiance_sum(&t, x, n, n, 20, 12, 3, 9);
    assert!((all - split).abs().max_element() < 1e-5 * all.max_element());
    assert_ne!(all, lighting.irradiance_sum(&t, x, n, n, 0, 32, 4, 9));
    assert_ne!(all, lighting.irradiance_sum(&t, x, n, n, 0, 32, 3, 10));
}

#[test]
fn a_turning_sun_follows_its_keys() {
    let mut s = floor(Vec3::ZERO);
    s.lights.push(Light {
        shape: LightShape::Sun { direction: Vec3::Y },
        color: Vec3::ONE,
        power: 1.0,
    });
    s.sun_keys.push(
        psao_scene::SunKeys::new(0, vec![0.0, 10.0], vec![Vec3::Y, Vec3::new(1.0, 1.0, 0.0)])
            .unwrap(),
    );
    let t = tracer(&s);
    let at = |time| {
        irradiance(
            &DiffuseLighting::new(&s, time, 0),
            &t,
            Vec3::ZERO,
            Vec3::Y,
            1,
        )
        .x
    };
    assert!((at(0.0) - 1.0).abs() < 1e-5);
    assert!((at(9.999) - 0.5f32.sqrt()).abs() < 1e-3);
}

#[test]
fn without_sharp_direct_the_point_keeps_only_the_bounces_of_suns_and_point_lights() {
    // The furnace's point light, direct at the point left to the client: E₀ (a + … + aᴺ).
    let a = 0.8f32;
    let (s, x, n) = furnace(a);
    let t = tracer(&s);
    let e0 = n.dot((Vec3::ZERO - x).normalize()) / x.length_squared();
    for (bounces, factor) in [(0, 0.0), (1, a), (2, a + a * a)] {
        let lighting = DiffuseLighting::new(&s, 0.0, bounces).without_sharp_direct();
        let e = irradiance(&lighting, &t, x, n, 2048);
        assert!(
            (e.x - e0 * factor).abs() <= 0.02 * e0 * factor,
            "{bounces} bounces: {} vs {}",
            e.x,
            e0 * factor
        );
    }
    // On an open plane a sun adds nothing to the sky's π·L; a rectangle light stays.
    let sky = Vec3::new(0.5, 1.0, 2.0);
    let mut s = floor(sky);
    s.lights.push(Light {
        shape: LightShape::Sun { direction: Vec3::Y },
        color: Vec3::ONE,
        power: 4.0,
    });
    let t = tracer(&s);
    let lighting = DiffuseLighting::new(&s, 0.0, 1).without_sharp_direct();
    let e = irradiance(&lighting, &t, Vec3::ZERO, Vec3::Y, 16);
    assert!(
        (e - std::f32::consts::PI * sky).abs().max_element() < 1e-4,
        "{e}"
    );
    s.lights.push(Light {
        shape: LightShape::Rect {
            centre: Vec3::Y,
            half_u: Vec3::X * 0.5,
            half_v: Vec3::Z * 0.5,
        },
        color: Vec3::ONE,
        power: 1.0,
    });
    let lighting = DiffuseLighting::new(&s, 0.0, 1).without_sharp_direct();
    let e = irradiance(&lighting, &tracer(&s), Vec3::ZERO, Vec3::Y, 64);
    assert!(e.x > std::f32::consts::PI * sky.x + 0.1, "{e}");
}
