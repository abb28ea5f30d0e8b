//! The resolution section: each family's standard setting timed per image
//! across widths ([`crate::scaling`]), the power of the width its time
//! grows with, and from which width it overtakes the per-pixel ray tracer
//! at equal error.
//!
//! Equal error: a setting's per-pixel error is the one scored at the
//! report's image width; the ray tracer's time at that error, at each
//! width, is read off its settings' times there against their errors at
//! the scored width (log-log between its settings, Monte-Carlo's time ∝
//! error⁻² beyond them, marked as extrapolated). A method's per-pixel
//! error barely moves with the width: its causes (samples per pixel, map
//! sides, the mesh's vertices) do not depend on it.

use std::path::Path;

use shadow_core::Result;

use super::{Block, Document, Figure, Report};
use crate::{
    chart::{self, WidthLine, WidthPanel},
    scaling::{self, ScalingRun, WidthTime},
    suite::RAY_TRACER,
};

/// The chart's file under `charts/`.
const CHART: &str = "resolution.png";

/// From which width a setting is faster than the ray tracer at its error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Overtakes {
    /// At every width measured.
    Everywhere,
    /// From about this width on (interpolated between the measured widths,
    /// log-log), up to the largest measured.
    From(f64),
    /// At none up to the largest width measured.
    Never,
}

/// A setting's times across widths against the ray tracer's at equal
/// error, on one scene.
#[derive(Clone, Debug)]
pub struct WidthComparison<'a> {
    pub run: &'a ScalingRun,
    /// The power of the width its time grows with ([`scaling::slope`]).
    pub slope: f64,
    /// Its per-pixel error at the report's image width.
    pub error: f32,
    /// Per width: the ray tracer's milliseconds per image at that error, and
    /// whether they are extrapolated beyond its settings' errors.
    pub ray_tracer_ms: Vec<(f64, bool)>,
    pub overtakes: Overtakes,
}

impl Report {
    /// The settings timed across widths on `scene`, in the order they ran.
    pub fn scaling_of<'a>(&'a self, scene: &'a str) -> impl Iterator<Item = &'a ScalingRun> {
        self.scaling.iter().filter(move |s| s.scene == scene)
    }

    /// Each setting timed across widths on `scene` but the ray tracer's,
    /// compared with the ray tracer at its error; none where the ray tracer
    /// or the setting's scored image is missing.
    pub fn width_comparisons<'a>(&'a self, scene: &'a str) -> Vec<WidthComparison<'a>> {
        let error_of = |setting: &str| {
            self.runs_of(scene)
                .find(|r| r.setting == setting)
                .and_then(|r| r.result.mean_image_error())
                .filter(|e| e.is_finite() && *e > 0.0)
        };
        // The ray tracer's per-pixel settings: their errors, and times per width.
        let tracers: Vec<(f32, &ScalingRun)> = self
            .scaling_of(scene)
            .filter(|s| s.family == RAY_TRACER && s.per_pixel)
            .filter_map(|s| Some((error_of(&s.setting)?, s)))
            .collect();
        if tracers.is_empty() {
            return Vec::new();
        }
        self.scaling_of(scene)
            .filter(|s| s.family != RAY_TRACER)
            .filter_map(|run| {
                let error = error_of(&run.setting)?;
                let ray_tracer_ms: Option<Vec<(f64, bool)>> = run
                    .widths
                    .iter()
                    .map(|w| {
                        let at: Vec<(f32, f64)> = tracers
                            .iter()
                            .filter_map(|(e, s)| Some((*e, ms_at(s, w.width)?)))
                            .collect();
                        equal_error_ms(&at, error)
                    })
                    .collect();
                let ray_tracer_ms = ray_tracer_ms.filter(|ms| !ms.is_empty())?;
                let ratios: Vec<(f64, f64)> = run
                    .widths
                    .iter()
                    .zip(&ray_tracer_ms)
                    .map(|(w, rt)| (f64::from(w.width), w.time.median() * 1e3 / rt.0))
                    .collect();
                Some(WidthComparison {
                    run,
                    slope: scaling::slope(&run.widths),
                    error,
                    ray_tracer_ms,
                    overtakes: overtakes(&ratios),
                })
            })
            .collect()
    }

    /// The scenes timed across widths, in the report's order.
    fn scaling_scenes(&self) -> Vec<&str> {
        self.scenes()
            .into_iter()
            .filter(|s| self.scaling_of(s).next().is_some())
            .collect()
    }

