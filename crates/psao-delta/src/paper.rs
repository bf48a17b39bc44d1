//! The `paper` codec (DESIGN §4): the paper's raw 32-bit records, zstd level 15, strategy
//! "lazy" (§3.4 compresses the changed HashBucket and CellData buffers with off-the-shelf zstd).
//!
//! Payload (little-endian 32-bit words) before compression:
//! ```text
//! tag "PSD1" · frame (2 words, low first) · flags (bit 0 snapshot, bit 1 wide keys,
//!     bit 2 lights)
//! transform count · per transform: instance, 12 floats (Affine3A columns)
//! instance count · per instance: instance, bucket count, cell count,
//!     buckets: index, 8 × (key [key high word if wide], slot)
//!     cells:   slot, 7 packed points [7 irradiance records if lights]
//! ```
//! Bucket entries and cell points are compacted, empty (zero) ones last. Keys (cell id + 1)
//! take one word unless some key in the update needs two ("wide keys"). With lighting every
//! cell carries its points' irradiance records (RGB9E5, `psao_points::irradiance`), raw like
//! the points: an instance delta of a lit update without them sends zeros.

use glam::Affine3A;
use psao_points::{Bucket, BucketEntry, Cell, BUCKET_ENTRIES, CELL_POINTS};

use crate::model::{compact_bucket, compact_cell, InstanceDelta, Update};
use crate::words::{WordReader, WordWriter};
use crate::{Codec, DeltaError};

/// zstd compression level of the paper codec.
pub const PAPER_LEVEL: i32 = 15;
/// The decode limit of a decoder that was not told what its stream may need (256 MiB): the
/// largest decompressed payload it accepts, and for the compact codec also the most its
/// reference may hold. A client raises or lowers it to what its instance table allows
/// ([`crate::Codec::set_decode_limit`]), never past [`MAX_DECODE_LIMIT`].
pub const MAX_DECODED_BYTES: u64 = 256 << 20;

/// The absolute ceiling of a decode limit (4 GiB), whatever an instance table asks for; the
/// densest Sponza we evaluate streams within it (docs/PROTOCOL.md, crates/psao/tests/dense.rs).
pub const MAX_DECODE_LIMIT: u64 = 4 << 30;

const TAG: u32 = u32::from_le_bytes(*b"PSD1");
const FLAG_SNAPSHOT: u32 = 1;
const FLAG_WIDE_KEYS: u32 = 2;
const FLAG_LIGHTS: u32 = 4;
const TRANSFORM_WORDS: usize = 13;
const INSTANCE_HEADER_WORDS: usize = 3;
const CELL_WORDS: usize = 1 + CELL_POINTS;

/// Words per cell: slot and points, and the irradiance records with `lights`.
fn cell_words(lights: bool) -> usize {
    CELL_WORDS + if lights { CELL_POINTS } else { 0 }
}

/// The paper's codec: raw records + zstd level 15 with the "lazy" strategy. Stateless: every
/// update decodes on its own, within the decode limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PaperCodec {
    decode_limit: u64,
}

impl PaperCodec {
    /// A codec with the [`MAX_DECODED_BYTES`] decoding limit.
    pub const fn new() -> Self {
        Self {
            decode_limit: MAX_DECODED_BYTES,
        }
    }
}

impl Default for PaperCodec {
    fn default() -> Self {
        Self::new()
    }
}

impl Codec for PaperCodec {
    fn name(&self) -> &'static str {
        "paper"
    }

    fn encode(&mut self, update: &Update) -> Vec<u8> {
        compress(&serialize(update))
    }

    fn advance(&mut self, _update: &Update) {}

    fn decode(&mut self, bytes: &[u8]) -> Result<Update, DeltaError> {
        deserialize(&crate::zstd_io::decompress(bytes, self.decode_limit)?)
    }

    fn set_decode_limit(&mut self, bytes: u64) {
        self.decode_limit = bytes.min(MAX_DECODE_LIMIT);
    }
}

fn bucket_words(wide: bool) -> usize {
    1 + BUCKET_ENTRIES * (if wide { 3 } else { 2 })
}

