//! A minimal test-only OBJ reader: `o`, `v` and `f` lines into one mesh (and one identity
//! instance) per object; polygons are fanned into triangles; everything else is ignored.

use std::collections::HashMap;
use std::path::Path;

use glam::{Affine3A, Vec3};
use psao_scene::Scene;

/// Reads the geometry of an OBJ file.
pub fn load(path: &Path) -> Scene {
    let text = std::fs::read_to_string(path).expect("readable OBJ");
    let mut vertices: Vec<Vec3> = Vec::new();
    let mut meshes = Vec::new();
    // Current object: positions, triangles, global → local vertex map.
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    let mut local: HashMap<usize, u32> = HashMap::new();
    let mut flush = |positions: &mut Vec<Vec3>,
                     indices: &mut Vec<[u32; 3]>,
                     local: &mut HashMap<usize, u32>| {
        if !indices.is_empty() {
            meshes.push(super::mesh(
                std::mem::take(positions),
                std::mem::take(indices),
                0,
            ));
        }
        positions.clear();
        local.clear();
    };
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("o") | Some("g") => flush(&mut positions, &mut indices, &mut local),
            Some("v") => {
                let c: Vec<f32> = words.take(3).map(|w| w.parse().expect("number")).collect();
                vertices.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let face: Vec<u32> = words
                    .map(|w| {
                        let i: i64 = w.split('/').next().unwrap().parse().expect("index");
                        let global = if i < 0 {
                            vertices.len() as i64 + i
                        } else {
                            i - 1
                        } as usize;
                        *local.entry(global).or_insert_with(|| {
                            positions.push(vertices[global]);
                            positions.len() as u32 - 1
                        })
                    })
                    .collect();
                for k in 1..face.len().saturating_sub(1) {
                    indices.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    flush(&mut positions, &mut indices, &mut local);
    let instances = (0..meshes.len())
        .map(|m| super::instance(m, Affine3A::IDENTITY))
        .collect();
    super::scene(meshes, instances)
}