    /// The resolution chart, under `dir/charts/`, when any scene was timed
    /// across widths.
    pub(super) fn write_resolution_chart(&self, dir: &Path) -> Result<()> {
        let scenes = self.scaling_scenes();
        if scenes.is_empty() {
            return Ok(());
        }
        let panels: Vec<WidthPanel> = scenes
            .iter()
            .map(|scene| WidthPanel {
                title: scene.to_string(),
                lines: self
                    .scaling_of(scene)
                    .map(|s| WidthLine {
                        label: format!("{} (slope {:.2})", s.setting, scaling::slope(&s.widths)),
                        points: s
                            .widths
                            .iter()
                            .map(|w| {
                                let t = &w.time;
                                (
                                    f64::from(w.width),
                                    t.median() * 1e3,
                                    (t.min() * 1e3, t.max() * 1e3),
                                )
                            })
                            .collect(),
                        baseline: s.family == RAY_TRACER,
                        colour: self.colour_of(&s.family),
                    })
                    .collect(),
            })
            .collect();
        let png = dir.join("charts").join(CHART);
        chart::time_against_width(
            &panels,
            "Time per image against image width (log-log)",
            &png,
            &png.with_extension("svg"),
        )
    }

    /// The resolution section (its chart written by
    /// [`Report::write_resolution_chart`]).
    pub(super) fn resolution_blocks(&self, doc: &mut Document) {
        let scenes = self.scaling_scenes();
        if scenes.is_empty() {
            return;
        }
        let width = self.settings.image_width;
        doc.push(Block::Heading(2, "Resolution".into()));
        doc.push(Block::Paragraph(format!(
            "Each family's standard setting and the per-pixel ray tracer's settings, timed per \
             image (update + render of a fresh frame, the first frame of each scene) at each \
             width, the camera's aspect kept; the slope is the power of the width the time grows \
             with (0: work per frame, 2: work per pixel). \"At equal error\" compares a setting \
             with the ray tracer at the setting's per-pixel error as scored at {width} pixels: the \
             ray tracer's time there is read off its settings' times against their errors \
             (log-log between them; beyond them, Monte Carlo's time ∝ error⁻², marked ≈)."
        )));
        doc.push(Block::Figures(vec![Figure {
            path: format!("charts/{CHART}"),
            caption: "time per image against width; the ray tracer dashed".into(),
        }]));
        for scene in scenes {
            doc.push(Block::Heading(3, format!("Resolution: {scene}")));
            doc.push(Block::Table(self.resolution_table(scene)));
            let sentences = self.resolution_sentences(scene);
            if !sentences.is_empty() {
                doc.push(Block::Bullets(sentences));
            }
        }
    }

    fn resolution_table(&self, scene: &str) -> super::Table {
        let comparisons = self.width_comparisons(scene);
        let runs: Vec<&ScalingRun> = self.scaling_of(scene).collect();
        let (first, last) = match runs.first().map(|r| &r.widths[..]) {
            Some([first, .., last]) => (first.width, last.width),
            Some([only]) => (only.width, only.width),
            _ => (0, 0),
        };
        let at = |w: u32| format!("ms at {w}#");
        let (ms_first, ms_last, rt_last) = (
            at(first),
            at(last),
            format!("ray tracer at equal error, ms at {last}#"),
        );
        let mut table = super::Table::new(&[
            "setting",
            "per-pixel error#",
            &ms_first,
            &ms_last,
            "slope#",
            &rt_last,
            "overtakes the ray tracer",
        ]);
        for run in runs {
            let ms = |w: Option<&WidthTime>| {
                w.map_or("–".into(), |w| {
                    let t = &w.time;
                    format!(
                        "{:.1} ({:.1}–{:.1})",
                        t.median() * 1e3,
                        t.min() * 1e3,
                        t.max() * 1e3
                    )
                })
            };
            let comparison = comparisons.iter().find(|c| std::ptr::eq(c.run, run));
            let error = self
                .runs_of(scene)
                .find(|r| r.setting == run.setting)
                .and_then(|r| r.result.mean_image_error())
                .map_or("–".into(), |e| format!("{:.2}%", e * 100.0));
            let (rt, overtakes) = match comparison {
                Some(c) => {
                    let (ms, extrapolated) = c.ray_tracer_ms.last().copied().unwrap_or_default();
                    (
                        format!("{}{ms:.1}", if extrapolated { "≈" } else { "" }),
                        describe(c.overtakes, first, last),
                    )
                }
                None if run.family == RAY_TRACER => ("–".into(), "(the ray tracer)".into()),
                None => ("–".into(), "–".into()),
            };
            table.row(vec![
                run.setting.clone(),
                error,
                ms(run.widths.first()),
                ms(run.widths.last()),
                format!("{:.2}", scaling::slope(&run.widths)),
                rt,
                overtakes,
            ]);
        }
        table
    }

