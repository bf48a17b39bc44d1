//! Tracer queries on hand-made scenes, for every compiled backend.

mod common;

use common::{hit_point, instance, quad, same_t, scene, unit_cube, unit_triangle};
use glam::{Affine3A, Quat, Vec3};
use psao_trace::{Backend, GeometryMode, Hit, Ray, TraceError, Tracer};

fn occluded(tracer: &Tracer, ray: Ray) -> bool {
    let mut out = [true];
    tracer.occluded(&[ray], &mut out);
    out[0]
}

fn intersect(tracer: &Tracer, ray: Ray) -> Option<Hit> {
    let mut out = [None];
    tracer.intersect(&[ray], &mut out);
    out[0]
}

fn down(x: f32, y: f32, z: f32, tmax: f32) -> Ray {
    Ray::new(Vec3::new(x, y, z), -Vec3::Z, tmax)
}

#[test]
fn backend_names_parse_and_default() {
    for b in [Backend::Obvhs, Backend::Embree] {
        assert_eq!(b.name().parse::<Backend>().unwrap(), b);
    }
    assert!(matches!(
        "optix".parse::<Backend>(),
        Err(TraceError::UnknownBackend(_))
    ));
    let compiled = Backend::compiled();
    assert!(compiled.contains(&Backend::Obvhs));
    assert_eq!(
        compiled.contains(&Backend::Embree),
        cfg!(feature = "embree")
    );
    assert_eq!(Backend::default(), compiled[0]);
    if !cfg!(feature = "embree") {
        let s = scene(
            vec![unit_triangle(0)],
            vec![instance(0, Affine3A::IDENTITY)],
        );
        assert!(matches!(
            Tracer::new(Backend::Embree, &s, GeometryMode::Primary),
            Err(TraceError::NotCompiled(Backend::Embree))
        ));
    }
}

#[test]
fn single_triangle_hit_miss_and_tmax() {
    let s = scene(
        vec![unit_triangle(0)],
        vec![instance(0, Affine3A::IDENTITY)],
    );
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        assert_eq!(t.backend(), backend);
        let hit = intersect(&t, down(0.25, 0.5, 2.0, 10.0)).expect("hit");
        assert!((hit.t - 2.0).abs() < 1e-5, "{backend}: {hit:?}");
        assert_eq!((hit.instance, hit.triangle), (0, 0));
        assert!(
            (hit.u - 0.25).abs() < 1e-5 && (hit.v - 0.5).abs() < 1e-5,
            "{hit:?}"
        );
        assert!(occluded(&t, down(0.25, 0.5, 2.0, 10.0)));
        // Outside the triangle, too short, pointing away, from below (back face counts).
        assert!(intersect(&t, down(0.8, 0.8, 2.0, 10.0)).is_none());
        assert!(!occluded(&t, down(0.8, 0.8, 2.0, 10.0)));
        assert!(intersect(&t, down(0.2, 0.2, 2.0, 1.9)).is_none());
        assert!(!occluded(&t, down(0.2, 0.2, 2.0, 1.9)));
        assert!(!occluded(
            &t,
            Ray::new(Vec3::new(0.2, 0.2, 2.0), Vec3::Z, 10.0)
        ));
        assert!(occluded(
            &t,
            Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 10.0)
        ));
        // Untraceable rays are misses, not panics.
        assert!(!occluded(
            &t,
            Ray::new(Vec3::splat(f32::NAN), Vec3::Z, 10.0)
        ));
        assert!(intersect(&t, Ray::new(Vec3::ZERO, Vec3::ZERO, 10.0)).is_none());
    }
}

#[test]
fn batches_match_single_queries_and_closest_wins() {
    // Three stacked planes at z = 0, 1, 2; rays from above hit the top one.
    let meshes = vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 5.0)];
    let instances = (0..3)
        .map(|k| instance(0, Affine3A::from_translation(Vec3::Z * k as f32)))
        .collect();
    let s = scene(meshes, instances);
    let rays: Vec<Ray> = (0..37)
        .map(|i| down(-4.0 + 0.2 * i as f32, 0.3, 5.0 - 0.05 * i as f32, 10.0))
        .collect();
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        let mut hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        t.intersect(&rays, &mut hits);
        t.occluded(&rays, &mut occ);
        for (i, r) in rays.iter().enumerate() {
            let h = hits[i].expect("hit");
            assert_eq!(h.instance, 2, "{backend}: ray {i}");
            assert!((h.t - (r.origin.z - 2.0)).abs() < 1e-5);
            // Alone, a ray takes Embree's single-ray kernel; in the batch, a packet kernel:
            // the same triangle, the distance equal within rounding (common::HIT_T_REL_TOL).
            let alone = intersect(&t, *r).expect("hit alone");
            assert_eq!((alone.instance, alone.triangle), (h.instance, h.triangle));
            assert!(
                same_t(alone.t, h.t),
                "{backend}: ray {i}: {alone:?} vs {h:?}"
            );
            assert!(occ[i]);
            assert!((hit_point(&s, &h) - (r.origin + r.dir * h.t)).length() < 1e-4);
        }
    }
}

