//! Images of a run for people to look at: the linear radiance as OpenEXR
//! (RGBA f32, alpha 1 where a surface covers the pixel), a tone-mapped PNG,
//! and a heat map of the per-pixel error against the reference with its
//! colour scale.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{
    Encoding, Image as ExrImage, Layer, LayerAttributes, ReadChannels, ReadLayers,
    SpecificChannels, Vec2 as ExrVec2, WritableImage,
};
use glam::Vec3;
use plotters::prelude::*;
use shadow_core::{Error, Image, Result};

use crate::{
    chart,
    io::{write_atomic, write_png_atomic},
    run::RunResult,
    score::FLOOR,
};

/// Writes `image` to `path` as OpenEXR: RGBA f32 in ZIP-compressed scan
/// lines, row 0 at the top, alpha 1 on covered pixels and 0 elsewhere.
/// Atomic.
pub fn write_exr(path: &Path, image: &Image) -> Result<()> {
    let width = image.width as usize;
    let layer = Layer::new(
        (width, image.height as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgba(|pos: ExrVec2<usize>| {
            let i = pos.y() * width + pos.x();
            let p = image.pixels[i];
            (p.x, p.y, p.z, if image.covered[i] { 1.0f32 } else { 0.0 })
        }),
    );
    let mut bytes = Cursor::new(Vec::new());
    ExrImage::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| Error::format(path, format!("could not encode OpenEXR ({e})")))?;
    write_atomic(path, bytes.get_ref())
}

/// Reads an image [`write_exr`] wrote: RGB radiance, covered where alpha is
/// above ½.
pub fn read_exr(path: &Path) -> Result<Image> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let read = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |size: ExrVec2<usize>, _| (size, vec![(Vec3::ZERO, false); size.area()]),
            |(size, pixels): &mut (ExrVec2<usize>, Vec<(Vec3, bool)>),
             pos: ExrVec2<usize>,
             (r, g, b, a): (f32, f32, f32, f32)| {
                pixels[pos.y() * size.width() + pos.x()] = (Vec3::new(r, g, b), a > 0.5);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes.as_slice()))
        .map_err(|e| Error::format(path, format!("not an RGBA OpenEXR image ({e})")))?;
    let (size, pixels) = read.layer_data.channel_data.pixels;
    Ok(Image {
        width: size.width() as u32,
        height: size.height() as u32,
        pixels: pixels.iter().map(|p| p.0).collect(),
        covered: pixels.iter().map(|p| p.1).collect(),
        std_error: None,
    })
}

/// The stem of a method's image files: its name with each `:` (which
/// Windows refuses in file names) as `_`, e.g. `hemi-raster_pvs_mask=16`.
pub fn file_stem(method: &str) -> String {
    method.replace(':', "_")
}

/// Writes the image set of one scene under `dir/{scene}/`: the reference
/// (`reference.exr`, `reference.png`) and, for each run with an image of the
/// same frame, its image (`{stem}.exr`, `{stem}.png`, shown with the
/// reference's exposure) and its error heat map (`{stem}-error.png`), where
/// `stem` is [`file_stem`] of the method's name.
pub fn write_scene(dir: &Path, scene: &str, reference: &Image, runs: &[&RunResult]) -> Result<()> {
    let dir = dir.join(scene);
    let exposure = Exposure::of(reference);
    write_exr(&dir.join("reference.exr"), reference)?;
    write_png(&dir.join("reference.png"), reference, exposure)?;
    for run in runs {
        let Some(image) = &run.last_image else {
            continue;
        };
        let name = file_stem(&run.method);
        write_exr(&dir.join(format!("{name}.exr")), image)?;
        write_png(&dir.join(format!("{name}.png")), image, exposure)?;
        write_error_map(&dir.join(format!("{name}-error.png")), image, reference)?;
    }
    Ok(())
}

/// The scale applied to radiance before display encoding, chosen from a
/// reference so that a method's image and its reference are shown alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure(pub f32);

impl Exposure {
    /// Maps the 99th percentile of the covered pixels' luminance to white
    /// (so that the brightest 1% clip); 1 for an image with no light.
    pub fn of(reference: &Image) -> Exposure {
        let mut luminance: Vec<f32> = (0..reference.pixels.len())
            .filter(|&i| reference.covered[i])
            .map(|i| reference.pixels[i].dot(Vec3::new(0.2126, 0.7152, 0.0722)))
            .collect();
        luminance.sort_unstable_by(f32::total_cmp);
        let p99 = luminance
            .get(luminance.len() * 99 / 100)
            .copied()
            .unwrap_or(0.0);
        Exposure(if p99 > 0.0 { 1.0 / p99 } else { 1.0 })
    }
}

