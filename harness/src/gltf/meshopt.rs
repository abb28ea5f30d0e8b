//! `EXT_meshopt_compression`: buffer views stored compressed by
//! meshoptimizer's codecs (what gltfpack and `gltf-transform meshopt` write),
//! decoded once at load time into the bytes the view would hold uncompressed.
//!
//! A compressed view names its compressed bytes (`buffer`, `byteOffset`,
//! `byteLength`), the decoded element size and count (`byteStride`, `count`),
//! the codec (`mode`: `ATTRIBUTES`, `TRIANGLES` or `INDICES`) and a filter
//! applied after decoding (`NONE`, `OCTAHEDRAL`, `QUATERNION`, `EXPONENTIAL`,
//! `COLOR`). The view's own `buffer` is then usually a fallback buffer
//! without data, which is never read.

use serde_json::Value;
use shadow_core::{Error, Result};

/// The extension's name, as it appears in `extensionsUsed`.
pub(super) const EXTENSION: &str = "EXT_meshopt_compression";

/// Whether a buffer is a fallback for compressed views: it may have no data.
pub(super) fn is_fallback(buffer: &::gltf::Buffer) -> bool {
    buffer
        .extension_value(EXTENSION)
        .and_then(|e| e.get("fallback"))
        .and_then(Value::as_bool)
        .unwrap_or(false)
}

