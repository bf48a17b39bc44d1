//! Typed errors of frame and message decoding.

/// Why bytes could not be read as a frame or a message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// The frame does not start with the magic `PSW1` (not a psao peer, or another frame
    /// format version).
    #[error("bad frame magic {0:02x?} (expected \"PSW1\")")]
    BadMagic([u8; 4]),
    /// The header announces a payload above the receiver's limit.
    #[error("frame of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge {
        /// Announced payload length.
        len: u64,
        /// The receiver's limit.
        limit: u64,
    },
    /// Fewer bytes than the header or the announced payload needs.
    #[error("truncated frame: {needed} bytes needed, {available} present")]
    Truncated {
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        available: u64,
    },
    /// Bytes after the announced payload (whole-frame decoding only).
    #[error("{0} bytes after the frame")]
    Trailing(usize),
    /// The payload's CRC-32 does not match the header.
    #[error("checksum mismatch: header {expected:#010x}, payload {found:#010x}")]
    Checksum {
        /// CRC in the header.
        expected: u32,
        /// CRC of the payload received.
        found: u32,
    },
    /// The payload is not a valid postcard-encoded message.
    #[error("malformed message: {0}")]
    Malformed(String),
    /// A decoded message breaks a protocol rule (field size, non-finite number, …).
    #[error("invalid message: {0}")]
    Invalid(String),
}
