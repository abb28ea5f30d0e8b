//! The comparison report: every method family swept over its settings on
//! every scene, time per stage and error against the reference, per vertex
//! and per pixel, with how much each method flickers between frames.
//!
//! Written into one folder: `index.html` (one self-contained page: charts,
//! image strips and tables embedded, readable offline), `report.md` (the
//! same document, figures linked), `report.json` (everything measured),
//! `report.csv` (one row per run) and the figures as PNG and SVG under
//! `charts/`. Every file is written atomically and only once every run has
//! finished, `index.html` last: an interrupted run leaves the previous
//! report as it was.

mod analyse;
mod atlas;
mod collect;
mod document;
mod gallery;
mod machine;
mod parts;
mod recommend;
mod render;
mod resolution;
#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

use crate::{
    pictures::Pictures,
    reference::ReferenceInfo,
    run::RunResult,
    scaling::ScalingRun,
    suite::{Suite, Sweep},
};
pub use atlas::{AtlasRun, AtlasScene, FAILURE_FACTOR, FAILURE_FLOOR, Outcome};
pub use collect::{Plan, collect};
pub use document::{Block, Document, Figure, Table};
pub use machine::MachineInfo;
pub use parts::{Part, copy_images, merge};
pub use recommend::{Budget, ERROR_BUDGETS, MARGIN, Recommendation, Score, TIME_BUDGETS_MS};
pub use resolution::{Overtakes, WidthComparison, equal_error_ms, overtakes};

/// How the report was run: everything needed to run it again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    pub suite: Suite,
    /// The plan's built-in scenes and stress scenes, in the order they run
    /// (a part ran those [`Part::holds`]).
    pub scenes: Vec<String>,
    pub atlas_scenes: Vec<String>,
    /// Which part of the plan this report holds ([`Part::WHOLE`] but for a
    /// part written with `--shard`).
    pub part: Part,
    /// Target relative L2 noise of the vertex and image references.
    pub target_noise: f32,
    pub image_target_noise: f32,
    /// Width of the scored images (each scene camera's aspect kept).
    pub image_width: u32,
    /// Width of the pictures ([`crate::pictures`]).
    pub picture_width: u32,
    /// Repeats per stage (at least three samples where it allows; medians
    /// and ranges reported).
    pub repeats: usize,
    /// Seed of the references' random streams.
    pub seed: u64,
}

/// A family's sweep as the report ran it ([`Sweep`], by name).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FamilySweep {
    pub family: String,
    /// What varies along the sweep.
    pub parameter: String,
    /// The settings' names, in order of cost.
    pub methods: Vec<String>,
}

impl From<&Sweep> for FamilySweep {
    fn from(sweep: &Sweep) -> FamilySweep {
        FamilySweep {
            family: sweep.family.to_string(),
            parameter: sweep.parameter.to_string(),
            methods: sweep.methods.iter().map(|m| m.name().to_string()).collect(),
        }
    }
}

/// One run of the report: a setting of a method family on a scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReportRun {
    pub family: String,
    /// The method name it was built from (`occlusion-query:k=66`).
    pub setting: String,
    #[serde(flatten)]
    pub result: RunResult,
}

/// A method that could not run on a scene, and why.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Skipped {
    pub method: String,
    pub scene: String,
    pub why: String,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    pub machine: MachineInfo,
    pub settings: Settings,
    pub references: Vec<ReferenceInfo>,
    pub families: Vec<FamilySweep>,
    pub runs: Vec<ReportRun>,
    pub skipped: Vec<Skipped>,
    /// Settings (or a scene's references, `reference`) that failed, and
    /// the error.
    pub failed: Vec<Skipped>,
    /// The stability atlas's scenes and runs:
    /// each standard setting, and after each that fails the best of its
    /// remedies.
    pub atlas_scenes: Vec<AtlasScene>,
    pub atlas: Vec<AtlasRun>,
    /// Every remedy that ran on a stress scene ([`AtlasRun::remedy`]).
    pub remedies: Vec<AtlasRun>,
    /// Time per image across widths ([`crate::scaling`]) on the suite's
    /// scenes for it ([`Suite::scaling_scenes`]) the report ran.
    pub scaling: Vec<ScalingRun>,
    /// The pictures of the strip's scene ([`crate::suite::STRIP_SCENE`]) and
    /// of the stress scenes where a setting may fail, under `pictures/`.
    pub pictures: Vec<Pictures>,
    /// For a report merged from parts, the machine each part ran on, in
    /// part order; empty for one run.
    pub merged_from: Vec<MachineInfo>,
}

impl Report {
    /// The scenes in the order they ran.
    pub fn scenes(&self) -> Vec<&str> {
        self.references.iter().map(|r| r.scene.as_str()).collect()
    }

    /// A report of nothing yet: `settings` run on `machine`, over the sweeps
    /// of `families`.
    pub fn new(machine: MachineInfo, settings: Settings, families: Vec<FamilySweep>) -> Report {
        Report {
            machine,
            settings,
            references: Vec::new(),
            families,
            runs: Vec::new(),
            skipped: Vec::new(),
            failed: Vec::new(),
            atlas_scenes: Vec::new(),
            atlas: Vec::new(),
            remedies: Vec::new(),
            scaling: Vec::new(),
            pictures: Vec::new(),
            merged_from: Vec::new(),
        }
    }

    /// Judges the atlas's standard settings over every standard scene's
    /// runs: their diagnoses, and after each that fails
    /// ([`AtlasRun::fails`]) the best of its remedies in
    /// [`Report::remedies`]. Depends on nothing else, so a report merged
    /// from parts judges as one run does.
    pub fn judge_atlas(&mut self) {
        self.atlas = atlas::judge(&self.atlas, &self.remedies, &self.runs);
    }

    /// The runs of one scene.
    pub fn runs_of<'a>(&'a self, scene: &'a str) -> impl Iterator<Item = &'a ReportRun> + 'a {
        self.runs.iter().filter(move |r| r.result.scene == scene)
    }
}
