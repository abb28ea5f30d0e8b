//! Writing files so that a crash never leaves half of one behind.

use std::{fs, io::Write, path::Path};

use shadow_core::{Error, Result};

/// Writes `bytes` to `path` atomically: into a temporary file beside it
/// (`tempfile`, removed if anything fails), flushed to disk, then renamed
/// over `path` (rename is atomic within a file system). Creates the parent
/// directory if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut builder = tempfile::Builder::new();
    // Readable by all, as a file created directly would be (a temporary
    // file is the owner's alone).
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
    let mut file = builder.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    file.write_all(bytes)
        .and_then(|()| file.as_file().sync_all())
        .map_err(|e| Error::io(path, e))?;
    file.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

/// Writes 8-bit RGB pixels, `width` × `height` row by row, as a PNG at
/// `path`, atomically; compressed hard, since the report's page embeds
/// every one.
pub fn write_png_atomic(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<()> {
    use image::{
        ExtendedColorType, ImageEncoder,
        codecs::png::{CompressionType, FilterType, PngEncoder},
    };
    let mut png = Vec::new();
    PngEncoder::new_with_quality(&mut png, CompressionType::Best, FilterType::Adaptive)
        .write_image(rgb, width, height, ExtendedColorType::Rgb8)
        .map_err(|e| Error::format(path, format!("encoding the PNG: {e}")))?;
    write_atomic(path, &png)
}

/// Writes `value` as pretty-printed JSON to `path`, atomically.
pub fn write_json_atomic(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let json = serde_json::to_vec_pretty(value).map_err(|e| Error::format(path, e.to_string()))?;
    write_atomic(path, &json)
}

/// Reads a float field that [`write_json_atomic`] may have written as
/// `null`: JSON has no NaN or infinity, and serde_json writes a non-finite
/// float as `null`, which this reads back as NaN (non-finite either way).
/// For `#[serde(deserialize_with = "crate::io::f32_or_null")]`.
pub fn f32_or_null<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> std::result::Result<f32, D::Error> {
    use serde::Deserialize;
    Option::<f32>::deserialize(deserializer).map(|v| v.unwrap_or(f32::NAN))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_replaces_without_leaving_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/report.json");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }

    #[cfg(unix)]
    #[test]
    fn written_files_are_readable_by_all() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("report.md");
        write_atomic(&path, b"x").unwrap();
        let mode = fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o444, 0o444, "{mode:o}");
    }

    #[test]
    fn unwritable_destination_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("file");
        fs::write(&blocker, b"x").unwrap();
        let err = write_atomic(&blocker.join("child.json"), b"y").unwrap_err();
        assert!(err.to_string().contains("file"), "{err}");
    }
}
