//! Per-frame relighting as a client runs it (paper §4.3): from a frame's joint transforms
//! and skinned vertices to one shade per vertex and colour channel.
//!
//! A client that animates and skins the character itself keeps a [`Relighter`]: the
//! trained [`PoseModel`] compacted for synthesis ([`CompactModel`]), a [`Shader`] and the
//! character's [`Rig`] (what turns joint transforms into the model's pose vector, and
//! skinned vertices into the frames visibility is stored in). Per frame it passes the
//! joints' local transforms, the skinned positions and normals, the SH lighting and the
//! eye; [`Relighter::shade_into`] synthesises each vertex's lobes and shades it straight
//! away, on the calling rayon pool (all cores, or one inside a one-thread pool; on a target
//! without threads, the calling thread). [`Relighter::shade_with`] gives each vertex's
//! shades with and without the model's shadowing to a function of the caller's (what a
//! client of a relighting server makes its per-vertex self-shadowing of, [`crate::served`]).
//! The code is pure and portable (no I/O, no platform code besides an AVX2 build of the
//! same loops chosen at run time on x86-64).
//!
//! Shading in world space: a vertex's visibility `v` (its lobes expanded to SH with their
//! axes in world space, eq. 1) is dotted with a vector `g` that depends only on the BRDF
//! axis and the lighting ([`Shader::axis_transfer`]); `g` is tabulated over the sphere once
//! per lighting ([`SphereTable`], [`TABLE_RES`] cells per side of the octahedral map) and
//! interpolated per vertex, which replaces rotating the lighting into every vertex's frame.
//! A constant light (SH coefficients zero beyond band 0, e.g. the white sky whose shade is
//! the self-visibility) needs no table: each lobe shades it in closed form
//! ([`Shader::constant_transfer`]), a cubic in the cosine between the lobe and the BRDF axis.
//! The mode's fade ([`crate::fade::FadeRule::of_mode`]) blends the synthesised visibility
//! towards unoccluded by one factor per frame, folded into the lobes' coefficients. The
//! result equals [`Shader::shade`] of the model's faded prediction
//! ([`crate::fade::predict`]) up to the compaction's bound and the table's interpolation
//! (measured in docs/RELIGHTING.md).
//!
//! Vertices go in blocks of [`LANES`], each in passes over a structure of arrays (one array
//! per quantity, one lane per vertex): the compacted model's synthesis of every lobe number
//! ([`CompactModel::synthesise_block`]); gathering of the skinned normals and tangent
//! neighbours; lane by lane and free of branches (loops the compiler vectorises): the frames,
//! the world lobe axes, their SH visibility and closed-form constant-light shades, the BRDF
//! axis and the table's corners; then per vertex the table's interpolation (four channels
//! side by side) and the dot products.

use glam::{Affine3A, Mat3, Quat, Vec3};
use rayon::prelude::*;

use crate::character::rotation_vector;
use crate::compact::{CompactModel, Lanes, DEFAULT_TOLERANCE, LANES};
use crate::fade::FadeRule;
use crate::filter::Filter;
use crate::model::{PoseModel, LOBE_DIM};
use crate::sh::{self, ShVec, BANDS, COEFFS};
use crate::shade::{orthonormalised, Mode, Shader};
use crate::transfer_table::SphereTable;
use crate::zonal::ZH_SCALE;
use crate::PrtError;

/// Cells per side of the octahedral map of the lighting's transfer table.
pub const TABLE_RES: usize = 64;

/// Blocks of [`LANES`] vertices per task of a frame.
const BLOCKS_PER_TASK: usize = 4;

/// Channels of the table side by side (one 4-wide vector per SH coefficient).
const GROUP: usize = 4;

/// `2√π`: the band-0 coefficient of the constant 1 (visibility 1).
const UNIT0: f32 = 3.544_907_7;

/// What relighting needs of a character besides its model.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// Per skin joint (the model's joint order): its rest (bind) local rotation.
    pub rest: Vec<Quat>,
    /// Per relit vertex: the vertex whose direction fixes the tangent of its frame (see
    /// [`crate::character::tangent_neighbours`]).
    pub neighbours: Vec<u32>,
}

impl Rig {
    /// Per joint, its local rotation relative to the rest pose as a rotation vector, from
    /// its local transform (relative to its parent node). Errors when the count differs
    /// from the rig's.
    pub fn joint_rotations(&self, local: &[Affine3A]) -> Result<Vec<Vec3>, PrtError> {
        if local.len() != self.rest.len() {
            return Err(PrtError::Parameter(format!(
                "{} joint transforms for a rig of {} joints",
                local.len(),
                self.rest.len()
            )));
        }
        Ok(local
            .iter()
            .zip(&self.rest)
            .map(|(t, rest)| {
                let (_, rotation, _) = t.to_scale_rotation_translation();
                rotation_vector(rest.inverse() * rotation)
            })
            .collect())
    }
}

