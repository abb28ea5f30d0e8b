//! The speed-versus-accuracy chart: every method on every scene as a point,
//! error against the reference across, time per frame up, both on log scales.
//! Lower left is better; a method is worth its complexity where it sits left of
//! or below the ray tracer.

use std::path::Path;

use image::{ImageEncoder, codecs::png::PngEncoder};
use plotters::prelude::*;
use shadow_core::{Error, Result};

use crate::{io::write_atomic, run::RunResult};

/// DejaVu Sans (free licence, see assets/fonts), embedded so that charts need
/// no system font libraries.
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

const WIDTH: u32 = 1100;
const HEIGHT: u32 = 720;

/// Draws `runs` to a PNG at `path`, written atomically.
pub fn speed_vs_error(runs: &[RunResult], path: &Path) -> Result<()> {
    let mut rgb = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    draw(runs, &mut rgb).map_err(|e| Error::format(path, format!("drawing the chart: {e}")))?;
    let mut png = Vec::new();
    PngEncoder::new(&mut png)
        .write_image(&rgb, WIDTH, HEIGHT, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::format(path, format!("encoding the chart: {e}")))?;
    write_atomic(path, &png)
}

fn draw(runs: &[RunResult], rgb: &mut [u8]) -> std::result::Result<(), Box<dyn std::error::Error>> {
    // Registering twice is harmless: the first registration stays.
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| "invalid embedded font")?;
    let points: Vec<(f64, f64, &RunResult)> = runs
        .iter()
        .map(|r| {
            (
                (r.mean_error() as f64 * 100.0).max(1e-3),
                (r.frame_seconds() * 1e3).max(1e-3),
                r,
            )
        })
        .collect();
    let (x_min, x_max) = bounds(points.iter().map(|p| p.0));
    let (y_min, y_max) = bounds(points.iter().map(|p| p.1));

    let root = BitMapBackend::with_buffer(rgb, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Time per frame against error (lower left is better)",
            ("sans-serif", 24),
        )
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((x_min..x_max).log_scale(), (y_min..y_max).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("relative L2 error against the reference (%)")
        .y_desc("update + shade per frame (ms)")
        .label_style(("sans-serif", 15))
        .draw()?;

    // One colour per method (each variant its own), one point per scene.
    let mut methods: Vec<&str> = runs.iter().map(|r| r.method.as_str()).collect();
    methods.sort_unstable();
    methods.dedup();
    for (i, method) in methods.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let mine: Vec<_> = points.iter().filter(|p| p.2.method == *method).collect();
        chart
            .draw_series(
                mine.iter()
                    .map(|(x, y, _)| Circle::new((*x, *y), 6, color.filled())),
            )?
            .label(*method)
            .legend(move |(x, y)| Circle::new((x, y), 6, color.filled()));
        chart.draw_series(mine.iter().map(|(x, y, r)| {
            Text::new(
                r.scene.clone(),
                (*x * 1.04, *y * 1.04),
                ("sans-serif", 13).into_font().color(&BLACK.mix(0.75)),
            )
        }))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 16))
        .draw()?;
    root.present()?;
    Ok(())
}

/// A log-scale range holding every value with a margin.
fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo.is_finite() {
        (lo / 2.0, hi * 2.0)
    } else {
        (1e-2, 1e2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::{FrameResult, StageTimes};
    use crate::score::ErrorStats;
    use shadow_core::Capabilities;

    fn run(method: &str, scene: &str, error: f32, ms: f64) -> RunResult {
        RunResult {
            method: method.into(),
            scene: scene.into(),
            environment: "uniform".into(),
            capabilities: Capabilities::ALL,
            frames: vec![FrameResult {
                frame: 0,
                error: ErrorStats {
                    relative_l2: error,
                    p99: error,
                    max: error,
                    reference_noise: 0.001,
                    count: 10,
                },
                times: StageTimes {
                    prepare: 0.0,
                    update: ms / 2e3,
                    relight: 0.0,
                    shade: ms / 2e3,
                },
            }],
            last_shading: None,
        }
    }

    #[test]
    fn writes_a_png_of_the_chart_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("chart.png");
        let runs = [
            run("unshadowed", "bunny", 0.2, 0.3),
            run("raytrace-16", "bunny", 0.05, 30.0),
            run("raytrace-64", "bunny", 0.01, 120.0),
        ];
        speed_vs_error(&runs, &path).unwrap();
        let img = image::load_from_memory(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
        // Something was drawn: not every pixel is white.
        assert!(img.to_rgb8().pixels().any(|p| p.0 != [255, 255, 255]));
    }
}
