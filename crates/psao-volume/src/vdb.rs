//! OpenVDB ingest. The header, grid descriptors, grid metadata, transform and root background
//! are parsed here first, so that files `vdb-rs` cannot handle (wrong magic, old versions,
//! unsupported transforms, non-float grids, truncated headers) are rejected with a typed error
//! before `vdb-rs` reads the tree. The tree itself is then walked once without allocating
//! ([`scan`]): every length is checked against the bytes left, and nodes, leaves and the
//! voxels of active tiles are counted against the limits below before `vdb-rs` reads it or
//! anything is expanded. Active tiles stay tiles ([`Tile`]): the volume gives each distinct
//! tile value one shared brick. A panic inside `vdb-rs` is caught as a last guard.
//!
//! The limits are far above the largest real file in the project's data
//! (`../shared/data/volumes/smoke1.vdb`: 1,049,275 active voxels in 3,117 leaves and no
//! tiles, i.e. 1/84 of [`MAX_LEAVES`] and 1/1345 of [`MAX_CELLS`]; checked by
//! `the_largest_real_file_is_far_inside_the_reader_limits` in `tests/real_data.rs`).

mod scan;

use crate::error::{Result, VolumeError};
use crate::grid::{voxel_index, GridClass, Leaf, SparseGrid, Tile, Transform, BRICK, BRICK_VOXELS};
use glam::{DVec3, IVec3};
use std::collections::HashSet;
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::Path;

/// Oldest OpenVDB file version accepted (per-grid compression and node-mask compression).
const MIN_VERSION: u32 = 222;
/// Newest OpenVDB file version accepted.
const MAX_VERSION: u32 = 224;
/// Upper bound on any length field in the header (names, metadata blobs).
const MAX_FIELD: u32 = 1 << 24;
/// Most bytes of a VDB file read from disk (4 GiB).
pub const MAX_FILE_BYTES: u64 = 1 << 32;
/// Most root children (5-level internal nodes, 4096³ voxels each): a volume must fit one
/// 4096³ flat-tree top node, which at most 2 × 2 × 2 aligned root children can touch.
pub const MAX_ROOT_NODES: usize = 8;
/// Most 4-level internal nodes (128³ voxels each; `vdb-rs` keeps some 17 KiB per node).
pub const MAX_INTERNAL_NODES: usize = 8192;
/// Most leaves (8³ voxels each; some 6 KiB per leaf while a volume is built, so this bounds
/// the build at about 1.6 GiB).
pub const MAX_LEAVES: usize = 1 << 18;
/// Most 8³ cells, leaves and the cells of active tiles together (1 << 22 cells are
/// 2.1 × 10⁹ voxels; each costs some 50 bytes of tree and bounds in a volume).
pub const MAX_CELLS: usize = 1 << 22;

/// What the header says about one grid.
#[derive(Clone, Debug)]
pub struct GridInfo {
    /// Grid name.
    pub name: String,
    /// OpenVDB tree type, e.g. `Tree_float_5_4_3`.
    pub grid_type: String,
    /// `class` metadata (`fog volume`, `level set`, …) if present.
    pub class: Option<String>,
    /// Whether values are stored as 16-bit floats.
    pub half_float: bool,
    /// Transform map name.
    pub transform_name: String,
    /// Index-to-world map, if supported.
    pub transform: Option<Transform>,
    /// Root background value.
    pub background: f32,
    /// Active voxel count from the metadata, if present.
    pub active_voxels: Option<i64>,
    /// Where the tree starts (known when the transform is supported).
    layout: Option<scan::TreeLayout>,
}

/// What the header says about a whole file.
#[derive(Clone, Debug)]
pub struct VdbInfo {
    /// OpenVDB file format version.
    pub file_version: u32,
    /// The grids in file order.
    pub grids: Vec<GridInfo>,
}

/// Reads a VDB file and returns the float grid named `grid` (or the first float grid).
pub fn read_vdb_file(path: &Path, grid: Option<&str>) -> Result<SparseGrid> {
    let bytes = read_regular_file(path)?;
    read_vdb_bytes(&bytes, &path.display().to_string(), grid)
}

