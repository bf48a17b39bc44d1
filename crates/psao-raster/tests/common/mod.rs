//! Test helpers: scenes from triangle lists, screen-space placement, and a brute-force-free
//! reference ray caster (a small median-split BVH).
#![allow(dead_code)]

use glam::{DVec3, Vec3};
use psao_scene::{Camera, Mesh, Scene};

/// A scene with one mesh (flat normals, vertices not shared) and one identity instance.
pub fn scene_of(tris: &[[Vec3; 3]]) -> Scene {
    let mut mesh = Mesh {
        name: "test".into(),
        ..Mesh::default()
    };
    for t in tris {
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        let base = mesh.positions.len() as u32;
        mesh.positions.extend_from_slice(t);
        mesh.normals.extend_from_slice(&[n; 3]);
        mesh.indices.push([base, base + 1, base + 2]);
    }
    Scene::of_meshes(vec![mesh])
}

/// Camera basis (forward, right, up) as the camera defines it.
pub fn basis(cam: &Camera) -> (Vec3, Vec3, Vec3) {
    let f = (cam.target - cam.position).normalize();
    let r = f.cross(cam.up).normalize();
    (f, r, r.cross(f))
}

/// World point seen at continuous pixel (`px`, `py`) at view depth `depth`.
pub fn unproject(cam: &Camera, px: f64, py: f64, depth: f64, w: u32, h: u32) -> Vec3 {
    let (f, r, u) = basis(cam);
    let (f, r, u) = (f.as_dvec3(), r.as_dvec3(), u.as_dvec3());
    let tan = (cam.fov_y as f64 * 0.5).tan();
    let aspect = w as f64 / h as f64;
    let x = (2.0 * px / w as f64 - 1.0) * tan * aspect;
    let y = (1.0 - 2.0 * py / h as f64) * tan;
    (cam.position.as_dvec3() + depth * (f + x * r + y * u)).as_vec3()
}

/// Ray through the centre of pixel (x, y), scaled to unit length along the view axis.
pub fn pixel_ray(cam: &Camera, x: u32, y: u32, w: u32, h: u32) -> DVec3 {
    let d = cam
        .ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h)
        .as_dvec3();
    let f = basis(cam).0.as_dvec3();
    d / d.dot(f)
}

/// Ray/triangle intersection in f64 (edges inclusive): (t, u, v).
pub fn intersect(o: DVec3, d: DVec3, t: [Vec3; 3]) -> Option<(f64, f64, f64)> {
    let [p0, p1, p2] = t.map(|p| p.as_dvec3());
    let (e1, e2) = (p1 - p0, p2 - p0);
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det == 0.0 {
        return None;
    }
    let s = o - p0;
    let u = s.dot(pv) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let tt = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0).then_some((tt, u, v))
}

/// Reads `v` and `f` lines of an OBJ file into one flat-shaded mesh (polygons fanned).
pub fn load_obj(path: &str) -> Option<Vec<[Vec3; 3]>> {
    let text = std::fs::read_to_string(path).ok()?;
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it.take(3).map(|s| s.parse().unwrap()).collect();
                verts.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let idx: Vec<usize> = it
                    .map(|s| {
                        let i: i64 = s.split('/').next().unwrap().parse().unwrap();
                        if i < 0 {
                            (verts.len() as i64 + i) as usize
                        } else {
                            i as usize - 1
                        }
                    })
                    .collect();
                for k in 1..idx.len() - 1 {
                    tris.push([verts[idx[0]], verts[idx[k]], verts[idx[k + 1]]]);
                }
            }
            _ => {}
        }
    }
    Some(tris)
}

/// A binary BVH over triangles, for reference primary visibility.
pub struct Bvh {
    tris: Vec<[Vec3; 3]>,
    order: Vec<u32>,
    nodes: Vec<Node>,
}

struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: first index into `order`; inner: index of the left child (right = left + 1).
    start: u32,
    /// Leaf: triangle count; inner: 0.
    count: u32,
}

/// The nearest and second-nearest hits along a ray: (t, triangle).
#[derive(Clone, Copy, Debug)]
pub struct Hits {
    pub first: Option<(f64, u32)>,
    pub second: Option<(f64, u32)>,
}

impl Bvh {
    pub fn new(tris: Vec<[Vec3; 3]>) -> Self {
        let mut bvh = Self {
            order: (0..tris.len() as u32).collect(),
            tris,
            nodes: Vec::new(),
        };
        bvh.nodes.push(Node {
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            start: 0,
            count: 0,
        });
        bvh.build(0, 0, bvh.order.len());
        bvh
    }

    fn centroid(&self, i: u32) -> Vec3 {
        let t = self.tris[i as usize];
        (t[0] + t[1] + t[2]) / 3.0
    }

    fn build(&mut self, node: usize, start: usize, end: usize) {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let (mut clo, mut chi) = (lo, hi);
        for &i in &self.order[start..end] {
            for p in self.tris[i as usize] {
                lo = lo.min(p);
                hi = hi.max(p);
            }
            let c = self.centroid(i);
            clo = clo.min(c);
            chi = chi.max(c);
        }
        self.nodes[node].lo = lo;
        self.nodes[node].hi = hi;
        let ext = chi - clo;
        if end - start <= 4 || ext.max_element() <= 0.0 {
            self.nodes[node].start = start as u32;
            self.nodes[node].count = (end - start) as u32;
            return;
        }
        let axis = ext.max_position();
        let mid = (start + end) / 2;
        let mut slice = std::mem::take(&mut self.order);
        slice[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            self.centroid(a)[axis].total_cmp(&self.centroid(b)[axis])
        });
        self.order = slice;
        let left = self.nodes.len();
        for _ in 0..2 {
            self.nodes.push(Node {
                lo: Vec3::ZERO,
                hi: Vec3::ZERO,
                start: 0,
                count: 0,
            });
        }
        self.nodes[node].start = left as u32;
        self.build(left, start, mid);
        self.build(left + 1, mid, end);
    }

    /// Two nearest hits with t in [tmin, ∞) of the ray o + t·d.
    pub fn two_nearest(&self, o: DVec3, d: DVec3, tmin: f64) -> Hits {
        let mut hits = Hits {
            first: None,
            second: None,
        };
        let inv = d.recip();
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            let limit = hits.second.map_or(f64::INFINITY, |h| h.0);
            let t0 = (node.lo.as_dvec3() - o) * inv;
            let t1 = (node.hi.as_dvec3() - o) * inv;
            let near = t0.min(t1).max_element();
            let far = t0.max(t1).min_element();
            if !(near <= far * (1.0 + 1e-9) + 1e-9 && far >= tmin && near <= limit) {
                continue;
            }
            if node.count == 0 {
                stack.push(node.start as usize);
                stack.push(node.start as usize + 1);
                continue;
            }
            for &i in &self.order[node.start as usize..(node.start + node.count) as usize] {
                let Some((t, _, _)) = intersect(o, d, self.tris[i as usize]) else {
                    continue;
                };
                if t < tmin {
                    continue;
                }
                let h = Some((t, i));
                match hits.first {
                    Some(f) if t >= f.0 => {
                        if hits.second.is_none_or(|s| t < s.0) {
                            hits.second = h;
                        }
                    }
                    _ => {
                        hits.second = hits.first;
                        hits.first = h;
                    }
                }
            }
        }
        hits
    }
}

/// Folder of the shared test data, `None` (with a note) when it is missing.
pub fn data_dir() -> Option<std::path::PathBuf> {
    let dir =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("note: {} missing, skipping", dir.display());
        None
    }
}
