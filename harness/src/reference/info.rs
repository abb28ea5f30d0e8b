//! A scene's references with what they cost: computed, or loaded from the
//! cache, and summarized for a report.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use shadow_core::{Camera, Environment, Result, Scene};

use super::{
    ImageReference, ReferenceCache, ReferenceSettings, VertexReference, scene_image_references,
    scene_references,
};
use crate::progress::Progress;

/// A scene's references: how they were made and how noisy they are.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReferenceInfo {
    pub scene: String,
    pub environment: String,
    pub frames: usize,
    pub vertices: usize,
    /// Worst per-frame relative L2 noise.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub noise: f32,
    pub rays: u64,
    /// Seconds spent computing it (0 when every frame came from the cache).
    pub seconds: f64,
    pub cached: bool,
    /// The per-pixel reference, when images are scored.
    pub image: Option<ImageReferenceInfo>,
}

/// A scene's per-pixel reference.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ImageReferenceInfo {
    pub width: u32,
    pub height: u32,
    /// Covered pixels, summed over frames.
    pub pixels: usize,
    /// Worst per-frame relative L2 noise over the covered pixels.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub noise: f32,
    pub rays: u64,
    pub seconds: f64,
    pub cached: bool,
}

impl ReferenceInfo {
    /// Every frame's vertex reference of `scene` under `environment`, from
    /// `cache` where it holds them, and their summary.
    pub fn compute(
        scene: &Scene,
        environment: &Environment,
        settings: &ReferenceSettings,
        cache: &ReferenceCache,
        progress: &Progress,
    ) -> Result<(Vec<VertexReference>, ReferenceInfo)> {
        let bar = progress.task(&format!("reference {}", scene.name()));
        let start = Instant::now();
        let (refs, cached) = scene_references(scene, environment, settings, Some(cache), &bar)?;
        bar.finish_and_clear();
        let info = ReferenceInfo {
            scene: scene.name().to_string(),
            environment: environment.name().to_string(),
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
}

impl ImageReferenceInfo {
    /// Every frame's per-pixel reference seen through `camera`, from
    /// `cache` where it holds them, and their summary.
    pub fn compute(
        scene: &Scene,
        environment: &Environment,
        camera: &Camera,
        settings: &ReferenceSettings,
        cache: &ReferenceCache,
        progress: &Progress,
    ) -> Result<(Vec<ImageReference>, ImageReferenceInfo)> {
        let bar = progress.task(&format!("image reference {}", scene.name()));
        let start = Instant::now();
        let (refs, cached) =
            scene_image_references(scene, environment, camera, settings, Some(cache), &bar)?;
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
}

/// Seconds since `start`, or 0 when the result came from the cache.
fn seconds_spent(cached: bool, start: Instant) -> f64 {
    if cached {
        0.0
    } else {
        start.elapsed().as_secs_f64()
    }
}
