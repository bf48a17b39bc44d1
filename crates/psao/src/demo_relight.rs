//! The relighting section of `psao demo`: a small shadowed-relighting model of a shared
//! character, trained with few rays and frames so that the demo stays quick, and one picture
//! (Monte Carlo reference | 2-lobe linear model | unshadowed) of a frame it never saw.
//! Skipped, with a note, when the shared data is not there (a fresh clone).

use std::path::{Path, PathBuf};

use anyhow::Result;
use psao_prt::reference::{reference_shading, ReferenceSettings};
use psao_prt::shade::{Mode, Shader, ShadingGeometry, Visibility};
use psao_prt::visibility::SelfTracer;

use crate::png_io::write_rgb_png;
use crate::relight_cmd::{frame_range, gather_split, split, train_model};
use crate::relight_eval::{luminance, side_by_side, to_image};
use crate::relight_io::{exposure_for, framing_camera, load_character, load_env, VertexImage};

/// The character and environment, relative to the shared data folder.
const CHARACTER: &str = "characters/Fox.glb";
const ENVIRONMENT: &str = "envmaps/20050806-03_hd.hdr";
/// Train on every K-th frame of the first clip.
const EVERY: u32 = 4;
/// Visibility rays per vertex and frame.
const RAYS: u32 = 128;
/// Zonal lobes of the model.
const LOBES: usize = 2;
/// Reference samples per vertex.
const REF_SAMPLES: u32 = 512;
/// Side of each picture, pixels.
const SIZE: u32 = 320;
/// The picture's file name in the demo's folder.
const PICTURE: &str = "relight.png";

/// Where the shared data may be: `../shared/data` from the working directory (the workspace
/// root when run with `cargo run`), or from the source tree this binary was built from.
fn shared_data() -> Option<PathBuf> {
    [
        PathBuf::from("../shared/data"),
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")),
    ]
    .into_iter()
    .find(|d| d.join(CHARACTER).exists() && d.join(ENVIRONMENT).exists())
}

/// Runs the section and returns its markdown (a note when the data is missing).
pub fn section(out: &Path) -> Result<String> {
    section_with(out, shared_data())
}

/// The section with the shared data folder `data` (None: skipped).
fn section_with(out: &Path, data: Option<PathBuf>) -> Result<String> {
    let Some(data) = data else {
        return Ok(format!(
            "## Shadowed relighting\n\nSkipped: `../shared/data/{CHARACTER}` and \
             `../shared/data/{ENVIRONMENT}` are not both present (see docs/RELIGHTING.md \
             for `psao relight`).\n"
        ));
    };
    let character = data.join(CHARACTER);
    let loaded = load_character(&character, None)?;
    let env = load_env(&data.join(ENVIRONMENT))?;
    let c = &loaded.character;
    let split = split(frame_range(c, None)?, EVERY, None)?;
    let (train_set, validate) = gather_split(c, &split, RAYS, 1)?;
    let (model, _) = train_model(&loaded.name, &train_set, &validate, LOBES)?;

    // The first test time: half a frame after a training frame, never trained on.
    let t = split.test[0];
    let pose = c.pose(t);
    let camera = framing_camera(&pose, SIZE, SIZE);
    let mut tracer = SelfTracer::new(c.occluder_mesh())?;
    tracer.set_pose(&pose)?;
    let reference: Vec<f32> = reference_shading(
        &tracer,
        &pose,
        &env,
        &ReferenceSettings {
            mode: Mode::Diffuse,
            eye: camera.position,
            env_rotation: 0.0,
            samples: REF_SAMPLES,
            seed: 1,
        },
    )
    .into_iter()
    .flatten()
    .collect();
    let lighting = env.project();
    let shader = Shader::new(Mode::Diffuse)?;
    let geometry = ShadingGeometry {
        positions: &pose.positions,
        frames: &pose.frames,
        transform: pose.transform,
    };
    let mut raw = Vec::new();
    model.predict_raw(&model.pose_vector(&pose.joint_rotations), &mut raw);
    let shadowed = shader.shade(
        Visibility::Model(&model, &raw),
        geometry,
        &lighting.rgb,
        camera.position,
    )?;
    let unshadowed = shader.shade(
        Visibility::Unshadowed,
        geometry,
        &lighting.rgb,
        camera.position,
    )?;

    let mut image = VertexImage::new(c);
    image.rasterize(&pose, &camera, SIZE, SIZE)?;
    let pixels: Vec<Vec<f32>> = [&reference, &shadowed, &unshadowed]
        .iter()
        .map(|v| image.shade(v, 3))
        .collect();
    let exposure = exposure_for(&luminance(&pixels[0]));
    let ref_image = to_image(&pixels[0], SIZE, SIZE, exposure);
    let mut rows = String::new();
    for (name, p) in [("2-lobe model", &pixels[1]), ("unshadowed", &pixels[2])] {
        let m = psao_eval::compare(&ref_image, &to_image(p, SIZE, SIZE, exposure))?;
        rows += &format!(
            "| {name} | {:.2} | {:.4} | {:.4} |\n",
            m.psnr, m.ssim, m.flip
        );
    }
    let panels: Vec<&[f32]> = pixels.iter().map(Vec::as_slice).collect();
    let (width, rgb) = side_by_side(&panels, SIZE, SIZE, exposure);
    write_rgb_png(&out.join(PICTURE), width, SIZE, rgb)?;
    Ok(format!(
        "## Shadowed relighting\n\n\
         `{}` (clip `{}`, {} vertices) under `{ENVIRONMENT}`, diffuse: a {LOBES}-lobe linear \
         pose model trained on {} frames (every {EVERY}th, {RAYS} visibility rays per vertex), \
         shown at t = {t:.3} s, a pose it never saw. Left to right: Monte Carlo reference \
         ({REF_SAMPLES} samples per vertex), the model, unshadowed.\n\n\
         ![relighting]({PICTURE})\n\n\
         | method | PSNR dB | SSIM | FLIP |\n|---|---|---|---|\n{rows}\n\
         Full evaluation: `psao relight eval` (docs/RELIGHTING.md).\n",
        loaded.name,
        c.clip_name(),
        c.vertex_count(),
        train_set.len(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_the_shared_data_the_section_says_it_was_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let text = section_with(dir.path(), None).unwrap();
        assert!(text.contains("Skipped"), "{text}");
        assert!(!dir.path().join(PICTURE).exists());
    }
}
