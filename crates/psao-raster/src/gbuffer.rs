//! The G-buffer: per-pixel surface attributes of the nearest visible triangle.

use glam::{Vec2, Vec3};
use psao_scene::Scene;
use rayon::prelude::*;

/// Per-pixel surface attributes, row-major with the origin at the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Linear view-space distance along the camera axis; `f32::INFINITY` where nothing is covered.
    pub depth: Vec<f32>,
    /// World-space position (perspective-correct).
    pub position: Vec<Vec3>,
    /// Unit world-space shading normal, interpolated and turned into the camera-facing
    /// hemisphere of the geometric normal.
    pub normal: Vec<Vec3>,
    /// Unit world-space face normal, facing the camera.
    pub geometric_normal: Vec<Vec3>,
    /// Scene instance index, [`GBuffer::NONE`] where empty.
    pub instance: Vec<u32>,
    /// Triangle index within the instance's mesh, [`GBuffer::NONE`] where empty.
    pub triangle: Vec<u32>,
    /// Barycentrics (u, v) with p = (1−u−v)·v0 + u·v1 + v·v2, perspective-correct.
    pub barycentric: Vec<Vec2>,
}

impl GBuffer {
    /// Marks pixels that no triangle covers (in [`GBuffer::instance`] and [`GBuffer::triangle`]).
    pub const NONE: u32 = u32::MAX;

    /// An all-empty G-buffer of the given size.
    pub fn empty(width: u32, height: u32) -> Self {
        let mut g = Self {
            width: 0,
            height: 0,
            depth: Vec::new(),
            position: Vec::new(),
            normal: Vec::new(),
            geometric_normal: Vec::new(),
            instance: Vec::new(),
            triangle: Vec::new(),
            barycentric: Vec::new(),
        };
        g.resize(width, height);
        g
    }

    /// Sets the size; pixels that already existed keep their (stale) values, new ones are empty.
    pub(crate) fn resize(&mut self, width: u32, height: u32) {
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        // Fill in parallel so that first-touch page faults of large buffers are spread out.
        fn fill<T: Copy + Send + Sync>(v: &mut Vec<T>, n: usize, value: T) {
            v.truncate(n);
            let extra = n - v.len();
            v.par_extend((0..extra).into_par_iter().map(|_| value));
        }
        fill(&mut self.depth, n, f32::INFINITY);
        fill(&mut self.position, n, Vec3::ZERO);
        fill(&mut self.normal, n, Vec3::ZERO);
        fill(&mut self.geometric_normal, n, Vec3::ZERO);
        fill(&mut self.instance, n, Self::NONE);
        fill(&mut self.triangle, n, Self::NONE);
        fill(&mut self.barycentric, n, Vec2::ZERO);
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.depth.len()
    }

    /// True when the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.depth.is_empty()
    }

    /// True when pixel `i` shows a triangle.
    pub fn covered(&self, i: usize) -> bool {
        self.instance[i] != Self::NONE
    }

    /// Linear index of pixel (`x`, `y`).
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// Material index (into [`Scene::materials`]) of the surface at pixel `i`, `None` where
    /// empty or when the instance does not belong to `scene`.
    pub fn material(&self, scene: &Scene, i: usize) -> Option<usize> {
        let inst = scene.instances.get(*self.instance.get(i)? as usize)?;
        Some(scene.meshes.get(inst.mesh)?.material)
    }

    /// Number of covered pixels.
    pub fn covered_count(&self) -> usize {
        self.instance.iter().filter(|&&i| i != Self::NONE).count()
    }

    /// Mutable views of the rows `band_height` at a time, top to bottom.
    pub(crate) fn bands_mut(&mut self, band_height: u32) -> Vec<BandMut<'_>> {
        let n = (self.width * band_height.max(1)) as usize;
        if n == 0 {
            return Vec::new();
        }
        let width = self.width;
        self.depth
            .chunks_mut(n)
            .zip(self.position.chunks_mut(n))
            .zip(self.normal.chunks_mut(n))
            .zip(self.geometric_normal.chunks_mut(n))
            .zip(self.instance.chunks_mut(n))
            .zip(self.triangle.chunks_mut(n))
            .zip(self.barycentric.chunks_mut(n))
            .enumerate()
            .map(
                |(
                    b,
                    (
                        (((((depth, position), normal), geometric_normal), instance), triangle),
                        barycentric,
                    ),
                )| {
                    BandMut {
                        y0: b as u32 * band_height,
                        width,
                        depth,
                        position,
                        normal,
                        geometric_normal,
                        instance,
                        triangle,
                        barycentric,
                    }
                },
            )
            .collect()
    }
}

/// Mutable slices of a horizontal band of full-width rows of a [`GBuffer`].
pub(crate) struct BandMut<'a> {
    /// First row of the band.
    pub y0: u32,
    /// Image width.
    pub width: u32,
    /// The band's rows of [`GBuffer::depth`].
    pub depth: &'a mut [f32],
    /// The band's rows of [`GBuffer::position`].
    pub position: &'a mut [Vec3],
    /// The band's rows of [`GBuffer::normal`].
    pub normal: &'a mut [Vec3],
    /// The band's rows of [`GBuffer::geometric_normal`].
    pub geometric_normal: &'a mut [Vec3],
    /// The band's rows of [`GBuffer::instance`].
    pub instance: &'a mut [u32],
    /// The band's rows of [`GBuffer::triangle`].
    pub triangle: &'a mut [u32],
    /// The band's rows of [`GBuffer::barycentric`].
    pub barycentric: &'a mut [Vec2],
}

impl BandMut<'_> {
    /// Marks pixel `p` of the band as empty.
    pub fn clear(&mut self, p: usize) {
        self.depth[p] = f32::INFINITY;
        self.position[p] = Vec3::ZERO;
        self.normal[p] = Vec3::ZERO;
        self.geometric_normal[p] = Vec3::ZERO;
        self.instance[p] = GBuffer::NONE;
        self.triangle[p] = GBuffer::NONE;
        self.barycentric[p] = Vec2::ZERO;
    }

    /// Number of rows in the band.
    pub fn rows(&self) -> u32 {
        (self.depth.len() / self.width as usize) as u32
    }
}
