//! The plain C ABI of [`crate::relit`] that web/src/relit.ts calls: a handle per served
//! scene, filled node by node, mesh by mesh, … from `/scene.glb`, then finished, given each
//! character's model, and relit frame by frame. Arrays are passed as little-endian bytes
//! (pointer and length in bytes, so that no alignment is assumed); the values of a frame are
//! read in place from wasm memory (4 f32 per mesh vertex). Every function accepts a null
//! handle (it then does nothing and returns 0 / null). Status codes: 0 success, else
//! [`RelitError::code`], or 3 for arguments the ABI itself refuses (lengths that do not fit).

use std::ptr;

use glam::{Affine3A, Mat4, Quat, Vec3};

use crate::relit::{channel, MeshData, RelitError, RelitScene};

/// Status of arguments the ABI refuses.
const BAD_ARGUMENTS: u32 = 3;

/// A served scene's relit characters and the last error's text.
#[derive(Default)]
pub struct RelitHandle {
    scene: RelitScene,
    error: String,
}

impl RelitHandle {
    fn status(&mut self, result: Result<(), RelitError>) -> u32 {
        match result {
            Ok(()) => 0,
            Err(e) => {
                self.error = e.to_string();
                e.code()
            }
        }
    }

    fn refuse(&mut self, what: &str) -> u32 {
        self.error = format!("relit: {what}");
        BAD_ARGUMENTS
    }
}

/// An empty scene.
#[no_mangle]
pub extern "C" fn psao_relit_new() -> *mut RelitHandle {
    Box::into_raw(Box::default())
}

/// Frees a scene.
///
/// # Safety
/// `handle` is null or from [`psao_relit_new`], not freed yet.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_free(handle: *mut RelitHandle) {
    if !handle.is_null() {
        drop(Box::from_raw(handle));
    }
}

/// Adds a node: `parent` (−1 for none) and its rest translation, rotation (x, y, z, w) and
/// scale, 10 f32 at `trs` (40 bytes).
///
/// # Safety
/// `handle` is null or live; `trs` points to 40 readable bytes.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_node(handle: *mut RelitHandle, parent: i32, trs: *const u8) {
    let Some(h) = handle.as_mut() else { return };
    let f = floats(trs, 40);
    if f.len() != 10 {
        return;
    }
    h.scene.push_node(
        usize::try_from(parent).ok(),
        Vec3::new(f[0], f[1], f[2]),
        Quat::from_xyzw(f[3], f[4], f[5], f[6]),
        Vec3::new(f[7], f[8], f[9]),
    );
}

/// Adds a mesh of `vertices` vertices: positions and normals (3 f32 each), `indices_len`
/// bytes of u32 triangle indices, and for skinned meshes (else null) 4 u16 joints and 4 f32
/// weights per vertex. Returns the status.
///
/// # Safety
/// `handle` is null or live; every non-null pointer points to the bytes its array needs.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn psao_relit_mesh(
    handle: *mut RelitHandle,
    vertices: usize,
    positions: *const u8,
    normals: *const u8,
    indices: *const u8,
    indices_len: usize,
    joints: *const u8,
    weights: *const u8,
) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let Some(bytes3) = vertices.checked_mul(12) else {
        return h.refuse("too many vertices");
    };
    let vec3s = |p| {
        floats(p, bytes3)
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect()
    };
    let index_words: Vec<u32> = bytes_at(indices, indices_len)
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let mut mesh = MeshData {
        positions: vec3s(positions),
        normals: vec3s(normals),
        indices: index_words
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
        ..MeshData::default()
    };
    if !joints.is_null() && !weights.is_null() {
        let Some(bytes8) = vertices.checked_mul(8) else {
            return h.refuse("too many vertices");
        };
        mesh.joints = bytes_at(joints, bytes8)
            .chunks_exact(8)
            .map(|b| std::array::from_fn(|k| u16::from_le_bytes([b[2 * k], b[2 * k + 1]])))
            .collect();
        mesh.weights = floats(weights, bytes3 / 3 * 4)
            .chunks_exact(4)
            .map(|w| [w[0], w[1], w[2], w[3]])
            .collect();
    }
    let result = h.scene.push_mesh(mesh);
    h.status(result)
}

