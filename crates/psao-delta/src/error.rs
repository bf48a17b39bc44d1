//! Typed errors of the codecs.

/// Everything that can go wrong when decoding an update or choosing a codec.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DeltaError {
    /// No codec has this name.
    #[error("unknown codec `{0}` (known: {known})", known = crate::CODEC_NAMES.join(", "))]
    UnknownCodec(String),
    /// The compressed stream is not valid zstd (or fails its checksum).
    #[error("corrupt compressed data: {0}")]
    Decompress(String),
    /// The compressed stream does not record its decompressed size (every encoder here does).
    #[error("compressed data does not record its decompressed size")]
    UnknownSize,
    /// The stream claims to expand to more bytes than any legitimate update.
    #[error("decompressed size {size} bytes exceeds the limit of {limit} bytes")]
    TooLarge {
        /// Claimed decompressed size.
        size: u64,
        /// The limit.
        limit: u64,
    },
    /// The payload does not start with the expected format tag.
    #[error("bad format tag {found:#010x} (expected {expected:#010x})")]
    BadTag {
        /// The tag read.
        found: u32,
        /// The tag this codec writes.
        expected: u32,
    },
    /// Flag bits this format does not define.
    #[error("unknown flag bits {0:#x}")]
    UnknownFlags(u32),
    /// The payload length is not a whole number of 32-bit words.
    #[error("payload of {0} bytes is not a whole number of 32-bit words")]
    Unaligned(usize),
    /// A count or record runs past the end of the payload.
    #[error("truncated {what}: needs {needed} words, {available} left")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Words needed.
        needed: u64,
        /// Words remaining.
        available: usize,
    },
    /// Words left over after the last record.
    #[error("{0} trailing words after the update")]
    Trailing(usize),
    /// A varint that is too long or a delta that leaves the 32-bit range.
    #[error("bad varint in {0}")]
    BadVarint(&'static str),
    /// The byte planes do not have the size the index stream implies.
    #[error("byte planes hold {found} bytes, the index stream implies {expected}")]
    PlaneSize {
        /// Bytes implied by the counts.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// A cell length above the 7 points a cell holds.
    #[error("cell length {0} exceeds 7 points")]
    CellLength(usize),
    /// A bucket entry count above the 8 entries a bucket holds.
    #[error("bucket entry count {0} exceeds 8 entries")]
    EntryCount(usize),
    /// A reference choice out of range (or a cell position past the update's cells).
    #[error("bad reference choice for a {0}")]
    BadChoice(&'static str),
    /// The update's indices would grow the decoder's reference past the decode limit.
    #[error("indices would grow the decoder's reference to {needed} bytes, past the limit of {limit} bytes")]
    ReferenceTooLarge {
        /// Bytes the reference would hold.
        needed: u64,
        /// The limit.
        limit: u64,
    },
    /// A residual that decodes to no valid record.
    #[error("bad {0}")]
    BadRecord(&'static str),
}