/// The decoded bytes of every compressed buffer view (`None` for the views
/// stored plainly), from the raw buffer payloads `data`.
pub(super) fn decode_views(
    path: &std::path::Path,
    document: &::gltf::Document,
    data: &[Vec<u8>],
) -> Result<Vec<Option<Vec<u8>>>> {
    document
        .views()
        .map(|view| {
            let Some(ext) = view.extension_value(EXTENSION) else {
                return Ok(None);
            };
            let bad = |what: String| {
                Error::format(
                    path,
                    format!("buffer view {} ({EXTENSION}): {what}", view.index()),
                )
            };
            let compressed = Compressed::parse(ext).map_err(bad)?;
            let source = data
                .get(compressed.buffer)
                .ok_or_else(|| bad(format!("buffer {} does not exist", compressed.buffer)))?;
            let bytes = compressed
                .offset
                .checked_add(compressed.length)
                .and_then(|end| source.get(compressed.offset..end))
                .ok_or_else(|| {
                    bad(format!(
                        "bytes {}..{} run past buffer {}, which has {} bytes",
                        compressed.offset,
                        compressed.offset.saturating_add(compressed.length),
                        compressed.buffer,
                        source.len()
                    ))
                })?;
            let decoded = compressed.decode(bytes).map_err(bad)?;
            if decoded.len() < view.length() {
                return Err(bad(format!(
                    "decodes to {} bytes, the view declares {}",
                    decoded.len(),
                    view.length()
                )));
            }
            Ok(Some(decoded))
        })
        .collect()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Attributes,
    Triangles,
    Indices,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Filter {
    None,
    Octahedral,
    Quaternion,
    Exponential,
    Color,
}

/// The extension object of one compressed view.
#[derive(Debug)]
struct Compressed {
    buffer: usize,
    offset: usize,
    length: usize,
    stride: usize,
    count: usize,
    mode: Mode,
    filter: Filter,
}

impl Compressed {
    fn parse(ext: &Value) -> std::result::Result<Compressed, String> {
        let number = |key: &str, default: Option<usize>| -> std::result::Result<usize, String> {
            match ext.get(key) {
                Some(v) => v
                    .as_u64()
                    .and_then(|n| usize::try_from(n).ok())
                    .ok_or_else(|| format!("{key} is {v}, not a non-negative integer")),
                None => default.ok_or_else(|| format!("{key} is missing")),
            }
        };
        let text = |key: &str| ext.get(key).and_then(Value::as_str);
        let mode = match text("mode") {
            Some("ATTRIBUTES") => Mode::Attributes,
            Some("TRIANGLES") => Mode::Triangles,
            Some("INDICES") => Mode::Indices,
            other => {
                return Err(format!(
                    "mode {other:?} is not ATTRIBUTES, TRIANGLES or INDICES"
                ));
            }
        };
        let filter = match text("filter") {
            None | Some("NONE") => Filter::None,
            Some("OCTAHEDRAL") => Filter::Octahedral,
            Some("QUATERNION") => Filter::Quaternion,
            Some("EXPONENTIAL") => Filter::Exponential,
            Some("COLOR") => Filter::Color,
            Some(other) => return Err(format!("unknown filter {other:?}")),
        };
        let c = Compressed {
            buffer: number("buffer", None)?,
            offset: number("byteOffset", Some(0))?,
            length: number("byteLength", None)?,
            stride: number("byteStride", None)?,
            count: number("count", None)?,
            mode,
            filter,
        };
        let stride_ok = match (c.mode, c.filter) {
            (Mode::Attributes, Filter::None | Filter::Exponential) => {
                c.stride.is_multiple_of(4) && (4..=256).contains(&c.stride)
            }
            (Mode::Attributes, Filter::Octahedral | Filter::Color) => matches!(c.stride, 4 | 8),
            (Mode::Attributes, Filter::Quaternion) => c.stride == 8,
            (Mode::Triangles | Mode::Indices, Filter::None) => matches!(c.stride, 2 | 4),
            (Mode::Triangles | Mode::Indices, _) => false,
        };
        if !stride_ok {
            return Err(format!(
                "byteStride {} does not suit mode {:?} with filter {:?}",
                c.stride, c.mode, c.filter
            ));
        }
        if c.mode == Mode::Triangles && !c.count.is_multiple_of(3) {
            return Err(format!("{} indices do not form triangles", c.count));
        }
        Ok(c)
    }

    /// Decodes `bytes` into `count · stride` bytes and applies the filter.
    fn decode(&self, bytes: &[u8]) -> std::result::Result<Vec<u8>, String> {
        // Refuse counts no real payload could hold before allocating for them:
        // meshoptimizer's codecs spend at least a bit per decoded byte pair
        // only in degenerate cases, so 256 decoded bytes per encoded byte is
        // far above anything valid.
        let size = self
            .count
            .checked_mul(self.stride)
            .filter(|&size| size <= bytes.len().saturating_mul(256).max(1 << 16))
            .ok_or_else(|| {
                format!(
                    "{} elements of {} bytes from {} compressed bytes is not plausible",
                    self.count,
                    self.stride,
                    bytes.len()
                )
            })?;
        // Four-byte words keep the filters' 16- and 32-bit accesses aligned.
        let mut words = vec![0u32; size.div_ceil(4)];
        let destination = words.as_mut_ptr().cast::<std::ffi::c_void>();
        // SAFETY: `words` holds at least `count · stride` bytes, the most each
        // decoder writes; the decoders read only `bytes.len()` bytes of
        // `bytes` and are documented as safe on untrusted input (they return
        // an error code, not out-of-bounds accesses, on malformed data).
        let code = unsafe {
            let (source, length) = (bytes.as_ptr(), bytes.len());
            match self.mode {
                Mode::Attributes => meshopt::ffi::meshopt_decodeVertexBuffer(
                    destination,
                    self.count,
                    self.stride,
                    source,
                    length,
                ),
                Mode::Triangles => meshopt::ffi::meshopt_decodeIndexBuffer(
                    destination,
                    self.count,
                    self.stride,
                    source,
                    length,
                ),
                Mode::Indices => meshopt::ffi::meshopt_decodeIndexSequence(
                    destination,
                    self.count,
                    self.stride,
                    source,
                    length,
                ),
            }
        };
        if code != 0 {
            return Err(format!(
                "the {:?} decoder refused the data (code {code})",
                self.mode
            ));
        }
        // SAFETY: the filters rewrite `count` elements of `stride` bytes in
        // place, inside the `count · stride` bytes of `words`; `parse` has
        // checked each filter's stride (4 or 8 for octahedral and colour, 8
        // for quaternions, a multiple of 4 for exponents).
        unsafe {
            let filter = match self.filter {
                Filter::None => None,
                Filter::Octahedral => Some(meshopt::ffi::meshopt_decodeFilterOct as FilterFn),
                Filter::Quaternion => Some(meshopt::ffi::meshopt_decodeFilterQuat as FilterFn),
                Filter::Exponential => Some(meshopt::ffi::meshopt_decodeFilterExp as FilterFn),
                Filter::Color => Some(meshopt::ffi::meshopt_decodeFilterColor as FilterFn),
            };
            if let Some(filter) = filter {
                filter(destination, self.count, self.stride);
            }
        }
        let mut decoded: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        decoded.truncate(size);
        Ok(decoded)
    }
}

type FilterFn = unsafe extern "C" fn(*mut std::ffi::c_void, usize, usize);

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn compressed(mode: &str, filter: &str, stride: usize, count: usize) -> Compressed {
        Compressed::parse(&json!({
            "buffer": 0, "byteLength": 1, "byteStride": stride, "count": count,
            "mode": mode, "filter": filter
        }))
        .unwrap()
    }

    #[test]
    fn vertex_and_index_streams_round_trip_through_meshoptimizer() {
        let vertices: Vec<[u16; 4]> = (0..100u16).map(|i| [i, 2 * i, 3 * i, 7]).collect();
        let encoded = meshopt::encode_vertex_buffer(&vertices).unwrap();
        let decoded = compressed("ATTRIBUTES", "NONE", 8, 100)
            .decode(&encoded)
            .unwrap();
        let expected: Vec<u8> = vertices
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        assert_eq!(decoded, expected);

        let indices: Vec<u32> = (0..30).map(|i| (i * 7) % 20).collect();
        let encoded = meshopt::encode_index_buffer(&indices, 20).unwrap();
        let decoded = compressed("TRIANGLES", "NONE", 4, 30)
            .decode(&encoded)
            .unwrap();
        let read: Vec<u32> = decoded
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        assert_eq!(read, indices);
    }

    #[test]
    fn malformed_extensions_and_data_are_refused() {
        let bad = |v: Value| Compressed::parse(&v).unwrap_err();
        assert!(
            bad(json!({"buffer": 0, "byteLength": 4, "byteStride": 6, "count": 1, "mode": "ATTRIBUTES"}))
                .contains("byteStride 6")
        );
        assert!(
            bad(
                json!({"buffer": 0, "byteLength": 4, "byteStride": 4, "count": 1, "mode": "POINTS"})
            )
            .contains("mode")
        );
        assert!(
            bad(json!({"buffer": 0, "byteStride": 4, "count": 1, "mode": "INDICES"}))
                .contains("byteLength is missing")
        );
        let garbage = compressed("ATTRIBUTES", "NONE", 4, 10).decode(&[0xff; 16]);
        assert!(garbage.unwrap_err().contains("refused"));
        let huge = compressed("ATTRIBUTES", "NONE", 256, usize::MAX / 128).decode(&[0; 16]);
        assert!(huge.unwrap_err().contains("not plausible"));
    }
}
