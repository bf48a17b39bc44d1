//! Seeded procedural volumes for benchmarks and tests, one of each kind that stresses the
//! renderers differently: a dense fractal-noise cloud (many bricks per ray), a large box level
//! set (flat faces, large empty interior and exterior), a thin torus shell level set and sparse
//! smoke puffs (much empty space between small bricks groups). Same kind, size and seed give
//! the same grid.

use crate::error::{Result, VolumeError};
use crate::grid::{voxel_index, GridClass, Leaf, SparseGrid, Transform, BRICK, BRICK_VOXELS};
use glam::{DVec3, IVec3, Vec3};
use rayon::prelude::*;

/// Half-width of the narrow band of the generated level sets, in voxels (OpenVDB's default).
const BAND: f32 = 3.0;

/// The kinds of generated volumes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Procedural {
    /// Fog: an ellipsoid of fractal value noise, dense inside, ragged at its edge.
    Cloud,
    /// Level set: an axis-aligned box filling most of the domain.
    Box,
    /// Level set: a torus shell two voxels thick.
    Torus,
    /// Fog: a trail of small, thin noisy puffs in a mostly empty domain.
    Smoke,
}

impl Procedural {
    /// All kinds.
    pub const ALL: [Procedural; 4] = [
        Procedural::Cloud,
        Procedural::Box,
        Procedural::Torus,
        Procedural::Smoke,
    ];

    /// Lower-case name (as on the command line).
    pub fn name(self) -> &'static str {
        match self {
            Procedural::Cloud => "cloud",
            Procedural::Box => "box",
            Procedural::Torus => "torus",
            Procedural::Smoke => "smoke",
        }
    }

    /// Parses a name from [`Procedural::name`].
    pub fn parse(s: &str) -> Option<Procedural> {
        Procedural::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Default domain edge in voxels (what the benchmark uses).
    pub fn default_size(self) -> u32 {
        match self {
            Procedural::Cloud => 128,
            Procedural::Box => 256,
            Procedural::Torus => 256,
            Procedural::Smoke => 192,
        }
    }

    /// Generates the grid in a cube of `size`³ voxels of edge 1/`size` world units, from
    /// `seed`. `size` is 16..=512: every voxel of the cube is evaluated (512³ takes seconds).
    pub fn generate(self, size: u32, seed: u64) -> Result<SparseGrid> {
        if !(16..=512).contains(&size) {
            return Err(VolumeError::InvalidParameter(format!(
                "procedural volume size {size} (16..=512 voxels)"
            )));
        }
        let n = size as f32;
        let voxel = 1.0 / size as f64;
        let noise = Noise::new(seed);
        let c = Vec3::splat(0.5 * n);
        let (class, field): (GridClass, Box<dyn Fn(Vec3) -> f32 + Sync>) = match self {
            Procedural::Cloud => (
                GridClass::Fog,
                Box::new(move |p| {
                    let q = (p - c) / (Vec3::new(0.45, 0.32, 0.4) * n);
                    let f = noise.fbm(p * (6.0 / n), 5);
                    let d = 1.0 - q.length() + 0.45 * (f - 0.5);
                    (d * 4.0).clamp(0.0, 1.0) * (0.55 + 0.45 * f)
                }),
            ),
            Procedural::Smoke => {
                let puffs: Vec<(Vec3, f32)> = (0..14)
                    .map(|k| {
                        let a = k as f32 * 0.55 + noise.lattice(IVec3::new(k, 7, 3)) * 0.4;
                        let h = 0.12 + 0.055 * k as f32;
                        let at = Vec3::new(0.5 + 0.3 * a.cos(), h, 0.5 + 0.3 * a.sin()) * n;
                        let r = (0.03 + 0.035 * noise.lattice(IVec3::new(k, 1, 9))) * n;
                        (at, r)
                    })
                    .collect();
                (
                    GridClass::Fog,
                    Box::new(move |p| {
                        let f = noise.fbm(p * (10.0 / n), 4);
                        let mut v = 0.0f32;
                        for &(at, r) in &puffs {
                            let d = 1.0 - (p - at).length() / r + 0.6 * (f - 0.5);
                            v = v.max((d * 2.0).clamp(0.0, 1.0));
                        }
                        v * 0.35 * f
                    }),
                )
            }
            Procedural::Box => {
                let half = Vec3::new(0.42, 0.3, 0.38) * n;
                (
                    GridClass::LevelSet,
                    Box::new(move |p| {
                        let q = (p - c).abs() - half;
                        q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
                    }),
                )
            }
            Procedural::Torus => {
                let (major, minor) = (0.3 * n, 0.12 * n);
                (
                    GridClass::LevelSet,
                    Box::new(move |p| {
                        let q = p - c;
                        let ring = (Vec3::new(q.x, 0.0, q.z).length() - major).hypot(q.y);
                        (ring - minor).abs() - 1.0
                    }),
                )
            }
        };
        let bricks = size.div_ceil(BRICK as u32) as i32;
        let origins: Vec<IVec3> = (0..bricks * bricks * bricks)
            .map(|i| IVec3::new(i % bricks, (i / bricks) % bricks, i / (bricks * bricks)))
            .map(|b| b * BRICK as i32)
            .collect();
        let leaves: Vec<Leaf> = origins
            .par_iter()
            .filter_map(|&o| leaf(o, class, &*field, voxel as f32))
            .collect();
        if leaves.is_empty() {
            return Err(VolumeError::Empty);
        }
        Ok(SparseGrid {
            name: self.name().into(),
            class,
            transform: Transform {
                scale: DVec3::splat(voxel),
                translation: DVec3::splat(-0.5),
            },
            background: match class {
                GridClass::Fog => 0.0,
                GridClass::LevelSet => BAND * voxel as f32,
            },
            leaves,
            tiles: Vec::new(),
        })
    }
}

