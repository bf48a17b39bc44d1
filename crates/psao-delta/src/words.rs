//! Little-endian 32-bit word streams with bounds-checked reads.

use crate::DeltaError;

/// Appends little-endian 32-bit words to a byte buffer.
#[derive(Default)]
pub(crate) struct WordWriter {
    bytes: Vec<u8>,
}

impl WordWriter {
    /// A writer with room for `words` words.
    pub(crate) fn with_capacity(words: usize) -> Self {
        Self {
            bytes: Vec::with_capacity(words * 4),
        }
    }

    /// Append one word.
    pub(crate) fn put(&mut self, word: u32) {
        self.bytes.extend_from_slice(&word.to_le_bytes());
    }

    /// Append a 64-bit value as two words, low first.
    pub(crate) fn put_u64(&mut self, value: u64) {
        self.put(value as u32);
        self.put((value >> 32) as u32);
    }

    /// Append a count (the formats cap every count at `u32::MAX`).
    pub(crate) fn put_len(&mut self, len: usize) {
        self.put(u32::try_from(len).unwrap_or(u32::MAX));
    }

    /// The bytes written.
    pub(crate) fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }
}

/// Reads little-endian 32-bit words; every read is checked against the remaining length.
pub(crate) struct WordReader<'a> {
    bytes: &'a [u8],
}

impl<'a> WordReader<'a> {
    /// A reader over `bytes`, which must be a whole number of words.
    pub(crate) fn new(bytes: &'a [u8]) -> Result<Self, DeltaError> {
        if bytes.len() & 3 != 0 {
            return Err(DeltaError::Unaligned(bytes.len()));
        }
        Ok(Self { bytes })
    }

    /// Words left.
    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() / 4
    }

    /// Fail unless `count` records of `record_words` words each fit in what is left; call
    /// before allocating for `count` records.
    pub(crate) fn require(
        &self,
        count: u32,
        record_words: usize,
        what: &'static str,
    ) -> Result<(), DeltaError> {
        let needed = u64::from(count) * record_words as u64;
        if needed > self.remaining() as u64 {
            return Err(DeltaError::Truncated {
                what,
                needed,
                available: self.remaining(),
            });
        }
        Ok(())
    }

    /// Read one word.
    pub(crate) fn get(&mut self, what: &'static str) -> Result<u32, DeltaError> {
        let Some((head, rest)) = self.bytes.split_first_chunk::<4>() else {
            return Err(DeltaError::Truncated {
                what,
                needed: 1,
                available: 0,
            });
        };
        self.bytes = rest;
        Ok(u32::from_le_bytes(*head))
    }

    /// Read a 64-bit value written by [`WordWriter::put_u64`].
    pub(crate) fn get_u64(&mut self, what: &'static str) -> Result<u64, DeltaError> {
        self.require(2, 1, what)?;
        let lo = self.get(what)?;
        let hi = self.get(what)?;
        Ok(u64::from(lo) | (u64::from(hi) << 32))
    }

    /// Fail if any words are left.
    pub(crate) fn finish(self) -> Result<(), DeltaError> {
        match self.remaining() {
            0 => Ok(()),
            n => Err(DeltaError::Trailing(n)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_trip_and_bounds() {
        let mut w = WordWriter::with_capacity(3);
        w.put(7);
        w.put_u64(0x1234_5678_9abc_def0);
        let bytes = w.into_bytes();
        let mut r = WordReader::new(&bytes).unwrap();
        assert!(r.require(4, 1, "x").is_err());
        assert!(r.require(3, 1, "x").is_ok());
        assert_eq!(r.get("a").unwrap(), 7);
        assert_eq!(r.get_u64("b").unwrap(), 0x1234_5678_9abc_def0);
        assert!(matches!(r.get("c"), Err(DeltaError::Truncated { .. })));
        assert!(WordReader::new(&[0u8; 5]).is_err());
        let r = WordReader::new(&bytes[..4]).unwrap();
        assert_eq!(r.finish(), Err(DeltaError::Trailing(1)));
    }
}
