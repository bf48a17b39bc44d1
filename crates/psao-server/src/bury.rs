//! Burial test: drop generated points that lie inside closed geometry (our addition to
//! DESIGN §3 "Generation").
//!
//! Scenes built from closed parts that touch or overlap (tiles resting on a slab, a box on a
//! floor, a column sunk into a plinth) put many points on faces nobody can see: the slab top
//! under a tile, a tile's underside. They are not harmless: their AO is near 0, they take
//! the capacity of the 7-point cells that visible points of the same neighbourhood need, and
//! reconstruction blends them into nearby visible pixels (a 2 cm groove between two tiles has
//! buried points a few millimetres below its visible floor). A point is *buried* when almost
//! every ray leaving it through its hemisphere hits the inside (back side) of single-sided
//! geometry, i.e. it sits in a closed volume. Points on open faces, points whose rays escape,
//! and back sides of double-sided materials (which have no inside) are kept. Alpha-masked
//! geometry is skipped by the server's tracer, so it never buries anything.

use glam::{Mat3A, Vec3};
use psao_points::InstancePoints;
use psao_scene::Scene;
use psao_trace::ao::{cosine_hemisphere, hash64, ray_offset, sample_2d};
use psao_trace::{sort_rays_spatially, Hit, Ray, Tracer};
use rayon::prelude::*;

/// Rays traced per point by the burial test.
pub const BURIAL_RAYS: u32 = 8;
/// A point is buried when at least this many of its [`BURIAL_RAYS`] rays hit the back side of
/// single-sided geometry: one ray may slip out through a crack between touching parts (or a
/// grazing hit may be judged the wrong side) without saving a buried point, while a point
/// with two escaping rays sees the open scene and is kept.
pub const BURIAL_MIN_INSIDE: u32 = 7;
const _: () = assert!(BURIAL_MIN_INSIDE >= 1 && BURIAL_MIN_INSIDE <= BURIAL_RAYS);
/// Points handled together per parallel work item.
const CHUNK_POINTS: usize = 1024;
/// Decorrelates the burial rays from the AO rays of the same points.
const BURIAL_SEED_SALT: u64 = 0x6275_7269_6564_2121;

/// Per hit instance: what judging a hit's side needs.
struct Side {
    /// Instance normal matrix (inverse transpose of the linear part).
    normal_matrix: Mat3A,
    /// Whether the instance's material is double-sided (no inside).
    double_sided: bool,
}

/// For every instance of `scene` (whose generated points are `points`, in instance order),
/// which of its points are buried (see the module docs). The rays are unbounded (they reach
/// across the whole scene), start at the points in the scene's current pose, and are seeded
/// by `seed`; the result does not depend on the thread count.
pub(crate) fn buried(
    tracer: &Tracer,
    scene: &Scene,
    points: &[InstancePoints],
    seed: u64,
) -> Vec<Vec<bool>> {
    let sides: Vec<Side> = scene
        .instances
        .iter()
        .map(|inst| Side {
            normal_matrix: inst.transform.matrix3.inverse().transpose(),
            double_sided: scene
                .meshes
                .get(inst.mesh)
                .and_then(|m| scene.materials.get(m.material))
                .is_some_and(|m| m.double_sided),
        })
        .collect();
    // World origin and normal of every point, with its (instance, index).
    let jobs: Vec<(u32, u32, Vec3, Vec3)> = points
        .iter()
        .zip(&scene.instances)
        .enumerate()
        .flat_map(|(ii, (p, inst))| {
            let nm = sides[ii].normal_matrix;
            p.points.iter().enumerate().map(move |(k, s)| {
                let x = inst.transform.transform_point3(s.position);
                let n = nm.mul_vec3(s.normal).normalize_or_zero();
                (ii as u32, k as u32, x, n)
            })
        })
        .collect();
    let probes: Vec<Ray> = jobs.iter().map(|j| Ray::new(j.2, j.3, 1.0)).collect();
    let order = sort_rays_spatially(&probes);
    let seed = seed ^ BURIAL_SEED_SALT;
    // Per point of `chunk` (indices into `jobs`): how many of its rays `range` hit an inside.
    let inside_hits = |chunk: &[u32], range: std::ops::Range<u32>| -> Vec<u32> {
        let per = range.len();
        let mut rays = Vec::with_capacity(chunk.len() * per);
        for &j in chunk {
            let (ii, k, x, n) = jobs[j as usize];
            let key = (u64::from(ii) << 32) | u64::from(k);
            let origin = ray_offset(x, n);
            rays.extend(range.clone().map(|i| burial_ray(seed, key, i, origin, n)));
        }
        let mut out = vec![None; rays.len()];
        tracer.intersect(&rays, &mut out);
        rays.chunks(per.max(1))
            .zip(out.chunks(per.max(1)))
            .map(|(rays, hits)| inside_count(scene, &sides, rays, hits))
            .collect()
    };
    // A point whose first rays all escape is kept whatever the others do, so they are traced
    // first and only the rest trace all of theirs: the same verdicts as tracing every ray
    // (up to a backend's choice between coincident faces, which may follow the batching).
    let first = BURIAL_RAYS - BURIAL_MIN_INSIDE + 1;
    let hits: Vec<(u32, bool)> = order
        .par_chunks(CHUNK_POINTS)
        .flat_map_iter(|chunk| {
            let early = inside_hits(chunk, 0..first);
            // Positions in `chunk` of the points that need their other rays.
            let open: Vec<usize> = (0..chunk.len()).filter(|&at| early[at] > 0).collect();
            let open_points: Vec<u32> = open.iter().map(|&at| chunk[at]).collect();
            let rest = inside_hits(&open_points, first..BURIAL_RAYS);
            let mut verdicts: Vec<(u32, bool)> = chunk.iter().map(|&j| (j, false)).collect();
            for (&at, m) in open.iter().zip(rest) {
                verdicts[at].1 = early[at] + m >= BURIAL_MIN_INSIDE;
            }
            verdicts
        })
        .collect();
    let mut out: Vec<Vec<bool>> = points.iter().map(|p| vec![false; p.points.len()]).collect();
    for (j, b) in hits {
        let (ii, k, _, _) = jobs[j as usize];
        out[ii as usize][k as usize] = b;
    }
    out
}

