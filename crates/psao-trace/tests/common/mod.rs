//! Helpers shared by the integration tests: hand-made scenes, a minimal OBJ reader and a
//! counter-based random source. Not every test file uses every helper.
#![allow(dead_code)]

pub mod obj;

use glam::{Affine3A, Vec3};
use psao_scene::{AlphaMode, Instance, Material, Mesh, Scene};
use psao_trace::ao::hash64;

/// Relative tolerance for hit distances (and values computed from them) that a tracing
/// backend returns. Embree picks its kernels by the CPU's instruction set (SSE4, AVX2,
/// AVX-512), and their reciprocals and fused multiply-adds round differently, so `t` may
/// differ in its last bits from one CPU to the next (2.9999998 instead of 3.0 on an AVX2
/// machine). 1e-5 of the distance is about 80 ulps of an f32: far above such rounding, far
/// below the unit-sized geometry these tests tell apart.
pub const HIT_T_REL_TOL: f32 = 1e-5;

/// Whether two hit distances agree within [`HIT_T_REL_TOL`] of the larger.
pub fn same_t(a: f32, b: f32) -> bool {
    (a - b).abs() <= HIT_T_REL_TOL * a.abs().max(b.abs())
}

/// Asserts that a hit distance is `expected` within [`HIT_T_REL_TOL`], and that both are
/// misses or both hits.
#[track_caller]
pub fn assert_hit_t(actual: Option<f32>, expected: Option<f32>, what: &str) {
    let ok = match (actual, expected) {
        (Some(a), Some(e)) => same_t(a, e),
        (None, None) => true,
        _ => false,
    };
    assert!(ok, "{what}: hit distance {actual:?}, expected {expected:?}");
}

/// A mesh from positions and triangles, with the given material.
pub fn mesh(positions: Vec<Vec3>, indices: Vec<[u32; 3]>, material: usize) -> Mesh {
    Mesh {
        name: "test".into(),
        positions,
        indices,
        material,
        ..Default::default()
    }
}

/// An instance of `mesh` placed by `transform`.
pub fn instance(mesh: usize, transform: Affine3A) -> Instance {
    Instance {
        mesh,
        node: None,
        transform,
        skin: None,
    }
}

/// A scene with material 0 opaque and material 1 alpha-masked.
pub fn scene(meshes: Vec<Mesh>, instances: Vec<Instance>) -> Scene {
    Scene {
        meshes,
        materials: vec![
            Material::default(),
            Material {
                name: "masked".into(),
                alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                ..Default::default()
            },
        ],
        instances,
        ao_radius: psao_scene::DEFAULT_AO_RADIUS,
        ..Default::default()
    }
}

/// The triangle (0,0,0), (1,0,0), (0,1,0) in the plane z = 0.
pub fn unit_triangle(material: usize) -> Mesh {
    mesh(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        vec![[0, 1, 2]],
        material,
    )
}

/// The axis-aligned cube [-0.5, 0.5]³ with outward counter-clockwise faces.
pub fn unit_cube() -> Mesh {
    let p: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -0.5 } else { 0.5 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -0.5 } else { 0.5 },
            )
        })
        .collect();
    let quads = [
        [0, 4, 6, 2], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [2, 6, 7, 3], // +y
        [0, 2, 3, 1], // -z
        [4, 5, 7, 6], // +z
    ];
    let indices = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    mesh(p, indices, 0)
}

/// A square of half-size `half` in the plane through `center` spanned by `a` and `b`
/// (normal a × b).
pub fn quad(center: Vec3, a: Vec3, b: Vec3, half: f32) -> Mesh {
    let p = vec![
        center - a * half - b * half,
        center + a * half - b * half,
        center + a * half + b * half,
        center - a * half + b * half,
    ];
    mesh(p, vec![[0, 1, 2], [0, 2, 3]], 0)
}

/// A uniform float in [0, 1) for (seed, counter): stateless, so tests are reproducible.
pub fn uniform(seed: u64, counter: u64) -> f32 {
    (hash64(hash64(seed) ^ counter) >> 40) as f32 / (1u64 << 24) as f32
}

