//! The stability atlas: every family's standard setting on the stress
//! scenes ([`crate::scenes::stress`]), each built to break something, with
//! the error percentiles, where on the surface the method fails (the error
//! heat map of its image) and one sentence on why, from what the run
//! measured. Where a family fails ([`AtlasRun::fails`]), its best setting
//! among the suite's remedies for it ([`crate::suite::remedies`]) runs
//! beside the standard one: what to do instead.

use serde::{Deserialize, Serialize};

use super::{Block, Document, Report, ReportRun, Table};
use crate::run::RunResult;
use crate::scenes::stress::twin_of;
use crate::{methods::MethodSpec, reference::ReferenceInfo};

/// A stress scene of the atlas and its reference.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AtlasScene {
    pub name: String,
    /// What the scene is built to break.
    pub breaks: String,
    pub reference: ReferenceInfo,
}

/// What a method did on a stress scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum Outcome {
    Ran(Box<RunResult>),
    /// The method refused the scene; the message names the capability or
    /// input at fault.
    Refused(String),
}

impl Outcome {
    /// The run, if the method ran.
    pub fn ran(&self) -> Option<&RunResult> {
        match self {
            Outcome::Ran(run) => Some(run),
            Outcome::Refused(_) => None,
        }
    }
}

/// One method on one stress scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AtlasRun {
    pub scene: String,
    pub family: String,
    pub setting: String,
    pub outcome: Outcome,
    /// One sentence on how it fared and why, from the measurements.
    pub diagnosis: String,
    /// For the best remedy of a failing setting: that setting.
    pub remedy_for: Option<String>,
}

impl AtlasRun {
    /// `spec`'s outcome on `scene`, not yet judged
    /// ([`Report::judge_atlas`] writes its diagnosis).
    pub fn new(scene: &str, spec: &MethodSpec, outcome: Outcome) -> AtlasRun {
        AtlasRun {
            scene: scene.to_string(),
            family: spec.family().to_string(),
            setting: spec.name().to_string(),
            outcome,
            diagnosis: String::new(),
            remedy_for: None,
        }
    }

    /// `spec`'s outcome as a remedy tried where `failing` failed.
    pub fn remedy(failing: &AtlasRun, spec: &MethodSpec, outcome: Outcome) -> AtlasRun {
        AtlasRun {
            remedy_for: Some(failing.setting.clone()),
            ..AtlasRun::new(&failing.scene, spec, outcome)
        }
    }

    /// The best of the remedies `tried` for `failing` on its scene (the
    /// lowest mean error of those that ran), with its diagnosis; `None`
    /// when none ran.
    pub fn best_remedy(failing: &AtlasRun, tried: &[AtlasRun]) -> Option<AtlasRun> {
        let tried: Vec<&AtlasRun> = tried
            .iter()
            .filter(|r| r.scene == failing.scene && r.remedy_for.as_ref() == Some(&failing.setting))
            .collect();
        let names: Vec<&str> = tried.iter().map(|r| r.setting.as_str()).collect();
        let (best, error) = tried
            .iter()
            .filter_map(|r| Some((r, r.mean_error().filter(|e| e.is_finite())?)))
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        let standard = failing.mean_error().unwrap_or(f32::NAN);
        // A remedy within a twentieth of the failing error does not help.
        let verdict = if error < 0.95 * standard {
            "the best of"
        } else {
            "nothing better among"
        };
        let diagnosis = format!(
            "{}: {verdict} {} here, {:.1}% error against {}'s {:.1}%.",
            best.setting,
            names.join(", "),
            error * 100.0,
            failing.setting,
            standard * 100.0
        );
        Some(AtlasRun {
            diagnosis,
            ..(*best).clone()
        })
    }

    fn mean_error(&self) -> Option<f32> {
        self.outcome.ran().map(RunResult::mean_error)
    }

