//! Per-frame relighting as a client runs it (paper §4.3): from a frame's joint transforms
//! and skinned vertices to one shade per vertex and colour channel.
//!
//! A client that animates and skins the character itself keeps a [`Relighter`]: the
//! trained [`PoseModel`] compacted for synthesis ([`CompactModel`]), a [`Shader`] and the
//! character's [`Rig`] (what turns joint transforms into the model's pose vector, and
//! skinned vertices into the frames visibility is stored in). Per frame it passes the
//! joints' local transforms, the skinned positions and normals, the SH lighting and the
//! eye; [`Relighter::shade`] synthesises each vertex's lobes and shades it straight away,
//! on the calling rayon pool (all cores, or one inside a one-thread pool).
//!
//! Shading in world space: a vertex's visibility `v` (its lobes expanded to SH with their
//! axes in world space, eq. 1) is dotted with a vector `g` that depends only on the BRDF
//! axis and the lighting ([`Shader::axis_transfer`]); `g` is tabulated over the sphere once
//! per lighting ([`SphereTable`], [`TABLE_RES`] cells per side of the octahedral map) and
//! interpolated per vertex, which replaces rotating the lighting into every vertex's frame.
//! The result equals [`Shader::shade`] of the model's prediction up to the compaction's
//! bound and the table's interpolation (measured in docs/RELIGHTING.md).

use glam::{Affine3A, Mat3, Quat, Vec3};
use psao_trace::ao::orthonormal_basis;
use rayon::prelude::*;

use crate::character::rotation_vector;
use crate::compact::{CompactModel, DEFAULT_TOLERANCE};
use crate::model::{PoseModel, LOBE_DIM};
use crate::sh::{self, ShVec, COEFFS};
use crate::shade::{orthonormalised, Mode, Shader};
use crate::transfer_table::SphereTable;
use crate::zonal::ZH_SCALE;
use crate::PrtError;

/// Cells per side of the octahedral map of the lighting's transfer table.
pub const TABLE_RES: usize = 64;

/// Vertices per task of a frame.
const CHUNK: usize = 256;
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

/// A character's model, shader and rig, ready to relight it frame after frame.
pub struct Relighter {
    compact: CompactModel,
    shader: Shader,
    rig: Rig,
    /// The lighting the table was made for, and the table (`17` values per channel: `g`,
    /// then `back`, see [`Shader::axis_transfer`]).
    table: Option<(Vec<ShVec>, SphereTable)>,
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
            table: None,
        })
    }

    /// The compacted model.
    pub fn compact(&self) -> &CompactModel {
        &self.compact
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
        let n = self.compact.vertices();
        if pose.positions.len() != n || pose.normals.len() != n {
            return Err(PrtError::Parameter(format!(
                "{} positions and {} normals for a model of {n} vertices",
                pose.positions.len(),
                pose.normals.len()
            )));
        }
        let rotations = self.rig.joint_rotations(pose.joint_local)?;
        let factors = self.compact.row_factors(&rotations);
        if !matches!(&self.table, Some((l, _)) if l == lights) {
            let shader = &self.shader;
            let table = SphereTable::new(TABLE_RES, lights.len() * (COEFFS + 1), |axis, out| {
                for (light, o) in lights.iter().zip(out.chunks_exact_mut(COEFFS + 1)) {
                    let (g, back) = shader.axis_transfer(axis, light);
                    o[..COEFFS].copy_from_slice(&g);
                    o[COEFFS] = back;
                }
            });
            self.table = Some((lights.to_vec(), table));
        }
        let Some((_, table)) = &self.table else {
            unreachable!("the table was just made")
        };
        let ch = lights.len();
        out.resize(n * ch, 0.0);
        if ch == 0 {
            return Ok(());
        }
        let frame = Frame {
            compact: &self.compact,
            shader: &self.shader,
            table,
            factors: &factors,
            neighbours: &self.rig.neighbours,
            pose,
            linear: orthonormalised(Mat3::from(pose.transform.matrix3)),
            eye,
        };
        out.par_chunks_mut(ch * CHUNK).enumerate().for_each_init(
            || Scratch::new(frame.compact, table),
            |scratch, (c, chunk)| frame.shade_chunk(c * CHUNK, ch, scratch, chunk),
        );
        Ok(())
    }
}

