//! Per-pixel dumps of chosen frames (`psao corrective eval --dump-frames`), to find why a
//! corrected frame lost against its base: every non-diffuse pixel's base, corrected and
//! reference values, and every cached sample with the pixel it projects to, its level, age
//! and radiance.

use psao_corrective::session::Corrector;
use serde::Serialize;

use super::frame::FrameImages;
use super::run::Budget;

/// One non-diffuse pixel of a dumped frame (linear RGB).
#[derive(Serialize)]
pub struct DumpPixel {
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// Object id.
    pub id: u32,
    /// The base frame.
    pub base: [f32; 3],
    /// The corrected frame.
    pub corrected: [f32; 3],
    /// The reference.
    pub reference: [f32; 3],
}

/// One cached sample of a dumped frame.
#[derive(Serialize)]
pub struct DumpSample {
    /// The pixel its position projects to in this frame (`None`: off screen).
    pub pixel: Option<(i32, i32)>,
    /// Its depth along the viewing axis now, and the G-buffer's depth at that pixel.
    pub depth: Option<(f32, f32)>,
    /// The object id at that pixel.
    pub id_there: Option<u32>,
    /// Its object.
    pub object: u32,
    /// √5 level (1 = coarsest).
    pub level: u8,
    /// Camera changes since it was traced.
    pub age: u32,
    /// Its traced radiance.
    pub color: [f32; 3],
    /// Its normal against the normal at that pixel (1: facing as it does).
    pub normal_cos: Option<f32>,
    /// `n · v` when it was traced, and now (its normal against its direction to the eye).
    pub ndotv: (f32, f32),
}

/// One ordering's frame, dumped.
#[derive(Serialize)]
pub struct FrameDump {
    /// Path name.
    pub path: String,
    /// Path frame.
    pub frame: u32,
    /// Ordering.
    pub order: String,
    /// Budget per frame.
    pub budget: Budget,
    /// Image size.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Camera age of the frame.
    pub camera_age: u32,
    /// √5 levels of the hierarchy (level ℓ's lattice spacing is √5^(levels − ℓ) pixels).
    pub levels: u8,
    /// The non-diffuse pixels.
    pub pixels: Vec<DumpPixel>,
    /// The cached samples after the frame.
    pub samples: Vec<DumpSample>,
}

/// What one frame dump is taken of.
pub struct DumpOf<'a> {
    /// Path name.
    pub path: &'a str,
    /// Path frame.
    pub frame: u32,
    /// Ordering name.
    pub order: &'a str,
    /// Budget per frame.
    pub budget: Budget,
}

/// The dump of `corrected`, frame `f` of `what`, with `corrector`'s cache.
pub fn dump_frame(
    what: &DumpOf<'_>,
    f: &FrameImages,
    corrected: &[[f32; 3]],
    corrector: &Corrector,
) -> FrameDump {
    let g = &f.gbuffer;
    let w = g.width;
    let pixels = (f.ids.iter().enumerate())
        .filter(|(_, &id)| id != 0)
        .map(|(i, &id)| DumpPixel {
            x: i as u32 % w,
            y: i as u32 / w,
            id,
            base: f.base[i],
            corrected: corrected[i],
            reference: f.reference[i],
        })
        .collect();
    let cache = corrector.cache();
    let age = cache.camera_age();
    let samples = (1..=corrector.hierarchy().levels())
        .flat_map(|l| cache.level(l))
        .map(|s| {
            let at = f.view.project(s.position);
            let i = at.map(|(x, y, _)| y as usize * w as usize + x as usize);
            DumpSample {
                pixel: at.map(|(x, y, _)| (x, y)),
                depth: at.zip(i).map(|((_, _, z), i)| (z, g.depth[i])),
                id_there: i.map(|i| f.ids[i]),
                object: s.object,
                level: s.level,
                age: age.saturating_sub(s.age),
                color: s.color,
                normal_cos: i.map(|i| g.normal[i].dot(s.normal)),
                ndotv: (
                    s.ndotv,
                    s.normal.dot((f.view.eye - s.position).normalize_or_zero()),
                ),
            }
        })
        .collect();
    FrameDump {
        path: what.path.to_string(),
        frame: what.frame,
        order: what.order.to_string(),
        budget: what.budget,
        width: w,
        height: g.height,
        camera_age: f.camera_age,
        levels: corrector.hierarchy().levels(),
        pixels,
        samples,
    }
}
