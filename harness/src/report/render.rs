//! The report's files: charts, tables, the Markdown and HTML document.

use std::path::Path;

use serde::Serialize;

use shadow_core::Result;

use super::analyse::Domain;
use super::recommend::{Budget, MARGIN, Recommendation};
use super::{Block, Document, Figure, Report, ReportRun, Table, atlas};
use crate::{
    chart::{self, Axes, Panel},
    io::{write_atomic, write_json_atomic},
    run::FrameResult,
    score::ErrorStats,
    timing::Timing,
};

/// `report.json`: everything measured, and what it recommends.
#[derive(Serialize)]
struct Written<'a> {
    #[serde(flatten)]
    report: &'a Report,
    recommendations: Vec<Recommendation>,
}

impl<'a> Written<'a> {
    fn new(report: &'a Report) -> Written<'a> {
        Written {
            report,
            recommendations: report.recommendations(),
        }
    }
}

/// The overall charts: every scene's curves as small multiples on shared
/// axes, per vertex and per pixel.
const OVERVIEW: [&str; 2] = ["scenes-vertex.png", "scenes-image.png"];

impl Report {
    /// Writes every file of the report into `dir` (see the module docs).
    pub fn write(&self, dir: &Path) -> Result<()> {
        for (domain, file) in [Domain::Vertex, Domain::Image].into_iter().zip(OVERVIEW) {
            let mut panels = Vec::new();
            for scene in self.scenes() {
                let curves = self.curves(scene, domain);
                if curves.is_empty() {
                    continue;
                }
                let noise = self.references.iter().find(|r| r.scene == scene);
                let noise = noise.and_then(|r| match domain {
                    Domain::Vertex => Some(f64::from(r.noise) * 100.0),
                    Domain::Image => r.image.as_ref().map(|i| f64::from(i.noise) * 100.0),
                });
                let stem = dir.join("charts").join(format!("{scene}-{}", domain.key()));
                let title = format!("{scene}: {}", domain.axes().title);
                let axes = Axes {
                    title: &title,
                    ..domain.axes()
                };
                chart::pareto(
                    &curves,
                    noise,
                    axes,
                    &stem.with_extension("png"),
                    &stem.with_extension("svg"),
                )?;
                panels.push(Panel {
                    title: scene.to_string(),
                    curves,
                    noise_percent: noise,
                });
            }
            if !panels.is_empty() {
                let png = dir.join("charts").join(file);
                chart::small_multiples(&panels, domain.axes(), &png, &png.with_extension("svg"))?;
            }
        }
        self.write_resolution_chart(dir)?;
        write_json_atomic(&dir.join("report.json"), &Written::new(self))?;
        write_atomic(&dir.join("report.csv"), self.runs_table().csv().as_bytes())?;
        let document = self.document(dir);
        write_atomic(&dir.join("report.md"), document.markdown().as_bytes())?;
        write_atomic(&dir.join("index.html"), document.html(dir).as_bytes())
    }

    /// One row per run: the CSV, and per scene the report's tables.
    pub fn runs_table(&self) -> Table {
        self.table_of(self.runs.iter(), true)
    }

