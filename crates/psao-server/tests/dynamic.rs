//! The server on small animated scenes: rigid motion sends nothing for the moving instance's
//! own points, skinned points follow their triangles, proximity invalidation re-traces
//! contact shadows within one server frame and leaves far static points alone, mirroring
//! stays exact, and everything is deterministic.

mod common;

use common::*;
use glam::{Affine3A, Mat4, Quat, Vec3};
use psao_delta::{Codec, PaperCodec};
use psao_points::{generate_scene_points, GenerateParams};
use psao_scene::{
    AnimatedProperty, Animation, Camera, Channel, Instance, Interpolation, Node, Scene, Skin,
};
use psao_server::{Invalidation, Server, ServerConfig, View};

/// A linear translation clip of `node` through `keys` (time, position).
fn translation_clip(node: usize, keys: &[(f32, Vec3)]) -> Animation {
    Animation {
        name: "move".into(),
        channels: vec![Channel {
            node,
            property: AnimatedProperty::Translation,
            interpolation: Interpolation::Linear,
            times: keys.iter().map(|k| k.0).collect(),
            values: keys.iter().flat_map(|k| k.1.to_array()).collect(),
        }],
    }
}

fn node(name: &str, translation: Vec3) -> Node {
    Node {
        name: name.into(),
        parent: None,
        translation,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    }
}

/// The common floor + boxes scene with the unit box (instance 1) driven by a node moving
/// through `keys`.
fn moving_box_scene(keys: &[(f32, Vec3)]) -> Scene {
    let mut scene = scene();
    scene.nodes.push(node("box", keys[0].1));
    scene.instances[1].node = Some(0);
    scene.instances[1].transform = Affine3A::from_translation(keys[0].1);
    scene.animations.push(translation_clip(0, keys));
    scene.playing.push(0);
    scene
}

fn view_of(from: Vec3, to: Vec3, fov: f32) -> View {
    View {
        camera: Camera::look_at(from, to, fov),
        aspect: 1.0,
    }
}

/// Step at `time` until nothing is traced any more.
fn converge_at(server: &mut Server, views: &[View], time: f32) {
    for _ in 0..64 {
        if server.step_at(views, time).unwrap().traced_points == 0 {
            return;
        }
    }
    panic!("not converged");
}

#[test]
fn rigid_motion_in_free_space_publishes_nothing_for_the_moving_instance() {
    // The box flies 1.5 m above the floor (well beyond R = 0.6 of anything).
    let scene = moving_box_scene(&[
        (0.0, Vec3::new(0.0, 2.0, 0.0)),
        (1.0, Vec3::new(0.5, 2.5, 0.0)),
    ]);
    let mut server = Server::new(&scene, config()).unwrap();
    let client = server.add_client();
    let view = wide_view();
    converge_at(&mut server, &[view], 0.0);
    let _ = server.update_for(client);
    let before: Vec<_> = server.points(1).collect();
    assert!(before.iter().any(|p| p.published.is_some()));
    let stats = server.step_at(&[view], 0.5).unwrap();
    assert_eq!(stats.moved_instances, 1);
    assert_eq!(
        stats.invalidated_points, 0,
        "nothing moved relative to anything within R"
    );
    assert_eq!((stats.rays, stats.published_points), (0, 0));
    let update = server.update_for(client);
    assert!(update.instances.is_empty(), "no cells or buckets resent");
    let t = update.transforms.iter().find(|t| t.0 == 1).unwrap().1;
    assert!(t
        .translation
        .abs_diff_eq(Vec3::new(0.25, 2.25, 0.0).into(), 1e-5));
    let after: Vec<_> = server.points(1).collect();
    assert_eq!(before, after, "local-space points untouched");
}

