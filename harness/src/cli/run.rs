//! `harness run`: one method on one scene, its time per stage and error per
//! frame.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;

use super::args::{Input, ScoringArgs, check_output};
use crate::{
    export, images,
    methods::{Methods, SharedGpu},
    progress::Progress,
    reference::{ImageReferenceInfo, ReferenceInfo},
    run::{self, References, RunResult},
};

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Method name (see `harness list`).
    #[arg(long)]
    method: String,
    #[command(flatten)]
    input: Input,
    #[command(flatten)]
    scoring: ScoringArgs,
    /// Write the method's per-vertex results of the last frame to this .csv or .json file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write what the method computed for the last frame (SH transfer
    /// vectors, or visibility over directions) to this .npz file, for numpy.
    #[arg(long)]
    export: Option<PathBuf>,
}

pub fn run(args: RunArgs, methods: &Methods, progress: &Progress) -> Result<()> {
    for path in args.out.iter().chain(&args.export) {
        check_output(path)?;
    }
    let spec = methods.parse(&args.method)?;
    let (scene, env) = args.input.load()?;
    let gpu = SharedGpu::new();
    let mut method = spec.build(&gpu)?;
    if args.export.is_some() && !method.capabilities().export {
        bail!(
            "{spec} has nothing to export (it does not support {})",
            shadow_core::Capability::Export
        );
    }
    let cache = args.scoring.estimator.cache();
    let settings = args.scoring.estimator.settings();
    let (refs, info) = ReferenceInfo::compute(&scene, &env, &settings, &cache, progress)?;
    let camera = args.scoring.image.camera(&scene)?;
    let image_settings = args.scoring.image.settings(&args.scoring.estimator);
    let (image_refs, image_info) =
        ImageReferenceInfo::compute(&scene, &env, &camera, &image_settings, &cache, progress)?;
    let references = References {
        vertex: &refs,
        image: Some((&camera, &image_refs)),
    };
    let mut exported = None;
    let last = scene.frames().len() - 1;
    let wants_export = args.export.is_some();
    let result = run::run_inspecting(
        method.as_mut(),
        &scene,
        &env,
        references,
        args.scoring.repeats,
        |i, m| {
            if wants_export && i == last {
                exported = Some(m.export()?);
            }
            Ok(())
        },
    )?;
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
    print!("{}", frame_table(&result));
    if let Some(path) = &args.out
        && let Some(shading) = &result.last_shading
    {
        export::write_vertices(path, &scene.frame_geometry(last)?, shading)?;
        println!("wrote {}", path.display());
    }
    if let (Some(path), Some(exported)) = (&args.export, exported) {
        let frame = scene.frame_geometry(last)?;
        let from = export::Provenance {
            method: &result.method,
            scene: &scene,
            frame: &frame,
        };
        export::write_npz(path, &exported, from)?;
        println!("wrote {}", path.display());
    }
    if let Some(dir) = &args.scoring.image.images_dir {
        images::write_scene(dir, scene.name(), &image_refs[last].image, &[&result])?;
        println!("wrote the images in {}", dir.join(scene.name()).display());
    }
    Ok(())
}

/// Per frame: the errors per vertex and per pixel, the stages' times and
/// the method's own profile; then the time per frame.
fn frame_table(result: &RunResult) -> String {
    let mut text = String::from(
        "frame  vertex error  p99      max      image error  p99      max      update ms  shade ms  render ms  relight ms\n",
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
        text += &format!(
            "{:>5}  {:>11.2}%  {:>6.1}%  {:>6.1}%  {image}  {:>9.2}  {:>8.2}  {:>9.2}  {:>10.2}\n",
            f.frame,
            f.vertex.relative_l2 * 100.0,
            f.vertex.p99 * 100.0,
            f.vertex.max * 100.0,
            f.times.update.median() * 1e3,
            f.times.shade.median() * 1e3,
            f.times.render.as_ref().map_or(0.0, |r| r.median()) * 1e3,
            f.times.relight.median() * 1e3,
        );
        for line in f.profile.to_string().lines() {
            text += &format!("       {line}\n");
        }
    }
    if result.evaluated_fraction() < 1.0 {
        text += &format!(
            "vertex errors are over the {:.1}% of vertices the method evaluated\n",
            result.evaluated_fraction() * 100.0
        );
    }
    text += &format!(
        "time per frame (median, range): {} per vertex (update + shade), {} per image (update + render)\n",
        result.frame_time().describe_ms(),
        result
            .image_frame_time()
            .map_or("–".into(), |t| t.describe_ms())
    );
    text
}
