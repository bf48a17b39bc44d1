//! MP4 from written PNG frames, through `ffmpeg` when it is installed.

use std::path::Path;
use std::process::Command;

/// Encodes `dir/frame_*.png` at `fps` into `dir/name` with ffmpeg; says what happened (the
/// file in backquotes, or why there are PNG frames only).
pub fn encode_video(dir: &Path, fps: u32, name: &str) -> String {
    let status = Command::new("ffmpeg")
        .args(["-y", "-loglevel", "error", "-framerate", &fps.to_string()])
        .args(["-pattern_type", "glob", "-i"])
        .arg(dir.join("frame_*.png"))
        .args([
            "-pix_fmt",
            "yuv420p",
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
        ])
        .arg(dir.join(name))
        .status();
    match status {
        Ok(s) if s.success() => format!("`{name}`"),
        Ok(s) => format!("ffmpeg failed ({s}); PNG frames only"),
        Err(_) => "ffmpeg not installed; PNG frames only".into(),
    }
}
