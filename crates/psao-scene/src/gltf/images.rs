//! Alpha masks: the alpha channel of the base-colour image of every alpha-masked material,
//! decoded from a buffer view, a data URI or a file next to the glTF. Only PNG is decoded;
//! JPEG has no alpha channel, so a JPEG mask is opaque everywhere and is not read.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;

use ::gltf::material::AlphaMode as GltfAlphaMode;
use ::gltf::Document;
use image::{DynamicImage, ImageFormat, ImageReader, Limits};
use rayon::prelude::*;

use super::buffers::{read_uri, Limit, UriError};
use crate::alpha::AlphaImage;
use crate::error::SceneError;

/// Largest encoded image accepted, in bytes.
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;

/// Largest image side accepted, in texels.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Most memory the PNG decoder may allocate (an 8192² RGBA image at 16 bits per channel).
const MAX_DECODE_ALLOC: u64 = 1 << 29;

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
const JPEG_SIGNATURE: &[u8] = b"\xff\xd8\xff";

/// Decoded masks by glTF image index; `None` for an image without alpha (opaque everywhere).
pub(super) type MaskImages = HashMap<usize, Option<Arc<AlphaImage>>>;

/// Decodes (in parallel) every image that an alpha-masked material uses as its base colour;
/// image files are read from `folder` (see [`read_uri`]).
pub(super) fn mask_images(
    doc: &Document,
    buffers: &[Vec<u8>],
    path: &Path,
    folder: Option<&Path>,
) -> Result<MaskImages, SceneError> {
    let mut users: Vec<(usize, String)> = Vec::new();
    for m in doc.materials() {
        if m.alpha_mode() != GltfAlphaMode::Mask {
            continue;
        }
        let Some(info) = m.pbr_metallic_roughness().base_color_texture() else {
            continue;
        };
        let image = info.texture().source().index();
        if users.iter().all(|(i, _)| *i != image) {
            let name = m.name().map_or_else(
                || format!("material{}", m.index().unwrap_or(0)),
                str::to_owned,
            );
            users.push((image, name));
        }
    }
    users
        .par_iter()
        .map(|(image, material)| {
            let label = label(doc, *image, material);
            let bytes = encoded(doc, *image, buffers, (path, folder), &label)?;
            Ok((*image, decode(&bytes, path, &label)?.map(Arc::new)))
        })
        .collect()
}

/// "image 3 ('leaf.png'), the base colour of alpha-masked material 'leaves'".
fn label(doc: &Document, image: usize, material: &str) -> String {
    let json = &doc.as_json().images[image];
    let source = match (&json.uri, &json.buffer_view) {
        (Some(uri), _) if uri.starts_with("data:") => " (data URI)".to_owned(),
        (Some(uri), _) => format!(" ('{uri}')"),
        (None, Some(view)) => format!(" (buffer view {})", view.value()),
        (None, None) => String::new(),
    };
    format!("image {image}{source}, the base colour of alpha-masked material '{material}'")
}

/// The encoded bytes of glTF image `image`.
fn encoded(
    doc: &Document,
    image: usize,
    buffers: &[Vec<u8>],
    (path, folder): (&Path, Option<&Path>),
    label: &str,
) -> Result<Vec<u8>, SceneError> {
    let json = &doc.as_json().images[image];
    if let Some(uri) = &json.uri {
        return read_uri(uri, folder, Limit::AtMost(MAX_IMAGE_BYTES)).map_err(|e| match e {
            UriError::Io(file, e) => {
                SceneError::image(path, label, format!("cannot read {}: {e}", file.display()))
            }
            UriError::Short(len) => {
                SceneError::image(path, label, format!("the file has only {len} bytes"))
            }
            UriError::Bad(msg) => SceneError::image(path, label, msg),
        });
    }
    let Some(index) = &json.buffer_view else {
        return Err(SceneError::image(
            path,
            label,
            "has neither a uri nor a buffer view",
        ));
    };
    // The view index was validated when the document was built.
    let Some(view) = doc.views().nth(index.value()) else {
        return Err(SceneError::index(
            path,
            format!("{label}: buffer view"),
            index.value(),
            doc.views().len(),
        ));
    };
    let buffer = &buffers[view.buffer().index()];
    let range = view.offset()..view.offset().saturating_add(view.length());
    let bytes = buffer
        .get(range.clone())
        .ok_or_else(|| SceneError::MissingBuffer {
            path: path.to_path_buf(),
            message: format!(
                "{label}: buffer view {} spans bytes {}..{} of buffer {} which has {}",
                view.index(),
                range.start,
                range.end,
                view.buffer().index(),
                buffer.len()
            ),
        })?;
    if bytes.len() as u64 > MAX_IMAGE_BYTES {
        return Err(SceneError::too_large(
            path,
            label,
            bytes.len() as u64,
            MAX_IMAGE_BYTES,
        ));
    }
    Ok(bytes.to_vec())
}

/// The alpha channel of an encoded image; `None` when it has none (or it is opaque throughout).
fn decode(bytes: &[u8], path: &Path, label: &str) -> Result<Option<AlphaImage>, SceneError> {
    if bytes.starts_with(JPEG_SIGNATURE) {
        return Ok(None);
    }
    if !bytes.starts_with(PNG_SIGNATURE) {
        return Err(SceneError::image(
            path,
            label,
            "unsupported image format (alpha masks must be PNG; JPEG has no alpha)",
        ));
    }
    let corrupt =
        |e: image::ImageError| SceneError::image(path, label, format!("corrupt PNG: {e}"));
    let reader = || ImageReader::with_format(Cursor::new(bytes), ImageFormat::Png);
    let (width, height) = reader().into_dimensions().map_err(corrupt)?;
    let side = width.max(height);
    if side > MAX_IMAGE_SIDE {
        return Err(SceneError::too_large(
            path,
            format!("{label}: side"),
            u64::from(side),
            u64::from(MAX_IMAGE_SIDE),
        ));
    }
    let mut limits = Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_DECODE_ALLOC);
    let mut reader = reader();
    reader.limits(limits);
    let image = reader.decode().map_err(corrupt)?;
    if !image.color().has_alpha() {
        return Ok(None);
    }
    let (width, height) = (image.width(), image.height());
    let alpha: Vec<u8> = match image {
        DynamicImage::ImageLumaA8(b) => b.pixels().map(|p| p[1]).collect(),
        DynamicImage::ImageRgba8(b) => b.pixels().map(|p| p[3]).collect(),
        other => other.to_rgba8().pixels().map(|p| p[3]).collect(),
    };
    if alpha.iter().all(|&a| a == u8::MAX) {
        return Ok(None);
    }
    AlphaImage::new(width, height, alpha)
        .map(Some)
        .ok_or_else(|| SceneError::image(path, label, "decoded to an empty image"))
}
