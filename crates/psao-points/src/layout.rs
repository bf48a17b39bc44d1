//! Geometry of an instance's virtual grid: cell size, dimensions, cell ids and hash buckets
//! (DESIGN §3 "Grid", paper §3.2).

use glam::{IVec3, UVec3, Vec3};

use crate::error::PointsError;
#[cfg(feature = "generate")]
use crate::generate::InstancePoints;
use crate::pack::{pack_point, unpack_frac, unpack_point};

/// Entries per hash bucket.
pub const BUCKET_ENTRIES: usize = 8;
/// Points per cell.
pub const CELL_POINTS: usize = 7;
/// Cell size in units of the instance's (grid) Poisson radius.
pub const CELL_RADIUS_FACTOR: f32 = 4.0;
/// Hash-table sizing: buckets for this many times the expected cells, divided by
/// [`BUCKET_ENTRIES`].
pub const TABLE_OVERSIZE: f64 = 4.0;
/// Expected number of cubes of side `c` a surface of area `A` crosses, in units of `A / c²`:
/// a plane with unit normal n crosses `A·(|n_x|+|n_y|+|n_z|)/c²` cells, whose mean over all
/// orientations is 1.5.
pub const CELLS_PER_AREA: f64 = 1.5;
/// Most cells per axis.
pub const MAX_DIM: u32 = 1 << 21;

/// A point decoded from its cell, in the instance's local space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecodedPoint {
    /// Local position (centre of its quantisation step).
    pub position: Vec3,
    /// Local unit normal.
    pub normal: Vec3,
    /// Ambient occlusion in [0, 1].
    pub ao: f32,
}

/// Everything a client needs to address an instance's grid (sent once, in the welcome).
///
/// Cell `(x, y, z)` covers `origin + [x, x+1) · cell_size` (likewise y, z). Its id is the
/// paper's hash-friendly `id = x + y·Dx·17 + z·Dx·Dy·31` (Eq. 1): unique for x < Dx, y < Dy
/// (the y term steps by 17·Dx > any x, the z term by 31·Dx·Dy > any x + y term), and spreading
/// neighbouring rows and slices over the table. Its bucket is `id mod bucket_count`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridLayout {
    /// Local-space corner of cell (0, 0, 0): the minimum of the instance's local bounds.
    pub origin: Vec3,
    /// Edge length of a cell, local units.
    pub cell_size: f32,
    /// Cells per axis (Dx, Dy, Dz), each ≥ 1.
    pub dims: UVec3,
    /// Poisson radius of one side's points in local units; reconstruction radius =
    /// this × interpolation factor.
    pub poisson_radius: f32,
    /// Number of hash buckets, a power of two.
    pub bucket_count: u32,
}

