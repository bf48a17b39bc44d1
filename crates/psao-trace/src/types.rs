//! Query types shared by every backend: rays, hits, backend and geometry selection, errors.

use std::fmt;
use std::str::FromStr;

use glam::Vec3;

/// A ray segment: points `origin + t·dir` with `0 < t < tmax` are tested (whether a hit at
/// exactly `tmax` counts depends on the backend).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// World-space start point.
    pub origin: Vec3,
    /// Unit direction (hit distances `t` are then world distances).
    pub dir: Vec3,
    /// Exclusive upper bound of the tested segment.
    pub tmax: f32,
}

impl Ray {
    /// A ray from `origin` along the unit direction `dir`, tested up to `tmax`.
    pub fn new(origin: Vec3, dir: Vec3, tmax: f32) -> Self {
        Self { origin, dir, tmax }
    }

    /// Whether the ray can be traced at all (finite, non-zero direction, positive `tmax`);
    /// backends report other rays as misses.
    pub(crate) fn is_traceable(&self) -> bool {
        self.tmax > 0.0 && self.origin.is_finite() && self.dir.is_finite() && self.dir != Vec3::ZERO
    }
}

/// The closest intersection of a ray with the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (a distance when the direction is unit).
    pub t: f32,
    /// Index into `Scene::instances`.
    pub instance: u32,
    /// Index into the instance's mesh `indices`.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex: `p = (1-u-v)·v0 + u·v1 + v·v2`.
    pub v: f32,
}

/// A ray-tracing implementation behind [`crate::Tracer`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Backend {
    /// Pure-Rust compressed wide BVHs from the `obvhs` crate (always available).
    Obvhs,
    /// Intel Embree 3 (cargo feature `embree`).
    Embree,
}

impl Backend {
    /// The backends compiled into this build, default first.
    pub fn compiled() -> Vec<Backend> {
        if cfg!(feature = "embree") {
            vec![Backend::Embree, Backend::Obvhs]
        } else {
            vec![Backend::Obvhs]
        }
    }

    /// Whether this backend is compiled into this build.
    pub fn is_compiled(self) -> bool {
        match self {
            Backend::Obvhs => true,
            Backend::Embree => cfg!(feature = "embree"),
        }
    }

    /// Lower-case name, as accepted by [`FromStr`].
    pub fn name(self) -> &'static str {
        match self {
            Backend::Obvhs => "obvhs",
            Backend::Embree => "embree",
        }
    }
}

impl Default for Backend {
    /// Embree when compiled in, otherwise obvhs.
    fn default() -> Self {
        if cfg!(feature = "embree") {
            Backend::Embree
        } else {
            Backend::Obvhs
        }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Backend {
    type Err = TraceError;

    /// Parses `"obvhs"` or `"embree"` (case-insensitive); it need not be compiled in.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "obvhs" => Ok(Backend::Obvhs),
            "embree" => Ok(Backend::Embree),
            _ => Err(TraceError::UnknownBackend(s.to_string())),
        }
    }
}

/// Which triangles the acceleration structure contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryMode {
    /// Every triangle (primary visibility, e.g. reference images).
    Primary,
    /// Skips meshes whose material is `skipped_by_rays()` (alpha-masked), as AO rays do.
    Occlusion,
}

/// Errors from building or updating a [`crate::Tracer`].
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// A backend name that is neither `obvhs` nor `embree`.
    #[error("unknown ray-tracing backend `{0}` (expected `obvhs` or `embree`)")]
    UnknownBackend(String),
    /// The backend exists but was not compiled in.
    #[error("ray-tracing backend `{0}` is not compiled in (enable the cargo feature `embree`)")]
    NotCompiled(Backend),
    /// An instance refers to a mesh that does not exist.
    #[error("instance {instance} refers to mesh {mesh}, but the scene has {meshes} meshes")]
    InstanceMesh {
        /// Instance index.
        instance: usize,
        /// The missing mesh index.
        mesh: usize,
        /// Number of meshes in the scene.
        meshes: usize,
    },
    /// A mesh index passed to an update does not exist.
    #[error("mesh {mesh} does not exist (the scene has {meshes} meshes)")]
    NoSuchMesh {
        /// The requested mesh.
        mesh: usize,
        /// Number of meshes.
        meshes: usize,
    },
    /// A mesh refers to a material that does not exist.
    #[error("mesh {mesh} refers to material {material}, but the scene has {materials} materials")]
    MeshMaterial {
        /// Mesh index.
        mesh: usize,
        /// The missing material index.
        material: usize,
        /// Number of materials.
        materials: usize,
    },
    /// A triangle index points past the mesh's vertices.
    #[error("mesh {mesh} triangle {triangle} uses vertex {vertex}, but the mesh has {vertices} vertices")]
    VertexIndex {
        /// Mesh index.
        mesh: usize,
        /// Triangle index.
        triangle: usize,
        /// The offending vertex index.
        vertex: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("mesh {mesh} vertex {vertex} has a non-finite position")]
    NonFinitePosition {
        /// Mesh index.
        mesh: usize,
        /// Vertex index.
        vertex: usize,
    },
    /// An update supplied a different number of positions than the mesh has.
    #[error("mesh {mesh} has {expected} vertices, but {got} positions were given")]
    PositionCount {
        /// Mesh index.
        mesh: usize,
        /// Vertex count of the mesh.
        expected: usize,
        /// Number of positions supplied.
        got: usize,
    },
    /// The Embree library reported an error.
    #[error("embree: {0}")]
    Embree(String),
}
