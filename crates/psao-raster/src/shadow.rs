//! Shadow-mapped direct light of suns and point lights (DESIGN §12, docs/LIGHTING.md): the
//! part of the lighting the points leave to the client, because sharp shadows need more
//! resolution than the points have.
//!
//! Every map is a depth image rendered with this crate's rasterizer (so alpha cut-outs and
//! posed instances cast the shadows the viewer sees):
//!
//! - a **sun** gets [`ShadowSettings::cascades`] maps, each fitted to the bounding sphere of
//!   one slice of the viewer's frustum (slices split mostly logarithmically, clipped
//!   to the scene's bounds), so texels are small near the viewer and the whole visible scene
//!   is covered. A directional light is rendered as a perspective view from very far away
//!   ([`SUN_DISTANCE`] scene radii): its rays deviate from the sun's direction by less than
//!   1/[`SUN_DISTANCE`] rad, below the 1° the server tolerates before it relights;
//! - a **point light** gets six 90° faces (widened by the filter's reach so that a filtered
//!   lookup never leaves the face its direction selects).
//!
//! A lookup compares the depth of the shaded point with the depths of the
//! `(2·pcf + 1)²` texels around it (percentage-closer filtering: a penumbra of fractional
//! visibility along shadow edges). The looked-up point is moved off its surface along the
//! normal by the filter's reach times the sine of the light's angle, which puts every tap of
//! a plane behind it at any angle, so a flat lit surface never shadows itself (no acne).
//! Rectangle lights are left out: their soft shadows are in the points' irradiance.

use glam::{Mat4, Vec3, Vec4};
use psao_scene::{Camera, Light, LightShape, Scene};

use crate::pose::{validate_poses, InstancePose, PoseError};
use crate::{GBuffer, RasterOptions, Rasterizer};

/// Distance of a sun's map camera from the fitted sphere, in units of the scene's reach.
pub const SUN_DISTANCE: f32 = 256.0;
/// Weight of the logarithmic split of the view range between cascades (the rest uniform):
/// mostly logarithmic, so the nearest cascade stays small in large scenes.
const LOG_SPLIT: f32 = 0.9;
/// Depth bias of every lookup, in texels (world size of a texel at the point's depth).
const DEPTH_BIAS_TEXELS: f32 = 1.0;

/// Resolution and filtering of the shadow maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowSettings {
    /// Texels per side of each sun cascade.
    pub sun_resolution: u32,
    /// Cascades per sun (1 fits one map to the whole visible scene).
    pub cascades: u32,
    /// Texels per side of each of a point light's six faces.
    pub point_resolution: u32,
    /// Filter radius in texels: `(2·pcf + 1)²` taps per lookup (0: a hard shadow).
    pub pcf: u32,
}

impl Default for ShadowSettings {
    /// 1024² per sun cascade, 3 cascades, 256² per point-light face, 3×3 taps.
    fn default() -> Self {
        Self {
            sun_resolution: 1024,
            cascades: 3,
            point_resolution: 256,
            pcf: 1,
        }
    }
}

impl ShadowSettings {
    /// Maps matched to a `width`×`height` image: sun cascades of the image's larger side
    /// (256 to 2048 texels; the cascades already give the view's near part the finest
    /// texels), point faces of half of it (64 to 512), 3 cascades, 3×3 taps.
    pub fn for_image(width: u32, height: u32) -> Self {
        let side = width.max(height);
        Self {
            sun_resolution: side.clamp(256, 2048),
            point_resolution: (side / 2).clamp(64, 512),
            ..Self::default()
        }
    }
}

/// One depth image and the view it was rendered from.
#[derive(Clone, Debug)]
struct DepthMap {
    /// World to clip of the map's view.
    view_proj: Mat4,
    origin: Vec3,
    /// Unit axis of the view (depth is measured along it).
    forward: Vec3,
    /// World size of a texel at unit depth.
    texel_per_depth: f32,
    resolution: u32,
    /// View depth per texel, row-major from the top-left; `f32::INFINITY` where empty.
    depth: Vec<f32>,
}

