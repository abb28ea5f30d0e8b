//! Driving a method through its stages on a scene, timing each stage and
//! scoring each frame against the reference.

use std::time::{Duration, Instant};

use serde::Serialize;
use shadow_core::{Capabilities, Environment, Result, Scene, ShadowMethod, VertexRadiance};

use crate::{
    reference::VertexReference,
    score::{ErrorStats, against},
};

/// Seconds of stage time per frame after which repeats stop.
pub const REPEAT_BUDGET: f64 = 2.0;

/// Median wall-clock seconds of each stage over the repeats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    pub prepare: f64,
    pub update: f64,
    pub relight: f64,
    pub shade: f64,
}

impl StageTimes {
    /// What a new frame costs: update, plus shade.
    pub fn per_frame(&self) -> f64 {
        self.update + self.shade
    }
}

/// One frame's result.
#[derive(Clone, Debug, Serialize)]
pub struct FrameResult {
    pub frame: usize,
    pub error: ErrorStats,
    pub times: StageTimes,
}

/// A method's run over a scene's frames under one environment.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    pub method: String,
    pub scene: String,
    pub environment: String,
    pub capabilities: Capabilities,
    pub frames: Vec<FrameResult>,
    #[serde(skip)]
    pub last_shading: Option<VertexRadiance>,
}

impl RunResult {
    /// The mean of the per-frame relative L2 errors.
    pub fn mean_error(&self) -> f32 {
        self.frames.iter().map(|f| f.error.relative_l2).sum::<f32>()
            / self.frames.len().max(1) as f32
    }

    /// The median over frames of the per-frame time (update + shade).
    pub fn frame_seconds(&self) -> f64 {
        median(self.frames.iter().map(|f| f.times.per_frame()).collect())
    }
}

/// Runs `method` on every frame of `scene` under `environment`, each stage
/// up to `repeats` times (median reported), and scores frame `i` against
/// `references[i]`. A frame whose stages have taken [`REPEAT_BUDGET`] seconds
/// is not repeated further: one slow run already measures well.
pub fn run(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    environment: &Environment,
    references: &[VertexReference],
    repeats: usize,
) -> Result<RunResult> {
    let repeats = repeats.max(1);
    let prepare = timed(|| method.prepare(scene))?;
    let eye = scene.camera().eye;
    let mut frames = Vec::new();
    let mut last = None;
    for (index, reference) in references.iter().enumerate().take(scene.frames().len()) {
        let geometry = scene.frame_geometry(index)?;
        let (mut update, mut relight, mut shade) = (Vec::new(), Vec::new(), Vec::new());
        let mut shading = None;
        let started = Instant::now();
        for _ in 0..repeats {
            if !update.is_empty() && started.elapsed().as_secs_f64() > REPEAT_BUDGET {
                break;
            }
            update.push(timed(|| method.update(&geometry))?);
            relight.push(timed(|| method.relight(environment))?);
            let start = Instant::now();
            shading = Some(method.shade(eye)?);
            shade.push(start.elapsed());
        }
        let shading = shading.expect("at least one repeat");
        let values: Vec<_> = shading.flat().collect();
        frames.push(FrameResult {
            frame: index,
            error: against(&values, reference),
            times: StageTimes {
                prepare: prepare.as_secs_f64(),
                update: median_secs(update),
                relight: median_secs(relight),
                shade: median_secs(shade),
            },
        });
        last = Some(shading);
    }
    Ok(RunResult {
        method: method.name().to_string(),
        scene: scene.name().to_string(),
        environment: environment.name().to_string(),
        capabilities: method.capabilities(),
        frames,
        last_shading: last,
    })
}

fn timed(f: impl FnOnce() -> Result<()>) -> Result<Duration> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed())
}

fn median_secs(d: Vec<Duration>) -> f64 {
    median(d.into_iter().map(|d| d.as_secs_f64()).collect())
}

/// The median (upper median for even counts); 0 for none.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