/// One frame of a character as the client has it.
#[derive(Clone, Copy, Debug)]
pub struct FramePose<'a> {
    /// Per skin joint: its local transform (relative to its parent node).
    pub joint_local: &'a [Affine3A],
    /// Skinned positions of the relit vertices.
    pub positions: &'a [Vec3],
    /// Skinned normals of the relit vertices.
    pub normals: &'a [Vec3],
    /// Positions and normals to world.
    pub transform: Affine3A,
}

/// Where one light's shade comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// A constant radiance `k` (times the constant 1): closed form.
    Constant(f32),
    /// The table (channels in the order of the lights).
    Table,
}

/// The lighting a [`Relighter`] last prepared.
struct Lighting {
    /// The lights as given.
    lights: Vec<ShVec>,
    /// Per light, where its shade comes from.
    sources: Vec<Source>,
    /// Per group of [`GROUP`] table channels, per grid point: `rows` vectors of [`GROUP`]
    /// numbers (`g` per SH coefficient, then translucency's back lobe); `None` without
    /// table channels.
    table: Option<SphereTable>,
    /// Groups of table channels.
    groups: usize,
}

impl Lighting {
    fn new(shader: &Shader, lights: &[ShVec]) -> Self {
        // A clamped visibility is not a sum of lobes: every light goes through the table.
        let closed_form = !shader.filter().clamp;
        let sources: Vec<Source> = lights
            .iter()
            .map(|l| {
                if closed_form && l[1..].iter().all(|&x| x == 0.0) {
                    Source::Constant(l[0] / UNIT0)
                } else {
                    Source::Table
                }
            })
            .collect();
        let channels = sources.iter().filter(|s| **s == Source::Table).count();
        let groups = channels.div_ceil(GROUP);
        let rows = table_rows(shader);
        let table = (channels > 0).then(|| {
            let tabled: Vec<&ShVec> = lights
                .iter()
                .zip(&sources)
                .filter(|(_, s)| matches!(s, Source::Table))
                .map(|(l, _)| l)
                .collect();
            SphereTable::new(TABLE_RES, groups * rows * GROUP, |axis, out| {
                out.fill(0.0);
                for (c, light) in tabled.iter().enumerate() {
                    let (g, back) = shader.axis_transfer(axis, light);
                    let group = &mut out[(c / GROUP) * rows * GROUP..][..rows * GROUP];
                    for (r, x) in g.iter().chain(&[back]).take(rows).enumerate() {
                        group[r * GROUP + c % GROUP] = *x;
                    }
                }
            })
        });
        Self {
            lights: lights.to_vec(),
            sources,
            table,
            groups,
        }
    }
}

/// Rows of a table group: the 16 SH coefficients, and translucency's back lobe.
fn table_rows(shader: &Shader) -> usize {
    match shader.mode() {
        Mode::Translucent { .. } => COEFFS + 1,
        _ => COEFFS,
    }
}

/// A character's model, shader and rig, ready to relight it frame after frame.
pub struct Relighter {
    compact: CompactModel,
    shader: Shader,
    rig: Rig,
    /// The lighting last shaded with, prepared (its table made once per lighting).
    lighting: Option<Lighting>,
}

impl Relighter {
    /// The model compacted with the default tolerance ([`DEFAULT_TOLERANCE`]). Errors when
    /// the rig is not the model's character's (joint or vertex counts).
    pub fn new(model: PoseModel, shader: Shader, rig: Rig) -> Result<Self, PrtError> {
        Self::with_tolerance(model, shader, rig, DEFAULT_TOLERANCE)
    }

    /// The model compacted with `tolerance` (see [`CompactModel::new`]).
    pub fn with_tolerance(
        model: PoseModel,
        shader: Shader,
        rig: Rig,
        tolerance: f32,
    ) -> Result<Self, PrtError> {
        if rig.rest.len() != model.joints || rig.neighbours.len() != model.vertices {
            return Err(PrtError::Parameter(format!(
                "a rig of {} joints and {} vertices for a model of {} joints and {} vertices",
                rig.rest.len(),
                rig.neighbours.len(),
                model.joints,
                model.vertices
            )));
        }
        if let Some(&n) = rig
            .neighbours
            .iter()
            .find(|&&n| n as usize >= model.vertices)
        {
            return Err(PrtError::Parameter(format!(
                "tangent neighbour {n} of {} vertices",
                model.vertices
            )));
        }
        Ok(Self {
            compact: CompactModel::new(&model, tolerance)?,
            shader,
            rig,
            lighting: None,
        })
    }

    /// The compacted model.
    pub fn compact(&self) -> &CompactModel {
        &self.compact
    }

    /// The shader.
    pub fn shader(&self) -> &Shader {
        &self.shader
    }