/// The bytes of a regular file of at most [`MAX_FILE_BYTES`] (a device such as `/dev/zero`
/// or a FIFO is refused, not read).
pub fn read_regular_file(path: &Path) -> Result<Vec<u8>> {
    let io = |source| VolumeError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(VolumeError::InvalidVdb(
            path.display().to_string(),
            "not a regular file".into(),
        ));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(VolumeError::LimitExceeded {
            label: path.display().to_string(),
            what: "file bytes",
            count: meta.len(),
            limit: MAX_FILE_BYTES,
        });
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_FILE_BYTES)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    Ok(bytes)
}

/// Parses only the header of a VDB file held in memory (`label` names it in errors).
pub fn inspect_vdb(bytes: &[u8], label: &str) -> Result<VdbInfo> {
    let mut r = Header {
        cur: Cursor::new(bytes),
        label,
    };
    r.parse()
}

/// Reads the float grid named `grid` (or the first float grid) from VDB bytes.
pub fn read_vdb_bytes(bytes: &[u8], label: &str, grid: Option<&str>) -> Result<SparseGrid> {
    let info = inspect_vdb(bytes, label)?;
    let chosen = match grid {
        Some(name) => info.grids.iter().find(|g| g.name == name).ok_or_else(|| {
            VolumeError::UnsupportedGrid(label.into(), format!("no grid named `{name}`"))
        })?,
        None => info
            .grids
            .iter()
            .find(|g| is_float_tree(&g.grid_type))
            .ok_or_else(|| {
                let types: Vec<_> = info.grids.iter().map(|g| g.grid_type.as_str()).collect();
                VolumeError::UnsupportedGrid(
                    label.into(),
                    format!("no float grid (grid types: {types:?})"),
                )
            })?,
    };
    if !is_float_tree(&chosen.grid_type) {
        return Err(VolumeError::UnsupportedGrid(
            label.into(),
            format!(
                "grid `{}` has type `{}`, expected a float 5-4-3 tree",
                chosen.name, chosen.grid_type
            ),
        ));
    }
    let transform = chosen.transform.ok_or_else(|| {
        VolumeError::UnsupportedTransform(label.into(), chosen.transform_name.clone())
    })?;
    let class = match chosen.class.as_deref() {
        Some("level set") => GridClass::LevelSet,
        Some("fog volume") | Some("unknown") | None => GridClass::Fog,
        Some(other) => {
            return Err(VolumeError::UnsupportedGrid(
                label.into(),
                format!("grid class `{other}`"),
            ))
        }
    };
    let layout = chosen.layout.ok_or_else(|| {
        VolumeError::UnsupportedGrid(label.into(), format!("grid `{}` has no tree", chosen.name))
    })?;
    scan::scan(bytes, label, layout)?;
    let tree = read_tree(bytes, label, &chosen.name)?;
    let (mut leaves, mut tiles) = collect_leaves(&tree, class, chosen.background)?;
    leaves.sort_by_key(|l| (l.origin.z, l.origin.y, l.origin.x));
    tiles.sort_by_key(|t| (t.origin.z, t.origin.y, t.origin.x));
    if class == GridClass::LevelSet {
        for leaf in &mut leaves {
            fill_inactive_signs(leaf, chosen.background.abs());
        }
    }
    Ok(SparseGrid {
        name: chosen.name.clone(),
        class,
        transform,
        background: if class == GridClass::Fog {
            0.0
        } else {
            chosen.background.abs()
        },
        leaves,
        tiles,
    })
}

fn is_float_tree(t: &str) -> bool {
    t == "Tree_float_5_4_3" || t == "Tree_float_5_4_3_HalfFloat"
}

