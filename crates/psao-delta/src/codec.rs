//! The codec interface and lookup by name.

use crate::{CompactCodec, DeltaError, PaperCodec, Update};

/// Names accepted by [`codec_by_name`].
pub const CODEC_NAMES: &[&str] = &["compact", "paper"];

/// Turns updates into bytes and back. Codecs may keep state between calls (e.g. the last
/// sent state the compact codec predicts from), so a sender and its receiver each hold one
/// instance and see the same sequence of updates.
pub trait Codec: Send {
    /// The codec's name, as accepted by [`codec_by_name`].
    fn name(&self) -> &'static str;
    /// Encode one update.
    fn encode(&mut self, update: &Update) -> Vec<u8>;
    /// Take the state encoding `update` leaves without producing the bytes: for a codec in
    /// the same state as one that encoded `update` (same name, and its receiver holds the
    /// server's state at the same frame), whose bytes are sent instead.
    fn advance(&mut self, update: &Update);
    /// Decode one update; malformed input gives an error, never a panic or an unbounded
    /// allocation.
    fn decode(&mut self, bytes: &[u8]) -> Result<Update, DeltaError>;
    /// Set the most bytes one update may decompress to (and the compact decoder's reference
    /// may hold) to what the instance table allows, at most [`crate::MAX_DECODE_LIMIT`].
    /// Codecs without a configurable limit keep [`crate::MAX_DECODED_BYTES`].
    fn set_decode_limit(&mut self, _bytes: u64) {}
    /// Heap bytes the codec keeps between updates (its encoder's and decoder's references,
    /// allocated capacity); 0 for a stateless codec.
    fn heap_bytes(&self) -> u64 {
        0
    }
}

/// A fresh codec by name (`"compact"` or `"paper"`).
pub fn codec_by_name(name: &str) -> Result<Box<dyn Codec>, DeltaError> {
    match name {
        "paper" => Ok(Box::new(PaperCodec::new())),
        "compact" => Ok(Box::new(CompactCodec::new())),
        _ => Err(DeltaError::UnknownCodec(name.to_string())),
    }
}
