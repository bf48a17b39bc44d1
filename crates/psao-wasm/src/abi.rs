//! The plain C ABI web/src/codec.ts calls (no wasm-bindgen): byte buffers the caller fills,
//! a viewer handle per session, status codes with error text, and pointers into wasm memory
//! for what the textures read. Lengths are in elements of the pointed-to type. Every function
//! taking a handle accepts a null one (it then does nothing and returns 0 / null).
//!
//! Status codes: 0 success, else [`ViewerError::code`].

use std::ptr;

use crate::table::table_of;
use crate::{Viewer, ViewerError};

/// A session: its viewer (or why the table was refused), the last error's text and room for
/// one transform handed out by [`psao_transform`].
pub struct Handle {
    viewer: Result<Viewer, ViewerError>,
    error: String,
    transform: [f32; 12],
}

/// A buffer of `len` zero bytes for the caller to fill; give it back with [`psao_free`].
#[no_mangle]
pub extern "C" fn psao_alloc(len: usize) -> *mut u8 {
    Box::into_raw(vec![0u8; len].into_boxed_slice()).cast()
}

/// Frees a buffer of [`psao_alloc`].
///
/// # Safety
/// `ptr` and `len` are those of one [`psao_alloc`] call not freed yet.
#[no_mangle]
pub unsafe extern "C" fn psao_free(ptr: *mut u8, len: usize) {
    drop(Box::from_raw(ptr::slice_from_raw_parts_mut(ptr, len)));
}

/// A session for the welcome's instance table: `len` bytes of little-endian f64s,
/// [`crate::table::TABLE_WORDS`] per instance. Check [`psao_table_status`].
///
/// # Safety
/// `table` points to `len` readable bytes.
#[no_mangle]
pub unsafe extern "C" fn psao_viewer_new(table: *const u8, len: usize) -> *mut Handle {
    let bytes = bytes_at(table, len);
    let words: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap_or_default()))
        .collect();
    let viewer = Viewer::new(&table_of(&words));
    let error = viewer.as_ref().err().map(ToString::to_string);
    Box::into_raw(Box::new(Handle {
        viewer,
        error: error.unwrap_or_default(),
        transform: [0.0; 12],
    }))
}

/// Frees a session.
///
/// # Safety
/// `handle` is null or from [`psao_viewer_new`], not freed yet.
#[no_mangle]
pub unsafe extern "C" fn psao_viewer_free(handle: *mut Handle) {
    if !handle.is_null() {
        drop(Box::from_raw(handle));
    }
}

/// 0 when the session's table was accepted, else the status code of why not (the text is
/// [`psao_error_ptr`]).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_table_status(handle: *const Handle) -> u32 {
    handle
        .as_ref()
        .map_or(0, |h| h.viewer.as_ref().err().map_or(0, ViewerError::code))
}

/// Decodes and applies one update payload (`snapshot`: 1 when its message was a snapshot);
/// returns the status code.
///
/// # Safety
/// `handle` is null or a live session; `payload` points to `len` readable bytes.
#[no_mangle]
pub unsafe extern "C" fn psao_apply(
    handle: *mut Handle,
    payload: *const u8,
    len: usize,
    snapshot: u32,
) -> u32 {
    let Some(h) = handle.as_mut() else {
        return 0;
    };
    let result = match &mut h.viewer {
        Ok(viewer) => viewer.apply(bytes_at(payload, len), snapshot != 0),
        Err(e) => Err(e.clone()),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            h.error = e.to_string();
            e.code()
        }
    }
}

/// The last error's text (UTF-8, [`psao_error_len`] bytes).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_error_ptr(handle: *const Handle) -> *const u8 {
    handle.as_ref().map_or(ptr::null(), |h| h.error.as_ptr())
}

/// Bytes of [`psao_error_ptr`]'s text.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_error_len(handle: *const Handle) -> usize {
    handle.as_ref().map_or(0, |h| h.error.len())
}

/// psao-client's state hash of the session's state (what the server sends to compare).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_state_hash(handle: *const Handle) -> u64 {
    viewer(handle).map_or(0, |v| v.state().state_hash())
}

/// 1 when the session's state holds irradiance records (the server computes lighting: its
/// frames are composited lit), else 0.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_has_lights(handle: *const Handle) -> u32 {
    viewer(handle).map_or(0, |v| u32::from(v.state().has_lights()))
}

/// The change records of the last applied update ([`crate::changes`]), [`psao_changes_len`]
/// u32 words, valid until the next call on this session.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_changes_ptr(handle: *const Handle) -> *const u32 {
    viewer(handle).map_or(ptr::null(), |v| v.changes().as_ptr())
}

/// Words of [`psao_changes_ptr`].
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_changes_len(handle: *const Handle) -> usize {
    viewer(handle).map_or(0, |v| v.changes().len())
}

/// Instances in the session's table.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_instance_count(handle: *const Handle) -> u32 {
    viewer(handle).map_or(0, |v| v.state().instance_count() as u32)
}

/// Hash buckets of `instance`'s grid (0 when it has none).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_bucket_count(handle: *const Handle, instance: u32) -> u32 {
    let grid = viewer(handle).and_then(|v| v.state().grid(instance as usize));
    grid.map_or(0, |g| g.bucket_count() as u32)
}

/// Cell slots `instance`'s layout addresses (0 when it has no grid).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_max_cells(handle: *const Handle, instance: u32) -> u32 {
    let grid = viewer(handle).and_then(|v| v.state().grid(instance as usize));
    grid.map_or(0, |g| g.layout().max_cells() as u32)
}

/// Cell slots `instance`'s grid has allocated (0 when it has none or no grid).
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_slot_count(handle: *const Handle, instance: u32) -> u32 {
    let grid = viewer(handle).and_then(|v| v.state().grid(instance as usize));
    grid.map_or(0, |g| g.slot_count() as u32)
}

