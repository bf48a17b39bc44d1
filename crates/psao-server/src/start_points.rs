//! The points a server starts from (generated, burial-tested, numbered in culling order),
//! their key, and their byte form, so that a restart with the same scene and settings can
//! skip generating them again. Pure: the caller stores the bytes.

use std::hash::Hasher;

use glam::Vec3;
use psao_points::{
    generate_scene_points_adaptive, Adaptive, GenerateParams, InstancePoints, SurfacePoint,
};
use psao_scene::{AlphaMode, Scene};
use psao_trace::{GeometryMode, Tracer};
use rayon::prelude::*;

use crate::bury::buried;
use crate::{ServerConfig, ServerError};

/// Format tag of [`StartPoints::to_bytes`].
const MAGIC: [u8; 4] = *b"PSSP";
/// Format version; bump it whenever the bytes or what generation produces change.
const VERSION: u32 = 2;
/// Bytes before the instances: magic, version, key, instance count, buried count.
const HEADER_BYTES: usize = 4 + 4 + 8 + 4 + 8;
/// Bytes of one instance's statistics before its points.
const INSTANCE_BYTES: usize = 4 * 4 + 1 + 6 * 4 + 8 + 8 + 8;
/// Bytes of one point: triangle, barycentrics, position, normal, back-face flag.
const POINT_BYTES: usize = 4 + 9 * 4 + 1;

/// The points of every instance as a server starts from them.
#[derive(Clone, Debug, PartialEq)]
pub struct StartPoints {
    /// What generated them ([`StartPoints::key`]).
    pub key: u64,
    /// Per instance, the kept points in culling order.
    pub instances: Vec<InstancePoints>,
    /// Points dropped as buried inside closed geometry.
    pub buried: usize,
}

impl StartPoints {
    /// The points [`crate::Server::with_medium`] would start from (it builds a tracer of its
    /// own for the burial test): to be stored and handed to
    /// [`crate::Server::with_start_points`] later.
    pub fn generate(scene: &Scene, config: &ServerConfig) -> Result<Self, ServerError> {
        crate::Server::checked_radius(scene, config)?;
        let tracer = Tracer::new(config.backend, scene, GeometryMode::Occlusion)?;
        Self::generate_with(scene, config, &tracer)
    }

    /// Generate the points of every instance of `scene` (in parallel; none on alpha-masked-out
    /// texels), drop buried ones with `tracer` when [`ServerConfig::cull_buried`] is set, and
    /// number each instance's points in the Morton order culling visits them (front and back
    /// copies stay adjacent: equal positions keep their order).
    pub(crate) fn generate_with(
        scene: &Scene,
        config: &ServerConfig,
        tracer: &Tracer,
    ) -> Result<Self, ServerError> {
        let params = GenerateParams {
            density: config.density,
            seed: config.seed,
        };
        let opaque = |mesh: usize, tri: u32, bary: Vec3| scene.opaque_at(mesh, tri, bary);
        let signal = |instance: usize, probes: &[(Vec3, Vec3)], spacing: f32| {
            crate::near_field::near_field_signal(tracer, config.seed, instance, probes, spacing)
        };
        let adaptive = (config.adaptive_boost > 1.0).then_some(Adaptive {
            max_boost: config.adaptive_boost,
            signal: &signal,
        });
        let mut points = generate_scene_points_adaptive(scene, &params, Some(&opaque), adaptive)?;
        let buried_points = if config.cull_buried {
            let buried = buried(tracer, scene, &points, config.seed);
            let mut dropped = 0;
            for (p, b) in points.iter_mut().zip(&buried) {
                let mut flags = b.iter();
                p.points.retain(|_| !flags.next().copied().unwrap_or(false));
                dropped += b.iter().filter(|&&x| x).count();
            }
            dropped
        } else {
            0
        };
        points.par_iter_mut().for_each(|p| {
            let positions: Vec<Vec3> = p.points.iter().map(|s| s.position).collect();
            let order = crate::blocks::morton_order(&positions);
            p.points = order.iter().map(|&i| p.points[i as usize]).collect();
        });
        Ok(Self {
            key: Self::key(scene, config),
            instances: points,
            buried: buried_points,
        })
    }

