//! The messages (DESIGN §4) and their validation rules.

use serde::{Deserialize, Serialize};

use crate::corrective::{RegionsMsg, SamplesMsg};
use crate::relighting::RelightingMsg;
use crate::WireError;

/// Protocol version spoken here; a hello with another version is refused.
pub const PROTOCOL_VERSION: u16 = 2;
/// Longest access token, bytes.
pub const MAX_TOKEN: usize = 256;
/// Longest free-text field (names, reasons, error messages), bytes.
pub const MAX_TEXT: usize = 1024;
/// Longest codec name, bytes.
pub const MAX_CODEC_NAME: usize = 32;
/// Most instances a welcome may list.
pub const MAX_INSTANCES: usize = 1 << 20;

/// Capability bits a client announces in its [`Hello`].
pub mod capabilities {
    /// Decodes the `paper` codec.
    pub const CODEC_PAPER: u32 = 1;
    /// Decodes the `compact` codec.
    pub const CODEC_COMPACT: u32 = 2;
    /// Wants the server's state hash with every delta (to verify its mirror).
    pub const STATE_HASH: u32 = 4;
    /// Wants corrective-splatting samples for the regions it sends (a server without
    /// corrections ignores the bit and the regions).
    pub const CORRECTIVE: u32 = 8;
    /// Understands [`super::Message::Status`] (a server sends it only to such clients).
    pub const STATUS: u32 = 16;
    /// Relights skinned characters: wants [`super::Message::Relighting`] after the welcome
    /// (docs/RELIGHTING.md).
    pub const RELIGHT: u32 = 32;
    /// Every bit defined by this version.
    pub const ALL: u32 = CODEC_PAPER | CODEC_COMPACT | STATE_HASH | CORRECTIVE | STATUS | RELIGHT;
}

/// Every message of the protocol; the variant index (a postcard varint) comes first.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// 0, client → server, first message: who is connecting.
    Hello(Hello),
    /// 1, server → client, answer to a good hello.
    Welcome(Welcome),
    /// 2, client → server: the client's current camera.
    Camera(CameraMsg),
    /// 3, server → client: the server's scene time (lockstep: "frame N done, no update").
    SceneTime(SceneTime),
    /// 4, client → server: deltas up to this server frame were applied.
    Ack(Ack),
    /// 5, server → client: what changed since the client's previous delta.
    Delta(Delta),
    /// 6, server → client: the full state (first update, or after a resync).
    Snapshot(Delta),
    /// 7, either way: a fatal error; the sender closes the session after it.
    Error(ErrorMsg),
    /// 8, either way: orderly end of the session.
    Bye(Bye),
    /// 9, client → server: the regions of the client's latest frame analysis (corrections).
    Regions(RegionsMsg),
    /// 10, server → client: correction samples traced for the client's camera.
    Samples(SamplesMsg),
    /// 11, server → client (only with [`capabilities::STATUS`]): updates stalled, or flowing
    /// again (a scale-out edge waiting for its trace nodes, docs/SCALE-OUT.md).
    Status(StatusMsg),
    /// 12, server → client (only with [`capabilities::RELIGHT`]), after the welcome: a
    /// skinned character's relighting model and the scene's lighting.
    Relighting(RelightingMsg),
}

/// Client → server, first message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// [`PROTOCOL_VERSION`] of the client.
    pub version: u16,
    /// [`capabilities`] bits.
    pub capabilities: u32,
    /// Access token, when the server requires one.
    pub token: Option<String>,
    /// Free-form client name for logs.
    pub name: String,
}

/// One instance of the server's instance table: its grid layout and point statistics.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstanceEntry {
    /// Local-space corner of cell (0, 0, 0).
    pub origin: [f32; 3],
    /// Edge length of a cell, local units.
    pub cell_size: f32,
    /// Cells per axis.
    pub dims: [u32; 3],
    /// Poisson radius stored in the grid layout.
    pub layout_poisson_radius: f32,
    /// Number of hash buckets (a power of two).
    pub bucket_count: u32,
    /// Poisson radius of the instance's points (reconstruction radius base).
    pub poisson_radius: f32,
    /// Points stored in the instance's grid.
    pub point_count: u32,
}

