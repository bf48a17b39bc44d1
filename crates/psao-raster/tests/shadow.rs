//! Shadow-mapped direct light: shadowed points, open points at the closed form, penumbrae
//! from the filter, and no self-shadowing on flat lit planes.

mod common;

use common::scene_of;
use glam::Vec3;
use psao_raster::{InstancePose, ShadowMaps, ShadowSettings};
use psao_scene::{Camera, Light, LightShape, Scene};

/// Half size of the ground square (y = 0).
const GROUND: f32 = 10.0;
/// Height and half size of the occluding square above the ground's centre.
const ROOF_Y: f32 = 2.0;
const ROOF: f32 = 1.0;

/// A horizontal square at height `y`, half size `h`, facing up.
fn square(y: f32, h: f32) -> [[Vec3; 3]; 2] {
    let (a, b) = (Vec3::new(-h, y, -h), Vec3::new(h, y, -h));
    let (c, d) = (Vec3::new(h, y, h), Vec3::new(-h, y, h));
    [[a, d, c], [a, c, b]]
}

/// The ground alone, or the ground with the roof above it.
fn scene(roof: bool) -> Scene {
    let mut tris = square(0.0, GROUND).to_vec();
    if roof {
        tris.extend(square(ROOF_Y, ROOF));
    }
    scene_of(&tris)
}

fn viewer() -> Camera {
    Camera::look_at(Vec3::new(0.0, 6.0, 12.0), Vec3::ZERO, 60.0)
}

fn sun(direction: Vec3) -> Light {
    Light {
        shape: LightShape::Sun {
            direction: direction.normalize(),
        },
        color: Vec3::new(1.0, 0.9, 0.8),
        power: 3.0,
    }
}

fn point(position: Vec3) -> Light {
    Light {
        shape: LightShape::Point { position },
        color: Vec3::new(0.8, 0.9, 1.0),
        power: 20.0,
    }
}

/// Maps of `lights` over `scene` for the test viewer.
fn maps(scene: &Scene, lights: &[Light], settings: ShadowSettings) -> ShadowMaps {
    let poses: Vec<_> = scene.instances.iter().map(InstancePose::rest).collect();
    let mut maps = ShadowMaps::new(settings);
    maps.render(scene, &poses, lights, &viewer(), 16.0 / 9.0)
        .unwrap();
    maps
}

fn small() -> ShadowSettings {
    ShadowSettings {
        sun_resolution: 256,
        cascades: 2,
        point_resolution: 128,
        pcf: 1,
    }
}

/// The unshadowed closed form of `light` at `p` with normal `n`.
fn closed_form(light: &Light, p: Vec3, n: Vec3) -> Vec3 {
    let strength = light.color * light.power;
    match light.shape {
        LightShape::Sun { direction } => strength * n.dot(direction).max(0.0),
        LightShape::Point { position } => {
            let d = position - p;
            strength * n.dot(d.normalize()).max(0.0) / d.length_squared()
        }
        LightShape::Rect { .. } => Vec3::ZERO,
    }
}

fn assert_close(got: Vec3, want: Vec3, what: &str) {
    assert!(
        (got - want).abs().max_element() <= 1e-5 * want.max_element().max(1.0),
        "{what}: got {got}, want {want}"
    );
}

#[test]
fn points_behind_the_occluder_are_shadowed() {
    let s = scene(true);
    let d = Vec3::new(0.3, 1.0, 0.2).normalize();
    let sun_maps = maps(&s, &[sun(d)], small());
    // The roof's shadow on the ground is the roof moved against the sun by ROOF_Y / d.y.
    let shift = -ROOF_Y / d.y * Vec3::new(d.x, 0.0, d.z);
    for p in [
        Vec3::ZERO,
        Vec3::new(0.5, 0.0, -0.5),
        Vec3::new(-0.5, 0.0, 0.5),
    ] {
        assert_eq!(
            sun_maps.direct(p + shift, Vec3::Y),
            Vec3::ZERO,
            "sun at {p}"
        );
    }
    let light = point(Vec3::new(0.0, 5.0, 0.0));
    let point_maps = maps(&s, &[light], small());
    for p in [
        Vec3::ZERO,
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(-1.2, 0.0, 0.3),
    ] {
        assert_eq!(
            point_maps.direct(p, Vec3::Y),
            Vec3::ZERO,
            "point light at {p}"
        );
    }
    // The roof's top is lit by both.
    let top = Vec3::new(0.2, ROOF_Y, 0.1);
    assert_close(
        sun_maps.direct(top, Vec3::Y),
        closed_form(&sun(d), top, Vec3::Y),
        "roof",
    );
    assert_close(
        point_maps.direct(top, Vec3::Y),
        closed_form(&light, top, Vec3::Y),
        "roof",
    );
}