/// World position of a hit: barycentrics on the instance's mesh triangle, transformed.
pub fn hit_point(scene: &Scene, hit: &psao_trace::Hit) -> Vec3 {
    let inst = &scene.instances[hit.instance as usize];
    let m = &scene.meshes[inst.mesh];
    let [a, b, c] = m.indices[hit.triangle as usize].map(|i| m.positions[i as usize]);
    inst.transform
        .transform_point3(a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v)
}

/// Where the shared data lives, or `None` (with a note) when this checkout has none.
pub fn data_file(rel: &str) -> Option<std::path::PathBuf> {
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        .join(rel);
    if path.exists() {
        Some(path)
    } else {
        println!("note: {} is missing; skipping", path.display());
        None
    }
}

/// `count` AO rays of length `radius` from random surface points: triangles uniform over all
/// instanced triangles, uniform barycentrics, cosine directions about the face normal.
pub fn surface_ao_rays(
    scene: &Scene,
    count: usize,
    seed: u64,
    radius: f32,
) -> Vec<psao_trace::Ray> {
    use psao_trace::ao::{cosine_hemisphere, ray_offset};
    let mut starts = Vec::new(); // first global triangle of each instance
    let mut total = 0usize;
    for inst in &scene.instances {
        starts.push(total);
        total += scene.meshes[inst.mesh].indices.len();
    }
    let mut rays = Vec::with_capacity(count);
    let mut counter = 0u64;
    while rays.len() < count {
        let r: [f32; 5] = std::array::from_fn(|k| uniform(seed, counter * 5 + k as u64));
        counter += 1;
        let global = ((r[0] * total as f32) as usize).min(total - 1);
        let i = starts.partition_point(|&s| s <= global) - 1;
        let inst = &scene.instances[i];
        let m = &scene.meshes[inst.mesh];
        let [a, b, c] = m.indices[global - starts[i]]
            .map(|v| inst.transform.transform_point3(m.positions[v as usize]));
        let Some(n) = (b - a).cross(c - a).try_normalize() else {
            continue;
        };
        let s = r[1].sqrt();
        let p = a * (1.0 - s) + b * (s * (1.0 - r[2])) + c * (s * r[2]);
        rays.push(psao_trace::Ray::new(
            ray_offset(p, n),
            cosine_hemisphere(n, r[3], r[4]),
            radius,
        ));
    }
    rays
}

/// A stopwatch over this thread's CPU time (from `/proc/thread-self/schedstat`, so other
/// processes on a shared machine do not distort it), or wall time where that is unavailable.
pub struct CpuTimer {
    cpu_ns: Option<u64>,
    wall: std::time::Instant,
}

fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

impl CpuTimer {
    /// Starts timing.
    pub fn start() -> Self {
        Self {
            cpu_ns: thread_cpu_ns(),
            wall: std::time::Instant::now(),
        }
    }

    /// Seconds since start.
    pub fn seconds(&self) -> f64 {
        match (self.cpu_ns, thread_cpu_ns()) {
            (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

/// Traces `rays` in `order` (occlusion), returning the answers in input order and Mrays/s
/// (per second of this thread's CPU time).
pub fn timed_occluded(
    tracer: &psao_trace::Tracer,
    rays: &[psao_trace::Ray],
    order: &[u32],
) -> (Vec<bool>, f64) {
    let ordered: Vec<psao_trace::Ray> = order.iter().map(|&i| rays[i as usize]).collect();
    let mut out = vec![false; rays.len()];
    let timer = CpuTimer::start();
    tracer.occluded(&ordered, &mut out);
    let rate = rays.len() as f64 / timer.seconds() / 1e6;
    let mut result = vec![false; rays.len()];
    for (&i, o) in order.iter().zip(out) {
        result[i as usize] = o;
    }
    (result, rate)
}

/// Like [`timed_occluded`] for closest hits.
pub fn timed_intersect(
    tracer: &psao_trace::Tracer,
    rays: &[psao_trace::Ray],
    order: &[u32],
) -> (Vec<Option<psao_trace::Hit>>, f64) {
    let ordered: Vec<psao_trace::Ray> = order.iter().map(|&i| rays[i as usize]).collect();
    let mut out = vec![None; rays.len()];
    let timer = CpuTimer::start();
    tracer.intersect(&ordered, &mut out);
    let rate = rays.len() as f64 / timer.seconds() / 1e6;
    let mut result = vec![None; rays.len()];
    for (&i, o) in order.iter().zip(out) {
        result[i as usize] = o;
    }
    (result, rate)
}
