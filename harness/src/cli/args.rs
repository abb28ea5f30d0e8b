//! Argument groups the commands share: the scene, the environment, the
//! reference's estimator, the scored images.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use shadow_core::{Camera, Environment, Scene, raster::MAX_IMAGE_SIZE};

use crate::{
    reference::{ReferenceCache, ReferenceSettings},
    scenes::{
        self, SCENES,
        stress::{STRESS_SCENES, stress_scene},
    },
};

/// A built-in scene or the user's glTF file.
#[derive(Args, Debug)]
pub struct Input {
    /// A built-in scene or a stress scene (see `harness list`).
    #[arg(long, conflicts_with = "mesh", required_unless_present = "mesh")]
    pub scene: Option<String>,
    /// Your own glTF/GLB file instead of a built-in scene (white Lambert material).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Frames to sample from the file's animation (default 1).
    #[arg(long, requires = "mesh")]
    pub frames: Option<usize>,
    /// Albedo of the white Lambert material given to --mesh (default 1: then
    /// `--env uniform` gives each vertex's ambient occlusion itself).
    #[arg(long, requires = "mesh")]
    pub albedo: Option<f32>,
    #[command(flatten)]
    pub env: EnvArgs,
}

impl Input {
    /// The scene and its environment (the scene's own unless `--env`).
    pub fn load(&self) -> Result<(Scene, Environment)> {
        let (scene, default_env) = match (&self.scene, &self.mesh) {
            (Some(name), _) if STRESS_SCENES.iter().any(|(s, _)| s == name) => {
                let stress = stress_scene(name)?;
                let env = match &self.env.env {
                    None => self.env.adjust(stress.environment)?,
                    Some(_) => self.env.load("uniform")?,
                };
                return Ok((stress.scene, env));
            }
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
                let frames = self.frames.unwrap_or(1);
                (
                    scenes::asset_scene(&name, path, frames, material)?,
                    "uniform",
                )
            }
            (None, None) => bail!("give --scene or --mesh"),
        };
        Ok((scene, self.env.load(default_env)?))
    }
}

/// The environment, turned and exposed.
#[derive(Args, Debug)]
pub struct EnvArgs {
    /// An environment name (see `harness list`; `uniform` gives ambient occlusion)
    /// or an OpenEXR (.exr) or Radiance (.hdr) lat-long map; default: the scene's own.
    #[arg(long)]
    pub env: Option<String>,
    /// Turns the environment about the vertical (+Y) axis by this many degrees
    /// (positive: counter-clockwise seen from above).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub env_rotate: f32,
    /// Scales the environment's radiance by 2^EV.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub exposure: f32,
}

impl EnvArgs {
    /// The environment named by --env (else `default`), turned and exposed.
    pub fn load(&self, default: &str) -> Result<Environment> {
        let name = self.env.as_deref().unwrap_or(default);
        let env =
            scenes::environment(name).with_context(|| format!("loading environment {name}"))?;
        self.adjust(env)
    }

    /// `env` turned and exposed as asked.
    pub fn adjust(&self, env: Environment) -> Result<Environment> {
        Ok(scenes::adjusted(env, self.env_rotate, self.exposure)?)
    }
}

/// The Monte-Carlo reference's noise target, seed and cache.
#[derive(Args, Debug)]
pub struct EstimatorArgs {
    /// Target relative L2 noise of the per-vertex reference.
    #[arg(long, default_value_t = 0.005)]
    pub target: f32,
    /// Seed of the reference's random streams.
    #[arg(long, default_value_t = ReferenceSettings::CONVERGED.seed)]
    pub seed: u64,
    /// Where references are cached.
    #[arg(long, default_value = ".cache/reference")]
    pub cache: PathBuf,
}

impl EstimatorArgs {
    /// The per-vertex reference's settings.
    pub fn settings(&self) -> ReferenceSettings {
        ReferenceSettings {
            seed: self.seed,
            target_noise: Some(self.target),
            ..ReferenceSettings::CONVERGED
        }
    }

    pub fn cache(&self) -> ReferenceCache {
        ReferenceCache::new(&self.cache)
    }
}

/// How runs are scored: the references, the images, the repeats.
#[derive(Args, Debug)]
pub struct ScoringArgs {
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    #[command(flatten)]
    pub image: ImageArgs,
    /// Repeats per stage: each stage is timed at least three times (where this
    /// allows) and reported as its median and range.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
}

/// The images scored per pixel.
#[derive(Args, Debug)]
pub struct ImageArgs {
    /// Width in pixels of the images scored per pixel (the scene camera's
    /// aspect kept); 512 matches the papers' comparisons.
    #[arg(long, default_value_t = DEFAULT_IMAGE_WIDTH,
          value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_IMAGE_SIZE)))]
    pub image_width: u32,
    /// Target relative L2 noise of the per-pixel reference.
    #[arg(long, default_value_t = ReferenceSettings::IMAGE.target_noise.unwrap_or(0.01))]
    pub image_target: f32,
    /// Also write each scene's images into this folder: per method the image
    /// (linear .exr and tone-mapped .png) and an error heat map, and the
    /// reference.
    #[arg(long)]
    pub images_dir: Option<PathBuf>,
}

/// The default width of scored images.
const DEFAULT_IMAGE_WIDTH: u32 = 160;

impl ImageArgs {
    pub fn camera(&self, scene: &Scene) -> Result<Camera> {
        Ok(scene.camera().with_width(self.image_width)?)
    }

    /// The per-pixel reference's settings.
    pub fn settings(&self, estimator: &EstimatorArgs) -> ReferenceSettings {
        ReferenceSettings {
            seed: estimator.seed,
            target_noise: Some(self.image_target),
            ..ReferenceSettings::IMAGE
        }
    }
}

/// Fails unless the folder `path` would be written into exists: checked
/// before any work, so that a typo costs nothing and leaves nothing behind.
pub fn check_output(path: &Path) -> Result<()> {
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
