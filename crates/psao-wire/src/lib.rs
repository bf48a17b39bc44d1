//! The psao network protocol (DESIGN §4, `docs/PROTOCOL.md`): versioned, length-prefixed,
//! checksummed frames carrying [`Message`]s encoded with `postcard`.
//!
//! A frame is a 12-byte header — magic `PSW1`, payload length (u32 LE), CRC-32 of the
//! payload (u32 LE) — followed by the payload. [`encode_frame`] builds one;
//! [`FrameHeader::parse`] + [`decode_payload`] (streams) or [`decode_frame`] (whole frames,
//! e.g. WebSocket messages) check and decode one. Decoding is hardened: every failure is a
//! typed [`WireError`], sizes are checked against a caller-given limit before anything is
//! allocated, and decoded messages are validated ([`Message::validate`]). No I/O here.

mod corrective;
mod error;
mod frame;
mod message;
mod relighting;

pub use corrective::{
    Region, RegionsMsg, SampleMsg, SamplesMsg, MAX_RADIANCE, MAX_REGIONS, MAX_REGION_IMAGE_SIDE,
    MAX_SAMPLES, MAX_SAMPLE_LEVEL,
};
pub use error::WireError;
pub use frame::{
    decode_frame, decode_payload, encode_frame, frame_payload, FrameHeader, HEADER_LEN, MAGIC,
    MAX_CLIENT_FRAME, MAX_SERVER_FRAME,
};
pub use message::{
    capabilities, Ack, Bye, CameraMsg, Delta, ErrorCode, ErrorMsg, Hello, InstanceEntry, Message,
    SceneTime, StatusMsg, Welcome, MAX_CODEC_NAME, MAX_INSTANCES, MAX_TEXT, MAX_TOKEN,
    PROTOCOL_VERSION,
};
pub use relighting::{RelightingMsg, MAX_LIGHT_CHANNELS, MAX_MODEL_BYTES, SH_COEFFS};
