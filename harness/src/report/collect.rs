//! Running a report: each scene's references, then every setting of every
//! sweep on it, then the stability atlas. A setting that fails is recorded
//! with its error and the run goes on; the page says what failed.

use std::path::PathBuf;

use shadow_core::{Camera, Environment, Error, Result, Scene};

use super::{
    AtlasRun, AtlasScene, MachineInfo, Outcome, Part, Report, ReportRun, Settings, Skipped,
};
use crate::{
    images,
    methods::{MethodSpec, SharedGpu},
    pictures::{self, Pictures, Shot},
    progress::Progress,
    reference::{
        ImageReference, ImageReferenceInfo, ReferenceCache, ReferenceInfo, ReferenceSettings,
        VertexReference,
    },
    run::{self, References, RunResult},
    scaling::{self, ScalingRun},
    scenes::{self, SCENES, stress},
    suite::{STRIP_SCENE, Suite, Sweep},
};

/// What a report runs, every name already checked.
#[derive(Clone, Debug)]
pub struct Plan {
    pub suite: Suite,
    /// Built-in scenes ([`SCENES`]) to run every sweep on.
    pub scenes: Vec<&'static str>,
    pub sweeps: Vec<Sweep>,
    /// Stress scenes ([`stress::STRESS_SCENES`]) of the atlas.
    pub atlas_scenes: Vec<&'static str>,
    pub atlas_settings: Vec<MethodSpec>,
    /// The vertex references' settings.
    pub vertex: ReferenceSettings,
    /// The image references' settings.
    pub image: ReferenceSettings,
    /// Width of the scored images (each scene camera's aspect kept).
    pub image_width: u32,
    pub repeats: usize,
    pub cache: PathBuf,
    /// Where every scene's images go, when asked.
    pub images: Option<PathBuf>,
    /// The report's folder: the pictures go under it.
    pub out_dir: PathBuf,
    /// Which part of the scenes to run ([`Part::WHOLE`] for all).
    pub part: Part,
    /// The pictures' width and their reference's settings
    /// ([`crate::pictures`]).
    pub picture_width: u32,
    pub picture: ReferenceSettings,
    /// The scenes timed across widths (where the plan runs them), the
    /// settings timed and the widths.
    pub scaling_scenes: Vec<&'static str>,
    pub scaling_settings: Vec<MethodSpec>,
    pub scaling_widths: Vec<u32>,
}

impl Plan {
    /// The runs its part makes (before the atlas's remedies).
    pub fn run_count(&self) -> usize {
        let settings: usize = self.sweeps.iter().map(|s| s.methods.len()).sum();
        self.scenes().len() * settings + self.atlas_scenes().len() * self.atlas_settings.len()
    }

    /// The built-in scenes of its part.
    pub fn scenes(&self) -> Vec<&'static str> {
        self.scenes
            .iter()
            .enumerate()
            .filter(|&(unit, _)| self.part.holds(unit))
            .map(|(_, &s)| s)
            .collect()
    }

    /// The stress scenes of its part (the units after the built-in scenes).
    pub fn atlas_scenes(&self) -> Vec<&'static str> {
        let first = self.scenes.len();
        self.atlas_scenes
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.part.holds(first + i))
            .map(|(_, &s)| s)
            .collect()
    }
}

/// A scene's references, per vertex and per pixel.
struct SceneReferences {
    vertex: Vec<VertexReference>,
    info: ReferenceInfo,
    camera: Camera,
    image: Vec<ImageReference>,
}

impl SceneReferences {
    fn compute(
        scene: &Scene,
        environment: &Environment,
        plan: &Plan,
        cache: &ReferenceCache,
        progress: &Progress,
    ) -> Result<SceneReferences> {
        let (vertex, mut info) =
            ReferenceInfo::compute(scene, environment, &plan.vertex, cache, progress)?;
        let camera = scene.camera().with_width(plan.image_width)?;
        let (image, image_info) =
            ImageReferenceInfo::compute(scene, environment, &camera, &plan.image, cache, progress)?;
        info.image = Some(image_info);
        Ok(SceneReferences {
            vertex,
            info,
            camera,
            image,
        })
    }