impl DepthMap {
    /// Renders `camera`'s square view of the posed scene at `resolution`².
    fn render(
        raster: &mut Rasterizer,
        scratch: &mut GBuffer,
        (scene, poses): (&Scene, &[InstancePose<'_>]),
        camera: &Camera,
        resolution: u32,
    ) -> Self {
        let opts = RasterOptions::new(resolution, resolution);
        raster.render(scene, poses, camera, &opts, scratch);
        // The rasterizer clamps the size to MAX_DIMENSION.
        let resolution = scratch.width;
        Self {
            view_proj: camera.projection(1.0) * camera.view(),
            origin: camera.position,
            forward: (camera.target - camera.position).normalize(),
            texel_per_depth: 2.0 * (camera.fov_y * 0.5).tan() / resolution as f32,
            resolution,
            depth: std::mem::take(&mut scratch.depth),
        }
    }

    /// Continuous texel coordinates of `p` (origin at the top-left corner) and its view
    /// depth, or `None` behind the view.
    fn project(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let clip = self.view_proj * Vec4::new(p.x, p.y, p.z, 1.0);
        if clip.w.is_nan() || clip.w <= 0.0 {
            return None;
        }
        let res = self.resolution as f32;
        let u = (clip.x / clip.w * 0.5 + 0.5) * res;
        let v = (0.5 - clip.y / clip.w * 0.5) * res;
        Some((u, v, (p - self.origin).dot(self.forward)))
    }

    /// Whether the `(2·pcf + 1)²` taps around `p` all lie inside the map.
    fn covers(&self, p: Vec3, pcf: u32) -> bool {
        let reach = pcf as f32 + 1.0;
        let res = self.resolution as f32;
        self.project(p)
            .is_some_and(|(u, v, _)| u >= reach && v >= reach && u < res - reach && v < res - reach)
    }

    /// Fraction of the taps around `p` (unit normal `n`, unit direction to the light `l`)
    /// that see `p` lit; taps outside the map count as lit.
    ///
    /// The lookup point is moved off the surface along `n` by `ρ·sin θ` (θ the angle between
    /// `n` and `l`, ρ the filter's reach in world units, a texel more than its radius): on a
    /// plane, the depth of every tap within ρ then lies behind the moved point, at any angle
    /// (normal-offset shadows); a constant bias of [`DEPTH_BIAS_TEXELS`] absorbs rounding.
    fn visibility(&self, p: Vec3, n: Vec3, l: Vec3, pcf: u32) -> f32 {
        let Some((_, _, z)) = self.project(p) else {
            return 1.0;
        };
        let texel = z * self.texel_per_depth;
        let cos = n.dot(l).clamp(0.0, 1.0);
        let sin = (1.0 - cos * cos).sqrt();
        let moved = p + n * (texel * (pcf as f32 + 1.5) * sin);
        let Some((u, v, z)) = self.project(moved) else {
            return 1.0;
        };
        let bias = texel * DEPTH_BIAS_TEXELS;
        let (cx, cy) = (u.floor() as i64, v.floor() as i64);
        let r = pcf as i64;
        let res = i64::from(self.resolution);
        let mut lit = 0u32;
        for y in cy - r..=cy + r {
            for x in cx - r..=cx + r {
                let inside = (0..res).contains(&x) && (0..res).contains(&y);
                if !inside || z - bias <= self.depth[(y * res + x) as usize] {
                    lit += 1;
                }
            }
        }
        lit as f32 / ((2 * r + 1) * (2 * r + 1)) as f32
    }
}

/// The maps of one light.
#[derive(Clone, Debug)]
enum LightMaps {
    /// A sun: unit direction towards it, its irradiance (colour × power), cascades nearest
    /// first.
    Sun {
        direction: Vec3,
        irradiance: Vec3,
        cascades: Vec<DepthMap>,
    },
    /// A point light: position, radiant intensity (colour × power), faces +x −x +y −y +z −z.
    Point {
        position: Vec3,
        intensity: Vec3,
        faces: Vec<DepthMap>,
    },
}

/// The shadow maps of a scene's suns and point lights for one viewer's frame; rendered with
/// [`ShadowMaps::render`], queried per pixel with [`ShadowMaps::direct`]. Keep one per viewer
/// to reuse the rasterizer's memory.
#[derive(Default)]
pub struct ShadowMaps {
    settings: ShadowSettings,
    raster: Rasterizer,
    scratch: Option<GBuffer>,
    lights: Vec<LightMaps>,
}

impl ShadowMaps {
    /// No maps yet, rendering with `settings` (resolutions of at least 1 texel).
    pub fn new(settings: ShadowSettings) -> Self {
        Self {
            settings: ShadowSettings {
                sun_resolution: settings.sun_resolution.max(1),
                point_resolution: settings.point_resolution.max(1),
                cascades: settings.cascades.max(1),
                ..settings
            },
            ..Self::default()
        }
    }

    /// The settings in use.
    pub fn settings(&self) -> &ShadowSettings {
        &self.settings
    }

    /// Renders the maps of `lights` (the scene's lights at the frame's time; rectangles are
    /// skipped) for the scene in `poses`, the suns' cascades fitted to `camera`'s view at
    /// image aspect `aspect`. Errors when the poses do not fit the scene.
    pub fn render(
        &mut self,
        scene: &Scene,
        poses: &[InstancePose<'_>],
        lights: &[Light],
        camera: &Camera,
        aspect: f32,
    ) -> Result<(), PoseError> {
        validate_poses(scene, poses)?;
        self.lights.clear();
        let Some(bounds) = posed_bounds(scene, poses) else {
            return Ok(()); // nothing to cast or receive shadows
        };
        let mut scratch = self.scratch.take().unwrap_or_else(|| GBuffer::empty(0, 0));
        let geometry = (scene, poses);
        for light in lights {
            let strength = light.color * light.power;
            let maps = match light.shape {
                LightShape::Sun { direction } => {
                    let direction = direction.normalize_or_zero();
                    if direction == Vec3::ZERO {
                        continue;
                    }
                    let cascades = cascade_spheres(camera, aspect, bounds, self.settings.cascades)
                        .into_iter()
                        .map(|sphere| {
                            let view = sun_camera(direction, sphere, bounds);
                            let res = self.settings.sun_resolution;
                            DepthMap::render(&mut self.raster, &mut scratch, geometry, &view, res)
                        })
                        .collect();
                    LightMaps::Sun {
                        direction,
                        irradiance: strength,
                        cascades,
                    }
                }
                LightShape::Point { position } => {
                    let res = self.settings.point_resolution;
                    let faces = face_cameras(position, bounds, res, self.settings.pcf)
                        .iter()
                        .map(|view| {
                            DepthMap::render(&mut self.raster, &mut scratch, geometry, view, res)
                        })
                        .collect();
                    LightMaps::Point {
                        position,
                        intensity: strength,
                        faces,
                    }
                }
                LightShape::Rect { .. } => continue,
            };
            self.lights.push(maps);
        }
        self.scratch = Some(scratch);
        Ok(())
    }

    /// Direct irradiance (linear RGB) of the rendered suns and point lights at world position
    /// `p` on a surface with unit normal `n`: per light its irradiance × max(0, n·l) (a point
    /// light's intensity / d²) times the filtered visibility. Zero before [`Self::render`].
    pub fn direct(&self, p: Vec3, n: Vec3) -> Vec3 {
        let pcf = self.settings.pcf;
        let mut e = Vec3::ZERO;
        for light in &self.lights {
            match light {
                LightMaps::Sun {
                    direction,
                    irradiance,
                    cascades,
                } => {
                    let cos = n.dot(*direction);
                    if cos <= 0.0 {
                        continue;
                    }
                    let visible = cascades
                        .iter()
                        .find(|m| m.covers(p, pcf))
                        .map_or(1.0, |m| m.visibility(p, n, *direction, pcf));
                    e += *irradiance * (cos * visible);
                }
                LightMaps::Point {
                    position,
                    intensity,
                    faces,
                } => {
                    let d = *position - p;
                    let dist2 = d.length_squared();
                    if dist2.is_nan() || dist2 <= 0.0 {
                        continue;
                    }
                    let l = d / dist2.sqrt();
                    let cos = n.dot(l);
                    if cos <= 0.0 {
                        continue;
                    }
                    let visible = faces[face_of(-d)].visibility(p, n, l, pcf);
                    e += *intensity * (cos * visible / dist2);
                }
            }
        }
        e
    }
}

/// A bounding sphere (centre, radius).
type Sphere = (Vec3, f32);

/// World bounds (min, max) of the posed scene's vertices, `None` when it has none.
fn posed_bounds(scene: &Scene, poses: &[InstancePose<'_>]) -> Option<(Vec3, Vec3)> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for (inst, pose) in scene.instances.iter().zip(poses) {
        let Some(mesh) = scene.meshes.get(inst.mesh) else {
            continue;
        };
        for p in pose.positions.unwrap_or(&mesh.positions) {
            let w = pose.transform.transform_point3(*p);
            if w.is_finite() {
                lo = lo.min(w);
                hi = hi.max(w);
            }
        }
    }
    (lo.cmple(hi).all()).then_some((lo, hi))
}

/// The bounding sphere of a box, with a radius of at least a millimetre.
fn box_sphere((lo, hi): (Vec3, Vec3)) -> Sphere {
    ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-3))
}

/// Bounding spheres of `count` slices of `camera`'s frustum (aspect `aspect`), from its near
/// distance to the farthest point of `bounds` (or its far distance, if nearer), split at
/// [`LOG_SPLIT`] logarithmically and the rest uniformly; a slice's sphere is the scene's when
/// that is smaller.
fn cascade_spheres(camera: &Camera, aspect: f32, bounds: (Vec3, Vec3), count: u32) -> Vec<Sphere> {
    let scene = box_sphere(bounds);
    let forward = (camera.target - camera.position).normalize_or_zero();
    let right = forward.cross(camera.up).normalize_or_zero();
    let up = right.cross(forward);
    let near = camera.near.max(1e-3);
    let reach = (scene.0 - camera.position).length() + scene.1;
    let far = camera.far.min(reach).max(near * 1.001);
    let tan_y = (camera.fov_y * 0.5).tan();
    let tan_x = tan_y * aspect;
    if !(forward.is_finite() && right != Vec3::ZERO && tan_x.is_finite() && tan_y.is_finite()) {
        return vec![scene];
    }
    let split = |k: u32| {
        let f = k as f32 / count as f32;
        (1.0 - LOG_SPLIT) * (near + (far - near) * f) + LOG_SPLIT * near * (far / near).powf(f)
    };
    (0..count)
        .map(|k| {
            let (d0, d1) = (split(k), split(k + 1));
            let corners = [d0, d1].into_iter().flat_map(|d| {
                [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)].map(|(sx, sy)| {
                    camera.position + d * (forward + sx * tan_x * right + sy * tan_y * up)
                })
            });
            let corners: Vec<Vec3> = corners.collect();
            let centre = corners.iter().copied().sum::<Vec3>() / corners.len() as f32;
            let radius = corners
                .iter()
                .map(|c| (*c - centre).length())
                .fold(0.0, f32::max);
            if radius < scene.1 {
                (centre, radius)
            } else {
                scene
            }
        })
        .collect()
}

