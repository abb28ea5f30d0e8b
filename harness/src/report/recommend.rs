//! What the runs recommend, per scene and domain: the fastest setting that
//! meets each error budget, the most accurate within each time budget, and
//! per family the fastest setting within [`MARGIN`] of its best error;
//! and the sentences of "Which method when", each made from those figures.

use serde::Serialize;

use super::analyse::Domain;
use super::{Report, ReportRun};
use crate::chart::clearly_faster;

/// Errors closer than this (in percent; 10⁻⁶ relative, the rounding of f32
/// radiance summed over a scene) are the same error.
pub const EQUAL_ERRORS_PERCENT: f64 = 1e-4;

/// Error budgets: relative L2 error in percent.
pub const ERROR_BUDGETS: [f64; 3] = [2.0, 5.0, 10.0];

/// Time budgets per frame on the report's host, in milliseconds.
pub const TIME_BUDGETS_MS: [f64; 3] = [1.0, 16.0, 100.0];

/// A family's setting in the summary: the fastest whose error is at most
/// this factor times the family's best on the scene.
pub const MARGIN: f64 = 1.1;

/// A run's figures in one domain: mean error over frames, median time per
/// frame and the range of its samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Score {
    pub error_percent: f64,
    pub ms: f64,
    pub ms_min: f64,
    pub ms_max: f64,
}

/// What a recommendation answers.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Budget {
    /// The fastest setting with at most this error.
    Error { percent: f64 },
    /// The most accurate setting within this time per frame.
    Time { ms: f64 },
}

impl Budget {
    /// Every budget, errors first.
    pub fn all() -> impl Iterator<Item = Budget> {
        let errors = ERROR_BUDGETS.map(|percent| Budget::Error { percent });
        let times = TIME_BUDGETS_MS.map(|ms| Budget::Time { ms });
        errors.into_iter().chain(times)
    }

    /// "≤ 2% error" or "≤ 16 ms".
    pub fn label(self) -> String {
        match self {
            Budget::Error { percent } => format!("≤ {percent}% error"),
            Budget::Time { ms } => format!("≤ {ms} ms"),
        }
    }
}

/// The setting a budget picks on a scene, in one domain.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Recommendation {
    pub scene: String,
    /// `vertex` or `image`.
    pub domain: &'static str,
    pub budget: Budget,
    /// The method name of the setting, `None` when no setting meets the
    /// budget.
    pub setting: Option<String>,
    pub family: Option<String>,
    pub score: Option<Score>,
}

impl Domain {
    /// A run's score in this domain.
    pub(super) fn score(self, run: &ReportRun) -> Option<Score> {
        let (error_percent, time) = self.point(&run.result)?;
        Some(Score {
            error_percent,
            ms: time.median() * 1e3,
            ms_min: time.min() * 1e3,
            ms_max: time.max() * 1e3,
        })
    }
}

/// The run `budget` picks among `runs`, counting as ties what a rerun
/// could reverse: errors within `noise` (the reference's, in percent) and
/// times neither of which is clearly faster. Meeting an error budget, the
/// fastest: of the runs tied with the fastest, the most accurate (ties:
/// the name). Within a time budget, the most accurate: of the runs tied
/// with the most accurate, the fastest (ties: the name). Times tie unless
/// one is [`clearly_faster`].
fn pick<'a>(
    runs: impl Iterator<Item = (&'a ReportRun, Score)>,
    budget: Budget,
    noise: f64,
) -> Option<(&'a ReportRun, Score)> {
    let meeting: Vec<(&ReportRun, Score)> = runs
        .filter(|(_, s)| match budget {
            Budget::Error { percent } => s.error_percent <= percent,
            Budget::Time { ms } => s.ms <= ms,
        })
        .collect();
    let by_name = |a: &(&ReportRun, Score), b: &(&ReportRun, Score)| a.0.setting.cmp(&b.0.setting);
    let fastest_of = |runs: Vec<(&'a ReportRun, Score)>| {
        let fastest = runs
            .iter()
            .map(|(_, s)| *s)
            .min_by(|a, b| a.ms.total_cmp(&b.ms))?;
        runs.into_iter()
            .filter(|(_, s)| {
                !clearly_faster((fastest.ms_min, fastest.ms_max), (s.ms_min, s.ms_max))
            })
            .min_by(|a, b| by_name(a, b))
    };
    let lowest = meeting
        .iter()
        .map(|(_, s)| s.error_percent)
        .min_by(f64::total_cmp)?;
    match budget {
        Budget::Error { .. } => {
            let fastest = meeting
                .iter()
                .map(|(_, s)| *s)
                .min_by(|a, b| a.ms.total_cmp(&b.ms))?;
            let tied: Vec<_> = meeting
                .into_iter()
                .filter(|(_, s)| {
                    !clearly_faster((fastest.ms_min, fastest.ms_max), (s.ms_min, s.ms_max))
                })
                .collect();
            let best = tied
                .iter()
                .map(|(_, s)| s.error_percent)
                .min_by(f64::total_cmp)?;
            tied.into_iter()
                .filter(|(_, s)| s.error_percent <= best + noise)
                .min_by(|a, b| by_name(a, b))
        }
        Budget::Time { .. } => fastest_of(
            meeting
                .into_iter()
                .filter(|(_, s)| s.error_percent <= lowest + noise)
                .collect(),
        ),
    }
}

