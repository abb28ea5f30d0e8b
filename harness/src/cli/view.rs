//! `harness view`: the interactive viewer, or its offscreen screenshot.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::{EnvArgs, Input, check_output};
use crate::{
    methods::Methods,
    reference::{ReferenceCache, ReferenceSettings},
    viewer::{self, Setup, offscreen::Shot},
};

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Method name (see `harness list`); switched live in the window.
    #[arg(long, default_value = "hemi-raster")]
    method: String,
    /// A built-in scene (see `harness list`).
    #[arg(long, conflicts_with = "mesh", required_unless_present = "mesh")]
    scene: Option<String>,
    /// Your own glTF/GLB file instead of a built-in scene (white Lambert material).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Frames to sample from the file's animation (default 1).
    #[arg(long, requires = "mesh")]
    mesh_frames: Option<usize>,
    #[command(flatten)]
    env: EnvArgs,
    /// Width of the window (or the screenshot) in pixels.
    #[arg(long, default_value_t = 800, value_parser = clap::value_parser!(u32).range(1..=16384))]
    width: u32,
    /// Height of the window (or the screenshot) in pixels.
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u32).range(1..=16384))]
    height: u32,
    /// Draw offscreen, without a window, write the last frame to this PNG
    /// and exit.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Frames drawn for --screenshot; the animation advances one scene frame
    /// per drawn frame, so the picture is of scene frame N − 1 (wrapping).
    #[arg(long, default_value_t = 1, requires = "screenshot",
          value_parser = clap::value_parser!(u32).range(1..))]
    frames: u32,
    /// Start with the error heat map against the cached image reference on.
    #[arg(long)]
    heat_map: bool,
    /// Display exposure in EV on top of the one `harness run --images` uses.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    display_ev: f32,
    /// Where references are cached (the heat map reads them).
    #[arg(long, default_value = ".cache/reference")]
    cache: PathBuf,
    /// Seed of the image references the heat map reads.
    #[arg(long, default_value_t = ReferenceSettings::IMAGE.seed)]
    seed: u64,
    /// Target noise of the image references the heat map reads (`harness
    /// run --image-target`).
    #[arg(long, default_value_t = ReferenceSettings::IMAGE.target_noise.unwrap_or(0.01))]
    image_target: f32,
}

pub fn view(args: ViewArgs, methods: &Methods) -> Result<()> {
    if let Some(path) = &args.screenshot {
        check_output(path)?;
    }
    methods.parse(&args.method)?;
    let input = Input {
        scene: args.scene,
        mesh: args.mesh,
        frames: args.mesh_frames,
        albedo: None,
        env: args.env,
    };
    let (scene, environment) = input.load()?;
    let setup = Setup {
        scene,
        environment,
        methods: methods.clone(),
        method: args.method,
        cache: ReferenceCache::new(&args.cache),
        reference: ReferenceSettings {
            seed: args.seed,
            target_noise: Some(args.image_target),
            ..ReferenceSettings::IMAGE
        },
    };
    let size = (args.width, args.height);
    match &args.screenshot {
        Some(out) => viewer::offscreen::screenshot(
            setup,
            &Shot {
                size,
                frames: args.frames as usize,
                heat_map: args.heat_map,
                exposure_ev: args.display_ev,
                out,
            },
        ),
        None => viewer::window::run(setup, size, args.heat_map, args.display_ev),
    }
}
