//! `psao corrective eval --lighting gi`: the base is the lit composite and the reference the
//! path-traced diffuse lighting, so diffuse pixels have an error of their own; with the AO
//! composite the reference shades diffuse pixels as the base does.

use glam::{Affine3A, Vec3};
use psao_eval::corrective::{evaluate_path, Budget, EvalConfig, GiEval, Order, Tracers};
use psao_scene::builtin::shapes::cuboid;
use psao_scene::{CameraPath, Environment, Light, LightShape, Scene};

const SKY: Vec3 = Vec3::new(0.5, 0.5, 0.6);

/// A diffuse 40 m floor (top at y = 0) under a uniform sky, with or without a small
/// rectangular light 2 m above it (sampled at one point per path: noise).
fn floor(lamp: bool) -> Scene {
    let mut s = Scene::of_meshes(vec![cuboid(Vec3::new(20.0, 0.5, 20.0))]);
    s.instances[0].transform = Affine3A::from_translation(Vec3::new(0.0, -0.5, 0.0));
    s.materials[0].base_color = Vec3::new(0.6, 0.5, 0.4).extend(1.0);
    s.environment = Environment::Constant(SKY);
    if lamp {
        s.lights.push(Light {
            shape: LightShape::Rect {
                centre: Vec3::new(0.0, 2.0, 0.0),
                half_u: Vec3::new(0.5, 0.0, 0.0),
                half_v: Vec3::new(0.0, 0.0, 0.5),
            },
            color: Vec3::ONE,
            power: 4.0,
        });
    }
    s
}

fn path() -> CameraPath {
    CameraPath::parse(
        "name = \"down\"\n\
         [[key]]\ntime = 0.0\nposition = [0.0, 1.5, 2.5]\nlook_at = [0.0, 0.0, 0.0]\n\
         [[key]]\ntime = 1.0\nposition = [0.3, 1.5, 2.5]\nlook_at = [0.0, 0.0, 0.0]\n",
    )
    .unwrap()
}

fn config(lighting: Option<GiEval>) -> EvalConfig {
    EvalConfig {
        width: 32,
        height: 18,
        frames: Some(0..2),
        budgets: vec![Budget::Samples(50)],
        orders: vec![Order::Uniform],
        decay: 0.8,
        analyze_every: 18,
        ao_spp: 8,
        static_frames: 0,
        seed: 3,
        mirror_turn: 1f32.to_radians(),
        lighting,
        dump_frames: Vec::new(),
        full_samples: false,
    }
}

const LIT: GiEval = GiEval {
    bounces: 1,
    base_paths: 2,
    reference_paths: 16,
};

/// The base row's PSNR over all pixels (every pixel is diffuse here).
fn base_psnr(scene: &Scene, lighting: Option<GiEval>) -> f64 {
    let tracers = Tracers::new(scene).unwrap();
    let eval = evaluate_path(scene, &tracers, &path(), &config(lighting), &mut || {}).unwrap();
    assert_eq!(eval.rows[0].order, "base");
    eval.rows[0].error.psnr
}

#[test]
fn the_lit_base_has_an_error_on_diffuse_pixels_where_the_ao_base_has_none() {
    let scene = floor(true);
    assert_eq!(
        base_psnr(&scene, None),
        psao_eval::corrective::metrics::PSNR_CAP
    );
    let lit = base_psnr(&scene, Some(LIT));
    assert!(lit < 60.0, "lit base PSNR {lit}");
}

#[test]
fn the_lit_reference_of_a_floor_under_a_uniform_sky_is_albedo_times_sky() {
    // E = π·L exactly at every path (all rays leave the scene): the lit base equals the
    // reference, while the AO composite (ambient × AO + the client's sun) does not.
    let scene = floor(false);
    assert_eq!(
        base_psnr(&scene, Some(LIT)),
        psao_eval::corrective::metrics::PSNR_CAP
    );
    let tracers = Tracers::new(&scene).unwrap();
    let mut config = config(Some(LIT));
    config.frames = Some(1..2);
    let eval = evaluate_path(&scene, &tracers, &path(), &config, &mut || {}).unwrap();
    let reference = eval.middle.unwrap().reference;
    let rho_sky = Vec3::new(0.6, 0.5, 0.4) * SKY;
    let expected = psao_client::composite_srgb8(&[rho_sky.to_array()]);
    let floor_pixels = reference
        .chunks_exact(3)
        .filter(|p| p.iter().zip(&expected).all(|(a, b)| a.abs_diff(*b) <= 1))
        .count();
    assert!(floor_pixels > 32 * 18 / 2, "{floor_pixels} floor pixels");
}
