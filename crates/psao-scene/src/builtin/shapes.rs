//! Procedural closed solids with outward counter-clockwise winding: boxes, surfaces of
//! revolution (cylinders, spheres, vases), stairs and arcades.
//!
//! Every shape is built in its own local frame (y up) with material 0; place it with an
//! instance transform or merge several with [`append`].

use glam::{Affine3A, Vec2, Vec3};

use crate::model::Mesh;

/// Collects vertices and triangles while a shape is generated.
#[derive(Default)]
struct Builder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
}

impl Builder {
    fn vertex(&mut self, position: Vec3, normal: Vec3) -> u32 {
        self.positions.push(position);
        self.normals.push(normal.normalize());
        (self.positions.len() - 1) as u32
    }

    /// A flat convex polygon fanned from its first vertex, wound so that it faces `normal`.
    fn flat_polygon(&mut self, corners: &[Vec3], normal: Vec3) {
        let mut newell = Vec3::ZERO;
        for (i, a) in corners.iter().enumerate() {
            newell += a.cross(corners[(i + 1) % corners.len()]);
        }
        let base = self.positions.len() as u32;
        for &c in corners {
            self.vertex(c, normal);
        }
        let flip = newell.dot(normal) < 0.0;
        for i in 1..corners.len() as u32 - 1 {
            if flip {
                self.indices.push([base, base + i + 1, base + i]);
            } else {
                self.indices.push([base, base + i, base + i + 1]);
            }
        }
    }

    fn finish(self, name: &str) -> Mesh {
        Mesh {
            name: name.to_owned(),
            positions: self.positions,
            normals: self.normals,
            indices: self.indices,
            ..Mesh::default()
        }
    }
}

/// An axis-aligned box centred at the origin with the given half extents, flat normals.
pub fn cuboid(half: Vec3) -> Mesh {
    let mut b = Builder::default();
    let corner = |sx: f32, sy: f32, sz: f32| Vec3::new(sx * half.x, sy * half.y, sz * half.z);
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut normal = Vec3::ZERO;
            normal[axis] = sign;
            // The two other axes span the face.
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let quad: Vec<Vec3> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .iter()
                .map(|&(su, sv)| {
                    let mut s = [0.0f32; 3];
                    s[axis] = sign;
                    s[u] = su;
                    s[v] = sv;
                    corner(s[0], s[1], s[2])
                })
                .collect();
            b.flat_polygon(&quad, normal);
        }
    }
    b.finish("box")
}

/// A surface of revolution about the y axis. `profile` holds (radius, height) points; walking
/// along it, the outward side is to the right (so a solid's profile runs from the axis at the
/// bottom, outwards, up, and back to the axis at the top). Along the circle the normals are
/// smooth; along the profile, neighbouring bands share an averaged normal when their normals
/// differ by less than `crease_deg`, and keep their own flat normal otherwise. Profile points on
/// the axis (radius 0) close the surface without degenerate triangles; repeated consecutive
/// points are skipped. `segments` (at least 3) is the number of segments around.
pub fn lathe(profile: &[Vec2], segments: u32, crease_deg: f32) -> Mesh {
    let mut b = Builder::default();
    let segments = segments.max(3);
    let band_normal = |i: usize| {
        let d = profile[i + 1] - profile[i];
        Vec2::new(d.y, -d.x).normalize()
    };
    let bands = profile.len().saturating_sub(1);
    let cos_crease = crease_deg.to_radians().cos();
    // Normal (radial, vertical) of band `i` at its end `end` (0 = start, 1 = finish).
    let end_normal = |i: usize, end: usize| -> Vec2 {
        let own = band_normal(i);
        let point = profile[i + end];
        let neighbour = if end == 0 {
            i.checked_sub(1)
        } else {
            Some(i + 1).filter(|&j| j < bands)
        };
        match neighbour {
            Some(j) if band_normal(j).dot(own) > cos_crease => (band_normal(j) + own).normalize(),
            None if crease_deg > 0.0 && point.x == 0.0 => Vec2::new(0.0, own.y.signum()),
            _ => own,
        }
    };
    let angle = |s: u32| (s % segments) as f32 * std::f32::consts::TAU / segments as f32;
    for i in 0..bands {
        let (p0, p1) = (profile[i], profile[i + 1]);
        if p0 == p1 {
            continue;
        }
        let (n0, n1) = (end_normal(i, 0), end_normal(i, 1));
        let base = b.positions.len() as u32;
        for s in 0..=segments {
            let (sin, cos) = angle(s).sin_cos();
            for (p, n) in [(p0, n0), (p1, n1)] {
                b.vertex(
                    Vec3::new(p.x * sin, p.y, p.x * cos),
                    Vec3::new(n.x * sin, n.y, n.x * cos),
                );
            }
        }
        for s in 0..segments {
            let (a0, a1) = (base + 2 * s, base + 2 * s + 1);
            let (b0, b1) = (a0 + 2, a1 + 2);
            if p0.x > 0.0 {
                b.indices.push([a0, b0, b1]);
            }
            if p1.x > 0.0 {
                b.indices.push([a0, b1, a1]);
            }
        }
    }
    b.finish("lathe")
}

