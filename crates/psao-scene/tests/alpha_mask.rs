//! Alpha masks: the loader decodes the base-colour alpha of `MASK` materials from every kind of
//! image source, `Scene::opaque_at` follows the texture, and broken images are typed errors.

#[path = "fixtures/masked_quad.rs"]
mod masked_quad;

use glam::{Vec2, Vec3};
use masked_quad::{checker_png, opaque_texel, write, ImageSource, SIZE};
use psao_scene::{AlphaMode, SceneError, Wrap};

#[test]
fn mask_texture_is_read_from_every_source() {
    let tmp = tempfile::tempdir().unwrap();
    let png = checker_png();
    let sources = [
        ImageSource::BufferView,
        ImageSource::DataUri,
        ImageSource::File("mask.png"),
    ];
    for (i, source) in sources.into_iter().enumerate() {
        let path = write(tmp.path(), &format!("quad{i}"), &png, source, "MASK");
        let scene = psao_scene::gltf::load(&path).unwrap_or_else(|e| panic!("{source:?}: {e}"));
        let material = &scene.materials[0];
        assert_eq!(material.alpha_mode, AlphaMode::Mask { cutoff: 0.5 });
        let tex = material
            .alpha_texture
            .as_ref()
            .expect("alpha texture loaded");
        assert_eq!((tex.image.width(), tex.image.height()), (SIZE, SIZE));
        assert_eq!((tex.wrap_s, tex.wrap_t), (Wrap::Repeat, Wrap::ClampToEdge));
        assert_eq!(tex.tex_coord, 0);
        for y in 0..SIZE {
            for x in 0..SIZE {
                let expected = if opaque_texel(x, y) { 255 } else { 0 };
                assert_eq!(tex.image.texel(x, y), expected, "{source:?} texel {x},{y}");
            }
        }
        assert_eq!(scene.meshes[0].uvs.len(), 4);
        // Triangle 0 is (v0, v2, v1) = UV (0,0), (1,1), (1,0): the centre of texel
        // (x, y) with y < x lies inside it.
        for (x, y) in [(1, 0), (3, 0), (5, 2), (7, 6), (6, 1)] {
            let uv = (Vec2::new(x as f32, y as f32) + 0.5) / SIZE as f32;
            // uv = b0·(0,0) + b1·(1,1) + b2·(1,0) → b1 = v, b2 = u − v.
            let bary = Vec3::new(1.0 - uv.x, uv.y, uv.x - uv.y);
            assert_eq!(
                scene.opaque_at(0, 0, bary),
                opaque_texel(x, y),
                "{source:?} texel {x},{y}"
            );
        }
    }
}

#[test]
fn without_mask_mode_the_texture_is_not_read() {
    let tmp = tempfile::tempdir().unwrap();
    // Not even a PNG: an opaque material never decodes its texture.
    let path = write(
        tmp.path(),
        "opaque",
        b"not an image",
        ImageSource::BufferView,
        "OPAQUE",
    );
    let scene = psao_scene::gltf::load(&path).unwrap();
    assert!(scene.materials[0].alpha_texture.is_none());
    assert!(scene.opaque_at(0, 0, Vec3::splat(1.0 / 3.0)));
}

#[test]
fn image_without_alpha_keeps_the_factor_only() {
    let tmp = tempfile::tempdir().unwrap();
    let rgb = image::RgbImage::from_pixel(4, 4, image::Rgb([10, 20, 30]));
    let mut png = std::io::Cursor::new(Vec::new());
    rgb.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let path = write(
        tmp.path(),
        "rgb",
        png.get_ref(),
        ImageSource::BufferView,
        "MASK",
    );
    let scene = psao_scene::gltf::load(&path).unwrap();
    assert!(scene.materials[0].alpha_texture.is_none());
    assert!(scene.opaque_at(0, 0, Vec3::splat(1.0 / 3.0)));
    // A JPEG (no alpha channel) is not decoded at all.
    let jpeg = [0xff, 0xd8, 0xff, 0xe0, 0, 0];
    let path = write(
        tmp.path(),
        "jpeg",
        &jpeg,
        ImageSource::File("mask.jpg"),
        "MASK",
    );
    assert!(psao_scene::gltf::load(&path).unwrap().materials[0]
        .alpha_texture
        .is_none());
}

/// Loads the glTF at `path`, expecting an image error whose message contains every `needle`.
fn image_error(path: &std::path::Path, needles: &[&str]) {
    match psao_scene::gltf::load(path) {
        Err(e @ SceneError::Image { .. }) => {
            let msg = e.to_string();
            for n in needles {
                assert!(msg.contains(n), "'{n}' not in: {msg}");
            }
            assert!(msg.contains("alpha-masked material 'checker'"), "{msg}");
        }
        other => panic!("expected an image error, got {other:?}"),
    }
}

