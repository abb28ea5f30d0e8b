//! `harness accuracy`: the transfer and radiance error of method settings
//! (by default each option of hemi-raster), Kautz et al.'s Table 1 measure.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::args::{EnvArgs, EstimatorArgs};
use crate::{
    accuracy::{self, AccuracyReport, Plan, Variant},
    methods::{Methods, SharedGpu},
    progress::Progress,
    reference::{ReferenceInfo, transfer::TransferSettings},
    report::MachineInfo,
    scenes::{self, SCENES},
};

#[derive(Args, Debug)]
pub struct AccuracyArgs {
    /// Only these built-in scenes (comma separated); default those of
    /// human, cloth and chess that are built in.
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// The method settings to score (comma separated names, see `harness
    /// list`); default hemi-raster's default and each of its options
    /// changed alone.
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    #[command(flatten)]
    env: EnvArgs,
    /// The folder to write accuracy.md, accuracy.json and the chart
    /// (accuracy.png and .svg) into.
    #[arg(long, default_value = "reports")]
    out_dir: PathBuf,
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
}

pub fn accuracy(args: AccuracyArgs, methods: &Methods, progress: &Progress) -> Result<()> {
    let names: Vec<&str> = if args.scenes.is_empty() {
        accuracy::DEFAULT_SCENES
            .iter()
            .copied()
            .filter(|name| SCENES.iter().any(|s| s.name == *name))
            .collect()
    } else {
        args.scenes.iter().map(String::as_str).collect()
    };
    for name in &names {
        if !SCENES.iter().any(|s| s.name == *name) {
            let known = SCENES.iter().map(|s| s.name);
            return Err(scenes::unknown(name, "built-in scene", known).into());
        }
    }
    let variants = if args.methods.is_empty() {
        accuracy::variants()
    } else {
        methods
            .parse_all(&args.methods)?
            .into_iter()
            .map(Variant::described)
            .collect()
    };
    let plan = Plan {
        transfer: TransferSettings {
            replicate_size: args.transfer_rays,
            replicates: args.transfer_replicates,
            ..TransferSettings::CONVERGED
        },
        variants,
        repeats: args.repeats,
    };
    let mut report = AccuracyReport {
        machine: MachineInfo::detect(None),
        repeats: args.repeats,
        scenes: Vec::new(),
    };
    let gpu = SharedGpu::new();
    let cache = args.estimator.cache();
    for name in names {
        let scene = scenes::builtin(name)?;
        let own = SCENES
            .iter()
            .find(|s| s.name == name)
            .map_or("uniform", |s| s.environment);
        let environment = args.env.load(own)?;
        let settings = args.estimator.settings();
        let (refs, info) =
            ReferenceInfo::compute(&scene, &environment, &settings, &cache, progress)?;
        let bar = progress.task(&format!("accuracy {name}"));
        let result = accuracy::evaluate(&scene, &environment, &refs, info, &plan, &gpu, &bar)
            .with_context(|| format!("accuracy on {name}"))?;
        bar.finish_and_clear();
        report.scenes.push(result);
    }
    report.machine.adapter = gpu.adapter();
    report.write(&args.out_dir)?;
    print!("{}", report.markdown());
    println!(
        "wrote accuracy.md, accuracy.json and {} (and SVG) in {}",
        accuracy::CHART,
        args.out_dir.display()
    );
    Ok(())
}
