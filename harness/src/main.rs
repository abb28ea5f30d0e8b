//! The `harness` command: list scenes, compute references, run methods, and
//! write the comparison report.

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use harness::{
    accuracy::{self, AccuracyReport, Plan},
    bake, export,
    gltf::{GltfAsset, patch},
    images, methods,
    reference::{
        self, ImageReference, ReferenceCache, ReferenceSettings, transfer::TransferSettings,
    },
    report::{self, ImageReferenceInfo, MachineInfo, ReferenceInfo, Report, STRIP_SCENE},
    run::{self, References},
    scenes::{self, ENVIRONMENTS, SCENES},
    suite::Suite,
};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use shadow_core::{Camera, Environment, Scene, raster::MAX_IMAGE_SIZE};

#[derive(Parser)]
#[command(
    name = "harness",
    about = "Compare soft-shadow methods against a Monte-Carlo reference"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the built-in scenes, environments and methods.
    List,
    /// Compute (or load from the cache) the reference of a scene and print its noise.
    Reference {
        #[command(flatten)]
        input: Input,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Write per-vertex results of the first frame to this .csv or .json file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Run one method on a scene: time per stage and error against the reference.
    Run {
        /// Method name (see `harness list`).
        #[arg(long)]
        method: String,
        #[command(flatten)]
        input: Input,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Repeats per stage; medians are reported.
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        #[command(flatten)]
        image: ImageArgs,
        /// Write the method's per-vertex results of the last frame to this .csv or .json file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write what the method computed for the last frame (SH transfer
        /// vectors, or visibility over directions) to this .npz file, for numpy.
        #[arg(long)]
        export: Option<PathBuf>,
    },
    /// Bake a per-vertex result of your glTF file into a copy of it: ambient
    /// occlusion, irradiance or radiance of one frame, as a vertex attribute.
    /// Everything else in the file is kept.
    Bake {
        /// Your glTF (.gltf or .glb) file.
        #[arg(long)]
        mesh: PathBuf,
        /// The file to write (.glb, or .gltf with its data in a .bin beside it).
        #[arg(long)]
        out: PathBuf,
        /// What to bake: ambient occlusion (needs `--env uniform`, the
        /// default), irradiance or outgoing radiance.
        #[arg(long, value_enum, default_value_t = bake::Quantity::AmbientOcclusion)]
        quantity: bake::Quantity,
        /// `reference` (the converged Monte-Carlo estimate) or a method name
        /// (see `harness list`).
        #[arg(long, default_value = "reference")]
        method: String,
        /// The vertex attribute: `COLOR_0` (ambient occlusion only; viewers
        /// multiply it into the base colour) or an application-specific
        /// `_NAME`; default `_AO`, `_IRRADIANCE` or `_RADIANCE`.
        #[arg(long)]
        attribute: Option<String>,
        /// Overwrite the attribute where the file already has it.
        #[arg(long)]
        replace: bool,
        /// Frames to sample from the file's first animation.
        #[arg(long, default_value_t = 1)]
        frames: usize,
        /// The frame to bake, of those sampled.
        #[arg(long, default_value_t = 0)]
        frame: usize,
        /// Albedo of the white Lambert material (matters for radiance only).
        #[arg(long, default_value_t = 1.0)]
        albedo: f32,
        #[command(flatten)]
        env: EnvArgs,
        /// Target relative L2 noise of the reference (with `--method reference`).
        #[arg(long, default_value_t = 0.005)]
        target: f32,
        /// Also write what the method computed (its SH transfer, say) to this
        /// .npz file.
        #[arg(long)]
        export: Option<PathBuf>,
    },
    /// Run every method on every built-in scene and write report.md and report.json.
    Report {
        /// How much to run: `quick` (four small scenes, a few settings a
        /// method: minutes), `default` (every built-in scene, each method
        /// swept over its settings), `full` (also the settings that take
        /// minutes per frame).
        #[arg(long, value_enum, default_value_t = Suite::Default)]
        suite: Suite,
        /// Shorthand for `--suite quick`.
        #[arg(long, conflicts_with_all = ["suite", "full"])]
        quick: bool,
        /// Shorthand for `--suite full`.
        #[arg(long, conflicts_with = "suite")]
        full: bool,
        /// Only these scenes of the suite (comma separated).
        #[arg(long, value_delimiter = ',')]
        scenes: Vec<String>,
        /// Where to write the report.
        #[arg(long, default_value = "reports")]
        dir: PathBuf,
        #[command(flatten)]
        estimator: EstimatorArgs,
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        #[command(flatten)]
        image: ImageArgs,
    },
    /// Criterion's saved results (`cargo bench -p benches`) as one table:
    /// each benchmark's median time per iteration with criterion's
    /// confidence interval, and the method's error where the bench
    /// recorded it.
    BenchTable {
        /// Criterion's output directory.
        #[arg(long, default_value = "target/criterion")]
        dir: PathBuf,
        /// Write the table here instead of printing it: `.md` for
        /// Markdown, `.csv` for CSV (one line per benchmark).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Score hemi-raster's options (hierarchy, plane table, mask, integration)
    /// by Kautz et al.'s transfer error and by radiance error; write
    /// accuracy.md, accuracy.json and accuracy.png and .svg (time against error).
    Accuracy {
        /// Only these built-in scenes (comma separated); default those of
        /// human, cloth and chess that are built in.
        #[arg(long = "scene", value_delimiter = ',')]
        scenes: Vec<String>,
        /// One environment for every scene instead of each scene's own.
        #[arg(long)]
        env: Option<String>,
        /// Where to write accuracy.md, accuracy.json and the chart.
        #[arg(long, default_value = "reports")]
        out: PathBuf,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Rays per replicate of the transfer reference.
        #[arg(long, default_value_t = TransferSettings::CONVERGED.replicate_size)]
        transfer_rays: u32,
        /// Replicates per vertex of the transfer reference (at least 2).
        #[arg(long, default_value_t = TransferSettings::CONVERGED.replicates)]
        transfer_replicates: u32,
        /// Timed runs of update and shade per frame; medians are reported.
        #[arg(long, default_value_t = 1)]
        repeats: usize,
        /// Only these configurations (comma separated, e.g.
        /// `default,flat,sh-blocks`); default every one.
        #[arg(long = "variant", value_delimiter = ',')]
        variants: Vec<String>,
    },
}

#[derive(Args)]
struct Input {
    /// A built-in scene (see `harness list`).
    #[arg(long, conflicts_with = "mesh", required_unless_present = "mesh")]
    scene: Option<String>,
    /// Your own glTF/GLB file instead of a built-in scene (white Lambert material).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Frames to sample from the file's animation (with --mesh).
    #[arg(long, default_value_t = 1)]
    frames: usize,
    /// Albedo of the white Lambert material given to --mesh (default 1: then
    /// `--env uniform` gives each vertex's ambient occlusion itself).
    #[arg(long, requires = "mesh")]
    albedo: Option<f32>,
    #[command(flatten)]
    env: EnvArgs,
}

#[derive(Args)]
struct EnvArgs {
    /// An environment name (see `harness list`; `uniform` gives ambient occlusion)
    /// or an OpenEXR (.exr) or Radiance (.hdr) lat-long map; default: the scene's own.
    #[arg(long)]
    env: Option<String>,
    /// Turns the environment about the vertical (+Y) axis by this many degrees
    /// (positive: counter-clockwise seen from above).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    env_rotate: f32,
    /// Scales the environment's radiance by 2^EV.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
}

impl EnvArgs {
    /// The environment named by --env (else `default`), turned and exposed.
    fn load(&self, default: &str) -> Result<Environment> {
        let name = self.env.as_deref().unwrap_or(default);
        let env =
            scenes::environment(name).with_context(|| format!("loading environment {name}"))?;
        Ok(scenes::adjusted(env, self.env_rotate, self.exposure)?)
    }
}

#[derive(Args)]
struct ImageArgs {
    /// Width in pixels of the images scored per pixel (the scene camera's
    /// aspect kept); 512 matches the papers' comparisons.
    #[arg(long = "image", default_value_t = DEFAULT_IMAGE_WIDTH,
          value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_IMAGE_SIZE)))]
    width: u32,
    /// Target relative L2 noise of the per-pixel reference.
    #[arg(long, default_value_t = ReferenceSettings::IMAGE.target_noise.unwrap_or(0.01))]
    image_target: f32,
    /// Write each scene's images here: per method the image (linear .exr and
    /// tone-mapped .png) and an error heat map, and the reference.
    #[arg(long)]
    images: Option<PathBuf>,
}

