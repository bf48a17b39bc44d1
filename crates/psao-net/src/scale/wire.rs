//! The payloads trace nodes and edges exchange through NATS (docs/SCALE-OUT.md): record
//! batches (sent compressed, in parts: [`BatchPart`], [`super::parts`]), snapshot chunks and
//! marks, and view sets, little-endian binary with a magic and a version. Decoding checks
//! every length against the message before allocating, so a malformed message is an error,
//! never a panic or a huge allocation.

use glam::Vec3;
use psao_scene::Camera;
use psao_server::{PointRecord, PointState, View};

/// Magic of a record batch.
const BATCH_MAGIC: &[u8; 4] = b"PSRB";
/// Magic of a part of a compressed record batch.
const PART_MAGIC: &[u8; 4] = b"PSRP";
/// Magic of a view set.
const VIEWS_MAGIC: &[u8; 4] = b"PSVW";
/// Magic of a snapshot chunk.
const SNAPSHOT_MAGIC: &[u8; 4] = b"PSSN";
/// Magic of a snapshot mark.
const MARK_MAGIC: &[u8; 4] = b"PSSM";
/// Version of the batches, view sets and snapshot marks.
const VERSION: u8 = 1;
/// Version of the snapshot chunks (2: with sample counts).
const SNAPSHOT_VERSION: u8 = 2;
/// Bytes of a batch before its records, and of one record.
const BATCH_HEADER: usize = 4 + 1 + 4 + 4 + 8 + 8 + 4;
const RECORD_BYTES: usize = 12;
/// Bytes of a batch part before its slice of the compressed batch.
pub const PART_HEADER: usize = 4 + 1 + 4 + 4 + 8 + 4 + 4;
/// Most parts of one batch.
pub const MAX_PARTS: u32 = 1024;
/// Bytes of a snapshot chunk before its points, and of one point (record and samples).
const SNAPSHOT_HEADER: usize = 4 + 1 + 4 * 4 + 8 + 8 + 8 + 4;
const POINT_BYTES: usize = RECORD_BYTES + 2;
/// Bytes of a snapshot mark.
const MARK_BYTES: usize = 4 + 1 + 3 * 4 + 8 + 8 + 8;
/// Points of a partition per snapshot chunk (every node of a session must use the same):
/// small enough that a round republishes little beside the points that changed, large
/// enough to keep the subjects few (some 370 for Sponza's 1.5 M points).
pub const CHUNK_POINTS: usize = 4096;
/// Most points a snapshot chunk may hold: 14 bytes each, so a chunk stays under NATS's
/// default 1 MiB payload limit.
pub const MAX_CHUNK_POINTS: usize = 65536;
/// Bytes of a view set before its views, and of one view.
const VIEWS_HEADER: usize = 4 + 1 + 8 + 8 + 4;
const VIEW_BYTES: usize = 13 * 4;
/// Most views in one view set (an edge sends the union of its viewers' views).
pub const MAX_VIEWS: usize = 4096;

/// One server frame's records of one partition.
#[derive(Clone, Debug, PartialEq)]
pub struct Batch {
    /// The partition that published them, and the number of partitions.
    pub partition: u32,
    pub partitions: u32,
    /// Server frame (1 for the first step).
    pub frame: u64,
    /// Scene time of the frame, seconds.
    pub seconds: f64,
    /// The points published, in (instance, index) order.
    pub records: Vec<PointRecord>,
}

/// One part of a record batch as published: the batch's payload ([`Batch::encode`]),
/// compressed, cut into `parts` slices; this is slice `part` ([`super::parts`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BatchPart {
    /// The batch's partition, and the number of partitions.
    pub partition: u32,
    pub partitions: u32,
    /// The batch's server frame.
    pub frame: u64,
    /// This part, and the batch's number of parts (at most [`MAX_PARTS`]).
    pub part: u32,
    pub parts: u32,
    /// The part's slice of the compressed batch.
    pub data: Vec<u8>,
}

