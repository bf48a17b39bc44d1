//! Scene-file `[[light]]` entries and `[[material]]` overrides.

use glam::Vec3;
use serde::Deserialize;

use crate::light::{Light, LightShape, SunKeys};
use crate::model::{Material, Scene};

/// A `[[light]]` entry.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LightEntry {
    kind: String,
    direction: Option<[f32; 3]>,
    position: Option<[f32; 3]>,
    size: Option<[f32; 2]>,
    normal: Option<[f32; 3]>,
    #[serde(default = "white")]
    color: [f32; 3],
    power: f32,
    keys: Option<SunKeysEntry>,
}

/// A sun's `keys = { times = [...], direction = [[x, y, z], ...] }`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SunKeysEntry {
    times: Vec<f32>,
    direction: Vec<[f32; 3]>,
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

/// A `[[material]]` override.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MaterialEntry {
    name: String,
    preset: Option<String>,
    base_color: Option<[f32; 3]>,
    metallic: Option<f32>,
    roughness: Option<f32>,
    transmission: Option<f32>,
    ior: Option<f32>,
}

/// The light an entry describes, checked, and its keys when it is a sun with `keys` (their
/// `light` index is `index`; the light's own direction is theirs at time 0).
pub(super) fn light(e: &LightEntry, index: usize) -> Result<(Light, Option<SunKeys>), String> {
    let keys = match &e.keys {
        None => None,
        Some(_) if e.kind != "sun" => {
            return Err(format!("only a sun takes `keys`, not a {} light", e.kind))
        }
        Some(_) if e.direction.is_some() => {
            return Err("a sun with `keys` takes its direction from them: drop `direction`".into())
        }
        Some(k) => {
            let directions = k.direction.iter().map(|&d| Vec3::from_array(d)).collect();
            Some(SunKeys::new(index, k.times.clone(), directions)?)
        }
    };
    let light = one_light(e, keys.as_ref().map(|k| k.direction_at(0.0)))?;
    Ok((light, keys))
}

/// The light an entry describes, checked; `direction` stands in for a sun's missing one.
fn one_light(e: &LightEntry, direction: Option<Vec3>) -> Result<Light, String> {
    let need = |v: Option<[f32; 3]>, what: &str| {
        v.map(Vec3::from_array)
            .ok_or_else(|| format!("a {} light needs `{what}`", e.kind))
    };
    let shape = match e.kind.as_str() {
        "sun" => LightShape::Sun {
            direction: match direction {
                Some(d) => d,
                None => need(e.direction, "direction")?.normalize_or_zero(),
            },
        },
        "point" => LightShape::Point {
            position: need(e.position, "position")?,
        },
        "rect" => {
            let centre = need(e.position, "position")?;
            let normal = e.normal.map_or(Vec3::NEG_Y, Vec3::from_array);
            let [su, sv] = e.size.ok_or("a rect light needs `size` = [u, v]")?;
            if !(su.is_finite() && sv.is_finite() && su > 0.0 && sv > 0.0) {
                return Err(format!(
                    "rect light size must be positive, got [{su}, {sv}]"
                ));
            }
            let n = normal.normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                return Err("rect light normal must be non-zero".into());
            }
            let helper = if n.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
            let u = n.cross(helper).normalize();
            // u × v = n: the rectangle emits towards its normal.
            let v = n.cross(u);
            LightShape::Rect {
                centre,
                half_u: u * (0.5 * su),
                half_v: v * (0.5 * sv),
            }
        }
        other => return Err(format!("unknown light kind '{other}' (sun, point, rect)")),
    };
    let light = Light {
        shape,
        color: Vec3::from_array(e.color),
        power: e.power,
    };
    light.check()?;
    Ok(light)
}

/// A named set of shading values an override may start from.
fn preset(material: &mut Material, name: &str) -> Result<(), String> {
    let (metallic, roughness, transmission) = match name {
        "chrome" | "mirror" => (1.0, 0.0, 0.0),
        "glossy" => (0.0, 0.1, 0.0),
        "glass" => (0.0, 0.0, 1.0),
        other => {
            return Err(format!(
                "unknown material preset '{other}' (chrome, mirror, glossy, glass)"
            ))
        }
    };
    material.metallic = metallic;
    material.roughness = roughness;
    material.transmission = transmission;
    Ok(())
}

/// Applies the overrides to every material of the scene with the entry's name; an entry that
/// matches no material, or leaves a value out of range, is an error.
pub(super) fn apply_overrides(scene: &mut Scene, entries: &[MaterialEntry]) -> Result<(), String> {
    for (i, e) in entries.iter().enumerate() {
        let what = |m: String| format!("material {i} ('{}'): {m}", e.name);
        let mut hits = 0;
        for m in scene.materials.iter_mut().filter(|m| m.name == e.name) {
            if let Some(p) = &e.preset {
                preset(m, p).map_err(what)?;
            }
            if let Some(c) = e.base_color {
                m.base_color = Vec3::from_array(c).extend(m.base_color.w);
            }
            m.metallic = e.metallic.unwrap_or(m.metallic);
            m.roughness = e.roughness.unwrap_or(m.roughness);
            m.transmission = e.transmission.unwrap_or(m.transmission);
            m.ior = e.ior.unwrap_or(m.ior);
            m.check().map_err(what)?;
            hits += 1;
        }
        if hits == 0 {
            let mut known: Vec<&str> = scene.materials.iter().map(|m| m.name.as_str()).collect();
            known.sort_unstable();
            known.dedup();
            return Err(what(format!(
                "no material of this name (materials: {known:?})"
            )));
        }
    }
    Ok(())
}