    /// One sentence per setting that overtakes the ray tracer somewhere,
    /// from the figures measured.
    pub(super) fn resolution_sentences(&self, scene: &str) -> Vec<String> {
        self.width_comparisons(scene)
            .iter()
            .filter_map(|c| {
                let last = c.run.widths.last()?;
                let (rt, extrapolated) = *c.ray_tracer_ms.last()?;
                let figures = format!(
                    "{:.1} ms against the ray tracer's {}{rt:.1} ms at {} pixels",
                    last.time.median() * 1e3,
                    if extrapolated { "≈" } else { "" },
                    last.width
                );
                let error = format!("{:.2}% per pixel", c.error * 100.0);
                match c.overtakes {
                    Overtakes::Everywhere => Some(format!(
                        "On {scene}, {} ({error}) is faster than the ray tracer at its error at \
                         every width from {} pixels: {figures}.",
                        c.run.setting, c.run.widths[0].width
                    )),
                    Overtakes::From(w) => Some(format!(
                        "On {scene}, {} ({error}) overtakes the ray tracer at its error from about \
                         {w:.0} pixels wide: {figures}.",
                        c.run.setting
                    )),
                    Overtakes::Never => None,
                }
            })
            .collect()
    }

    /// The family's colour on every chart: its index among the families.
    fn colour_of(&self, family: &str) -> usize {
        self.families
            .iter()
            .position(|f| f.family == family)
            .unwrap_or(self.families.len())
    }
}

/// The median milliseconds of `run` at `width`, if timed there.
fn ms_at(run: &ScalingRun, width: u32) -> Option<f64> {
    let w = run.widths.iter().find(|w| w.width == width)?;
    Some(w.time.median() * 1e3)
}

/// The ray tracer's milliseconds at `error`, from its settings' (error,
/// milliseconds) `at` one width: log-log between the two settings around
/// `error`, time ∝ error⁻² from the nearest beyond them (then `true`).
pub fn equal_error_ms(at: &[(f32, f64)], error: f32) -> Option<(f64, bool)> {
    let mut points: Vec<(f64, f64)> = at
        .iter()
        .filter(|(e, t)| *e > 0.0 && *t > 0.0)
        .map(|&(e, t)| (f64::from(e).ln(), t.ln()))
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let e = f64::from(error).ln();
    let (lowest, highest) = (points.first()?, points.last()?);
    let beyond = |p: &(f64, f64)| Some(((p.1 - 2.0 * (e - p.0)).exp(), true));
    if e < lowest.0 {
        return beyond(lowest);
    }
    if e > highest.0 {
        return beyond(highest);
    }
    if points.len() == 1 {
        return Some((lowest.1.exp(), false));
    }
    let i = points
        .partition_point(|p| p.0 < e)
        .clamp(1, points.len() - 1);
    let (a, b) = (points[i - 1], points[i]);
    let t = if b.0 > a.0 {
        a.1 + (e - a.0) / (b.0 - a.0) * (b.1 - a.1)
    } else {
        a.1.min(b.1)
    };
    Some((t.exp(), false))
}

/// From the (width, time ÷ the ray tracer's) of a setting, in order of
/// width: from where on it stays below 1.
pub fn overtakes(ratios: &[(f64, f64)]) -> Overtakes {
    let Some(behind) = ratios.iter().rposition(|r| r.1 >= 1.0) else {
        return Overtakes::Everywhere;
    };
    if behind + 1 == ratios.len() {
        return Overtakes::Never;
    }
    let ((w0, r0), (w1, r1)) = (ratios[behind], ratios[behind + 1]);
    let (l0, l1) = (r0.ln(), r1.ln());
    let f = if l0 > l1 { l0 / (l0 - l1) } else { 1.0 };
    Overtakes::From((w0.ln() + f * (w1.ln() - w0.ln())).exp())
}

/// The table's cell for `overtakes` over widths `first` to `last`.
fn describe(overtakes: Overtakes, first: u32, last: u32) -> String {
    match overtakes {
        Overtakes::Everywhere => format!("at every width from {first}"),
        Overtakes::From(w) => format!("from ≈{w:.0} px"),
        Overtakes::Never => format!("not up to {last}"),
    }
}
