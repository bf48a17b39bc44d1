//! Bounds-checked glTF accessor decoding (dense and sparse, every component type).
//!
//! The `gltf` crate's own readers slice buffers with unchecked arithmetic and silently
//! shorten truncated data, so accessors are decoded here with every offset, stride and
//! index validated against the loaded buffers.

use std::path::Path;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::{buffer, Accessor};

use crate::error::{SceneError, MAX_ELEMENTS};

/// Largest element count of an accessor without a buffer view (its data is all zeros
/// plus sparse values, so a tiny file could otherwise request gigabytes).
const MAX_UNBACKED: usize = 1 << 20;

/// The loaded buffers of one glTF file plus its path (for error messages).
pub(super) struct BufferData<'a> {
    /// The glTF file.
    pub path: &'a Path,
    /// One byte vector per glTF buffer, each at least as long as declared.
    pub buffers: &'a [Vec<u8>],
}

impl BufferData<'_> {
    /// Decodes `acc` as floats (normalised integers mapped to [0, 1] / [−1, 1]).
    /// Returns the flat component list; `dims` lists the accepted element types.
    pub fn floats(
        &self,
        acc: &Accessor,
        dims: &[Dimensions],
        what: &str,
    ) -> Result<Vec<f32>, SceneError> {
        self.check_dims(acc, dims, what)?;
        let convert = float_converter(acc.data_type(), acc.normalized());
        let values = self.decode(acc, what, convert)?;
        if values.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::non_finite(self.path, what));
        }
        Ok(values)
    }

    /// Decodes `acc` as unsigned integers (u8, u16 or u32 components only).
    pub fn uints(
        &self,
        acc: &Accessor,
        dims: &[Dimensions],
        what: &str,
    ) -> Result<Vec<u32>, SceneError> {
        self.check_dims(acc, dims, what)?;
        let convert: fn(&[u8]) -> u32 = match acc.data_type() {
            DataType::U8 => |b| u32::from(b[0]),
            DataType::U16 => |b| u32::from(u16::from_le_bytes([b[0], b[1]])),
            DataType::U32 => |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            other => {
                return Err(self.parse(format!(
                    "{what}: accessor {} has component type {other:?}, expected unsigned integers",
                    acc.index()
                )))
            }
        };
        self.decode(acc, what, convert)
    }

    fn parse(&self, message: String) -> SceneError {
        SceneError::parse(self.path, "glTF", message)
    }

    fn check_dims(
        &self,
        acc: &Accessor,
        dims: &[Dimensions],
        what: &str,
    ) -> Result<(), SceneError> {
        if dims.contains(&acc.dimensions()) {
            Ok(())
        } else {
            Err(self.parse(format!(
                "{what}: accessor {} has type {:?}, expected one of {dims:?}",
                acc.index(),
                acc.dimensions()
            )))
        }
    }

    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(&self, view: &buffer::View, what: &str) -> Result<&[u8], SceneError> {
        let b = view.buffer().index();
        let data = self
            .buffers
            .get(b)
            .ok_or_else(|| SceneError::index(self.path, "buffer", b, self.buffers.len()))?;
        let start = view.offset();
        let end = start.checked_add(view.length());
        end.and_then(|end| data.get(start..end))
            .ok_or_else(|| SceneError::MissingBuffer {
                path: self.path.to_path_buf(),
                message: format!(
                "{what}: buffer view {} (offset {start}, length {}) exceeds buffer {b} ({} bytes)",
                view.index(),
                view.length(),
                data.len()
            ),
            })
    }

    /// Checks that `count` elements of `elem` bytes at `offset` with `stride` fit in `bytes`.
    fn check_fits(
        &self,
        bytes: &[u8],
        (offset, stride, elem, count): (usize, usize, usize, usize),
        what: &str,
    ) -> Result<(), SceneError> {
        if count == 0 {
            return Ok(());
        }
        let need = stride
            .checked_mul(count - 1)
            .and_then(|n| n.checked_add(elem))
            .and_then(|n| n.checked_add(offset));
        match need {
            Some(need) if need <= bytes.len() => Ok(()),
            _ => Err(SceneError::MissingBuffer {
                path: self.path.to_path_buf(),
                message: format!(
                    "{what}: {count} elements of {elem} bytes (stride {stride}, offset {offset}) \
                     do not fit in a buffer view of {} bytes",
                    bytes.len()
                ),
            }),
        }
    }

    fn check_count(&self, count: usize, what: &str) -> Result<(), SceneError> {
        if count > MAX_ELEMENTS {
            return Err(SceneError::too_large(
                self.path,
                format!("{what} element count"),
                count as u64,
                MAX_ELEMENTS as u64,
            ));
        }
        Ok(())
    }

    /// Decodes every component of `acc` with `convert` (applied to each component's bytes).
    fn decode<T: Copy + Default>(
        &self,
        acc: &Accessor,
        what: &str,
        convert: fn(&[u8]) -> T,
    ) -> Result<Vec<T>, SceneError> {
        let comps = acc.dimensions().multiplicity();
        let size = acc.data_type().size();
        let count = acc.count();
        self.check_count(count, what)?;
        if matches!(acc.dimensions(), Dimensions::Mat2 | Dimensions::Mat3) && size < 4 {
            return Err(SceneError::unsupported(
                self.path,
                format!("{what}: padded matrix accessor {}", acc.index()),
            ));
        }
        let elem = comps * size;
        let mut out = match acc.view() {
            None if count > MAX_UNBACKED => {
                return Err(SceneError::too_large(
                    self.path,
                    format!("{what}: accessor {} without buffer view", acc.index()),
                    count as u64,
                    MAX_UNBACKED as u64,
                ))
            }
            None => vec![T::default(); count * comps],
            Some(view) => {
                let bytes = self.view_bytes(&view, what)?;
                let stride = view.stride().unwrap_or(elem);
                if stride < elem {
                    return Err(self.parse(format!(
                        "{what}: buffer view {} stride {stride} is smaller than the element ({elem} bytes)",
                        view.index()
                    )));
                }
                let offset = acc.offset();
                self.check_fits(bytes, (offset, stride, elem, count), what)?;
                let mut out = Vec::with_capacity(count * comps);
                for i in 0..count {
                    let start = offset + i * stride;
                    out.extend(bytes[start..start + elem].chunks_exact(size).map(convert));
                }
                out
            }
        };
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            self.check_count(n, what)?;
            let idx = sparse.indices();
            let idx_bytes = self.view_bytes(&idx.view(), what)?;
            let idx_size = idx.index_type().size();
            self.check_fits(idx_bytes, (idx.offset(), idx_size, idx_size, n), what)?;
            let vals = sparse.values();
            let val_bytes = self.view_bytes(&vals.view(), what)?;
            self.check_fits(val_bytes, (vals.offset(), elem, elem, n), what)?;
            for k in 0..n {
                let at = idx.offset() + k * idx_size;
                let target = read_uint(&idx_bytes[at..at + idx_size]);
                if target >= count {
                    return Err(SceneError::index(
                        self.path,
                        format!("{what}: sparse target"),
                        target,
                        count,
                    ));
                }
                let src = vals.offset() + k * elem;
                let decoded = val_bytes[src..src + elem].chunks_exact(size).map(convert);
                for (dst, v) in out[target * comps..(target + 1) * comps]
                    .iter_mut()
                    .zip(decoded)
                {
                    *dst = v;
                }
            }
        }
        Ok(out)
    }
}