/// The default width of scored images.
const DEFAULT_IMAGE_WIDTH: u32 = 160;

impl ImageArgs {
    fn camera(&self, scene: &Scene) -> Result<Camera> {
        Ok(scene.camera().with_width(self.width)?)
    }

    fn settings(&self, estimator: &EstimatorArgs) -> ReferenceSettings {
        ReferenceSettings {
            seed: estimator.seed,
            target_noise: Some(self.image_target),
            ..ReferenceSettings::IMAGE
        }
    }
}

#[derive(Args)]
struct EstimatorArgs {
    /// Target relative L2 noise of the reference.
    #[arg(long, default_value_t = 0.005)]
    target: f32,
    /// Seed of the reference's random streams.
    #[arg(long, default_value_t = ReferenceSettings::CONVERGED.seed)]
    seed: u64,
    /// Where references are cached.
    #[arg(long, default_value = ".cache/reference")]
    cache: PathBuf,
}

impl EstimatorArgs {
    fn settings(&self) -> ReferenceSettings {
        ReferenceSettings {
            seed: self.seed,
            target_noise: Some(self.target),
            ..ReferenceSettings::CONVERGED
        }
    }
}

impl Input {
    fn load(&self) -> Result<(Scene, Environment)> {
        let (scene, default_env) = match (&self.scene, &self.mesh) {
            (Some(name), _) => {
                let spec = SCENES.iter().find(|s| s.name == name);
                (
                    scenes::builtin(name)?,
                    spec.map_or("uniform", |s| s.environment),
                )
            }
            (None, Some(path)) => {
                let name = path
                    .file_stem()
                    .map_or("mesh".into(), |s| s.to_string_lossy().into_owned());
                let material = scenes::lambert(self.albedo.unwrap_or(1.0))?;
                let scene = scenes::asset_scene(&name, path, self.frames, material)?;
                (scene, "uniform")
            }
            (None, None) => bail!("give --scene or --mesh"),
        };
        Ok((scene, self.env.load(default_env)?))
    }
}

