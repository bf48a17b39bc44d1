//! Scene-file motion keys: `walk` (a walker along a path) and `keys` (a keyframed rigid clip
//! of the asset's wrapper node).

use glam::{Quat, Vec3};
use serde::Deserialize;

use crate::anim::walk::WalkPath;
use crate::anim::Animator;
use crate::model::{AnimatedProperty, Animation, Channel, Interpolation, Node, Scene, Walker};

/// `walk = { points = [[x, y, z], ...], speed = 1.2, loop = true, roll = false }`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WalkEntry {
    points: Vec<[f32; 3]>,
    #[serde(default = "default_speed")]
    speed: f32,
    #[serde(default = "yes", rename = "loop")]
    closed: bool,
    #[serde(default)]
    roll: bool,
}

fn default_speed() -> f32 {
    1.0
}

fn yes() -> bool {
    true
}

/// `keys = { times = [...], translation = [[...], ...], rotation_deg = [[...], ...], interpolation = "linear" }`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct KeysEntry {
    times: Vec<f32>,
    translation: Option<Vec<[f32; 3]>>,
    rotation_deg: Option<Vec<[f32; 3]>>,
    #[serde(default)]
    interpolation: KeyInterpolation,
}

/// Interpolation of scene-file keys.
#[derive(Deserialize, Default, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum KeyInterpolation {
    #[default]
    Linear,
    Step,
}

/// The rotation for `rotation_deg` (about X, then Y, then Z, fixed axes).
pub(super) fn euler_deg(deg: [f32; 3]) -> Quat {
    let [rx, ry, rz] = deg.map(f32::to_radians);
    Quat::from_rotation_z(rz) * Quat::from_rotation_y(ry) * Quat::from_rotation_x(rx)
}

/// Gives every node-less instance of `asset` a root node carrying its transform, so that
/// the asset's wrapper node moves it.
pub(super) fn attach_loose_instances(asset: &mut Scene) {
    for i in 0..asset.instances.len() {
        if asset.instances[i].node.is_some() {
            continue;
        }
        let (scale, rotation, translation) =
            asset.instances[i].transform.to_scale_rotation_translation();
        asset.nodes.push(Node {
            name: format!("instance{i}"),
            parent: None,
            translation,
            rotation,
            scale,
        });
        asset.instances[i].node = Some(asset.nodes.len() - 1);
    }
}

/// The walker for an asset wrapped by a root with `rotation` and `scale` (its `node` still
/// to be set), and the wrapper's pose at time 0.
pub(super) fn walker(
    entry: &WalkEntry,
    asset: &Scene,
    rotation: Quat,
    scale: Vec3,
) -> Result<(Walker, Vec3, Quat), String> {
    let points: Vec<Vec3> = entry.points.iter().map(|&p| Vec3::from_array(p)).collect();
    if points.is_empty() || points.iter().any(|p| !p.is_finite()) {
        return Err("walk: points must be a non-empty list of finite [x, y, z]".into());
    }
    if !(entry.speed.is_finite() && entry.speed >= 0.0) {
        return Err(format!("walk: speed must be ≥ 0, got {}", entry.speed));
    }
    let (lo, hi) = rest_bounds(asset).map_err(|e| format!("walk: {e}"))?;
    let centre = 0.5 * (lo + hi);
    let lift = scale.y * (centre.y - lo.y);
    let roll_radius = match entry.roll {
        true if lift > 0.0 => Some(lift),
        true => return Err("walk: cannot roll an asset without height".into()),
        false => None,
    };
    let walker = Walker {
        node: 0,
        points,
        speed: entry.speed,
        closed: entry.closed,
        rotation,
        centre,
        lift,
        roll_radius,
    };
    let (t, r) = WalkPath::new(&walker).local_at(0.0, scale);
    Ok((walker, t, r))
}

/// Bounds of `asset` (in its own space) in its pose at time 0.
fn rest_bounds(asset: &Scene) -> Result<(Vec3, Vec3), String> {
    let pose = Animator::new(asset)
        .map_err(|e| e.to_string())?
        .pose_at(0.0);
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for (i, inst) in asset.instances.iter().enumerate() {
        let Some(posed) = pose.instance(i) else {
            continue;
        };
        let positions = posed
            .positions
            .unwrap_or(&asset.meshes[inst.mesh].positions);
        for p in positions {
            let w = posed.transform.transform_point3(*p);
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    if lo.cmple(hi).all() {
        Ok((lo, hi))
    } else {
        Err("the asset has no vertices".into())
    }
}

/// The keyframed clip of `node` (name `keys:<file>`) and its pose at the first key;
/// `rest` fills in a property the keys leave out.
pub(super) fn keys_clip(
    entry: &KeysEntry,
    file: &str,
    node: usize,
    rest: (Vec3, Quat),
) -> Result<(Animation, Vec3, Quat), String> {
    let n = entry.times.len();
    if n == 0 || entry.times.iter().any(|t| !t.is_finite()) {
        return Err("keys: times must be a non-empty list of finite seconds".into());
    }
    if entry.times.windows(2).any(|w| w[1] < w[0]) {
        return Err("keys: times must not decrease".into());
    }
    if entry.translation.is_none() && entry.rotation_deg.is_none() {
        return Err("keys: give translation and/or rotation_deg".into());
    }
    let interpolation = match entry.interpolation {
        KeyInterpolation::Linear => Interpolation::Linear,
        KeyInterpolation::Step => Interpolation::Step,
    };
    let mut channels = Vec::new();
    let (mut t0, mut r0) = rest;
    if let Some(tr) = &entry.translation {
        check_len("translation", tr.len(), n)?;
        if tr.iter().flatten().any(|v| !v.is_finite()) {
            return Err("keys: non-finite translation".into());
        }
        t0 = Vec3::from_array(tr[0]);
        channels.push(Channel {
            node,
            property: AnimatedProperty::Translation,
            interpolation,
            times: entry.times.clone(),
            values: tr.iter().flatten().copied().collect(),
        });
    }
    if let Some(rot) = &entry.rotation_deg {
        check_len("rotation_deg", rot.len(), n)?;
        if rot.iter().flatten().any(|v| !v.is_finite()) {
            return Err("keys: non-finite rotation".into());
        }
        // Keep consecutive keys in one hemisphere so slerp takes the short way.
        let mut previous = Quat::IDENTITY;
        let mut values = Vec::with_capacity(4 * n);
        for (k, &deg) in rot.iter().enumerate() {
            let mut q = euler_deg(deg);
            if k > 0 && q.dot(previous) < 0.0 {
                q = -q;
            }
            previous = q;
            values.extend(q.to_array());
        }
        r0 = euler_deg(rot[0]);
        channels.push(Channel {
            node,
            property: AnimatedProperty::Rotation,
            interpolation,
            times: entry.times.clone(),
            values,
        });
    }
    Ok((
        Animation {
            name: format!("keys:{file}"),
            channels,
        },
        t0,
        r0,
    ))
}

fn check_len(what: &str, got: usize, want: usize) -> Result<(), String> {
    if got == want {
        Ok(())
    } else {
        Err(format!("keys: {got} {what} values for {want} times"))
    }
}