    /// Shades every vertex of `pose` under `lights` (SH radiance in world space, one vector
    /// per channel) seen from `eye` (world): `lights.len()` values per vertex, interleaved.
    /// Errors when the pose's joint or vertex counts are not the model's.
    pub fn shade(
        &mut self,
        pose: &FramePose<'_>,
        lights: &[ShVec],
        eye: Vec3,
    ) -> Result<Vec<f32>, PrtError> {
        let mut out = Vec::new();
        self.shade_into(pose, lights, eye, &mut out)?;
        Ok(out)
    }

    /// [`Self::shade`] into `out` (resized; a client reuses it from frame to frame).
    pub fn shade_into(
        &mut self,
        pose: &FramePose<'_>,
        lights: &[ShVec],
        eye: Vec3,
        out: &mut Vec<f32>,
    ) -> Result<(), PrtError> {
        let ch = lights.len();
        out.resize(self.compact.vertices() * ch, 0.0);
        self.shade_with(pose, lights, eye, ch, out, |shadowed, _, slot| {
            slot.copy_from_slice(shadowed)
        })
    }

    /// Shades every vertex of `pose` under `lights` seen from `eye` (as [`Self::shade`]) and
    /// hands each vertex's shades to `f`: `f(shadowed, unshadowed, slot)` with one value
    /// per light in each (the shade with the model's visibility, and with visibility 1)
    /// and the vertex's `per_vertex` entries of `out`. Allocates nothing once the lighting
    /// has been seen (the table is made once per lighting) besides a scratch per task.
    /// Errors when the pose's joint or vertex counts are not the model's or `out` is not
    /// `per_vertex` entries per vertex.
    pub fn shade_with<T: Send>(
        &mut self,
        pose: &FramePose<'_>,
        lights: &[ShVec],
        eye: Vec3,
        per_vertex: usize,
        out: &mut [T],
        f: impl Fn(&[f32], &[f32], &mut [T]) + Sync,
    ) -> Result<(), PrtError> {
        let n = self.compact.vertices();
        if pose.positions.len() != n || pose.normals.len() != n {
            return Err(PrtError::Parameter(format!(
                "{} positions and {} normals for a model of {n} vertices",
                pose.positions.len(),
                pose.normals.len()
            )));
        }
        if out.len() != n * per_vertex || per_vertex == 0 {
            return Err(PrtError::Parameter(format!(
                "{} outputs of {per_vertex} per vertex for {n} vertices",
                out.len()
            )));
        }
        let rotations = self.rig.joint_rotations(pose.joint_local)?;
        let factors = self.compact.row_factors(&rotations);
        let fade = FadeRule::of_mode(self.shader.mode()).weight(self.compact.shape(), &rotations);
        if !matches!(&self.lighting, Some(l) if l.lights == lights) {
            self.lighting = Some(Lighting::new(&self.shader, lights));
        }
        let Some(lighting) = &self.lighting else {
            unreachable!("the lighting was just prepared")
        };
        let frame = Frame {
            compact: &self.compact,
            shader: &self.shader,
            lighting,
            rows: table_rows(&self.shader),
            constant: self.shader.constant_transfer(),
            window: self.shader.filter().window.factors(),
            fade,
            factors: &factors,
            neighbours: &self.rig.neighbours,
            pose,
            linear: orthonormalised(Mat3::from(pose.transform.matrix3)),
            eye,
        };
        let task = BLOCKS_PER_TASK * LANES;
        out.par_chunks_mut(per_vertex * task)
            .enumerate()
            .for_each_init(
                || Scratch::new(&frame),
                |scratch, (t, chunk)| {
                    for (b, slots) in chunk.chunks_mut(per_vertex * LANES).enumerate() {
                        frame.shade_block(t * BLOCKS_PER_TASK + b, per_vertex, scratch, slots, &f);
                    }
                },
            );
        Ok(())
    }
}

/// What every vertex of one frame shares.
struct Frame<'a> {
    compact: &'a CompactModel,
    shader: &'a Shader,
    lighting: &'a Lighting,
    /// Rows of a table group.
    rows: usize,
    /// The closed form of constant lights ([`Shader::constant_transfer`]).
    constant: ([f32; BANDS], f32),
    /// The visibility filter's window per band.
    window: [f32; BANDS],
    /// The share of the predicted shadowing kept at this pose ([`crate::fade`]).
    fade: f32,
    factors: &'a [f32],
    neighbours: &'a [u32],
    pose: &'a FramePose<'a>,
    /// The rotation of the pose's transform.
    linear: Mat3,
    eye: Vec3,
}