/// Runs `vdb-rs` on a grid whose header was validated, turning errors and panics into errors.
fn read_tree(bytes: &[u8], label: &str, name: &str) -> Result<vdb_rs::Grid<f32>> {
    let invalid = |m: String| VolumeError::InvalidVdb(label.into(), m);
    let outcome = std::panic::catch_unwind(|| {
        let mut reader = vdb_rs::VdbReader::new(Cursor::new(bytes))?;
        reader.read_grid::<f32>(name)
    });
    match outcome {
        Ok(Ok(grid)) => Ok(grid),
        Ok(Err(e)) => Err(invalid(format!("{e} ({e:?})"))),
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "reader panicked".into());
            Err(invalid(format!("damaged tree data ({msg})")))
        }
    }
}

fn ivec<T: Into<[i32; 3]>>(v: T) -> IVec3 {
    IVec3::from_array(v.into())
}

/// Flattens the `vdb-rs` tree into 8³ leaves and, for fog volumes, active tiles (level sets
/// keep only their leaves: their tiles are the inside and outside of the narrow band).
fn collect_leaves(
    tree: &vdb_rs::Grid<f32>,
    class: GridClass,
    background: f32,
) -> Result<(Vec<Leaf>, Vec<Tile>)> {
    let mut leaves = Vec::new();
    let mut tiles = Vec::new();
    let fog = class == GridClass::Fog;
    for n5 in &tree.tree.root_nodes {
        for n4 in n5.nodes.values() {
            for n3 in n4.nodes.values() {
                leaves.push(convert_leaf(n3)?);
            }
            for idx in n4
                .value_mask
                .iter_ones()
                .filter(|&i| fog && !n4.child_mask[i])
            {
                tiles.push(Tile {
                    origin: ivec(n4.origin) + child_offset(idx, 4, 3),
                    span: BRICK as i32,
                    value: *n4.data.get(idx).unwrap_or(&background),
                });
            }
        }
        for idx in n5
            .value_mask
            .iter_ones()
            .filter(|&i| fog && !n5.child_mask[i])
        {
            tiles.push(Tile {
                origin: ivec(n5.origin) + child_offset(idx, 5, 7),
                span: 128,
                value: *n5.data.get(idx).unwrap_or(&background),
            });
        }
    }
    Ok((leaves, tiles))
}

/// Index-space offset of child `idx` of an internal node with `log2dim` children per axis,
/// each spanning `1 << child_log2` voxels (OpenVDB order: x slowest).
fn child_offset(idx: usize, log2dim: u32, child_log2: u32) -> IVec3 {
    let n = 1usize << log2dim;
    let x = idx / (n * n);
    let y = (idx / n) % n;
    let z = idx % n;
    IVec3::new(x as i32, y as i32, z as i32) * (1 << child_log2)
}

fn convert_leaf(n3: &vdb_rs::Node3<f32>) -> Result<Leaf> {
    if n3.buffer.len() != BRICK_VOXELS || n3.value_mask.len() != BRICK_VOXELS {
        return Err(VolumeError::InvalidVdb(
            "leaf".into(),
            format!("leaf with {} values", n3.buffer.len()),
        ));
    }
    let mut values = Box::new([0.0f32; BRICK_VOXELS]);
    let mut mask = [0u64; 8];
    for (src, (&v, active)) in n3.buffer.iter().zip(n3.value_mask.iter()).enumerate() {
        // OpenVDB leaf order: offset = x * 64 + y * 8 + z.
        let (x, y, z) = (src / 64, (src / 8) % 8, src % 8);
        let dst = voxel_index(x, y, z);
        values[dst] = v;
        if *active {
            mask[dst / 64] |= 1 << (dst % 64);
        }
    }
    Ok(Leaf {
        origin: ivec(n3.origin),
        values,
        mask,
    })
}