/// A closed cylinder of the given radius standing on y = 0 up to y = `height`.
pub fn cylinder(radius: f32, height: f32, segments: u32) -> Mesh {
    let profile = [
        Vec2::new(0.0, 0.0),
        Vec2::new(radius, 0.0),
        Vec2::new(radius, height),
        Vec2::new(0.0, height),
    ];
    let mut mesh = lathe(&profile, segments, 0.0);
    mesh.name = "cylinder".into();
    mesh
}

/// A smooth sphere centred at the origin, `segments` around and `segments / 2` from pole to pole.
pub fn sphere(radius: f32, segments: u32) -> Mesh {
    let rings = (segments / 2).max(2);
    let profile: Vec<Vec2> = (0..=rings)
        .map(|k| {
            let a = std::f32::consts::PI * k as f32 / rings as f32;
            if k == 0 || k == rings {
                Vec2::new(0.0, -radius * a.cos())
            } else {
                Vec2::new(radius * a.sin(), -radius * a.cos())
            }
        })
        .collect();
    let mut mesh = lathe(&profile, segments, 60.0);
    mesh.name = "sphere".into();
    mesh
}

/// A straight flight of `steps` steps ascending towards +z, `width` wide along x (centred),
/// starting at z = 0 on y = 0. Each step rises `rise` and runs `run`; the top step is a landing
/// `landing` deep. Flat normals; no T-junctions.
pub fn stairs(width: f32, rise: f32, run: f32, steps: u32, landing: f32) -> Mesh {
    let mut b = Builder::default();
    let hx = width * 0.5;
    let n = steps.max(1) as usize;
    let z = |k: usize| {
        if k < n {
            k as f32 * run
        } else {
            (n - 1) as f32 * run + landing
        }
    };
    let top = |k: usize| (k + 1) as f32 * rise;
    for k in 0..n {
        let (z0, z1) = (z(k), z(k + 1));
        let (y_prev, y) = (k as f32 * rise, top(k));
        // Riser and tread.
        let riser = [
            Vec3::new(-hx, y_prev, z0),
            Vec3::new(hx, y_prev, z0),
            Vec3::new(hx, y, z0),
            Vec3::new(-hx, y, z0),
        ];
        b.flat_polygon(&riser, Vec3::NEG_Z);
        let tread = [
            Vec3::new(-hx, y, z0),
            Vec3::new(hx, y, z0),
            Vec3::new(hx, y, z1),
            Vec3::new(-hx, y, z1),
        ];
        b.flat_polygon(&tread, Vec3::Y);
        // Bottom strip under this step.
        let bottom = [
            Vec3::new(-hx, 0.0, z0),
            Vec3::new(-hx, 0.0, z1),
            Vec3::new(hx, 0.0, z1),
            Vec3::new(hx, 0.0, z0),
        ];
        b.flat_polygon(&bottom, Vec3::NEG_Y);
        // Side columns, including the previous step's corner on the left edge.
        for (sx, normal) in [(-hx, Vec3::NEG_X), (hx, Vec3::X)] {
            let mut side = vec![
                Vec3::new(sx, 0.0, z1),
                Vec3::new(sx, y, z1),
                Vec3::new(sx, y, z0),
            ];
            if k > 0 {
                side.push(Vec3::new(sx, y_prev, z0));
            }
            side.push(Vec3::new(sx, 0.0, z0));
            b.flat_polygon(&side, normal);
        }
    }
    let (z_end, y_end) = (z(n), top(n - 1));
    let back = [
        Vec3::new(-hx, 0.0, z_end),
        Vec3::new(hx, 0.0, z_end),
        Vec3::new(hx, y_end, z_end),
        Vec3::new(-hx, y_end, z_end),
    ];
    b.flat_polygon(&back, Vec3::Z);
    b.finish("stairs")
}