/// Prints a line above the progress bars, or to stderr when they are hidden
/// (output not a terminal).
fn say(multi: &MultiProgress, line: String) {
    if multi.is_hidden() || multi.println(&line).is_err() {
        eprintln!("{line}");
    }
}

fn progress(label: &str, multi: &MultiProgress) -> ProgressBar {
    let bar = multi.add(ProgressBar::new(0));
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>24} [{elapsed_precise}] {wide_bar} {percent}% eta {eta}",
        )
        .expect("valid template"),
    );
    bar.set_message(label.to_string());
    bar
}

fn references(
    scene: &Scene,
    env: &Environment,
    args: &EstimatorArgs,
    multi: &MultiProgress,
) -> Result<(Vec<reference::VertexReference>, ReferenceInfo)> {
    let bar = progress(&format!("reference {}", scene.name()), multi);
    let start = Instant::now();
    let cache = ReferenceCache::new(&args.cache);
    let (refs, cached) =
        reference::scene_references(scene, env, &args.settings(), Some(&cache), &bar)?;
    bar.finish_and_clear();
    let info = ReferenceInfo {
        scene: scene.name().to_string(),
        environment: env.name().to_string(),
        frames: refs.len(),
        vertices: scene.vertex_count(),
        noise: refs.iter().map(|r| r.noise).fold(0.0, f32::max),
        rays: refs.iter().map(|r| r.rays).sum(),
        seconds: seconds_spent(cached, start),
        cached,
        image: None,
    };
    Ok((refs, info))
}