/// Level sets: `vdb-rs` does not restore the ±background of inactive leaf voxels, so each
/// inactive voxel gets ±`bg` with the sign spread from its active neighbours.
fn fill_inactive_signs(leaf: &mut Leaf, bg: f32) {
    let mut sign = [0i8; BRICK_VOXELS];
    for (i, s) in sign.iter_mut().enumerate() {
        if leaf.is_active(i) {
            *s = if leaf.values[i] < 0.0 { -1 } else { 1 };
        } else if leaf.values[i] != 0.0 {
            *s = if leaf.values[i] < 0.0 { -1 } else { 1 };
            leaf.values[i] = bg * *s as f32;
        }
    }
    for _ in 0..3 * BRICK {
        let mut changed = false;
        for z in 0..BRICK {
            for y in 0..BRICK {
                for x in 0..BRICK {
                    let i = voxel_index(x, y, z);
                    if sign[i] != 0 {
                        continue;
                    }
                    let neighbours = [
                        (x > 0).then(|| voxel_index(x - 1, y, z)),
                        (x + 1 < BRICK).then(|| voxel_index(x + 1, y, z)),
                        (y > 0).then(|| voxel_index(x, y - 1, z)),
                        (y + 1 < BRICK).then(|| voxel_index(x, y + 1, z)),
                        (z > 0).then(|| voxel_index(x, y, z - 1)),
                        (z + 1 < BRICK).then(|| voxel_index(x, y, z + 1)),
                    ];
                    if let Some(j) = neighbours.into_iter().flatten().find(|&j| sign[j] != 0) {
                        sign[i] = sign[j];
                        changed = true;
                    }
                }
            }
        }
        if !changed {
            break;
        }
    }
    for (i, s) in sign.iter().enumerate() {
        if !leaf.is_active(i) {
            leaf.values[i] = bg * if *s < 0 { -1.0 } else { 1.0 };
        }
    }
}

/// A bounds-checked little-endian reader over the file header.
struct Header<'a> {
    cur: Cursor<&'a [u8]>,
    label: &'a str,
}