    /// A hash of everything that shapes the start points: the format version; per mesh its
    /// positions, normals, UVs, triangles and material; per material its sidedness, alpha
    /// mode, base-colour alpha and alpha texture; per instance its mesh, transform and skin; the density, seed,
    /// burial switch, adaptive boost and tracing backend (burial verdicts may differ between backends on
    /// coincident faces). Equal keys give equal points.
    pub fn key(scene: &Scene, config: &ServerConfig) -> u64 {
        // std's SipHash with fixed keys: deterministic within a Rust release; another release
        // may hash differently, which only makes stored points look stale (regenerated).
        let mut h = std::hash::DefaultHasher::new();
        let floats = |h: &mut std::hash::DefaultHasher, v: &mut dyn Iterator<Item = f32>| {
            let mut n = 0usize;
            v.for_each(|x| {
                h.write_u32(x.to_bits());
                n += 1;
            });
            h.write_usize(n);
        };
        h.write_u32(VERSION);
        h.write_usize(scene.meshes.len());
        for m in &scene.meshes {
            floats(&mut h, &mut m.positions.iter().flat_map(|v| v.to_array()));
            floats(&mut h, &mut m.normals.iter().flat_map(|v| v.to_array()));
            floats(&mut h, &mut m.uvs.iter().flat_map(|v| v.to_array()));
            h.write_usize(m.indices.len());
            m.indices.iter().flatten().for_each(|&i| h.write_u32(i));
            h.write_usize(m.material);
        }
        h.write_usize(scene.materials.len());
        for mat in &scene.materials {
            h.write_u8(u8::from(mat.double_sided));
            match mat.alpha_mode {
                AlphaMode::Opaque => h.write_u8(0),
                AlphaMode::Mask { cutoff } => {
                    h.write_u8(1);
                    h.write_u32(cutoff.to_bits());
                }
                AlphaMode::Blend => h.write_u8(2),
            }
            h.write_u32(mat.base_color.w.to_bits());
            if let Some(t) = &mat.alpha_texture {
                let img = &t.image;
                h.write(format!("{} {:?} {:?}", t.tex_coord, t.wrap_s, t.wrap_t).as_bytes());
                h.write_u32(img.width());
                h.write_u32(img.height());
                for y in 0..img.height() {
                    (0..img.width()).for_each(|x| h.write_u8(img.texel(x, y)));
                }
            }
        }
        h.write_usize(scene.instances.len());
        for inst in &scene.instances {
            h.write_usize(inst.mesh);
            floats(&mut h, &mut inst.transform.to_cols_array().into_iter());
            h.write_u8(u8::from(inst.skin.is_some()));
        }
        h.write_u32(config.density.to_bits());
        h.write_u64(config.seed);
        h.write_u8(u8::from(config.cull_buried));
        h.write_u32(config.adaptive_boost.to_bits());
        h.write(config.backend.name().as_bytes());
        h.finish()
    }

    /// Points stored over all instances.
    pub fn point_count(&self) -> usize {
        self.instances.iter().map(|i| i.points.len()).sum()
    }

