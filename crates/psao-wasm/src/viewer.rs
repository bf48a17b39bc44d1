//! One session's decoder and client state: the welcome's table, then every update payload
//! decoded and applied in order, as psao-net's client does for `psao view`.

use psao_client::{ClientError, ClientState};
use psao_delta::{Codec, CompactCodec, DeltaError, InstanceInfo, MAX_TOTAL_BUCKETS};

use crate::changes::write_changes;

/// Why a table or an update was refused. After an update error the session must end (the
/// decoder's reference and the state may no longer be the server's).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewerError {
    /// The table's grids would take more buckets than a client accepts.
    #[error("the instance table asks for {buckets} hash buckets (limit {MAX_TOTAL_BUCKETS})")]
    TableTooLarge {
        /// Buckets over all instances.
        buckets: u64,
    },
    /// The payload is not a valid `compact` update.
    #[error("undecodable update: {0}")]
    Decode(#[from] DeltaError),
    /// The update's snapshot flag is not that of the message carrying it.
    #[error("the update's snapshot flag does not match its message")]
    SnapshotFlag,
    /// The update does not fit the state (nothing was changed).
    #[error("update not applicable: {0}")]
    Apply(#[from] ClientError),
}

impl ViewerError {
    /// The status code the C ABI returns for this error (0 is success).
    pub fn code(&self) -> u32 {
        match self {
            Self::TableTooLarge { .. } => 1,
            Self::Decode(_) => 2,
            Self::SnapshotFlag => 3,
            Self::Apply(_) => 4,
        }
    }
}

/// A session's decoder, state and the changes of its last update.
pub struct Viewer {
    codec: CompactCodec,
    state: ClientState,
    changes: Vec<u32>,
}

impl Viewer {
    /// An empty state for the welcome's `table`, the decoder limited to what updates for it
    /// can take (psao-net's rules: [`psao_delta::decode_limit`], [`MAX_TOTAL_BUCKETS`]).
    pub fn new(table: &[InstanceInfo]) -> Result<Self, ViewerError> {
        let buckets = psao_delta::total_buckets(table);
        if buckets > MAX_TOTAL_BUCKETS {
            return Err(ViewerError::TableTooLarge { buckets });
        }
        let mut codec = CompactCodec::new();
        codec.set_decode_limit(psao_delta::decode_limit(table));
        Ok(Self {
            codec,
            state: ClientState::new(table),
            changes: Vec::new(),
        })
    }

    /// Decodes `payload` (a delta or snapshot message's, `snapshot` telling which) and applies
    /// it; [`Self::changes`] then lists what it changed.
    pub fn apply(&mut self, payload: &[u8], snapshot: bool) -> Result<(), ViewerError> {
        self.changes.clear();
        let update = self.codec.decode(payload)?;
        if update.snapshot != snapshot {
            return Err(ViewerError::SnapshotFlag);
        }
        self.state.apply(&update)?;
        write_changes(&self.state, &update, &mut self.changes);
        Ok(())
    }

    /// The client state.
    pub fn state(&self) -> &ClientState {
        &self.state
    }

    /// The records of what the last applied update changed ([`crate::changes`]); empty after
    /// an error.
    pub fn changes(&self) -> &[u32] {
        &self.changes
    }
}

#[cfg(test)]
mod tests {
    use glam::{Affine3A, UVec3, Vec3};
    use psao_delta::{GridLayout, InstanceDelta, Update};
    use psao_points::{Bucket, BucketEntry, Cell};

    use super::*;
    use crate::changes::{BUCKET, CELL, RESET};

    fn table() -> Vec<InstanceInfo> {
        let layout = GridLayout {
            origin: Vec3::ZERO,
            cell_size: 0.5,
            dims: UVec3::new(4, 4, 4),
            poisson_radius: 0.1,
            bucket_count: 16,
        };
        vec![
            InstanceInfo {
                layout,
                poisson_radius: 0.1,
                point_count: 3,
            };
            2
        ]
    }

    /// An update putting cell id `id` of instance 1 into slot `slot` with `points`.
    fn update(frame: u64, snapshot: bool, id: u64, slot: u32, points: &[u32]) -> Update {
        let layout = table()[1].layout;
        let mut bucket = Bucket::default();
        bucket.entries[0] = BucketEntry { key: id + 1, slot };
        let mut cell = Cell::default();
        cell.points[..points.len()].copy_from_slice(points);
        Update {
            frame,
            snapshot,
            transforms: vec![(1, Affine3A::from_translation(Vec3::X))],
            instances: vec![InstanceDelta {
                instance: 1,
                buckets: vec![(layout.bucket_of(id) as u32, bucket)],
                cells: vec![(slot, cell)],
                lights: Vec::new(),
            }],
        }
    }

    fn valid(i: u32) -> u32 {
        psao_points::pack::VALID_BIT | i
    }

    #[test]
    fn updates_apply_like_the_client_state_and_list_their_changes() {
        let mut encoder = CompactCodec::new();
        let mut viewer = Viewer::new(&table()).unwrap();
        let mut reference = ClientState::new(&table());
        let first = update(1, true, 1, 0, &[valid(1), valid(2)]);
        let second = update(2, false, 2, 1, &[valid(3)]);
        for u in [&first, &second] {
            viewer.apply(&encoder.encode(u), u.snapshot).unwrap();
            reference.apply(u).unwrap();
            assert_eq!(viewer.state().state_hash(), reference.state_hash());
        }
        assert_eq!(
            viewer.state().transform(1),
            Some(Affine3A::from_translation(Vec3::X))
        );
        let bucket = table()[1].layout.bucket_of(2) as u32;
        let mut expected = vec![BUCKET, 1, bucket, 1, 3, 0, 1, CELL, 1, 1, valid(3)];
        expected.extend([0; 6 + 7]);
        assert_eq!(viewer.changes(), expected);
    }

    #[test]
    fn a_snapshot_lists_the_whole_state_after_a_reset() {
        let mut encoder = CompactCodec::new();
        let mut viewer = Viewer::new(&table()).unwrap();
        let u = update(1, true, 1, 2, &[valid(7)]);
        viewer.apply(&encoder.encode(&u), true).unwrap();
        let bucket = table()[1].layout.bucket_of(1) as u32;
        let mut expected = vec![RESET, BUCKET, 1, bucket, 1, 2, 0, 2, CELL, 1, 2, valid(7)];
        expected.extend([0; 6 + 7]);
        assert_eq!(viewer.changes(), expected);
    }

    #[test]
    fn lit_updates_keep_their_records_and_list_them_with_the_cells() {
        let mut encoder = CompactCodec::new();
        let mut viewer = Viewer::new(&table()).unwrap();
        let mut reference = ClientState::new(&table());
        let record = psao_points::irradiance::pack_rgb9e5(Vec3::new(0.5, 1.0, 2.0));
        let mut lit = update(1, true, 1, 2, &[valid(7), valid(8)]);
        lit.instances[0].lights = vec![[record, 7, 0, 0, 0, 0, 0]];
        viewer.apply(&encoder.encode(&lit), true).unwrap();
        reference.apply(&lit).unwrap();
        assert!(viewer.state().has_lights());
        assert_eq!(viewer.state().state_hash(), reference.state_hash());
        let mut plain = ClientState::new(&table());
        plain
            .apply(&update(1, true, 1, 2, &[valid(7), valid(8)]))
            .unwrap();
        assert_ne!(
            viewer.state().state_hash(),
            plain.state_hash(),
            "the hash covers the records"
        );
        let bucket = table()[1].layout.bucket_of(1) as u32;
        let mut expected = vec![
            RESET,
            BUCKET,
            1,
            bucket,
            1,
            2,
            0,
            2,
            CELL,
            1,
            2,
            valid(7),
            valid(8),
        ];
        expected.extend([0; 5]);
        expected.extend([record, 7, 0, 0, 0, 0, 0]);
        assert_eq!(viewer.changes(), expected);
        // A delta changing the cell without records clears them, as the client state does.
        let mut next = update(2, false, 1, 2, &[valid(9)]);
        next.instances[0].buckets.clear();
        viewer.apply(&encoder.encode(&next), false).unwrap();
        reference.apply(&next).unwrap();
        assert_eq!(viewer.state().state_hash(), reference.state_hash());
        let mut expected = vec![CELL, 1, 2, valid(9)];
        expected.extend([0; 6 + 7]);
        assert_eq!(viewer.changes(), expected);
    }

    #[test]
    fn bad_payloads_and_flags_are_typed_errors() {
        let mut viewer = Viewer::new(&table()).unwrap();
        let err = viewer.apply(b"garbage", false).unwrap_err();
        assert!(
            matches!(err, ViewerError::Decode(DeltaError::UnknownSize)),
            "{err}"
        );
        assert_eq!(err.code(), 2);
        let bytes = CompactCodec::new().encode(&update(1, true, 1, 0, &[valid(1)]));
        assert_eq!(viewer.apply(&bytes, false), Err(ViewerError::SnapshotFlag));
        // A slot past what the layout addresses: decoded, then refused by the state.
        let mut viewer = Viewer::new(&table()).unwrap();
        let bytes = CompactCodec::new().encode(&update(1, true, 1, 130, &[valid(1)]));
        let err = viewer.apply(&bytes, true).unwrap_err();
        assert!(matches!(err, ViewerError::Apply(_)), "{err}");
        assert!(viewer.changes().is_empty());
    }

    #[test]
    fn a_table_past_the_bucket_limit_is_refused() {
        let mut big = table();
        big[0].layout.bucket_count = 1 << 23;
        let err = Viewer::new(&big).err().unwrap();
        assert_eq!(err.code(), 1);
    }
}
