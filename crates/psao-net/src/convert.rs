//! Conversions between wire messages and the algorithm types.

use glam::{UVec3, Vec3};
use psao_delta::{Codec, GridLayout, InstanceInfo};
use psao_scene::Camera;
use psao_server::View;
use psao_wire::{CameraMsg, InstanceEntry};

use crate::NetError;

use psao_delta::decode_limit;
pub use psao_delta::MAX_TOTAL_BUCKETS;

/// The wire form of an instance-table entry.
pub fn entry_of(info: &InstanceInfo) -> InstanceEntry {
    let l = &info.layout;
    InstanceEntry {
        origin: l.origin.to_array(),
        cell_size: l.cell_size,
        dims: l.dims.to_array(),
        layout_poisson_radius: l.poisson_radius,
        bucket_count: l.bucket_count,
        poisson_radius: info.poisson_radius,
        point_count: info.point_count,
    }
}

/// The instance table of a welcome, refused when its grids would take more than
/// [`MAX_TOTAL_BUCKETS`] buckets.
pub fn table_of(entries: &[InstanceEntry]) -> Result<Vec<InstanceInfo>, NetError> {
    let buckets: u64 = entries.iter().map(|e| u64::from(e.bucket_count)).sum();
    if buckets > MAX_TOTAL_BUCKETS {
        return Err(NetError::Protocol(format!(
            "the instance table asks for {buckets} hash buckets (limit {MAX_TOTAL_BUCKETS})"
        )));
    }
    Ok(entries
        .iter()
        .map(|e| InstanceInfo {
            layout: GridLayout {
                origin: Vec3::from_array(e.origin),
                cell_size: e.cell_size,
                dims: UVec3::from_array(e.dims),
                poisson_radius: e.layout_poisson_radius,
                bucket_count: e.bucket_count,
            },
            poisson_radius: e.poisson_radius,
            point_count: e.point_count,
        })
        .collect())
}

/// A client's decoder for codec `name`, limited to what updates for `table` can take
/// ([`decode_limit`]).
pub fn client_decoder(name: &str, table: &[InstanceInfo]) -> Result<Box<dyn Codec>, NetError> {
    let mut codec =
        psao_delta::codec_by_name(name).map_err(NetError::codec("the server's codec"))?;
    let limit = decode_limit(table);
    tracing::debug!(
        "decode limit {:.1} MiB for {} instances",
        limit as f64 / f64::from(1 << 20),
        table.len()
    );
    codec.set_decode_limit(limit);
    Ok(codec)
}

/// The camera message of client frame `frame`.
pub fn camera_msg(frame: u32, camera: &Camera, aspect: f32) -> CameraMsg {
    CameraMsg {
        frame,
        position: camera.position.to_array(),
        target: camera.target.to_array(),
        up: camera.up.to_array(),
        fov_y: camera.fov_y,
        near: camera.near,
        far: camera.far,
        aspect,
    }
}

/// The server's view from a (validated) camera message.
pub fn view_of(msg: &CameraMsg) -> View {
    View {
        camera: Camera {
            position: Vec3::from_array(msg.position),
            target: Vec3::from_array(msg.target),
            up: Vec3::from_array(msg.up),
            fov_y: msg.fov_y,
            near: msg.near,
            far: msg.far,
        },
        aspect: msg.aspect,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_accepted_table_gets_its_whole_decode_limit() {
        let entry = |bucket_count: u32| InstanceEntry {
            origin: [0.0; 3],
            cell_size: 0.1,
            dims: [64; 3],
            layout_poisson_radius: 0.025,
            bucket_count,
            poisson_radius: 0.025,
            point_count: 0,
        };
        let largest = table_of(&[entry(1 << 22), entry(1 << 22)]).unwrap();
        let limit = decode_limit(&largest);
        assert!(limit > psao_delta::MAX_DECODED_BYTES, "{limit}");
        assert!(limit <= psao_delta::MAX_DECODE_LIMIT, "{limit}");
        assert!(table_of(&[entry(1 << 22), entry((1 << 22) + 1)]).is_err());
    }
}