/// Writes `image` as an 8-bit sRGB PNG: radiance times `exposure`, clipped
/// to [0, 1]; uncovered pixels dark grey. Atomic.
pub fn write_png(path: &Path, image: &Image, exposure: Exposure) -> Result<()> {
    let rgb: Vec<u8> = image
        .pixels
        .iter()
        .zip(&image.covered)
        .flat_map(|(p, &covered)| {
            if covered {
                (*p * exposure.0).to_array().map(srgb)
            } else {
                [40; 3]
            }
        })
        .collect();
    write_png_atomic(path, &rgb, image.width, image.height)
}

/// The linear value of an 8-bit sRGB level: the inverse of the encoding the
/// PNGs are written with.
pub fn linear_from_srgb(level: u8) -> f32 {
    let v = f32::from(level) / 255.0;
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB encoding of a linear value in [0, 1] (clipped).
fn srgb(linear: f32) -> u8 {
    let v = linear.clamp(0.0, 1.0);
    let encoded = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}

/// The heat map's range of per-pixel relative error, on a log scale.
pub const ERROR_SCALE: (f32, f32) = (1e-3, 1.0);

/// The relative error of each pixel the reference covers, as the score
/// measures it (`|x − r| / max(|r|, floor)`, a pixel the method leaves
/// uncovered counting as zero); `None` for background.
pub fn pixel_errors(image: &Image, reference: &Image) -> Vec<Option<f32>> {
    let covered = (0..reference.pixels.len()).filter(|&i| reference.covered[i]);
    let sum_r2: f64 = covered
        .map(|i| reference.pixels[i].length_squared() as f64)
        .sum();
    let count = reference.covered.iter().filter(|c| **c).count().max(1);
    let floor = FLOOR * (sum_r2 / count as f64).sqrt() as f32;
    (0..reference.pixels.len())
        .map(|i| {
            reference.covered[i].then(|| {
                let x = if image.covered[i] {
                    image.pixels[i]
                } else {
                    Vec3::ZERO
                };
                let r = reference.pixels[i];
                (x - r).length() / r.length().max(floor).max(f32::MIN_POSITIVE)
            })
        })
        .collect()
}

/// Writes the heat map of [`pixel_errors`] with its colour scale beneath:
/// Viridis over [`ERROR_SCALE`] on a log scale in bands of a quarter
/// decade (errors beyond either end take its colour), background grey; small images are magnified by a whole
/// factor to at least 480 pixels wide. Atomic.
pub fn write_error_map(path: &Path, image: &Image, reference: &Image) -> Result<()> {
    if (image.width, image.height) != (reference.width, reference.height) {
        return Err(Error::format(
            path,
            format!(
                "a {}×{} image against a {}×{} reference",
                image.width, image.height, reference.width, reference.height
            ),
        ));
    }
    let errors = pixel_errors(image, reference);
    let zoom = 480u32.div_ceil(image.width).max(1);
    let (width, map_height) = (image.width * zoom, image.height * zoom);
    let height = map_height + 64;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    draw_error_map(
        &errors,
        image.width,
        zoom,
        map_height,
        &mut rgb,
        (width, height),
    )
    .map_err(|e| Error::format(path, format!("drawing the heat map: {e}")))?;
    write_png_atomic(path, &rgb, width, height)
}

/// The heat map's sRGB colour of a pixel's relative error: Viridis over
/// [`ERROR_SCALE`] in quarter-decade bands; grey for background (`None`).
pub fn error_colour(error: Option<f32>) -> [u8; 3] {
    match error {
        Some(e) => {
            let c = ViridisRGB.get_color(band(scale_position(e)));
            [c.0, c.1, c.2]
        }
        None => [96, 96, 96],
    }
}

/// Colours per decade of the heat map: a band is a quarter decade (so the
/// eye reads levels, and maps of noisy errors compress).
const BANDS_PER_DECADE: f32 = 4.0;

/// The band of scale position `t` (in [0, 1]), as the position of its
/// colour: the first band 0, the last 1.
fn band(t: f32) -> f32 {
    let (lo, hi) = ERROR_SCALE;
    let bands = ((hi / lo).log10() * BANDS_PER_DECADE).round().max(2.0);
    (t * bands).floor().min(bands - 1.0) / (bands - 1.0)
}

/// Where `error` falls on the log scale, in [0, 1].
fn scale_position(error: f32) -> f32 {
    let (lo, hi) = ERROR_SCALE;
    ((error.max(lo).ln() - lo.ln()) / (hi.ln() - lo.ln())).clamp(0.0, 1.0)
}

fn draw_error_map(
    errors: &[Option<f32>],
    image_width: u32,
    zoom: u32,
    map_height: u32,
    rgb: &mut [u8],
    size: (u32, u32),
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    chart::register_font()?;
    let root = BitMapBackend::with_buffer(rgb, size).into_drawing_area();
    root.fill(&WHITE)?;
    let (map, legend) = root.split_vertically(map_height);
    let zoom = zoom as i32;
    for (i, error) in errors.iter().enumerate() {
        let (x, y) = (
            (i as u32 % image_width) as i32,
            (i as u32 / image_width) as i32,
        );
        let [r, g, b] = error_colour(*error);
        let colour = RGBColor(r, g, b);
        let corner = (x * zoom, y * zoom);
        map.draw(&Rectangle::new(
            [corner, (corner.0 + zoom, corner.1 + zoom)],
            colour.filled(),
        ))?;
    }
    // The colour bar, 24 px high, with a tick per decade.
    let (bar_left, bar_right) = (40i32, size.0 as i32 - 40);
    for x in bar_left..bar_right {
        let t = (x - bar_left) as f32 / (bar_right - bar_left - 1).max(1) as f32;
        legend.draw(&Rectangle::new(
            [(x, 6), (x + 1, 30)],
            ViridisRGB.get_color(band(t)).filled(),
        ))?;
    }
    let style = ("sans-serif", 14).into_font().color(&BLACK);
    let (lo, hi) = ERROR_SCALE;
    let decades = (hi / lo).log10().round() as i32;
    for d in 0..=decades {
        let error = lo * 10f32.powi(d);
        let x = bar_left + ((bar_right - bar_left - 1) as f32 * scale_position(error)) as i32;
        legend.draw(&PathElement::new([(x, 30), (x, 36)], BLACK))?;
        let percent = error * 100.0;
        let label = if percent < 1.0 {
            format!("{percent:.1}%")
        } else {
            format!("{percent:.0}%")
        };
        legend.draw(&Text::new(label, (x - 12, 40), style.clone()))?;
    }
    legend.draw(&Text::new(
        "relative error per pixel (grey: background)",
        (bar_left, 52),
        style,
    ))?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(pixels: Vec<Vec3>, covered: Vec<bool>, width: u32) -> Image {
        let height = pixels.len() as u32 / width;
        Image {
            width,
            height,
            pixels,
            covered,
            std_error: None,
        }
    }

    #[test]
    fn exr_round_trips_radiance_and_coverage() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("img.exr");
        let pixels: Vec<Vec3> = (0..12).map(|i| Vec3::new(i as f32, 0.5, 1e4)).collect();
        let covered: Vec<bool> = (0..12).map(|i| i % 3 != 0).collect();
        let original = image(pixels, covered, 4);
        write_exr(&path, &original).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (4, 3));
        assert_eq!(back.pixels, original.pixels);
        assert_eq!(back.covered, original.covered);
    }

    #[test]
    fn pixel_errors_count_uncovered_as_zero_and_skip_background() {
        let reference = image(vec![Vec3::ONE; 4], vec![true, true, true, false], 2);
        let method = image(
            vec![Vec3::ONE, Vec3::splat(1.5), Vec3::ONE, Vec3::ONE],
            vec![true, true, false, true],
            2,
        );
        let errors = pixel_errors(&method, &reference);
        assert_eq!(errors[0], Some(0.0));
        assert!((errors[1].unwrap() - 0.5).abs() < 1e-6);
        assert_eq!(errors[2], Some(1.0));
        assert_eq!(errors[3], None);
    }

    #[test]
    fn heat_map_and_png_decode_at_their_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let reference = image(vec![Vec3::splat(0.5); 6], vec![true; 6], 3);
        let method = image(vec![Vec3::splat(0.6); 6], vec![true; 6], 3);
        let map = dir.path().join("error.png");
        write_error_map(&map, &method, &reference).unwrap();
        let decoded = image::open(&map).unwrap();
        assert_eq!(decoded.width(), 480);
        assert_eq!(decoded.height(), 2 * 160 + 64);
        let png = dir.path().join("img.png");
        write_png(&png, &method, Exposure::of(&reference)).unwrap();
        let decoded = image::open(&png).unwrap().to_rgb8();
        // 0.6 × (1 / 0.5) clips to white.
        assert_eq!(decoded.get_pixel(0, 0).0, [255, 255, 255]);
        let other = image(vec![Vec3::ONE; 4], vec![true; 4], 2);
        assert!(write_error_map(&map, &method, &other).is_err());
    }
}
