//! Speed-versus-accuracy charts: every configuration on every scene as a
//! point, error against the reference across, time per frame up, both on
//! log scales. Lower left is better. The report draws every method (a method
//! is worth its complexity where it sits left of or below the ray tracer);
//! the accuracy table draws every option of one method. The resolution
//! chart ([`time_against_width`]) draws time per image against image width.

mod scaling;

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use shadow_core::{Error, Result};

use crate::io::{write_atomic, write_png_atomic};
pub use scaling::{WidthLine, WidthPanel, time_against_width};

/// DejaVu Sans (free licence, see assets/fonts), embedded so that charts need
/// no system font libraries.
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

const WIDTH: u32 = 1100;
const HEIGHT: u32 = 720;

/// One point of a chart: a configuration (`series`, one colour each) on a
/// scene (`label`, written beside the point).
#[derive(Clone, Debug)]
pub struct Point {
    pub series: String,
    pub label: String,
    /// Relative error, in percent.
    pub error_percent: f64,
    /// Time per frame, in milliseconds.
    pub frame_ms: f64,
}

/// What a chart says on its axes.
#[derive(Clone, Copy, Debug)]
pub struct Axes<'a> {
    pub title: &'a str,
    pub error: &'a str,
    pub time: &'a str,
}

impl Axes<'_> {
    /// The report's, per vertex: exit radiance against the converged reference.
    pub const RADIANCE: Axes<'static> = Axes {
        title: "Per vertex: time per frame against error (lower left is better)",
        error: "relative L2 error over vertices against the reference (%)",
        time: "update + shade per frame (ms)",
    };

    /// The report's, per pixel.
    pub const IMAGE: Axes<'static> = Axes {
        title: "Per pixel: time per image against error (lower left is better)",
        error: "relative L2 error over covered pixels against the reference (%)",
        time: "update + render per image (ms)",
    };
}

/// Makes the embedded font plotters' "sans-serif". Registering twice is
/// harmless: the first registration stays.
pub(crate) fn register_font() -> std::result::Result<(), &'static str> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| "invalid embedded font")
}

/// Charts with more points than this draw them unlabelled: the legend's
/// colours still tell the series apart, and the per-scene charts label
/// theirs.
const MAX_LABELLED: usize = 40;

/// Draws `points` as PNG to `png` and SVG to `svg`, written atomically.
pub fn speed_vs_error(points: &[Point], axes: Axes, png: &Path, svg: &Path) -> Result<()> {
    write_chart(&Scatter { points, axes }, png, svg)
}

/// What a chart's drawing returns: plotters' errors, boxed.
type Drawn = std::result::Result<(), Box<dyn std::error::Error>>;

/// A chart that draws itself the same way on any plotters backend.
trait Chart {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Drawn
    where
        DB::ErrorType: 'static;

    /// Width and height in pixels.
    fn size(&self) -> (u32, u32) {
        (WIDTH, HEIGHT)
    }
}

/// Draws `chart` as PNG to `png` and SVG to `svg`, each written atomically.
fn write_chart(chart: &impl Chart, png: &Path, svg: &Path) -> Result<()> {
    let (width, height) = chart.size();
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
    chart
        .draw(root)
        .map_err(|e| Error::format(png, format!("drawing the chart: {e}")))?;
    write_png_atomic(png, &rgb, width, height)?;
    let mut text = String::new();
    let root = SVGBackend::with_string(&mut text, (width, height)).into_drawing_area();
    chart
        .draw(root)
        .map_err(|e| Error::format(svg, format!("drawing the chart: {e}")))?;
    write_atomic(svg, text.as_bytes())
}

type LogLog = Cartesian2d<LogCoord<f64>, LogCoord<f64>>;

/// The frame every chart draws in: `root` cleared, time per frame against
/// error on log scales over `x` and `y`, the axes labelled as `axes` says.
fn log_log<'a, DB: DrawingBackend + 'a>(
    root: &'a DrawingArea<DB, Shift>,
    axes: Axes,
    x: (f64, f64),
    y: (f64, f64),
) -> std::result::Result<ChartContext<'a, DB, LogLog>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    register_font()?;
    root.fill(&WHITE)?;
    framed(root, axes, x, y, 24)
}

