//! The relit characters a server hands out (docs/RELIGHTING.md, "Served characters"): each
//! skinned character's model file, served at `GET /characters/N.prt` (with
//! `GET /characters/index.json` telling the browser how many there are and the lighting,
//! [`ServedCharacters::index_json`]) and sent in a
//! [`Message::Relighting`] after the welcome to clients that announce
//! [`capabilities::RELIGHT`], with the scene's environment lighting as order-4 SH.
//!
//! The models are made (trained or read from the cache) by the caller; this module only
//! bounds and serves them.

use bytes::Bytes;
use psao_wire::{capabilities, Message, RelightingMsg, MAX_MODEL_BYTES};

use crate::NetError;

/// Longest `N` accepted in `/characters/N.prt` (digits).
const MAX_INDEX_DIGITS: usize = 6;

/// The models and the lighting served; empty when the server relights nothing.
#[derive(Clone, Debug, Default)]
pub struct ServedCharacters {
    models: Vec<Bytes>,
    lighting: Vec<f32>,
}

impl ServedCharacters {
    /// Model files (character `N` is `models[N]`) and SH lighting (16 numbers per channel),
    /// checked as a [`RelightingMsg`] is.
    pub fn new(models: Vec<Vec<u8>>, lighting: Vec<f32>) -> Result<Self, NetError> {
        let served = Self {
            models: models.into_iter().map(Bytes::from).collect(),
            lighting,
        };
        for m in served.messages() {
            m.validate()?;
        }
        Ok(served)
    }

    /// Characters served.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }

    /// The model file of `/characters/N.prt` for a request `path`; `None` for any other path
    /// or an `N` out of range.
    pub fn model_at(&self, path: &str) -> Option<Bytes> {
        let n = path.strip_prefix("/characters/")?.strip_suffix(".prt")?;
        if n.is_empty() || n.len() > MAX_INDEX_DIGITS || !n.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        self.models.get(n.parse::<usize>().ok()?).cloned()
    }

    /// `/characters/index.json`: `{"count": N, "lighting": [...]}`, the characters served
    /// (`/characters/0.prt` … `N−1`) and the SH lighting they are relit under (16 numbers per
    /// colour channel, as in the relighting messages; empty when none is served).
    pub fn index_json(&self) -> Bytes {
        let index = serde_json::json!({ "count": self.models.len(), "lighting": self.lighting });
        Bytes::from(index.to_string())
    }

    /// The relighting messages a client with `client_capabilities` is sent after the welcome
    /// (none without [`capabilities::RELIGHT`]).
    pub fn messages_for(&self, client_capabilities: u32) -> Vec<Message> {
        if client_capabilities & capabilities::RELIGHT == 0 {
            return Vec::new();
        }
        self.messages()
    }

    fn messages(&self) -> Vec<Message> {
        self.models
            .iter()
            .enumerate()
            .map(|(i, m)| {
                Message::Relighting(RelightingMsg {
                    character: i as u32,
                    model: m.to_vec(),
                    lighting: self.lighting.clone(),
                })
            })
            .collect()
    }
}

/// Whether `len` bytes may be a served model file.
pub fn model_size_ok(len: u64) -> bool {
    len > 0 && len <= MAX_MODEL_BYTES as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn served() -> ServedCharacters {
        ServedCharacters::new(vec![b"zero".to_vec(), b"one".to_vec()], vec![0.5; 48]).unwrap()
    }

    #[test]
    fn paths_name_models_by_index_and_nothing_else() {
        let s = served();
        assert_eq!(s.model_at("/characters/0.prt").unwrap(), &b"zero"[..]);
        assert_eq!(s.model_at("/characters/1.prt").unwrap(), &b"one"[..]);
        for bad in [
            "/characters/2.prt",
            "/characters/.prt",
            "/characters/-1.prt",
            "/characters/+1.prt",
            "/characters/1",
            "/characters/99999999999999999999.prt",
            "/characters/0.prt/x",
            "/scene.glb",
        ] {
            assert!(s.model_at(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn messages_go_only_to_clients_that_relight() {
        let s = served();
        assert!(s.messages_for(capabilities::STATE_HASH).is_empty());
        let m = s.messages_for(capabilities::RELIGHT | capabilities::STATE_HASH);
        assert_eq!(m.len(), 2);
        let Message::Relighting(r) = &m[1] else {
            panic!("{m:?}")
        };
        assert_eq!((r.character, r.model.as_slice()), (1, &b"one"[..]));
        assert_eq!(r.channels(), 3);
    }

    #[test]
    fn the_index_lists_the_count_and_the_lighting_exactly() {
        let lighting: Vec<f32> = (0..48).map(|i| 0.1 + i as f32 / 7.0).collect();
        let s = ServedCharacters::new(vec![b"m".to_vec(); 3], lighting.clone()).unwrap();
        let index: serde_json::Value = serde_json::from_slice(&s.index_json()).unwrap();
        assert_eq!(index["count"], 3);
        let got: Vec<f32> = index["lighting"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(got, lighting, "every number reads back to the same f32");
        let none: serde_json::Value =
            serde_json::from_slice(&ServedCharacters::default().index_json()).unwrap();
        assert_eq!(none, serde_json::json!({ "count": 0, "lighting": [] }));
    }

    #[test]
    fn bad_lighting_or_empty_models_are_refused() {
        assert!(ServedCharacters::new(vec![Vec::new()], vec![0.0; 48]).is_err());
        assert!(ServedCharacters::new(vec![b"m".to_vec()], vec![0.0; 47]).is_err());
        assert!(ServedCharacters::new(Vec::new(), Vec::new())
            .unwrap()
            .is_empty());
    }
}