/// Adds a skin: `count` joint node indices (u32) and, unless null, as many inverse bind
/// matrices (16 f32 each, column-major).
///
/// # Safety
/// `handle` is null or live; the pointers point to the bytes their arrays need.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_skin(
    handle: *mut RelitHandle,
    count: usize,
    joints: *const u8,
    inverse_bind: *const u8,
) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let (Some(jb), Some(mb)) = (count.checked_mul(4), count.checked_mul(64)) else {
        return h.refuse("too many joints");
    };
    let joints = bytes_at(joints, jb)
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .collect();
    let inverse_bind = if inverse_bind.is_null() {
        vec![Mat4::IDENTITY; count]
    } else {
        floats(inverse_bind, mb)
            .chunks_exact(16)
            .map(Mat4::from_cols_slice)
            .collect()
    };
    h.scene.push_skin(joints, inverse_bind);
    0
}

/// Adds an instance: its mesh, node and skin (−1 for none) and rest matrix (16 f32,
/// column-major; its last row is taken as 0 0 0 1).
///
/// # Safety
/// `handle` is null or live; `matrix` points to 64 readable bytes.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_instance(
    handle: *mut RelitHandle,
    mesh: u32,
    node: i32,
    skin: i32,
    matrix: *const u8,
) {
    let Some(h) = handle.as_mut() else { return };
    let m = floats(matrix, 64);
    if m.len() != 16 {
        return;
    }
    let transform = Affine3A::from_mat4(Mat4::from_cols_slice(&m));
    h.scene.push_instance(
        mesh as usize,
        usize::try_from(node).ok(),
        usize::try_from(skin).ok(),
        transform,
    );
}

/// Adds a channel to clip `clip`: `property` 0 translation, 1 rotation, 2 scale;
/// `interpolation` 0 step, 1 linear, 2 cubic spline; `times_len` and `values_len` bytes of
/// f32. Returns the status.
///
/// # Safety
/// `handle` is null or live; the pointers point to their lengths' readable bytes.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn psao_relit_channel(
    handle: *mut RelitHandle,
    clip: u32,
    node: u32,
    property: u32,
    interpolation: u32,
    times: *const u8,
    times_len: usize,
    values: *const u8,
    values_len: usize,
) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    match channel(
        node as usize,
        property,
        interpolation,
        floats(times, times_len),
        floats(values, values_len),
    ) {
        Some(c) => {
            let result = h.scene.push_channel(clip as usize, c);
            h.status(result)
        }
        None => h.refuse("unknown channel property or interpolation"),
    }
}

/// Plays clip `clip`; returns the status.
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_play(handle: *mut RelitHandle, clip: u32) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let result = h.scene.play(clip as usize);
    h.status(result)
}

/// Checks the scene and prepares its playback; returns the status. [`psao_relit_count`]
/// then gives its characters.
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_finish(handle: *mut RelitHandle) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let result = h.scene.finish().map(|_| ());
    h.status(result)
}

/// Relights character `index` with its model file (`model_len` bytes) and the served
/// lighting (`lighting_len` bytes of f32, 16 per colour channel); returns the status.
///
/// # Safety
/// `handle` is null or live; the pointers point to their lengths' readable bytes.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_character(
    handle: *mut RelitHandle,
    index: u32,
    model: *const u8,
    model_len: usize,
    lighting: *const u8,
    lighting_len: usize,
) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let lighting = floats(lighting, lighting_len);
    let result = h
        .scene
        .insert(index, bytes_at(model, model_len), &lighting)
        .map(|_| ());
    h.status(result)
}