/// A log-log frame on `area` (not cleared), its caption `caption_size`
/// points high.
fn framed<'a, DB: DrawingBackend + 'a>(
    area: &'a DrawingArea<DB, Shift>,
    axes: Axes,
    x: (f64, f64),
    y: (f64, f64),
    caption_size: u32,
) -> std::result::Result<ChartContext<'a, DB, LogLog>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(area)
        .caption(axes.title, ("sans-serif", caption_size))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((x.0..x.1).log_scale(), (y.0..y.1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc(axes.error)
        .y_desc(axes.time)
        .label_style(("sans-serif", 15))
        .draw()?;
    Ok(chart)
}

/// Every point in one cloud, a colour per series.
struct Scatter<'a> {
    points: &'a [Point],
    axes: Axes<'a>,
}

impl Chart for Scatter<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Drawn
    where
        DB::ErrorType: 'static,
    {
        let points = self.points;
        let xy = |p: &Point| (p.error_percent.max(1e-3), p.frame_ms.max(1e-3));
        let x = bounds(points.iter().map(|p| xy(p).0));
        let y = bounds(points.iter().map(|p| xy(p).1));
        let mut chart = log_log(&root, self.axes, x, y)?;

        // One colour per series, one point per scene.
        let mut series: Vec<&str> = Vec::new();
        for p in points {
            if !series.contains(&p.series.as_str()) {
                series.push(&p.series);
            }
        }
        for (i, name) in series.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let mine: Vec<_> = points.iter().filter(|p| p.series == *name).collect();
            chart
                .draw_series(mine.iter().map(|p| Circle::new(xy(p), 6, color.filled())))?
                .label(*name)
                .legend(move |(x, y)| Circle::new((x, y), 6, color.filled()));
            if points.len() > MAX_LABELLED {
                continue;
            }
            chart.draw_series(mine.iter().map(|p| {
                let (x, y) = xy(p);
                Text::new(
                    p.label.clone(),
                    (x * 1.04, y * 1.04),
                    ("sans-serif", 13).into_font().color(&BLACK.mix(0.75)),
                )
            }))?;
        }
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 16)?;
        root.present()?;
        Ok(())
    }
}

/// One setting on a curve.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvePoint {
    pub label: String,
    pub error_percent: f64,
    /// Median milliseconds per frame.
    pub ms: f64,
    /// The fastest and slowest sample, in milliseconds: drawn as a bar.
    pub ms_range: (f64, f64),
}

impl CurvePoint {
    /// A point whose samples all took `ms`.
    pub fn exact(label: &str, error_percent: f64, ms: f64) -> CurvePoint {
        CurvePoint {
            label: label.into(),
            error_percent,
            ms,
            ms_range: (ms, ms),
        }
    }
}

/// One method family's sweep on one scene: its settings in order of cost.
#[derive(Clone, Debug)]
pub struct Curve {
    pub family: String,
    pub points: Vec<CurvePoint>,
    /// The line to beat (the ray tracer): drawn black and dashed.
    pub baseline: bool,
    /// The family's colour (an index into plotters' 99-colour palette),
    /// the same on every chart of a report.
    pub colour: usize,
}

impl Curve {
    /// The points no other point of the curve beats (the family's Pareto
    /// frontier), as a mask over `points`. A point beats another where it
    /// is clearly better on one axis and not clearly worse on the other:
    /// errors differ clearly when by more than `noise_percent` (the
    /// reference's noise), times when one's slowest sample times
    /// [`TIME_TIE`] is below the other's fastest. Differences below that
    /// change between runs, and would move the frontier with them.
    pub fn frontier(&self, noise_percent: f64) -> Vec<bool> {
        let p = &self.points;
        (0..p.len())
            .map(|i| !(0..p.len()).any(|j| j != i && beats(&p[j], &p[i], noise_percent)))
            .collect()
    }
}

/// How much slower than another's slowest sample a setting's fastest must
/// be to count as slower: back-to-back runs of the quick report on a
/// 2-thread host moved a setting's samples by up to a fifth.
pub const TIME_TIE: f64 = 1.25;

/// Whether a setting timed over `a` (fastest, slowest) is clearly faster
/// than one timed over `b`.
pub fn clearly_faster(a: (f64, f64), b: (f64, f64)) -> bool {
    a.1 * TIME_TIE < b.0
}