/// The camera of a sun's map covering `sphere`: far away along the sun's `direction`, just
/// wide enough for the sphere, its depth range holding every caster of the scene `bounds`.
fn sun_camera(direction: Vec3, (centre, radius): Sphere, bounds: (Vec3, Vec3)) -> Camera {
    let scene = box_sphere(bounds);
    // Every scene point lies within `reach` of the sphere's centre.
    let reach = ((scene.0 - centre).length() + scene.1).max(radius);
    let distance = SUN_DISTANCE * reach;
    let up = if direction.y.abs() < 0.9 {
        Vec3::Y
    } else {
        Vec3::X
    };
    Camera {
        position: centre + direction * distance,
        target: centre,
        up,
        fov_y: 2.0 * (radius / distance).asin(),
        near: distance - 1.01 * reach,
        far: distance + 1.01 * reach,
    }
}

/// The six face cameras of a point light at `position` (+x −x +y −y +z −z), reaching past
/// `bounds`; each face 90° widened by `pcf + 1` texels on every side at `res` texels.
fn face_cameras(position: Vec3, bounds: (Vec3, Vec3), res: u32, pcf: u32) -> [Camera; 6] {
    let scene = box_sphere(bounds);
    let far = ((scene.0 - position).length() + scene.1) * 1.01;
    let near = (far * 1e-5).max(1e-4);
    // tan of the half-angle: 1 plus the filter's reach, with the image widened to match.
    let widen = 1.0 + 2.0 * (pcf as f32 + 1.0) / res as f32;
    let fov_y = 2.0 * widen.atan();
    let face = |axis: Vec3, up: Vec3| Camera {
        position,
        target: position + axis,
        up,
        fov_y,
        near,
        far,
    };
    [
        face(Vec3::X, Vec3::Y),
        face(Vec3::NEG_X, Vec3::Y),
        face(Vec3::Y, Vec3::Z),
        face(Vec3::NEG_Y, Vec3::Z),
        face(Vec3::Z, Vec3::Y),
        face(Vec3::NEG_Z, Vec3::Y),
    ]
}

/// The face (in [`face_cameras`] order) whose axis is the dominant one of direction `d`.
fn face_of(d: Vec3) -> usize {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        usize::from(d.x < 0.0)
    } else if a.y >= a.z {
        2 + usize::from(d.y < 0.0)
    } else {
        4 + usize::from(d.z < 0.0)
    }
}
