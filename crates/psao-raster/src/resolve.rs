//! Attribute resolve: turns (pixel, triangle id) into depth, position, normals and
//! barycentrics by intersecting the pixel-centre ray with the triangle's plane.

use glam::{Vec2, Vec3};

use crate::gbuffer::BandMut;
use crate::geometry::{locate, PosedInstance};
use crate::raster::VisibilityBand;
use crate::view::View;

/// Maps global triangle ids to instances and resolves attributes.
pub(crate) struct Resolver<'a> {
    /// The view.
    pub view: &'a View,
    /// Posed instances.
    pub instances: &'a [PosedInstance<'a>],
    /// First global id of each instance.
    pub first_id: &'a [u32],
}

/// Per-triangle quantities shared by all pixels showing that triangle.
struct Triangle {
    /// Global id.
    id: u32,
    /// Instance index.
    instance: u32,
    /// Triangle index within the instance's mesh.
    triangle: u32,
    /// World-space vertices.
    p: [Vec3; 3],
    /// Barycentrics per pixel.
    bary: BaryPlane,
    /// Unit face normal turned towards the eye (`None` for a degenerate triangle).
    face_normal: Option<Vec3>,
    /// How the shading normal is found.
    shading: Shading,
}

/// Shading normal source of a triangle.
enum Shading {
    /// Constant unit normal, already in the camera-facing hemisphere.
    Flat(Vec3),
    /// World-space vertex normals to interpolate.
    Smooth([Vec3; 3]),
    /// No usable vertex normals: use the geometric normal.
    Geometric,
}

impl Resolver<'_> {
    /// Writes every pixel of `band` from the visibility buffer `vis` of the same rows.
    pub fn resolve_band(&self, vis: &VisibilityBand, band: &mut BandMut<'_>) {
        let mut cached: Option<Triangle> = None;
        let width = band.width as usize;
        for r in 0..band.rows() as usize {
            let y = band.y0 + r as u32;
            for x in 0..width {
                let p = r * width + x;
                let Some(id) = vis.id(p) else {
                    band.clear(p);
                    continue;
                };
                if !matches!(&cached, Some(t) if t.id == id) {
                    cached = self.triangle(id);
                }
                match &cached {
                    Some(tri) => self.shade(tri, x as u32, y, band, p),
                    None => band.clear(p),
                }
            }
        }
    }

    /// Writes pixel `p` of `band`, which shows `tri` at image pixel (`x`, `y`).
    fn shade(&self, tri: &Triangle, x: u32, y: u32, band: &mut BandMut<'_>, p: usize) {
        let barycentric = tri.bary.at(x, y);
        let (u, v) = (barycentric.x, barycentric.y);
        let w = 1.0 - u - v;
        let position = w * tri.p[0] + u * tri.p[1] + v * tri.p[2];
        let geometric_normal = tri
            .face_normal
            .unwrap_or_else(|| -self.view.pixel_ray(x, y).normalize());
        let normal = match tri.shading {
            Shading::Flat(n) => n,
            Shading::Smooth([n0, n1, n2]) => {
                let n = (w * n0 + u * n1 + v * n2).normalize_or_zero();
                if n == Vec3::ZERO {
                    geometric_normal
                } else if n.dot(geometric_normal) < 0.0 {
                    -n
                } else {
                    n
                }
            }
            Shading::Geometric => geometric_normal,
        };
        band.depth[p] = (position - self.view.origin).dot(self.view.forward);
        band.position[p] = position;
        band.normal[p] = normal;
        band.geometric_normal[p] = geometric_normal;
        band.instance[p] = tri.instance;
        band.triangle[p] = tri.triangle;
        band.barycentric[p] = barycentric;
    }

    /// Per-triangle data of global triangle `id`.
    fn triangle(&self, id: u32) -> Option<Triangle> {
        let (instance, triangle) = locate(self.first_id, id)?;
        let posed = &self.instances[instance];
        let (idx, p) = posed.triangle(triangle as usize)?;
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let s = self.view.origin - p[0];
        // Towards the eye means into the half-space of the plane that contains the eye.
        let face_normal = Some(e1.cross(e2).normalize_or_zero())
            .filter(|n| *n != Vec3::ZERO)
            .map(|n| if n.dot(s) < 0.0 { -n } else { n });
        let towards_eye = face_normal.unwrap_or(s);
        let shading = match posed.normals.zip(posed.normal_matrix) {
            None => Shading::Geometric,
            Some((n, m)) => {
                let [n0, n1, n2] = idx.map(|i| m * n[i as usize]);
                if n0 == n1 && n1 == n2 {
                    match n0.normalize_or_zero() {
                        n if n == Vec3::ZERO => Shading::Geometric,
                        n if n.dot(towards_eye) < 0.0 => Shading::Flat(-n),
                        n => Shading::Flat(n),
                    }
                } else {
                    Shading::Smooth([n0, n1, n2])
                }
            }
        };
        Some(Triangle {
            id,
            instance: instance as u32,
            triangle,
            p,
            bary: BaryPlane::new(self.view, p),
            face_normal,
            shading,
        })
    }
}

/// The barycentrics of one world-space triangle as seen through each pixel centre:
/// Möller–Trumbore rearranged so that u and v at pixel (x, y) are ratios of affine functions
/// of x and y (see [`View::pixel_affine`]).
pub(crate) struct BaryPlane {
    /// Numerator of u.
    u_num: Vec3,
    /// Numerator of v.
    v_num: Vec3,
    /// Common denominator of u and v.
    den: Vec3,
}

impl BaryPlane {
    /// The plane of world-space triangle `p` in `view`.
    pub fn new(view: &View, p: [Vec3; 3]) -> Self {
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let s = view.origin - p[0];
        Self {
            u_num: view.pixel_affine(e2.cross(s)),
            v_num: view.pixel_affine(s.cross(e1)),
            den: view.pixel_affine(e2.cross(e1)),
        }
    }

    /// Barycentrics (u, v) of where the eye ray through the centre of pixel (`x`, `y`) meets
    /// the plane, clamped into the triangle (the centroid when the ray is parallel to the
    /// plane).
    pub fn at(&self, x: u32, y: u32) -> Vec2 {
        let (x, y) = (x as f32, y as f32);
        let at = |f: Vec3| f.x + f.y * x + f.z * y;
        let uv = Vec2::new(at(self.u_num), at(self.v_num)) * at(self.den).recip();
        if !uv.is_finite() {
            return Vec2::splat(1.0 / 3.0);
        }
        // Nearest point of u, v ≥ 0, u + v ≤ 1; up to the sub-pixel snapping error this only
        // moves points that lie on an edge.
        let c = uv.max(Vec2::ZERO);
        let sum = c.x + c.y;
        if sum > 1.0 {
            c / sum
        } else {
            c
        }
    }
}