/// The uncompressed payload.
fn serialize(update: &Update) -> Vec<u8> {
    let wide = update
        .instances
        .iter()
        .flat_map(|d| d.buckets.iter())
        .flat_map(|(_, b)| b.entries.iter())
        .any(|e| e.key > u64::from(u32::MAX));
    let lights = update.has_lights();
    let words = 5
        + update.transforms.len() * TRANSFORM_WORDS
        + update
            .instances
            .iter()
            .map(|d| {
                INSTANCE_HEADER_WORDS
                    + d.buckets.len() * bucket_words(wide)
                    + d.cells.len() * cell_words(lights)
            })
            .sum::<usize>();
    let mut w = WordWriter::with_capacity(words);
    w.put(TAG);
    w.put_u64(update.frame);
    let flags = if update.snapshot { FLAG_SNAPSHOT } else { 0 };
    let flags = flags | if wide { FLAG_WIDE_KEYS } else { 0 };
    w.put(flags | if lights { FLAG_LIGHTS } else { 0 });
    w.put_len(update.transforms.len());
    for (instance, t) in &update.transforms {
        w.put(*instance);
        t.to_cols_array().iter().for_each(|f| w.put(f.to_bits()));
    }
    w.put_len(update.instances.len());
    for d in &update.instances {
        w.put(d.instance);
        w.put_len(d.buckets.len());
        w.put_len(d.cells.len());
        for (index, bucket) in &d.buckets {
            w.put(*index);
            for e in compact_bucket(bucket).entries {
                if wide {
                    w.put_u64(e.key);
                } else {
                    w.put(e.key as u32);
                }
                w.put(e.slot);
            }
        }
        for (k, (slot, cell)) in d.cells.iter().enumerate() {
            w.put(*slot);
            compact_cell(cell).points.iter().for_each(|&p| w.put(p));
            if lights {
                let records = d.lights.get(k).copied().unwrap_or_default();
                records.iter().for_each(|&e| w.put(e));
            }
        }
    }
    w.into_bytes()
}

/// Parse a payload; every count is checked against the words left before allocating.
fn deserialize(bytes: &[u8]) -> Result<Update, DeltaError> {
    let mut r = WordReader::new(bytes)?;
    let tag = r.get("format tag")?;
    if tag != TAG {
        return Err(DeltaError::BadTag {
            found: tag,
            expected: TAG,
        });
    }
    let frame = r.get_u64("frame number")?;
    let flags = r.get("flags")?;
    if flags & !(FLAG_SNAPSHOT | FLAG_WIDE_KEYS | FLAG_LIGHTS) != 0 {
        return Err(DeltaError::UnknownFlags(flags));
    }
    let wide = flags & FLAG_WIDE_KEYS != 0;
    let lit = flags & FLAG_LIGHTS != 0;

    let count = r.get("transform count")?;
    r.require(count, TRANSFORM_WORDS, "transforms")?;
    let mut transforms = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let instance = r.get("transform")?;
        let mut cols = [0.0f32; 12];
        for c in &mut cols {
            *c = f32::from_bits(r.get("transform")?);
        }
        transforms.push((instance, Affine3A::from_cols_array(&cols)));
    }

    let count = r.get("instance count")?;
    r.require(count, INSTANCE_HEADER_WORDS, "instance deltas")?;
    let mut instances = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let instance = r.get("instance header")?;
        let buckets = r.get("instance header")?;
        let cells = r.get("instance header")?;
        r.require(buckets, bucket_words(wide), "buckets")?;
        let buckets = (0..buckets)
            .map(|_| read_bucket(&mut r, wide))
            .collect::<Result<_, _>>()?;
        r.require(cells, cell_words(lit), "cells")?;
        let mut lights = Vec::with_capacity(if lit { cells as usize } else { 0 });
        let cells = (0..cells)
            .map(|_| {
                let cell = read_cell(&mut r)?;
                if lit {
                    let mut records = [0; CELL_POINTS];
                    for e in &mut records {
                        *e = r.get("irradiance")?;
                    }
                    lights.push(records);
                }
                Ok(cell)
            })
            .collect::<Result<_, DeltaError>>()?;
        instances.push(InstanceDelta {
            instance,
            buckets,
            cells,
            lights,
        });
    }
    r.finish()?;
    Ok(Update {
        frame,
        snapshot: flags & FLAG_SNAPSHOT != 0,
        transforms,
        instances,
    })
}

fn read_bucket(r: &mut WordReader<'_>, wide: bool) -> Result<(u32, Bucket), DeltaError> {
    let index = r.get("bucket")?;
    let mut bucket = Bucket::default();
    for e in &mut bucket.entries {
        let key = if wide {
            r.get_u64("bucket")?
        } else {
            u64::from(r.get("bucket")?)
        };
        *e = BucketEntry {
            key,
            slot: r.get("bucket")?,
        };
    }
    Ok((index, bucket))
}

fn read_cell(r: &mut WordReader<'_>) -> Result<(u32, Cell), DeltaError> {
    let slot = r.get("cell")?;
    let mut cell = Cell::default();
    for p in &mut cell.points {
        *p = r.get("cell")?;
    }
    Ok((slot, cell))
}

/// zstd level 15, strategy lazy, with content size and checksum recorded.
fn compress(payload: &[u8]) -> Vec<u8> {
    crate::zstd_io::compress_with(payload, PAPER_LEVEL, crate::zstd_io::Search::Lazy)
}