// The lane loops index several arrays per lane, which is what the compiler vectorises.
#[allow(clippy::needless_range_loop)]
impl Frame<'_> {
    /// Shades block `block` into `slots` (`per` entries per vertex, as many vertices as the
    /// slots hold), with the processor's wider vector instructions where it has them.
    fn shade_block<T>(
        &self,
        block: usize,
        per: usize,
        scratch: &mut Scratch,
        slots: &mut [T],
        f: &impl Fn(&[f32], &[f32], &mut [T]),
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the processor has AVX2 and FMA (checked just above).
            unsafe { self.shade_block_avx2(block, per, scratch, slots, f) };
            return;
        }
        self.shade_block_plain(block, per, scratch, slots, f);
    }

    /// [`Self::shade_block`] compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The processor must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn shade_block_avx2<T>(
        &self,
        block: usize,
        per: usize,
        scratch: &mut Scratch,
        slots: &mut [T],
        f: &impl Fn(&[f32], &[f32], &mut [T]),
    ) {
        self.shade_block_plain(block, per, scratch, slots, f);
    }

    /// [`Self::shade_block`] in portable code: the passes of the module's documentation.
    #[inline(always)]
    fn shade_block_plain<T>(
        &self,
        block: usize,
        per: usize,
        s: &mut Scratch,
        slots: &mut [T],
        f: &impl Fn(&[f32], &[f32], &mut [T]),
    ) {
        let start = block * LANES;
        let count = slots.len() / per;
        self.compact
            .synthesise_block(self.factors, block, &mut s.lobes);
        self.gather(start, count, s);
        self.frames(s);
        self.lobes(s);
        if let Some(table) = &self.lighting.table {
            for i in 0..LANES {
                let axis = Vec3::new(s.axis[0][i], s.axis[1][i], s.axis[2][i]);
                let (offsets, weights) = table.corners(axis);
                for k in 0..3 {
                    s.offsets[k][i] = offsets[k];
                    s.weights[k][i] = weights[k];
                }
            }
            self.table_shades(table, count, s);
        }
        self.constant_shades(s);
        for (i, slot) in slots.chunks_mut(per).enumerate() {
            for (light, (shadowed, unshadowed)) in s.shadowed.iter().zip(&s.unshadowed).enumerate()
            {
                s.vertex_shadowed[light] = shadowed[i];
                s.vertex_unshadowed[light] = unshadowed[i];
            }
            f(&s.vertex_shadowed, &s.vertex_unshadowed, slot);
        }
    }

    /// Each vertex's skinned normal, the offset to its tangent neighbour and (Phong) its
    /// position, into the lanes (lanes past `count` hold +z normals and zero offsets).
    #[inline(always)]
    fn gather(&self, start: usize, count: usize, s: &mut Scratch) {
        let pose = self.pose;
        for i in 0..LANES {
            let (n, e, p) = if i < count {
                let v = start + i;
                let p = pose.positions[v];
                (
                    pose.normals[v],
                    pose.positions[self.neighbours[v] as usize] - p,
                    p,
                )
            } else {
                (Vec3::Z, Vec3::ZERO, Vec3::ZERO)
            };
            for k in 0..3 {
                s.normal[k][i] = n[k];
                s.edge[k][i] = e[k];
                s.position[k][i] = p[k];
            }
        }
    }

    /// Lane by lane: the frame that follows the skin (as `character::skin_frames`) turned to
    /// world, the BRDF axis and (Phong) the share of its lobe above the horizon.
    #[inline(always)]
    fn frames(&self, s: &mut Scratch) {
        let m = self.linear;
        let phong = matches!(self.shader.mode(), Mode::Phong { .. });
        for i in 0..LANES {
            let n = normalize_or(
                Vec3::new(s.normal[0][i], s.normal[1][i], s.normal[2][i]),
                Vec3::Z,
            );
            let e = Vec3::new(s.edge[0][i], s.edge[1][i], s.edge[2][i]);
            let t = e - n * e.dot(n);
            let len2 = t.length_squared();
            let t = if len2 > 0.0 && len2.is_finite() {
                t / len2.sqrt()
            } else {
                n.any_orthonormal_pair().0
            };
            let (t, b, n) = (m * t, m * n.cross(t), m * n);
            for k in 0..3 {
                s.tangent[k][i] = t[k];
                s.bitangent[k][i] = b[k];
                s.world_normal[k][i] = n[k];
            }
        }
        if phong {
            let to_world = self.pose.transform;
            for i in 0..LANES {
                let n = Vec3::new(
                    s.world_normal[0][i],
                    s.world_normal[1][i],
                    s.world_normal[2][i],
                );
                let p = to_world.transform_point3(Vec3::new(
                    s.position[0][i],
                    s.position[1][i],
                    s.position[2][i],
                ));
                let wo = normalize_or(self.eye - p, n);
                let cos = n.dot(wo);
                let r = normalize_or(2.0 * cos * n - wo, n);
                for k in 0..3 {
                    s.axis[k][i] = r[k];
                }
                s.above[i] = self.shader.above_horizon(cos);
            }
        } else {
            s.axis = s.world_normal;
            s.above = [1.0; LANES];
        }
    }

    /// Lane by lane: each lobe's axis turned to world, its SH visibility summed into `vis`
    /// (eq. 1; when a light uses the table or visibility is clamped) and its closed-form
    /// shade under the constant 1 summed into `unit` (when a light is constant).
    #[inline(always)]
    fn lobes(&self, s: &mut Scratch) {
        let need_vis = self.lighting.table.is_some() || self.shader.filter().clamp;
        let need_unit = self
            .lighting
            .sources
            .iter()
            .any(|x| matches!(x, Source::Constant(_)));
        let u = self.constant.0;
        let w = self.window.map(|x| x * self.fade);
        // What the fade blends in: unoccluded visibility (band 0 alone, as the window
        // keeps it).
        let open = (1.0 - self.fade) * UNIT0;
        // The first lobe's visibility is added to the open share's (written, not added, so
        // that the lanes need no clearing).
        let start: [f32; COEFFS] = std::array::from_fn(|k| if k == 0 { open } else { 0.0 });
        if s.lobes.is_empty() {
            s.vis = start.map(|x| [x; LANES]);
        }
        s.unit = [open * u[0]; LANES];
        for (j, lobe) in s.lobes.chunks_exact(LOBE_DIM).enumerate() {
            for i in 0..LANES {
                let local = normalize_or(Vec3::new(lobe[0][i], lobe[1][i], lobe[2][i]), Vec3::Z);
                let t = Vec3::new(s.tangent[0][i], s.tangent[1][i], s.tangent[2][i]);
                let b = Vec3::new(s.bitangent[0][i], s.bitangent[1][i], s.bitangent[2][i]);
                let n = Vec3::new(
                    s.world_normal[0][i],
                    s.world_normal[1][i],
                    s.world_normal[2][i],
                );
                let axis = t * local.x + b * local.y + n * local.z;
                let c: [f32; BANDS] = std::array::from_fn(|l| lobe[3 + l][i] * w[l]);
                if need_vis {
                    let y = sh::eval(axis);
                    for (k, y) in y.iter().enumerate() {
                        let l = sh::band_of(k);
                        let before = if j == 0 { start[k] } else { s.vis[k][i] };
                        s.vis[k][i] = before + ZH_SCALE[l] * c[l] * y;
                    }
                }
                if need_unit {
                    let x = axis.dot(Vec3::new(s.axis[0][i], s.axis[1][i], s.axis[2][i]));
                    let p = legendre(x);
                    s.unit[i] += c[0] * u[0] * p[0]
                        + c[1] * u[1] * p[1]
                        + c[2] * u[2] * p[2]
                        + c[3] * u[3] * p[3];
                }
            }
        }
    }

    /// The first `count` lanes' shades under the table's lights, with and without
    /// shadowing, into the lights' lanes: per vertex and group of [`GROUP`] channels, the
    /// table interpolated (its three corners, the group's channels side by side) and dotted
    /// with the visibility.
    #[inline(always)]
    fn table_shades(&self, table: &SphereTable, count: usize, s: &mut Scratch) {
        let rows = self.rows;
        let filtered = self.shader.filter() != Filter::default();
        for group in 0..self.lighting.groups {
            for i in 0..count {
                let mut vis: ShVec = std::array::from_fn(|k| s.vis[k][i]);
                if filtered {
                    self.shader.filter_visibility(&mut vis);
                }
                let mut g = [0.0f32; COEFFS * GROUP];
                let mut back = [0.0f32; GROUP];
                for k in 0..3 {
                    let w = s.weights[k][i];
                    let point =
                        &table.point(s.offsets[k][i])[group * rows * GROUP..][..rows * GROUP];
                    let (front, rest) = point.split_at(COEFFS * GROUP);
                    let front: &[f32; COEFFS * GROUP] =
                        front.try_into().expect("a group's front is 16 vectors");
                    for (g, t) in g.iter_mut().zip(front) {
                        *g += w * t;
                    }
                    for (b, t) in back.iter_mut().zip(rest) {
                        *b += w * t;
                    }
                }
                let mut dot = [0.0f32; GROUP];
                for (v, g) in vis.iter().zip(g.chunks_exact(GROUP)) {
                    for (d, g) in dot.iter_mut().zip(g) {
                        *d += v * g;
                    }
                }
                let above = s.above[i];
                for c in 0..GROUP {
                    s.group_shadowed[c][i] = above * dot[c] + back[c];
                    s.group_unshadowed[c][i] = above * UNIT0 * g[c] + back[c];
                }
            }
            for c in 0..GROUP {
                if let Some(&light) = s.table_lights.get(group * GROUP + c) {
                    s.shadowed[light] = s.group_shadowed[c];
                    s.unshadowed[light] = s.group_unshadowed[c];
                }
            }
        }
    }

    /// Lane by lane: the shades under the constant lights, with and without shadowing,
    /// into the lights' lanes.
    #[inline(always)]
    fn constant_shades(&self, s: &mut Scratch) {
        let (u, back) = self.constant;
        for (light, source) in self.lighting.sources.iter().enumerate() {
            if let Source::Constant(k) = *source {
                for i in 0..LANES {
                    let above = s.above[i];
                    s.shadowed[light][i] = k * (above * s.unit[i] + back);
                    s.unshadowed[light][i] = k * (above * UNIT0 * u[0] + back);
                }
            }
        }
    }
}