/// Seconds since `start`, or 0 when the result came from the cache.
fn seconds_spent(cached: bool, start: Instant) -> f64 {
    if cached {
        0.0
    } else {
        start.elapsed().as_secs_f64()
    }
}

/// The per-pixel references of every frame seen through `camera`, and what
/// they cost.
fn image_references(
    scene: &Scene,
    env: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    args: &EstimatorArgs,
    multi: &MultiProgress,
) -> Result<(Vec<ImageReference>, ImageReferenceInfo)> {
    let bar = progress(&format!("image reference {}", scene.name()), multi);
    let start = Instant::now();
    let cache = ReferenceCache::new(&args.cache);
    let (refs, cached) =
        reference::scene_image_references(scene, env, camera, settings, Some(&cache), &bar)?;
    bar.finish_and_clear();
    let info = ImageReferenceInfo {
        width: camera.width,
        height: camera.height,
        pixels: refs
            .iter()
            .map(|r| r.image.covered.iter().filter(|c| **c).count())
            .sum(),
        noise: refs.iter().map(|r| r.noise).fold(0.0, f32::max),
        rays: refs.iter().map(|r| r.rays).sum(),
        seconds: seconds_spent(cached, start),
        cached,
    };
    Ok((refs, info))
}

/// Fails unless the folder `path` would be written into exists: checked
/// before any work, so that a typo costs nothing and leaves nothing behind.
fn check_output(path: &Path) -> Result<()> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    match parent {
        Some(dir) if !dir.is_dir() => bail!(
            "cannot write {}: the folder {} does not exist",
            path.display(),
            dir.display()
        ),
        _ => Ok(()),
    }
}