/// What every vertex of one frame shares.
struct Frame<'a> {
    compact: &'a CompactModel,
    shader: &'a Shader,
    table: &'a SphereTable,
    factors: &'a [f32],
    neighbours: &'a [u32],
    pose: &'a FramePose<'a>,
    /// The rotation of the pose's transform.
    linear: Mat3,
    eye: Vec3,
}

impl Frame<'_> {
    /// Shades the vertices from `first` on into `chunk` (`ch` values each), with the
    /// processor's wider vector instructions where it has them.
    fn shade_chunk(&self, first: usize, ch: usize, scratch: &mut Scratch, chunk: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the processor has AVX2 and FMA (checked just above).
            unsafe { self.shade_chunk_avx2(first, ch, scratch, chunk) };
            return;
        }
        self.shade_chunk_plain(first, ch, scratch, chunk);
    }

    /// [`Self::shade_chunk`] compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The processor must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn shade_chunk_avx2(
        &self,
        first: usize,
        ch: usize,
        scratch: &mut Scratch,
        chunk: &mut [f32],
    ) {
        self.shade_chunk_plain(first, ch, scratch, chunk);
    }

    /// [`Self::shade_chunk`] in portable code: blocks of [`BLOCK`] vertices, each in three
    /// passes over a structure of arrays (synthesis and gathering per vertex; frames,
    /// lobes and visibility lane by lane, which the compiler vectorises; the table per
    /// vertex).
    #[inline(always)]
    fn shade_chunk_plain(&self, first: usize, ch: usize, scratch: &mut Scratch, chunk: &mut [f32]) {
        for (b, slots) in chunk.chunks_mut(ch * BLOCK).enumerate() {
            let start = first + b * BLOCK;
            let count = slots.len() / ch;
            self.gather(start, count, scratch);
            self.visibility(scratch);
            for (i, slot) in slots.chunks_mut(ch).enumerate() {
                self.shade_vertex(start + i, i, scratch, slot);
            }
        }
    }

    /// Pass 1: each vertex's synthesised lobes, position, normal and the offset to its
    /// tangent neighbour, into the lanes (lanes beyond `count` are zero).
    #[inline(always)]
    fn gather(&self, start: usize, count: usize, s: &mut Scratch) {
        let per = self.compact.outputs_per_vertex();
        for lanes in s.lobes.iter_mut().chain(&mut s.normal).chain(&mut s.edge) {
            lanes.fill(0.0);
        }
        for i in 0..count {
            let v = start + i;
            let out = &mut s.outputs[..per];
            self.compact.vertex_outputs(self.factors, v, out);
            for (lanes, x) in s.lobes.iter_mut().zip(&out[..per]) {
                lanes[i] = *x;
            }
            let p = self.pose.positions[v];
            let n = self.pose.normals[v];
            let e = self.pose.positions[self.neighbours[v] as usize] - p;
            for k in 0..3 {
                s.normal[k][i] = n[k];
                s.edge[k][i] = e[k];
            }
        }
    }

    /// Pass 2, lane by lane: the frame that follows the skin (as
    /// `character::skin_frames`) turned to world, and the visibility in world space (the
    /// lobes with their axes turned to world, eq. 1).
    #[inline(always)]
    fn visibility(&self, s: &mut Scratch) {
        for lanes in &mut s.vis {
            lanes.fill(0.0);
        }
        for i in 0..BLOCK {
            let n = Vec3::new(s.normal[0][i], s.normal[1][i], s.normal[2][i]).normalize_or(Vec3::Z);
            let e = Vec3::new(s.edge[0][i], s.edge[1][i], s.edge[2][i]);
            let t = e - n * e.dot(n);
            let len2 = t.length_squared();
            let t = if len2 > 0.0 && len2.is_finite() {
                t / len2.sqrt()
            } else {
                orthonormal_basis(n).0
            };
            let to_world = self.linear * Mat3::from_cols(t, n.cross(t), n);
            for k in 0..3 {
                s.world_normal[k][i] = to_world.z_axis[k];
            }
            for lobe in s.lobes.chunks_exact(LOBE_DIM) {
                let local = Vec3::new(lobe[0][i], lobe[1][i], lobe[2][i]).normalize_or(Vec3::Z);
                let y = sh::eval(to_world * local);
                for (c, y) in y.iter().enumerate() {
                    s.vis[c][i] += ZH_SCALE[sh::band_of(c)] * lobe[3 + sh::band_of(c)][i] * y;
                }
            }
        }
    }

    /// Pass 3 for vertex `v` in lane `i`: the filter, the BRDF axis and horizon, the table
    /// and the shade per channel into `slot`.
    #[inline(always)]
    fn shade_vertex(&self, v: usize, i: usize, s: &mut Scratch, slot: &mut [f32]) {
        let mut vis: ShVec = std::array::from_fn(|c| s.vis[c][i]);
        self.shader.filter_visibility(&mut vis);
        let normal = Vec3::new(
            s.world_normal[0][i],
            s.world_normal[1][i],
            s.world_normal[2][i],
        );
        // The BRDF axis and the share of its lobe above the horizon.
        let (axis, above) = match self.shader.mode() {
            Mode::Phong { .. } => {
                let p = self.pose.transform.transform_point3(self.pose.positions[v]);
                let wo = (self.eye - p).normalize_or(normal);
                let cos = normal.dot(wo);
                (
                    (2.0 * cos * normal - wo).normalize_or(normal),
                    self.shader.above_horizon(cos),
                )
            }
            _ => (normal, 1.0),
        };
        self.table.lookup(axis, &mut s.transfer);
        for (o, t) in slot.iter_mut().zip(s.transfer.chunks_exact(COEFFS + 1)) {
            *o = above * sh::dot(&vis, t[..COEFFS].try_into().expect("16 values")) + t[COEFFS];
        }
    }
}

