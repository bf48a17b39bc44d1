//! Loading glTF buffers (GLB chunk, external files, base64 data URIs) and reading URIs.
//!
//! A glTF file may come from anyone, so the files its URIs name are confined: a URI must
//! resolve (symbolic links followed) to a regular file inside the glTF's own folder, and no
//! more bytes are read than the buffer declares (or than an image may have).

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use ::gltf::buffer::Source;
use ::gltf::Document;

use crate::error::SceneError;

/// Loads every buffer of `doc`; `path` is the glTF file, `folder` the folder its external
/// URIs are relative to (`None`: a glTF read from memory may not name files). Each buffer
/// must hold at least the bytes the file declares; of a file only those are read.
pub(super) fn load_buffers(
    doc: &Document,
    mut blob: Option<Vec<u8>>,
    path: &Path,
    folder: Option<&Path>,
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
        let declared = buffer.length() as u64;
        let data = match buffer.source() {
            Source::Bin => blob
                .take()
                .ok_or_else(|| missing(format!("buffer {i} refers to a missing GLB BIN chunk")))?,
            Source::Uri(uri) => {
                read_uri(uri, folder, Limit::Prefix(declared)).map_err(|e| match e {
                    UriError::Io(file, e) => SceneError::io(&file, e),
                    UriError::Short(len) => missing(format!(
                        "{label} is a file of {len} bytes but the glTF declares {declared}"
                    )),
                    UriError::Bad(msg) => {
                        SceneError::parse(path, "glTF", format!("buffer {i}: {msg}"))
                    }
                })?
            }
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
    /// The file it names has fewer bytes (given) than its buffer declares.
    Short(u64),
    /// The URI is malformed, unsupported, names a file outside the glTF's folder or not a
    /// regular file, or names too much data.
    Bad(String),
}

/// How much of a URI's data is read.
#[derive(Clone, Copy, Debug)]
pub(super) enum Limit {
    /// At most this many bytes: more is an error.
    AtMost(u64),
    /// The first this many bytes of a file (of a data URI, all of it); fewer is an error.
    Prefix(u64),
}

/// Reads a URI: `data:…;base64,…`, or a `file:` URI or percent-encoded relative path that
/// resolves to a regular file inside `folder` (the glTF's folder; `None`: no files).
pub(super) fn read_uri(
    uri: &str,
    folder: Option<&Path>,
    limit: Limit,
) -> Result<Vec<u8>, UriError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| UriError::Bad("data URI is not base64".into()))?;
        let data =
            decode_base64(payload).ok_or_else(|| UriError::Bad("invalid base64 data".into()))?;
        return match (limit, data.len() as u64) {
            (Limit::AtMost(max), len) if len > max => Err(too_long(len, max)),
            _ => Ok(data),
        };
    }
    let named = if let Some(rest) = uri.strip_prefix("file://") {
        rest
    } else if let Some(rest) = uri.strip_prefix("file:") {
        rest
    } else if uri.contains(':') {
        return Err(UriError::Bad(format!("unsupported URI scheme in '{uri}'")));
    } else {
        uri
    };
    let decoded = percent_decode(named)
        .ok_or_else(|| UriError::Bad(format!("invalid percent-encoding in '{uri}'")))?;
    let folder = folder.ok_or_else(|| {
        UriError::Bad(format!(
            "'{uri}' names a file, but this glTF was not read from a folder"
        ))
    })?;
    let file = confined(uri, folder, Path::new(&decoded))?;
    let not_regular = || {
        UriError::Bad(format!(
            "'{uri}' ({}) is not a regular file",
            file.display()
        ))
    };
    // Checked before opening (opening a FIFO would block) and again on the opened file.
    let meta = std::fs::metadata(&file).map_err(|e| UriError::Io(file.clone(), e))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let f = File::open(&file).map_err(|e| UriError::Io(file.clone(), e))?;
    let meta = f.metadata().map_err(|e| UriError::Io(file.clone(), e))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let take = match limit {
        Limit::AtMost(max) if meta.len() > max => return Err(too_long(meta.len(), max)),
        Limit::AtMost(max) => max,
        Limit::Prefix(len) if meta.len() < len => return Err(UriError::Short(meta.len())),
        Limit::Prefix(len) => len,
    };
    let mut data = Vec::with_capacity(take.min(meta.len()) as usize);
    f.take(take)
        .read_to_end(&mut data)
        .map_err(|e| UriError::Io(file, e))?;
    Ok(data)
}

fn too_long(len: u64, max: u64) -> UriError {
    UriError::Bad(format!("{len} bytes, more than the limit of {max}"))
}

/// `named` (relative to `folder`, or absolute) resolved with every symbolic link followed,
/// if it lies inside `folder`.
fn confined(uri: &str, folder: &Path, named: &Path) -> Result<PathBuf, UriError> {
    let root = folder
        .canonicalize()
        .map_err(|e| UriError::Io(folder.to_path_buf(), e))?;
    let joined = root.join(named);
    let real = joined
        .canonicalize()
        .map_err(|e| UriError::Io(joined.clone(), e))?;
    if !real.starts_with(&root) {
        return Err(UriError::Bad(format!(
            "'{uri}' resolves to {}, outside the glTF's folder {}",
            real.display(),
            root.display()
        )));
    }
    Ok(real)
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
