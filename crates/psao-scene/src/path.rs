//! Camera paths: keyframes in a TOML file, sampled with a centripetal Catmull-Rom spline
//! at [`PATH_HZ`].
//!
//! ```toml
//! name = "sponza_nave"          # optional (default: the file stem)
//! fov_y_deg = 60.0              # default for keys that omit it
//! [[key]]
//! time = 0.0                    # seconds, strictly increasing
//! position = [0.0, 1.5, 0.0]
//! look_at = [1.0, 1.5, 0.0]
//! fov_y_deg = 55.0              # optional
//! ```

use std::path::Path;

use glam::Vec3;
use serde::Deserialize;

use crate::camera::Camera;
use crate::error::{read_file, toml_message, SceneError};

/// Rate at which paths are turned into frames (DESIGN §5).
pub const PATH_HZ: f32 = 60.0;

/// Longest accepted path (one day), so frame counts stay sane.
const MAX_DURATION_S: f32 = 86_400.0;

/// One keyframe of a camera path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraKey {
    /// Time in seconds.
    pub time: f32,
    /// Eye position.
    pub position: Vec3,
    /// Point looked at.
    pub look_at: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

/// A validated camera path: at least two keys with strictly increasing times.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    /// Path name.
    pub name: String,
    /// Keyframes, times strictly increasing.
    pub keys: Vec<CameraKey>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PathFile {
    name: Option<String>,
    fov_y_deg: Option<f32>,
    #[serde(default)]
    key: Vec<KeyFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyFile {
    time: f32,
    position: [f32; 3],
    look_at: [f32; 3],
    fov_y_deg: Option<f32>,
}

/// Vertical FOV used when neither the file nor the key gives one.
pub(crate) const DEFAULT_FOV_Y_DEG: f32 = 60.0;

impl CameraPath {
    /// Loads and validates a camera path file.
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let bytes = read_file(path)?;
        let text = String::from_utf8(bytes)
            .map_err(|_| SceneError::parse(path, "camera path", "file is not UTF-8 text"))?;
        let stem = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        Self::parse_named(&text, path, stem)
    }

    /// Parses and validates camera path text (errors name the source `<text>`).
    pub fn parse(text: &str) -> Result<Self, SceneError> {
        Self::parse_named(text, Path::new("<text>"), "path".into())
    }

    fn parse_named(text: &str, path: &Path, default_name: String) -> Result<Self, SceneError> {
        let bad = |message: String| SceneError::parse(path, "camera path", message);
        let file: PathFile = toml::from_str(text).map_err(|e| bad(toml_message(text, &e)))?;
        let default_fov = file.fov_y_deg.unwrap_or(DEFAULT_FOV_Y_DEG);
        let keys: Vec<CameraKey> = file
            .key
            .iter()
            .map(|k| CameraKey {
                time: k.time,
                position: Vec3::from_array(k.position),
                look_at: Vec3::from_array(k.look_at),
                fov_y_deg: k.fov_y_deg.unwrap_or(default_fov),
            })
            .collect();
        if keys.len() < 2 {
            return Err(bad(format!(
                "needs at least 2 [[key]] entries, found {}",
                keys.len()
            )));
        }
        for (i, k) in keys.iter().enumerate() {
            if !(k.time.is_finite()
                && k.position.is_finite()
                && k.look_at.is_finite()
                && k.fov_y_deg.is_finite())
            {
                return Err(SceneError::non_finite(path, format!("camera key {i}")));
            }
            if !(k.fov_y_deg > 0.0 && k.fov_y_deg < 180.0) {
                return Err(bad(format!(
                    "key {i}: fov_y_deg {} outside (0, 180)",
                    k.fov_y_deg
                )));
            }
            let dir = k.look_at - k.position;
            if dir.length() < 1e-6 {
                return Err(bad(format!("key {i}: position equals look_at")));
            }
            if dir.normalize().cross(Vec3::Y).length() < 1e-4 {
                return Err(bad(format!(
                    "key {i}: looks straight up or down (parallel to the +Y up vector)"
                )));
            }
            if i > 0 && k.time <= keys[i - 1].time {
                return Err(bad(format!(
                    "key {i}: time {} is not after {}",
                    k.time,
                    keys[i - 1].time
                )));
            }
        }
        let duration = keys[keys.len() - 1].time - keys[0].time;
        if duration > MAX_DURATION_S {
            return Err(bad(format!(
                "duration {duration} s exceeds {MAX_DURATION_S} s"
            )));
        }
        Ok(Self {
            name: file.name.unwrap_or(default_name),
            keys,
        })
    }

    /// Length in seconds from the first to the last key.
    pub fn duration(&self) -> f32 {
        self.keys[self.keys.len() - 1].time - self.keys[0].time
    }

    /// The camera at time `t` (file time, clamped to the key range): centripetal
    /// Catmull-Rom on position and look-at (end keys duplicated), FOV linear.
    pub fn sample(&self, t: f32) -> Camera {
        let k = &self.keys;
        let t = t.clamp(k[0].time, k[k.len() - 1].time);
        // Segment i runs from key i to key i + 1; a time equal to a key starts its segment.
        let i = k[1..k.len() - 1].partition_point(|key| key.time <= t);
        let (a, b) = (&k[i], &k[i + 1]);
        let u = ((t - a.time) / (b.time - a.time)).clamp(0.0, 1.0);
        let prev = &k[i.saturating_sub(1)];
        let next = &k[(i + 2).min(k.len() - 1)];
        let position = catmull_rom([prev.position, a.position, b.position, next.position], u);
        let look_at = catmull_rom([prev.look_at, a.look_at, b.look_at, next.look_at], u);
        let fov = a.fov_y_deg + (b.fov_y_deg - a.fov_y_deg) * u;
        Camera::look_at(position, look_at, fov)
    }

    /// Number of frames at [`PATH_HZ`]: `floor(duration · 60) + 1`.
    pub fn frame_count(&self) -> usize {
        (self.duration() * PATH_HZ).floor() as usize + 1
    }

    /// The camera of frame `i` (time `first key + i / 60`, clamped at the end).
    pub fn camera_at_frame(&self, i: usize) -> Camera {
        self.sample(self.keys[0].time + i as f32 / PATH_HZ)
    }

    /// The path as camera path file text, which [`CameraPath::parse`] reads back exactly
    /// (every number is written in its shortest form that round-trips).
    pub fn to_toml(&self) -> String {
        let v = |v: Vec3| format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z);
        let mut text = format!("name = {}\n", toml::Value::String(self.name.clone()));
        for k in &self.keys {
            text += &format!(
                "\n[[key]]\ntime = {:?}\nposition = {}\nlook_at = {}\nfov_y_deg = {:?}\n",
                k.time,
                v(k.position),
                v(k.look_at),
                k.fov_y_deg
            );
        }
        text
    }
}