impl Report {
    /// The runs of `scene` scored in `domain`.
    fn scored<'a>(
        &'a self,
        scene: &'a str,
        domain: Domain,
    ) -> impl Iterator<Item = (&'a ReportRun, Score)> + 'a {
        self.runs_of(scene)
            .filter_map(move |r| Some((r, domain.score(r)?)))
    }

    /// The relative noise of `scene`'s reference in `domain`, in percent,
    /// and at least [`EQUAL_ERRORS_PERCENT`]: errors closer than that are
    /// equal even against a reference that is exact (the furnace's, whose
    /// control variate knows the whole answer).
    pub(super) fn noise_percent(&self, scene: &str, domain: Domain) -> f64 {
        let reference = self.references.iter().find(|r| r.scene == scene);
        let noise = match domain {
            Domain::Vertex => reference.map(|r| r.noise),
            Domain::Image => reference.and_then(|r| r.image.as_ref()).map(|i| i.noise),
        };
        (f64::from(noise.unwrap_or(0.0)) * 100.0).max(EQUAL_ERRORS_PERCENT)
    }

    /// Every scene × domain × budget, in that order; a domain no run of the
    /// scene was scored in is left out.
    pub fn recommendations(&self) -> Vec<Recommendation> {
        let mut out = Vec::new();
        for scene in self.scenes() {
            for domain in [Domain::Vertex, Domain::Image] {
                if self.scored(scene, domain).next().is_none() {
                    continue;
                }
                for budget in Budget::all() {
                    let noise = self.noise_percent(scene, domain);
                    let picked = pick(self.scored(scene, domain), budget, noise);
                    out.push(Recommendation {
                        scene: scene.to_string(),
                        domain: domain.key(),
                        budget,
                        setting: picked.map(|(r, _)| r.setting.clone()),
                        family: picked.map(|(r, _)| r.family.clone()),
                        score: picked.map(|(_, s)| s),
                    });
                }
            }
        }
        out
    }

    /// `family`'s setting for the summary on `scene`: the fastest whose
    /// error is within [`MARGIN`] of the family's best there.
    pub(super) fn family_pick<'a>(
        &'a self,
        scene: &'a str,
        family: &'a str,
        domain: Domain,
    ) -> Option<(&'a ReportRun, Score)> {
        let runs = || {
            self.scored(scene, domain)
                .filter(|(r, _)| r.family == family)
        };
        let best = runs()
            .map(|(_, s)| s.error_percent)
            .min_by(f64::total_cmp)?;
        pick(
            runs(),
            Budget::Error {
                percent: best * MARGIN,
            },
            0.0,
        )
    }

    /// "Which method when": per family, the budgets it is picked for and on
    /// which scenes; per scene where both kinds ran, the best per-pixel
    /// method's image against the best per-vertex method's.
    pub fn which_method_when(&self) -> Vec<String> {
        let recommendations = self.recommendations();
        let mut sentences = Vec::new();
        for sweep in &self.families {
            // What it is picked for (the budgets of one kind and domain) →
            // the scenes, in the order first met.
            let mut picked: Vec<(String, Vec<String>)> = Vec::new();
            for scene in self.scenes() {
                for domain in ["vertex", "image"] {
                    for by_error in [true, false] {
                        let budgets: Vec<String> = recommendations
                            .iter()
                            .filter(|r| {
                                r.scene == scene
                                    && r.domain == domain
                                    && r.family.as_deref() == Some(sweep.family.as_str())
                            })
                            .filter_map(|r| match r.budget {
                                Budget::Error { percent } if by_error => {
                                    Some(format!("{percent}%"))
                                }
                                Budget::Time { ms } if !by_error => Some(format!("{ms} ms")),
                                _ => None,
                            })
                            .collect();
                        if budgets.is_empty() {
                            continue;
                        }
                        let what = if by_error {
                            format!("the fastest {} to {}", domain_words(domain), list(&budgets))
                        } else {
                            format!(
                                "the most accurate {} within {}",
                                domain_words(domain),
                                list(&budgets)
                            )
                        };
                        match picked.iter_mut().find(|(w, _)| *w == what) {
                            Some((_, scenes)) => scenes.push(scene.to_string()),
                            None => picked.push((what, vec![scene.to_string()])),
                        }
                    }
                }
            }
            sentences.push(if picked.is_empty() {
                format!(
                    "{}: picked for no budget on any scene of this run.",
                    sweep.family
                )
            } else {
                let parts: Vec<String> = picked
                    .iter()
                    .map(|(what, scenes)| format!("{what} on {}", list(scenes)))
                    .collect();
                format!("{}: {}.", sweep.family, parts.join("; "))
            });
        }
        for scene in self.scenes() {
            let best = |per_pixel: bool| {
                self.scored(scene, Domain::Image)
                    .filter(|(r, _)| r.result.capabilities.per_pixel == per_pixel)
                    .min_by(|a, b| a.1.error_percent.total_cmp(&b.1.error_percent))
            };
            let (Some((pixel, p)), Some((vertex, v))) = (best(true), best(false)) else {
                continue;
            };
            let noise = self.noise_percent(scene, Domain::Image);
            let verdict = if (p.error_percent - v.error_percent).abs() <= noise {
                "the same error within the reference's noise".to_string()
            } else if p.error_percent < v.error_percent {
                format!("per pixel {:.1}× lower", v.error_percent / p.error_percent)
            } else {
                format!("per vertex {:.1}× lower", p.error_percent / v.error_percent)
            };
            sentences.push(format!(
                "On {scene}, images: the best per-pixel method, {} ({:.2}% at {:.1} ms), against \
                 the best per-vertex method interpolated, {} ({:.2}% at {:.1} ms): {verdict}.",
                pixel.setting, p.error_percent, p.ms, vertex.setting, v.error_percent, v.ms,
            ));
        }
        sentences
    }
}

/// "a", "a and b", "a, b and c".
fn list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

fn domain_words(domain: &str) -> &'static str {
    if domain == "image" {
        "per pixel"
    } else {
        "per vertex"
    }
}