/// How many of `rays` (with their `hits`) hit the inside of single-sided geometry.
fn inside_count(scene: &Scene, sides: &[Side], rays: &[Ray], hits: &[Option<Hit>]) -> u32 {
    rays.iter()
        .zip(hits)
        .filter(|(r, h)| h.is_some_and(|h| hits_inside(scene, sides, r, &h)))
        .count() as u32
}

/// Burial ray `i` of the point with sample key `key` at `origin` (already offset) with
/// normal `n`.
fn burial_ray(seed: u64, key: u64, i: u32, origin: Vec3, n: Vec3) -> Ray {
    let (u1, u2) = sample_2d(hash64(seed), key, i);
    Ray::new(origin, cosine_hemisphere(n, u1, u2), f32::INFINITY)
}

/// Whether `ray` hit the back side (judged by the interpolated vertex normal, else the face
/// normal) of a single-sided surface.
fn hits_inside(scene: &Scene, sides: &[Side], ray: &Ray, hit: &Hit) -> bool {
    let Some(side) = sides.get(hit.instance as usize) else {
        return false;
    };
    if side.double_sided {
        return false;
    }
    let inst = &scene.instances[hit.instance as usize];
    let Some(mesh) = scene.meshes.get(inst.mesh) else {
        return false;
    };
    let Some(tri) = mesh.indices.get(hit.triangle as usize) else {
        return false;
    };
    let vertex = |i: u32| mesh.positions.get(i as usize).copied();
    let (Some(a), Some(b), Some(c)) = (vertex(tri[0]), vertex(tri[1]), vertex(tri[2])) else {
        return false;
    };
    let face = (b - a).cross(c - a);
    let local = if mesh.normals.len() == mesh.positions.len() {
        let w = Vec3::new(1.0 - hit.u - hit.v, hit.u, hit.v);
        let n = mesh.normals[tri[0] as usize] * w.x
            + mesh.normals[tri[1] as usize] * w.y
            + mesh.normals[tri[2] as usize] * w.z;
        if n.length_squared() > 0.0 {
            n
        } else {
            face
        }
    } else {
        face
    };
    side.normal_matrix.mul_vec3(local).dot(ray.dir) > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_points::SurfacePoint;
    use psao_scene::builtin::shapes::cuboid;
    use psao_trace::{Backend, GeometryMode};

    #[test]
    fn two_rounds_give_the_verdicts_of_every_ray() {
        // A closed box missing its top: points inside see the opening with some rays only,
        // so their inside counts spread over 0..=8 and the verdict's edge is exercised.
        let mut open_box = cuboid(Vec3::splat(1.0));
        open_box.indices.retain(|t| {
            let c = (open_box.positions[t[0] as usize]
                + open_box.positions[t[1] as usize]
                + open_box.positions[t[2] as usize])
                / 3.0;
            c.y < 0.99
        });
        let scene = Scene::of_meshes(vec![open_box]);
        let point = |k: u64| {
            let h = hash64(k);
            let f = |s: u32| ((h >> s) & 0xffff) as f32 / 65535.0 * 1.8 - 0.9;
            let normal = Vec3::new(f(0), f(16), f(32)).normalize_or(Vec3::Y);
            SurfacePoint {
                triangle: 0,
                bary: Vec3::new(1.0, 0.0, 0.0),
                position: Vec3::new(f(8), f(24), f(40)),
                normal,
                back_face: false,
            }
        };
        let points = vec![InstancePoints {
            points: (0..3000).map(point).collect(),
            poisson_radius: 0.01,
            poisson_radius_local: 0.01,
            area: 1.0,
            area_local: 1.0,
            sides: 1,
            local_bounds: (Vec3::splat(-1.0), Vec3::splat(1.0)),
            spawned: 3000,
            alpha_rejected: 0,
        }];
        let tracer = Tracer::new(Backend::default(), &scene, GeometryMode::Occlusion).unwrap();
        let seed = 11;
        let verdicts = buried(&tracer, &scene, &points, seed);
        let sides = [Side {
            normal_matrix: Mat3A::IDENTITY,
            double_sided: false,
        }];
        let mut counts = [0usize; BURIAL_RAYS as usize + 1];
        for (k, p) in points[0].points.iter().enumerate() {
            let origin = ray_offset(p.position, p.normal);
            let key = k as u64;
            let rays: Vec<Ray> = (0..BURIAL_RAYS)
                .map(|i| burial_ray(seed ^ BURIAL_SEED_SALT, key, i, origin, p.normal))
                .collect();
            let mut hits = vec![None; rays.len()];
            tracer.intersect(&rays, &mut hits);
            let inside = inside_count(&scene, &sides, &rays, &hits);
            counts[inside as usize] += 1;
            assert_eq!(verdicts[0][k], inside >= BURIAL_MIN_INSIDE, "point {k}");
        }
        // Both verdicts and the counts around the edge occur.
        let edge = BURIAL_MIN_INSIDE as usize;
        assert!(counts[edge - 1] > 0 && counts[edge] > 0, "{counts:?}");
        assert!(
            counts[0] > 0 && counts[BURIAL_RAYS as usize] > 0,
            "{counts:?}"
        );
    }
}
