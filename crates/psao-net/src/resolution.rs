//! Image resolutions given as `WxH`.

use std::str::FromStr;

/// Largest image side accepted on the command line.
pub const MAX_IMAGE_SIDE: u32 = 16_384;

/// An image resolution given as `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resolution {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// A resolution string that is malformed or out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ResolutionError(String);

impl FromStr for Resolution {
    type Err = ResolutionError;
    fn from_str(s: &str) -> Result<Self, ResolutionError> {
        let bad = || ResolutionError(format!("resolution '{s}' is not of the form WIDTHxHEIGHT"));
        let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
        let width: u32 = w.trim().parse().map_err(|_| bad())?;
        let height: u32 = h.trim().parse().map_err(|_| bad())?;
        if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            return Err(ResolutionError(format!(
                "resolution '{s}' out of range: each side must be 1..={MAX_IMAGE_SIDE}"
            )));
        }
        Ok(Self { width, height })
    }
}

impl std::fmt::Display for Resolution {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_resolutions() {
        let r: Resolution = "640x360".parse().unwrap();
        assert_eq!((r.width, r.height), (640, 360));
        assert!("640".parse::<Resolution>().is_err());
        assert!("0x10".parse::<Resolution>().is_err());
        assert!("100000x10".parse::<Resolution>().is_err());
        assert!("axb".parse::<Resolution>().is_err());
    }
}