/// Relights every character at scene time `time` seen from the eye (`ex`, `ey`, `ez`):
/// `transforms` holds `count` × 12 f32 (instance i's Affine3A: columns x, y, z, then the
/// translation), `given` `count` bytes (1 where instance i's transform is given, i.e. came
/// with a server update). Returns the status.
///
/// # Safety
/// `handle` is null or live; `transforms` points to `count` × 48 and `given` to `count`
/// readable bytes.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn psao_relit_frame(
    handle: *mut RelitHandle,
    time: f32,
    count: usize,
    transforms: *const u8,
    given: *const u8,
    ex: f32,
    ey: f32,
    ez: f32,
) -> u32 {
    let Some(h) = handle.as_mut() else { return 0 };
    let Some(bytes) = count.checked_mul(48) else {
        return h.refuse("too many instances");
    };
    let t = floats(transforms, bytes);
    let given = bytes_at(given, count);
    let transforms: Vec<Option<Affine3A>> = t
        .chunks_exact(12)
        .zip(given)
        .map(|(m, &g)| (g != 0).then(|| Affine3A::from_cols_slice(m)))
        .collect();
    let result = h.scene.relight(time, &transforms, Vec3::new(ex, ey, ez));
    h.status(result)
}

/// Instance `instance`'s values of the last frame: 4 f32 per mesh vertex (self-shadowing
/// per colour channel, then self-visibility), [`psao_relit_values_len`] floats, valid until
/// the next call on this scene; null when the instance is not relit.
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_values_ptr(
    handle: *const RelitHandle,
    instance: u32,
) -> *const f32 {
    handle
        .as_ref()
        .and_then(|h| h.scene.values(instance as usize))
        .map_or(ptr::null(), |v| v.as_ptr().cast())
}

/// Floats of [`psao_relit_values_ptr`].
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_values_len(handle: *const RelitHandle, instance: u32) -> usize {
    handle
        .as_ref()
        .and_then(|h| h.scene.values(instance as usize))
        .map_or(0, |v| v.len() * 4)
}

/// The scene's characters (skinned node groups), once finished.
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_count(handle: *const RelitHandle) -> u32 {
    handle
        .as_ref()
        .map_or(0, |h| h.scene.character_count() as u32)
}

/// Vertices relit per frame (over every character given a model).
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_vertices(handle: *const RelitHandle) -> u32 {
    handle.as_ref().map_or(0, |h| h.scene.vertex_count() as u32)
}

/// The last error's text (UTF-8, [`psao_relit_error_len`] bytes).
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_error_ptr(handle: *const RelitHandle) -> *const u8 {
    handle.as_ref().map_or(ptr::null(), |h| h.error.as_ptr())
}

/// Bytes of [`psao_relit_error_ptr`]'s text.
///
/// # Safety
/// `handle` is null or live.
#[no_mangle]
pub unsafe extern "C" fn psao_relit_error_len(handle: *const RelitHandle) -> usize {
    handle.as_ref().map_or(0, |h| h.error.len())
}

/// `len` bytes at `ptr` (none when null or empty).
unsafe fn bytes_at<'a>(ptr: *const u8, len: usize) -> &'a [u8] {
    if ptr.is_null() || len == 0 {
        &[]
    } else {
        std::slice::from_raw_parts(ptr, len)
    }
}