#[test]
fn contact_shadow_updates_within_one_frame_and_far_points_cost_nothing() {
    // The box rests on the floor at t = 0 and is lifted far away by t = 1 (clips loop over
    // their last key's time).
    let scene = moving_box_scene(&[
        (0.0, Vec3::new(0.0, 0.5, 0.0)),
        (1.0, Vec3::new(0.0, 3.0, 0.0)),
        (2.0, Vec3::new(0.0, 3.0, 0.0)),
    ]);
    let cfg = ServerConfig {
        max_samples: 64,
        ..config()
    };
    let mut server = Server::new(&scene, cfg).unwrap();
    let client = server.add_client();
    let views = [wide_view()];
    converge_at(&mut server, &views, 0.0);
    let _ = server.update_for(client);
    // Floor points right next to the box (occluded) and far in a corner (unaffected).
    let floor: Vec<_> = server.points(0).collect();
    let near: Vec<usize> = (0..floor.len())
        .filter(|&i| {
            let p = floor[i].position;
            floor[i].stored && p.x.abs() < 0.6 && p.z.abs() < 0.6 && p.x.abs() > 0.5
        })
        .collect();
    let far: Vec<usize> = (0..floor.len())
        .filter(|&i| {
            let p = floor[i].position;
            floor[i].stored && p.x < -1.4 && p.z > 1.4
        })
        .collect();
    assert!(
        near.len() >= 3 && far.len() >= 3,
        "{} {}",
        near.len(),
        far.len()
    );
    let near_before: f32 = near.iter().map(|&i| floor[i].published_ao().unwrap()).sum();

    let stats = server.step_at(&views, 1.0).unwrap();
    assert!(stats.invalidated_points > 0 && stats.rays > 0);
    let floor_after: Vec<_> = server.points(0).collect();
    for &i in &near {
        assert!(floor_after[i].samples > 0 && floor_after[i].samples <= cfg.rays_per_point);
    }
    let near_after: f32 = near
        .iter()
        .map(|&i| floor_after[i].published_ao().unwrap())
        .sum();
    assert!(
        near_after > near_before + 0.1 * near.len() as f32,
        "AO next to the lifted box rises: {near_before} -> {near_after}"
    );
    for &i in &far {
        assert_eq!(floor_after[i], floor[i], "far converged point untouched");
    }
    // The moved box's top face (beyond R of the floor and the small box at both poses)
    // kept its AO.
    let top: Vec<_> = server
        .points(1)
        .filter(|p| p.stored && p.position.y > 0.45 && p.position.x < 0.2)
        .collect();
    assert!(!top.is_empty() && top.iter().all(|p| p.samples == cfg.max_samples));
    // The published grid still mirrors exactly.
    let mut mirror = Mirror::new(server.instance_table());
    let fresh = server.add_client();
    mirror.receive(&server.update_for(fresh));
    mirror.assert_matches(&server);
}

#[test]
fn invalidating_everything_retraces_every_visible_point() {
    let keys = [
        (0.0, Vec3::new(0.0, 0.5, 0.0)),
        (1.0, Vec3::new(0.0, 3.0, 0.0)),
    ];
    let scene = moving_box_scene(&keys);
    let run = |invalidation| {
        let cfg = ServerConfig {
            invalidation,
            max_samples: 32,
            ..config()
        };
        let mut server = Server::new(&scene, cfg).unwrap();
        converge_at(&mut server, &[wide_view()], 0.0);
        server.step_at(&[wide_view()], 0.1).unwrap()
    };
    let proximity = run(Invalidation::Proximity);
    let everything = run(Invalidation::Everything);
    assert_eq!(everything.traced_points, everything.visible_points);
    assert!(
        everything.rays > 2 * proximity.rays,
        "{} vs {}",
        everything.rays,
        proximity.rays
    );
}

/// A vertical strip of two quads (y = 0..2, x = ±0.25) skinned to two joints, the upper
/// joint swinging about z; plus the floor. Returns the scene and the strip's instance.
fn skinned_scene() -> (Scene, usize) {
    let mut scene = scene();
    scene.instances.truncate(1);
    let ys = [0.0f32, 1.0, 2.0];
    let mut mesh = psao_scene::Mesh {
        name: "strip".into(),
        ..Default::default()
    };
    for &y in &ys {
        for x in [-0.25f32, 0.25] {
            mesh.positions.push(Vec3::new(x, y + 0.3, 0.0));
            mesh.normals.push(Vec3::Z);
            let w = y / 2.0;
            mesh.joints.push([0, 1, 0, 0]);
            mesh.weights.push([1.0 - w, w, 0.0, 0.0]);
        }
    }
    mesh.indices = vec![[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]];
    scene.meshes.push(mesh);
    scene.nodes = vec![
        node("mesh", Vec3::ZERO),
        node("root", Vec3::ZERO),
        Node {
            parent: Some(1),
            ..node("upper", Vec3::new(0.0, 1.3, 0.0))
        },
    ];
    let swing = |a: f32| Quat::from_rotation_z(a).to_array();
    scene.animations.push(Animation {
        name: "swing".into(),
        channels: vec![Channel {
            node: 2,
            property: AnimatedProperty::Rotation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, 1.0, 2.0],
            values: [swing(0.0), swing(1.2), swing(0.0)].concat(),
        }],
    });
    scene.playing.push(0);
    scene.skins.push(Skin {
        name: "strip".into(),
        joints: vec![1, 2],
        inverse_bind: vec![
            Mat4::IDENTITY,
            Mat4::from_translation(Vec3::new(0.0, -1.3, 0.0)),
        ],
    });
    scene.instances.push(Instance {
        mesh: 2,
        node: Some(0),
        transform: Affine3A::IDENTITY,
        skin: Some(0),
    });
    (scene, 1)
}

