//! Reading accessor data out of the loaded buffers, every byte range checked
//! before it is read.
//!
//! The `gltf` crate's own readers answer `None` both for a missing attribute and
//! for data that runs past its buffer, and debug-assert (panic) when an
//! accessor's element size does not match the type asked for. Reading here
//! checks the element type, count, stride and byte ranges (also of sparse
//! substitutions) and returns an error naming the file, the accessor and what
//! it was read for.

use std::ops::Range;
use std::path::Path;

use ::gltf::accessor::{Accessor, DataType, Dimensions};
use ::gltf::buffer::View;
use glam::Vec3;
use shadow_core::{Error, Result};

/// The binary payloads of one glTF document.
pub(super) struct Buffers<'a> {
    pub path: &'a Path,
    /// Indexed like the document's `buffers`.
    pub data: &'a [Vec<u8>],
    /// Indexed like its `bufferViews`: the decoded bytes of views stored
    /// compressed (`EXT_meshopt_compression`), `None` for plain ones.
    pub decoded: &'a [Option<Vec<u8>>],
    /// The file uses `KHR_mesh_quantization`: float attributes may be stored
    /// as integers that are not normalized, read as their values.
    pub quantized: bool,
}

impl Buffers<'_> {
    fn error(&self, accessor: &Accessor, what: &str, problem: String) -> Error {
        Error::format(
            self.path,
            format!("accessor {} ({what}): {problem}", accessor.index()),
        )
    }

    /// The bytes of a buffer view, decoded if it is stored compressed, else
    /// checked to lie inside its buffer.
    fn view_bytes(&self, accessor: &Accessor, what: &str, view: &View) -> Result<&[u8]> {
        if let Some(Some(decoded)) = self.decoded.get(view.index()) {
            return Ok(&decoded[..view.length()]);
        }
        let buffer = view.buffer().index();
        let data = self
            .data
            .get(buffer)
            .ok_or_else(|| self.error(accessor, what, format!("buffer {buffer} is not loaded")))?;
        view.offset()
            .checked_add(view.length())
            .and_then(|end| data.get(view.offset()..end))
            .ok_or_else(|| {
                self.error(
                    accessor,
                    what,
                    format!(
                        "buffer view {} spans bytes {}..{} of buffer {buffer}, which has {} bytes",
                        view.index(),
                        view.offset(),
                        view.offset().saturating_add(view.length()),
                        data.len()
                    ),
                )
            })
    }

    /// Reads every component of `accessor` as `f32`: 32-bit floats as they are,
    /// normalized integers mapped to [0, 1] or [-1, 1] as glTF 2.0 §3.11
    /// prescribes (`max(c / 127, -1)` for signed bytes, `c / 255` for unsigned
    /// bytes, likewise for shorts), and, in a file that uses
    /// `KHR_mesh_quantization`, integers that are not normalized as their
    /// values (the node transforms scale them back to metres). Components
    /// come element by element.
    pub fn floats(&self, accessor: &Accessor, what: &str, dims: Dimensions) -> Result<Vec<f32>> {
        let convert: fn(&[u8]) -> f32 = match (accessor.data_type(), accessor.normalized()) {
            (DataType::F32, _) => |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            (DataType::I8, true) => |b| (b[0] as i8 as f32 / 127.0).max(-1.0),
            (DataType::U8, true) => |b| b[0] as f32 / 255.0,
            (DataType::I16, true) => {
                |b| (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0)
            }
            (DataType::U16, true) => |b| u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
            (DataType::I8, false) if self.quantized => |b| b[0] as i8 as f32,
            (DataType::U8, false) if self.quantized => |b| b[0] as f32,
            (DataType::I16, false) if self.quantized => |b| i16::from_le_bytes([b[0], b[1]]) as f32,
            (DataType::U16, false) if self.quantized => |b| u16::from_le_bytes([b[0], b[1]]) as f32,
            (other, normalized) => {
                return Err(self.error(
                    accessor,
                    what,
                    format!(
                        "component type {other:?} (normalized: {normalized}) is not a float type \
                         (integers that are not normalized need KHR_mesh_quantization)"
                    ),
                ));
            }
        };
        let values = self.read(accessor, what, dims, 0.0, convert)?;
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.error(
                accessor,
                what,
                format!(
                    "element {} has a non-finite component",
                    i / dims.multiplicity()
                ),
            ));
        }
        Ok(values)
    }

    /// Reads every component of `accessor` as an unsigned integer (indices,
    /// joint numbers): unsigned, not normalized.
    pub fn uints(&self, accessor: &Accessor, what: &str, dims: Dimensions) -> Result<Vec<u32>> {
        let convert: fn(&[u8]) -> u32 = match (accessor.data_type(), accessor.normalized()) {
            (DataType::U8, false) => |b| b[0] as u32,
            (DataType::U16, false) => |b| u16::from_le_bytes([b[0], b[1]]) as u32,
            (DataType::U32, false) => |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            (other, normalized) => {
                return Err(self.error(
                    accessor,
                    what,
                    format!(
                        "component type {other:?} (normalized: {normalized}) is not an unsigned integer type"
                    ),
                ));
            }
        };
        self.read(accessor, what, dims, 0, convert)
    }

    /// A VEC3 float accessor as vectors.
    pub fn vec3s(&self, accessor: &Accessor, what: &str) -> Result<Vec<Vec3>> {
        Ok(self
            .floats(accessor, what, Dimensions::Vec3)?
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect())
    }

    /// The checked read: dense data from the buffer view (or zeros when the
    /// accessor has none, glTF 2.0 §3.6.2.4), then sparse substitutions.
    fn read<T: Copy>(
        &self,
        accessor: &Accessor,
        what: &str,
        dims: Dimensions,
        zero: T,
        convert: fn(&[u8]) -> T,
    ) -> Result<Vec<T>> {
        let bad = |problem: String| self.error(accessor, what, problem);
        if accessor.dimensions() != dims {
            return Err(bad(format!(
                "is {:?}, expected {dims:?}",
                accessor.dimensions()
            )));
        }
        let component = accessor.data_type().size();
        let n = dims.multiplicity();
        if matches!(dims, Dimensions::Mat2 | Dimensions::Mat3) && component < 4 {
            // Such matrices carry column padding; nothing read here uses them.
            return Err(bad(format!(
                "padded {dims:?} of {:?} is not supported",
                accessor.data_type()
            )));
        }
        let element = n * component;
        let count = accessor.count();
        if count == 0 {
            return Err(bad("count is 0".into()));
        }
        let components_of = |bytes: &[u8], out: &mut Vec<T>| {
            out.extend(bytes.chunks_exact(component).map(convert));
        };

        let mut values = match accessor.view() {
            Some(view) => {
                let bytes = self.view_bytes(accessor, what, &view)?;
                let stride = view.stride().unwrap_or(element);
                if stride < element {
                    return Err(bad(format!(
                        "buffer view {} has stride {stride}, below the element size {element}",
                        view.index()
                    )));
                }
                let range = span(accessor.offset(), stride, count, element)
                    .ok_or_else(|| bad(format!("{count} elements overflow the address space")))?;
                let bytes = bytes.get(range.clone()).ok_or_else(|| {
                    bad(format!(
                        "{count} elements need bytes {}..{} of buffer view {}, which has {} bytes",
                        range.start,
                        range.end,
                        view.index(),
                        bytes.len()
                    ))
                })?;
                let mut out = Vec::with_capacity(count * n);
                for i in 0..count {
                    components_of(&bytes[i * stride..i * stride + element], &mut out);
                }
                out
            }
            None => {
                // Zero-filled data larger than the file's whole binary payload is
                // a corrupt count, not a model: refuse it rather than allocate.
                let payload: usize = self.data.iter().map(Vec::len).sum();
                if count > payload {
                    return Err(bad(format!(
                        "has no buffer view and a count of {count}, more than the {payload} bytes of binary data"
                    )));
                }
                vec![zero; count * n]
            }
        };

        if let Some(sparse) = accessor.sparse() {
            let k = sparse.count();
            if k == 0 || k > count {
                return Err(bad(format!("sparse count {k} is not in 1..={count}")));
            }
            let indices = sparse.indices();
            let index_size = indices.index_type().size();
            let index_bytes = self.view_bytes(accessor, what, &indices.view())?;
            let index_bytes = span(indices.offset(), index_size, k, index_size)
                .and_then(|r| index_bytes.get(r))
                .ok_or_else(|| {
                    bad(format!(
                        "{k} sparse indices run past buffer view {}",
                        indices.view().index()
                    ))
                })?;
            let sparse_values = sparse.values();
            let value_bytes = self.view_bytes(accessor, what, &sparse_values.view())?;
            let value_bytes = span(sparse_values.offset(), element, k, element)
                .and_then(|r| value_bytes.get(r))
                .ok_or_else(|| {
                    bad(format!(
                        "{k} sparse values run past buffer view {}",
                        sparse_values.view().index()
                    ))
                })?;
            let mut substitute = Vec::with_capacity(n);
            for (j, (ib, vb)) in index_bytes
                .chunks_exact(index_size)
                .zip(value_bytes.chunks_exact(element))
                .enumerate()
            {
                let index = match ib.len() {
                    1 => ib[0] as usize,
                    2 => u16::from_le_bytes([ib[0], ib[1]]) as usize,
                    _ => u32::from_le_bytes([ib[0], ib[1], ib[2], ib[3]]) as usize,
                };
                if index >= count {
                    return Err(bad(format!(
                        "sparse index {j} is {index}, beyond the count {count}"
                    )));
                }
                substitute.clear();
                components_of(vb, &mut substitute);
                values[index * n..(index + 1) * n].copy_from_slice(&substitute);
            }
        }
        Ok(values)
    }
}

/// The byte range of `count` elements of `element` bytes spaced `stride`
/// apart from `offset`, or `None` on overflow.
fn span(offset: usize, stride: usize, count: usize, element: usize) -> Option<Range<usize>> {
    let end = stride
        .checked_mul(count - 1)?
        .checked_add(element)?
        .checked_add(offset)?;
    Some(offset..end)
}
