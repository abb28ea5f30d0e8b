//! Reading environments from Radiance RGBE files (`.hdr`, the `image` crate's
//! decoder), the format most HDR skies are downloaded in.
//!
//! RGBE stores three 8-bit mantissas that share one exponent: a texel's
//! brightest channel keeps better than 1% relative precision, and the other
//! channels are quantized in steps of under 1% of that brightest one. The
//! decoder reads the standard orientation, "-Y height +X width": scan lines
//! from the top down, each from left to right, so the file's first scan line
//! is row 0, the top row (θ near 0, +Y), as in [`Environment`] and the
//! OpenEXR loader. Files in any of the seven other orientations are refused.
//! Texels are taken as stored: the header's optional EXPOSURE and COLORCORR
//! are not applied ([`Environment::scaled`] applies an exposure).

use std::fs;
use std::io::ErrorKind;
use std::path::Path;

use glam::Vec3;
use image::codecs::hdr::HdrDecoder;
use image::{DynamicImage, ImageError};

use super::Environment;
use crate::{Error, Result};

impl Environment {
    /// Loads a Radiance RGBE (`.hdr`) file.
    ///
    /// The environment is named after the path. A missing or unreadable file
    /// is an [`Error::Io`]; a file that is not Radiance RGBE (no `#?RADIANCE`
    /// signature), has a malformed header, holds XYZE rather than RGBE data,
    /// is stored in a non-standard orientation, or is truncated or corrupt is
    /// an [`Error::Format`] naming the file. The texels go through
    /// [`Environment::new`]'s validation, whose errors name the file too.
    pub fn load_hdr(path: &Path) -> Result<Environment> {
        let bytes = fs::read(path).map_err(|e| Error::io(path, e))?;
        let bad = |what: String| Error::format(path, what);
        // Strict: the signature is required, so any other file is refused
        // before its bytes are taken for a header.
        let decoder = HdrDecoder::new(bytes.as_slice()).map_err(|e| {
            let why = describe(e, "the file ends before its header does");
            bad(format!("not a readable Radiance HDR file ({why})"))
        })?;
        let image = DynamicImage::from_decoder(decoder)
            .map_err(|e| {
                let why = describe(e, "the file ends before its last scan line");
                bad(format!("corrupt or truncated Radiance HDR data ({why})"))
            })?
            .into_rgb32f();
        let (width, height) = (image.width() as usize, image.height() as usize);
        let texels = image
            .into_raw()
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect();
        Environment::new(path.display().to_string(), width, height, texels)
    }
}