    fn references(&self) -> References<'_> {
        References {
            vertex: &self.vertex,
            image: Some((&self.camera, &self.image)),
        }
    }
}

/// Runs `plan`, GPU methods on `gpu`'s device: the report, with every
/// failure recorded in [`Report::failed`]. Fails only where nothing can be
/// written (an image folder that cannot be written).
pub fn collect(plan: &Plan, gpu: &SharedGpu, progress: &Progress) -> Result<Report> {
    let cache = ReferenceCache::new(&plan.cache);
    let mut report = Report::new(
        MachineInfo::detect(None),
        Settings {
            suite: plan.suite,
            target_noise: plan.vertex.target_noise.unwrap_or(0.0),
            image_target_noise: plan.image.target_noise.unwrap_or(0.0),
            image_width: plan.image_width,
            picture_width: plan.picture_width,
            repeats: plan.repeats,
            seed: plan.vertex.seed,
            scenes: plan.scenes.iter().map(|s| s.to_string()).collect(),
            atlas_scenes: plan.atlas_scenes.iter().map(|s| s.to_string()).collect(),
            part: plan.part,
        },
        plan.sweeps.iter().map(Into::into).collect(),
    );
    let overall = progress.runs(plan.run_count());
    let failed = |report: &mut Report, method: &str, scene: &str, error: &Error| {
        progress.say(format!("{scene}: {method} failed: {error}"));
        report.failed.push(Skipped {
            method: method.to_string(),
            scene: scene.to_string(),
            why: error.to_string(),
        });
    };
    let settings: usize = plan.sweeps.iter().map(|s| s.methods.len()).sum();
    for name in plan.scenes() {
        overall.set_message(format!("references of {name}"));
        let loaded = builtin(name).and_then(|(scene, environment)| {
            let references =
                SceneReferences::compute(&scene, &environment, plan, &cache, progress)?;
            Ok((scene, environment, references))
        });
        let (scene, environment, references) = match loaded {
            Ok(loaded) => loaded,
            Err(e) => {
                failed(&mut report, "reference", name, &e);
                overall.inc(settings as u64);
                continue;
            }
        };
        report.references.push(references.info.clone());
        let first_run = report.runs.len();
        for sweep in &plan.sweeps {
            for spec in &sweep.methods {
                overall.set_message(format!("{name}: {spec}"));
                let ran = spec.build(gpu).and_then(|mut method| {
                    let references = references.references();
                    run::run(
                        method.as_mut(),
                        &scene,
                        &environment,
                        references,
                        plan.repeats,
                    )
                });
                match ran {
                    Ok(result) => {
                        progress.say(format!(
                            "{name:<10} {spec:<28} error {:.2}% per vertex, {} per pixel",
                            result.mean_error() * 100.0,
                            result
                                .mean_image_error()
                                .map_or("–".into(), |e| format!("{:.2}%", e * 100.0))
                        ));
                        report.runs.push(ReportRun {
                            family: sweep.family.to_string(),
                            setting: spec.name().to_string(),
                            result,
                        });
                    }
                    Err(e @ Error::Unsupported { .. }) => report.skipped.push(Skipped {
                        method: spec.name().to_string(),
                        scene: name.to_string(),
                        why: e.to_string(),
                    }),
                    Err(e) => failed(&mut report, spec.name(), name, &e),
                }
                overall.inc(1);
            }
        }
        let runs: Vec<&RunResult> = report.runs[first_run..].iter().map(|r| &r.result).collect();
        if let (Some(dir), Some(reference)) = (&plan.images, references.image.last()) {
            images::write_scene(dir, name, &reference.image, &runs)?;
        }
        if name == STRIP_SCENE {
            // The strip's settings that drew an image, framed on their errors.
            let runs = &report.runs[first_run..];
            let (shown, specs): (Vec<&RunResult>, Vec<&MethodSpec>) = Suite::strip_settings()
                .iter()
                .filter_map(|m| {
                    let run = runs.iter().find(|r| r.setting == m.name())?;
                    let spec = plan.sweeps.iter().flat_map(|s| &s.methods);
                    Some((&run.result, spec.clone().find(|s| s.name() == m.name())?))
                })
                .unzip();
            overall.set_message(format!("{name}: pictures"));
            let view = View {
                scene: &scene,
                environment: &environment,
                references: &references,
            };
            let taken = take_pictures(&view, &shown, &specs, plan, gpu, &cache, progress)?;
            report.pictures.extend(taken);
        }
        if plan.scaling_scenes.contains(&name) {
            overall.inc_length(plan.scaling_settings.len() as u64);
            for spec in &plan.scaling_settings {
                overall.set_message(format!("{name}: {spec} across widths"));
                match time_across_widths(spec, &scene, &environment, plan, gpu) {
                    Ok(run) => report.scaling.push(run),
                    Err(Error::Unsupported { .. }) => {}
                    Err(e) => failed(&mut report, &format!("{spec} across widths"), name, &e),
                }
                overall.inc(1);
            }
        }
    }
    for name in plan.atlas_scenes() {
        overall.set_message(format!("references of {name}"));
        let loaded = stress::stress_scene(name).and_then(|stress| {
            let references = SceneReferences::compute(
                &stress.scene,
                &stress.environment,
                plan,
                &cache,
                progress,
            )?;
            Ok((stress, references))
        });
        let (stress, references) = match loaded {
            Ok(loaded) => loaded,
            Err(e) => {
                failed(&mut report, "reference", name, &e);
                overall.inc(plan.atlas_settings.len() as u64);
                continue;
            }
        };
        let atlas_scene = AtlasScene {
            name: name.to_string(),
            breaks: stress.breaks.to_string(),
            reference: references.info.clone(),
        };
        let first = (report.atlas.len(), report.remedies.len());
        for spec in &plan.atlas_settings {
            overall.set_message(format!("{name}: {spec}"));
            let outcome = run_stressed(spec, &stress, &references, plan.repeats, gpu);
            report.atlas.push(AtlasRun::new(name, spec, outcome));
            overall.inc(1);
        }
        // Where a standard setting fails, its family's remedies. Whether
        // it fails depends on every standard scene; a part, which has not
        // run them all, tries every setting that may fail. The pictures
        // show every setting that may fail (framed on them alike in a part
        // and in one run) and the remedies tried.
        let mut may_fail = Vec::new();
        let mut pictured: Vec<MethodSpec> = Vec::new();
        for (i, spec) in (first.0..report.atlas.len()).zip(&plan.atlas_settings) {
            let run = &report.atlas[i];
            if !run.may_fail() {
                continue;
            }
            may_fail.push(i);
            pictured.push(spec.clone());
            if plan.part.is_whole() && !run.fails(&report.runs) {
                continue;
            }
            let remedies = crate::suite::remedies(&run.family);
            overall.inc_length(remedies.len() as u64);
            for spec in remedies {
                overall.set_message(format!("{name}: {spec} (remedy)"));
                let outcome = run_stressed(&spec, &stress, &references, plan.repeats, gpu);
                let remedy = AtlasRun::remedy(&report.atlas[i], &spec, outcome);
                report.remedies.push(remedy);
                pictured.push(spec);
                overall.inc(1);
            }
        }
        let shown: Vec<&RunResult> = may_fail
            .iter()
            .filter_map(|&i| report.atlas[i].outcome.ran())
            .collect();
        if !shown.is_empty() {
            overall.set_message(format!("{name}: pictures"));
            let view = View {
                scene: &stress.scene,
                environment: &stress.environment,
                references: &references,
            };
            let specs: Vec<&MethodSpec> = pictured.iter().collect();
            let taken = take_pictures(&view, &shown, &specs, plan, gpu, &cache, progress)?;
            report.pictures.extend(taken);
        }
        if let (Some(dir), Some(reference)) = (&plan.images, references.image.last()) {
            let runs: Vec<&RunResult> = report.atlas[first.0..]
                .iter()
                .chain(&report.remedies[first.1..])
                .filter_map(|a| a.outcome.ran())
                .collect();
            images::write_scene(dir, name, &reference.image, &runs)?;
        }
        report.atlas_scenes.push(atlas_scene);
    }
    overall.finish_and_clear();
    report.machine.adapter = gpu.adapter();
    report.judge_atlas();
    for run in &report.atlas {
        progress.say(format!("{:<16} {}", run.scene, run.diagnosis));
    }
    Ok(report)
}