    /// Whether the setting failed on its scene: non-finite radiance, or a
    /// mean error above [`FAILURE_FLOOR`] and above [`FAILURE_FACTOR`] times
    /// its median on the standard scenes (10% when it ran on none). A
    /// refusal is not a failure: the capability it names is what is
    /// missing.
    pub fn fails(&self, standard: &[ReportRun]) -> bool {
        let Some(error) = self.mean_error() else {
            return false;
        };
        let mut typical: Vec<f32> = standard
            .iter()
            .filter(|r| r.setting == self.setting)
            .map(|r| r.result.mean_error())
            .collect();
        typical.sort_by(f32::total_cmp);
        let limit = typical
            .get(typical.len() / 2)
            .map_or(0.10, |&t| (FAILURE_FACTOR * t).max(FAILURE_FLOOR));
        !error.is_finite() || error > limit
    }

    /// Whether [`AtlasRun::fails`] may hold once the standard scenes are
    /// known: non-finite radiance or a mean error above [`FAILURE_FLOOR`].
    /// A part of a sharded report runs the remedies of every such setting.
    pub fn may_fail(&self) -> bool {
        self.mean_error()
            .is_some_and(|e| !e.is_finite() || e > FAILURE_FLOOR)
    }
}

/// The atlas as the report shows it: each standard setting's run of
/// `atlas` (remedies there are dropped) with its diagnosis against
/// `standard`, and after each that fails the best of its remedies among
/// `tried`. Depends on nothing else, so a report merged from parts judges
/// as one run does.
pub fn judge(atlas: &[AtlasRun], tried: &[AtlasRun], standard: &[ReportRun]) -> Vec<AtlasRun> {
    let mut judged = Vec::new();
    for run in atlas.iter().filter(|r| r.remedy_for.is_none()) {
        let twin = twin_of(&run.scene).and_then(|twin| {
            let on_twin = atlas
                .iter()
                .find(|r| r.scene == twin && r.setting == run.setting && r.remedy_for.is_none())?;
            Some((twin, on_twin.mean_error()?))
        });
        let mut diagnosis = diagnose(&run.setting, &run.outcome, standard);
        if let (Some((twin, twin_error)), Some(error)) = (twin, run.mean_error()) {
            diagnosis = format!(
                "{} It gives {:.2}× its error on the plain twin {twin} ({:.2}%){}.",
                diagnosis,
                error / twin_error,
                twin_error * 100.0,
                if error > TWIN_FACTOR * twin_error {
                    ", more than the twin allows: a tolerance taken from the scene's size or place"
                } else {
                    ""
                }
            );
        }
        let run = AtlasRun {
            diagnosis,
            ..run.clone()
        };
        let remedy = run
            .fails(standard)
            .then(|| AtlasRun::best_remedy(&run, tried))
            .flatten();
        judged.push(run);
        judged.extend(remedy);
    }
    judged
}

/// How many times its error on the standard scenes (the median) a setting
/// may reach on a stress scene before it counts as failing there.
pub const FAILURE_FACTOR: f32 = 2.0;

/// The mean error below which no setting fails on a stress scene.
pub const FAILURE_FLOOR: f32 = 0.05;

/// How many times its error on a stress scene's plain twin
/// ([`crate::scenes::stress::TWINS`]) a setting may reach on the moved,
/// scaled or enlarged scene.
pub const TWIN_FACTOR: f32 = 1.25;