/// The decoder's error in words about the file: running out of bytes (which
/// the decoder reports as an I/O error, "failed to fill whole buffer") is
/// `truncated`.
fn describe(error: ImageError, truncated: &str) -> String {
    match error {
        ImageError::IoError(e) if e.kind() == ErrorKind::UnexpectedEof => truncated.to_string(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use approx::assert_abs_diff_eq;
    use image::Rgb;
    use image::codecs::hdr::HdrEncoder;

    use super::*;

    /// Writes `texels` (row-major, row 0 first) with the `image` crate's
    /// encoder, which run-length encodes scan lines 8 to 32767 wide.
    fn write_hdr(path: &Path, width: usize, height: usize, texels: &[Vec3]) {
        let pixels: Vec<Rgb<f32>> = texels.iter().map(|t| Rgb(t.to_array())).collect();
        let file = fs::File::create(path).unwrap();
        HdrEncoder::new(std::io::BufWriter::new(file))
            .encode(&pixels, width, height)
            .unwrap();
    }

    /// A map with values from 1e-3 to 5e4 (a sun) and black texels.
    fn varied(width: usize, height: usize) -> Vec<Vec3> {
        (0..width * height)
            .map(|i| match i % 7 {
                0 => Vec3::ZERO,
                3 => Vec3::new(5.0e4, 4.0e4, 3.0e4),
                k => {
                    let v = 1e-3 * 10f32.powi(k as i32) * (1.0 + i as f32 / 100.0);
                    Vec3::new(v, 0.7 * v, 0.4 * v)
                }
            })
            .collect()
    }

    #[test]
    fn encoded_map_round_trips_within_rgbe_precision() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sky.hdr");
        let (w, h) = (32, 16);
        let texels = varied(w, h);
        write_hdr(&path, w, h, &texels);
        let env = Environment::load_hdr(&path).unwrap();
        assert_eq!((env.width(), env.height()), (w, h));
        assert_eq!(env.name(), path.display().to_string());
        assert_eq!(env.report().negative_clamped, 0);
        for (back, original) in env.texels().iter().zip(&texels) {
            // Every channel within 1% of the texel's brightest channel.
            assert_abs_diff_eq!(*back, *original, epsilon = 0.01 * original.max_element());
        }
    }

    #[test]
    fn first_scan_line_is_the_top_row() {
        let dir = tempfile::tempdir().unwrap();
        // By hand: flat RGBE pixels (scan lines narrower than 8 are never
        // run-length encoded), value = mantissa · 2^(exponent − 136).
        let path = dir.path().join("hand.hdr");
        let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 3\n".to_vec();
        bytes.extend_from_slice(&[128, 64, 32, 129, 128, 128, 128, 136, 128, 64, 32, 129]);
        bytes.extend_from_slice(&[128, 64, 32, 129, 128, 64, 32, 129, 0, 0, 0, 0]);
        fs::write(&path, bytes).unwrap();
        let env = Environment::load_hdr(&path).unwrap();
        assert_eq!((env.width(), env.height()), (3, 2));
        assert_eq!(env.texel(0, 1), Vec3::splat(128.0));
        assert_eq!(env.texel(0, 0), Vec3::new(1.0, 0.5, 0.25));
        assert_eq!(env.texel(1, 2), Vec3::ZERO);
        assert!(env.direction(0, 1).y > 0.0);

        // Through the encoder: one bright texel in the top row of 16×8.
        let path = dir.path().join("sun.hdr");
        let mut texels = vec![Vec3::ONE; 16 * 8];
        texels[5] = Vec3::splat(1000.0);
        write_hdr(&path, 16, 8, &texels);
        let env = Environment::load_hdr(&path).unwrap();
        let brightest = (0..env.texels().len())
            .max_by(|&a, &b| env.texels()[a].x.total_cmp(&env.texels()[b].x))
            .unwrap();
        assert_eq!((brightest / 16, brightest % 16), (0, 5));
    }

    fn assert_format_error_naming(path: &Path, err: Error) {
        let name = path.file_name().unwrap().to_string_lossy();
        assert!(matches!(err, Error::Format { .. }), "{err}");
        assert!(err.to_string().contains(&*name), "{err}");
    }

    #[test]
    fn truncated_or_garbage_file_is_format_error_naming_file() {
        let dir = tempfile::tempdir().unwrap();
        let whole = dir.path().join("whole.hdr");
        write_hdr(&whole, 16, 8, &varied(16, 8));
        let bytes = fs::read(&whole).unwrap();
        let path = dir.path().join("cut.hdr");
        for len in [0, 5, 30, bytes.len() / 2, bytes.len() - 1] {
            fs::write(&path, &bytes[..len]).unwrap();
            let err = Environment::load_hdr(&path).unwrap_err();
            let msg = err.to_string();
            assert!(msg.contains("ends before") || msg.contains("EOF"), "{msg}");
            assert_format_error_naming(&path, err);
        }

        let text = dir.path().join("notes.hdr");
        fs::write(&text, "this is not an image\n").unwrap();
        assert_format_error_naming(&text, Environment::load_hdr(&text).unwrap_err());

        // A real header in an orientation other than the standard one.
        let flipped = dir.path().join("flipped.hdr");
        fs::write(
            &flipped,
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n+Y 1 +X 1\n\x80\x80\x80\x81",
        )
        .unwrap();
        let err = Environment::load_hdr(&flipped).unwrap_err();
        assert!(err.to_string().contains("Orientation +Y +X"), "{err}");
        assert_format_error_naming(&flipped, err);
    }

    #[test]
    fn missing_file_is_io_error_naming_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing: PathBuf = dir.path().join("missing.hdr");
        let err = Environment::load_hdr(&missing).unwrap_err();
        assert!(
            matches!(err, Error::Io { .. }) && err.to_string().contains("missing.hdr"),
            "{err}"
        );
    }
}
