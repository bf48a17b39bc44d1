//! Diffuse irradiance at the points (DESIGN §12, docs/LIGHTING.md): closed forms on open
//! geometry (a uniform sky gives π·L, a sun E·cos θ, a wall's first bounce ρ/2 of its
//! radiance's π), lights light what faces them, results are deterministic per seed, moving
//! geometry and a turning sun restart what they change, and a server without lighting is
//! the AO-only server it was.

mod common;

use common::*;
use glam::{Affine3A, Vec3, Vec4};
use psao_scene::{
    AnimatedProperty, Animation, Channel, Environment, Instance, Interpolation, Light, LightShape,
    Material, Mesh, Node, Scene, SunKeys,
};
use psao_server::{LightingConfig, Server, ServerConfig, StepStats, View, SUN_TOLERANCE_DEG};

/// A single-sided quad with corners `a b c d` (counter-clockwise seen from its front).
fn quad(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> Mesh {
    let n = (b - a).cross(c - a).normalize();
    Mesh {
        positions: vec![a, b, c, d],
        normals: vec![n; 4],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    }
}

/// A floor quad at y = 0 over `x0..x1` × `z0..z1`, facing up.
fn floor(x0: f32, x1: f32, z0: f32, z1: f32) -> Mesh {
    quad(
        Vec3::new(x0, 0.0, z0),
        Vec3::new(x0, 0.0, z1),
        Vec3::new(x1, 0.0, z1),
        Vec3::new(x1, 0.0, z0),
    )
}

/// A scene placing each mesh once, with one material of grey albedo `rho`, constant sky
/// `sky` and `lights`.
fn scene_of(meshes: Vec<Mesh>, rho: f32, sky: Vec3, lights: Vec<Light>) -> Scene {
    let mut scene = Scene::of_meshes(meshes);
    scene.materials = vec![Material {
        base_color: Vec4::new(rho, rho, rho, 1.0),
        ..Material::default()
    }];
    scene.environment = Environment::Constant(sky);
    scene.lights = lights;
    scene
}

fn sun(direction: Vec3, color: Vec3, power: f32) -> Light {
    Light {
        shape: LightShape::Sun {
            direction: direction.normalize(),
        },
        color,
        power,
    }
}

fn lit(bounces: u32, paths_per_point: u32) -> ServerConfig {
    ServerConfig {
        density: 64.0,
        seed: 3,
        rays_per_point: 4,
        max_samples: 16,
        ray_budget: 10_000_000,
        cull_buried: false,
        lighting: Some(LightingConfig {
            bounces,
            paths_per_point,
            sharp_direct: false,
            ..LightingConfig::default()
        }),
        ..ServerConfig::default()
    }
}

/// [`lit`] with the direct light of suns and point lights in the points too.
fn lit_sharp(bounces: u32, paths_per_point: u32) -> ServerConfig {
    let mut config = lit(bounces, paths_per_point);
    if let Some(l) = &mut config.lighting {
        l.sharp_direct = true;
    }
    config
}

fn view(from: Vec3, to: Vec3, fov: f32) -> View {
    View {
        camera: psao_scene::Camera::look_at(from, to, fov),
        aspect: 1.0,
    }
}

/// (point index, local position, local normal, mean irradiance, paths) of every point of
/// `instance` that has paths.
fn lit_points(server: &Server, instance: usize) -> Vec<(usize, Vec3, Vec3, Vec3, u32)> {
    server
        .points(instance)
        .enumerate()
        .filter_map(|(i, p)| {
            let (e, n) = server.irradiance(instance, i)?;
            (n > 0).then_some((i, p.position, p.normal, e, n))
        })
        .collect()
}

fn close(a: Vec3, b: Vec3, relative: f32) -> bool {
    (a - b).abs().max_element() <= relative * b.abs().max_element().max(1e-6)
}

#[test]
fn open_floor_gets_pi_times_the_sky_plus_the_sun_cosine() {
    let sky = Vec3::new(0.2, 0.5, 1.0);
    let (color, power) = (Vec3::new(1.0, 0.5, 0.25), 3.0);
    let direction = Vec3::new(1.0, 1.0, 0.0);
    let sky_only = std::f32::consts::PI * sky;
    let with_sun = sky_only + color * power * std::f32::consts::FRAC_1_SQRT_2;
    // The sun's direct light is in the points only when asked for (clients render it).
    for (bounces, sharp, expected) in [
        (0, true, with_sun),
        (2, true, with_sun),
        (1, false, sky_only),
    ] {
        let scene = scene_of(
            vec![floor(-1.0, 1.0, -1.0, 1.0)],
            0.8,
            sky,
            vec![sun(direction, color, power)],
        );
        let config = if sharp {
            lit_sharp(bounces, 4)
        } else {
            lit(bounces, 4)
        };
        let mut server = Server::new(&scene, config).unwrap();
        let views = [view(Vec3::new(0.0, 3.0, 2.0), Vec3::ZERO, 60.0)];
        let steps = converge(&mut server, &views, 20);
        assert!(steps > 1);
        let points = lit_points(&server, 0);
        assert!(points.len() > 100, "{} lit points", points.len());
        // Every cosine ray leaves the open floor and no shadow ray is blocked: each path is
        // exactly π·L + E·cos θ.
        for (i, _, _, e, n) in &points {
            assert_eq!(*n, 16, "point {i} converged at max_samples paths");
            assert!(close(*e, expected, 1e-5), "point {i}: {e} vs {expected}");
        }
    }
}

/// A 12 m × 8 m wall in the z = 0 plane facing +z and a small floor patch in front of it,
/// albedo `rho`, black sky, a sun from (0, 1, 1) of power `power`.
fn wall_scene(rho: f32, power: f32) -> Scene {
    let wall = quad(
        Vec3::new(-6.0, 0.0, 0.0),
        Vec3::new(6.0, 0.0, 0.0),
        Vec3::new(6.0, 8.0, 0.0),
        Vec3::new(-6.0, 8.0, 0.0),
    );
    scene_of(
        vec![wall, floor(-0.3, 0.3, 0.02, 0.3)],
        rho,
        Vec3::ZERO,
        vec![sun(Vec3::new(0.0, 1.0, 1.0), Vec3::ONE, power)],
    )
}

#[test]
fn the_first_bounce_off_a_sunlit_wall_matches_its_closed_form() {
    // The floor receives the sun, E = P/√2, directly. The wall, facing the sun at 45°
    // too, has radiance ρ·P/(√2·π) and fills the half of the floor's hemisphere on its
    // side: a first bounce of π · ρ·P/(√2·π) · ½. Total P/√2 · (1 + ρ/2) (the wall's finite
    // width misses < 0.7 % of it at the patch's far corner); by default the points leave the
    // sun's direct light to the clients and keep the bounce, P/√2 · ρ/2.
    let (rho, power) = (0.5, 2.0);
    let direct = power * std::f32::consts::FRAC_1_SQRT_2;
    let floor_view = [view(
        Vec3::new(0.0, 1.5, 0.6),
        Vec3::new(0.0, 0.0, 0.16),
        25.0,
    )];
    let cases = [
        (0, true, direct, 1e-5),
        (1, true, direct * (1.0 + rho / 2.0), 0.025),
        (1, false, direct * rho / 2.0, 0.025),
        (0, false, 0.0, 0.0),
    ];
    for (bounces, sharp, expected, tolerance) in cases {
        let mut config = if sharp {
            lit_sharp(bounces, 64)
        } else {
            lit(bounces, 64)
        };
        config.max_samples = 64;
        let mut server = Server::new(&wall_scene(rho, power), config).unwrap();
        converge(&mut server, &floor_view, 40);
        let points = lit_points(&server, 1);
        assert!(points.len() >= 5, "{} floor points", points.len());
        assert!(points.iter().all(|p| p.4 == 1024), "converged floor points");
        let mean = points.iter().map(|p| p.3).sum::<Vec3>() / points.len() as f32;
        assert!(
            close(mean, Vec3::splat(expected), tolerance),
            "{bounces} bounces, sharp {sharp}: {mean} vs {expected}"
        );
        if bounces == 0 {
            // Without bounces every path is exactly the sun's direct light (or nothing).
            for p in &points {
                assert!(close(p.3, Vec3::splat(expected), 1e-5), "{:?}", p);
            }
        }
    }
}

/// The common floor-and-boxes scene under a black sky, with `lights`.
fn boxes_with(lights: Vec<Light>) -> Scene {
    let mut scene = scene();
    scene.environment = Environment::Constant(Vec3::ZERO);
    scene.lights = lights;
    scene
}

/// A 1 m × 1 m rectangle light at height 3 above the origin, emitting down (`down`) or up.
fn ceiling_light(down: bool) -> Light {
    let (u, v) = (Vec3::X * 0.5, Vec3::Z * 0.5);
    Light {
        shape: LightShape::Rect {
            centre: Vec3::Y * 3.0,
            // u × v = −y: emitting down.
            half_u: if down { u } else { v },
            half_v: if down { v } else { u },
        },
        color: Vec3::ONE,
        power: 5.0,
    }
}

#[test]
fn lights_light_what_faces_them_and_darkness_stays_black() {
    let views = [wide_view()];
    let run = |lights: Vec<Light>| {
        let mut server = Server::new(&boxes_with(lights), lit(1, 4)).unwrap();
        let mut stats = StepStats::default();
        for _ in 0..3 {
            stats = server.step(&views);
        }
        (server, stats)
    };
    // A black sky and no lights (or a light facing away): exactly nothing.
    for lights in [vec![], vec![ceiling_light(false)]] {
        let (server, stats) = run(lights);
        assert!(stats.light_paths > 0);
        for instance in 0..3 {
            assert!(lit_points(&server, instance)
                .iter()
                .all(|p| p.3 == Vec3::ZERO));
        }
    }
    let (server, stats) = run(vec![ceiling_light(true)]);
    // One closest-hit and one shadow ray per vertex at most.
    assert!(stats.light_rays > stats.light_paths && stats.light_rays <= 4 * stats.light_paths);
    let floor = lit_points(&server, 0);
    let bright = floor.iter().filter(|p| p.3.min_element() > 0.0).count();
    // All but those under the boxes (black inside) and a few deep in their shadow.
    assert!(
        bright * 4 > floor.len() * 3,
        "{bright} of {} floor points lit",
        floor.len()
    );
    // The top of the unit box (y = 0.5 local, 2.5 m under the light) is lit directly.
    let top: Vec<_> = lit_points(&server, 1)
        .into_iter()
        .filter(|p| p.2.y > 0.9)
        .collect();
    assert!(!top.is_empty() && top.iter().all(|p| p.3.min_element() > 0.1));
    // The box's sides, beside the light's footprint, get only the bounce: less than its top.
    let mean_red = |pts: &[(usize, Vec3, Vec3, Vec3, u32)]| {
        pts.iter().map(|p| p.3.x).sum::<f32>() / pts.len() as f32
    };
    let sides: Vec<_> = lit_points(&server, 1)
        .into_iter()
        .filter(|p| p.2.y.abs() < 0.1)
        .collect();
    assert!(!sides.is_empty() && mean_red(&sides) < mean_red(&top));
}

/// Irradiance (as bits) and paths of every point of every instance.
fn snapshot(server: &Server) -> Vec<(u32, u32, u32, u32)> {
    (0..server.instance_count())
        .flat_map(|inst| {
            (0..server.points(inst).count()).map(move |i| {
                let (e, n) = server.irradiance(inst, i).unwrap();
                (e.x.to_bits(), e.y.to_bits(), e.z.to_bits(), n)
            })
        })
        .collect()
}

#[test]
fn irradiance_is_deterministic_per_seed() {
    let lights = vec![
        ceiling_light(true),
        sun(Vec3::new(0.3, 1.0, 0.2), Vec3::ONE, 1.0),
    ];
    let run = |seed: u64| {
        let mut config = lit(1, 2);
        config.seed = seed;
        config.ray_budget = 20_000;
        let mut server = Server::new(&boxes_with(lights.clone()), config).unwrap();
        let stats: Vec<(u64, u64, usize)> = (0..4)
            .map(|_| {
                let s = server.step(&[wide_view(), corner_view()]);
                (s.light_paths, s.light_rays, s.traced_points)
            })
            .collect();
        (snapshot(&server), stats)
    };
    let (a, b, c) = (run(7), run(7), run(8));
    assert_eq!(a, b);
    assert!(a.0.iter().filter(|p| p.3 > 0).count() > 100);
    assert_ne!(a.0, c.0, "another seed draws other paths");
}

#[test]
fn the_budget_charges_light_paths_and_the_ao_is_unchanged_by_them() {
    let scene = boxes_with(vec![ceiling_light(true)]);
    let views = [wide_view()];
    // A budget for every visible point: lighting changes nothing in the published AO.
    let mut ao_only = Server::new(
        &scene,
        ServerConfig {
            lighting: None,
            ..lit(1, 4)
        },
    )
    .unwrap();
    let mut with_light = Server::new(&scene, lit(1, 4)).unwrap();
    for _ in 0..5 {
        let (a, b) = (ao_only.step(&views), with_light.step(&views));
        assert_eq!((a.traced_points, a.rays), (b.traced_points, b.rays));
        assert_eq!((a.light_paths, a.light_rays, a.relit_points), (0, 0, 0));
        assert_eq!(b.light_paths, 4 * b.traced_points as u64);
    }
    for i in 0..ao_only.instance_count() {
        let (x, y) = (ao_only.grid(i).unwrap(), with_light.grid(i).unwrap());
        assert!(x.cells().eq(y.cells()) && x.buckets().eq(y.buckets()));
        assert_eq!(ao_only.irradiance(i, 0), None);
    }
    assert!(ao_only.lights().is_empty() && with_light.lights().len() == 1);
    let named = |s: &Server| s.memory_use().iter().any(|p| p.name.contains("irradiance"));
    assert!(!named(&ao_only) && named(&with_light));
    // A tight budget: each selected point is charged its 4 AO rays plus 4 paths × 2
    // vertices × (1 + 1 light) rays.
    let mut tight = Server::new(
        &scene,
        ServerConfig {
            ray_budget: 2000,
            ..lit(1, 4)
        },
    )
    .unwrap();
    let stats = tight.step(&views);
    assert_eq!(stats.traced_points, 2000 / (4 + 4 * 2 * 2));
    assert!(stats.rays + stats.light_rays <= 2000);
}

/// Floor and boxes under a sun and a grey sky, the unit box (instance 1) jumping 1.5 m
/// along +x at t = 1.
fn jumping_box() -> Scene {
    let mut scene = boxes_with(vec![sun(Vec3::Y, Vec3::ONE, 1.0)]);
    scene.environment = Environment::Constant(Vec3::splat(0.3));
    let start = Vec3::new(-0.8, 0.5, 0.0);
    scene.nodes.push(Node {
        name: "box".into(),
        parent: None,
        translation: start,
        rotation: glam::Quat::IDENTITY,
        scale: Vec3::ONE,
    });
    scene.instances[1] = Instance {
        node: Some(0),
        transform: Affine3A::from_translation(start),
        ..scene.instances[1].clone()
    };
    let end = start + Vec3::X * 1.5;
    scene.animations.push(Animation {
        name: "jump".into(),
        channels: vec![Channel {
            node: 0,
            property: AnimatedProperty::Translation,
            interpolation: Interpolation::Step,
            // Looping over 2 s: at the start until t = 1, then at the end.
            times: vec![0.0, 1.0, 2.0],
            values: [start.to_array(), end.to_array(), end.to_array()].concat(),
        }],
    });
    scene.playing.push(0);
    scene
}

#[test]
fn moving_geometry_restarts_the_irradiance_near_it() {
    let mut config = lit(1, 4);
    config.max_samples = 8;
    let mut server = Server::new(&jumping_box(), config).unwrap();
    let views = [wide_view()];
    for _ in 0..4 {
        server.step_at(&views, 0.0).unwrap();
    }
    let before = lit_points(&server, 0);
    assert!(before.iter().all(|p| p.4 == 8), "floor converged");
    // The box leaves (−0.8, 0) for (0.7, 0): floor points near either place restart, the
    // far corners keep their paths.
    let stats = server.step_at(&[], 1.5).unwrap();
    assert!(stats.invalidated_points > 0);
    assert_eq!(stats.light_paths, 0, "no view: nothing traced");
    let count = |i: usize| server.irradiance(0, i).unwrap().1;
    let (mut near, mut far) = (0, 0);
    for (i, p, ..) in &before {
        let d_old = (p.x + 0.8).abs().max(p.z.abs());
        let d_new = (p.x - 0.7).abs().max(p.z.abs());
        if d_old < 0.55 || d_new < 0.55 {
            near += 1;
            assert!(count(*i) < 8, "point {i} at {p} next to the box restarted");
        } else if d_old > 0.5 + 0.6 + 0.2 && d_new > 0.5 + 0.6 + 0.2 {
            far += 1;
            assert_eq!(
                count(*i),
                8,
                "point {i} at {p} far from the box kept its paths"
            );
        }
    }
    assert!(near > 10 && far > 10, "{near} near, {far} far");
}

/// The common scene under a sun turning from straight up (t = 0) to +x (t = 10 s): 9°/s.
fn turning_sun() -> Scene {
    let mut scene = boxes_with(vec![sun(Vec3::Y, Vec3::ONE, 2.0)]);
    scene
        .sun_keys
        .push(SunKeys::new(0, vec![0.0, 10.0], vec![Vec3::Y, Vec3::X]).unwrap());
    scene
}

#[test]
fn a_turning_sun_relights_what_it_lights_past_the_tolerance() {
    let views = [wide_view()];
    let below = SUN_TOLERANCE_DEG / 9.0 * 0.5;
    let above = SUN_TOLERANCE_DEG / 9.0 * 2.0;
    // Without bounces and with the sun's direct light left to the clients, the sun does not
    // reach the points: nothing restarts.
    let mut server = Server::new(&turning_sun(), lit(0, 4)).unwrap();
    server.step_at(&views, 0.0).unwrap();
    assert_eq!(server.step_at(&views, above).unwrap().relit_points, 0);
    for bounces in [0, 1] {
        let mut config = lit_sharp(bounces, 4);
        config.max_samples = 8;
        let mut server = Server::new(&turning_sun(), config).unwrap();
        for _ in 0..4 {
            server.step_at(&views, 0.0).unwrap();
        }
        let total: usize = (0..3).map(|i| lit_points(&server, i).len()).sum();
        assert!(total > 500);
        // Half the tolerance: nothing restarts, the paths keep the old sun.
        let stats = server.step_at(&[], below).unwrap();
        assert_eq!(stats.relit_points, 0);
        assert_eq!(
            server.lights()[0].shape,
            LightShape::Sun { direction: Vec3::Y }
        );
        // Twice the tolerance: the new sun is taken and what it lights restarts.
        let stats = server.step_at(&[], above).unwrap();
        let now = turning_sun().lights_at(above)[0].shape;
        assert_eq!(server.lights()[0].shape, now);
        let left: usize = (0..3).map(|i| lit_points(&server, i).len()).sum();
        if bounces == 0 {
            // Points facing neither sun (the −x sides of the boxes) keep their paths.
            assert!(stats.relit_points > 0 && stats.relit_points < total);
            let away: Vec<_> = lit_points(&server, 1)
                .into_iter()
                .filter(|p| p.2.x < -0.9)
                .collect();
            assert!(!away.is_empty() && away.iter().all(|p| p.4 == 8));
            assert!(left > 0 && left < total);
        } else {
            // With bounces the sun's light may reach any point: all restart.
            assert!(stats.relit_points >= total);
            assert_eq!(left, 0);
        }
        // The relit points are traced again, first.
        let stats = server.step_at(&views, above).unwrap();
        assert!(stats.light_paths > 0);
    }
}

/// The lights of every cell of `update`, checked to be one array per cell.
fn lights_of(update: &psao_delta::Update) -> Vec<[u32; 7]> {
    for d in &update.instances {
        assert_eq!(d.lights.len(), d.cells.len(), "one light array per cell");
    }
    update
        .instances
        .iter()
        .flat_map(|d| d.lights.clone())
        .collect()
}

#[test]
fn updates_carry_irradiance_records_resent_past_the_threshold() {
    use psao_delta::{Codec, CompactCodec, PaperCodec};
    use psao_points::irradiance::unpack_rgb9e5;
    let (sky, power) = (Vec3::splat(0.3), 2.0);
    let mut scene = scene_of(
        vec![floor(-1.0, 1.0, -1.0, 1.0)],
        0.8,
        sky,
        vec![sun(Vec3::Y, Vec3::ONE, power)],
    );
    // 9° per second, from straight up towards +x.
    scene
        .sun_keys
        .push(SunKeys::new(0, vec![0.0, 10.0], vec![Vec3::Y, Vec3::X]).unwrap());
    let views = [view(Vec3::new(0.0, 3.0, 2.0), Vec3::ZERO, 60.0)];
    let mut server = Server::new(&scene, lit_sharp(0, 4)).unwrap();
    let client = server.add_client();
    let (mut compact, mut compact_rx) = (CompactCodec::new(), CompactCodec::new());
    let mut send = |server: &mut Server| {
        let update = server.update_for(client);
        let decoded = compact_rx.decode(&compact.encode(&update)).unwrap();
        assert_eq!(lights_of(&decoded), lights_of(&update));
        let bytes = PaperCodec::new().encode(&update);
        let decoded = PaperCodec::new().decode(&bytes).unwrap();
        assert_eq!(lights_of(&decoded), lights_of(&update));
        update
    };
    // Every record of a converged lit cell is the points' irradiance (RGB9E5 keeps 1/256).
    let check = |update: &psao_delta::Update, expected: Vec3| {
        let mut n = 0;
        for d in &update.instances {
            for ((_, cell), lights) in d.cells.iter().zip(&d.lights) {
                for (p, e) in cell.points.iter().zip(lights) {
                    if *p == 0 {
                        assert_eq!(*e, 0, "no record past the cell's points");
                    } else {
                        assert!(close(unpack_rgb9e5(*e), expected, 1.0 / 256.0));
                        n += 1;
                    }
                }
            }
        }
        n
    };
    let pi = std::f32::consts::PI;
    converge(&mut server, &views, 10);
    let first = send(&mut server);
    assert!(first.snapshot && check(&first, pi * sky + Vec3::splat(power)) > 100);
    // A 2° turn relights every floor point, but its irradiance moves by 0.06 %: under the
    // threshold, nothing is resent (the AO of the open floor is exactly 1 throughout).
    let t = 2.0 / 9.0;
    let mut relit = 0;
    for _ in 0..4 {
        let stats = server.step_at(&views, t).unwrap();
        relit += stats.relit_points;
        assert_eq!(stats.published_points, 0);
    }
    assert!(relit > 100);
    assert!(send(&mut server).is_empty());
    // A 40° turn moves it by 16 %: every point is resent with the new irradiance.
    let t = 40.0 / 9.0;
    let cos = scene.lights_at(t)[0].shape;
    let LightShape::Sun { direction } = cos else {
        unreachable!()
    };
    for _ in 0..4 {
        server.step_at(&views, t).unwrap();
    }
    let update = send(&mut server);
    assert!(check(&update, pi * sky + Vec3::splat(power * direction.y)) > 100);
    // Without lighting no records travel.
    let mut ao_only = Server::new(
        &scene,
        ServerConfig {
            lighting: None,
            ..lit(0, 4)
        },
    )
    .unwrap();
    let id = ao_only.add_client();
    ao_only.step(&views);
    let update = ao_only.update_for(id);
    assert!(update.changed_cells() > 0 && !update.has_lights());
}

#[test]
fn at_equal_points_per_frame_lighting_leaves_the_ao_of_a_moving_scene_unchanged() {
    // The jumping box made to slide (3.75 cm per step, past the invalidation tolerance), so
    // invalidated points keep part of their samples; 8 rays and 2 paths per point make the
    // two counts differ in units. The lit server's budget is its charge per point (8 + 2
    // paths × 2 vertices × (1 + 1 light) = 16) times the AO-only server's points per frame.
    let mut scene = jumping_box();
    let channel = &mut scene.animations[0].channels[0];
    channel.interpolation = Interpolation::Linear;
    channel.times = vec![0.0, 2.0];
    channel.values.truncate(6);
    let base = ServerConfig {
        rays_per_point: 8,
        max_samples: 16,
        ray_budget: 8 * 150,
        ..lit(1, 2)
    };
    let mut ao_only = Server::new(
        &scene,
        ServerConfig {
            lighting: None,
            ..base
        },
    )
    .unwrap();
    let mut with_light = Server::new(
        &scene,
        ServerConfig {
            ray_budget: 16 * 150,
            ..base
        },
    )
    .unwrap();
    let views = [wide_view()];
    let mut invalidated = 0;
    for k in 0..30 {
        let t = if k < 10 { 0.0 } else { (k - 10) as f32 * 0.05 };
        let (a, b) = (
            ao_only.step_at(&views, t).unwrap(),
            with_light.step_at(&views, t).unwrap(),
        );
        assert_eq!(
            (a.traced_points, a.rays),
            (b.traced_points, b.rays),
            "step {k}"
        );
        assert_eq!(a.invalidated_points, b.invalidated_points);
        invalidated += a.invalidated_points;
    }
    assert!(invalidated > 0);
    for i in 0..ao_only.instance_count() {
        let (x, y) = (ao_only.grid(i).unwrap(), with_light.grid(i).unwrap());
        assert!(
            x.cells().eq(y.cells()) && x.buckets().eq(y.buckets()),
            "instance {i}"
        );
    }
}

/// A floor in front of a sunlit 4 m × 2 m wall (one mesh, albedo 0.8, sky 0.1): the floor is
/// lit by the sky and the wall's bounce, which few cosine paths find (noisy young points).
fn sunlit_corner() -> Scene {
    let wall = quad(
        Vec3::new(-2.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        Vec3::new(-2.0, 2.0, 0.0),
    );
    let ground = floor(-2.0, 2.0, 0.0, 2.0);
    let mut corner = wall.clone();
    corner.positions.extend(&ground.positions);
    corner.normals.extend(&ground.normals);
    corner
        .indices
        .extend(ground.indices.iter().map(|t| t.map(|i| i + 4)));
    // A horizontal sun lights the wall (E = power) and not the floor.
    scene_of(
        vec![corner],
        0.8,
        Vec3::splat(0.1),
        vec![sun(Vec3::Z, Vec3::ONE, 2.0)],
    )
}

/// While few of the points around a record have paths (a cold start: a budget that traces
/// one point in twelve per frame), its pooling reach widens until it holds `pool_paths`
/// paths (docs/LIGHTING.md, "Pooling"): after one frame the floor's published records lie
/// closer to the converged irradiance (256 paths per point) than with the reach held at the
/// reconstruction radius (`pool_paths = 0`). (That the reach stays in the tangent plane is
/// `published_irradiance_pools_coplanar_points_of_a_cell_only`'s, whose records widen too.)
#[test]
fn young_records_widen_their_pooling_towards_pool_paths() {
    let scene = sunlit_corner();
    let views = [view(
        Vec3::new(0.0, 2.5, 3.5),
        Vec3::new(0.0, 0.3, 0.0),
        80.0,
    )];
    let config = |paths_per_point: u32, pool_paths: u32, ray_budget: u64| {
        let mut c = lit(1, paths_per_point);
        c.density = 256.0;
        c.ray_budget = ray_budget;
        if let Some(l) = &mut c.lighting {
            l.pool_paths = pool_paths;
        }
        c
    };
    let mut truth = Server::new(&scene, config(256, 0, 100_000_000)).unwrap();
    truth.step(&views);
    let converged: Vec<(usize, Vec3)> = lit_points(&truth, 0)
        .iter()
        .filter(|(_, _, n, _, paths)| n.y > 0.9 && *paths == 256)
        .map(|(i, _, _, e, _)| (*i, *e))
        .collect();
    let floor_points = truth.points(0).filter(|p| p.normal.y > 0.9).count();
    assert!(
        converged.len() > 1000,
        "{} converged floor points",
        converged.len()
    );
    // Charge per point: 4 AO rays + 4 paths × 2 vertices × (1 + 1 light) = 20 rays.
    let budget = 20 * (2 * floor_points as u64) / 12;
    let rms_error = |pool_paths: u32| {
        let mut server = Server::new(&scene, config(4, pool_paths, budget)).unwrap();
        let stats = server.step(&views);
        assert!(stats.traced_points * 8 < 2 * floor_points, "{stats:?}");
        let errors: Vec<f32> = converged
            .iter()
            .filter_map(|&(i, e)| Some((server.published_irradiance(0, i)? - e).x))
            .collect();
        assert!(errors.len() > 50, "{} published floor points", errors.len());
        (errors.iter().map(|d| d * d).sum::<f32>() / errors.len() as f32).sqrt()
    };
    let (widened, fixed) = (rms_error(64), rms_error(0));
    assert!(
        widened < 0.7 * fixed,
        "rms error {widened} widening to 64 paths vs {fixed} at the reconstruction radius"
    );
}

/// Published irradiance pools the paths of coplanar points (docs/LIGHTING.md, "Pooling"):
/// on one mesh of a floor before a sunlit wall, the floor's published records vary less
/// than its points' own means after one frame of 4 paths, and at the crease, where cells
/// hold floor and wall points, neither takes the other's light, also with the reach widened
/// (the points within the reconstruction radius hold fewer than `pool_paths` paths).
#[test]
fn published_irradiance_pools_coplanar_points_of_a_cell_only() {
    use psao_points::irradiance::unpack_rgb9e5;
    use psao_points::pack::unpack_normal;
    // The sun lights the wall (E = power) and not the floor (sky only, ≤ π·0.1).
    let (scene, power) = (sunlit_corner(), 2.0);
    let mut server = Server::new(&scene, lit_sharp(0, 4)).unwrap();
    let client = server.add_client();
    let views = [view(
        Vec3::new(0.0, 2.5, 3.5),
        Vec3::new(0.0, 0.3, 0.0),
        80.0,
    )];
    server.step(&views);
    let update = server.update_for(client);
    let is_floor = |n: Vec3| n.y > 0.9;
    let (mut floor_records, mut wall_records, mut crease_cells) = (Vec::new(), 0, 0);
    for d in &update.instances {
        for ((_, cell), lights) in d.cells.iter().zip(&d.lights) {
            let points = cell.points.iter().zip(lights).filter(|(p, _)| **p != 0);
            let (mut floors, mut walls) = (0, 0);
            for (p, e) in points {
                let (n, e) = (unpack_normal(*p), unpack_rgb9e5(*e));
                if is_floor(n) {
                    assert!(e.x < 0.5, "a floor record took the wall's sun: {e}");
                    floor_records.push(e.x);
                    floors += 1;
                } else {
                    assert!(e.x >= 0.99 * power, "a wall record lost its sun: {e}");
                    wall_records += 1;
                    walls += 1;
                }
            }
            crease_cells += usize::from(floors > 0 && walls > 0);
        }
    }
    assert!(floor_records.len() > 100 && wall_records > 100 && crease_cells > 0);
    let own: Vec<f32> = lit_points(&server, 0)
        .iter()
        .filter(|(_, _, n, _, _)| is_floor(*n))
        .map(|(_, _, _, e, _)| e.x)
        .collect();
    let variance = |v: &[f32]| {
        let mean = v.iter().sum::<f32>() / v.len() as f32;
        v.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / v.len() as f32
    };
    let (pooled, alone) = (variance(&floor_records), variance(&own));
    assert!(pooled < 0.6 * alone, "pooled variance {pooled} vs {alone}");
}
