//! The relighting message: a skinned character's shadowed-relighting model and the scene's
//! environment lighting (docs/RELIGHTING.md), sent after the welcome to clients that
//! announce [`crate::capabilities::RELIGHT`].
//!
//! The model travels as the bytes of `psao-prt`'s model file (magic, version, counts, pose
//! limits, f32 weights and a checksum); this crate bounds its size and the client's reader
//! validates the rest. The lighting is order-4 SH radiance in world space, 16 coefficients
//! per colour channel.

use serde::{Deserialize, Serialize};

use crate::WireError;

/// Largest model file a relighting message may carry, bytes (below the server frame limit;
/// a 35 000-vertex character with 2 lobes and 19 active joints is 114 MB).
pub const MAX_MODEL_BYTES: usize = 192 << 20;
/// SH coefficients per lighting channel (order 4).
pub const SH_COEFFS: usize = 16;
/// Most lighting channels (RGB, or RGB and one more).
pub const MAX_LIGHT_CHANNELS: usize = 4;

/// Server → client: one character's relighting model and the scene's lighting.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RelightingMsg {
    /// Index of the character among the scene's skinned characters (the `N` of
    /// `/characters/N.prt`).
    pub character: u32,
    /// The model file's bytes.
    #[serde(with = "serde_bytes")]
    pub model: Vec<u8>,
    /// SH radiance in world space: [`SH_COEFFS`] numbers per channel, channel after channel.
    pub lighting: Vec<f32>,
}

impl RelightingMsg {
    /// Lighting channels.
    pub fn channels(&self) -> usize {
        self.lighting.len() / SH_COEFFS
    }

    /// A model of at most [`MAX_MODEL_BYTES`] that is not empty; 1 to
    /// [`MAX_LIGHT_CHANNELS`] whole channels of finite lighting.
    pub fn validate(&self) -> Result<(), WireError> {
        if self.model.is_empty() || self.model.len() > MAX_MODEL_BYTES {
            return Err(WireError::Invalid(format!(
                "relighting model of {} bytes (must be 1 to {MAX_MODEL_BYTES})",
                self.model.len()
            )));
        }
        let n = self.lighting.len();
        if self.channels() * SH_COEFFS != n || n == 0 || n > SH_COEFFS * MAX_LIGHT_CHANNELS {
            return Err(WireError::Invalid(format!(
                "relighting lighting of {n} numbers (must be 1 to {MAX_LIGHT_CHANNELS} channels \
                 of {SH_COEFFS})"
            )));
        }
        if !self.lighting.iter().all(|x| x.is_finite()) {
            return Err(WireError::Invalid(
                "relighting lighting is not finite".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{decode_frame, encode_frame, Message, MAX_SERVER_FRAME};

    fn msg() -> RelightingMsg {
        RelightingMsg {
            character: 2,
            model: b"PSAOPRT\0 model bytes".to_vec(),
            lighting: (0..3 * SH_COEFFS).map(|i| i as f32 * 0.1).collect(),
        }
    }

    #[test]
    fn a_relighting_message_round_trips() {
        let m = Message::Relighting(msg());
        let bytes = encode_frame(&m).unwrap();
        assert_eq!(decode_frame(&bytes, MAX_SERVER_FRAME).unwrap(), m);
        assert_eq!(msg().channels(), 3);
        assert_eq!(m.kind(), "relighting");
    }

    #[test]
    fn malformed_relighting_messages_are_refused_with_the_reason() {
        type Spoil = fn(&mut RelightingMsg);
        let cases: [(Spoil, &str); 5] = [
            (|m| m.model.clear(), "model of 0 bytes"),
            (|m| m.model = vec![0; MAX_MODEL_BYTES + 1], "model of"),
            (|m| m.lighting.truncate(20), "lighting of 20 numbers"),
            (
                |m| m.lighting = vec![0.0; 5 * SH_COEFFS],
                "lighting of 80 numbers",
            ),
            (|m| m.lighting[7] = f32::NAN, "not finite"),
        ];
        for (spoil, reason) in cases {
            let mut m = msg();
            spoil(&mut m);
            let err = Message::Relighting(m.clone()).validate().unwrap_err();
            assert!(err.to_string().contains(reason), "{err}");
            // Encoding refuses it too, and bytes that decode to it are refused on decoding.
            assert!(encode_frame(&Message::Relighting(m)).is_err());
        }
        // A frame whose lighting was spoilt after encoding: a clear decoding error.
        let good = encode_frame(&Message::Relighting(msg())).unwrap();
        let mut payload = good[crate::HEADER_LEN..].to_vec();
        // The last lighting number's bytes (f32 little-endian at the end) become a NaN.
        let end = payload.len();
        payload[end - 4..].copy_from_slice(&f32::NAN.to_le_bytes());
        let spoilt = crate::frame_payload(&payload).unwrap();
        let err = decode_frame(&spoilt, MAX_SERVER_FRAME).unwrap_err();
        assert!(matches!(err, WireError::Invalid(_)), "{err}");
        // Truncated bytes are malformed or truncated, never a panic.
        assert!(decode_frame(&good[..good.len() - 3], MAX_SERVER_FRAME).is_err());
    }
}