/// `v` normalised, or `fallback` when it has no direction (zero or not finite), without
/// branches.
#[inline(always)]
fn normalize_or(v: Vec3, fallback: Vec3) -> Vec3 {
    let len2 = v.length_squared();
    if len2 > 0.0 && len2.is_finite() {
        v / len2.sqrt()
    } else {
        fallback
    }
}

/// The Legendre polynomials `P_0..P_3` at `x`.
#[inline(always)]
fn legendre(x: f32) -> [f32; BANDS] {
    let x2 = x * x;
    [1.0, x, 1.5 * x2 - 0.5, x * (2.5 * x2 - 1.5)]
}

/// One task's scratch for a block of vertices, as a structure of arrays (one array of
/// [`LANES`] lanes per quantity).
struct Scratch {
    /// Per lobe number (`lobes·7`), its lanes.
    lobes: Vec<Lanes>,
    /// Skinned normal, per component.
    normal: [Lanes; 3],
    /// Offset to the tangent neighbour, per component.
    edge: [Lanes; 3],
    /// Skinned position, per component.
    position: [Lanes; 3],
    /// The frame in world space, per component of each axis.
    tangent: [Lanes; 3],
    bitangent: [Lanes; 3],
    world_normal: [Lanes; 3],
    /// The BRDF axis, per component, and the share of its lobe above the horizon.
    axis: [Lanes; 3],
    above: Lanes,
    /// Visibility in world space, per coefficient.
    vis: [Lanes; COEFFS],
    /// Shade under the constant 1 (closed form, before `above` and the back lobe).
    unit: Lanes,
    /// The table's corners: offsets and weights.
    offsets: [[u32; LANES]; 3],
    weights: [Lanes; 3],
    /// Per table channel, its light.
    table_lights: Vec<usize>,
    /// One group of table channels: per channel, the lanes' shades with and without
    /// shadowing.
    group_shadowed: [Lanes; GROUP],
    group_unshadowed: [Lanes; GROUP],
    /// Per light, the lanes' shades with and without shadowing.
    shadowed: Vec<Lanes>,
    unshadowed: Vec<Lanes>,
    /// One vertex's shades per light, with and without shadowing.
    vertex_shadowed: Vec<f32>,
    vertex_unshadowed: Vec<f32>,
}

