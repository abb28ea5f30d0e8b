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
//! Every stage gets at least [`MIN_SAMPLES`] samples where `repeats`
//! allows, and reports their median with their range ([`Timing`]).
//! `update` is what a new frame costs, and a repeated call with the same
//! geometry may find nothing to redo (a method that keeps its visibility
//! while nothing moves), so it is timed on its first call per frame; a
//! scene of fewer frames than [`MIN_SAMPLES`] (a still scene) gets its
//! update's samples by first updating to a nudged twin of the frame (every
//! object moved by a ten-thousandth of the scene's size), untimed, so that
//! each timed update recomputes. Shading, rendering and relighting are
//! repeated as they are. A still scene's samples are batches: a stage
//! faster than [`BATCH_SECONDS`] is called again within its sample until
//! then, and the sample is the mean call.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};
use shadow_core::{
    Camera, Capabilities, Environment, FrameGeometry, Image, Mesh, PosedObject, Profile,
    ProfileValue, Result, Scene, ShadowMethod, Stage, VertexRadiance,
};

use crate::{
    reference::{ImageReference, VertexReference},
    score::{self, ErrorStats, Temporal},
    timing::Timing,
};

/// Samples every stage gets at least, unless `repeats` asks for fewer: the
/// median of fewer is not a figure.
pub const MIN_SAMPLES: usize = 3;

/// Seconds of stage time per frame after which repeats beyond
/// [`MIN_SAMPLES`] stop.
pub const REPEAT_BUDGET: f64 = 2.0;

/// Wall-clock seconds of each stage: the samples of the frame's fresh
/// updates, and of its repeated shading, rendering and (on the first frame)
/// relighting.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Once per run.
    pub prepare: f64,
    pub relight: Timing,
    pub update: Timing,
    pub shade: Timing,
    /// When the run rendered images.
    pub render: Option<Timing>,
}

impl StageTimes {
    /// What a new frame of per-vertex results costs: update + shade, per
    /// repeat.
    pub fn vertex_frame(&self) -> Timing {
        per_repeat(&self.update, &self.shade)
    }

    /// What a new image costs: update + render, per repeat.
    pub fn image_frame(&self) -> Option<Timing> {
        self.render
            .as_ref()
            .map(|render| per_repeat(&self.update, render))
    }
}

/// `update` plus `other` per repeat; a single update (timed once per frame)
/// goes with every repeat of `other`.
fn per_repeat(update: &Timing, other: &Timing) -> Timing {
    match update.samples() {
        &[once] => Timing::new(other.samples().iter().map(|s| once + s).collect()),
        _ => update.plus(other),
    }
}