/// Little-endian unsigned integer of 1, 2 or 4 bytes.
fn read_uint(b: &[u8]) -> usize {
    b.iter()
        .rev()
        .fold(0usize, |acc, &x| (acc << 8) | usize::from(x))
}

/// Component decoder to f32 per glTF's normalisation rules.
fn float_converter(ty: DataType, normalized: bool) -> fn(&[u8]) -> f32 {
    match (ty, normalized) {
        (DataType::F32, _) => |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        (DataType::I8, false) => |b| f32::from(b[0] as i8),
        (DataType::I8, true) => |b| (f32::from(b[0] as i8) / 127.0).max(-1.0),
        (DataType::U8, false) => |b| f32::from(b[0]),
        (DataType::U8, true) => |b| f32::from(b[0]) / 255.0,
        (DataType::I16, false) => |b| f32::from(i16::from_le_bytes([b[0], b[1]])),
        (DataType::I16, true) => {
            |b| (f32::from(i16::from_le_bytes([b[0], b[1]])) / 32767.0).max(-1.0)
        }
        (DataType::U16, false) => |b| f32::from(u16::from_le_bytes([b[0], b[1]])),
        (DataType::U16, true) => |b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
        (DataType::U32, false) => |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        (DataType::U32, true) => {
            |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32 / u32::MAX as f32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_components_map_to_unit_range() {
        assert_eq!(float_converter(DataType::U8, true)(&[255]), 1.0);
        assert_eq!(float_converter(DataType::I8, true)(&[0x80]), -1.0);
        assert_eq!(
            float_converter(DataType::I16, true)(&0x7fffi16.to_le_bytes()),
            1.0
        );
        assert_eq!(
            float_converter(DataType::U16, false)(&300u16.to_le_bytes()),
            300.0
        );
        assert_eq!(read_uint(&[0x34, 0x12]), 0x1234);
        assert_eq!(read_uint(&[1, 0, 0, 1]), 0x0100_0001);
    }
}