/// One chunk of the published records of a partition's points at one server frame, with
/// their sample counts: a joining edge or trace node starts from every chunk's latest
/// message instead of the whole history.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// The partition, and the number of partitions.
    pub partition: u32,
    pub partitions: u32,
    /// This chunk, and the partition's number of chunks (see [`CHUNK_POINTS`]).
    pub chunk: u32,
    pub chunks: u32,
    /// The server frame the records are the state of, and its scene time, seconds.
    pub frame: u64,
    pub seconds: f64,
    /// Records-stream sequence number of the partition's batch of `frame`: the partition's
    /// later batches follow it.
    pub sequence: u64,
    /// The published records of the chunk's points (stored ones only), in (instance,
    /// index) order, with their sample counts (sent as 16 bits: larger counts saturate); at
    /// most [`MAX_CHUNK_POINTS`].
    pub points: Vec<PointState>,
}

/// Published after a trace node's snapshot round of one partition at `frame`: every chunk
/// of the partition whose points changed since its previous message was published again
/// at `frame` (and stored) before this mark, so the latest message of every chunk is the
/// state of its points at `frame` or later.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotMark {
    /// The partition, and the number of partitions.
    pub partition: u32,
    pub partitions: u32,
    /// The partition's number of chunks.
    pub chunks: u32,
    /// The frame of the round, and its scene time, seconds.
    pub frame: u64,
    pub seconds: f64,
    /// Records-stream sequence number of the partition's batch of `frame`.
    pub sequence: u64,
}

/// The views an edge's viewers had for one server frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSet {
    /// The server frame they are for.
    pub frame: u64,
    /// Its scene time, seconds.
    pub seconds: f64,
    /// The distinct views.
    pub views: Vec<View>,
}

/// Why a payload was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("malformed {what}: {reason}")]
pub struct PayloadError {
    what: &'static str,
    reason: String,
}

pub(super) fn fail(what: &'static str, reason: impl Into<String>) -> PayloadError {
    PayloadError {
        what,
        reason: reason.into(),
    }
}

/// Reads little-endian fields from a byte slice.
struct Reader<'a> {
    bytes: &'a [u8],
    what: &'static str,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], PayloadError> {
        if self.bytes.len() < N {
            return Err(fail(self.what, "truncated"));
        }
        let (head, rest) = self.bytes.split_at(N);
        self.bytes = rest;
        Ok(head.try_into().expect("N bytes"))
    }
    fn u32(&mut self) -> Result<u32, PayloadError> {
        self.take().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Result<u64, PayloadError> {
        self.take().map(u64::from_le_bytes)
    }
    fn f64(&mut self) -> Result<f64, PayloadError> {
        self.take().map(f64::from_le_bytes)
    }
    fn f32(&mut self) -> Result<f32, PayloadError> {
        self.take().map(f32::from_le_bytes)
    }
    fn vec3(&mut self) -> Result<Vec3, PayloadError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }
    /// The magic and version, checked.
    fn header(&mut self, magic: &[u8; 4]) -> Result<(), PayloadError> {
        self.header_version(magic, VERSION)
    }
    /// The magic and a version other than [`VERSION`], checked.
    fn header_version(&mut self, magic: &[u8; 4], want: u8) -> Result<(), PayloadError> {
        if &self.take::<4>()? != magic {
            return Err(fail(self.what, "wrong magic"));
        }
        let [version] = self.take::<1>()?;
        if version != want {
            return Err(fail(self.what, format!("version {version}, not {want}")));
        }
        Ok(())
    }
    fn u16(&mut self) -> Result<u16, PayloadError> {
        self.take().map(u16::from_le_bytes)
    }
    /// A partition and partition count, checked.
    fn partition(&mut self) -> Result<(u32, u32), PayloadError> {
        let (partition, partitions) = (self.u32()?, self.u32()?);
        if partitions == 0 || partition >= partitions {
            return Err(fail(
                self.what,
                format!("partition {partition} of {partitions}"),
            ));
        }
        Ok((partition, partitions))
    }
    /// A count of items of `size` bytes that must fill the rest exactly.
    fn count(&mut self, size: usize, max: usize) -> Result<usize, PayloadError> {
        let n = self.u32()? as usize;
        if n > max || n.checked_mul(size) != Some(self.bytes.len()) {
            return Err(fail(
                self.what,
                format!(
                    "{n} items do not fit its {} remaining bytes",
                    self.bytes.len()
                ),
            ));
        }
        Ok(n)
    }
}

