//! NumPy's `.npz` format, written: a zip archive of `.npy` arrays (stored,
//! uncompressed, as `np.savez` writes them), which `np.load` reads without
//! custom code or pickling.

use std::io::{Cursor, Write};

use zip::{CompressionMethod, ZipWriter, write::SimpleFileOptions};

/// One array: a NumPy type descriptor, a shape and its little-endian data in
/// C order.
pub struct Array {
    descr: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Array {
    /// `float32` values in `shape`.
    pub fn f32(shape: &[usize], values: &[f32]) -> Array {
        Array::of("<f4", shape, values)
    }

    /// `int64` values in `shape`.
    pub fn i64(shape: &[usize], values: &[i64]) -> Array {
        Array::of("<i8", shape, values)
    }

    /// `uint8` values in `shape`.
    pub fn u8(shape: &[usize], values: &[u8]) -> Array {
        Array::of("|u1", shape, values)
    }

    /// A 0-d unicode string (`str(array)` gives it back).
    pub fn text(text: &str) -> Array {
        let chars: Vec<u32> = text.chars().map(u32::from).collect();
        let data = chars.iter().flat_map(|c| c.to_le_bytes()).collect();
        Array {
            descr: format!("<U{}", chars.len().max(1)),
            shape: Vec::new(),
            data: if chars.is_empty() { vec![0; 4] } else { data },
        }
    }

    fn of<T: bytemuck::Pod>(descr: &str, shape: &[usize], values: &[T]) -> Array {
        assert_eq!(
            shape.iter().product::<usize>(),
            values.len(),
            "npz: shape {shape:?} does not hold {} values",
            values.len()
        );
        Array {
            descr: descr.to_string(),
            shape: shape.to_vec(),
            data: bytemuck::cast_slice(values).to_vec(),
        }
    }

    /// The `.npy` file: magic, version 1.0, the header dictionary padded
    /// with spaces so that the data starts at a multiple of 64 bytes, data.
    fn npy(&self) -> Vec<u8> {
        let shape = match self.shape.as_slice() {
            [] => "()".to_string(),
            [n] => format!("({n},)"),
            dims => format!(
                "({})",
                dims.iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let mut header = format!(
            "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
            self.descr
        );
        let unpadded = 10 + header.len() + 1;
        header.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
        header.push('\n');
        let mut out = Vec::with_capacity(10 + header.len() + self.data.len());
        out.extend_from_slice(b"\x93NUMPY\x01\x00");
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&self.data);
        out
    }
}

/// The bytes of an `.npz` archive holding `arrays` by name (`name.npy`).
pub fn archive(arrays: &[(&str, Array)]) -> std::io::Result<Vec<u8>> {
    let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
    let options = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .large_file(
            arrays
                .iter()
                .any(|(_, a)| a.data.len() >= u32::MAX as usize / 2),
        );
    for (name, array) in arrays {
        zip.start_file(format!("{name}.npy"), options)
            .map_err(std::io::Error::other)?;
        zip.write_all(&array.npy())?;
    }
    Ok(zip.finish().map_err(std::io::Error::other)?.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_headers_align_the_data() {
        for array in [
            Array::f32(&[2, 3], &[0.0; 6]),
            Array::i64(&[1], &[7]),
            Array::text("{\"a\": 1}"),
        ] {
            let npy = array.npy();
            assert!(npy.starts_with(b"\x93NUMPY\x01\x00"));
            let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
            assert_eq!((10 + header_len) % 64, 0);
            assert_eq!(npy[10 + header_len - 1], b'\n');
            assert_eq!(npy.len() - 10 - header_len, array.data.len());
        }
        let header = String::from_utf8(Array::f32(&[4, 25], &[0.0; 100]).npy()[10..].to_vec())
            .unwrap_or_default();
        assert!(header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (4, 25), }"));
    }

    #[test]
    fn archives_list_every_array() {
        let bytes =
            archive(&[("a", Array::u8(&[3], &[1, 2, 3])), ("b", Array::text("hi"))]).unwrap();
        let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
        let names: Vec<String> = zip.file_names().map(|n| n.unwrap().into_owned()).collect();
        assert_eq!(names.len(), 2);
        assert!(names.contains(&"a.npy".to_string()));
        let mut a = zip.by_name("a.npy").unwrap();
        let mut content = Vec::new();
        std::io::Read::read_to_end(&mut a, &mut content).unwrap();
        assert_eq!(&content[content.len() - 3..], &[1, 2, 3]);
    }
}
