//! Driving a method through its stages on a scene, timing each stage and
//! scoring each frame against the references, per vertex and per pixel.
//!
//! # Time per frame
//!
//! Defined once, here, per domain: per-vertex results cost update + shade
//! ([`StageTimes::vertex_frame`]), images cost update + render
//! ([`StageTimes::image_frame`]); relighting is timed apart. Every stage has
//! finished its work when it returns (GPU methods wait for their queue), so
//! the wall clock around a stage is the stage's time.
//!
//! `update` is timed on its first call for each frame: a repeated call with
//! the same geometry may find nothing to redo (a method that keeps its
//! visibility while nothing moves), which is not what a new frame costs.
//! Shading, rendering and relighting are timed as medians over repeats.

use std::time::{Duration, Instant};

use serde::Serialize;
use shadow_core::{
    Camera, Capabilities, Environment, Image, Profile, ProfileValue, Result, Scene, ShadowMethod,
    Stage, VertexRadiance,
};

use crate::{
    reference::{ImageReference, VertexReference},
    score::{self, ErrorStats, Temporal},
};

/// Seconds of stage time per frame after which repeats stop.
pub const REPEAT_BUDGET: f64 = 2.0;

/// Wall-clock seconds of each stage: the first update of the frame, medians
/// of the others over the repeats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    pub prepare: f64,
    pub relight: f64,
    pub update: f64,
    pub shade: f64,
    /// When the run rendered images.
    pub render: Option<f64>,
}

impl StageTimes {
    /// What a new frame of per-vertex results costs: update + shade.
    pub fn vertex_frame(&self) -> f64 {
        self.update + self.shade
    }

    /// What a new image costs: update + render.
    pub fn image_frame(&self) -> Option<f64> {
        self.render.map(|render| self.update + render)
    }
}

/// One frame's result.
#[derive(Clone, Debug, Serialize)]
pub struct FrameResult {
    pub frame: usize,
    /// Error over the vertices the method evaluated (`vertex.count` of
    /// `vertices`).
    pub vertex: ErrorStats,
    /// Vertices in the frame.
    pub vertices: usize,
    /// Error over the reference image's covered pixels, when images were scored.
    pub image: Option<ErrorStats>,
    /// How the per-vertex error changed since the previous frame (none on
    /// the first).
    pub temporal: Option<Temporal>,
    pub times: StageTimes,
    /// The method's own breakdown of its stages, each entry's median over the
    /// repeats (relight's from the first frame).
    pub profile: Profile,
}

/// A method's run over a scene's frames under one environment.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    pub method: String,
    pub scene: String,
    pub environment: String,
    pub capabilities: Capabilities,
    /// Width and height of the scored images, if any.
    pub image_size: Option<(u32, u32)>,
    pub frames: Vec<FrameResult>,
    #[serde(skip)]
    pub last_shading: Option<VertexRadiance>,
    #[serde(skip)]
    pub last_image: Option<Image>,
}

impl RunResult {
    /// The mean over frames of the per-vertex relative L2 error.
    pub fn mean_error(&self) -> f32 {
        mean(self.frames.iter().map(|f| f.vertex.relative_l2))
    }

    /// The mean over frames of the image's relative L2 error.
    pub fn mean_image_error(&self) -> Option<f32> {
        let errors: Option<Vec<f32>> = self
            .frames
            .iter()
            .map(|f| f.image.map(|e| e.relative_l2))
            .collect();
        errors
            .filter(|e| !e.is_empty())
            .map(|e| mean(e.into_iter()))
    }

    /// The median over frames of the per-vertex time per frame.
    pub fn frame_seconds(&self) -> f64 {
        median(self.frames.iter().map(|f| f.times.vertex_frame()).collect())
    }

    /// The median over frames of the time per image.
    pub fn image_frame_seconds(&self) -> Option<f64> {
        let times: Option<Vec<f64>> = self.frames.iter().map(|f| f.times.image_frame()).collect();
        times.filter(|t| !t.is_empty()).map(median)
    }

