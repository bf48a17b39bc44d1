//! The frame pipeline and its reusable scratch memory.

use psao_scene::{Camera, Scene};
use rayon::prelude::*;

use crate::geometry::{self, PosedInstance, VertexBuffers};
use crate::mask::{Cut, MaskTest};
use crate::pose::{validate_poses, InstancePose, PoseError};
use crate::raster::{self, Bins, VisibilityBand, BAND_ROWS};
use crate::resolve::Resolver;
use crate::setup::{SetupTri, TriangleSetup, MAX_DIMENSION};
use crate::view::View;
use crate::{GBuffer, RasterOptions};

/// Triangles per setup task.
const SETUP_CHUNK: usize = 4096;

/// A rasterizer that keeps its scratch memory between frames; reuse one (and one output
/// [`GBuffer`]) per view in a frame loop to avoid reallocating every frame.
#[derive(Default)]
pub struct Rasterizer {
    vertices: Vec<VertexBuffers>,
    setup_chunks: Vec<Vec<SetupTri>>,
    tris: Vec<SetupTri>,
    bins: Bins,
}

impl Rasterizer {
    /// A rasterizer with no scratch memory yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Rasterizes `scene` at its stored transforms into `out` (resized as needed; every pixel
    /// is overwritten).
    pub fn rasterize(
        &mut self,
        scene: &Scene,
        camera: &Camera,
        opts: &RasterOptions,
        out: &mut GBuffer,
    ) {
        let poses: Vec<InstancePose<'static>> =
            scene.instances.iter().map(InstancePose::rest).collect();
        self.render(scene, &poses, camera, opts, out);
    }

    /// Rasterizes `scene` with instance `i` posed by `poses[i]` into `out` (resized as needed;
    /// every pixel is overwritten).
    pub fn rasterize_posed(
        &mut self,
        scene: &Scene,
        poses: &[InstancePose<'_>],
        camera: &Camera,
        opts: &RasterOptions,
        out: &mut GBuffer,
    ) -> Result<(), PoseError> {
        validate_poses(scene, poses)?;
        self.render(scene, poses, camera, opts, out);
        Ok(())
    }

    /// Rasterizes with poses already validated.
    pub(crate) fn render(
        &mut self,
        scene: &Scene,
        poses: &[InstancePose<'_>],
        camera: &Camera,
        opts: &RasterOptions,
        out: &mut GBuffer,
    ) {
        let (width, height) = (
            opts.width.min(MAX_DIMENSION),
            opts.height.min(MAX_DIMENSION),
        );
        out.resize(width, height);
        if width == 0 || height == 0 {
            return;
        }
        let view = View::new(camera, width, height);
        let instances = geometry::pose_instances(scene, poses, &view, &mut self.vertices);
        let first_id = first_ids(&instances);
        setup_triangles(
            &instances,
            &first_id,
            &TriangleSetup::new(&view, opts.cull_backfaces),
            &mut self.setup_chunks,
            &mut self.tris,
        );
        self.bins
            .rebuild(&self.tris, height.div_ceil(BAND_ROWS) as usize);
        let resolver = Resolver {
            view: &view,
            instances: &instances,
            first_id: &first_id,
        };
        let masks = MaskTest {
            view: &view,
            instances: &instances,
            first_id: &first_id,
        };
        let (tris, bins) = (&self.tris, &self.bins);
        out.bands_mut(BAND_ROWS)
            .into_par_iter()
            .enumerate()
            .for_each_init(VisibilityBand::default, |vis, (b, mut band)| {
                let rows = (band.y0, band.rows(), width);
                raster::rasterize_band(tris, bins.band(b), rows, (view.inv_far, &masks), vis);
                resolver.resolve_band(vis, &mut band);
            });
    }
}

/// First global triangle id of each instance (ids from `u32::MAX` on are never rasterized).
fn first_ids(instances: &[PosedInstance<'_>]) -> Vec<u32> {
    let mut next = 0u64;
    instances
        .iter()
        .map(|inst| {
            let first = next.min(u64::from(u32::MAX)) as u32;
            next += inst.indices.len() as u64;
            first
        })
        .collect()
}

/// Clips, projects and sets up all triangles into `tris`, in global id order.
fn setup_triangles(
    instances: &[PosedInstance<'_>],
    first_id: &[u32],
    setup: &TriangleSetup<'_>,
    chunks: &mut Vec<Vec<SetupTri>>,
    tris: &mut Vec<SetupTri>,
) {
    let work: Vec<(usize, usize)> = instances
        .iter()
        .enumerate()
        .flat_map(|(i, inst)| {
            (0..inst.indices.len())
                .step_by(SETUP_CHUNK)
                .map(move |s| (i, s))
        })
        .collect();
    chunks.resize_with(work.len(), Vec::new);
    chunks
        .par_iter_mut()
        .zip(&work)
        .for_each(|(out, &(i, start))| {
            out.clear();
            let inst = &instances[i];
            let masked = match inst.cut {
                Cut::Nothing => false,
                Cut::Everything => return,
                Cut::Texels { .. } => true,
            };
            for tri in start..(start + SETUP_CHUNK).min(inst.indices.len()) {
                let id = u64::from(first_id[i]) + tri as u64;
                if id >= u64::from(u32::MAX) {
                    break;
                }
                if let Some((idx, world)) = inst.triangle(tri) {
                    let clip = idx.map(|v| inst.clip[v as usize]);
                    setup.push(id as u32, world, clip, (inst.single_sided, masked), out);
                }
            }
        });
    tris.clear();
    for c in chunks.iter() {
        tris.extend_from_slice(c);
    }
}
