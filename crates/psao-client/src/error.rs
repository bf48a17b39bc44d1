//! Typed errors of the client.

use psao_points::PointsError;

/// Why an update could not be applied. A rejected update leaves the client state untouched.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClientError {
    /// The update names an instance the instance table does not have.
    #[error("instance {instance} out of range ({count} instances)")]
    InstanceOutOfRange {
        /// The offending instance index.
        instance: u32,
        /// Number of instances in the table.
        count: usize,
    },
    /// The instance's layout in the table was unusable, so it has no grid to update.
    #[error("instance {instance} has no grid (its layout in the instance table is invalid)")]
    NoGrid {
        /// The instance index.
        instance: u32,
    },
    /// A transform with NaN or infinite entries.
    #[error("instance {instance}: transform is not finite")]
    NonFiniteTransform {
        /// The instance index.
        instance: u32,
    },
    /// A bucket index outside the instance's hash table.
    #[error("instance {instance}: bucket {bucket} out of range ({count} buckets)")]
    BucketOutOfRange {
        /// The instance index.
        instance: u32,
        /// The offending bucket index.
        bucket: u32,
        /// Number of buckets of the instance.
        count: u32,
    },
    /// A bucket entry whose key names no cell of the grid, a cell hashing to another bucket,
    /// or a key the bucket already holds.
    #[error("instance {instance}: bucket {bucket} has an entry with invalid cell key {key}")]
    InvalidBucketEntry {
        /// The instance index.
        instance: u32,
        /// The bucket index.
        bucket: u32,
        /// The offending key (cell id + 1).
        key: u64,
    },
    /// A cell slot (of a cell or of a bucket entry) that no bucket could ever reference.
    #[error("instance {instance}: cell slot {slot} out of range (at most {max} slots)")]
    CellSlotOutOfRange {
        /// The instance index.
        instance: u32,
        /// The offending slot.
        slot: u32,
        /// Number of addressable slots of the instance.
        max: usize,
    },
    /// Irradiance records that do not pair with the delta's cells one to one.
    #[error("instance {instance}: {lights} irradiance records for {cells} cells")]
    LightsMismatch {
        /// The instance index.
        instance: u32,
        /// Number of record arrays.
        lights: usize,
        /// Number of cells.
        cells: usize,
    },
    /// The point grid refused a change that validation accepted (an internal inconsistency;
    /// the update may then be partly applied).
    #[error("instance {instance}: {source}")]
    Grid {
        /// The instance index.
        instance: u32,
        /// The grid's error.
        source: PointsError,
    },
}
