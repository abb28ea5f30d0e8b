//! Reading and writing environments as OpenEXR files (the `exr` crate).
//!
//! Reading takes the R, G and B channels of the file's first layer, whatever
//! their sample type (f16, f32 or u32, converted to f32) and whatever
//! compression `exr` decodes (including the lossy DWAA/DWAB of the bundled
//! assets); an alpha channel is ignored. Pixel row 0 of the file is the top
//! row, as in [`Environment`]. Writing stores RGB f32 with ZIP compression in
//! scan lines: the `exr` default (RLE in 64×64 tiles) barely compresses float
//! data.

use std::fs;
use std::io::{BufWriter, Cursor};
use std::path::Path;

use ::exr::prelude::{
    Encoding, Image, Layer, LayerAttributes, ReadChannels, ReadLayers, SpecificChannels,
    Vec2 as ExrVec2, WritableImage,
};
use glam::Vec3;

use super::Environment;
use crate::{Error, Result};

impl Environment {
    /// Loads the R, G, B channels of the first layer of an OpenEXR file.
    ///
    /// The environment is named after the path. A missing or unreadable file
    /// is an [`Error::Io`]; a file that is not OpenEXR, is truncated or
    /// corrupt, holds deep data, or whose first layer lacks any of R, G, B is
    /// an [`Error::Format`] naming the file. NaN or infinite texels are
    /// rejected by [`Environment::new`] (the error names the file and counts
    /// them); negative texels are clamped and counted in [`Environment::report`].
    pub fn load_exr(path: &Path) -> Result<Environment> {
        let bytes = fs::read(path).map_err(|e| Error::io(path, e))?;
        let bad = |what: String| Error::format(path, what);

        // Check the first layer by hand so that the error can say what the
        // file holds instead (`exr` would only say no layer matched).
        let meta = ::exr::meta::MetaData::read_from_buffered(bytes.as_slice(), false)
            .map_err(|e| bad(format!("not a readable OpenEXR file ({e})")))?;
        let first = meta
            .headers
            .first()
            .ok_or_else(|| bad("OpenEXR file has no layers".into()))?;
        if first.deep {
            return Err(bad("the first layer holds deep data, not an image".into()));
        }
        // The mapping covers the whole sphere: a data window that is a crop of
        // the display window would put every texel in the wrong direction.
        let display = first.shared_attributes.display_window;
        let data = (first.own_attributes.layer_position, first.layer_size);
        if (display.position, display.size) != data {
            return Err(bad(format!(
                "the data window ({}×{} at {:?}) is not the whole image ({}×{} at {:?}); \
                 cropped lat-long maps are not supported",
                data.1.width(),
                data.1.height(),
                (data.0.x(), data.0.y()),
                display.size.width(),
                display.size.height(),
                (display.position.x(), display.position.y()),
            )));
        }
        let names: Vec<String> = first
            .channels
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        let missing: Vec<&str> = ["R", "G", "B"]
            .into_iter()
            .filter(|want| !names.iter().any(|n| n == want))
            .collect();
        if !missing.is_empty() {
            return Err(bad(format!(
                "the first layer has no {} channel (its channels: {})",
                missing.join(", "),
                names.join(", ")
            )));
        }

        // Pedantic: the chunk offset table is validated (in range, no
        // duplicates), so a corrupt table is an error rather than an image
        // whose unread blocks are silently zero. Truncation fails either way.
        let image = ::exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .rgb_channels(
                |size: ExrVec2<usize>, _| (size.width(), vec![Vec3::ZERO; size.area()]),
                |(width, texels): &mut (usize, Vec<Vec3>),
                 pos: ExrVec2<usize>,
                 (r, g, b): (f32, f32, f32)| {
                    texels[pos.y() * *width + pos.x()] = Vec3::new(r, g, b);
                },
            )
            .first_valid_layer()
            .all_attributes()
            .pedantic()
            .from_buffered(Cursor::new(bytes.as_slice()))
            .map_err(|e| bad(format!("corrupt or truncated OpenEXR data ({e})")))?;

        let layer = image.layer_data;
        let (width, height) = (layer.size.width(), layer.size.height());
        let (_, texels) = layer.channel_data.pixels;
        Environment::new(path.display().to_string(), width, height, texels)
    }