/// Server → client, answer to a hello.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// [`PROTOCOL_VERSION`] of the server.
    pub version: u16,
    /// The id the server gave this session.
    pub client_id: u32,
    /// Codec of every delta and snapshot payload of this session.
    pub codec: String,
    /// Server frames per second of scene time.
    pub server_hz: u32,
    /// Client frames per second of scene time the server assumes (60).
    pub client_hz: u32,
    /// Whether the server steps in lockstep with its clients' camera messages.
    pub lockstep: bool,
    /// Scene name.
    pub scene: String,
    /// Server frame at the time of joining.
    pub frame: u64,
    /// Scene time at the time of joining, seconds.
    pub scene_time: f64,
    /// The instance table.
    pub instances: Vec<InstanceEntry>,
}

/// Client → server: the camera the client renders with.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraMsg {
    /// Client frame number (on its camera path).
    pub frame: u32,
    /// Eye position.
    pub position: [f32; 3],
    /// Point looked at.
    pub target: [f32; 3],
    /// Up hint.
    pub up: [f32; 3],
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Near clip distance.
    pub near: f32,
    /// Far clip distance.
    pub far: f32,
    /// Image width / height.
    pub aspect: f32,
}

/// Server → client: scene time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneTime {
    /// Current server frame.
    pub frame: u64,
    /// Scene time, seconds.
    pub seconds: f64,
    /// Lockstep: the client frame this answers (no update was due for it).
    pub client_frame: Option<u32>,
}

/// Client → server: every delta up to server frame `frame` was applied.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ack {
    /// Server frame of the latest applied delta or snapshot.
    pub frame: u64,
}

/// Server → client: an encoded update (delta or snapshot).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Delta {
    /// Server frame the update was taken at.
    pub frame: u64,
    /// Scene time of that frame, seconds.
    pub scene_time: f64,
    /// Lockstep: the client frame this update answers.
    pub client_frame: Option<u32>,
    /// Hash of the server's buckets + cells at `frame` (when the client asked for it).
    pub state_hash: Option<u64>,
    /// The update, encoded with the session's codec.
    #[serde(with = "serde_bytes")]
    pub payload: Vec<u8>,
}

/// Why a session ended with an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ErrorCode {
    /// 0: the peer speaks another protocol version.
    Version,
    /// 1: missing or wrong token.
    Token,
    /// 2: a frame failed to decode (magic, size, checksum, postcard, validation).
    Frame,
    /// 3: a valid message at the wrong time (e.g. a camera before the hello).
    Protocol,
    /// 4: the payload could not be decoded or applied.
    Update,
    /// 5: the server is shutting down or failed.
    Server,
}

/// A fatal error; the session closes after it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorMsg {
    /// Machine-readable reason.
    pub code: ErrorCode,
    /// Human-readable explanation.
    pub message: String,
}

/// How the server is doing, sent when it changes; not an error: the session goes on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatusMsg {
    /// Whether updates are stalled.
    pub stalled: bool,
    /// Human-readable explanation (empty when updates flow again).
    pub text: String,
}

/// Orderly end of a session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bye {
    /// Human-readable reason.
    pub reason: String,
}

fn check_text(what: &str, text: &str, max: usize) -> Result<(), WireError> {
    if text.len() > max {
        return Err(WireError::Invalid(format!(
            "{what} of {} bytes exceeds {max}",
            text.len()
        )));
    }
    Ok(())
}

fn check_finite(what: &str, values: &[f32]) -> Result<(), WireError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(WireError::Invalid(format!("{what} is not finite")))
    }
}

impl CameraMsg {
    /// Finite numbers, `0 < fov_y < π`, `0 < near < far`, `aspect > 0`, position ≠ target:
    /// the cameras a server steps for (also those that reach it through scale-out views).
    pub fn validate(&self) -> Result<(), WireError> {
        let mut all = Vec::with_capacity(13);
        for v in [self.position, self.target, self.up] {
            all.extend_from_slice(&v);
        }
        all.extend_from_slice(&[self.fov_y, self.near, self.far, self.aspect]);
        check_finite("camera", &all)?;
        let ok = self.fov_y > 0.0
            && self.fov_y < std::f32::consts::PI
            && self.near > 0.0
            && self.far > self.near
            && self.aspect > 0.0
            && self.position != self.target;
        if !ok {
            return Err(WireError::Invalid(
                "camera: need 0 < fov_y < π, 0 < near < far, aspect > 0, position ≠ target".into(),
            ));
        }
        Ok(())
    }
}

