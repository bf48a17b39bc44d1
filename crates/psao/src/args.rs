//! Parsers for command-line values shared by several subcommands.

use anyhow::{bail, Context, Result};
use std::str::FromStr;

pub use psao_net::Resolution;

/// A half-open range of frame numbers given as `A..B`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    /// First frame.
    pub start: u32,
    /// One past the last frame.
    pub end: u32,
}

impl FromStr for FrameRange {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        let (a, b) = s
            .split_once("..")
            .with_context(|| format!("frame range '{s}' is not of the form A..B"))?;
        let start: u32 = a
            .trim()
            .parse()
            .with_context(|| format!("bad start in '{s}'"))?;
        let end: u32 = b
            .trim()
            .parse()
            .with_context(|| format!("bad end in '{s}'"))?;
        if end <= start {
            bail!("frame range '{s}' is empty (B must be greater than A)");
        }
        Ok(Self { start, end })
    }
}

impl FrameRange {
    /// `requested`, or else all `count` frames of a camera path, checked to lie within the path.
    pub fn within_path(requested: Option<FrameRange>, count: u32) -> Result<FrameRange> {
        let range = requested.unwrap_or(FrameRange {
            start: 0,
            end: count,
        });
        if range.end > count {
            bail!(
                "the camera path has {count} frames (0..{count}); asked for {}..{}",
                range.start,
                range.end
            );
        }
        Ok(range)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_frame_ranges() {
        let f: FrameRange = "10..20".parse().unwrap();
        assert_eq!((f.start, f.end), (10, 20));
        assert!("5..5".parse::<FrameRange>().is_err());
        assert!("5".parse::<FrameRange>().is_err());
        assert!("-1..3".parse::<FrameRange>().is_err());
    }

    #[test]
    fn frame_ranges_are_checked_against_the_path() {
        let all = FrameRange::within_path(None, 901).unwrap();
        assert_eq!((all.start, all.end), (0, 901));
        let r = FrameRange { start: 10, end: 20 };
        assert_eq!(FrameRange::within_path(Some(r), 20).unwrap(), r);
        assert!(FrameRange::within_path(Some(r), 19).is_err());
    }
}
