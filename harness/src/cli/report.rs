//! `harness report`: every family's sweep on every scene of a suite, and
//! the stability atlas, written as one report.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;

use super::args::ScoringArgs;
use crate::{
    methods::{Methods, SharedGpu},
    pictures::PICTURE_WIDTH,
    progress::Progress,
    reference::ReferenceSettings,
    report::{self, Part, Plan, Report},
    scenes::{self, SCENES, stress::STRESS_SCENES},
    suite::{Suite, Sweep},
};

#[derive(Args, Debug)]
pub struct ReportArgs {
    /// How much to run: `quick` (four small scenes, a few settings a
    /// method: minutes), `default` (every built-in scene but the 35k-vertex
    /// bunny, each method swept over its settings), `full` (every scene,
    /// and the settings that take minutes per frame).
    #[arg(long, value_enum, default_value_t = Suite::Default)]
    suite: Suite,
    /// Shorthand for `--suite quick`.
    #[arg(long, conflicts_with_all = ["suite", "full"])]
    quick: bool,
    /// Shorthand for `--suite full`.
    #[arg(long, conflicts_with = "suite")]
    full: bool,
    /// Only these scenes (comma separated): built-in scenes and stress
    /// scenes (see `harness list`), whether or not the suite lists them.
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// More settings to run beside the suite's (comma separated method
    /// names): each joins its family's sweep, and a family the suite does
    /// not have gets a sweep of its own and its first setting in the atlas.
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// Run only part I of N disjoint parts of the plan (its scenes dealt
    /// round-robin), writing that part's report.json and images into
    /// --out-dir; `--merge` builds the report from the N folders.
    #[arg(long, value_name = "I/N")]
    shard: Option<Part>,
    /// Build the report from the folders of parts written with --shard
    /// (every part of one plan, once), instead of running anything; the
    /// parts' settings are the report's.
    #[arg(
        long,
        value_name = "DIR",
        num_args = 1..,
        conflicts_with_all = ["shard", "suite", "quick", "full", "scenes", "methods", "picture_width"]
    )]
    merge: Vec<PathBuf>,
    /// The folder to write index.html, report.md, report.json, report.csv,
    /// charts/ and pictures/ into.
    #[arg(long, default_value = "reports")]
    out_dir: PathBuf,
    /// Width in pixels of the pictures of the strip and the atlas (framed
    /// on the errors they show, beside their error maps); their reference
    /// converges to three times the scored images' noise.
    #[arg(long, default_value_t = PICTURE_WIDTH,
          value_parser = clap::value_parser!(u32).range(16..=4096))]
    picture_width: u32,
    #[command(flatten)]
    scoring: ScoringArgs,
}

pub fn report(args: ReportArgs, methods: &Methods, progress: &Progress) -> Result<()> {
    if !args.merge.is_empty() {
        return merge(&args.merge, &args.out_dir);
    }
    let suite = match (args.quick, args.full) {
        (true, _) => Suite::Quick,
        (_, true) => Suite::Full,
        _ => args.suite,
    };
    let plan = plan(&args, suite, methods)?;
    let report = report::collect(&plan, &SharedGpu::new(), progress)?;
    if plan.part.is_whole() {
        report.write(&args.out_dir)?;
        println!(
            "wrote index.html, report.md, report.json, report.csv, the charts and the images in {}",
            args.out_dir.display()
        );
    } else {
        report.write_part(&args.out_dir)?;
        println!(
            "wrote part {} (report.json and the images) in {}; build the report with \
             `harness report --merge` and every part's folder",
            plan.part,
            args.out_dir.display()
        );
    }
    failures(&report, Some(plan.run_count()))
}

/// `report --merge`: the report from its parts' folders.
fn merge(dirs: &[PathBuf], out_dir: &Path) -> Result<()> {
    let parts = dirs
        .iter()
        .map(|dir| Ok((dir.display().to_string(), Report::read(dir)?)))
        .collect::<Result<Vec<_>>>()?;
    let report = report::merge(parts)?;
    for dir in dirs {
        report::copy_images(dir, out_dir)?;
    }
    report.write(out_dir)?;
    println!(
        "merged {} parts: wrote index.html, report.md, report.json, report.csv, the charts and \
         the images in {}",
        dirs.len(),
        out_dir.display()
    );
    failures(&report, None)
}

/// Fails, after the report is written, when any of its runs (`runs` of
/// them, where known) failed.
fn failures(report: &Report, runs: Option<usize>) -> Result<()> {
    if !report.failed.is_empty() {
        bail!(
            "{}{} runs failed (listed in the report): {}",
            report.failed.len(),
            runs.map_or(String::new(), |n| format!(" of {n}")),
            report
                .failed
                .iter()
                .map(|f| format!("{} on {}", f.method, f.scene))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}

/// What `args` asks of `suite`, every name checked before any work.
fn plan(args: &ReportArgs, suite: Suite, methods: &Methods) -> Result<Plan> {
    let stress: Vec<&'static str> = STRESS_SCENES.iter().map(|s| s.0).collect();
    for name in &args.scenes {
        let builtin = SCENES.iter().any(|s| s.name == name);
        if !builtin && !stress.contains(&name.as_str()) {
            let names = SCENES.iter().map(|s| s.name).chain(stress.iter().copied());
            return Err(scenes::unknown(name, "scene", names).into());
        }
    }
    // Named scenes run whichever suite lists them; without names, the
    // suite's own.
    let (scenes, atlas_scenes): (Vec<&'static str>, Vec<&'static str>) = if args.scenes.is_empty() {
        (suite.scenes(), suite.atlas_scenes())
    } else {
        let chosen = |name: &&str| args.scenes.iter().any(|c| c == name);
        (
            SCENES.iter().map(|s| s.name).filter(chosen).collect(),
            stress.iter().copied().filter(chosen).collect(),
        )
    };
    let mut sweeps = suite.families();
    let mut atlas_settings = suite.atlas_settings();
    for spec in methods.parse_all(&args.methods)? {
        match sweeps.iter_mut().find(|s| s.family == spec.family()) {
            Some(sweep) if sweep.methods.iter().any(|m| m.name() == spec.name()) => {}
            Some(sweep) => sweep.methods.push(spec),
            None => {
                atlas_settings.push(spec.clone());
                sweeps.push(Sweep {
                    family: spec.family(),
                    parameter: "the settings given with --methods",
                    methods: vec![spec],
                });
            }
        }
    }
    let image = args.scoring.image.settings(&args.scoring.estimator);
    Ok(Plan {
        suite,
        scenes,
        sweeps,
        atlas_scenes,
        atlas_settings,
        vertex: args.scoring.estimator.settings(),
        image,
        image_width: args.scoring.image.image_width,
        repeats: args.scoring.repeats,
        cache: args.scoring.estimator.cache.clone(),
        images: args.scoring.image.images_dir.clone(),
        out_dir: args.out_dir.clone(),
        part: args.shard.unwrap_or(Part::WHOLE),
        picture_width: args.picture_width,
        picture: ReferenceSettings {
            seed: image.seed,
            target_noise: image.target_noise.map(|n| 3.0 * n),
            ..ReferenceSettings::PICTURE
        },
        scaling_scenes: suite.scaling_scenes(),
        scaling_settings: suite.scaling_settings(),
        scaling_widths: suite.scaling_widths().to_vec(),
    })
}