fn main() -> Result<()> {
    let multi = MultiProgress::new();
    match Cli::parse().command {
        Command::List => {
            println!("scenes:");
            for s in SCENES {
                println!("  {:<10} ({}) {}", s.name, s.environment, s.shows);
            }
            println!(
                "environments: {} (or a path to an .exr or .hdr lat-long map)",
                ENVIRONMENTS.join(", ")
            );
            println!("methods:");
            for (name, what) in methods::METHODS {
                println!("  {name:<12} {what}");
            }
        }
        Command::Reference {
            input,
            estimator,
            out,
        } => {
            let (scene, env) = input.load()?;
            let (refs, info) = references(&scene, &env, &estimator, &multi)?;
            println!(
                "{} under {}: {} frames, {} vertices, relative noise {:.3}%, {} rays, {}",
                info.scene,
                info.environment,
                info.frames,
                info.vertices,
                info.noise * 100.0,
                info.rays,
                if info.cached {
                    "from cache".to_string()
                } else {
                    format!("{:.1} s", info.seconds)
                }
            );
            if let Some(path) = out {
                export::write_vertices(&path, &scene.frame_geometry(0)?, &refs[0].radiance)?;
                println!("wrote {}", path.display());
            }
        }
        Command::Run {
            method,
            input,
            estimator,
            repeats,
            image,
            out,
            export: export_path,
        } => {
            for path in out.iter().chain(&export_path) {
                check_output(path)?;
            }
            let (scene, env) = input.load()?;
            let gpu = methods::SharedGpu::new();
            let mut m = methods::by_name(&method, &gpu)?;
            if export_path.is_some() && !m.capabilities().export {
                bail!(
                    "{} has nothing to export (it does not support {})",
                    m.name(),
                    shadow_core::Capability::Export
                );
            }
            let (refs, info) = references(&scene, &env, &estimator, &multi)?;
            let camera = image.camera(&scene)?;
            let (image_refs, image_info) = image_references(
                &scene,
                &env,
                &camera,
                &image.settings(&estimator),
                &estimator,
                &multi,
            )?;
            let references = References {
                vertex: &refs,
                image: Some((&camera, &image_refs)),
            };
            let mut exported = None;
            let last = scene.frames().len() - 1;
            let result =
                run::run_inspecting(m.as_mut(), &scene, &env, references, repeats, |i, m| {
                    if export_path.is_some() && i == last {
                        exported = Some(m.export()?);
                    }
                    Ok(())
                })?;
            println!(
                "{} on {} under {} (reference noise {:.3}% per vertex, {:.3}% per pixel at {}×{})",
                result.method,
                result.scene,
                result.environment,
                info.noise * 100.0,
                image_info.noise * 100.0,
                camera.width,
                camera.height
            );
            if let Some(adapter) = gpu.adapter() {
                println!("GPU adapter: {adapter}");
            }
            println!(
                "frame  vertex error  p99      max      image error  p99      max      update ms  shade ms  render ms  relight ms"
            );
            for f in &result.frames {
                let image = f.image.map_or_else(
                    || format!("{:>11}  {:>7}  {:>7}", "–", "–", "–"),
                    |e| {
                        format!(
                            "{:>10.2}%  {:>6.1}%  {:>6.1}%",
                            e.relative_l2 * 100.0,
                            e.p99 * 100.0,
                            e.max * 100.0
                        )
                    },
                );
                println!(
                    "{:>5}  {:>11.2}%  {:>6.1}%  {:>6.1}%  {image}  {:>9.2}  {:>8.2}  {:>9.2}  {:>10.2}",
                    f.frame,
                    f.vertex.relative_l2 * 100.0,
                    f.vertex.p99 * 100.0,
                    f.vertex.max * 100.0,
                    f.times.update * 1e3,
                    f.times.shade * 1e3,
                    f.times.render.unwrap_or(0.0) * 1e3,
                    f.times.relight * 1e3,
                );
                if !f.profile.is_empty() {
                    for line in f.profile.to_string().lines() {
                        println!("       {line}");
                    }
                }
            }
            if result.evaluated_fraction() < 1.0 {
                println!(
                    "vertex errors are over the {:.1}% of vertices the method evaluated",
                    result.evaluated_fraction() * 100.0
                );
            }
            println!(
                "time per frame: {:.2} ms per vertex (update + shade), {} per image (update + render)",
                result.frame_seconds() * 1e3,
                result
                    .image_frame_seconds()
                    .map_or("–".into(), |s| format!("{:.2} ms", s * 1e3))
            );
            if let (Some(path), Some(shading)) = (out, &result.last_shading) {
                export::write_vertices(&path, &scene.frame_geometry(last)?, shading)?;
                println!("wrote {}", path.display());
            }
            if let (Some(path), Some(exported)) = (export_path, exported) {
                let frame = scene.frame_geometry(last)?;
                let from = export::Provenance {
                    method: &result.method,
                    scene: &scene,
                    frame: &frame,
                };
                export::write_npz(&path, &exported, from)?;
                println!("wrote {}", path.display());
            }
            if let Some(dir) = &image.images {
                images::write_scene(dir, scene.name(), &image_refs[last].image, &[&result])?;
                println!("wrote the images in {}", dir.join(scene.name()).display());
            }
        }
        Command::Bake {
            mesh,
            out,
            quantity,
            method,
            attribute,
            replace,
            frames,
            frame,
            albedo,
            env,
            target,
            export: export_path,
        } => {
            for path in std::iter::once(&out).chain(&export_path) {
                check_output(path)?;
            }
            let attribute = attribute.unwrap_or_else(|| quantity.default_attribute().into());
            let spec = patch::AttributeSpec::new(&attribute, replace)?;
            let environment = env.load("uniform")?;
            quantity.check(&environment, &attribute)?;
            let asset = GltfAsset::load(&mesh)?;
            let name = mesh
                .file_stem()
                .map_or("mesh".into(), |s| s.to_string_lossy().into_owned());
            let scene = scenes::scene_of_asset(&name, &asset, frames, scenes::lambert(albedo)?)?;
            if frame >= scene.frames().len() {
                bail!(
                    "--frame {frame}: {} has {} frames (sample more with --frames)",
                    mesh.display(),
                    scene.frames().len()
                );
            }
            let start = Instant::now();
            let (radiance, exported) = if method == "reference" {
                if export_path.is_some() {
                    bail!("the reference has nothing to export: name a method");
                }
                let settings = ReferenceSettings {
                    target_noise: Some(target),
                    ..ReferenceSettings::CONVERGED
                };
                let bar = progress(&format!("reference {name}"), &multi);
                let r = bake::reference_frame(&scene, &environment, frame, &settings, &bar)?;
                bar.finish_and_clear();
                println!("reference: relative noise {:.3}%", r.noise * 100.0);
                (r.radiance, None)
            } else {
                let gpu = methods::SharedGpu::new();
                let mut m = methods::by_name(&method, &gpu)?;
                let radiance = bake::method_frame(m.as_mut(), &scene, &environment, frame)?;
                let exported = export_path.as_ref().map(|_| m.export()).transpose()?;
                (radiance, exported)
            };
            let values = quantity.values(&radiance, albedo);
            let sources: Vec<_> = asset.sources().cloned().collect();
            let summary = patch::write_with_attribute(&mesh, &out, &sources, &values, &spec)?;
            let all: Vec<f32> = values
                .iter()
                .flat_map(|v| v.values.iter().copied())
                .collect();
            let mean = all.iter().map(|&v| f64::from(v)).sum::<f64>() / all.len().max(1) as f64;
            println!(
                "{quantity:?} of {} under {}, frame {frame}, by {method} in {:.1} s: \
                 mean {mean:.4}, min {:.4}, max {:.4}",
                mesh.display(),
                environment.name(),
                start.elapsed().as_secs_f64(),
                all.iter().copied().fold(f32::INFINITY, f32::min),
                all.iter().copied().fold(f32::NEG_INFINITY, f32::max),
            );
            println!(
                "wrote {} with {attribute} on {} primitives ({} meshes copied for their \
                 instances, {} attributes replaced)",
                out.display(),
                summary.primitives,
                summary.copied_meshes,
                summary.replaced
            );
            if let (Some(path), Some(exported)) = (export_path, exported) {
                let geometry = scene.frame_geometry(frame)?;
                let from = export::Provenance {
                    method: &method,
                    scene: &scene,
                    frame: &geometry,
                };
                export::write_npz(&path, &exported, from)?;
                println!("wrote {}", path.display());
            }
        }
        Command::Report {
            suite,
            quick,
            full,
            scenes: chosen,
            dir,
            estimator,
            repeats,
            image,
        } => {
            let suite = match (quick, full) {
                (true, _) => Suite::Quick,
                (_, true) => Suite::Full,
                _ => suite,
            };
            let names: Vec<&str> = suite
                .scenes()
                .into_iter()
                .filter(|s| chosen.is_empty() || chosen.iter().any(|c| c == s))
                .collect();
            if names.is_empty() {
                bail!("no scene of the {suite:?} suite matches {chosen:?}");
            }
            let families = suite.families();
            let gpu = methods::SharedGpu::new();
            let mut report = Report {
                machine: MachineInfo::detect(None),
                settings: report::Settings {
                    suite,
                    target_noise: estimator.target,
                    image_target_noise: image.image_target,
                    image_width: image.width,
                    repeats,
                    seed: estimator.seed,
                },
                references: Vec::new(),
                families: families.clone(),
                runs: Vec::new(),
                skipped: Vec::new(),
                strip: None,
                atlas_scenes: Vec::new(),
                atlas: Vec::new(),
            };
            let settings_count: usize = families.iter().map(|f| f.methods.len()).sum();
            let atlas_names = if chosen.is_empty() {
                suite.atlas_scenes()
            } else {
                Vec::new()
            };
            let atlas_settings = suite.atlas_settings();
            let total = names.len() * settings_count + atlas_names.len() * atlas_settings.len();
            let overall = multi.add(ProgressBar::new(total as u64));
            overall.set_style(
                ProgressStyle::with_template(
                    "{msg:>40} [{elapsed_precise}] {wide_bar} {pos}/{len} runs",
                )
                .expect("valid template"),
            );
            for name in names {
                let spec = SCENES.iter().find(|s| s.name == name);
                let scene = scenes::builtin(name)?;
                let env = scenes::environment(spec.map_or("uniform", |s| s.environment))?;
                overall.set_message(format!("references of {name}"));
                let (refs, mut info) = references(&scene, &env, &estimator, &multi)?;
                let camera = image.camera(&scene)?;
                let settings = image.settings(&estimator);
                let (image_refs, image_info) =
                    image_references(&scene, &env, &camera, &settings, &estimator, &multi)?;
                info.image = Some(image_info);
                report.references.push(info);
                let references = References {
                    vertex: &refs,
                    image: Some((&camera, &image_refs)),
                };
                let first_run = report.runs.len();
                for family in &families {
                    for setting in &family.methods {
                        overall.set_message(format!("{name}: {setting}"));
                        let mut m = methods::by_name(setting, &gpu)?;
                        match run::run(m.as_mut(), &scene, &env, references, repeats) {
                            Ok(result) => {
                                say(
                                    &multi,
                                    format!(
                                        "{name:<10} {setting:<28} error {:.2}% per vertex, {} per pixel",
                                        result.mean_error() * 100.0,
                                        result
                                            .mean_image_error()
                                            .map_or("–".into(), |e| format!("{:.2}%", e * 100.0))
                                    ),
                                );
                                report.runs.push(report::ReportRun {
                                    family: family.name.to_string(),
                                    setting: setting.to_string(),
                                    result,
                                });
                            }
                            Err(e @ shadow_core::Error::Unsupported { .. }) => {
                                report.skipped.push(report::Skipped {
                                    method: setting.to_string(),
                                    scene: name.to_string(),
                                    why: e.to_string(),
                                });
                            }
                            Err(e) => {
                                return Err(e).with_context(|| format!("{setting} on {name}"));
                            }
                        }
                        overall.inc(1);
                    }
                }
                let runs: Vec<_> = report.runs[first_run..].iter().map(|r| &r.result).collect();
                if let (Some(images_dir), Some(reference)) = (&image.images, image_refs.last()) {
                    images::write_scene(images_dir, scene.name(), &reference.image, &runs)?;
                }
                if let (true, Some(reference)) = (name == STRIP_SCENE, image_refs.last()) {
                    images::write_scene(&dir.join("strip"), scene.name(), &reference.image, &runs)?;
                    report.strip = Some(scene.name().to_string());
                }
            }
            for name in atlas_names {
                let stress = scenes::stress::stress_scene(name)?;
                let (scene, env) = (&stress.scene, &stress.environment);
                overall.set_message(format!("references of {name}"));
                let (refs, mut info) = references(scene, env, &estimator, &multi)?;
                let camera = image.camera(scene)?;
                let settings = image.settings(&estimator);
                let (image_refs, image_info) =
                    image_references(scene, env, &camera, &settings, &estimator, &multi)?;
                info.image = Some(image_info);
                let atlas_scene = report::AtlasScene {
                    name: name.to_string(),
                    breaks: stress.breaks.to_string(),
                    reference: info,
                };
                let references = References {
                    vertex: &refs,
                    image: Some((&camera, &image_refs)),
                };
                let first = report.atlas.len();
                for (family, setting) in &atlas_settings {
                    overall.set_message(format!("{name}: {setting}"));
                    let mut m = methods::by_name(setting, &gpu)?;
                    let outcome = match run::run(m.as_mut(), scene, env, references, repeats) {
                        Ok(result) => report::Outcome::Ran(Box::new(result)),
                        Err(e) => report::Outcome::Refused(e.to_string()),
                    };
                    let entry =
                        report::AtlasRun::new(&atlas_scene, family, setting, outcome, &report.runs);
                    say(&multi, format!("{name:<16} {}", entry.diagnosis));
                    report.atlas.push(entry);
                    overall.inc(1);
                }
                let runs: Vec<&run::RunResult> = report.atlas[first..]
                    .iter()
                    .filter_map(|a| match &a.outcome {
                        report::Outcome::Ran(r) => Some(r.as_ref()),
                        report::Outcome::Refused(_) => None,
                    })
                    .collect();
                if let Some(reference) = image_refs.last() {
                    images::write_scene(&dir.join("atlas"), name, &reference.image, &runs)?;
                }
                report.atlas_scenes.push(atlas_scene);
            }
            overall.finish_and_clear();
            report.machine.adapter = gpu.adapter();
            report.write(&dir)?;
            println!(
                "wrote index.html, report.md, report.json, report.csv and the charts in {}",
                dir.display()
            );
        }
        Command::BenchTable { dir, out } => {
            let table = harness::bench_table::collect(&dir)?;
            match out {
                None => print!("{}", table.markdown()),
                Some(path) => {
                    let text = match path.extension().and_then(|e| e.to_str()) {
                        Some(ext) if ext.eq_ignore_ascii_case("md") => table.markdown(),
                        Some(ext) if ext.eq_ignore_ascii_case("csv") => table.csv(),
                        _ => bail!("--out {}: expected a .md or .csv file", path.display()),
                    };
                    harness::io::write_atomic(&path, text.as_bytes())?;
                    println!("wrote {}", path.display());
                }
            }
        }
        Command::Accuracy {
            scenes: chosen,
            env,
            out,
            estimator,
            transfer_rays,
            transfer_replicates,
            repeats,
            variants: wanted,
        } => {
            let names: Vec<&str> = if chosen.is_empty() {
                accuracy::DEFAULT_SCENES
                    .iter()
                    .copied()
                    .filter(|name| SCENES.iter().any(|s| s.name == *name))
                    .collect()
            } else {
                chosen.iter().map(String::as_str).collect()
            };
            let all = accuracy::variants();
            if let Some(unknown) = wanted.iter().find(|w| !all.iter().any(|v| v.name == *w)) {
                let known: Vec<&str> = all.iter().map(|v| v.name).collect();
                bail!(
                    "no configuration {unknown:?}; there are {}",
                    known.join(", ")
                );
            }
            let plan = Plan {
                transfer: TransferSettings {
                    replicate_size: transfer_rays,
                    replicates: transfer_replicates,
                    ..TransferSettings::CONVERGED
                },
                variants: all
                    .into_iter()
                    .filter(|v| wanted.is_empty() || wanted.iter().any(|w| w == v.name))
                    .collect(),
                repeats,
            };
            let mut report = AccuracyReport {
                machine: MachineInfo::detect(None),
                repeats,
                scenes: Vec::new(),
            };
            for name in names {
                let scene = scenes::builtin(name)?;
                let env_name = env.as_deref().unwrap_or_else(|| {
                    SCENES
                        .iter()
                        .find(|s| s.name == name)
                        .map_or("uniform", |s| s.environment)
                });
                let environment = scenes::environment(env_name)
                    .with_context(|| format!("loading environment {env_name}"))?;
                let (refs, info) = references(&scene, &environment, &estimator, &multi)?;
                let bar = progress(&format!("accuracy {name}"), &multi);
                let result = accuracy::evaluate(&scene, &environment, &refs, info, &plan, &bar)
                    .with_context(|| format!("accuracy on {name}"))?;
                bar.finish_and_clear();
                report.scenes.push(result);
            }
            report.write(&out)?;
            print!("{}", report.markdown());
            println!(
                "wrote accuracy.md, accuracy.json and {} (and SVG) in {}",
                accuracy::CHART,
                out.display()
            );
        }
    }
    Ok(())
}