/// Whether `a` beats `b` (see [`Curve::frontier`]).
fn beats(a: &CurvePoint, b: &CurvePoint, noise_percent: f64) -> bool {
    let more_accurate = a.error_percent < b.error_percent - noise_percent;
    let less_accurate = a.error_percent > b.error_percent + noise_percent;
    let faster = clearly_faster(a.ms_range, b.ms_range);
    let slower = clearly_faster(b.ms_range, a.ms_range);
    (more_accurate && !slower) || (faster && !less_accurate)
}

/// Draws one scene's sweeps as a log-log chart of time per frame against
/// error, one curve per family through its settings, each family's frontier
/// marked by filled points (dominated settings hollow), the baseline dashed,
/// and the reference's noise as a grey band below which errors cannot be
/// told apart. Written as PNG to `png` and SVG to `svg`, atomically.
pub fn pareto(
    curves: &[Curve],
    noise_percent: Option<f64>,
    axes: Axes,
    png: &Path,
    svg: &Path,
) -> Result<()> {
    let chart = Pareto {
        curves,
        noise_percent,
        axes,
    };
    write_chart(&chart, png, svg)
}

/// One scene's curves, their frontiers and the reference's noise.
struct Pareto<'a> {
    curves: &'a [Curve],
    noise_percent: Option<f64>,
    axes: Axes<'a>,
}

impl Chart for Pareto<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Drawn
    where
        DB::ErrorType: 'static,
    {
        let (x, y) = curve_ranges(self.curves.iter(), self.noise_percent);
        let mut chart = log_log(&root, self.axes, x, y)?;
        plot_curves(&mut chart, self.curves, self.noise_percent, x, y)?;
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 16)?;
        root.present()?;
        Ok(())
    }
}

/// The log ranges holding every point of `curves` (with their time bars)
/// and the noise band, with headroom above for the legend.
fn curve_ranges<'a>(
    curves: impl Iterator<Item = &'a Curve> + Clone,
    noise_percent: Option<f64>,
) -> ((f64, f64), (f64, f64)) {
    let all = || curves.clone().flat_map(|c| c.points.iter());
    let x = bounds(
        all()
            .map(|p| p.error_percent.max(1e-3))
            .chain(noise_percent),
    );
    let (y_min, y_max) =
        bounds(all().flat_map(|p| [p.ms_range.0, p.ms_range.1].map(|t| t.max(1e-3))));
    // Headroom above the slowest point for the legend.
    (x, (y_min, y_max * 8.0))
}

/// `curves` on `chart` over the ranges `x` and `y`: the noise band, each
/// family's line, time bars, points (filled on its frontier) and labels.
fn plot_curves<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, LogLog>,
    curves: &[Curve],
    noise_percent: Option<f64>,
    (x_min, _): (f64, f64),
    (y_min, y_max): (f64, f64),
) -> Drawn
where
    DB::ErrorType: 'static,
{
    let xy = |p: &CurvePoint| (p.error_percent.max(1e-3), p.ms.max(1e-3));
    if let Some(noise) = noise_percent.filter(|n| *n > x_min) {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x_min, y_min), (noise, y_max)],
                BLACK.mix(0.08).filled(),
            )))?
            .label("reference noise: errors below cannot be told apart")
            .legend(|(x, y)| {
                Rectangle::new([(x - 6, y - 6), (x + 6, y + 6)], BLACK.mix(0.15).filled())
            });
    }
    for curve in curves {
        let color = if curve.baseline {
            BLACK.to_rgba()
        } else {
            Palette99::pick(curve.colour).to_rgba()
        };
        let points: Vec<(f64, f64)> = curve.points.iter().map(xy).collect();
        let mut sorted = points.clone();
        sorted.sort_by(|a, b| a.1.total_cmp(&b.1));
        let line = if curve.baseline {
            chart.draw_series(DashedLineSeries::new(sorted, 8, 5, color.stroke_width(2)))?
        } else {
            chart.draw_series(LineSeries::new(sorted, color.stroke_width(2)))?
        };
        line.label(curve.family.clone()).legend(move |(x, y)| {
            PathElement::new(vec![(x - 10, y), (x + 10, y)], color.stroke_width(2))
        });
        // Each setting's spread of time: a bar from its fastest to its
        // slowest sample.
        chart.draw_series(
            curve
                .points
                .iter()
                .filter(|p| p.ms_range.1 > p.ms_range.0)
                .map(|p| {
                    let x = xy(p).0;
                    let (lo, hi) = (p.ms_range.0.max(1e-3), p.ms_range.1.max(1e-3));
                    PathElement::new(vec![(x, lo), (x, hi)], color.stroke_width(1))
                }),
        )?;
        let frontier = curve.frontier(noise_percent.unwrap_or(0.0));
        chart.draw_series(points.iter().zip(&frontier).map(|(&p, &best)| {
            let style = if best {
                color.filled()
            } else {
                color.stroke_width(2)
            };
            Circle::new(p, 6, style)
        }))?;
        chart.draw_series(curve.points.iter().zip(&points).map(|(p, &(x, y))| {
            Text::new(
                p.label.clone(),
                (x * 1.05, y * 1.05),
                ("sans-serif", 12).into_font().color(&BLACK.mix(0.7)),
            )
        }))?;
    }
    Ok(())
}