/// Centripetal Catmull-Rom between `p[1]` (u = 0) and `p[2]` (u = 1) in Hermite form.
/// Zero-length knot intervals (duplicated or repeated points) contribute zero tangent,
/// the limit of the centripetal tangent as the interval vanishes.
fn catmull_rom(p: [Vec3; 4], u: f32) -> Vec3 {
    let knot = |a: Vec3, b: Vec3| a.distance(b).sqrt();
    let (d0, d1, d2) = (knot(p[0], p[1]), knot(p[1], p[2]), knot(p[2], p[3]));
    let div = |v: Vec3, d: f32| if d > 1e-12 { v / d } else { Vec3::ZERO };
    let m1 = (div(p[1] - p[0], d0) - div(p[2] - p[0], d0 + d1) + div(p[2] - p[1], d1)) * d1;
    let m2 = (div(p[2] - p[1], d1) - div(p[3] - p[1], d1 + d2) + div(p[3] - p[2], d2)) * d1;
    let (u2, u3) = (u * u, u * u * u);
    p[1] * (2.0 * u3 - 3.0 * u2 + 1.0)
        + m1 * (u3 - 2.0 * u2 + u)
        + p[2] * (3.0 * u2 - 2.0 * u3)
        + m2 * (u3 - u2)
}
