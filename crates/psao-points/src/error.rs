//! Typed errors of the point representation.

use glam::Vec3;

/// Everything that can go wrong when generating points or building and updating a grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointsError {
    /// The requested point density is not a finite positive number.
    #[error("invalid point density {0}: must be finite and > 0")]
    InvalidDensity(f32),
    /// The adaptive placement's largest density boost is not a finite number ≥ 1.
    #[error("invalid adaptive density boost {0}: must be finite and >= 1")]
    InvalidBoost(f32),
    /// A triangle references a vertex that does not exist.
    #[error("triangle {triangle} references vertex {index}, but the mesh has {count} positions")]
    IndexOutOfRange {
        /// Triangle index in the mesh.
        triangle: u32,
        /// The offending vertex index.
        index: u32,
        /// Number of positions in the mesh.
        count: usize,
    },
    /// A triangle has non-finite coordinates (before or after the instance transform).
    #[error("triangle {0} has non-finite coordinates")]
    NonFiniteGeometry(u32),
    /// The instance would need more points than an instance can index.
    #[error("instance needs {requested} points; at most {max} are supported")]
    TooManyPoints {
        /// Points that would have been spawned.
        requested: f64,
        /// The limit.
        max: u32,
    },
    /// A scene instance references a mesh that does not exist.
    #[error("instance {instance} references mesh {mesh}, but the scene has {count} meshes")]
    MeshOutOfRange {
        /// Instance index.
        instance: usize,
        /// The offending mesh index.
        mesh: usize,
        /// Number of meshes.
        count: usize,
    },
    /// Grid parameters are unusable (non-finite or non-positive radius, inverted bounds, ...).
    #[error("invalid grid parameters: {0}")]
    InvalidGrid(&'static str),
    /// The grid would have more cells per axis than cell ids can address.
    #[error("grid too large: {dims:?} cells for bounds extent {extent:?}")]
    GridTooLarge {
        /// Requested cells per axis (saturated).
        dims: [u64; 3],
        /// Bounding-box extent in local units.
        extent: Vec3,
    },
    /// A bucket index outside the hash table.
    #[error("bucket {index} out of range ({count} buckets)")]
    BucketOutOfRange {
        /// The offending index.
        index: usize,
        /// Number of buckets.
        count: usize,
    },
    /// A cell slot that no bucket could ever reference.
    #[error("cell slot {slot} out of range (at most {max} slots)")]
    CellSlotOutOfRange {
        /// The offending slot.
        slot: u32,
        /// Number of addressable slots (buckets × entries per bucket).
        max: usize,
    },
    /// Overflow: the cell's hash bucket has no free entry, so the cell cannot be allocated.
    #[error("hash bucket {bucket} is full")]
    BucketFull {
        /// The full bucket.
        bucket: usize,
    },
    /// Overflow: the cell already holds the maximum number of points.
    #[error("cell slot {slot} is full")]
    CellFull {
        /// The full cell.
        slot: u32,
    },
    /// The position lies outside the instance's grid.
    #[error("position {0} lies outside the grid")]
    OutsideGrid(Vec3),
    /// A received bucket entry names a cell that does not exist, hashes elsewhere, or is
    /// already in the bucket.
    #[error("bucket {bucket} has an entry with invalid cell key {key}")]
    InvalidBucketEntry {
        /// Bucket index.
        bucket: usize,
        /// The offending key (cell id + 1).
        key: u64,
    },
    /// A grid's bucket table would hold more entries than it can index.
    #[error("bucket table full: at most {max} entries")]
    TooManyEntries {
        /// Most entries a table holds.
        max: usize,
    },
    /// A point location that does not hold a point.
    #[error("no point at cell slot {slot}, index {index}")]
    NoSuchPoint {
        /// Cell slot.
        slot: u32,
        /// Index inside the cell.
        index: u8,
    },
}