impl Scratch {
    fn new(frame: &Frame<'_>) -> Box<Self> {
        let lights = frame.lighting.sources.len();
        let table_lights = frame
            .lighting
            .sources
            .iter()
            .enumerate()
            .filter(|(_, s)| matches!(s, Source::Table))
            .map(|(l, _)| l)
            .collect();
        Box::new(Self {
            lobes: vec![[0.0; LANES]; frame.compact.outputs_per_vertex()],
            normal: [[0.0; LANES]; 3],
            edge: [[0.0; LANES]; 3],
            position: [[0.0; LANES]; 3],
            tangent: [[0.0; LANES]; 3],
            bitangent: [[0.0; LANES]; 3],
            world_normal: [[0.0; LANES]; 3],
            axis: [[0.0; LANES]; 3],
            above: [1.0; LANES],
            vis: [[0.0; LANES]; COEFFS],
            unit: [0.0; LANES],
            offsets: [[0; LANES]; 3],
            weights: [[0.0; LANES]; 3],
            table_lights,
            group_shadowed: [[0.0; LANES]; GROUP],
            group_unshadowed: [[0.0; LANES]; GROUP],
            shadowed: vec![[0.0; LANES]; lights],
            unshadowed: vec![[0.0; LANES]; lights],
            vertex_shadowed: vec![0.0; lights],
            vertex_unshadowed: vec![0.0; lights],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::skin_frames;
    use crate::shade::{unit_visibility, ShadingGeometry, Visibility};

    /// One joint with a rest rotation, two vertices each other's tangent neighbour, one
    /// lobe whose axis tilts with the joint's rotation about z.
    fn model() -> PoseModel {
        let n = 2 * LOBE_DIM;
        let mut weights = vec![0.0f32; 4 * n];
        for v in 0..2 {
            let c = v * LOBE_DIM;
            // Constant: axis +z, coefficients of a half-open lobe.
            weights[c + 2] = 1.0;
            weights[c + 3..c + 7].copy_from_slice(&[2.0, 1.0, 0.3, 0.0]);
            // The rotation about z tilts the axis towards +x.
            weights[3 * n + c] = 2.0;
        }
        PoseModel {
            character: "t".into(),
            vertices: 2,
            joints: 1,
            lobes: 1,
            active: vec![0],
            weights,
            limits: Default::default(),
        }
    }

    fn rig() -> Rig {
        Rig {
            rest: vec![Quat::from_rotation_x(0.3)],
            neighbours: vec![1, 0],
        }
    }

    fn relighter() -> Relighter {
        Relighter::new(model(), Shader::new(Mode::Diffuse).unwrap(), rig()).unwrap()
    }

    #[test]
    fn joint_rotations_are_relative_to_the_rest_pose() {
        let rig = rig();
        let local = Affine3A::from_rotation_translation(
            Quat::from_rotation_x(0.3) * Quat::from_rotation_z(0.5),
            Vec3::new(1.0, 2.0, 3.0),
        );
        let r = rig.joint_rotations(&[local]).unwrap();
        assert!((r[0] - Vec3::new(0.0, 0.0, 0.5)).length() < 1e-5, "{r:?}");
        assert!(rig.joint_rotations(&[]).is_err());
    }

    #[test]
    fn a_frame_is_shaded_from_its_joint_transforms_and_skinned_vertices() {
        let mut r = relighter();
        let positions = [Vec3::ZERO, Vec3::X];
        let normals = [Vec3::Z; 2];
        // Brighter towards +z: the shade depends on where the lobe points.
        let mut sky = unit_visibility();
        sky[2] = 1.5;
        let shade = |r: &mut Relighter, angle: f32| {
            let local =
                Affine3A::from_quat(Quat::from_rotation_x(0.3) * Quat::from_rotation_z(angle));
            let pose = FramePose {
                joint_local: &[local],
                positions: &positions,
                normals: &normals,
                transform: Affine3A::IDENTITY,
            };
            r.shade(&pose, &[sky], Vec3::Z)
        };
        // At rest the lobe is about the normal; rotating the joint tilts it away, which
        // changes the shade of every vertex alike.
        let rest = shade(&mut r, 0.0).unwrap();
        let tilted = shade(&mut r, 0.4).unwrap();
        assert_eq!(rest.len(), 2);
        assert!((rest[0] - rest[1]).abs() < 1e-6 && (tilted[0] - tilted[1]).abs() < 1e-6);
        assert!((rest[0] - tilted[0]).abs() > 1e-3, "{rest:?} vs {tilted:?}");
        // The same as shading the model's prediction directly, up to the table's
        // interpolation.
        let model = model();
        let mut raw = Vec::new();
        model.predict_raw(&model.pose_vector(&[Vec3::new(0.0, 0.0, 0.4)]), &mut raw);
        let frames = skin_frames(&positions, &normals, &[1, 0]);
        let direct = Shader::new(Mode::Diffuse)
            .unwrap()
            .shade(
                Visibility::Model(&model, &raw),
                ShadingGeometry {
                    positions: &positions,
                    frames: &frames,
                    transform: Affine3A::IDENTITY,
                },
                &[sky],
                Vec3::Z,
            )
            .unwrap();
        assert!(direct
            .iter()
            .zip(&tilted)
            .all(|(a, b)| (a - b).abs() < 1e-3 * b.abs().max(1.0)));
    }

    #[test]
    fn constant_lights_are_shaded_in_closed_form_as_the_direct_shading_does() {
        let model = model();
        let positions = [Vec3::ZERO, Vec3::X];
        let normals = [Vec3::Z, Vec3::new(0.2, -0.3, 0.9).normalize()];
        let mut sky = unit_visibility();
        sky[2] = 1.5;
        sky[5] = -0.3;
        // A constant light between two table lights, one of them also constant but
        // scaled: every light keeps its place in the output.
        let lights = [
            sky,
            unit_visibility().map(|x| 0.7 * x),
            sky,
            unit_visibility(),
        ];
        let eye = Vec3::new(1.0, -2.0, 3.0);
        let transform = Affine3A::from_rotation_translation(Quat::from_rotation_y(0.5), Vec3::X);
        for mode in [
            Mode::Diffuse,
            Mode::Phong { alpha: 8.0 },
            Mode::Translucent { transmission: 0.3 },
        ] {
            let mut r = Relighter::new(model.clone(), Shader::new(mode).unwrap(), rig()).unwrap();
            let local =
                Affine3A::from_quat(Quat::from_rotation_x(0.3) * Quat::from_rotation_z(0.3));
            let pose = FramePose {
                joint_local: &[local],
                positions: &positions,
                normals: &normals,
                transform,
            };
            let mut got = vec![0.0f32; 2 * 4];
            let mut unshadowed = vec![0.0f32; 2 * 4];
            r.shade_with(&pose, &lights, eye, 4, &mut got, |s, _, slot| {
                slot.copy_from_slice(s)
            })
            .unwrap();
            r.shade_with(&pose, &lights, eye, 4, &mut unshadowed, |_, u, slot| {
                slot.copy_from_slice(u)
            })
            .unwrap();
            let mut raw = Vec::new();
            model.predict_raw(&model.pose_vector(&[Vec3::new(0.0, 0.0, 0.3)]), &mut raw);
            let geometry = ShadingGeometry {
                positions: &positions,
                frames: &skin_frames(&positions, &normals, &[1, 0]),
                transform,
            };
            let shader = Shader::new(mode).unwrap();
            let direct = shader
                .shade(Visibility::Model(&model, &raw), geometry, &lights, eye)
                .unwrap();
            let plain = shader
                .shade(Visibility::Unshadowed, geometry, &lights, eye)
                .unwrap();
            for (k, (a, b)) in got.iter().zip(&direct).enumerate() {
                // The constant lights (1 and 3) in closed form: as exact as the direct
                // shading up to the compaction's rounding; the table's within its
                // interpolation.
                let tol = if k % 4 % 2 == 1 { 1e-4 } else { 2e-3 };
                assert!(
                    (a - b).abs() < tol * b.abs().max(1.0),
                    "{mode:?} {k}: {a} vs {b}"
                );
            }
            for (k, (a, b)) in unshadowed.iter().zip(&plain).enumerate() {
                let tol = if k % 4 % 2 == 1 { 1e-4 } else { 2e-3 };
                assert!(
                    (a - b).abs() < tol * b.abs().max(1.0),
                    "{mode:?} unshadowed {k}: {a} vs {b}"
                );
            }
            // The constant light scaled by 0.7 is shaded 0.7 times the white one.
            assert!((got[1] - 0.7 * got[3]).abs() < 1e-6);
        }
    }

    #[test]
    fn a_glossy_frame_fades_the_shadows_of_a_pose_outside_the_box_as_the_direct_shading_does() {
        use crate::fade::{predict, FadeRule};
        use crate::limits::PoseLimits;
        // The training poses turned the joint about z within ±0.2 rad.
        let model = PoseModel {
            limits: PoseLimits {
                mean: vec![0.0; 3],
                axes: vec![0.0, 0.0, 1.0],
                range: vec![[-0.2, 0.2]],
                ..PoseLimits::default()
            },
            ..model()
        };
        let positions = [Vec3::ZERO, Vec3::X];
        let normals = [Vec3::Z; 2];
        let mut sky = unit_visibility();
        sky[2] = 1.5;
        sky[3] = 0.4;
        // Seen from −x: the reflection vector leans away from the lobe (tilted towards +x).
        let eye = Vec3::new(-3.0, 0.0, 1.0);
        let mode = Mode::Phong { alpha: 8.0 };
        // 0.4 about z (0.2 kept) and 0.3 about x (none kept): coverage 0.2 / 0.5.
        let rotation = Vec3::new(0.3, 0.0, 0.4);
        let fade = FadeRule::of_mode(mode);
        assert!((fade.weight(&model, &[rotation]) - 0.4).abs() < 1e-5);
        let mut r = Relighter::new(model.clone(), Shader::new(mode).unwrap(), rig()).unwrap();
        let local =
            Affine3A::from_quat(Quat::from_rotation_x(0.3) * Quat::from_scaled_axis(rotation));
        let pose = FramePose {
            joint_local: &[local],
            positions: &positions,
            normals: &normals,
            transform: Affine3A::IDENTITY,
        };
        let client = r.shade(&pose, &[sky], eye).unwrap();
        let geometry = ShadingGeometry {
            positions: &positions,
            frames: &skin_frames(&positions, &normals, &[1, 0]),
            transform: Affine3A::IDENTITY,
        };
        let shader = Shader::new(mode).unwrap();
        let shade = |rule: FadeRule| {
            let mut raw = Vec::new();
            predict(&model, rule, &[rotation], &mut raw);
            shader
                .shade(Visibility::Model(&model, &raw), geometry, &[sky], eye)
                .unwrap()
        };
        let (faded, unfaded) = (shade(fade), shade(FadeRule::NONE));
        let plain = shader
            .shade(Visibility::Unshadowed, geometry, &[sky], eye)
            .unwrap();
        for v in 0..2 {
            let (a, b) = (client[v], faded[v]);
            assert!((a - b).abs() < 2e-3 * b.abs().max(1.0), "{v}: {a} vs {b}");
            // 40 % of the way from unshadowed to the unfaded model's shade.
            let want = plain[v] + 0.4 * (unfaded[v] - plain[v]);
            assert!((b - want).abs() < 1e-4, "{v}: {b} vs {want}");
            assert!(
                (unfaded[v] - plain[v]).abs() > 2e-3,
                "{v}: the model shadows: {} vs {}",
                unfaded[v],
                plain[v]
            );
        }
    }

    #[test]
    fn mismatched_rigs_and_frames_are_refused() {
        let bad_rig = Rig {
            rest: vec![Quat::IDENTITY],
            neighbours: vec![0, 5],
        };
        assert!(Relighter::new(model(), Shader::new(Mode::Diffuse).unwrap(), bad_rig).is_err());
        let mut r = relighter();
        let pose = FramePose {
            joint_local: &[Affine3A::IDENTITY],
            positions: &[Vec3::ZERO],
            normals: &[Vec3::Z],
            transform: Affine3A::IDENTITY,
        };
        assert!(r.shade(&pose, &[unit_visibility()], Vec3::Z).is_err());
    }
}
