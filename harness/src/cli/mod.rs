//! The `harness` command line: its arguments and which command runs. A
//! host with method families of its own runs the same commands over them
//! with [`main`]:
//!
//! ```no_run
//! use harness::methods::Methods;
//!
//! fn main() -> anyhow::Result<()> {
//!     harness::cli::main(Methods::builtin())
//! }
//! ```

mod accuracy;
mod args;
mod bake;
mod report;
mod run;
#[cfg(feature = "viewer")]
mod view;

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};

use crate::{
    methods::Methods,
    progress::Progress,
    reference::ReferenceInfo,
    scenes::{ENVIRONMENTS, SCENES, stress::STRESS_SCENES},
};
use args::{EstimatorArgs, Input, check_output};

#[derive(Parser, Debug)]
#[command(
    name = "harness",
    about = "Compare soft-shadow methods against a Monte-Carlo reference"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// List the built-in scenes, stress scenes, environments and method
    /// families with their options.
    List,
    /// Compute (or load from the cache) the reference of a scene and print
    /// its noise; with --out, write the first frame's per-vertex radiance.
    Reference {
        #[command(flatten)]
        input: Input,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Write per-vertex results of the first frame to this .csv or .json file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Run one method on a scene and print its time per stage and error per
    /// frame; with --out, --export or --images-dir, write its results.
    Run(run::RunArgs),
    /// Bake a per-vertex result of your glTF file into a copy of it: ambient
    /// occlusion, irradiance or radiance of one frame, as a vertex attribute.
    /// Everything else in the file is kept.
    Bake(bake::BakeArgs),
    /// Run every family's sweep on every scene of a suite and the stability
    /// atlas; write index.html, report.md, report.json, report.csv, the
    /// charts (PNG and SVG) and the images into --out-dir. A setting that
    /// fails is listed in the report and the command fails after writing it.
    Report(report::ReportArgs),
    /// Criterion's saved results (`cargo bench -p benches`) as one table:
    /// each benchmark's median time per iteration with criterion's
    /// confidence interval, and the method's error where the bench
    /// recorded it; printed as Markdown, or written to --out.
    BenchTable {
        /// Criterion's output folder, read.
        #[arg(long, default_value = "target/criterion")]
        criterion_dir: PathBuf,
        /// Write the table to this file instead of printing it: `.md` for
        /// Markdown, `.csv` for CSV (one line per benchmark).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Score method settings (by default hemi-raster's options) by Kautz et
    /// al.'s transfer error and by radiance error; write accuracy.md,
    /// accuracy.json and accuracy.png and .svg (time against error) into
    /// --out-dir.
    Accuracy(accuracy::AccuracyArgs),
    /// Show a scene with a method's result in a window: switch methods
    /// (keys 1–5 or any name), orbit (drag), turn the environment (← →),
    /// play the animation (space), show the error against a cached image
    /// reference (H); with --screenshot, draw offscreen and write a PNG.
    #[cfg(feature = "viewer")]
    View(view::ViewArgs),
}

/// Parses the process's arguments and runs the command, with `methods` the
/// families every command accepts.
pub fn main(methods: Methods) -> Result<()> {
    let progress = Progress::new();
    match Cli::parse().command {
        Command::List => list(&methods),
        Command::Reference {
            input,
            estimator,
            out,
        } => reference(&input, &estimator, out, &progress),
        Command::Run(args) => run::run(args, &methods, &progress),
        Command::Bake(args) => bake::bake(args, &methods, &progress),
        Command::Report(args) => report::report(args, &methods, &progress),
        Command::BenchTable { criterion_dir, out } => bench_table(&criterion_dir, out),
        Command::Accuracy(args) => accuracy::accuracy(args, &methods, &progress),
        #[cfg(feature = "viewer")]
        Command::View(args) => view::view(args, &methods),
    }
}

fn list(methods: &Methods) -> Result<()> {
    println!("scenes:");
    for s in SCENES {
        println!("  {:<10} ({}) {}", s.name, s.environment, s.shows);
    }
    println!("stress scenes (the stability atlas):");
    for (name, breaks) in STRESS_SCENES {
        println!("  {name:<18} {breaks}");
    }
    println!(
        "environments: {} (or a path to an .exr or .hdr lat-long map)",
        ENVIRONMENTS.join(", ")
    );
    println!("method families (a name is the family, then options after ':'):");
    for family in methods.families() {
        println!("  {:<16} {}", family.name, family.about);
        if !family.options.is_empty() {
            println!("  {:<16} options: {}", "", family.options.join(", "));
        }
    }
    Ok(())
}

fn reference(
    input: &Input,
    estimator: &EstimatorArgs,
    out: Option<PathBuf>,
    progress: &Progress,
) -> Result<()> {
    if let Some(path) = &out {
        check_output(path)?;
    }
    let (scene, env) = input.load()?;
    let (refs, info) = ReferenceInfo::compute(
        &scene,
        &env,
        &estimator.settings(),
        &estimator.cache(),
        progress,
    )?;
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
        crate::export::write_vertices(&path, &scene.frame_geometry(0)?, &refs[0].radiance)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn bench_table(criterion_dir: &std::path::Path, out: Option<PathBuf>) -> Result<()> {
    let table = crate::bench_table::collect(criterion_dir)?;
    match out {
        None => print!("{}", table.markdown()),
        Some(path) => {
            let text = match path.extension().and_then(|e| e.to_str()) {
                Some(ext) if ext.eq_ignore_ascii_case("md") => table.markdown(),
                Some(ext) if ext.eq_ignore_ascii_case("csv") => table.csv(),
                _ => bail!("--out {}: expected a .md or .csv file", path.display()),
            };
            crate::io::write_atomic(&path, text.as_bytes())?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