/// Vertices per block of a chunk's passes.
const BLOCK: usize = 64;

/// One thread's scratch for a block of vertices, as a structure of arrays (one array of
/// [`BLOCK`] lanes per quantity).
struct Scratch {
    /// One vertex's synthesised outputs.
    outputs: Vec<f32>,
    /// Per lobe number (`lobes·7`), its lanes.
    lobes: Vec<[f32; BLOCK]>,
    /// Skinned normal, per component.
    normal: [[f32; BLOCK]; 3],
    /// Offset to the tangent neighbour, per component.
    edge: [[f32; BLOCK]; 3],
    /// The frame's normal in world space, per component.
    world_normal: [[f32; BLOCK]; 3],
    /// Visibility in world space, per coefficient.
    vis: [[f32; BLOCK]; COEFFS],
    /// The table's values at one vertex's BRDF axis.
    transfer: Vec<f32>,
}

impl Scratch {
    fn new(compact: &CompactModel, table: &SphereTable) -> Box<Self> {
        Box::new(Self {
            outputs: vec![0.0; compact.outputs_per_vertex()],
            lobes: vec![[0.0; BLOCK]; compact.outputs_per_vertex()],
            normal: [[0.0; BLOCK]; 3],
            edge: [[0.0; BLOCK]; 3],
            world_normal: [[0.0; BLOCK]; 3],
            vis: [[0.0; BLOCK]; COEFFS],
            transfer: vec![0.0; table.width()],
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