/// Appends a record count and the records.
fn put_records(out: &mut Vec<u8>, records: &[PointRecord]) {
    out.extend_from_slice(&(records.len() as u32).to_le_bytes());
    for r in records {
        for v in [r.instance, r.index, r.bits] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

impl Reader<'_> {
    /// A record count (at most `max`) and the records, filling the rest exactly.
    fn records(&mut self, max: usize) -> Result<Vec<PointRecord>, PayloadError> {
        let n = self.count(RECORD_BYTES, max)?;
        let mut records = Vec::with_capacity(n);
        for _ in 0..n {
            records.push(PointRecord {
                instance: self.u32()?,
                index: self.u32()?,
                bits: self.u32()?,
            });
        }
        Ok(records)
    }
}

impl Snapshot {
    /// Bytes of the payload of a chunk of `points` points.
    pub fn encoded_len(points: usize) -> usize {
        SNAPSHOT_HEADER + points * POINT_BYTES
    }

    /// The payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(SNAPSHOT_HEADER + self.points.len() * POINT_BYTES);
        out.extend_from_slice(SNAPSHOT_MAGIC);
        out.push(SNAPSHOT_VERSION);
        for v in [self.partition, self.partitions, self.chunk, self.chunks] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.seconds.to_le_bytes());
        out.extend_from_slice(&self.sequence.to_le_bytes());
        out.extend_from_slice(&(self.points.len() as u32).to_le_bytes());
        for p in &self.points {
            let r = p.record;
            for v in [r.instance, r.index, r.bits] {
                out.extend_from_slice(&v.to_le_bytes());
            }
            let samples = u16::try_from(p.samples).unwrap_or(u16::MAX);
            out.extend_from_slice(&samples.to_le_bytes());
        }
        out
    }

    /// Decode a payload; refuses a partition or chunk outside its count, more than
    /// [`MAX_CHUNK_POINTS`] points and non-finite times.
    pub fn decode(bytes: &[u8]) -> Result<Snapshot, PayloadError> {
        let mut r = Reader {
            bytes,
            what: "snapshot chunk",
        };
        r.header_version(SNAPSHOT_MAGIC, SNAPSHOT_VERSION)?;
        let (partition, partitions) = r.partition()?;
        let (chunk, chunks) = (r.u32()?, r.u32()?);
        if chunk >= chunks {
            return Err(fail(r.what, format!("chunk {chunk} of {chunks}")));
        }
        let (frame, seconds, sequence) = (r.u64()?, r.f64()?, r.u64()?);
        if !seconds.is_finite() {
            return Err(fail(r.what, "non-finite scene time"));
        }
        let n = r.count(POINT_BYTES, MAX_CHUNK_POINTS)?;
        let mut points = Vec::with_capacity(n);
        for _ in 0..n {
            let record = PointRecord {
                instance: r.u32()?,
                index: r.u32()?,
                bits: r.u32()?,
            };
            let samples = u32::from(r.u16()?);
            points.push(PointState { record, samples });
        }
        Ok(Snapshot {
            partition,
            partitions,
            chunk,
            chunks,
            frame,
            seconds,
            sequence,
            points,
        })
    }
}

impl SnapshotMark {
    /// The payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(MARK_BYTES);
        out.extend_from_slice(MARK_MAGIC);
        out.push(VERSION);
        for v in [self.partition, self.partitions, self.chunks] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.seconds.to_le_bytes());
        out.extend_from_slice(&self.sequence.to_le_bytes());
        out
    }

    /// Decode a payload; refuses a partition outside its count, non-finite times and
    /// trailing bytes.
    pub fn decode(bytes: &[u8]) -> Result<SnapshotMark, PayloadError> {
        let mut r = Reader {
            bytes,
            what: "snapshot mark",
        };
        r.header(MARK_MAGIC)?;
        let (partition, partitions) = r.partition()?;
        let chunks = r.u32()?;
        let (frame, seconds, sequence) = (r.u64()?, r.f64()?, r.u64()?);
        if !seconds.is_finite() {
            return Err(fail(r.what, "non-finite scene time"));
        }
        if !r.bytes.is_empty() {
            return Err(fail(r.what, "trailing bytes"));
        }
        Ok(SnapshotMark {
            partition,
            partitions,
            chunks,
            frame,
            seconds,
            sequence,
        })
    }
}

