//! The burial test: points inside closed geometry are dropped before the grids are built,
//! points on open faces are kept, deterministically for a seed, on every backend.

use glam::{Affine3A, Vec3};
use psao_scene::builtin::shapes::cuboid;
use psao_scene::{Instance, Material, Mesh, Scene};
use psao_server::{Server, ServerConfig};
use psao_trace::Backend;

/// A single-sided square of side `size` in the plane y = 0 facing +y, centred at the origin.
fn square(size: f32) -> Mesh {
    let h = size * 0.5;
    Mesh {
        name: "square".into(),
        positions: vec![
            Vec3::new(-h, 0.0, -h),
            Vec3::new(h, 0.0, -h),
            Vec3::new(h, 0.0, h),
            Vec3::new(-h, 0.0, h),
        ],
        normals: vec![Vec3::Y; 4],
        indices: vec![[0, 2, 1], [0, 3, 2]],
        ..Default::default()
    }
}

/// Instance 0: an open 4 m floor; 1: a closed cube floating at y = 2; 2: a 0.6 m square
/// sealed inside the cube; 3: the same square, double-sided material, inside a second cube
/// (4) — its both sides are buried too.
fn scene() -> Scene {
    let place = |mesh: usize, at: Vec3| Instance {
        mesh,
        node: None,
        transform: Affine3A::from_translation(at),
        skin: None,
    };
    let mut inner_two_sided = square(0.6);
    inner_two_sided.material = 1;
    Scene {
        meshes: vec![
            square(4.0),
            cuboid(Vec3::splat(0.5)),
            square(0.6),
            inner_two_sided,
        ],
        materials: vec![
            Material::default(),
            Material {
                double_sided: true,
                ..Material::default()
            },
        ],
        instances: vec![
            place(0, Vec3::ZERO),
            place(1, Vec3::new(0.0, 2.0, 0.0)),
            place(2, Vec3::new(0.0, 2.0, 0.0)),
            place(3, Vec3::new(1.5, 2.0, 0.0)),
            place(1, Vec3::new(1.5, 2.0, 0.0)),
        ],
        ao_radius: 0.6,
        ..Default::default()
    }
}

fn config(backend: Backend, cull_buried: bool) -> ServerConfig {
    ServerConfig {
        density: 256.0,
        seed: 3,
        backend,
        cull_buried,
        ..ServerConfig::default()
    }
}

fn counts(server: &Server) -> Vec<usize> {
    (0..server.instance_count())
        .map(|i| server.points(i).count())
        .collect()
}

#[test]
fn points_inside_closed_geometry_are_dropped_and_open_faces_kept() {
    let scene = scene();
    for backend in Backend::compiled() {
        let all = Server::new(&scene, config(backend, false)).unwrap();
        let culled = Server::new(&scene, config(backend, true)).unwrap();
        let (all_n, culled_n) = (counts(&all), counts(&culled));
        assert_eq!(all.buried_points(), 0);
        assert!(all_n[2] > 50 && all_n[3] > 100, "{all_n:?}");
        // The sealed squares lose every point (both sides of the double-sided one).
        assert_eq!(culled_n[2], 0, "{backend:?} {culled_n:?}");
        assert_eq!(culled_n[3], 0, "{backend:?} {culled_n:?}");
        // The open floor and the cubes' outer faces keep every point.
        for i in [0, 1, 4] {
            assert_eq!(culled_n[i], all_n[i], "{backend:?} instance {i}");
        }
        assert_eq!(culled.buried_points(), all_n[2] + all_n[3]);
        let total = |n: &[usize]| n.iter().sum::<usize>();
        assert_eq!(total(&culled_n) + culled.buried_points(), total(&all_n));
        // Fewer points compete for cell capacity, so no more are stored than before.
        assert!(culled.point_count() <= all.point_count());
    }
}

#[test]
fn burial_is_deterministic_per_seed() {
    let scene = scene();
    let backend = Backend::default();
    let a = Server::new(&scene, config(backend, true)).unwrap();
    let b = Server::new(&scene, config(backend, true)).unwrap();
    assert_eq!(a.buried_points(), b.buried_points());
    for i in 0..a.instance_count() {
        let pa: Vec<_> = a.points(i).map(|p| p.position).collect();
        let pb: Vec<_> = b.points(i).map(|p| p.position).collect();
        assert_eq!(pa, pb, "instance {i}");
    }
}
