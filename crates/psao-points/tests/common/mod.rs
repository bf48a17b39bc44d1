//! Test-only helpers: a minimal OBJ reader (`o`, `v`, `f`) and generated meshes.
#![allow(dead_code)]

use std::path::PathBuf;

use glam::{Affine3A, Vec3};
use psao_points::{generate_instance_points, GenerateParams, InstancePoints};
use psao_scene::{Material, Mesh};

/// `/work/shared/data` relative to this crate, or `None` (with a note) when missing.
pub fn data_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("note: {} not found, skipping", dir.display());
        None
    }
}

/// Read the Dabrovic Sponza OBJ as one mesh per `o` object, at most `max_triangles` in total.
pub fn sponza(max_triangles: usize) -> Option<Vec<Mesh>> {
    let path = data_dir()?.join("scenes/dabrovic_sponza.obj");
    let text = std::fs::read_to_string(&path).ok()?;
    Some(read_obj(&text, max_triangles))
}

/// Parse `o`, `v` and `f` lines (polygons fan-triangulated, `i`, `i/j`, `i//k`, `i/j/k` and
/// negative indices). Vertices are not shared; normals are the flat face normals.
pub fn read_obj(text: &str, max_triangles: usize) -> Vec<Mesh> {
    let mut positions: Vec<Vec3> = Vec::new();
    let mut meshes: Vec<Mesh> = Vec::new();
    let mut total = 0usize;
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("o") | Some("g") => meshes.push(Mesh {
                name: it.next().unwrap_or("").to_string(),
                ..Default::default()
            }),
            Some("v") => {
                let c: Vec<f32> = it.take(3).map(|t| t.parse().unwrap()).collect();
                positions.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                if total >= max_triangles {
                    break;
                }
                let idx: Vec<usize> = it
                    .map(|t| {
                        let i: i64 = t.split('/').next().unwrap().parse().unwrap();
                        if i < 0 {
                            (positions.len() as i64 + i) as usize
                        } else {
                            (i - 1) as usize
                        }
                    })
                    .collect();
                if meshes.is_empty() {
                    meshes.push(Mesh::default());
                }
                let mesh = meshes.last_mut().unwrap();
                for k in 1..idx.len() - 1 {
                    let tri = [positions[idx[0]], positions[idx[k]], positions[idx[k + 1]]];
                    push_triangle(mesh, tri);
                    total += 1;
                }
            }
            _ => {}
        }
    }
    meshes.retain(|m| !m.indices.is_empty());
    meshes
}

/// Append a triangle with unshared vertices and its face normal.
pub fn push_triangle(mesh: &mut Mesh, tri: [Vec3; 3]) {
    let n = (tri[1] - tri[0])
        .cross(tri[2] - tri[0])
        .normalize_or(Vec3::Z);
    let base = mesh.positions.len() as u32;
    mesh.positions.extend_from_slice(&tri);
    mesh.normals.extend_from_slice(&[n; 3]);
    mesh.indices.push([base, base + 1, base + 2]);
}

/// An axis-aligned plane z = `z` over [0, size]² split into `cells`² quads, normal +Z.
pub fn plane(size: f32, cells: u32, z: f32) -> Mesh {
    let mut mesh = Mesh {
        name: "plane".into(),
        ..Default::default()
    };
    let step = size / cells as f32;
    for i in 0..cells {
        for j in 0..cells {
            let (x0, y0) = (i as f32 * step, j as f32 * step);
            let a = Vec3::new(x0, y0, z);
            let b = Vec3::new(x0 + step, y0, z);
            let c = Vec3::new(x0 + step, y0 + step, z);
            let d = Vec3::new(x0, y0 + step, z);
            push_triangle(&mut mesh, [a, b, c]);
            push_triangle(&mut mesh, [a, c, d]);
        }
    }
    mesh
}

/// Total triangle area of a mesh (local units).
pub fn area(mesh: &Mesh) -> f64 {
    mesh.indices
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            0.5 * f64::from((b - a).cross(c - a).length())
        })
        .sum()
}

/// Smallest distance between any two points (grid accelerated), ignoring exact duplicates
/// when `skip_identical` (the two sides of a double-sided point).
pub fn min_distance(points: &[Vec3], cell: f32, skip_identical: bool) -> f32 {
    use std::collections::HashMap;
    let key = |p: Vec3| (p / cell).floor().as_ivec3();
    let mut map: HashMap<glam::IVec3, Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        map.entry(key(*p)).or_default().push(i);
    }
    let mut best = f32::INFINITY;
    for (i, p) in points.iter().enumerate() {
        let k = key(*p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = map.get(&(k + glam::IVec3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for &j in list {
                        if j <= i || (skip_identical && points[j] == *p) {
                            continue;
                        }
                        best = best.min(p.distance(points[j]));
                    }
                }
            }
        }
    }
    best
}

/// Uniform points of `mesh` (default material, identity transform, no alpha test).
pub fn uniform_points(mesh: &Mesh, params: &GenerateParams) -> InstancePoints {
    generate_instance_points(
        mesh,
        &Material::default(),
        &Affine3A::IDENTITY,
        params,
        None,
    )
    .unwrap()
}