impl Message {
    /// Check the rules the type system does not: text and table sizes, finite numbers,
    /// sane cameras. Decoding calls it; so does encoding.
    pub fn validate(&self) -> Result<(), WireError> {
        match self {
            Message::Hello(h) => {
                if let Some(t) = &h.token {
                    check_text("token", t, MAX_TOKEN)?;
                }
                check_text("client name", &h.name, MAX_TEXT)
            }
            Message::Welcome(w) => {
                check_text("codec name", &w.codec, MAX_CODEC_NAME)?;
                check_text("scene name", &w.scene, MAX_TEXT)?;
                if w.instances.len() > MAX_INSTANCES {
                    return Err(WireError::Invalid(format!(
                        "{} instances exceed {MAX_INSTANCES}",
                        w.instances.len()
                    )));
                }
                if !w.scene_time.is_finite() {
                    return Err(WireError::Invalid("scene time is not finite".into()));
                }
                w.instances.iter().try_for_each(|i| {
                    let [x, y, z] = i.origin;
                    let values = [
                        x,
                        y,
                        z,
                        i.cell_size,
                        i.layout_poisson_radius,
                        i.poisson_radius,
                    ];
                    check_finite("instance entry", &values)
                })
            }
            Message::Camera(c) => c.validate(),
            Message::SceneTime(t) if !t.seconds.is_finite() => {
                Err(WireError::Invalid("scene time is not finite".into()))
            }
            Message::Delta(d) | Message::Snapshot(d) if !d.scene_time.is_finite() => {
                Err(WireError::Invalid("scene time is not finite".into()))
            }
            Message::Error(e) => check_text("error message", &e.message, MAX_TEXT),
            Message::Bye(b) => check_text("bye reason", &b.reason, MAX_TEXT),
            Message::Status(s) => check_text("status text", &s.text, MAX_TEXT),
            Message::Regions(r) => r.validate(),
            Message::Samples(s) => s.validate(),
            Message::Relighting(r) => r.validate(),
            _ => Ok(()),
        }
    }

    /// Short name of the message kind (for logs and errors).
    pub fn kind(&self) -> &'static str {
        match self {
            Message::Hello(_) => "hello",
            Message::Welcome(_) => "welcome",
            Message::Camera(_) => "camera",
            Message::SceneTime(_) => "scene time",
            Message::Ack(_) => "ack",
            Message::Delta(_) => "delta",
            Message::Snapshot(_) => "snapshot",
            Message::Error(_) => "error",
            Message::Bye(_) => "bye",
            Message::Regions(_) => "regions",
            Message::Samples(_) => "samples",
            Message::Status(_) => "status",
            Message::Relighting(_) => "relighting",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_rejects_oversized_and_non_finite_fields() {
        let hello = |token: &str| {
            Message::Hello(Hello {
                version: PROTOCOL_VERSION,
                capabilities: 0,
                token: Some(token.into()),
                name: String::new(),
            })
        };
        assert!(hello("ok").validate().is_ok());
        assert!(hello(&"x".repeat(MAX_TOKEN + 1)).validate().is_err());
        let mut cam = CameraMsg {
            frame: 0,
            position: [0.0, 1.0, 0.0],
            target: [0.0, 1.0, -1.0],
            up: [0.0, 1.0, 0.0],
            fov_y: 1.0,
            near: 0.1,
            far: 100.0,
            aspect: 1.5,
        };
        assert!(Message::Camera(cam).validate().is_ok());
        cam.position[1] = f32::NAN;
        assert!(Message::Camera(cam).validate().is_err());
        cam.position[1] = 1.0;
        cam.far = 0.01;
        assert!(Message::Camera(cam).validate().is_err());
        let t = Message::SceneTime(SceneTime {
            frame: 0,
            seconds: f64::INFINITY,
            client_frame: None,
        });
        assert!(t.validate().is_err());
    }
}