#[test]
fn instance_transforms_are_honoured_and_updated() {
    let placed = Affine3A::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_rotation_z(0.4),
        Vec3::new(5.0, 0.0, 0.0),
    );
    let s = scene(
        vec![unit_cube()],
        vec![instance(0, Affine3A::IDENTITY), instance(0, placed)],
    );
    for backend in Backend::compiled() {
        let mut t = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        let a = intersect(&t, down(0.0, 0.0, 10.0, 100.0)).unwrap();
        assert_eq!(a.instance, 0);
        assert!((a.t - 9.5).abs() < 1e-4, "{backend}: {a:?}");
        // Scaled by 2: top face at z = 1.
        let b = intersect(&t, down(5.0, 0.3, 10.0, 100.0)).unwrap();
        assert_eq!(b.instance, 1);
        assert!((b.t - 9.0).abs() < 1e-4, "{backend}: {b:?}");
        let p = Vec3::new(5.0, 0.3, 1.0);
        assert!(
            (hit_point(&s, &b) - p).length() < 1e-4,
            "triangle index maps back"
        );
        assert!(!occluded(&t, down(2.5, 0.0, 10.0, 100.0)));

        // Move instance 1 away: the old spot is empty, the new one is hit.
        let moved = Affine3A::from_translation(Vec3::new(20.0, 0.0, -3.0));
        t.set_instance_transform(1, moved);
        t.commit();
        assert!(!occluded(&t, down(5.0, 0.3, 10.0, 100.0)));
        let c = intersect(&t, down(20.0, 0.1, 10.0, 100.0)).unwrap();
        assert_eq!(c.instance, 1);
        assert!((c.t - 12.5).abs() < 1e-4, "{backend}: {c:?}");
        // A singular transform hides the instance; a valid one brings it back.
        t.set_instance_transform(1, Affine3A::from_scale(Vec3::ZERO));
        t.commit();
        assert!(!occluded(&t, down(20.0, 0.1, 10.0, 100.0)));
        t.set_instance_transform(1, moved);
        t.set_instance_transform(99, moved); // out of range: ignored
        t.commit();
        assert!(occluded(&t, down(20.0, 0.1, 10.0, 100.0)));
    }
}

#[test]
fn deforming_mesh_updates_refit() {
    let cube = unit_cube();
    let s = scene(
        vec![cube.clone(), unit_triangle(0)],
        vec![
            instance(0, Affine3A::IDENTITY),
            instance(1, Affine3A::from_translation(Vec3::new(10.0, 0.0, 0.0))),
            instance(0, Affine3A::from_translation(Vec3::new(0.0, 10.0, 0.0))),
        ],
    );
    for backend in Backend::compiled() {
        let mut t = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        // Stretch the cube upwards twice: both instances follow, every time.
        for step in 1..=2 {
            let top = 0.5 + step as f32;
            let stretched: Vec<Vec3> = cube
                .positions
                .iter()
                .map(|p| {
                    if p.z > 0.0 {
                        Vec3::new(p.x, p.y, top)
                    } else {
                        *p
                    }
                })
                .collect();
            t.update_mesh_positions(0, &stretched).unwrap();
            t.commit();
            for (y, inst) in [(0.0, 0), (10.0, 2)] {
                let h = intersect(&t, down(0.1, y + 0.1, 10.0, 100.0)).unwrap();
                assert_eq!(h.instance, inst);
                assert!(
                    (h.t - (10.0 - top)).abs() < 1e-4,
                    "{backend} step {step}: {h:?}"
                );
            }
            assert!(
                occluded(&t, down(10.2, 0.2, 5.0, 100.0)),
                "other mesh untouched"
            );
        }
        assert!(matches!(
            t.update_mesh_positions(0, &[Vec3::ZERO]),
            Err(TraceError::PositionCount {
                mesh: 0,
                expected: 8,
                got: 1
            })
        ));
        assert!(matches!(
            t.update_mesh_positions(5, &[]),
            Err(TraceError::NoSuchMesh { mesh: 5, .. })
        ));
        let mut bad = cube.positions.clone();
        bad[3] = Vec3::splat(f32::INFINITY);
        assert!(matches!(
            t.update_mesh_positions(0, &bad),
            Err(TraceError::NonFinitePosition { mesh: 0, vertex: 3 })
        ));
    }
}