/// A wall pierced by `bays` semicircular arches in a row along x, centred at the origin.
/// Each bay is `2·half_width` wide with an opening of `radius` (< `half_width`) whose springing
/// line is y = 0; the wall reaches up to `height` (> `radius`) and is `depth` thick along z.
/// `segments` (rounded up to even, at least 4) is the number of segments of each semicircle;
/// `bays` is at least 1.
pub fn arcade(
    bays: u32,
    half_width: f32,
    radius: f32,
    height: f32,
    depth: f32,
    segments: u32,
) -> Mesh {
    let mut b = Builder::default();
    let segments = (segments.max(4) + 1) & !1;
    let bays = bays.max(1);
    let hz = depth * 0.5;
    let (w, r, h) = (half_width, radius, height);
    let boundary = |k: u32| (k as f32 - bays as f32 * 0.5) * 2.0 * w;
    for bay in 0..bays {
        let (x_left, x_right) = (boundary(bay), boundary(bay + 1));
        let cx = (x_left + x_right) * 0.5;
        let arc: Vec<Vec2> = (0..=segments)
            .map(|s| {
                let (sin, cos) = (std::f32::consts::PI * s as f32 / segments as f32).sin_cos();
                match s {
                    0 => Vec2::new(cx + r, 0.0),
                    s if s == segments => Vec2::new(cx - r, 0.0),
                    s if s == segments / 2 => Vec2::new(cx, r),
                    _ => Vec2::new(cx + r * cos, r * sin),
                }
            })
            .collect();
        let right_top = Vec2::new(x_right, h);
        let left_top = Vec2::new(x_left, h);
        let right_bottom = Vec2::new(x_right, 0.0);
        let left_bottom = Vec2::new(x_left, 0.0);
        let half = segments as usize / 2;
        // Front (+z) and back (-z) faces: fans from the two top corners.
        for (zf, normal) in [(hz, Vec3::Z), (-hz, Vec3::NEG_Z)] {
            let at = |p: Vec2| p.extend(zf);
            b.flat_polygon(&[at(right_top), at(arc[0]), at(right_bottom)], normal);
            b.flat_polygon(&[at(left_top), at(left_bottom), at(arc[2 * half])], normal);
            b.flat_polygon(&[at(right_top), at(left_top), at(arc[half])], normal);
            for s in 0..2 * half {
                let corner = if s < half { right_top } else { left_top };
                b.flat_polygon(&[at(corner), at(arc[s + 1]), at(arc[s])], normal);
            }
        }
        // Intrados: smooth normals pointing at the arch's axis.
        let base = b.positions.len() as u32;
        for p in &arc {
            let inward = (Vec2::new(cx, 0.0) - *p).normalize().extend(0.0);
            b.vertex(p.extend(hz), inward);
            b.vertex(p.extend(-hz), inward);
        }
        for s in 0..segments {
            let (f0, k0) = (base + 2 * s, base + 2 * s + 1);
            let (f1, k1) = (f0 + 2, k0 + 2);
            b.indices.push([f0, f1, k1]);
            b.indices.push([f0, k1, k0]);
        }
        // Top and the two flat soffits beside the opening.
        let top = [
            Vec3::new(x_left, h, -hz),
            Vec3::new(x_left, h, hz),
            Vec3::new(x_right, h, hz),
            Vec3::new(x_right, h, -hz),
        ];
        b.flat_polygon(&top, Vec3::Y);
        for (x0, x1) in [(cx + r, x_right), (x_left, cx - r)] {
            let soffit = [
                Vec3::new(x0, 0.0, -hz),
                Vec3::new(x1, 0.0, -hz),
                Vec3::new(x1, 0.0, hz),
                Vec3::new(x0, 0.0, hz),
            ];
            b.flat_polygon(&soffit, Vec3::NEG_Y);
        }
    }
    for (x, normal) in [(boundary(bays), Vec3::X), (boundary(0), Vec3::NEG_X)] {
        let side = [
            Vec3::new(x, 0.0, -hz),
            Vec3::new(x, 0.0, hz),
            Vec3::new(x, h, hz),
            Vec3::new(x, h, -hz),
        ];
        b.flat_polygon(&side, normal);
    }
    b.finish("arcade")
}

/// Appends `src`, moved by the rigid `transform`, to `dst` (positions, normals and triangles).
pub fn append(dst: &mut Mesh, src: &Mesh, transform: Affine3A) {
    let base = dst.positions.len() as u32;
    dst.positions
        .extend(src.positions.iter().map(|&p| transform.transform_point3(p)));
    dst.normals.extend(
        src.normals
            .iter()
            .map(|&n| transform.transform_vector3(n).normalize()),
    );
    dst.indices
        .extend(src.indices.iter().map(|t| t.map(|i| i + base)));
}

/// Points along a circular arc in the profile plane, from angle `from` to `to` (radians,
/// counter-clockwise from +radius), both ends included.
pub fn arc_profile(centre: Vec2, radius: f32, from: f32, to: f32, steps: u32) -> Vec<Vec2> {
    (0..=steps)
        .map(|k| {
            let a = from + (to - from) * k as f32 / steps as f32;
            centre + radius * Vec2::new(a.cos(), a.sin())
        })
        .collect()
}