/// One frame's result.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
#[derive(Clone, Debug, Serialize, Deserialize)]
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

    /// The per-vertex time per frame: every frame's samples pooled.
    pub fn frame_time(&self) -> Timing {
        let frames: Vec<Timing> = self.frames.iter().map(|f| f.times.vertex_frame()).collect();
        Timing::pooled(&frames)
    }

    /// The time per image: every frame's samples pooled.
    pub fn image_frame_time(&self) -> Option<Timing> {
        let frames: Option<Vec<Timing>> =
            self.frames.iter().map(|f| f.times.image_frame()).collect();
        frames.filter(|f| !f.is_empty()).map(|f| Timing::pooled(&f))
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
/// at least [`MIN_SAMPLES`] and beyond that until they have taken
/// [`REPEAT_BUDGET`] seconds. Relighting is timed on the first frame, after
/// its update, so that light-dependent work has geometry to act on.
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
    let mut relight = Timing::default();
    let frame_count = scene.frames().len().min(references.vertex.len());
    let still = scene.frames().len() < MIN_SAMPLES;
    let least = MIN_SAMPLES.min(repeats);
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
        let twin = still.then(|| nudged(&geometry)).transpose()?;
        let (mut update, mut shade, mut render) = (Vec::new(), Vec::new(), Vec::new());
        let mut profiles = Vec::new();
        let (mut shading, mut image) = (None, None);
        let started = Instant::now();
        for repeat in 0..repeats {
            if repeat >= least && started.elapsed().as_secs_f64() > REPEAT_BUDGET {
                break;
            }
            let fresh = repeat == 0 || twin.is_some();
            // A still scene's samples are few: each is a batch of calls
            // lasting BATCH_SECONDS, each update made fresh by the twin.
            let batch = if still { BATCH_SECONDS } else { 0.0 };
            let mut first = repeat == 0;
            let updated = sample(batch, || {
                if let (Some(twin), false) = (&twin, first) {
                    method.update(twin, camera)?;
                }
                first = false;
                timed(|| method.update(&geometry, camera))
            })?;
            if fresh {
                update.push(updated);
            }
            shade.push(sample(batch, || {
                let start = Instant::now();
                shading = Some(method.shade(camera.eye)?);
                Ok(start.elapsed())
            })?);
            if let Some((image_camera, _)) = image_reference {
                render.push(sample(batch, || {
                    let start = Instant::now();
                    image = Some(method.render(image_camera)?);
                    Ok(start.elapsed())
                })?);
            }
            let profile = method.profile();
            if fresh {
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
            relight = timing(times);
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
                relight: relight.clone(),
                update: timing(update),
                shade: timing(shade),
                render: (!render.is_empty()).then(|| timing(render)),
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

/// How long one sample of a still scene's stage lasts at least: a faster
/// stage is called again within the sample until then (at most
/// [`MAX_BATCH`] times), and the sample is the mean call. Three single calls
/// of a sub-millisecond stage spread by more than a quarter between
/// back-to-back reports.
pub const BATCH_SECONDS: f64 = 0.01;

/// Calls one sample of a stage holds at most.
pub const MAX_BATCH: u32 = 64;

/// One sample of `call`, which times its own work: calls until they have
/// taken `seconds` in all (at least one, at most [`MAX_BATCH`]), their mean.
pub(crate) fn sample(seconds: f64, mut call: impl FnMut() -> Result<Duration>) -> Result<Duration> {
    let (mut total, mut calls) = (call()?, 1);
    while total.as_secs_f64() < seconds && calls < MAX_BATCH {
        total += call()?;
        calls += 1;
    }
    Ok(total / calls)
}

pub(crate) fn timed(f: impl FnOnce() -> Result<()>) -> Result<Duration> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed())
}

fn timing(d: Vec<Duration>) -> Timing {
    Timing::new(d.into_iter().map(|d| d.as_secs_f64()).collect())
}

/// `frame` with every object moved up by a ten-thousandth of its bounds'
/// diagonal: a frame any method must recompute, that shades the same.
pub(crate) fn nudged(frame: &FrameGeometry) -> Result<FrameGeometry> {
    let offset = Vec3::Y * (frame.bounds().diagonal() * 1e-4).max(f32::MIN_POSITIVE);
    let objects = frame
        .objects
        .iter()
        .map(|object| {
            let positions = object.positions().iter().map(|p| *p + offset).collect();
            let mesh = Mesh::new(
                object.name(),
                positions,
                Some(object.normals().to_vec()),
                object.triangles().to_vec(),
            )?;
            Ok(PosedObject {
                mesh: Arc::new(mesh),
                transform: object
                    .transform
                    .map(|t| Affine3A::from_translation(offset) * t),
            })
        })
        .collect::<Result<_>>()?;
    Ok(FrameGeometry {
        frame: frame.frame,
        objects,
    })
}

/// Every entry of `profiles`, its value the median over the profiles that
/// have it, in the order first seen.
fn median_profile(profiles: &[Profile]) -> Profile {
    let mut out = Profile::default();
    for entry in profiles.iter().flat_map(|p| p.entries()) {
        if out.get(entry.stage, &entry.name).is_some() {
            continue;
        }
        let values = profiles
            .iter()
            .filter_map(|p| p.get(entry.stage, &entry.name));
        match entry.value {
            ProfileValue::Seconds(_) => {
                let seconds = values.filter_map(|v| match v {
                    ProfileValue::Seconds(s) => Some(s),
                    ProfileValue::Count(_) => None,
                });
                out.seconds(entry.stage, entry.name.clone(), median(seconds.collect()));
            }
            ProfileValue::Count(_) => {
                let mut counts: Vec<u64> = values
                    .filter_map(|v| match v {
                        ProfileValue::Count(n) => Some(n),
                        ProfileValue::Seconds(_) => None,
                    })
                    .collect();
                counts.sort_unstable();
                out.count(entry.stage, entry.name.clone(), counts[counts.len() / 2]);
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
            relight: Timing::new(vec![5.0]),
            update: Timing::new(vec![1.0]),
            shade: Timing::new(vec![2.0, 3.0, 2.5]),
            render: Some(Timing::new(vec![4.0, 4.0, 6.0])),
        };
        // One fresh update per frame goes with every repeat.
        assert_eq!(times.vertex_frame().samples(), &[3.0, 4.0, 3.5]);
        assert_eq!(times.image_frame().unwrap().median(), 5.0);
        let repeated = StageTimes {
            update: Timing::new(vec![1.0, 2.0, 3.0]),
            render: None,
            ..times
        };
        assert_eq!(repeated.vertex_frame().samples(), &[3.0, 5.0, 5.5]);
        assert_eq!(repeated.image_frame(), None);
    }

    /// A method whose update does work only when the geometry changed, as
    /// one that keeps its visibility while nothing moves.
    #[derive(Default)]
    struct Lazy {
        last: Option<Vec<Vec3>>,
        updates: usize,
        recomputed: usize,
        vertices: Vec<usize>,
    }

    impl ShadowMethod for Lazy {
        fn name(&self) -> &str {
            "lazy"
        }
        fn capabilities(&self) -> Capabilities {
            Capabilities::ALL
        }
        fn prepare(&mut self, scene: &Scene) -> Result<()> {
            self.vertices = scene
                .objects()
                .iter()
                .map(|o| o.mesh.vertex_count())
                .collect();
            Ok(())
        }
        fn relight(&mut self, _: &Environment) -> Result<()> {
            Ok(())
        }
        fn update(&mut self, frame: &FrameGeometry, _: &Camera) -> Result<()> {
            let positions: Vec<Vec3> = frame.vertices().map(|(p, _)| p).collect();
            self.updates += 1;
            if self.last.as_ref() != Some(&positions) {
                self.recomputed += 1;
                self.last = Some(positions);
            }
            Ok(())
        }
        fn shade(&mut self, _: Vec3) -> Result<VertexRadiance> {
            Ok(VertexRadiance::new(
                self.vertices.iter().map(|&n| vec![Vec3::ONE; n]).collect(),
            ))
        }
        fn render(&mut self, _: &Camera) -> Result<Image> {
            unreachable!("no image references")
        }
        fn profile(&self) -> Profile {
            Profile::default()
        }
    }

    fn reference(scene: &Scene) -> VertexReference {
        let ones = scene
            .objects()
            .iter()
            .map(|o| vec![Vec3::ONE; o.mesh.vertex_count()])
            .collect();
        VertexReference {
            radiance: VertexRadiance::new(ones),
            replicates: vec![1; scene.vertex_count()],
            rays: 0,
            noise: 0.0,
            seconds: 0.0,
        }
    }

    /// A still scene's update is sampled MIN_SAMPLES times, each a batch of
    /// recomputations (the nudged twin in between); an animated scene's
    /// once per frame, unbatched; the last update of each frame is of that
    /// frame.
    #[test]
    fn every_timed_update_recomputes() {
        use shadow_core::{Frame, Object, Pose, shapes};
        let floor = Arc::new(shapes::floor("floor", Vec3::ZERO, 1.0, 2).unwrap());
        let object = Object {
            mesh: floor,
            material: shadow_core::Brdf::lambert(Vec3::splat(0.5)).unwrap(),
        };
        let camera = Camera::framing(Vec3::ZERO, 2.0, Vec3::ONE, 8, 8).unwrap();
        let env = Environment::uniform(Vec3::ONE);

        let still = Scene::still("still", vec![object.clone()], camera).unwrap();
        let refs = [reference(&still)];
        let mut lazy = Lazy::default();
        let result = run(&mut lazy, &still, &env, References::vertices(&refs), 5).unwrap();
        let update = &result.frames[0].times.update;
        assert!(update.len() >= MIN_SAMPLES, "{update:?}");
        // Every update recomputed (timed ones and twins alternate), and
        // the fast update's samples were batches of calls.
        assert_eq!(lazy.recomputed, lazy.updates);
        assert!(lazy.updates > 2 * update.len(), "{}", lazy.updates);
        let frame = still.frame_geometry(0).unwrap();
        assert_eq!(
            lazy.last.unwrap(),
            frame.vertices().map(|(p, _)| p).collect::<Vec<_>>()
        );

        let frames = (0..4)
            .map(|i| Frame {
                time: i as f32,
                poses: vec![Pose::Rigid(Affine3A::from_translation(Vec3::X * i as f32))],
            })
            .collect();
        let moving = Scene::new("moving", vec![object], frames, camera).unwrap();
        let refs: Vec<_> = (0..4).map(|_| reference(&moving)).collect();
        let mut lazy = Lazy::default();
        let result = run(&mut lazy, &moving, &env, References::vertices(&refs), 3).unwrap();
        assert!(result.frames.iter().all(|f| f.times.update.len() == 1));
        assert!(result.frames.iter().all(|f| f.times.shade.len() == 3));
        assert_eq!(lazy.recomputed, 4);
        assert_eq!(result.frame_time().len(), 12);
    }
}