#[test]
fn occlusion_mode_skips_masked_meshes_without_shifting_ids() {
    // Mesh 0 is alpha-masked and lies above mesh 1; mesh 1 has two triangles.
    let masked = unit_triangle(1);
    let s = scene(
        vec![masked, quad(Vec3::ZERO, Vec3::X, Vec3::Y, 3.0)],
        vec![
            instance(0, Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0))),
            instance(1, Affine3A::IDENTITY),
        ],
    );
    let ray = down(0.2, 0.2, 5.0, 100.0);
    for backend in Backend::compiled() {
        let primary = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        let h = intersect(&primary, ray).unwrap();
        assert_eq!((h.instance, h.triangle), (0, 0));
        assert!((h.t - 4.0).abs() < 1e-5);
        let occl = Tracer::new(backend, &s, GeometryMode::Occlusion).unwrap();
        assert_eq!(occl.mode(), GeometryMode::Occlusion);
        let h = intersect(&occl, ray).unwrap();
        assert_eq!(h.instance, 1, "{backend}");
        assert!((h.t - 5.0).abs() < 1e-5);
        assert!((hit_point(&s, &h) - Vec3::new(0.2, 0.2, 0.0)).length() < 1e-5);
        // The other triangle of the quad, also by index.
        let h = intersect(&occl, down(-0.5, 0.5, 5.0, 100.0)).unwrap();
        assert!((hit_point(&s, &h) - Vec3::new(-0.5, 0.5, 0.0)).length() < 1e-5);
    }
}

#[test]
fn empty_and_invalid_scenes() {
    let empty = scene(vec![], vec![]);
    let no_triangles = scene(
        vec![common::mesh(vec![Vec3::ZERO], vec![], 0)],
        vec![instance(0, Affine3A::IDENTITY)],
    );
    for backend in Backend::compiled() {
        for s in [&empty, &no_triangles] {
            let t = Tracer::new(backend, s, GeometryMode::Occlusion).unwrap();
            assert!(!occluded(&t, down(0.0, 0.0, 1.0, 10.0)));
            assert!(intersect(&t, down(0.0, 0.0, 1.0, 10.0)).is_none());
        }
        let bad_index = scene(
            vec![common::mesh(vec![Vec3::ZERO, Vec3::X], vec![[0, 1, 2]], 0)],
            vec![],
        );
        assert!(matches!(
            Tracer::new(backend, &bad_index, GeometryMode::Primary),
            Err(TraceError::VertexIndex {
                mesh: 0,
                triangle: 0,
                vertex: 2,
                ..
            })
        ));
        let bad_mesh = scene(vec![], vec![instance(3, Affine3A::IDENTITY)]);
        assert!(matches!(
            Tracer::new(backend, &bad_mesh, GeometryMode::Primary),
            Err(TraceError::InstanceMesh { mesh: 3, .. })
        ));
        let bad_material = scene(vec![unit_triangle(7)], vec![]);
        assert!(matches!(
            Tracer::new(backend, &bad_material, GeometryMode::Occlusion),
            Err(TraceError::MeshMaterial { material: 7, .. })
        ));
    }
}

/// Embree counts what it holds (at least the copied vertices and triangles); obvhs does not.
#[test]
fn embree_counts_its_structure_bytes() {
    let s = scene(
        vec![unit_cube()],
        vec![
            instance(0, Affine3A::IDENTITY),
            instance(0, Affine3A::IDENTITY),
        ],
    );
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        match backend {
            Backend::Obvhs => assert_eq!(t.structure_bytes(), None),
            Backend::Embree => {
                let mesh = &s.meshes[0];
                let copied = 12 * (mesh.positions.len() + mesh.indices.len()) as u64;
                let bytes = t.structure_bytes().unwrap();
                assert!(bytes >= copied, "{bytes} < {copied}");
            }
        }
    }
}