#[test]
fn skinned_points_follow_their_triangles_and_mirroring_stays_exact() {
    let (scene, strip) = skinned_scene();
    assert_eq!(
        scene.instance_motion().unwrap()[strip],
        psao_scene::Motion::Skinned
    );
    let cfg = ServerConfig {
        density: 256.0,
        ..config()
    };
    let generated = generate_scene_points(
        &scene,
        &GenerateParams {
            density: cfg.density,
            seed: cfg.seed,
        },
        None,
    )
    .unwrap();
    // The server numbers the points in Morton order of their rest positions.
    let rest: Vec<Vec3> = generated[strip].points.iter().map(|p| p.position).collect();
    let generated: Vec<_> = psao_server::morton_order(&rest)
        .iter()
        .map(|&i| generated[strip].points[i as usize])
        .collect();
    let mut server = Server::new(&scene, cfg).unwrap();
    let client = server.add_client();
    let mut mirror = Mirror::new(server.instance_table());
    let views = [view_of(
        Vec3::new(0.0, 1.5, 4.0),
        Vec3::new(0.0, 1.0, 0.0),
        70.0,
    )];
    let mesh = &scene.meshes[2];
    let mut changed_cells = false;
    for k in 0..12 {
        let t = k as f32 * 0.1;
        let stats = server.step_at(&views, t).unwrap();
        assert!(stats.moved_instances >= 1);
        mirror.receive(&server.update_for(client));
        mirror.assert_matches(&server);
        let pose = scene.pose_at(t).unwrap();
        let geo = pose.skinned[strip].as_ref().unwrap();
        let points: Vec<_> = server.points(strip).collect();
        assert_eq!(points.len(), generated.len());
        for (p, g) in points.iter().zip(&generated) {
            let [a, b, c] = mesh.indices[g.triangle as usize].map(|v| v as usize);
            let want = geo.positions[a] * g.bary.x
                + geo.positions[b] * g.bary.y
                + geo.positions[c] * g.bary.z;
            assert!(
                p.position.abs_diff_eq(want, 1e-5),
                "{} vs {want}",
                p.position
            );
            let n =
                (geo.normals[a] * g.bary.x + geo.normals[b] * g.bary.y + geo.normals[c] * g.bary.z)
                    .normalize();
            let n = if g.back_face { -n } else { n };
            assert!(p.normal.abs_diff_eq(n, 1e-4));
        }
        let stored = points.iter().filter(|p| p.stored).count();
        assert!(
            stored * 10 >= points.len() * 9,
            "{stored} of {} stored",
            points.len()
        );
        changed_cells |= points
            .iter()
            .zip(&generated)
            .any(|(p, g)| (p.position - g.position).length() > 0.5);
    }
    assert!(changed_cells, "the swing moved points across cells");
    // Published records decode near their points' current positions.
    let grid = server.grid(strip).unwrap();
    let layout = *grid.layout();
    let current: Vec<Vec3> = server.points(strip).map(|p| p.position).collect();
    let step = layout.cell_size / 32.0;
    let mut decoded = 0;
    for (b, bucket) in grid.buckets().enumerate() {
        for e in bucket.entries.iter().filter(|e| e.key != 0) {
            let coord = layout.coord_of_id(e.key - 1).unwrap();
            assert_eq!(layout.bucket_of(e.key - 1), b);
            let slot = grid.find_cell(coord).unwrap();
            for p in grid
                .records(slot)
                .iter()
                .filter_map(|&r| layout.unpack(coord, r))
            {
                decoded += 1;
                let near = current
                    .iter()
                    .any(|c| (*c - p.position).abs().max_element() <= 3.5 * step);
                assert!(near, "published point {} is stale", p.position);
            }
        }
    }
    assert!(decoded > 20);
}

