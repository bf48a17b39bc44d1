//! Loading glTF buffers (GLB chunk, external files, base64 data URIs) and reading URIs.

use std::path::{Path, PathBuf};

use ::gltf::buffer::Source;
use ::gltf::Document;

use crate::error::SceneError;

/// Loads every buffer of `doc`; `path` is the glTF file (external URIs are relative to it).
/// Each buffer is checked to be at least as long as the file declares.
pub(super) fn load_buffers(
    doc: &Document,
    mut blob: Option<Vec<u8>>,
    path: &Path,
) -> Result<Vec<Vec<u8>>, SceneError> {
    let missing = |message: String| SceneError::MissingBuffer {
        path: path.to_path_buf(),
        message,
    };
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let label = match buffer.source() {
            Source::Bin => format!("buffer {i} (GLB BIN chunk)"),
            Source::Uri(uri) if uri.starts_with("data:") => format!("buffer {i} (data URI)"),
            Source::Uri(uri) => format!("buffer {i} ({uri})"),
        };
        let data = match buffer.source() {
            Source::Bin => blob
                .take()
                .ok_or_else(|| missing(format!("buffer {i} refers to a missing GLB BIN chunk")))?,
            Source::Uri(uri) => read_uri(uri, path, u64::MAX).map_err(|e| match e {
                UriError::Io(file, e) => SceneError::io(&file, e),
                UriError::Bad(msg) => SceneError::parse(path, "glTF", format!("buffer {i}: {msg}")),
            })?,
        };
        if data.len() < buffer.length() {
            return Err(missing(format!(
                "{label} has {} bytes but the file declares {}",
                data.len(),
                buffer.length()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// Why a URI could not be read.
pub(super) enum UriError {
    /// The file it names could not be read.
    Io(PathBuf, std::io::Error),
    /// The URI is malformed, unsupported or names too much data.
    Bad(String),
}

/// Reads a URI: `data:…;base64,…`, `file:` or a percent-encoded path relative to the glTF
/// file; at most `max_bytes` (a longer file is not read).
pub(super) fn read_uri(uri: &str, gltf_path: &Path, max_bytes: u64) -> Result<Vec<u8>, UriError> {
    let too_long =
        |len: u64| UriError::Bad(format!("{len} bytes, more than the limit of {max_bytes}"));
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| UriError::Bad("data URI is not base64".into()))?;
        let data =
            decode_base64(payload).ok_or_else(|| UriError::Bad("invalid base64 data".into()))?;
        return match data.len() as u64 {
            len if len > max_bytes => Err(too_long(len)),
            _ => Ok(data),
        };
    }
    let relative = if let Some(rest) = uri.strip_prefix("file://") {
        rest
    } else if let Some(rest) = uri.strip_prefix("file:") {
        rest
    } else if uri.contains(':') {
        return Err(UriError::Bad(format!("unsupported URI scheme in '{uri}'")));
    } else {
        uri
    };
    let decoded = percent_decode(relative)
        .ok_or_else(|| UriError::Bad(format!("invalid percent-encoding in '{uri}'")))?;
    let file: PathBuf = gltf_path
        .parent()
        .unwrap_or_else(|| Path::new(""))
        .join(decoded);
    let len = std::fs::metadata(&file)
        .map_err(|e| UriError::Io(file.clone(), e))?
        .len();
    if len > max_bytes {
        return Err(too_long(len));
    }
    std::fs::read(&file).map_err(|e| UriError::Io(file, e))
}

/// Decodes `%XX` escapes; `None` for malformed escapes or non-UTF-8 results.
fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = s.get(i + 1..i + 3)?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Standard base64 (with optional `=` padding) to bytes; `None` on any invalid character.
fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let s = s.trim_end_matches('=');
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_vectors() {
        assert_eq!(decode_base64("TWFu").unwrap(), b"Man");
        assert_eq!(decode_base64("TWE=").unwrap(), b"Ma");
        assert_eq!(decode_base64("TQ==").unwrap(), b"M");
        assert_eq!(decode_base64("").unwrap(), b"");
        assert!(decode_base64("TW!u").is_none());
    }

    #[test]
    fn percent_decoding_handles_escapes_and_rejects_garbage() {
        assert_eq!(percent_decode("a%20b.bin").unwrap(), "a b.bin");
        assert!(percent_decode("a%2").is_none());
        assert!(percent_decode("a%zz").is_none());
        assert!(percent_decode("%FF").is_none());
    }
}
