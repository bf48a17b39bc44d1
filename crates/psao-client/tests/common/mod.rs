//! Test-only helpers: hand-made scenes, grids built with psao-points, and updates built the
//! way a server would (snapshot = every non-empty bucket and cell, delta = what changed).
#![allow(dead_code)]

use glam::{Affine3A, Quat, Vec3};
use psao_delta::{compact_bucket, compact_cell, InstanceDelta, InstanceInfo, Update};
use psao_points::{
    generate_instance_points, Bucket, Cell, GenerateParams, GridLayout, InstanceGrid,
    InstancePoints, PointLoc,
};
use psao_scene::{Camera, Instance, Material, Mesh, Scene};

/// Append a quad (a, b, c, d counter-clockwise seen from the front) with flat normal.
fn push_quad(mesh: &mut Mesh, q: [Vec3; 4]) {
    let n = (q[1] - q[0]).cross(q[2] - q[0]).normalize();
    let base = mesh.positions.len() as u32;
    mesh.positions.extend_from_slice(&q);
    mesh.normals.extend_from_slice(&[n; 4]);
    mesh.indices.push([base, base + 1, base + 2]);
    mesh.indices.push([base, base + 2, base + 3]);
}

/// The square y = 0, x and z in [−half, half], facing +y.
pub fn plane(half: f32) -> Mesh {
    let mut mesh = Mesh {
        name: "plane".into(),
        ..Default::default()
    };
    let h = half;
    push_quad(
        &mut mesh,
        [
            Vec3::new(-h, 0.0, -h),
            Vec3::new(-h, 0.0, h),
            Vec3::new(h, 0.0, h),
            Vec3::new(h, 0.0, -h),
        ],
    );
    mesh
}

/// The unit cube [−0.5, 0.5]³ with outward faces.
pub fn cube() -> Mesh {
    let mut mesh = Mesh {
        name: "cube".into(),
        ..Default::default()
    };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::from_array(std::array::from_fn(|k| if k == axis { sign } else { 0.0 }));
            // Two tangents with t × b = n.
            let t = Vec3::from_array(std::array::from_fn(|k| {
                if k == (axis + 1) % 3 {
                    1.0
                } else {
                    0.0
                }
            }));
            let b = n.cross(t);
            let c = n * 0.5;
            push_quad(
                &mut mesh,
                [
                    c - 0.5 * t - 0.5 * b,
                    c + 0.5 * t - 0.5 * b,
                    c + 0.5 * t + 0.5 * b,
                    c - 0.5 * t + 0.5 * b,
                ],
            );
        }
    }
    mesh
}

/// A grey plane of half-size `half` and `cubes` red unit cubes standing on it in a row.
pub fn scene(half: f32, cubes: usize) -> Scene {
    let grey = Material {
        name: "grey".into(),
        base_color: glam::Vec4::new(0.7, 0.7, 0.7, 1.0),
        ..Default::default()
    };
    let red = Material {
        name: "red".into(),
        base_color: glam::Vec4::new(0.8, 0.2, 0.1, 1.0),
        ..Default::default()
    };
    let mut cube_mesh = cube();
    cube_mesh.material = 1;
    let mut instances = vec![Instance {
        mesh: 0,
        node: None,
        transform: Affine3A::IDENTITY,
        skin: None,
    }];
    for k in 0..cubes {
        let x = (k as f32 - (cubes as f32 - 1.0) * 0.5) * 1.8;
        instances.push(Instance {
            mesh: 1,
            node: None,
            transform: Affine3A::from_rotation_translation(
                Quat::from_rotation_y(0.3 + k as f32),
                Vec3::new(x, 0.5, -0.5 * k as f32),
            ),
            skin: None,
        });
    }
    Scene {
        meshes: vec![plane(half), cube_mesh],
        materials: vec![grey, red],
        instances,
        ..Default::default()
    }
}

/// A camera looking down at the origin from the front (+z) and above.
pub fn camera() -> Camera {
    Camera::look_at(Vec3::new(0.0, 3.0, 5.0), Vec3::new(0.0, 0.0, -0.5), 50.0)
}

/// Points of every instance of `scene` at `density`.
pub fn points(scene: &Scene, density: f32, seed: u64) -> Vec<InstancePoints> {
    scene
        .instances
        .iter()
        .enumerate()
        .map(|(i, inst)| {
            let mesh = &scene.meshes[inst.mesh];
            generate_instance_points(
                mesh,
                &scene.materials[mesh.material],
                &inst.transform,
                &GenerateParams {
                    density,
                    seed: seed + i as u64,
                },
                None,
            )
            .unwrap()
        })
        .collect()
}