/// Valid points over all grids.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_point_count(handle: *const Handle) -> u32 {
    viewer(handle).map_or(0, |v| v.state().point_count() as u32)
}

/// `instance`'s transform from the latest update carrying one, as 12 floats (the columns
/// x, y, z, then the translation), valid until the next call on this session; null when none.
///
/// # Safety
/// `handle` is null or a live session.
#[no_mangle]
pub unsafe extern "C" fn psao_transform(handle: *mut Handle, instance: u32) -> *const f32 {
    let Some(h) = handle.as_mut() else {
        return ptr::null();
    };
    let Some(t) = h
        .viewer
        .as_ref()
        .ok()
        .and_then(|v| v.state().transform(instance as usize))
    else {
        return ptr::null();
    };
    let m = t.matrix3;
    for (k, column) in [m.x_axis, m.y_axis, m.z_axis, t.translation]
        .iter()
        .enumerate()
    {
        h.transform[3 * k..3 * k + 3].copy_from_slice(&column.to_array());
    }
    h.transform.as_ptr()
}

/// The session's viewer, if its table was accepted.
unsafe fn viewer<'a>(handle: *const Handle) -> Option<&'a Viewer> {
    handle.as_ref()?.viewer.as_ref().ok()
}

/// `len` bytes at `ptr` (none when null or empty).
unsafe fn bytes_at<'a>(ptr: *const u8, len: usize) -> &'a [u8] {
    if ptr.is_null() || len == 0 {
        &[]
    } else {
        std::slice::from_raw_parts(ptr, len)
    }
}

#[cfg(test)]
mod tests {
    use psao_delta::{Codec, CompactCodec, InstanceDelta, Update};
    use psao_points::{Bucket, BucketEntry, Cell};

    use super::*;

    /// Copies `bytes` into a [`psao_alloc`] buffer.
    fn put(bytes: &[u8]) -> *mut u8 {
        let p = psao_alloc(bytes.len());
        unsafe { std::slice::from_raw_parts_mut(p, bytes.len()) }.copy_from_slice(bytes);
        p
    }

    fn error(h: *const Handle) -> String {
        unsafe {
            let bytes = std::slice::from_raw_parts(psao_error_ptr(h), psao_error_len(h));
            String::from_utf8(bytes.to_vec()).unwrap()
        }
    }

    #[test]
    fn a_session_through_the_c_abi() {
        // One instance: origin 0, cell 0.5, 4³ cells, 16 buckets.
        let words: [f64; 11] = [0.0, 0.0, 0.0, 0.5, 4.0, 4.0, 4.0, 0.1, 16.0, 0.1, 1.0];
        let table: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let info = table_of(&words);
        let mut cell = Cell::default();
        cell.points[0] = psao_points::pack::VALID_BIT | 5;
        let mut bucket = Bucket::default();
        bucket.entries[0] = BucketEntry { key: 4, slot: 0 };
        let update = Update {
            frame: 3,
            snapshot: true,
            transforms: vec![(0, glam::Affine3A::from_translation(glam::Vec3::Y))],
            instances: vec![InstanceDelta {
                instance: 0,
                buckets: vec![(info[0].layout.bucket_of(3) as u32, bucket)],
                cells: vec![(0, cell)],
                lights: Vec::new(),
            }],
        };
        let payload = CompactCodec::new().encode(&update);
        let mut reference = psao_client::ClientState::new(&info);
        reference.apply(&update).unwrap();
        unsafe {
            let t = put(&table);
            let h = psao_viewer_new(t, table.len());
            psao_free(t, table.len());
            assert_eq!(psao_table_status(h), 0);
            assert_eq!((psao_instance_count(h), psao_bucket_count(h, 0)), (1, 16));
            assert_eq!((psao_max_cells(h, 0), psao_bucket_count(h, 1)), (128, 0));
            assert!(psao_transform(h, 0).is_null());
            let p = put(&payload);
            assert_eq!(psao_apply(h, p, payload.len(), 0), 3, "snapshot flag");
            assert!(error(h).contains("snapshot flag"));
            assert_eq!(psao_apply(h, p, payload.len(), 1), 0);
            psao_free(p, payload.len());
            assert_eq!(psao_state_hash(h), reference.state_hash());
            assert_eq!(psao_point_count(h), 1);
            assert_eq!((psao_slot_count(h, 0), psao_slot_count(h, 1)), (1, 0));
            assert!(psao_changes_len(h) > 0);
            let translation = std::slice::from_raw_parts(psao_transform(h, 0), 12);
            assert_eq!(translation[9..], [0.0, 1.0, 0.0]);
            assert_eq!(psao_apply(h, ptr::null(), 0, 0), 2);
            assert!(error(h).starts_with("undecodable update"), "{}", error(h));
            psao_viewer_free(h);
        }
    }

    #[test]
    fn a_refused_table_reports_on_every_call() {
        let words = [
            0.0,
            0.0,
            0.0,
            0.5,
            4.0,
            4.0,
            4.0,
            0.1,
            f64::from(1u32 << 24),
            0.1,
            1.0,
        ];
        let table: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        unsafe {
            let h = psao_viewer_new(table.as_ptr(), table.len());
            assert_eq!(psao_table_status(h), 1);
            assert!(error(h).contains("hash buckets"));
            assert_eq!(psao_apply(h, ptr::null(), 0, 0), 1);
            assert_eq!((psao_state_hash(h), psao_changes_len(h)), (0, 0));
            psao_viewer_free(h);
            assert_eq!(psao_apply(ptr::null_mut(), ptr::null(), 0, 0), 0);
        }
    }
}