    pub(super) fn table_of<'a>(
        &self,
        runs: impl Iterator<Item = &'a ReportRun>,
        with_scene: bool,
    ) -> Table {
        let mut columns = vec![
            "scene",
            "family",
            "setting",
            "vertex error#",
            "p99#",
            "max#",
            "ms per frame#",
            "ms per frame, range",
            "image error#",
            "image p99#",
            "ms per image#",
            "ms per image, range",
            "flicker#",
            "relight ms#",
            "prepare ms#",
            "frontier",
        ];
        if !with_scene {
            columns.remove(0);
        }
        let mut table = Table::new(&columns);
        for run in runs {
            let r = &run.result;
            let worst = |f: fn(&ErrorStats) -> f32,
                         domain: fn(&FrameResult) -> Option<ErrorStats>| {
                let values: Option<Vec<f32>> = r
                    .frames
                    .iter()
                    .map(|fr| domain(fr).map(|e| f(&e)))
                    .collect();
                values.map(|v| v.into_iter().fold(0.0, f32::max))
            };
            let vertex = |fr: &FrameResult| Some(fr.vertex);
            let image = |fr: &FrameResult| fr.image;
            let percent = |v: Option<f32>, digits: usize| {
                v.map_or("–".to_string(), |v| format!("{:.*}%", digits, v * 100.0))
            };
            let ms = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{:.2}", v * 1e3));
            let median = |t: Option<&Timing>| ms(t.map(Timing::median));
            let range = |t: Option<&Timing>| match t {
                None => "–".to_string(),
                Some(t) if t.len() < 2 => format!("{} sample", t.len()),
                Some(t) => format!("{:.2}–{:.2}", t.min() * 1e3, t.max() * 1e3),
            };
            let (frame, image_frame) = (r.frame_time(), r.image_frame_time());
            let evaluated = r.evaluated_fraction();
            let vertex_error = if evaluated < 1.0 {
                format!(
                    "{:.2}% ({:.0}% of vertices)",
                    r.mean_error() * 100.0,
                    evaluated * 100.0
                )
            } else {
                format!("{:.2}%", r.mean_error() * 100.0)
            };
            let flicker = r.worst_temporal().map_or("–".to_string(), |t| {
                format!(
                    "{:.2}% (reference {:.2}%, noise {:.2}%)",
                    t.error_change * 100.0,
                    t.reference_change * 100.0,
                    t.noise_floor * 100.0
                )
            });
            let on_frontier = |domain: Domain| {
                let curves = self.curves(&r.scene, domain);
                curves
                    .iter()
                    .find(|c| c.family == run.family)
                    .and_then(|c| {
                        let i = c
                            .points
                            .iter()
                            .position(|p| p.label == setting_label(&run.setting))?;
                        c.frontier(self.noise_percent(&r.scene, domain))[i].then_some(domain.key())
                    })
            };
            let frontier: Vec<&str> = [Domain::Vertex, Domain::Image]
                .into_iter()
                .filter_map(on_frontier)
                .collect();
            let first = r.frames.first().map(|f| &f.times);
            let mut row = vec![
                r.scene.clone(),
                run.family.clone(),
                run.setting.clone(),
                vertex_error,
                percent(worst(|e| e.p99, vertex), 1),
                percent(worst(|e| e.max, vertex), 1),
                median(Some(&frame)),
                range(Some(&frame)),
                percent(r.mean_image_error(), 2),
                percent(worst(|e| e.p99, image), 1),
                median(image_frame.as_ref()),
                range(image_frame.as_ref()),
                flicker,
                median(first.map(|t| &t.relight)),
                ms(first.map(|t| t.prepare)),
                frontier.join(", "),
            ];
            if !with_scene {
                row.remove(0);
            }
            table.row(row);
        }
        table
    }

