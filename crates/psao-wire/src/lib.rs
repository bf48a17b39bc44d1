//! The psao network protocol (DESIGN §4): versioned, length-prefixed, checksummed frames.