    /// The byte form: a header with the format version and key, the instances, and a CRC-32
    /// of everything before it.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            HEADER_BYTES
                + self.instances.len() * INSTANCE_BYTES
                + self.point_count() * POINT_BYTES
                + 4,
        );
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&self.key.to_le_bytes());
        out.extend_from_slice(&(self.instances.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.buried as u64).to_le_bytes());
        for inst in &self.instances {
            for x in [
                inst.poisson_radius,
                inst.poisson_radius_local,
                inst.area,
                inst.area_local,
            ] {
                out.extend_from_slice(&x.to_le_bytes());
            }
            out.push(inst.sides);
            for v in [inst.local_bounds.0, inst.local_bounds.1] {
                put_vec3(&mut out, v);
            }
            out.extend_from_slice(&(inst.spawned as u64).to_le_bytes());
            out.extend_from_slice(&(inst.alpha_rejected as u64).to_le_bytes());
            out.extend_from_slice(&(inst.points.len() as u64).to_le_bytes());
            for p in &inst.points {
                out.extend_from_slice(&p.triangle.to_le_bytes());
                for v in [p.bary, p.position, p.normal] {
                    put_vec3(&mut out, v);
                }
                out.push(u8::from(p.back_face));
            }
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Read [`Self::to_bytes`]'s form back, refusing another format version, another key
    /// than `expected_key`, a checksum mismatch, or counts the bytes cannot hold.
    pub fn from_bytes(bytes: &[u8], expected_key: u64) -> Result<Self, ServerError> {
        let bad = |why: String| ServerError::StartPoints(why);
        let body_len = bytes
            .len()
            .checked_sub(4)
            .ok_or_else(|| bad("shorter than a checksum".into()))?;
        let (body, crc) = bytes.split_at(body_len);
        let mut r = Reader { bytes: body, at: 0 };
        if r.take(4)? != MAGIC {
            return Err(bad("not a psao start-points file".into()));
        }
        let version = r.u32()?;
        if version != VERSION {
            return Err(bad(format!(
                "format version {version}, this psao reads {VERSION}"
            )));
        }
        let key = r.u64()?;
        if key != expected_key {
            return Err(bad(format!(
                "made for key {key:016x}, not {expected_key:016x} (another scene or settings)"
            )));
        }
        let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
        if crc32fast::hash(body) != stored {
            return Err(bad("checksum mismatch (a damaged file)".into()));
        }
        let count = r.u32()? as usize;
        let buried = r.u64()? as usize;
        if count > r.left() / INSTANCE_BYTES {
            return Err(bad(format!("{count} instances do not fit in the file")));
        }
        let mut instances = Vec::with_capacity(count);
        for _ in 0..count {
            let [poisson_radius, poisson_radius_local, area, area_local] =
                [r.f32()?, r.f32()?, r.f32()?, r.f32()?];
            let sides = r.take(1)?[0];
            let local_bounds = (r.vec3()?, r.vec3()?);
            let spawned = r.u64()? as usize;
            let alpha_rejected = r.u64()? as usize;
            let n = r.u64()?;
            if n > (r.left() / POINT_BYTES) as u64 {
                return Err(bad(format!("{n} points do not fit in the file")));
            }
            let mut points = Vec::with_capacity(n as usize);
            for _ in 0..n {
                points.push(SurfacePoint {
                    triangle: r.u32()?,
                    bary: r.vec3()?,
                    position: r.vec3()?,
                    normal: r.vec3()?,
                    back_face: r.take(1)?[0] != 0,
                });
            }
            instances.push(InstancePoints {
                points,
                poisson_radius,
                poisson_radius_local,
                area,
                area_local,
                sides,
                local_bounds,
                spawned,
                alpha_rejected,
            });
        }
        if r.left() != 0 {
            return Err(bad(format!("{} bytes after the last instance", r.left())));
        }
        Ok(Self {
            key,
            instances,
            buried,
        })
    }
}

fn put_vec3(out: &mut Vec<u8>, v: Vec3) {
    for x in v.to_array() {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// A cursor over little-endian fields.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn take(&mut self, n: usize) -> Result<&[u8], ServerError> {
        if n > self.left() {
            return Err(ServerError::StartPoints(format!(
                "truncated at byte {}",
                self.at
            )));
        }
        self.at += n;
        Ok(&self.bytes[self.at - n..self.at])
    }

    fn u32(&mut self) -> Result<u32, ServerError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }

    fn u64(&mut self) -> Result<u64, ServerError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or([0; 8]),
        ))
    }

    fn f32(&mut self) -> Result<f32, ServerError> {
        Ok(f32::from_bits(self.u32()?))
    }

    fn vec3(&mut self) -> Result<Vec3, ServerError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }
}