/// `spec`'s time per image on `scene` at each of the plan's widths.
fn time_across_widths(
    spec: &MethodSpec,
    scene: &Scene,
    environment: &Environment,
    plan: &Plan,
    gpu: &SharedGpu,
) -> Result<ScalingRun> {
    let mut method = spec.build(gpu)?;
    let per_pixel = method.capabilities().per_pixel;
    let widths = scaling::time_images(
        method.as_mut(),
        scene,
        environment,
        &plan.scaling_widths,
        scaling::samples(plan.repeats),
    )?;
    Ok(ScalingRun {
        scene: scene.name().to_string(),
        family: spec.family().to_string(),
        setting: spec.name().to_string(),
        per_pixel,
        widths,
    })
}

/// A scene as the pictures see it: its environment and scored references.
struct View<'a> {
    scene: &'a Scene,
    environment: &'a Environment,
    references: &'a SceneReferences,
}

/// The pictures of `specs` on `view`'s scene, framed on the errors of the
/// runs `shown` in the scored images (their last frame), into
/// `out_dir/pictures/{scene}`; `None` without a scored image to frame by.
fn take_pictures(
    view: &View,
    shown: &[&RunResult],
    specs: &[&MethodSpec],
    plan: &Plan,
    gpu: &SharedGpu,
    cache: &ReferenceCache,
    progress: &Progress,
) -> Result<Option<Pictures>> {
    let Some(reference) = view.references.image.last() else {
        return Ok(None);
    };
    let scored = &view.references.camera;
    let mut errors = vec![0.0; (scored.width * scored.height) as usize];
    for run in shown {
        if let Some(image) = &run.last_image {
            for (sum, e) in errors
                .iter_mut()
                .zip(pictures::error_weights(image, &reference.image))
            {
                *sum += e;
            }
        }
    }
    let (center, fraction) = pictures::window(scored.width, scored.height, &errors);
    let shot = Shot {
        scene: view.scene,
        environment: view.environment,
        scored,
        center,
        fraction,
        width: plan.picture_width,
        reference: &plan.picture,
    };
    let name = view.scene.name();
    let folder = format!("pictures/{name}");
    let pictures = pictures::take(&shot, specs, gpu, cache, &plan.out_dir, &folder, progress)?;
    for f in &pictures.failed {
        progress.say(format!("{name}: no picture of {}: {}", f.setting, f.why));
    }
    progress.say(format!(
        "{name:<10} pictures: reference {:.1} s",
        pictures.reference_seconds
    ));
    Ok(Some(pictures))
}

/// `spec` on a stress scene: its run, or why it could not run.
fn run_stressed(
    spec: &MethodSpec,
    stress: &stress::StressScene,
    references: &SceneReferences,
    repeats: usize,
    gpu: &SharedGpu,
) -> Outcome {
    let ran = spec.build(gpu).and_then(|mut method| {
        run::run(
            method.as_mut(),
            &stress.scene,
            &stress.environment,
            references.references(),
            repeats,
        )
    });
    match ran {
        Ok(result) => Outcome::Ran(Box::new(result)),
        Err(e) => Outcome::Refused(e.to_string()),
    }
}

/// Built-in scene `name` and its own environment.
fn builtin(name: &str) -> Result<(Scene, Environment)> {
    let environment = SCENES
        .iter()
        .find(|s| s.name == name)
        .map_or("uniform", |s| s.environment);
    Ok((scenes::builtin(name)?, scenes::environment(environment)?))
}