    /// The report as a document.
    pub fn document(&self, dir: &Path) -> Document {
        let m = &self.machine;
        let mut doc = Document {
            title: "Soft-shadow methods compared".into(),
            blocks: Vec::new(),
        };
        let adapter = match &m.adapter {
            Some(a) if m.software_adapter() => {
                format!("{a}; its GPU timings are software-rasterized, on the same CPU cores")
            }
            Some(a) => a.clone(),
            None => "none used (CPU methods only)".into(),
        };
        doc.push(Block::Paragraph(format!(
            "Machine: {}, {} threads, {} build. GPU adapter: {adapter}. Suite: {:?}.",
            m.cpu, m.threads, m.profile, self.settings.suite
        )));
        doc.push(Block::Paragraph(
            "Errors are relative L2 errors against the Monte-Carlo reference, averaged over frames: \
             per vertex over the vertices a method evaluated, per pixel over the pixels the reference \
             covers (a pixel the method leaves uncovered counts as zero). p99 and max are per-element \
             relative errors (floor 1% of the RMS radiance), the worst over frames. Time per frame is \
             update + shade per vertex, update + render per image; relighting is timed apart. Each \
             stage is timed at least three times (a still scene's update made fresh each time) and \
             reported as the median, with the range in the tables and as bars on the charts. Flicker is \
             the worst frame-to-frame change of the per-vertex error, sqrt(Σ|e_t − e_t−1|² / Σ|r_t|²), \
             beside how much the reference itself changes and the part the references' noise explains. \
             Each chart draws a family's settings as one curve, filled points on its frontier (no other \
             setting of the family is both faster and more accurate), the ray tracer dashed as the line \
             to beat, and the reference's noise as a grey band."
                .into(),
        ));
        if let Some(summary) = self.summary() {
            doc.push(Block::Heading(2, "Summary".into()));
            doc.push(Block::Paragraph(format!(
                "Per scene and family, the fastest setting whose error is within {:.0}% of the \
                 family's best on that scene, per vertex (error, median time per frame) and per \
                 pixel.",
                (MARGIN - 1.0) * 100.0
            )));
            doc.push(Block::Table(summary));
            let recommendations = self.recommendations();
            doc.push(Block::Heading(2, "Recommendations".into()));
            doc.push(Block::Paragraph(
                "Per scene, for each error budget the fastest setting that meets it, and for each \
                 time budget per frame (on this host) the most accurate setting within it; \
                 \"none\" where no setting run does."
                    .into(),
            ));
            for (domain, what) in [(Domain::Vertex, "Per vertex"), (Domain::Image, "Per pixel")] {
                let table = self.recommendations_table(&recommendations, domain);
                if !table.rows.is_empty() {
                    doc.push(Block::Paragraph(format!("{what}:")));
                    doc.push(Block::Table(table));
                }
            }
            doc.push(Block::Heading(2, "Which method when".into()));
            doc.push(Block::Bullets(self.which_method_when()));
            let overview: Vec<Figure> = OVERVIEW
                .iter()
                .filter(|f| dir.join("charts").join(f).exists())
                .map(|f| Figure {
                    path: format!("charts/{f}"),
                    caption: "every scene on the same axes, a family in one colour everywhere"
                        .into(),
                })
                .collect();
            doc.push(Block::Figures(overview));
        }
        doc.push(Block::Heading(2, "References".into()));
        doc.push(Block::Table(self.references_table()));
        for scene in self.scenes() {
            doc.push(Block::Heading(2, format!("Scene: {scene}")));
            if let Some(spec) = crate::scenes::SCENES.iter().find(|s| s.name == scene) {
                doc.push(Block::Paragraph(format!(
                    "{} (under `{}`).",
                    spec.shows, spec.environment
                )));
            }
            let figures: Vec<Figure> = [Domain::Vertex, Domain::Image]
                .into_iter()
                .map(|d| format!("charts/{scene}-{}.png", d.key()))
                .filter(|p| dir.join(p).exists())
                .map(|path| Figure {
                    caption: format!("{scene}: time against error"),
                    path,
                })
                .collect();
            doc.push(Block::Figures(figures));
            doc.push(Block::Table(self.table_of(self.runs_of(scene), false)));
        }
        let profiled: Vec<String> = (self.runs.iter())
            .filter_map(|run| {
                let r = &run.result;
                let frame = r.frames.get(r.frames.len() / 2)?;
                (!frame.profile.is_empty()).then(|| {
                    format!(
                        "{} on {} (frame {}): {}",
                        run.setting,
                        r.scene,
                        frame.frame,
                        frame.profile.to_string().replace('\n', "; ")
                    )
                })
            })
            .collect();
        if !profiled.is_empty() {
            doc.push(Block::Heading(2, "Where the time goes".into()));
            doc.push(Block::Paragraph(
                "Each method's own breakdown of its stages, on the middle frame (medians over repeats)."
                    .into(),
            ));
            doc.push(Block::Bullets(profiled));
        }
        self.resolution_blocks(&mut doc);
        self.strip_blocks(&mut doc);
        atlas::blocks(&mut doc, self);
        for (heading, list) in [
            ("Failed", &self.failed),
            ("Not run (not supported)", &self.skipped),
        ] {
            if !list.is_empty() {
                doc.push(Block::Heading(2, heading.into()));
                doc.push(Block::Bullets(
                    list.iter()
                        .map(|s| format!("{} on {}: {}", s.method, s.scene, s.why))
                        .collect(),
                ));
            }
        }
        doc.push(Block::Heading(2, "Reproducibility".into()));
        let s = &self.settings;
        let suite = format!("{:?}", s.suite).to_lowercase();
        doc.push(Block::Bullets(vec![
            format!("revision: {}", m.revision.as_deref().unwrap_or("unknown (not a git checkout)")),
            format!("CPU: {} with {}; {} threads; {} build", m.cpu, m.cpu_features.join(", "), m.threads, m.profile),
            format!("GPU adapter: {adapter}"),
            format!(
                "references: seed {:#x}, target relative noise {} per vertex and {} per pixel, images {} pixels wide",
                s.seed, s.target_noise, s.image_target_noise, s.image_width
            ),
            format!("repeats per stage: {}", s.repeats),
            format!(
                "command: `cargo run --release -p harness -- report --suite {suite} --target {} --image-target {} --image-width {} --picture-width {} --seed {} --repeats {}`",
                s.target_noise, s.image_target_noise, s.image_width, s.picture_width, s.seed, s.repeats
            ),
            format!(
                "settings run: {}",
                self.families
                    .iter()
                    .map(|f| {
                        format!("{} ({}): {}", f.family, f.parameter, f.methods.join(", "))
                    })
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        ]));
        if !self.merged_from.is_empty() {
            doc.push(Block::Paragraph(self.parts_note()));
        }
        doc
    }

    /// Which machines a report merged from parts ran on, and whether its
    /// timings compare across them.
    fn parts_note(&self) -> String {
        let count = self.merged_from.len();
        let machines: Vec<String> = self
            .merged_from
            .iter()
            .enumerate()
            .map(|(i, m)| {
                format!(
                    "part {}/{count} on {}, {} threads, {}",
                    i + 1,
                    m.cpu,
                    m.threads,
                    m.adapter.as_deref().unwrap_or("no GPU adapter")
                )
            })
            .collect();
        let same = self.merged_from.iter().all(|m| {
            let first = &self.merged_from[0];
            (&m.cpu, &m.cpu_features, m.threads, &m.adapter)
                == (
                    &first.cpu,
                    &first.cpu_features,
                    first.threads,
                    &first.adapter,
                )
        });
        format!(
            "Merged from {count} parts, each run with `--shard I/{count}`: {}. {}",
            machines.join("; "),
            if same {
                "One kind of machine: times compare across scenes."
            } else {
                "The parts ran on different machines: times compare within a scene, not across \
                 scenes of different parts."
            }
        )
    }

    /// Scenes × families: each family's fastest setting within [`MARGIN`]
    /// of its best error, per vertex and per pixel.
    pub(super) fn summary(&self) -> Option<Table> {
        if self.runs.is_empty() {
            return None;
        }
        let mut columns = vec!["scene"];
        columns.extend(self.families.iter().map(|f| f.family.as_str()));
        let mut table = Table::new(&columns);
        for scene in self.scenes() {
            let mut row = vec![scene.to_string()];
            for family in &self.families {
                let pick = |domain| self.family_pick(scene, &family.family, domain);
                let cell = match (pick(Domain::Vertex), pick(Domain::Image)) {
                    (None, _) => "–".to_string(),
                    (Some((run, v)), image) => {
                        let image = image.map_or(String::new(), |(run, p)| {
                            format!(
                                "; {:.2}% per pixel at {:.1} ms ({})",
                                p.error_percent,
                                p.ms,
                                setting_label(&run.setting)
                            )
                        });
                        format!(
                            "{:.2}% at {:.1} ms ({}){image}",
                            v.error_percent,
                            v.ms,
                            setting_label(&run.setting)
                        )
                    }
                };
                row.push(cell);
            }
            table.row(row);
        }
        Some(table)
    }

    /// Scenes × budgets in one domain: the setting each budget picks.
    fn recommendations_table(&self, recommendations: &[Recommendation], domain: Domain) -> Table {
        let budgets: Vec<Budget> = Budget::all().collect();
        let labels: Vec<String> = budgets.iter().map(|b| b.label()).collect();
        let mut columns = vec!["scene"];
        columns.extend(labels.iter().map(String::as_str));
        let mut table = Table::new(&columns);
        for scene in self.scenes() {
            let mine: Vec<&Recommendation> = recommendations
                .iter()
                .filter(|r| r.scene == scene && r.domain == domain.key())
                .collect();
            if mine.is_empty() {
                continue;
            }
            let mut row = vec![scene.to_string()];
            for budget in &budgets {
                let cell = mine
                    .iter()
                    .find(|r| r.budget == *budget)
                    .and_then(|r| Some((r.setting.as_ref()?, r.score?)))
                    .map_or("none".to_string(), |(setting, s)| {
                        format!("{setting} ({:.2}%, {:.1} ms)", s.error_percent, s.ms)
                    });
                row.push(cell);
            }
            table.row(row);
        }
        table
    }

    fn references_table(&self) -> Table {
        let mut t = Table::new(&[
            "scene",
            "environment",
            "frames#",
            "vertices#",
            "noise#",
            "rays#",
            "seconds#",
            "image",
            "image noise#",
            "image seconds#",
        ]);
        let secs = |cached: bool, seconds: f64| {
            if cached {
                "cached".to_string()
            } else {
                format!("{seconds:.1}")
            }
        };
        for r in &self.references {
            let (size, noise, seconds) = match &r.image {
                Some(i) => (
                    format!("{}×{}", i.width, i.height),
                    format!("{:.3}%", i.noise * 100.0),
                    secs(i.cached, i.seconds),
                ),
                None => ("–".into(), "–".into(), "–".into()),
            };
            t.row(vec![
                r.scene.clone(),
                r.environment.clone(),
                r.frames.to_string(),
                r.vertices.to_string(),
                format!("{:.3}%", r.noise * 100.0),
                r.rays.to_string(),
                secs(r.cached, r.seconds),
                size,
                noise,
                seconds,
            ]);
        }
        t
    }
}

/// A setting's short label on a chart: the options after the family name
/// (`k=66`), or `default`.
pub(super) fn setting_label(setting: &str) -> String {
    setting
        .split_once(':')
        .map_or("default", |(_, options)| options)
        .to_string()
}
