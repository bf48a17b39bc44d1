//! File and image plumbing of the relighting commands: characters, HDR environment maps,
//! model files, the clip's frame clock, the camera and per-vertex shading to pixels.

use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::Vec3;
use psao_prt::character::{Character, CharacterPose};
use psao_prt::lighting::EnvMap;
use psao_prt::model::PoseModel;
use psao_prt::{model_file, PrtError};
use psao_raster::{GBuffer, InstancePose, RasterOptions, Rasterizer};
use psao_scene::{Camera, Scene};

/// Frames per second of the clip sampling (frame `i` is at `i / FPS` seconds).
pub const FPS: f32 = 30.0;

/// Largest model file read (bytes): far above any character's model, far below trouble.
const MAX_MODEL_BYTES: u64 = 2 << 30;

/// A character loaded from a glTF file, with the name models record (the file stem).
pub struct LoadedCharacter {
    /// The character with its clip selected.
    pub character: Character,
    /// Its name.
    pub name: String,
}

/// Loads the skinned character of `path` with clip `clip` (name or index).
pub fn load_character(path: &Path, clip: Option<&str>) -> Result<LoadedCharacter> {
    let scene = psao_scene::load_scene(path)
        .with_context(|| format!("cannot load character {}", path.display()))?;
    let character = Character::new(scene, clip)
        .with_context(|| format!("cannot relight {}", path.display()))?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "character".into());
    Ok(LoadedCharacter { character, name })
}

/// Reads a Radiance `.hdr` environment map (latitude–longitude).
pub fn load_env(path: &Path) -> Result<EnvMap> {
    let map = psao_scene::environment::read_hdr(path)
        .with_context(|| format!("unusable environment map {}", path.display()))?;
    Ok(EnvMap::from(map))
}

/// Writes `model` to `path`.
pub fn write_model(path: &Path, model: &PoseModel) -> Result<()> {
    std::fs::write(path, model_file::to_bytes(model))
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Reads the model at `path` and checks that it belongs to `character`.
pub fn read_model(path: &Path, character: &LoadedCharacter) -> Result<PoseModel> {
    let size = std::fs::metadata(path)
        .with_context(|| format!("cannot open model {}", path.display()))?
        .len();
    if size > MAX_MODEL_BYTES {
        bail!(
            "{} is {size} bytes, more than any relighting model",
            path.display()
        );
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let model = model_file::from_bytes(&bytes)
        .with_context(|| format!("{} is not a usable model", path.display()))?;
    let c = &character.character;
    if model.character != character.name
        || model.vertices != c.vertex_count()
        || model.joints != c.joint_count()
    {
        return Err(PrtError::WrongCharacter {
            model: model.character.clone(),
            model_vertices: model.vertices,
            model_joints: model.joints,
            character: character.name.clone(),
            vertices: c.vertex_count(),
            joints: c.joint_count(),
        })
        .with_context(|| format!("cannot use {}", path.display()));
    }
    Ok(model)
}

/// Number of frames of the selected clip at [`FPS`] (at least 1).
pub fn clip_frames(character: &Character) -> u32 {
    ((character.duration() * FPS).round() as u32).max(1)
}

/// A camera looking at the pose's bounds from the front-right and a little above.
pub fn framing_camera(pose: &CharacterPose, width: u32, height: u32) -> Camera {
    let (lo, hi) = pose.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| {
            let w = pose.transform.transform_point3(*p);
            (lo.min(w), hi.max(w))
        },
    );
    let centre = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-3);
    let fov = 35.0f32;
    let aspect = width as f32 / height.max(1) as f32;
    let half = (fov.to_radians() * 0.5).tan() * aspect.min(1.0);
    let distance = radius / half.max(1e-3) * 0.85;
    let dir = Vec3::new(0.55, 0.3, 1.0).normalize();
    let mut camera = Camera::look_at(centre + dir * distance, centre, fov);
    camera.near = distance * 0.01;
    camera.far = distance * 10.0;
    camera
}

/// Rasterizes the character's pose and writes, per pixel, the per-vertex `values`
/// (`channels` per vertex) interpolated with the pixel's barycentrics; background is 0.
pub struct VertexImage {
    scene: Scene,
    rasterizer: Rasterizer,
    gbuffer: GBuffer,
}

impl VertexImage {
    /// For the mesh of `character`.
    pub fn new(character: &Character) -> Self {
        Self {
            scene: Scene::of_meshes(vec![character.mesh().clone()]),
            rasterizer: Rasterizer::new(),
            gbuffer: GBuffer::empty(0, 0),
        }
    }

    /// Rasterizes `pose` seen by `camera` at `width × height`.
    pub fn rasterize(
        &mut self,
        pose: &CharacterPose,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<()> {
        let poses = [InstancePose {
            transform: pose.transform,
            positions: Some(&pose.positions),
            normals: Some(&pose.normals),
        }];
        self.rasterizer
            .rasterize_posed(
                &self.scene,
                &poses,
                camera,
                &RasterOptions::new(width, height),
                &mut self.gbuffer,
            )
            .context("cannot rasterize the character")?;
        Ok(())
    }

    /// Interpolated values (`channels` per pixel) of the last rasterized pose.
    pub fn shade(&self, values: &[f32], channels: usize) -> Vec<f32> {
        let g = &self.gbuffer;
        let indices = &self.scene.meshes[0].indices;
        let mut out = vec![0.0f32; g.len() * channels];
        for (i, px) in out.chunks_mut(channels).enumerate() {
            if !g.covered(i) {
                continue;
            }
            let Some(tri) = indices.get(g.triangle[i] as usize) else {
                continue;
            };
            let b = g.barycentric[i];
            let w = [1.0 - b.x - b.y, b.x, b.y];
            for (k, &v) in tri.iter().enumerate() {
                for (c, p) in px.iter_mut().enumerate() {
                    *p += w[k]
                        * values
                            .get(v as usize * channels + c)
                            .copied()
                            .unwrap_or(0.0);
                }
            }
        }
        out
    }
}

/// Linear radiance to a display value in [0, 1]: exposure, clamp, gamma 1/2.2.
pub fn display(value: f32, exposure: f32) -> f32 {
    (value * exposure).clamp(0.0, 1.0).powf(1.0 / 2.2)
}

/// The exposure that maps the 99th percentile of `values` to 0.9 (before gamma).
pub fn exposure_for(values: &[f32]) -> f32 {
    let mut v: Vec<f32> = values
        .iter()
        .copied()
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    if v.is_empty() {
        return 1.0;
    }
    v.sort_by(f32::total_cmp);
    0.9 / v[((v.len() - 1) as f32 * 0.99) as usize].max(1e-12)
}