impl Header<'_> {
    fn err(&self, what: &str) -> VolumeError {
        VolumeError::InvalidVdb(
            self.label.into(),
            format!("{what} (at byte {})", self.cur.position()),
        )
    }

    fn bytes(&mut self, n: usize) -> Result<Vec<u8>> {
        let mut v = vec![0; n];
        self.cur
            .read_exact(&mut v)
            .map_err(|_| self.err("file ends inside the header"))?;
        Ok(v)
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.bytes(1)?[0])
    }

    fn u32(&mut self) -> Result<u32> {
        let b = self.bytes(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self) -> Result<u64> {
        let b = self.bytes(8)?;
        let mut a = [0; 8];
        a.copy_from_slice(&b);
        Ok(u64::from_le_bytes(a))
    }

    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(self.u64()?))
    }

    fn dvec3(&mut self) -> Result<DVec3> {
        Ok(DVec3::new(self.f64()?, self.f64()?, self.f64()?))
    }

    fn len(&mut self) -> Result<usize> {
        let n = self.u32()?;
        if n > MAX_FIELD {
            return Err(self.err("implausible length field"));
        }
        Ok(n as usize)
    }

    fn string(&mut self) -> Result<String> {
        let n = self.len()?;
        let b = self.bytes(n)?;
        String::from_utf8(b).map_err(|_| self.err("name is not UTF-8"))
    }

    fn seek(&mut self, pos: u64) -> Result<()> {
        if pos > self.cur.get_ref().len() as u64 {
            return Err(self.err(&format!("offset {pos} lies past the end of the file")));
        }
        self.cur
            .seek(SeekFrom::Start(pos))
            .map_err(|_| self.err("bad offset"))?;
        Ok(())
    }

    /// Metadata as (name, type, raw bytes).
    fn metadata(&mut self) -> Result<Vec<(String, String, Vec<u8>)>> {
        let count = self.u32()?;
        if count > 4096 {
            return Err(self.err("implausible metadata count"));
        }
        let mut out = Vec::new();
        let mut names = HashSet::new();
        for _ in 0..count {
            let name = self.string()?;
            let ty = self.string()?;
            let n = self.len()?;
            // `vdb-rs` reads these types by their size, not by the stored length.
            let size = match ty.as_str() {
                "bool" => Some(1),
                "int32" | "float" => Some(4),
                "int64" => Some(8),
                "vec3i" => Some(12),
                _ => None,
            };
            if size.is_some_and(|s| s != n) {
                return Err(self.err(&format!("metadata `{name}` of type {ty} has {n} bytes")));
            }
            if !names.insert(name.clone()) {
                return Err(self.err(&format!("metadata `{name}` appears twice")));
            }
            out.push((name, ty, self.bytes(n)?));
        }
        Ok(out)
    }

    fn parse(&mut self) -> Result<VdbInfo> {
        let magic = self.u64()?;
        if magic != 0x5644_4220 {
            return Err(self.err("wrong magic number"));
        }
        let file_version = self.u32()?;
        if !(MIN_VERSION..=MAX_VERSION).contains(&file_version) {
            return Err(VolumeError::InvalidVdb(
                self.label.into(),
                format!(
                    "file format version {file_version} not supported ({MIN_VERSION}..={MAX_VERSION})"
                ),
            ));
        }
        let _lib_major = self.u32()?;
        let _lib_minor = self.u32()?;
        if self.u8()? != 1 {
            return Err(self.err("file without grid offsets"));
        }
        let _uuid = self.bytes(36)?;
        self.metadata()?;
        let grid_count = self.u32()?;
        if grid_count == 0 || grid_count > 1024 {
            return Err(self.err(&format!("implausible grid count {grid_count}")));
        }
        let mut grids: Vec<GridInfo> = Vec::new();
        for _ in 0..grid_count {
            let name = self.string()?;
            let grid_type = self.string()?;
            let instance_parent = self.string()?;
            let grid_pos = self.u64()?;
            let block_pos = self.u64()?;
            let end_pos = self.u64()?;
            if !(grid_pos <= block_pos && block_pos <= end_pos) {
                return Err(self.err("grid offsets out of order"));
            }
            if grids.iter().any(|g| g.name == name) {
                return Err(self.err(&format!("two grids named `{name}`")));
            }
            self.seek(end_pos)?;
            self.seek(grid_pos)?;
            let compression = self.u32()?;
            let meta = self.metadata()?;
            let text = |key: &str| {
                meta.iter()
                    .find(|(n, t, _)| n == key && t == "string")
                    .map(|(_, _, b)| String::from_utf8_lossy(b).into_owned())
            };
            let class = text("class");
            let half_float = meta.iter().any(|(n, t, b)| {
                n == "is_saved_as_half_float" && t == "bool" && b.first().is_some_and(|&v| v != 0)
            });
            let active_voxels = meta
                .iter()
                .find(|(n, t, b)| n == "file_voxel_count" && t == "int64" && b.len() == 8)
                .map(|(_, _, b)| i64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8])));
            let transform_name = self.string()?;
            let transform = match transform_name.as_str() {
                "UniformScaleMap" => {
                    let scale = self.dvec3()?;
                    self.bytes(4 * 24)?;
                    Some(Transform {
                        scale,
                        translation: DVec3::ZERO,
                    })
                }
                "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
                    let translation = self.dvec3()?;
                    let scale = self.dvec3()?;
                    self.bytes(4 * 24)?;
                    Some(Transform { scale, translation })
                }
                _ => None,
            };
            if let Some(t) = &transform {
                let ok = |v: DVec3| v.is_finite();
                if !ok(t.scale) || !ok(t.translation) || t.scale.min_element() <= 0.0 {
                    return Err(self.err("degenerate transform"));
                }
            }
            let (background, layout) = if transform.is_some() && instance_parent.is_empty() {
                if self.u32()? != 1 {
                    return Err(self.err("multi-buffer trees are not supported"));
                }
                let background = f32::from_bits(self.u32()?);
                let layout = scan::TreeLayout {
                    topology: self.cur.position(),
                    blocks: block_pos,
                    compression,
                    half_float,
                };
                (background, Some(layout))
            } else {
                (0.0, None)
            };
            if !instance_parent.is_empty() {
                return Err(VolumeError::UnsupportedGrid(
                    self.label.into(),
                    format!("grid `{name}` is an instance of `{instance_parent}`"),
                ));
            }
            grids.push(GridInfo {
                name,
                grid_type,
                class,
                half_float,
                transform_name,
                transform,
                background,
                active_voxels,
                layout,
            });
            self.seek(end_pos)?;
        }
        Ok(VdbInfo {
            file_version,
            grids,
        })
    }
}