#[test]
fn open_points_get_the_closed_form() {
    let s = scene(true);
    let lights = [
        sun(Vec3::new(0.3, 1.0, 0.2)),
        point(Vec3::new(0.0, 5.0, 0.0)),
        point(Vec3::new(4.0, 1.5, -3.0)),
    ];
    let m = maps(&s, &lights, small());
    for p in [
        Vec3::new(5.0, 0.0, 5.0),
        Vec3::new(-6.0, 0.0, 2.0),
        Vec3::new(3.0, 0.0, -4.0),
        Vec3::new(-2.5, 0.0, -2.5),
    ] {
        let want: Vec3 = lights.iter().map(|l| closed_form(l, p, Vec3::Y)).sum();
        assert_close(m.direct(p, Vec3::Y), want, &format!("at {p}"));
    }
    // Surfaces facing away get nothing.
    assert_eq!(m.direct(Vec3::new(5.0, 0.0, 5.0), Vec3::NEG_Y), Vec3::ZERO);
}

#[test]
fn filtering_gives_a_penumbra() {
    let s = scene(true);
    let d = Vec3::Y;
    let m = maps(&s, &[sun(d)], small());
    let full = closed_form(&sun(d), Vec3::ZERO, Vec3::Y).x;
    // Across the shadow's edge at x = ROOF, in steps far below a texel.
    let values: Vec<f32> = (0..=400)
        .map(|k| {
            let x = ROOF - 0.5 + k as f32 * 0.0025;
            m.direct(Vec3::new(x, 0.0, 0.0), Vec3::Y).x / full
        })
        .collect();
    assert_eq!(values[0], 0.0);
    assert_eq!(*values.last().unwrap(), 1.0);
    let partial = values.iter().filter(|&&v| v > 0.0 && v < 1.0).count();
    assert!(partial >= 3, "no penumbra: {values:?}");
    assert!(
        values.windows(2).all(|w| w[1] >= w[0]),
        "visibility must grow away from the shadow: {values:?}"
    );
    // A hard shadow (no filtering) has no penumbra.
    let hard = maps(&s, &[sun(d)], ShadowSettings { pcf: 0, ..small() });
    for k in 0..=400 {
        let v = hard
            .direct(Vec3::new(ROOF - 0.5 + k as f32 * 0.0025, 0.0, 0.0), Vec3::Y)
            .x
            / full;
        assert!(v == 0.0 || v == 1.0, "hard shadow value {v}");
    }
}

#[test]
fn flat_lit_planes_do_not_shadow_themselves() {
    let s = scene(false);
    for (k, light) in [
        sun(Vec3::Y),
        sun(Vec3::new(1.0, 1.0, 0.0)),  // 45°
        sun(Vec3::new(-0.3, 0.1, 0.2)), // grazing, ~75°
        point(Vec3::new(0.5, 3.0, -0.5)),
        point(Vec3::new(-4.0, 0.6, 2.0)), // low over the plane
    ]
    .iter()
    .enumerate()
    {
        for settings in [small(), ShadowSettings::default()] {
            let m = maps(&s, std::slice::from_ref(light), settings);
            for i in 0..=40 {
                for j in 0..=40 {
                    let p = Vec3::new(-8.0 + 0.4 * i as f32, 0.0, -8.0 + 0.4 * j as f32);
                    let want = closed_form(light, p, Vec3::Y);
                    assert_close(m.direct(p, Vec3::Y), want, &format!("light {k} at {p}"));
                }
            }
        }
    }
}

#[test]
fn cascades_resolve_small_shadows_near_the_viewer_of_a_large_scene() {
    // A 200 m ground and a 20 cm square 30 cm above it, 3 m in front of the viewer.
    let mut tris = square(0.0, 100.0).to_vec();
    tris.extend(square(0.3, 0.1));
    let s = scene_of(&tris);
    let poses: Vec<_> = s.instances.iter().map(InstancePose::rest).collect();
    let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.0), Vec3::ZERO, 60.0);
    let light = sun(Vec3::Y);
    let shadow_at_centre = |cascades| {
        let mut m = ShadowMaps::new(ShadowSettings {
            cascades,
            ..small()
        });
        m.render(&s, &poses, &[light], &camera, 16.0 / 9.0).unwrap();
        m.direct(Vec3::ZERO, Vec3::Y)
    };
    // One 256² map over the whole ground has texels of ~1.1 m: the shadow is lost.
    assert_ne!(shadow_at_centre(1), Vec3::ZERO);
    // The nearest of three cascades covers a few metres: the shadow is there.
    assert_eq!(shadow_at_centre(3), Vec3::ZERO);
}

#[test]
fn no_maps_no_light_and_rectangles_are_left_out() {
    let s = scene(true);
    let empty = ShadowMaps::new(small());
    assert_eq!(empty.direct(Vec3::ZERO, Vec3::Y), Vec3::ZERO);
    let rect = Light {
        shape: LightShape::Rect {
            centre: Vec3::new(0.0, 4.0, 0.0),
            half_u: Vec3::X,
            half_v: Vec3::Z,
        },
        color: Vec3::ONE,
        power: 1.0,
    };
    let m = maps(&s, &[rect], small());
    assert_eq!(m.direct(Vec3::new(5.0, 0.0, 5.0), Vec3::Y), Vec3::ZERO);
    // Poses that do not fit the scene are an error, not a panic.
    let mut maps = ShadowMaps::new(small());
    assert!(maps
        .render(&s, &[], &[sun(Vec3::Y)], &viewer(), 1.0)
        .is_err());
}

#[test]
fn maps_can_be_shared_between_threads() {
    fn shareable<T: Send + Sync>() {}
    shareable::<ShadowMaps>();
}