#[test]
fn animated_runs_are_deterministic() {
    let (scene, _) = skinned_scene();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut server = Server::new(&scene, config()).unwrap();
            let client = server.add_client();
            (0..8)
                .map(|k| {
                    server.step_at(&[wide_view()], k as f32 / 15.0).unwrap();
                    PaperCodec::new().encode(&server.update_for(client))
                })
                .collect::<Vec<_>>()
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn slow_drift_invalidates_once_it_adds_up() {
    // 1 cm per 0.1 s next to the floor; the tolerance is R · 8/255 ≈ 1.9 cm.
    let scene = moving_box_scene(&[
        (0.0, Vec3::new(0.0, 0.5, 0.0)),
        (10.0, Vec3::new(1.0, 0.5, 0.0)),
    ]);
    let mut server = Server::new(&scene, config()).unwrap();
    let views = [wide_view()];
    converge_at(&mut server, &views, 0.0);
    let counts: Vec<usize> = (1..=4)
        .map(|k| {
            server
                .step_at(&views, k as f32 * 0.1)
                .unwrap()
                .invalidated_points
        })
        .collect();
    assert_eq!(counts[0], 0, "1 cm: below the tolerance");
    assert!(counts[1] > 0, "2 cm since the reference pose: {counts:?}");
    assert_eq!(counts[2], 0, "1 cm since the new reference");
    assert!(counts[3] > 0, "{counts:?}");
}

#[test]
fn small_motion_keeps_part_of_the_history() {
    // The box slides 3 cm along the floor per server frame (tolerance ≈ 1.9 cm): nearby
    // floor points keep tolerance / (tolerance + shift) of their samples.
    let scene = moving_box_scene(&[
        (0.0, Vec3::new(0.0, 0.5, 0.0)),
        (10.0, Vec3::new(3.0, 0.5, 0.0)),
    ]);
    let cfg = ServerConfig {
        max_samples: 64,
        ..config()
    };
    let mut server = Server::new(&scene, cfg).unwrap();
    let views = [wide_view()];
    converge_at(&mut server, &views, 0.0);
    let before: Vec<_> = server.points(0).collect();
    let stats = server.step_at(&views, 0.1).unwrap();
    assert!(stats.invalidated_points > 0);
    let after: Vec<_> = server.points(0).collect();
    let tolerance = 0.6 * cfg.thresholds.ao;
    let kept = tolerance / (tolerance + 0.03);
    let mut near = 0;
    for (b, a) in before.iter().zip(&after) {
        if a.samples < b.samples {
            near += 1;
            let forgotten = (b.samples as f32 * kept) as u32;
            assert!(
                a.samples == forgotten || a.samples == forgotten + cfg.rays_per_point,
                "{} samples -> {} (keep {kept})",
                b.samples,
                a.samples
            );
        }
    }
    assert!(near > 0, "some floor points forgot part of their samples");
}

#[test]
fn a_tight_budget_re_traces_every_point_near_steady_motion_in_turn() {
    // The box slides 3 cm per server frame without stopping; the budget covers half of the
    // points it invalidates. With a fixed tie-break and restarts to zero samples, the same
    // half would win every frame and the other half would never be re-traced.
    let scene = moving_box_scene(&[
        (0.0, Vec3::new(0.0, 0.5, 0.0)),
        (10.0, Vec3::new(3.0, 0.5, 0.0)),
    ]);
    let views = [wide_view()];
    let rays_per_point = config().rays_per_point;
    let mut probe = Server::new(&scene, config()).unwrap();
    converge_at(&mut probe, &views, 0.0);
    let demand = probe.step_at(&views, 0.1).unwrap().invalidated_points as u64;
    let cfg = ServerConfig {
        ray_budget: (demand / 2).max(1) * u64::from(rays_per_point),
        ..config()
    };
    let mut server = Server::new(&scene, cfg).unwrap();
    while server.step_at(&views, 0.0).unwrap().traced_points > 0 {}
    // Floor points beside the box, within R of it on its whole way (x of the box ≤ 0.75 m).
    let steady: Vec<usize> = server
        .points(0)
        .enumerate()
        .filter(|(_, p)| {
            let q = p.position;
            p.stored && q.x.abs() < 0.3 && q.z > 0.5 && q.z < 0.8
        })
        .map(|(i, _)| i)
        .collect();
    assert!(steady.len() >= 5, "{}", steady.len());
    let mut traced = vec![false; steady.len()];
    for k in 1..=25 {
        let stats = server.step_at(&views, k as f32 * 0.1).unwrap();
        assert!(
            stats.traced_points < stats.invalidated_points,
            "the budget is tight"
        );
        if k <= 8 {
            continue; // untraced points may still hold many old samples
        }
        // After eight frames an untraced point has fewer than `rays_per_point` samples (it
        // keeps at most half per frame), a point traced this frame at least that many.
        let now: Vec<_> = server.points(0).collect();
        for (t, &i) in traced.iter_mut().zip(&steady) {
            *t |= now[i].samples >= rays_per_point;
        }
    }
    let starved = traced.iter().filter(|t| !**t).count();
    assert_eq!(
        starved,
        0,
        "{starved} of {} points never re-traced",
        steady.len()
    );
}
