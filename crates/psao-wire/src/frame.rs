//! Framing: header, checksum, size limits.

use crate::{Message, WireError};

/// First four bytes of every frame: `PSW` and the frame format version `1`.
pub const MAGIC: [u8; 4] = *b"PSW1";
/// Header bytes: magic, payload length (u32 LE), CRC-32 of the payload (u32 LE).
pub const HEADER_LEN: usize = 12;
/// Largest payload a server accepts from a client (64 KiB: hello, camera, ack, bye).
pub const MAX_CLIENT_FRAME: u32 = 64 << 10;
/// Largest payload a client accepts from a server by default (256 MiB: a snapshot of a big
/// scene); clients may lower it.
pub const MAX_SERVER_FRAME: u32 = 256 << 20;

/// A checked frame header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameHeader {
    /// Payload length in bytes.
    pub len: u32,
    /// CRC-32 (IEEE) of the payload.
    pub crc: u32,
}

impl FrameHeader {
    /// Parse and check a header: magic, and payload length ≤ `limit`.
    pub fn parse(bytes: &[u8; HEADER_LEN], limit: u32) -> Result<Self, WireError> {
        let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
        if magic != MAGIC {
            return Err(WireError::BadMagic(magic));
        }
        let len = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
        let crc = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if len > limit {
            return Err(WireError::TooLarge {
                len: u64::from(len),
                limit: u64::from(limit),
            });
        }
        Ok(Self { len, crc })
    }
}

/// Encode `message` as one frame (header + payload). Fails only when the message breaks a
/// rule of [`Message::validate`] or does not fit in a `u32` length.
pub fn encode_frame(message: &Message) -> Result<Vec<u8>, WireError> {
    message.validate()?;
    let out = vec![0u8; HEADER_LEN];
    let mut out =
        postcard::to_extend(message, out).map_err(|e| WireError::Malformed(e.to_string()))?;
    let header = header_for(&out[HEADER_LEN..])?;
    out[..HEADER_LEN].copy_from_slice(&header);
    Ok(out)
}

/// Frame an already-encoded payload as is (header + `payload`), without checking that it
/// holds a valid message: for relaying, and for tests that send malformed payloads.
pub fn frame_payload(payload: &[u8]) -> Result<Vec<u8>, WireError> {
    let mut out = header_for(payload)?.to_vec();
    out.extend_from_slice(payload);
    Ok(out)
}

/// The header of a frame carrying `payload`: magic, length, CRC-32.
fn header_for(payload: &[u8]) -> Result<[u8; HEADER_LEN], WireError> {
    let len = u32::try_from(payload.len()).map_err(|_| WireError::TooLarge {
        len: payload.len() as u64,
        limit: u64::from(u32::MAX),
    })?;
    let mut header = [0u8; HEADER_LEN];
    header[..4].copy_from_slice(&MAGIC);
    header[4..8].copy_from_slice(&len.to_le_bytes());
    header[8..12].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    Ok(header)
}

/// Check the payload of a frame against its header and decode + validate the message.
pub fn decode_payload(header: &FrameHeader, payload: &[u8]) -> Result<Message, WireError> {
    if payload.len() as u64 != u64::from(header.len) {
        return Err(WireError::Truncated {
            needed: u64::from(header.len),
            available: payload.len() as u64,
        });
    }
    let found = crc32fast::hash(payload);
    if found != header.crc {
        return Err(WireError::Checksum {
            expected: header.crc,
            found,
        });
    }
    let (message, rest): (Message, _) =
        postcard::take_from_bytes(payload).map_err(|e| WireError::Malformed(e.to_string()))?;
    if !rest.is_empty() {
        return Err(WireError::Malformed(format!(
            "{} bytes after the message",
            rest.len()
        )));
    }
    message.validate()?;
    Ok(message)
}

/// Decode exactly one whole frame (header + payload, nothing after) with payload ≤ `limit`.
pub fn decode_frame(bytes: &[u8], limit: u32) -> Result<Message, WireError> {
    let header: &[u8; HEADER_LEN] = bytes.first_chunk().ok_or(WireError::Truncated {
        needed: HEADER_LEN as u64,
        available: bytes.len() as u64,
    })?;
    let header = FrameHeader::parse(header, limit)?;
    let payload = &bytes[HEADER_LEN..];
    let len = header.len as usize;
    if payload.len() < len {
        return Err(WireError::Truncated {
            needed: (HEADER_LEN + len) as u64,
            available: bytes.len() as u64,
        });
    }
    if payload.len() > len {
        return Err(WireError::Trailing(payload.len() - len));
    }
    decode_payload(&header, payload)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{capabilities, Ack, Delta, Hello, PROTOCOL_VERSION};

    fn hello() -> Message {
        Message::Hello(Hello {
            version: PROTOCOL_VERSION,
            capabilities: capabilities::STATE_HASH,
            token: Some("secret".into()),
            name: "test".into(),
        })
    }

    #[test]
    fn frames_round_trip() {
        for m in [
            hello(),
            Message::Ack(Ack { frame: 9 }),
            Message::Delta(Delta {
                frame: 3,
                scene_time: 0.05,
                client_frame: Some(3),
                state_hash: None,
                payload: vec![1, 2, 3],
            }),
        ] {
            let bytes = encode_frame(&m).unwrap();
            assert_eq!(&bytes[..4], b"PSW1");
            assert_eq!(decode_frame(&bytes, MAX_CLIENT_FRAME).unwrap(), m);
            let header =
                FrameHeader::parse(bytes[..HEADER_LEN].try_into().unwrap(), 1 << 20).unwrap();
            assert_eq!(header.len as usize, bytes.len() - HEADER_LEN);
        }
    }

    #[test]
    fn damaged_frames_give_typed_errors() {
        let good = encode_frame(&hello()).unwrap();
        assert!(matches!(
            decode_frame(&good[..5], 1 << 16),
            Err(WireError::Truncated { .. })
        ));
        assert!(matches!(
            decode_frame(&good[..good.len() - 1], 1 << 16),
            Err(WireError::Truncated { .. })
        ));
        let mut long = good.clone();
        long.push(0);
        assert_eq!(decode_frame(&long, 1 << 16), Err(WireError::Trailing(1)));
        let mut bad = good.clone();
        bad[0] = b'X';
        assert!(matches!(
            decode_frame(&bad, 1 << 16),
            Err(WireError::BadMagic(_))
        ));
        let mut flipped = good.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert!(matches!(
            decode_frame(&flipped, 1 << 16),
            Err(WireError::Checksum { .. })
        ));
        assert!(matches!(
            decode_frame(&good, 4),
            Err(WireError::TooLarge { len: _, limit: 4 })
        ));
        // A correct checksum over garbage.
        let frame = frame_payload(&[0xffu8; 9]).unwrap();
        assert!(matches!(
            decode_frame(&frame, 1 << 16),
            Err(WireError::Malformed(_))
        ));
    }

    #[test]
    fn huge_length_prefixes_inside_a_small_frame_do_not_allocate() {
        // Delta variant whose byte payload claims 2^32 bytes.
        let mut payload = vec![5u8]; // variant index of Delta
        payload.extend_from_slice(&[1, 0, 0, 0, 0, 0, 0, 0, 0]); // frame, scene time
        payload.extend_from_slice(&[0, 0, 0xff, 0xff, 0xff, 0xff, 0x0f]);
        let header = FrameHeader {
            len: payload.len() as u32,
            crc: crc32fast::hash(&payload),
        };
        assert!(decode_payload(&header, &payload).is_err());
    }
}