    /// The worst frame-to-frame change of the per-vertex error, with the
    /// reference's own change and noise floor on that frame; `None` for a
    /// single frame.
    pub fn worst_temporal(&self) -> Option<Temporal> {
        self.frames
            .iter()
            .filter_map(|f| f.temporal)
            .max_by(|a, b| a.error_change.total_cmp(&b.error_change))
    }

    /// The fraction of vertices the method evaluated, over all frames.
    pub fn evaluated_fraction(&self) -> f64 {
        let evaluated: usize = self.frames.iter().map(|f| f.vertex.count).sum();
        let all: usize = self.frames.iter().map(|f| f.vertices).sum();
        evaluated as f64 / all.max(1) as f64
    }
}

fn mean(values: impl ExactSizeIterator<Item = f32>) -> f32 {
    let n = values.len().max(1) as f32;
    values.sum::<f32>() / n
}

/// What a run is scored against: per frame, the vertex reference, and the
/// image reference seen through one camera when images are scored.
#[derive(Clone, Copy, Debug)]
pub struct References<'a> {
    pub vertex: &'a [VertexReference],
    pub image: Option<(&'a Camera, &'a [ImageReference])>,
}

impl<'a> References<'a> {
    /// Per-vertex references only: images are not rendered.
    pub fn vertices(vertex: &'a [VertexReference]) -> References<'a> {
        References {
            vertex,
            image: None,
        }
    }
}

/// Runs `method` on every frame of `scene` under `environment`, each stage
/// up to `repeats` times (medians reported), and scores frame `i` against the
/// references of frame `i` ([`run_inspecting`] without inspection).
pub fn run(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    environment: &Environment,
    references: References,
    repeats: usize,
) -> Result<RunResult> {
    run_inspecting(method, scene, environment, references, repeats, |_, _| {
        Ok(())
    })
}

/// Runs `method` as [`run`] does, and calls `inspect` with each frame's index
/// and the method once the frame's stages have run (to read what the method
/// computed, its export say).
///
/// The order is the renderer's: prepare, relight, then per frame update,
/// shade and render. Each frame's stages are repeated up to `repeats` times,
/// until they have taken [`REPEAT_BUDGET`] seconds: one slow run already
/// measures well. Relighting is timed on the first frame, after its update,
/// so that light-dependent work has geometry to act on.
pub fn run_inspecting(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    environment: &Environment,
    references: References,
    repeats: usize,
    mut inspect: impl FnMut(usize, &dyn ShadowMethod) -> Result<()>,
) -> Result<RunResult> {
    let repeats = repeats.max(1);
    let prepare = timed(|| method.prepare(scene))?.as_secs_f64();
    method.relight(environment)?;
    let camera = scene.camera();
    let mut frames = Vec::new();
    let (mut last_shading, mut last_image) = (None, None);
    let mut relight = 0.0;
    let frame_count = scene.frames().len().min(references.vertex.len());
    for (index, vertex_reference) in references.vertex.iter().enumerate().take(frame_count) {
        let geometry = scene.frame_geometry(index)?;
        let image_reference = references
            .image
            .map(|(camera, refs)| (camera, refs.get(index)))
            .map(|(camera, r)| {
                r.map(|r| (camera, r)).ok_or_else(|| {
                    shadow_core::Error::InvalidScene(format!(
                        "{}: no image reference for frame {index}",
                        scene.name()
                    ))
                })
            })
            .transpose()?;
        let (mut update, mut shade, mut render) = (Vec::new(), Vec::new(), Vec::new());
        let mut profiles = Vec::new();
        let (mut shading, mut image) = (None, None);
        let started = Instant::now();
        for _ in 0..repeats {
            if !update.is_empty() && started.elapsed().as_secs_f64() > REPEAT_BUDGET {
                break;
            }
            let updated = timed(|| method.update(&geometry, camera))?;
            if update.is_empty() {
                update.push(updated);
            }
            let start = Instant::now();
            shading = Some(method.shade(camera.eye)?);
            shade.push(start.elapsed());
            if let Some((image_camera, _)) = image_reference {
                let start = Instant::now();
                image = Some(method.render(image_camera)?);
                render.push(start.elapsed());
            }
            let profile = method.profile();
            if profiles.is_empty() {
                profiles.push(profile.of_stages(|s| s != Stage::Relight));
            } else {
                profiles.push(profile.of_stages(|s| s != Stage::Relight && s != Stage::Update));
            }
        }
        if index == 0 {
            let mut times = Vec::new();
            for _ in 0..repeats {
                times.push(timed(|| method.relight(environment))?);
                profiles.push(method.profile().of_stages(|s| s == Stage::Relight));
            }
            relight = median_secs(times);
        }
        inspect(index, method)?;
        let shading = shading.expect("at least one repeat");
        let image_error = match (&image, image_reference) {
            (Some(image), Some((_, reference))) => Some(score::image(image, reference)?),
            _ => None,
        };
        frames.push(FrameResult {
            frame: index,
            vertex: score::vertices(&shading, vertex_reference),
            vertices: geometry.objects.iter().map(|o| o.vertex_count()).sum(),
            image: image_error,
            temporal: last_shading
                .as_ref()
                .zip(index.checked_sub(1).map(|i| &references.vertex[i]))
                .map(|previous| score::temporal(previous, (&shading, vertex_reference))),
            times: StageTimes {
                prepare,
                relight,
                update: median_secs(update),
                shade: median_secs(shade),
                render: (!render.is_empty()).then(|| median_secs(render)),
            },
            profile: median_profile(&profiles),
        });
        last_shading = Some(shading);
        last_image = image;
    }
    Ok(RunResult {
        method: method.name().to_string(),
        scene: scene.name().to_string(),
        environment: environment.name().to_string(),
        capabilities: method.capabilities(),
        image_size: references.image.map(|(c, _)| (c.width, c.height)),
        frames,
        last_shading,
        last_image,
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

/// Every entry of `profiles`, its value the median over the profiles that
/// have it, in the order first seen.
fn median_profile(profiles: &[Profile]) -> Profile {
    let mut out = Profile::default();
    for entry in profiles.iter().flat_map(|p| p.entries()) {
        if out.get(entry.stage, entry.name).is_some() {
            continue;
        }
        let values = profiles
            .iter()
            .filter_map(|p| p.get(entry.stage, entry.name));
        match entry.value {
            ProfileValue::Seconds(_) => {
                let seconds = values.filter_map(|v| match v {
                    ProfileValue::Seconds(s) => Some(s),
                    ProfileValue::Count(_) => None,
                });
                out.seconds(entry.stage, entry.name, median(seconds.collect()));
            }
            ProfileValue::Count(_) => {
                let mut counts: Vec<u64> = values
                    .filter_map(|v| match v {
                        ProfileValue::Count(n) => Some(n),
                        ProfileValue::Seconds(_) => None,
                    })
                    .collect();
                counts.sort_unstable();
                out.count(entry.stage, entry.name, counts[counts.len() / 2]);
            }
        }
    }
    out
}

/// The median (upper median for even counts); 0 for none.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_merge_to_medians_per_entry() {
        let mut profiles = Vec::new();
        for (ms, n) in [(3.0, 10), (1.0, 30), (2.0, 20)] {
            let mut p = Profile::default();
            p.seconds(Stage::Update, "maps", ms / 1e3);
            p.count(Stage::Update, "pairs", n);
            profiles.push(p);
        }
        let mut relit = Profile::default();
        relit.seconds(Stage::Relight, "project", 0.5);
        profiles.push(relit);
        let merged = median_profile(&profiles);
        assert_eq!(merged.seconds_in(Stage::Update, "maps"), Some(2.0 / 1e3));
        assert_eq!(merged.count_in(Stage::Update, "pairs"), Some(20));
        assert_eq!(merged.seconds_in(Stage::Relight, "project"), Some(0.5));
    }

    #[test]
    fn time_per_frame_is_defined_per_domain() {
        let times = StageTimes {
            prepare: 9.0,
            relight: 5.0,
            update: 1.0,
            shade: 2.0,
            render: Some(4.0),
        };
        assert_eq!(times.vertex_frame(), 3.0);
        assert_eq!(times.image_frame(), Some(5.0));
        let vertex_only = StageTimes {
            render: None,
            ..times
        };
        assert_eq!(vertex_only.image_frame(), None);
    }
}
