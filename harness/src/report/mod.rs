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
mod machine;
mod recommend;
mod render;
#[cfg(test)]
mod tests;

use serde::Serialize;

use crate::{
    reference::ReferenceInfo,
    run::RunResult,
    suite::{Suite, Sweep},
};
pub use atlas::{AtlasRun, AtlasScene, FAILURE_FACTOR, Outcome};
pub use collect::{Plan, collect};
pub use document::{Block, Document, Figure, Table};
pub use machine::MachineInfo;
pub use recommend::{Budget, ERROR_BUDGETS, MARGIN, Recommendation, Score, TIME_BUDGETS_MS};

/// How the report was run: everything needed to run it again.
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub suite: Suite,
    /// Target relative L2 noise of the vertex and image references.
    pub target_noise: f32,
    pub image_target_noise: f32,
    /// Width of the scored images (each scene camera's aspect kept).
    pub image_width: u32,
    /// Repeats per stage (at least three samples where it allows; medians
    /// and ranges reported).
    pub repeats: usize,
    /// Seed of the references' random streams.
    pub seed: u64,
}

/// One run of the report: a setting of a method family on a scene.
#[derive(Clone, Debug, Serialize)]
pub struct ReportRun {
    pub family: String,
    /// The method name it was built from (`occlusion-query:k=66`).
    pub setting: String,
    #[serde(flatten)]
    pub result: RunResult,
}

/// A method that could not run on a scene, and why.
#[derive(Clone, Debug, Serialize)]
pub struct Skipped {
    pub method: String,
    pub scene: String,
    pub why: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub machine: MachineInfo,
    pub settings: Settings,
    pub references: Vec<ReferenceInfo>,
    pub families: Vec<Sweep>,
    pub runs: Vec<ReportRun>,
    pub skipped: Vec<Skipped>,
    /// Settings (or a scene's references, `reference`) that failed, and
    /// the error.
    pub failed: Vec<Skipped>,
    /// The scene whose images the report shows side by side
    /// ([`crate::suite::STRIP_SCENE`]), when its images were written (under
    /// `strip/{scene}/`).
    pub strip: Option<String>,
    /// The stability atlas's scenes and runs (images under `atlas/{scene}/`).
    pub atlas_scenes: Vec<AtlasScene>,
    pub atlas: Vec<AtlasRun>,
}

impl Report {
    /// The scenes in the order they ran.
    pub fn scenes(&self) -> Vec<&str> {
        self.references.iter().map(|r| r.scene.as_str()).collect()
    }

    /// The runs of one scene.
    pub fn runs_of<'a>(&'a self, scene: &'a str) -> impl Iterator<Item = &'a ReportRun> + 'a {
        self.runs.iter().filter(move |r| r.result.scene == scene)
    }
}