/// The leaf at `origin` of a fog density or a signed distance in voxels, if any voxel is
/// active (non-zero density, or within the narrow band).
fn leaf(origin: IVec3, class: GridClass, field: &dyn Fn(Vec3) -> f32, voxel: f32) -> Option<Leaf> {
    let mut values = Box::new([0.0f32; BRICK_VOXELS]);
    let mut mask = [0u64; 8];
    for z in 0..BRICK {
        for y in 0..BRICK {
            for x in 0..BRICK {
                let i = voxel_index(x, y, z);
                let p = (origin + IVec3::new(x as i32, y as i32, z as i32)).as_vec3();
                let v = field(p);
                let (value, active) = match class {
                    GridClass::Fog => (v, v > 0.0),
                    GridClass::LevelSet => (v.clamp(-BAND, BAND) * voxel, v.abs() < BAND),
                };
                values[i] = value;
                if active {
                    mask[i / 64] |= 1 << (i % 64);
                }
            }
        }
    }
    mask.iter().any(|&w| w != 0).then_some(Leaf {
        origin,
        values,
        mask,
    })
}

/// Seeded value noise on the integer lattice with smooth trilinear interpolation.
#[derive(Clone, Copy)]
struct Noise {
    seed: u64,
}

impl Noise {
    fn new(seed: u64) -> Self {
        Noise { seed }
    }

    /// Value in 0..1 at lattice point `p` (a 64-bit mix of the coordinates and the seed).
    fn lattice(&self, p: IVec3) -> f32 {
        let mut h = self.seed ^ 0x9E37_79B9_7F4A_7C15;
        for c in [p.x, p.y, p.z] {
            h = (h ^ c as u32 as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h ^= h >> 31;
        }
        h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 29;
        (h >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Smoothly interpolated value noise in 0..1.
    fn value(&self, p: Vec3) -> f32 {
        let b = p.floor();
        let f = p - b;
        let s = f * f * (Vec3::splat(3.0) - 2.0 * f);
        let i = b.as_ivec3();
        let v = |dx, dy, dz| self.lattice(i + IVec3::new(dx, dy, dz));
        let x0 = v(0, 0, 0) + (v(1, 0, 0) - v(0, 0, 0)) * s.x;
        let x1 = v(0, 1, 0) + (v(1, 1, 0) - v(0, 1, 0)) * s.x;
        let x2 = v(0, 0, 1) + (v(1, 0, 1) - v(0, 0, 1)) * s.x;
        let x3 = v(0, 1, 1) + (v(1, 1, 1) - v(0, 1, 1)) * s.x;
        let y0 = x0 + (x1 - x0) * s.y;
        let y1 = x2 + (x3 - x2) * s.y;
        y0 + (y1 - y0) * s.z
    }

    /// Fractal sum of `octaves` octaves (doubling frequency, halving amplitude), in 0..1.
    fn fbm(&self, p: Vec3, octaves: u32) -> f32 {
        let (mut sum, mut amp, mut norm, mut q) = (0.0, 1.0, 0.0, p);
        for k in 0..octaves {
            sum += amp * self.value(q + Vec3::splat(17.0 * k as f32));
            norm += amp;
            amp *= 0.5;
            q *= 2.0;
        }
        sum / norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_grid_other_seed_other_grid() {
        let a = Procedural::Cloud.generate(32, 3).unwrap();
        let b = Procedural::Cloud.generate(32, 3).unwrap();
        let c = Procedural::Cloud.generate(32, 4).unwrap();
        assert_eq!(a.leaves.len(), b.leaves.len());
        assert!(a
            .leaves
            .iter()
            .zip(&b.leaves)
            .all(|(x, y)| x.values == y.values));
        let differs = a.leaves.len() != c.leaves.len()
            || a.leaves
                .iter()
                .zip(&c.leaves)
                .any(|(x, y)| x.values != y.values);
        assert!(differs);
    }

    #[test]
    fn level_sets_have_a_narrow_band_with_the_right_signs() {
        for kind in [Procedural::Box, Procedural::Torus] {
            let g = kind.generate(64, 1).unwrap();
            assert_eq!(g.class, GridClass::LevelSet);
            let bg = g.background;
            let (mut inside, mut outside) = (0, 0);
            for l in &g.leaves {
                for (i, &v) in l.values.iter().enumerate() {
                    assert!(v.abs() <= bg + 1e-6);
                    if l.is_active(i) {
                        assert!(v.abs() < bg);
                        inside += (v < 0.0) as u32;
                        outside += (v > 0.0) as u32;
                    }
                }
            }
            assert!(
                inside > 100 && outside > 100,
                "{kind:?}: {inside} / {outside}"
            );
        }
    }

    #[test]
    fn fog_kinds_are_non_negative_and_sparse_smoke_is_sparser_than_the_cloud() {
        let cloud = Procedural::Cloud.generate(64, 1).unwrap();
        let smoke = Procedural::Smoke.generate(64, 1).unwrap();
        for g in [&cloud, &smoke] {
            assert!(g.leaves.iter().all(|l| l.values.iter().all(|&v| v >= 0.0)));
            assert!(g.active_voxels() > 0);
        }
        assert!(smoke.active_voxels() * 2 < cloud.active_voxels());
        assert!(Procedural::Box.generate(8, 1).is_err());
        assert_eq!(Procedural::parse("torus"), Some(Procedural::Torus));
        assert_eq!(Procedural::parse("nope"), None);
    }
}