/// The sentence: how the mean error compares with the setting's median on
/// the standard scenes, whether the error is everywhere or concentrated in
/// a few vertices, and whether it jumps between frames.
fn diagnose(setting: &str, outcome: &Outcome, standard: &[ReportRun]) -> String {
    let run = match outcome {
        Outcome::Refused(why) => return format!("{setting} refuses the scene: {why}."),
        Outcome::Ran(run) => run,
    };
    let mean = run.mean_error();
    let worst = |f: fn(&crate::score::ErrorStats) -> f32| {
        run.frames
            .iter()
            .map(|f2| f(&f2.vertex))
            .fold(0.0, f32::max)
    };
    let (p50, p99) = (worst(|e| e.p50), worst(|e| e.p99));
    let noise = run
        .frames
        .iter()
        .map(|f| f.vertex.reference_noise)
        .fold(0.0, f32::max);
    if !mean.is_finite() || !p99.is_finite() {
        return format!("{setting} returns non-finite radiance on this scene.");
    }
    let mut typical: Vec<f32> = standard
        .iter()
        .filter(|r| r.setting == setting)
        .map(|r| r.result.mean_error())
        .collect();
    typical.sort_by(f32::total_cmp);
    let compared = match typical.get(typical.len() / 2) {
        Some(&t) if t > 0.0 => format!(
            "{:.1}% error, {:.1}× its median on the standard scenes ({:.1}%)",
            mean * 100.0,
            mean / t,
            t * 100.0
        ),
        _ => format!("{:.1}% error", mean * 100.0),
    };
    let spread = if p50 <= (2.0 * noise).max(0.02) && p99 > 10.0 * p50.max(noise) && p99 > 0.05 {
        format!(
            "most vertices are right (median {:.1}%) but the worst 1% reach {:.0}%: a local failure, \
             which the error map places",
            p50 * 100.0,
            p99 * 100.0
        )
    } else if mean < 2.0 * noise.max(0.005) {
        "indistinguishable from the reference's noise".to_string()
    } else {
        format!(
            "the error is spread over the surface (median {:.1}%, worst 1% {:.0}%)",
            p50 * 100.0,
            p99 * 100.0
        )
    };
    let flicker = run.worst_temporal().filter(|t| {
        t.error_change > 3.0 * t.noise_floor && t.error_change > 0.5 * t.reference_change
    });
    let flicker = flicker.map_or(String::new(), |t| {
        format!(
            "; its error jumps between frames by {:.1}% where the reference itself moves {:.1}%",
            t.error_change * 100.0,
            t.reference_change * 100.0
        )
    });
    format!("{setting}: {compared}; {spread}{flicker}.")
}

/// The atlas's section of the report.
pub(super) fn blocks(doc: &mut Document, report: &Report) {
    if report.atlas_scenes.is_empty() {
        return;
    }
    doc.push(Block::Heading(2, "Stability atlas".into()));
    doc.push(Block::Paragraph(
        "Each family's standard setting on scenes built to break something. Per-vertex relative \
         error percentiles (worst frame), flicker, and a sentence from the measurements. Where a \
         setting fails (above 5% and twice its median error on the standard scenes), the best of \
         its family's remedies on that scene follows it, marked \"instead of\", and pictures of \
         both show where it fails, beside their error maps (0.1% to 100%, logarithmic)."
            .into(),
    ));
    for scene in &report.atlas_scenes {
        doc.push(Block::Heading(3, format!("Stress: {}", scene.name)));
        doc.push(Block::Paragraph(format!(
            "Built to break {} (reference noise {:.2}% per vertex).",
            scene.breaks,
            scene.reference.noise * 100.0
        )));
        let mut table = Table::new(&[
            "setting", "error#", "p50#", "p90#", "p99#", "max#", "flicker#", "why",
        ]);
        let runs: Vec<&AtlasRun> = report
            .atlas
            .iter()
            .filter(|r| r.scene == scene.name)
            .collect();
        for run in &runs {
            let percent = |v: f32| format!("{:.1}%", v * 100.0);
            match &run.outcome {
                Outcome::Refused(_) => table.row(vec![
                    run.setting.clone(),
                    "refused".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    run.diagnosis.clone(),
                ]),
                Outcome::Ran(r) => {
                    let worst = |f: fn(&crate::score::ErrorStats) -> f32| {
                        r.frames.iter().map(|fr| f(&fr.vertex)).fold(0.0, f32::max)
                    };
                    let setting = match &run.remedy_for {
                        Some(standard) => format!("{} (instead of {standard})", run.setting),
                        None => run.setting.clone(),
                    };
                    table.row(vec![
                        setting,
                        percent(r.mean_error()),
                        percent(worst(|e| e.p50)),
                        percent(worst(|e| e.p90)),
                        percent(worst(|e| e.p99)),
                        percent(worst(|e| e.max)),
                        r.worst_temporal()
                            .map_or("–".into(), |t| percent(t.error_change)),
                        run.diagnosis.clone(),
                    ]);
                }
            }
        }
        doc.push(Block::Table(table));
        for block in super::gallery::atlas_rows(report, &scene.name, &runs) {
            doc.push(block);
        }
    }
}
