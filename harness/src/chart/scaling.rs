//! Time per image against image width, log-log: one panel per scene, a line
//! per setting through its widths (its samples' range as a bar at each),
//! the ray tracer's settings dashed in greys. A line's slope is the power
//! of the width its time grows with: 2 for work per pixel, 0 for work per
//! frame.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use shadow_core::Result;

use super::{Chart, Drawn, bounds, draw_legend, register_font, write_chart};

/// One setting's times across widths.
#[derive(Clone, Debug)]
pub struct WidthLine {
    /// The legend's text (the setting and its fitted slope).
    pub label: String,
    /// Width in pixels, median milliseconds, and the fastest and slowest
    /// sample's.
    pub points: Vec<(f64, f64, (f64, f64))>,
    /// A ray tracer's line: dashed, grey.
    pub baseline: bool,
    /// The family's colour (plotters' 99-colour palette), as on the
    /// report's other charts.
    pub colour: usize,
}

/// One scene's lines.
#[derive(Clone, Debug)]
pub struct WidthPanel {
    pub title: String,
    pub lines: Vec<WidthLine>,
}

const PANEL_WIDTH: u32 = 760;
const PANEL_HEIGHT: u32 = 620;

/// Draws `panels` side by side over the same ranges, written as PNG to
/// `png` and SVG to `svg`, atomically.
pub fn time_against_width(
    panels: &[WidthPanel],
    title: &str,
    png: &Path,
    svg: &Path,
) -> Result<()> {
    write_chart(&Panels { panels, title }, png, svg)
}

struct Panels<'a> {
    panels: &'a [WidthPanel],
    title: &'a str,
}

impl Chart for Panels<'_> {
    fn size(&self) -> (u32, u32) {
        (
            PANEL_WIDTH * self.panels.len().max(1) as u32,
            PANEL_HEIGHT + 40,
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Drawn
    where
        DB::ErrorType: 'static,
    {
        register_font()?;
        root.fill(&WHITE)?;
        let all = || {
            self.panels
                .iter()
                .flat_map(|p| &p.lines)
                .flat_map(|l| &l.points)
        };
        let x = bounds(all().map(|p| p.0));
        let x = (x.0 * 1.6, x.1 / 1.4);
        let (y_min, y_max) = bounds(all().flat_map(|p| [p.2.0, p.2.1]).map(|t| t.max(1e-3)));
        // The measured widths label the axis.
        let mut widths: Vec<f64> = all().map(|p| p.0).collect();
        widths.sort_by(f64::total_cmp);
        widths.dedup();
        let (header, grid) = root.split_vertically(40);
        header.draw(&Text::new(
            self.title.to_string(),
            (16, 8),
            ("sans-serif", 24).into_font(),
        ))?;
        let cells = grid.split_evenly((1, self.panels.len().max(1)));
        for (panel, cell) in self.panels.iter().zip(&cells) {
            let mut chart = ChartBuilder::on(cell)
                .caption(&panel.title, ("sans-serif", 20))
                .margin(16)
                .x_label_area_size(48)
                .y_label_area_size(72)
                .build_cartesian_2d(
                    (x.0..x.1).log_scale().with_key_points(widths.clone()),
                    (y_min..y_max * 3.0).log_scale(),
                )?;
            chart
                .configure_mesh()
                .x_desc("image width (pixels)")
                .y_desc("update + render per image (ms)")
                .x_label_formatter(&|w| format!("{w:.0}"))
                .label_style(("sans-serif", 15))
                .draw()?;
            let baselines = panel.lines.iter().filter(|l| l.baseline).count().max(1);
            let mut grey = 0;
            for line in &panel.lines {
                let color = if line.baseline {
                    grey += 1;
                    BLACK.mix(0.35 + 0.65 * grey as f64 / baselines as f64)
                } else {
                    Palette99::pick(line.colour).to_rgba()
                };
                let points: Vec<(f64, f64)> =
                    line.points.iter().map(|p| (p.0, p.1.max(1e-3))).collect();
                let drawn = if line.baseline {
                    chart.draw_series(DashedLineSeries::new(
                        points.clone(),
                        8,
                        5,
                        color.stroke_width(2),
                    ))?
                } else {
                    chart.draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
                };
                drawn.label(line.label.clone()).legend(move |(x, y)| {
                    PathElement::new(vec![(x - 10, y), (x + 10, y)], color.stroke_width(2))
                });
                chart.draw_series(line.points.iter().map(|p| {
                    let (lo, hi) = (p.2.0.max(1e-3), p.2.1.max(1e-3));
                    PathElement::new(vec![(p.0, lo), (p.0, hi)], color.stroke_width(1))
                }))?;
                chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
        }
        root.present()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn width_charts_are_written_as_png_and_svg() {
        let dir = tempfile::tempdir().unwrap();
        let (png, svg) = (dir.path().join("w.png"), dir.path().join("w.svg"));
        let line = |label: &str, slope: f64, baseline| WidthLine {
            label: label.into(),
            points: [160.0, 512.0, 1024.0]
                .map(|w: f64| {
                    let ms = (w / 160.0).powf(slope);
                    (w, ms, (ms * 0.9, ms * 1.2))
                })
                .to_vec(),
            baseline,
            colour: 2,
        };
        let panels = [
            WidthPanel {
                title: "bunny".into(),
                lines: vec![
                    line("a (slope 0.1)", 0.1, false),
                    line("rt (slope 2.0)", 2.0, true),
                ],
            },
            WidthPanel {
                title: "human".into(),
                lines: vec![line("a (slope 0.5)", 0.5, false)],
            },
        ];
        time_against_width(&panels, "Time against width", &png, &svg).unwrap();
        let image = image::load_from_memory(&std::fs::read(&png).unwrap()).unwrap();
        assert_eq!(image.width(), 2 * PANEL_WIDTH);
        assert!(
            std::fs::read_to_string(&svg)
                .unwrap()
                .contains("rt (slope 2.0)")
        );
    }
}