impl Batch {
    /// Bytes of the payload of a batch of `records` records.
    pub fn encoded_len(records: usize) -> usize {
        BATCH_HEADER + records * RECORD_BYTES
    }

    /// The payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(BATCH_HEADER + self.records.len() * RECORD_BYTES);
        out.extend_from_slice(BATCH_MAGIC);
        out.push(VERSION);
        out.extend_from_slice(&self.partition.to_le_bytes());
        out.extend_from_slice(&self.partitions.to_le_bytes());
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.seconds.to_le_bytes());
        put_records(&mut out, &self.records);
        out
    }

    /// Decode a payload; refuses a partition outside its count and non-finite times.
    pub fn decode(bytes: &[u8]) -> Result<Batch, PayloadError> {
        let mut r = Reader {
            bytes,
            what: "record batch",
        };
        r.header(BATCH_MAGIC)?;
        let (partition, partitions) = r.partition()?;
        let (frame, seconds) = (r.u64()?, r.f64()?);
        if !seconds.is_finite() {
            return Err(fail(r.what, "non-finite scene time"));
        }
        let records = r.records(usize::MAX)?;
        Ok(Batch {
            partition,
            partitions,
            frame,
            seconds,
            records,
        })
    }
}

impl BatchPart {
    /// The payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(PART_HEADER + self.data.len());
        out.extend_from_slice(PART_MAGIC);
        out.push(VERSION);
        out.extend_from_slice(&self.partition.to_le_bytes());
        out.extend_from_slice(&self.partitions.to_le_bytes());
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.part.to_le_bytes());
        out.extend_from_slice(&self.parts.to_le_bytes());
        out.extend_from_slice(&self.data);
        out
    }

    /// Decode a payload; refuses a partition outside its count, no parts or more than
    /// [`MAX_PARTS`], and a part outside its count.
    pub fn decode(bytes: &[u8]) -> Result<BatchPart, PayloadError> {
        let mut r = Reader {
            bytes,
            what: "record batch part",
        };
        r.header(PART_MAGIC)?;
        let (partition, partitions) = r.partition()?;
        let frame = r.u64()?;
        let (part, parts) = (r.u32()?, r.u32()?);
        if parts == 0 || parts > MAX_PARTS || part >= parts {
            return Err(fail(
                r.what,
                format!("part {part} of {parts} (at most {MAX_PARTS} parts)"),
            ));
        }
        Ok(BatchPart {
            partition,
            partitions,
            frame,
            part,
            parts,
            data: r.bytes.to_vec(),
        })
    }
}