    /// Writes the map as RGB f32, ZIP-compressed scan lines.
    ///
    /// The write is atomic: the image goes to a temporary file in the target's
    /// directory, is flushed to disk and then renamed over `path`, so a crash
    /// or a full disk never leaves a half-written file under that name.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            SpecificChannels::rgb(|pos: ExrVec2<usize>| {
                let t = self.texel(pos.y(), pos.x());
                (t.x, t.y, t.z)
            }),
        );
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let mut builder = tempfile::Builder::new();
        // Readable by all, as a file created directly would be.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
        let temp = builder.tempfile_in(dir).map_err(|e| Error::io(path, e))?;
        let mut writer = BufWriter::new(temp);
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut writer)
            .map_err(|e| match e {
                ::exr::error::Error::Io(io) => Error::io(path, io),
                other => Error::format(path, format!("could not encode OpenEXR ({other})")),
            })?;
        let temp = writer
            .into_inner()
            .map_err(|e| Error::io(path, e.into_error()))?;
        temp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
        temp.persist(path).map_err(|e| Error::io(path, e.error))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::environment::luminance;
    use ::exr::prelude::{f16, write_rgb_file, write_rgba_file};
    use std::path::PathBuf;

    fn asset_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/environments")
    }

    fn assets() -> Vec<PathBuf> {
        let mut paths: Vec<PathBuf> = fs::read_dir(asset_dir())
            .expect("assets/environments exists")
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "exr"))
            .collect();
        paths.sort();
        paths
    }

    #[test]
    fn every_asset_loads_at_full_size() {
        let paths = assets();
        assert!(paths.len() >= 8, "{paths:?}");
        for path in paths {
            let env = Environment::load_exr(&path).unwrap();
            assert_eq!((env.width(), env.height()), (1024, 512), "{path:?}");
            assert_eq!(env.name(), path.display().to_string());
            assert!(
                env.texels()
                    .iter()
                    .all(|t| t.is_finite() && t.min_element() >= 0.0)
            );
            let report = env.report();
            // Lossy DWAB compression rings slightly below zero near edges: up
            // to ~9000 channels of 1.5 M, by at most ~0.004 (2% of the mean
            // radiance of the darkest map, night.exr).
            let mean = luminance(env.integral()) / (4.0 * std::f32::consts::PI);
            assert!(mean > 0.0, "{path:?} is black");
            assert!(
                report.negative_clamped < 3 * env.texels().len() / 100,
                "{path:?}: {report:?}"
            );
            assert!(
                -report.most_negative < 0.05 * mean,
                "{path:?}: {report:?}, mean {mean}"
            );
            assert_eq!(
                report.negative_clamped == 0,
                report.most_negative == 0.0,
                "{report:?}"
            );
        }
    }

    /// The stress case of DESIGN.md ("a sun-dominated HDR map"): in the
    /// sunrise map the 20 brightest of 524,288 texels carry 59% of the light
    /// (luminance × solid angle), which is what breaks methods that sample or
    /// compress the lighting coarsely.
    #[test]
    fn sunrise_is_dominated_by_twenty_texels() {
        let env = Environment::load_exr(&asset_dir().join("sunrise.exr")).unwrap();
        let mut energy: Vec<f64> = (0..env.texels().len())
            .map(|i| {
                let row = i / env.width();
                (luminance(env.texels()[i]) * env.solid_angle(row)) as f64
            })
            .collect();
        let total: f64 = energy.iter().sum();
        energy.sort_by(|a, b| b.total_cmp(a));
        let top: f64 = energy[..20].iter().sum();
        let share = top / total;
        assert!(
            (0.57..0.61).contains(&share),
            "20 brightest texels carry {share}"
        );
    }

    #[test]
    fn write_then_read_is_exact_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.exr");
        let (w, h) = (7, 5);
        let texels: Vec<Vec3> = (0..w * h)
            .map(|i| {
                let x = i as f32;
                Vec3::new(x * 0.37, 1e-6 * x, 3.0e4 + x.sin())
            })
            .collect();
        let env = Environment::new("small", w, h, texels).unwrap();
        env.write_exr(&path).unwrap();
        // Overwriting an existing file goes through the same rename.
        env.write_exr(&path).unwrap();
        let back = Environment::load_exr(&path).unwrap();
        assert_eq!((back.width(), back.height()), (w, h));
        assert_eq!(back.texels(), env.texels());
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["map.exr"]);
    }

    #[test]
    fn write_to_missing_directory_is_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/dir/map.exr");
        let err = Environment::uniform(Vec3::ONE)
            .write_exr(&path)
            .unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
        assert!(err.to_string().contains("no/such/dir/map.exr"), "{err}");
    }

    #[test]
    fn truncated_asset_is_format_error_naming_file() {
        let bytes = fs::read(asset_dir().join("studio.exr")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cut.exr");
        for len in [0, 3, 20, 300, 3000, bytes.len() / 2, bytes.len() - 1] {
            fs::write(&path, &bytes[..len]).unwrap();
            let err = Environment::load_exr(&path).unwrap_err();
            assert!(matches!(err, Error::Format { .. }), "{len} bytes: {err}");
            assert!(err.to_string().contains("cut.exr"), "{err}");
        }
    }

    #[test]
    fn missing_file_is_io_error_and_text_is_format_error() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.exr");
        let err = Environment::load_exr(&missing).unwrap_err();
        assert!(
            matches!(err, Error::Io { .. }) && err.to_string().contains("missing.exr"),
            "{err}"
        );

        let text = dir.path().join("notes.exr");
        fs::write(&text, "this is not an image\n").unwrap();
        let err = Environment::load_exr(&text).unwrap_err();
        assert!(
            matches!(err, Error::Format { .. }) && err.to_string().contains("notes.exr"),
            "{err}"
        );
    }

    #[test]
    fn missing_blue_channel_is_format_error_listing_channels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rg.exr");
        let pixels = SpecificChannels::build()
            .with_channel("R")
            .with_channel("G")
            .with_pixel_fn(|_| (1.0f32, 2.0f32));
        Image::from_channels((4, 2), pixels)
            .write()
            .to_file(&path)
            .unwrap();
        let msg = Environment::load_exr(&path).unwrap_err().to_string();
        assert!(
            msg.contains("rg.exr") && msg.contains("no B channel") && msg.contains("G, R"),
            "{msg}"
        );
    }

    #[test]
    fn cropped_data_window_is_format_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("crop.exr");
        let mut layer = Layer::new(
            (4, 2),
            LayerAttributes::default(),
            Encoding::UNCOMPRESSED,
            SpecificChannels::rgb(|_: ExrVec2<usize>| (1.0f32, 1.0f32, 1.0f32)),
        );
        layer.attributes.layer_position = ExrVec2(2, 1);
        let mut image = Image::from_layer(layer);
        image.attributes.display_window =
            ::exr::meta::attribute::IntegerBounds::new((0, 0), (8, 4));
        image.write().to_file(&path).unwrap();
        let err = Environment::load_exr(&path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::Format { .. }), "{msg}");
        assert!(
            msg.contains("crop.exr") && msg.contains("4×2 at (2, 1)") && msg.contains("8×4"),
            "{msg}"
        );
    }

    #[test]
    fn nan_texel_is_rejected_naming_file_and_count() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nan.exr");
        write_rgb_file(&path, 8, 4, |x, y| {
            if (x, y) == (5, 2) {
                (1.0, f32::NAN, 1.0)
            } else {
                (1.0f32, 1.0f32, 1.0f32)
            }
        })
        .unwrap();
        let err = Environment::load_exr(&path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::InvalidEnvironment { .. }), "{msg}");
        assert!(
            msg.contains("nan.exr") && msg.contains("1 texels") && msg.contains("row 2, column 5"),
            "{msg}"
        );
    }

    #[test]
    fn negative_texels_load_clamped_and_counted() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ringing.exr");
        write_rgb_file(&path, 8, 4, |x, y| match (x, y) {
            (0, 0) => (-0.25f32, 1.0f32, 1.0f32),
            (3, 3) => (1.0, -2.0, -0.5),
            _ => (1.0, 1.0, 1.0),
        })
        .unwrap();
        let env = Environment::load_exr(&path).unwrap();
        assert_eq!(env.report().negative_clamped, 3);
        assert_eq!(env.report().most_negative, -2.0);
        assert_eq!(env.texel(3, 3), Vec3::new(1.0, 0.0, 0.0));
    }

    #[test]
    fn half_float_rgba_reads_with_row_zero_on_top() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("half.exr");
        // Bright top row, alpha that must not leak into the colour.
        write_rgba_file(&path, 6, 3, |x, y| {
            let v = if y == 0 { 8.0 } else { 0.5 + x as f32 };
            (
                f16::from_f32(v),
                f16::from_f32(v),
                f16::from_f32(0.25),
                f16::from_f32(0.0),
            )
        })
        .unwrap();
        let env = Environment::load_exr(&path).unwrap();
        assert_eq!((env.width(), env.height()), (6, 3));
        assert_eq!(env.texel(0, 4), Vec3::new(8.0, 8.0, 0.25));
        assert_eq!(env.texel(2, 4), Vec3::new(4.5, 4.5, 0.25));
    }
}
