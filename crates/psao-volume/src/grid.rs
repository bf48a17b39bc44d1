//! The in-memory sparse grid that ingest produces and the flat tree consumes: 8³ leaves in
//! index space plus the index-to-world transform.

use glam::{DVec3, IVec3, Vec3};

/// Voxels per brick edge.
pub const BRICK: usize = 8;
/// Voxels per brick.
pub const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;

/// Linear index of voxel (x, y, z) inside a brick: x fastest, z slowest.
#[inline]
pub fn voxel_index(x: usize, y: usize, z: usize) -> usize {
    x + BRICK * (y + BRICK * z)
}

/// Component-wise floor to integers without a libm call (inputs well inside the i32 range).
#[inline]
pub fn floor_ivec(p: glam::Vec3) -> IVec3 {
    let f = |x: f32| {
        let i = x as i32;
        i - ((i as f32) > x) as i32
    };
    IVec3::new(f(p.x), f(p.y), f(p.z))
}

/// What the values of a grid mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridClass {
    /// Fog volume: non-negative density, 0 outside.
    Fog,
    /// Narrow-band signed distance field: negative inside, zero on the surface.
    LevelSet,
}

impl GridClass {
    /// Lower-case name used in reports and files.
    pub fn name(self) -> &'static str {
        match self {
            GridClass::Fog => "fog",
            GridClass::LevelSet => "levelset",
        }
    }
}

/// Index-to-world map: `world = index * scale + translation` (voxel centres at integer indices).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Voxel size per axis (world units).
    pub scale: DVec3,
    /// World position of index (0, 0, 0).
    pub translation: DVec3,
}

impl Transform {
    /// World position of an index-space point.
    pub fn index_to_world(&self, p: Vec3) -> Vec3 {
        (p.as_dvec3() * self.scale + self.translation).as_vec3()
    }

    /// Index-space position of a world point.
    pub fn world_to_index(&self, p: Vec3) -> Vec3 {
        ((p.as_dvec3() - self.translation) / self.scale).as_vec3()
    }

    /// Index-space direction of a world direction, so that a ray parameter `t` means the same
    /// point in both spaces.
    pub fn world_dir_to_index(&self, d: Vec3) -> Vec3 {
        (d.as_dvec3() / self.scale).as_vec3()
    }
}

/// One 8³ leaf: values (layout of [`voxel_index`]) and the active-voxel mask (bit = index).
#[derive(Clone, Debug)]
pub struct Leaf {
    /// Index-space origin (multiple of 8).
    pub origin: IVec3,
    /// Voxel values.
    pub values: Box<[f32; BRICK_VOXELS]>,
    /// Active voxels, bit `voxel_index` of word `index / 64`.
    pub mask: [u64; 8],
}

impl Leaf {
    /// Whether voxel `i` is active.
    #[inline]
    pub fn is_active(&self, i: usize) -> bool {
        self.mask[i / 64] >> (i % 64) & 1 == 1
    }

    /// Number of active voxels.
    pub fn active_count(&self) -> u32 {
        self.mask.iter().map(|w| w.count_ones()).sum()
    }
}

/// An active tile of a fog volume: a cube of `span`³ voxels of one value (an OpenVDB tile of
/// a 4-level node spans 8, of a 5-level node 128). It is never expanded into leaves: a volume
/// stores one brick per distinct tile value and points the tile's 8³ cells at it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile {
    /// Index-space origin (a multiple of `span`).
    pub origin: IVec3,
    /// Voxels per edge: 8 or 128.
    pub span: i32,
    /// The value of all its voxels.
    pub value: f32,
}

impl Tile {
    /// Number of 8³ cells it covers.
    pub fn cells(&self) -> u64 {
        (self.span as u64 / BRICK as u64).pow(3)
    }

    /// Origins of its 8³ cells.
    pub fn cell_origins(&self) -> impl Iterator<Item = IVec3> + '_ {
        let n = self.span / BRICK as i32;
        (0..n * n * n)
            .map(move |i| self.origin + IVec3::new(i % n, (i / n) % n, i / (n * n)) * BRICK as i32)
    }
}

/// A sparse grid of one frame, as read from a file.
#[derive(Clone, Debug)]
pub struct SparseGrid {
    /// Grid name in the file.
    pub name: String,
    /// Fog or level set.
    pub class: GridClass,
    /// Index-to-world map.
    pub transform: Transform,
    /// Background value (outside the leaves).
    pub background: f32,
    /// Leaves sorted by origin (z, y, x).
    pub leaves: Vec<Leaf>,
    /// Active tiles (all voxels active), sorted by origin (z, y, x); they do not overlap
    /// the leaves.
    pub tiles: Vec<Tile>,
}

impl SparseGrid {
    /// A fog grid of constant `density` filling `leaves` 8³ leaves per axis from index 0, with
    /// cubic voxels of `voxel_size` at the world origin (a homogeneous medium: trilinear
    /// samples are exactly `density` for index coordinates in `0..=8·leaves − 1`).
    pub fn constant_fog(leaves: IVec3, voxel_size: f64, density: f32) -> SparseGrid {
        let mut out = Vec::new();
        for z in 0..leaves.z {
            for y in 0..leaves.y {
                for x in 0..leaves.x {
                    out.push(Leaf {
                        origin: IVec3::new(x, y, z) * BRICK as i32,
                        values: Box::new([density; BRICK_VOXELS]),
                        mask: [u64::MAX; 8],
                    });
                }
            }
        }
        SparseGrid {
            name: "density".into(),
            class: GridClass::Fog,
            transform: Transform {
                scale: DVec3::splat(voxel_size),
                translation: DVec3::ZERO,
            },
            background: 0.0,
            leaves: out,
            tiles: Vec::new(),
        }
    }

    /// Number of active voxels (of the leaves and the tiles).
    pub fn active_voxels(&self) -> u64 {
        let leaves: u64 = self.leaves.iter().map(|l| l.active_count() as u64).sum();
        leaves
            + self
                .tiles
                .iter()
                .map(|t| (t.span as u64).pow(3))
                .sum::<u64>()
    }

    /// Index-space bounds of the leaves and tiles: (min corner, max corner exclusive), or
    /// `None` if empty.
    pub fn leaf_bounds(&self) -> Option<(IVec3, IVec3)> {
        let boxes = self.leaves.iter().map(|l| (l.origin, BRICK as i32));
        let mut it = boxes.chain(self.tiles.iter().map(|t| (t.origin, t.span)));
        let (o, span) = it.next()?;
        let init = (o, o + IVec3::splat(span));
        Some(it.fold(init, |(lo, hi), (o, span)| {
            (lo.min(o), hi.max(o + IVec3::splat(span)))
        }))
    }
}