impl GridLayout {
    /// A layout over local `bounds` (min, max) with the given cell size, sizing the hash table
    /// for a surface of `surface_area` local units² (see [`CELLS_PER_AREA`], [`TABLE_OVERSIZE`]).
    /// `poisson_radius` may be 0 (an instance without points).
    pub fn new(
        bounds: (Vec3, Vec3),
        poisson_radius: f32,
        cell_size: f32,
        surface_area: f32,
    ) -> Result<Self, PointsError> {
        let (lo, hi) = bounds;
        if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
            return Err(PointsError::InvalidGrid(
                "bounds must be finite with min <= max",
            ));
        }
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return Err(PointsError::InvalidGrid("cell size must be finite and > 0"));
        }
        if !(poisson_radius.is_finite() && poisson_radius >= 0.0) {
            return Err(PointsError::InvalidGrid(
                "Poisson radius must be finite and >= 0",
            ));
        }
        if !(surface_area.is_finite() && surface_area >= 0.0) {
            return Err(PointsError::InvalidGrid(
                "surface area must be finite and >= 0",
            ));
        }
        let extent = hi - lo;
        // floor + 1 (not ceil) so a point exactly on the max face still has a cell.
        let cells = (extent * (1.0 / cell_size)).floor() + 1.0;
        let dims64 = [cells.x, cells.y, cells.z].map(|c| c.min(u64::MAX as f32) as u64);
        let too_large = dims64.iter().any(|&d| d > u64::from(MAX_DIM))
            || 31 * u128::from(dims64[0]) * u128::from(dims64[1]) * u128::from(dims64[2])
                >= u128::from(u64::MAX);
        let expected = CELLS_PER_AREA * f64::from(surface_area) / f64::from(cell_size).powi(2);
        let buckets = (TABLE_OVERSIZE * expected / BUCKET_ENTRIES as f64)
            .ceil()
            .max(1.0);
        if too_large || buckets > f64::from(1u32 << 31) {
            return Err(PointsError::GridTooLarge {
                dims: dims64,
                extent,
            });
        }
        Ok(Self {
            origin: lo,
            cell_size,
            dims: UVec3::new(dims64[0] as u32, dims64[1] as u32, dims64[2] as u32),
            poisson_radius,
            bucket_count: (buckets as u32).next_power_of_two(),
        })
    }

    /// The layout DESIGN §3 prescribes for generated points: the instance's local bounds
    /// (padded by 1/1000 of a cell against rounding of interpolated positions), cell size =
    /// [`CELL_RADIUS_FACTOR`] × [`InstancePoints::grid_radius_local`], table sized from the local
    /// surface area. An instance without points gets a single-cell grid.
    #[cfg(feature = "generate")]
    pub fn for_points(points: &InstancePoints) -> Result<Self, PointsError> {
        let (lo, hi) = points.local_bounds;
        let grid_radius = points.grid_radius_local();
        let cell = if grid_radius > 0.0 {
            CELL_RADIUS_FACTOR * grid_radius
        } else {
            (hi - lo).max_element().max(f32::MIN_POSITIVE) * 2.0
        };
        let pad = Vec3::splat(1e-3 * cell);
        Self::new(
            (lo - pad, hi + pad),
            points.poisson_radius_local,
            cell,
            points.area_local,
        )
    }

    /// Addressable cell slots: every bucket entry can reference one cell.
    pub fn max_cells(&self) -> usize {
        self.bucket_count as usize * BUCKET_ENTRIES
    }

    /// Continuous grid coordinates of a local position (cell units from the origin).
    #[inline]
    pub fn grid_coords(&self, p: Vec3) -> Vec3 {
        (p - self.origin) * (1.0 / self.cell_size)
    }

    /// The cell containing local position `p`, or `None` outside the grid.
    #[inline]
    pub fn cell_coord(&self, p: Vec3) -> Option<UVec3> {
        let f = self.grid_coords(p).floor();
        let inside = f.cmpge(Vec3::ZERO).all() && f.cmplt(self.dims.as_vec3()).all();
        inside.then(|| f.as_uvec3())
    }

    /// Lowest corner of the 2×2×2 block of cells whose centres surround `p` (may lie outside
    /// the grid; callers skip cells out of range).
    #[inline]
    pub fn nearest_base(&self, p: Vec3) -> IVec3 {
        let f = (self.grid_coords(p) - 0.5).floor();
        // Saturating float → int cast keeps far-away or NaN inputs harmless.
        IVec3::new(f.x as i32, f.y as i32, f.z as i32)
    }

    /// The cell at integer coordinates `c`, if inside the grid.
    #[inline]
    pub fn checked_coord(&self, c: IVec3) -> Option<UVec3> {
        let inside = c.cmpge(IVec3::ZERO).all() && c.as_uvec3().cmplt(self.dims).all();
        inside.then(|| c.as_uvec3())
    }

    /// Cell id of Eq. 1: `x + y·Dx·17 + z·Dx·Dy·31`.
    #[inline]
    pub fn cell_id(&self, c: UVec3) -> u64 {
        let (dx, dy) = (u64::from(self.dims.x), u64::from(self.dims.y));
        u64::from(c.x) + u64::from(c.y) * dx * 17 + u64::from(c.z) * dx * dy * 31
    }

    /// Inverse of [`Self::cell_id`]; `None` for ids no cell of this grid has.
    pub fn coord_of_id(&self, id: u64) -> Option<UVec3> {
        let (dx, dy) = (u64::from(self.dims.x), u64::from(self.dims.y));
        let slice = dx * dy * 31;
        let row = dx * 17;
        let (z, rem) = (id / slice, id % slice);
        let (y, x) = (rem / row, rem % row);
        let c = UVec3::new(x as u32, y as u32, z.min(u64::from(u32::MAX)) as u32);
        (x < dx && y < dy && z < u64::from(self.dims.z)).then_some(c)
    }

    /// Hash bucket of a cell id: `id mod bucket_count`.
    #[inline]
    pub fn bucket_of(&self, id: u64) -> usize {
        (id & u64::from(self.bucket_count - 1)) as usize
    }

    /// Local-space minimum corner of cell `c`.
    #[inline]
    pub fn cell_min(&self, c: UVec3) -> Vec3 {
        self.origin + c.as_vec3() * self.cell_size
    }

    /// Pack a point that lies in cell `c` (positions outside clamp to the cell's border).
    #[inline]
    pub fn pack(&self, c: UVec3, position: Vec3, normal: Vec3, ao: f32) -> u32 {
        pack_point(self.grid_coords(position) - c.as_vec3(), normal, ao)
    }

    /// Local position of a packed point stored in cell `c`.
    #[inline]
    pub fn unpack_position(&self, c: UVec3, bits: u32) -> Vec3 {
        self.origin + (c.as_vec3() + unpack_frac(bits)) * self.cell_size
    }

    /// Decode a packed point stored in cell `c`; `None` for an empty entry.
    pub fn unpack(&self, c: UVec3, bits: u32) -> Option<DecodedPoint> {
        unpack_point(bits).map(|u| DecodedPoint {
            position: self.origin + (c.as_vec3() + u.frac) * self.cell_size,
            normal: u.normal,
            ao: u.ao,
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// 21 × 6 × 11 cells, 16 buckets (128 slots): the layout the crate's unit tests share.
    pub(crate) fn layout() -> GridLayout {
        GridLayout::new(
            (Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 0.5, 3.0)),
            0.025,
            0.1,
            3.0,
        )
        .unwrap()
    }

    #[test]
    fn dims_and_table_size() {
        let l = layout();
        assert_eq!(l.dims, UVec3::new(21, 6, 11));
        // 1.5 · 3 / 0.01 = 450 expected cells → 4 · 450 / 8 = 225 → 256 buckets.
        assert_eq!(l.bucket_count, 256);
        assert_eq!(l.max_cells(), 2048);
    }

    #[test]
    fn cell_ids_are_unique_and_invertible() {
        let l = layout();
        let mut seen = std::collections::HashSet::new();
        for x in 0..l.dims.x {
            for y in 0..l.dims.y {
                for z in 0..l.dims.z {
                    let c = UVec3::new(x, y, z);
                    let id = l.cell_id(c);
                    assert!(seen.insert(id), "duplicate id {id}");
                    assert_eq!(l.coord_of_id(id), Some(c));
                }
            }
        }
        assert_eq!(l.cell_id(UVec3::new(2, 1, 1)), 2 + 21 * 17 + 21 * 6 * 31);
        assert_eq!(l.coord_of_id(u64::MAX), None);
        assert_eq!(l.coord_of_id(30), None, "x >= Dx is not a cell");
    }

    #[test]
    fn coords_and_bounds() {
        let l = layout();
        assert_eq!(l.cell_coord(Vec3::new(-1.0, 0.0, 2.0)), Some(UVec3::ZERO));
        assert!(
            l.cell_coord(Vec3::new(1.0, 0.5, 3.0)).is_some(),
            "max corner"
        );
        assert_eq!(l.cell_coord(Vec3::new(-1.01, 0.0, 2.0)), None);
        assert_eq!(l.cell_coord(Vec3::NAN), None);
        // Centres of cells 3 and 4 (3.5, 4.5) surround x = 4.3; of 2 and 3 surround y = 2.7.
        let p = l.origin + Vec3::new(4.3, 2.7, 0.6) * l.cell_size;
        assert_eq!(l.nearest_base(p), IVec3::new(3, 2, 0));
        assert_eq!(l.checked_coord(IVec3::new(-1, 0, 0)), None);
        assert_eq!(
            l.checked_coord(IVec3::new(20, 5, 10)),
            Some(UVec3::new(20, 5, 10))
        );
        assert_eq!(l.checked_coord(IVec3::new(21, 5, 10)), None);
    }

    #[test]
    fn pack_roundtrip_in_cell() {
        let l = layout();
        let p = Vec3::new(0.123, 0.321, 2.555);
        let c = l.cell_coord(p).unwrap();
        let bits = l.pack(c, p, Vec3::Y, 0.25);
        let d = l.unpack(c, bits).unwrap();
        let half_step = l.cell_size / 64.0;
        assert!((d.position - p).abs().max_element() <= half_step + 1e-6);
        assert_eq!(l.unpack_position(c, bits), d.position);
    }

    #[test]
    fn rejects_bad_parameters() {
        let b = (Vec3::ZERO, Vec3::ONE);
        assert!(GridLayout::new(b, 0.1, 0.0, 1.0).is_err());
        assert!(GridLayout::new(b, f32::NAN, 0.1, 1.0).is_err());
        assert!(GridLayout::new((Vec3::ONE, Vec3::ZERO), 0.1, 0.1, 1.0).is_err());
        assert!(GridLayout::new(b, 0.1, 0.1, -1.0).is_err());
        assert!(matches!(
            GridLayout::new((Vec3::ZERO, Vec3::splat(1e6)), 0.1, 1e-3, 1.0),
            Err(PointsError::GridTooLarge { .. })
        ));
        let single = GridLayout::new((Vec3::ONE, Vec3::ONE), 0.0, 1.0, 0.0).unwrap();
        assert_eq!(single.dims, UVec3::ONE);
        assert_eq!(single.bucket_count, 1);
    }
}