/// A server-side grid per instance with AO `ao(local position)` per point, and the point
/// locations.
pub fn grids(
    points: &[InstancePoints],
    ao: impl Fn(Vec3) -> f32,
) -> Vec<(InstanceGrid, Vec<Option<PointLoc>>)> {
    points
        .iter()
        .map(|pts| {
            let layout = GridLayout::for_points(pts).unwrap();
            InstanceGrid::build(
                layout,
                pts.points
                    .iter()
                    .map(|p| (p.position, p.normal, ao(p.position))),
            )
        })
        .collect()
}

/// The instance table a server would send.
pub fn table(points: &[InstancePoints], grids: &[InstanceGrid]) -> Vec<InstanceInfo> {
    points
        .iter()
        .zip(grids)
        .map(|(p, g)| InstanceInfo {
            layout: *g.layout(),
            poisson_radius: p.poisson_radius_local,
            point_count: p.points.len() as u32,
        })
        .collect()
}

/// Every instance transform of `scene`.
pub fn transforms(scene: &Scene) -> Vec<(u32, Affine3A)> {
    scene
        .instances
        .iter()
        .enumerate()
        .map(|(i, inst)| (i as u32, inst.transform))
        .collect()
}

/// A snapshot: every non-empty bucket and cell of every grid.
pub fn snapshot(frame: u64, grids: &[InstanceGrid], transforms: Vec<(u32, Affine3A)>) -> Update {
    let empty: Vec<InstanceGrid> = grids
        .iter()
        .map(|g| InstanceGrid::new(*g.layout()))
        .collect();
    Update {
        snapshot: true,
        ..delta(frame, &empty, grids, transforms)
    }
}

/// A delta: the buckets and cells of `cur` that differ from `prev` (same layouts), compacted
/// as a server sends them.
pub fn delta(
    frame: u64,
    prev: &[InstanceGrid],
    cur: &[InstanceGrid],
    transforms: Vec<(u32, Affine3A)>,
) -> Update {
    let instances = prev
        .iter()
        .zip(cur)
        .enumerate()
        .map(|(i, (p, c))| {
            let buckets: Vec<(u32, Bucket)> = c
                .buckets()
                .enumerate()
                .filter(|(b, bucket)| p.bucket(*b) != *bucket)
                .map(|(b, bucket)| (b as u32, compact_bucket(&bucket)))
                .collect();
            let cells: Vec<(u32, Cell)> = c
                .cells()
                .enumerate()
                .filter(|&(s, cell)| p.cell(s as u32) != cell)
                .map(|(s, cell)| (s as u32, compact_cell(cell)))
                .collect();
            InstanceDelta {
                instance: i as u32,
                buckets,
                cells,
                lights: Vec::new(),
            }
        })
        .filter(|d| !d.buckets.is_empty() || !d.cells.is_empty())
        .collect();
    Update {
        frame,
        snapshot: false,
        transforms,
        instances,
    }
}

/// `update` with irradiance records for every cell: record `k` of a cell holds
/// `light(position of its point k)` (zeros past the cell's points), as a lit server sends them.
pub fn with_lights(
    mut update: Update,
    grids: &[InstanceGrid],
    light: impl Fn(Vec3) -> Vec3,
) -> Update {
    for d in &mut update.instances {
        let layout = *grids[d.instance as usize].layout();
        d.lights = d
            .cells
            .iter()
            .map(|(slot, cell)| {
                let coord = grids[d.instance as usize]
                    .buckets()
                    .flat_map(|b| b.entries)
                    .find(|e| e.key != 0 && e.slot == *slot)
                    .and_then(|e| layout.coord_of_id(e.key - 1));
                std::array::from_fn(|k| match (coord, cell.points[k]) {
                    (Some(c), bits) if psao_points::pack::is_valid(bits) => {
                        psao_points::irradiance::pack_rgb9e5(light(layout.unpack_position(c, bits)))
                    }
                    _ => 0,
                })
            })
            .collect();
    }
    update
}

/// Assert that the client mirrors `grids` exactly (up to compaction) and hashes alike.
pub fn assert_mirrors(state: &psao_client::ClientState, grids: &[InstanceGrid]) {
    for (i, g) in grids.iter().enumerate() {
        let mirror = state.grid(i).expect("grid");
        assert_eq!(mirror.layout(), g.layout(), "instance {i} layout");
        let buckets = g.buckets().map(|b| compact_bucket(&b));
        let cells = g.cells().map(compact_cell);
        assert!(mirror.buckets().eq(buckets), "instance {i} buckets differ");
        assert!(mirror.cells().eq(cells), "instance {i} cells differ");
    }
    let server_hash = psao_client::state_hash_of(grids.iter().map(Some));
    assert_eq!(state.state_hash(), server_hash);
}
