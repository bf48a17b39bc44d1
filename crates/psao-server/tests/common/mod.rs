//! Shared test fixtures: a small hand-made scene, views, and a client that mirrors grids.
#![allow(dead_code)]

use glam::{Affine3A, Quat, Vec3};
use psao_delta::{Codec, InstanceInfo, PaperCodec, Update};
use psao_points::InstanceGrid;
use psao_scene::{Camera, Instance, Material, Mesh, Scene};
use psao_server::{Server, ServerConfig, View};

/// A 4 m × 4 m floor at y = 0 with a unit box on it and a smaller rotated box.
pub fn scene() -> Scene {
    let floor = Mesh {
        name: "floor".into(),
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
    let instance = |mesh: usize, transform: Affine3A| Instance {
        mesh,
        node: None,
        transform,
        skin: None,
    };
    Scene {
        meshes: vec![floor, unit_box()],
        materials: vec![Material::default()],
        instances: vec![
            instance(0, Affine3A::IDENTITY),
            instance(1, Affine3A::from_translation(Vec3::new(0.0, 0.5, 0.0))),
            instance(
                1,
                Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.5),
                    Quat::from_rotation_y(0.5),
                    Vec3::new(1.2, 0.25, 1.2),
                ),
            ),
        ],
        ao_radius: 0.6,
        ..Default::default()
    }
}

/// A closed unit cube centred at the origin with outward flat normals.
fn unit_box() -> Mesh {
    let mut mesh = Mesh {
        name: "box".into(),
        ..Default::default()
    };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let (mut u, mut v) = (Vec3::ZERO, Vec3::ZERO);
            u[(axis + 1) % 3] = 0.5;
            v[(axis + 2) % 3] = 0.5;
            let c = n * 0.5;
            let base = mesh.positions.len() as u32;
            mesh.positions
                .extend([c - u - v, c + u - v, c + u + v, c - u + v]);
            mesh.normals.extend([n; 4]);
            // u × v = +n for the cyclic axis order, so (0, 1, 2) faces +n when sign > 0.
            if sign > 0.0 {
                mesh.indices
                    .extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
            } else {
                mesh.indices
                    .extend([[base, base + 2, base + 1], [base, base + 3, base + 2]]);
            }
        }
    }
    mesh
}

/// A small, fast configuration: 64 points per m², everything else default.
pub fn config() -> ServerConfig {
    ServerConfig {
        density: 64.0,
        seed: 5,
        ..Default::default()
    }
}

/// Looks at the whole scene.
pub fn wide_view() -> View {
    View {
        camera: Camera::look_at(Vec3::new(0.0, 3.0, 5.0), Vec3::ZERO, 60.0),
        aspect: 16.0 / 9.0,
    }
}

/// Looks at the floor's (−x, −z) corner only.
pub fn corner_view() -> View {
    View {
        camera: Camera::look_at(Vec3::new(-1.5, 1.5, 0.0), Vec3::new(-1.5, 0.0, -1.5), 20.0),
        aspect: 1.0,
    }
}

/// Looks at the floor's (+x, +z) corner only.
pub fn other_corner_view() -> View {
    View {
        camera: Camera::look_at(Vec3::new(1.7, 1.5, 0.0), Vec3::new(1.7, 0.0, 1.7), 15.0),
        aspect: 1.0,
    }
}

/// Step until nothing is traced any more (at most `limit` steps); returns the steps taken.
pub fn converge(server: &mut Server, views: &[View], limit: usize) -> usize {
    for i in 1..=limit {
        if server.step(views).traced_points == 0 {
            return i;
        }
    }
    panic!("not converged after {limit} steps");
}

/// A client's copy of the grids, fed through a codec.
pub struct Mirror {
    pub table: Vec<InstanceInfo>,
    pub grids: Vec<InstanceGrid>,
    pub codec: PaperCodec,
    pub bytes: usize,
}

impl Mirror {
    pub fn new(table: Vec<InstanceInfo>) -> Self {
        let grids = table.iter().map(|i| InstanceGrid::new(i.layout)).collect();
        Self {
            table,
            grids,
            codec: PaperCodec::new(),
            bytes: 0,
        }
    }

    /// Encode on the "server" side, decode here, apply; returns the decoded update.
    pub fn receive(&mut self, update: &Update) -> Update {
        let bytes = PaperCodec::new().encode(update);
        self.bytes += bytes.len();
        let u = self.codec.decode(&bytes).expect("decodes");
        if u.snapshot {
            self.grids = self
                .table
                .iter()
                .map(|i| InstanceGrid::new(i.layout))
                .collect();
        }
        for d in &u.instances {
            let g = &mut self.grids[d.instance as usize];
            for (b, bucket) in &d.buckets {
                g.set_bucket(*b as usize, *bucket).expect("valid bucket");
            }
            for (s, cell) in &d.cells {
                g.set_cell(*s, *cell).expect("valid cell");
            }
        }
        u
    }

    /// Assert the mirror equals the server's published grids bit for bit.
    pub fn assert_matches(&self, server: &Server) {
        for (i, mine) in self.grids.iter().enumerate() {
            let theirs = server.grid(i).unwrap();
            assert!(mine.buckets().eq(theirs.buckets()), "instance {i} buckets");
            let n = mine.slot_count().max(theirs.slot_count()) as u32;
            for s in 0..n {
                assert_eq!(*mine.cell(s), theirs.cell(s), "instance {i} cell slot {s}");
            }
        }
    }
}