/// One scene of [`small_multiples`]: its title, curves and reference noise.
#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    pub curves: Vec<Curve>,
    pub noise_percent: Option<f64>,
}

/// Panels a row of [`small_multiples`] holds.
const PANELS_PER_ROW: usize = 3;
const PANEL_WIDTH: u32 = 540;
const PANEL_HEIGHT: u32 = 400;
/// The title and the legend above the grid.
const HEADER_HEIGHT: u32 = 80;

/// One small chart per scene on a grid, every one over the same ranges
/// (so that positions compare across scenes), each family in the same
/// colour everywhere with its frontier filled, the legend once above the
/// grid. Written as PNG to `png` and SVG to `svg`, atomically.
pub fn small_multiples(panels: &[Panel], axes: Axes, png: &Path, svg: &Path) -> Result<()> {
    write_chart(&Grid { panels, axes }, png, svg)
}

struct Grid<'a> {
    panels: &'a [Panel],
    axes: Axes<'a>,
}

impl Chart for Grid<'_> {
    fn size(&self) -> (u32, u32) {
        let rows = self.panels.len().div_ceil(PANELS_PER_ROW).max(1) as u32;
        (
            PANEL_WIDTH * PANELS_PER_ROW as u32,
            HEADER_HEIGHT + rows * PANEL_HEIGHT,
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Drawn
    where
        DB::ErrorType: 'static,
    {
        register_font()?;
        root.fill(&WHITE)?;
        let noise = self
            .panels
            .iter()
            .filter_map(|p| p.noise_percent)
            .reduce(f64::max);
        let (x, y) = curve_ranges(self.panels.iter().flat_map(|p| p.curves.iter()), noise);
        let (header, grid) = root.split_vertically(HEADER_HEIGHT);
        header.draw(&Text::new(
            self.axes.title.to_string(),
            (16, 8),
            ("sans-serif", 24).into_font(),
        ))?;
        // The legend: every family once, in its colour.
        let mut families: Vec<&Curve> = Vec::new();
        for curve in self.panels.iter().flat_map(|p| p.curves.iter()) {
            if !families.iter().any(|f| f.family == curve.family) {
                families.push(curve);
            }
        }
        for (i, curve) in families.iter().enumerate() {
            let (left, top) = (16 + 230 * i as i32, 50);
            let color = if curve.baseline {
                BLACK.to_rgba()
            } else {
                Palette99::pick(curve.colour).to_rgba()
            };
            header.draw(&PathElement::new(
                vec![(left, top + 8), (left + 24, top + 8)],
                color.stroke_width(3),
            ))?;
            header.draw(&Text::new(
                curve.family.clone(),
                (left + 32, top),
                ("sans-serif", 16).into_font(),
            ))?;
        }
        let rows = self.panels.len().div_ceil(PANELS_PER_ROW).max(1);
        let cells = grid.split_evenly((rows, PANELS_PER_ROW));
        for (panel, cell) in self.panels.iter().zip(&cells) {
            let axes = Axes {
                title: &panel.title,
                ..self.axes
            };
            let mut chart = framed(cell, axes, x, y, 18)?;
            plot_curves(&mut chart, &panel.curves, panel.noise_percent, x, y)?;
        }
        root.present()?;
        Ok(())
    }
}

/// The legend of a log-log chart, in its upper right corner.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    font_size: u32,
) -> Drawn
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", font_size))
        .draw()?;
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

    #[test]
    fn the_frontier_keeps_what_nothing_beats_on_both_axes() {
        let curve = Curve {
            family: "f".into(),
            points: vec![
                CurvePoint::exact("a", 10.0, 1.0),
                CurvePoint::exact("b", 5.0, 2.0),
                CurvePoint::exact("c", 6.0, 3.0), // beaten by b on both
                CurvePoint::exact("d", 1.0, 9.0),
                CurvePoint::exact("e", 5.0, 2.0), // ties b: neither beats the other
            ],
            baseline: false,
            colour: 0,
        };
        assert_eq!(curve.frontier(0.0), vec![true, true, false, true, true]);
        // Within the reference's noise, c's error ties b's, and neither is
        // clearly faster once their ranges overlap.
        let mut noisy = curve.clone();
        noisy.points[2].ms_range = (1.5, 3.0);
        assert_eq!(noisy.frontier(0.0), vec![true, true, false, true, true]);
        assert_eq!(noisy.frontier(1.5), vec![true, true, true, true, true]);
    }

    #[test]
    fn pareto_charts_are_written_as_png_and_svg() {
        let dir = tempfile::tempdir().unwrap();
        let (png, svg) = (dir.path().join("c.png"), dir.path().join("c.svg"));
        let curves = [
            Curve {
                family: "raytrace".into(),
                points: vec![
                    CurvePoint::exact("4", 20.0, 3.0),
                    CurvePoint {
                        ms_range: (10.0, 15.0),
                        ..CurvePoint::exact("16", 9.0, 12.0)
                    },
                ],
                baseline: true,
                colour: 0,
            },
            Curve {
                family: "hemi-raster".into(),
                points: vec![CurvePoint::exact("pvs", 3.0, 0.5)],
                baseline: false,
                colour: 0,
            },
        ];
        pareto(&curves, Some(0.5), Axes::RADIANCE, &png, &svg).unwrap();
        let img = image::load_from_memory(&std::fs::read(&png).unwrap()).unwrap();
        assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.starts_with("<svg") && text.contains("hemi-raster"));
    }

    fn point(series: &str, label: &str, error_percent: f64, frame_ms: f64) -> Point {
        Point {
            series: series.into(),
            label: label.into(),
            error_percent,
            frame_ms,
        }
    }

    #[test]
    fn writes_a_png_of_the_chart_size_and_an_svg() {
        let dir = tempfile::tempdir().unwrap();
        let (png, svg) = (dir.path().join("chart.png"), dir.path().join("chart.svg"));
        let points = [
            point("unshadowed", "bunny", 20.0, 0.3),
            point("raytrace-16", "bunny", 5.0, 30.0),
            point("raytrace-64", "bunny", 1.0, 120.0),
        ];
        speed_vs_error(&points, Axes::RADIANCE, &png, &svg).unwrap();
        let img = image::load_from_memory(&std::fs::read(&png).unwrap()).unwrap();
        assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
        // Something was drawn: not every pixel is white.
        assert!(img.to_rgb8().pixels().any(|p| p.0 != [255, 255, 255]));
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.starts_with("<svg") && text.contains("raytrace-64"));
    }

    #[test]
    fn small_multiples_hold_every_panel_on_one_canvas() {
        let dir = tempfile::tempdir().unwrap();
        let (png, svg) = (dir.path().join("g.png"), dir.path().join("g.svg"));
        let curve = |family: &str, colour, scale: f64| Curve {
            family: family.into(),
            points: vec![
                CurvePoint::exact("a", 10.0 * scale, 1.0),
                CurvePoint::exact("b", 2.0 * scale, 8.0),
            ],
            baseline: family == "raytrace",
            colour,
        };
        let panels: Vec<Panel> = (0..4)
            .map(|i| Panel {
                title: format!("scene {i}"),
                curves: vec![
                    curve("raytrace", 0, 1.0),
                    curve("hemi-raster", 1, 0.5 + i as f64),
                ],
                noise_percent: Some(0.5),
            })
            .collect();
        small_multiples(&panels, Axes::RADIANCE, &png, &svg).unwrap();
        let img = image::open(&png).unwrap();
        // Two rows of three panels under the header.
        assert_eq!(
            (img.width(), img.height()),
            (3 * PANEL_WIDTH, HEADER_HEIGHT + 2 * PANEL_HEIGHT)
        );
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.contains("scene 3") && text.contains("hemi-raster"));
    }
}