#[test]
fn broken_images_are_typed_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let png = checker_png();
    // Truncated at several points (inside the header, inside the image data, before IEND).
    for cut in [4, 20, png.len() / 2, png.len() - 8] {
        for (i, source) in [ImageSource::BufferView, ImageSource::DataUri]
            .into_iter()
            .enumerate()
        {
            let path = write(
                tmp.path(),
                &format!("cut{cut}_{i}"),
                &png[..cut],
                source,
                "MASK",
            );
            let needle = if cut < 8 {
                "unsupported image format"
            } else {
                "corrupt PNG"
            };
            image_error(&path, &[needle]);
        }
    }
    // Corrupted bytes inside the compressed data (the PNG CRCs catch them).
    let mut flipped = png.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x55;
    let path = write(
        tmp.path(),
        "flipped",
        &flipped,
        ImageSource::BufferView,
        "MASK",
    );
    image_error(&path, &["corrupt PNG"]);
    // Not an image at all.
    let path = write(
        tmp.path(),
        "garbage",
        b"GIF89a....",
        ImageSource::BufferView,
        "MASK",
    );
    image_error(&path, &["unsupported image format"]);
    // The external file is missing.
    let path = write(
        tmp.path(),
        "missing",
        &png,
        ImageSource::File("gone.png"),
        "MASK",
    );
    std::fs::remove_file(tmp.path().join("gone.png")).unwrap();
    image_error(&path, &["cannot read", "gone.png", "image 0 ('gone.png')"]);
}

#[test]
fn oversized_images_are_rejected_before_decoding() {
    let tmp = tempfile::tempdir().unwrap();
    // A valid PNG header declaring a huge image (the decoder never allocates it).
    let side = psao_scene::gltf::MAX_IMAGE_SIDE + 1;
    let mut png = checker_png();
    png[16..20].copy_from_slice(&side.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    let path = write(tmp.path(), "huge", &png, ImageSource::BufferView, "MASK");
    match psao_scene::gltf::load(&path) {
        Err(SceneError::TooLarge { what, size, .. }) => {
            assert!(what.contains("image 0"), "{what}");
            assert_eq!(size, u64::from(side));
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
}

/// CRC-32 (ISO-HDLC), as PNG chunks use.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn base_colour_alpha_scales_the_texture_and_decides_alone_without_one() {
    let tmp = tempfile::tempdir().unwrap();
    let path = write(
        tmp.path(),
        "quad",
        &checker_png(),
        ImageSource::BufferView,
        "MASK",
    );
    let mut material = psao_scene::gltf::load(&path).unwrap().materials.remove(0);
    let (opaque_uv, clear_uv) = (Some(Vec2::splat(0.01)), Some(Vec2::new(0.3, 0.01)));
    assert!(material.opaque_at(opaque_uv) && !material.opaque_at(clear_uv));
    // No UVs: the texture cannot be addressed, the factor decides.
    assert!(material.opaque_at(None));
    material.base_color.w = 0.4;
    assert!(!material.opaque_at(opaque_uv) && !material.opaque_at(None));
    material.alpha_texture = None;
    assert!(!material.opaque_at(clear_uv));
    material.base_color.w = 0.6;
    assert!(material.opaque_at(clear_uv) && !material.has_texel_mask());
    material.alpha_mode = AlphaMode::Opaque;
    material.base_color.w = 0.0;
    assert!(material.opaque_at(None));
}

#[test]
fn the_mask_reads_the_uv_set_its_texture_names() {
    let tmp = tempfile::tempdir().unwrap();
    let path = write(
        tmp.path(),
        "set1",
        &checker_png(),
        ImageSource::BufferView,
        "MASK",
    );
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let attributes = &mut json["meshes"][0]["primitives"][0]["attributes"];
    attributes["TEXCOORD_1"] = attributes["TEXCOORD_0"].take();
    attributes.as_object_mut().unwrap().remove("TEXCOORD_0");
    json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] = 1.into();
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let scene = psao_scene::gltf::load(&path).unwrap();
    assert_eq!(
        scene.materials[0].alpha_texture.as_ref().unwrap().tex_coord,
        1
    );
    assert_eq!(scene.meshes[0].uvs.len(), 4);
    // Texel (1, 0) is opaque, (3, 0) cut out (see mask_texture_is_read_from_every_source).
    let bary = |x: f32, y: f32| {
        let uv = (Vec2::new(x, y) + 0.5) / SIZE as f32;
        Vec3::new(1.0 - uv.x, uv.y, uv.x - uv.y)
    };
    assert!(scene.opaque_at(0, 0, bary(1.0, 0.0)));
    assert!(!scene.opaque_at(0, 0, bary(3.0, 0.0)));
    // Without that set the texture cannot be addressed: the factor alone decides.
    let attributes = &mut json["meshes"][0]["primitives"][0]["attributes"];
    attributes.as_object_mut().unwrap().remove("TEXCOORD_1");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let scene = psao_scene::gltf::load(&path).unwrap();
    assert!(scene.meshes[0].uvs.is_empty());
    assert!(scene.opaque_at(0, 0, bary(3.0, 0.0)));
}