/// The little-endian f32s of `len` bytes at `ptr` (a trailing partial float is dropped).
unsafe fn floats(ptr: *const u8, len: usize) -> Vec<f32> {
    bytes_at(ptr, len)
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

#[cfg(test)]
mod tests {
    use psao_prt::model::PoseModel;
    use psao_prt::model_file;

    use super::*;

    fn le(floats: &[f32]) -> Vec<u8> {
        floats.iter().flat_map(|f| f.to_le_bytes()).collect()
    }

    fn words(words: &[u32]) -> Vec<u8> {
        words.iter().flat_map(|w| w.to_le_bytes()).collect()
    }

    fn error(h: *const RelitHandle) -> String {
        unsafe {
            let bytes =
                std::slice::from_raw_parts(psao_relit_error_ptr(h), psao_relit_error_len(h));
            String::from_utf8(bytes.to_vec()).unwrap()
        }
    }

    #[test]
    fn a_relit_scene_through_the_c_abi() {
        let identity = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let positions = le(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let normals = le(&[0.0, 0.0, 1.0].repeat(3));
        let indices = words(&[0, 1, 2]);
        let joints: Vec<u8> = [0u16; 12].iter().flat_map(|j| j.to_le_bytes()).collect();
        let weights = le(&[1.0, 0.0, 0.0, 0.0].repeat(3));
        let matrix = le(&Mat4::IDENTITY.to_cols_array());
        let model = model_file::to_bytes(&PoseModel {
            character: "triangle".into(),
            vertices: 3,
            joints: 1,
            lobes: 1,
            active: vec![0],
            // The constant row (one open lobe per vertex), then three rows of zeros.
            weights: [
                [0.0, 0.0, 1.0, 3.5, 0.0, 0.0, 0.0].repeat(3),
                vec![0.0; 3 * 3 * 7],
            ]
            .concat(),
            limits: Default::default(),
        });
        let lighting = le(&[[1.0; 16], [1.0; 16], [1.0; 16]].concat());
        unsafe {
            let h = psao_relit_new();
            psao_relit_node(h, -1, le(&identity).as_ptr());
            let status = psao_relit_mesh(
                h,
                3,
                positions.as_ptr(),
                normals.as_ptr(),
                indices.as_ptr(),
                indices.len(),
                joints.as_ptr(),
                weights.as_ptr(),
            );
            assert_eq!(status, 0, "{}", error(h));
            assert_eq!(psao_relit_skin(h, 1, words(&[0]).as_ptr(), ptr::null()), 0);
            psao_relit_instance(h, 0, 0, 0, matrix.as_ptr());
            assert_eq!(psao_relit_play(h, 0), 0);
            // Relighting before the scene is finished is refused.
            let none = psao_relit_character(
                h,
                0,
                model.as_ptr(),
                model.len(),
                lighting.as_ptr(),
                lighting.len(),
            );
            assert_eq!(none, 1, "{}", error(h));
            assert_eq!(psao_relit_finish(h), 0, "{}", error(h));
            assert_eq!(psao_relit_count(h), 1);
            let status = psao_relit_character(
                h,
                0,
                model.as_ptr(),
                model.len(),
                lighting.as_ptr(),
                lighting.len(),
            );
            assert_eq!(status, 0, "{}", error(h));
            assert_eq!(psao_relit_vertices(h), 3);
            let transform = le(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0]);
            assert_eq!(
                psao_relit_frame(h, 0.1, 1, transform.as_ptr(), [1u8].as_ptr(), 0.0, 0.0, 5.0),
                0
            );
            assert_eq!(psao_relit_values_len(h, 0), 12);
            let values = std::slice::from_raw_parts(psao_relit_values_ptr(h, 0), 12);
            assert!(values.iter().all(|v| (0.0..=1.0).contains(v)), "{values:?}");
            assert!(psao_relit_values_ptr(h, 1).is_null());
            // A model of another character, and a malformed one.
            let junk = b"not a model";
            assert_eq!(
                psao_relit_character(
                    h,
                    0,
                    junk.as_ptr(),
                    junk.len(),
                    lighting.as_ptr(),
                    lighting.len()
                ),
                2
            );
            assert!(error(h).starts_with("relit character 0"), "{}", error(h));
            assert_eq!(
                psao_relit_character(
                    h,
                    1,
                    model.as_ptr(),
                    model.len(),
                    lighting.as_ptr(),
                    lighting.len()
                ),
                2
            );
            // Unknown channel kinds are refused by the ABI.
            let status = psao_relit_channel(h, 0, 0, 9, 1, ptr::null(), 0, ptr::null(), 0);
            assert_eq!(status, BAD_ARGUMENTS);
            psao_relit_free(h);
            assert_eq!(psao_relit_finish(ptr::null_mut()), 0);
        }
    }
}