impl ViewSet {
    /// The payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(VIEWS_HEADER + self.views.len() * VIEW_BYTES);
        out.extend_from_slice(VIEWS_MAGIC);
        out.push(VERSION);
        out.extend_from_slice(&self.frame.to_le_bytes());
        out.extend_from_slice(&self.seconds.to_le_bytes());
        out.extend_from_slice(&(self.views.len() as u32).to_le_bytes());
        for v in &self.views {
            let c = &v.camera;
            let floats = [c.position, c.target, c.up]
                .into_iter()
                .flat_map(|p| p.to_array())
                .chain([c.fov_y, c.near, c.far, v.aspect]);
            for f in floats {
                out.extend_from_slice(&f.to_le_bytes());
            }
        }
        out
    }

    /// Decode a payload; refuses more than [`MAX_VIEWS`] views and cameras a client could not
    /// send ([`psao_wire::CameraMsg::validate`]).
    pub fn decode(bytes: &[u8]) -> Result<ViewSet, PayloadError> {
        let mut r = Reader {
            bytes,
            what: "view set",
        };
        r.header(VIEWS_MAGIC)?;
        let (frame, seconds) = (r.u64()?, r.f64()?);
        let n = r.count(VIEW_BYTES, MAX_VIEWS)?;
        let mut views = Vec::with_capacity(n);
        for _ in 0..n {
            let (position, target, up) = (r.vec3()?, r.vec3()?, r.vec3()?);
            let (fov_y, near, far, aspect) = (r.f32()?, r.f32()?, r.f32()?, r.f32()?);
            // The rules a client's camera message obeys (a view steps the trace nodes).
            let camera = psao_wire::CameraMsg {
                frame: 0,
                position: position.into(),
                target: target.into(),
                up: up.into(),
                fov_y,
                near,
                far,
                aspect,
            };
            camera.validate().map_err(|e| fail(r.what, e.to_string()))?;
            views.push(View {
                camera: Camera {
                    position,
                    target,
                    up,
                    fov_y,
                    near,
                    far,
                },
                aspect,
            });
        }
        if !seconds.is_finite() {
            return Err(fail(r.what, "non-finite scene time"));
        }
        Ok(ViewSet {
            frame,
            seconds,
            views,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch() -> Batch {
        Batch {
            partition: 1,
            partitions: 3,
            frame: 42,
            seconds: 1.4,
            records: (0..5)
                .map(|i| PointRecord {
                    instance: i / 2,
                    index: i * 7,
                    bits: 0xdead_0000 + i,
                })
                .collect(),
        }
    }

    fn snapshot() -> Snapshot {
        let b = batch();
        Snapshot {
            partition: 2,
            partitions: 3,
            chunk: 1,
            chunks: 4,
            frame: 64,
            seconds: 2.1,
            sequence: 190,
            points: b
                .records
                .into_iter()
                .zip([0, 3, 70_000, 16, 1])
                .map(|(record, samples)| PointState { record, samples })
                .collect(),
        }
    }

    fn mark() -> SnapshotMark {
        SnapshotMark {
            partition: 1,
            partitions: 2,
            chunks: 3,
            frame: 64,
            seconds: 2.1,
            sequence: 191,
        }
    }

    fn views() -> ViewSet {
        let v = |x: f32| View {
            camera: Camera::look_at(Vec3::new(x, 1.0, 2.0), Vec3::ZERO, 55.0),
            aspect: 1.5,
        };
        ViewSet {
            frame: 9,
            seconds: 0.3,
            views: vec![v(1.0), v(-2.5)],
        }
    }

    #[test]
    fn views_a_client_could_not_send_are_refused() {
        for bad in [
            |c: &mut Camera| c.fov_y = 4.0,
            |c: &mut Camera| c.near = -1.0,
            |c: &mut Camera| c.far = c.near,
            |c: &mut Camera| c.target = c.position,
            |c: &mut Camera| c.position.x = f32::NAN,
        ] {
            let mut v = views();
            bad(&mut v.views[1].camera);
            let err = ViewSet::decode(&v.encode()).unwrap_err();
            assert!(err.to_string().contains("camera"), "{err}");
        }
    }

    #[test]
    fn payloads_round_trip() {
        let b = batch();
        assert_eq!(Batch::decode(&b.encode()), Ok(b));
        let v = views();
        assert_eq!(ViewSet::decode(&v.encode()), Ok(v));
        let empty = Batch {
            records: Vec::new(),
            ..batch()
        };
        assert_eq!(Batch::decode(&empty.encode()), Ok(empty));
        let mut s = snapshot();
        let back = Snapshot::decode(&s.encode()).unwrap();
        assert_eq!(
            back.points[2].samples,
            u32::from(u16::MAX),
            "counts saturate"
        );
        s.points[2].samples = u32::from(u16::MAX);
        assert_eq!(back, s);
        let m = mark();
        assert_eq!(SnapshotMark::decode(&m.encode()), Ok(m));
    }

    #[test]
    fn every_truncation_and_corruption_is_an_error() {
        let (b, v, s) = (batch().encode(), views().encode(), snapshot().encode());
        let m = mark().encode();
        for bytes in [&b, &v, &s, &m] {
            for n in 0..bytes.len() {
                assert!(Batch::decode(&bytes[..n]).is_err());
                assert!(ViewSet::decode(&bytes[..n]).is_err());
                assert!(Snapshot::decode(&bytes[..n]).is_err());
                assert!(SnapshotMark::decode(&bytes[..n]).is_err());
            }
        }
        let mut extra = m.clone();
        extra.push(0);
        assert!(SnapshotMark::decode(&extra).is_err());
        let mut wrong = m.clone();
        wrong[5..9].copy_from_slice(&2u32.to_le_bytes());
        assert!(SnapshotMark::decode(&wrong)
            .unwrap_err()
            .to_string()
            .contains("partition 2 of 2"));
        let mut wrong = s.clone();
        wrong[13..17].copy_from_slice(&4u32.to_le_bytes());
        assert!(Snapshot::decode(&wrong)
            .unwrap_err()
            .to_string()
            .contains("chunk 4 of 4"));
        let mut wrong = b.clone();
        wrong[0] = b'X';
        assert!(Batch::decode(&wrong)
            .unwrap_err()
            .to_string()
            .contains("magic"));
        let mut wrong = b.clone();
        wrong[4] = 9;
        assert!(Batch::decode(&wrong)
            .unwrap_err()
            .to_string()
            .contains("version"));
        let mut wrong = b.clone();
        wrong[5..9].copy_from_slice(&3u32.to_le_bytes());
        assert!(Batch::decode(&wrong)
            .unwrap_err()
            .to_string()
            .contains("partition"));
        // A count claiming 2^32-1 records: refused before allocating.
        let mut huge = b.clone();
        huge[BATCH_HEADER - 4..BATCH_HEADER].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Batch::decode(&huge)
            .unwrap_err()
            .to_string()
            .contains("do not fit"));
        let mut extra = b.clone();
        extra.push(0);
        assert!(Batch::decode(&extra).is_err());
        let mut nan = v.clone();
        nan[VIEWS_HEADER..VIEWS_HEADER + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(ViewSet::decode(&nan)
            .unwrap_err()
            .to_string()
            .contains("camera is not finite"));
    }

    #[test]
    fn batch_parts_round_trip_and_refuse_forged_counts() {
        let p = BatchPart {
            partition: 1,
            partitions: 2,
            frame: 7,
            part: 2,
            parts: 3,
            data: vec![1, 2, 3, 4],
        };
        let bytes = p.encode();
        assert_eq!(bytes.len(), PART_HEADER + 4);
        assert_eq!(BatchPart::decode(&bytes), Ok(p.clone()));
        for n in 0..PART_HEADER {
            assert!(BatchPart::decode(&bytes[..n]).is_err());
        }
        for (part, parts) in [(3, 3), (0, 0), (0, MAX_PARTS + 1)] {
            let forged = BatchPart {
                part,
                parts,
                ..p.clone()
            };
            let e = BatchPart::decode(&forged.encode()).unwrap_err();
            assert!(e.to_string().contains(&format!("part {part} of {parts}")));
        }
        let last = BatchPart {
            part: MAX_PARTS - 1,
            parts: MAX_PARTS,
            ..p
        };
        assert_eq!(BatchPart::decode(&last.encode()), Ok(last));
    }

    #[test]
    fn the_largest_snapshot_chunk_is_accepted_and_one_more_record_refused() {
        let mut s = snapshot();
        s.points = vec![s.points[0]; MAX_CHUNK_POINTS];
        let bytes = s.encode();
        assert_eq!(bytes.len(), Snapshot::encoded_len(MAX_CHUNK_POINTS));
        assert!(bytes.len() < 1 << 20, "under NATS's default payload limit");
        assert_eq!(
            Snapshot::decode(&bytes).unwrap().points.len(),
            MAX_CHUNK_POINTS
        );
        s.points.push(s.points[0]);
        assert!(Snapshot::decode(&s.encode()).is_err());
    }

    #[test]
    fn the_largest_view_set_is_accepted_and_one_more_refused() {
        let mut v = views();
        v.views = vec![v.views[0]; MAX_VIEWS];
        assert_eq!(ViewSet::decode(&v.encode()).unwrap().views.len(), MAX_VIEWS);
        v.views.push(v.views[0]);
        assert!(ViewSet::decode(&v.encode()).is_err());
    }
}
