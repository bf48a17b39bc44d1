//! Loading the volume a scene file places (`[[volume]]`) into a medium for AO rays.

use anyhow::{bail, Context, Result};
use psao_scene::scene_file::SceneVolume;
use psao_volume::{psv, vdb, BrickFormat, PlacedVolume, Placement, Volume};
use std::hash::{Hash, Hasher};
use std::sync::Arc;

/// Brick format of `.vdb` volumes placed in scenes when the entry gives none: `f16` is
/// lossless for the half-float grids production files store, builds instantly (BC7 encoding
/// takes seconds per frame) and keeps smoke-sized volumes at a few MB.
pub const DEFAULT_FORMAT: BrickFormat = BrickFormat::F16;

/// A placed volume ready for AO rays, with a hash of everything that changes its effect.
pub struct SceneMedium {
    /// The medium.
    pub volume: Arc<PlacedVolume>,
    /// Hash of the files' bytes, placement, density scale, format and frame.
    pub key: u64,
}

/// Reads and places the volume of a scene-file entry. Errors name the scene file, the
/// volume file and the field.
pub fn load(v: &SceneVolume) -> Result<SceneMedium> {
    let scene = v.scene_file.display();
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let mut bytes = Vec::with_capacity(v.files.len());
    for f in &v.files {
        let b = std::fs::read(f)
            .with_context(|| format!("scene {scene}: volume file {}", f.display()))?;
        b.hash(&mut h);
        bytes.push(b);
    }
    let volume = if psv::is_psv(&bytes[0]) {
        if v.files.len() > 1 {
            bail!("scene {scene}: volume file: a .psv file holds all its frames; give it alone");
        }
        if v.format.is_some() {
            bail!(
                "scene {scene}: volume format: {} is a .psv file, which keeps its own brick format",
                v.files[0].display()
            );
        }
        psv::from_bytes(&bytes[0])
            .with_context(|| format!("scene {scene}: volume file {}", v.files[0].display()))?
    } else {
        let format = match &v.format {
            None => DEFAULT_FORMAT,
            Some(name) => BrickFormat::parse(name).with_context(|| {
                format!("scene {scene}: volume format: unknown brick format '{name}' (f32, f16, unorm8, bc4, bc7)")
            })?,
        };
        let frames = v
            .files
            .iter()
            .zip(&bytes)
            .map(|(f, b)| {
                vdb::read_vdb_bytes(b, &f.display().to_string(), None)
                    .with_context(|| format!("scene {scene}: volume file {}", f.display()))
            })
            .collect::<Result<Vec<_>>>()?;
        Volume::build(&frames, format, None)
            .with_context(|| format!("scene {scene}: cannot build the volume"))?
            .0
    };
    let placement = Placement {
        translation: v.translation,
        rotation: v.rotation,
        scale: v.scale,
    };
    format!(
        "{:?}{:?}{:?}{}{:?}{}",
        placement.translation,
        placement.rotation,
        placement.scale,
        v.density_scale,
        volume.pool.format,
        v.frame
    )
    .hash(&mut h);
    let placed = PlacedVolume::new(volume, v.frame, placement, v.density_scale)
        .with_context(|| format!("scene {scene}: cannot place the volume"))?;
    let (lo, hi) = placed.world_bounds();
    tracing::info!(
        "volume {} placed over {lo:.2} .. {hi:.2}, extinction {} /m at the densest voxel, frame {}",
        v.files[0].display(),
        v.density_scale,
        v.frame
    );
    Ok(SceneMedium {
        volume: Arc::new(placed),
        key: h.finish(),
    })
}
