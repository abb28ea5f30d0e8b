//! The Monte-Carlo reference every method is scored against (DESIGN.md,
//! "Scoring"): an unbiased estimate of outgoing radiance per vertex or per
//! pixel, with its standard error, optionally run until its own noise is a
//! given fraction of the signal, and cached on disk by content hash.

mod cache;
mod estimator;

use std::time::Instant;

use glam::Vec3;
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use shadow_core::{
    Camera, Environment, FrameGeometry, Image, Result, Scene, VertexRadiance, bvh::SceneBvh,
    environment::EnvironmentSampler,
};

pub use cache::{ReferenceCache, cache_key};
pub use estimator::{Accumulator, Estimator, ShadingPoint, stream};

/// How long the estimator runs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceSettings {
    /// Seed of every random stream: same seed, same result.
    pub seed: u64,
    /// MIS iterations per point in the first round (each iteration draws one
    /// cosine and one environment sample).
    pub min_iterations: u32,
    /// No point gets more iterations than this.
    pub max_iterations: u32,
    /// Run until the relative L2 noise `sqrt(Σ|SE|² / Σ|L|²)` is at most this:
    /// after each round, points whose |SE|² exceeds target² · mean(|L|²) get
    /// twice their iterations (up to `max_iterations`). `None` runs exactly
    /// `min_iterations` per point.
    pub target_noise: Option<f32>,
}

impl ReferenceSettings {
    /// A converged reference: 0.5% relative noise, at most 2²⁰ iterations a point.
    pub const CONVERGED: ReferenceSettings = ReferenceSettings {
        seed: 0x5eed,
        min_iterations: 64,
        max_iterations: 1 << 20,
        target_noise: Some(0.005),
    };

    /// Exactly `iterations` per point, no adaptivity (the ray-tracing baseline).
    pub fn fixed(iterations: u32, seed: u64) -> ReferenceSettings {
        ReferenceSettings {
            seed,
            min_iterations: iterations,
            max_iterations: iterations,
            target_noise: None,
        }
    }
}

/// Estimates at a list of points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Estimates {
    pub mean: Vec<Vec3>,
    pub std_error: Vec<Vec3>,
    pub iterations: Vec<u32>,
    /// Shadow rays traced in all.
    pub rays: u64,
}

impl Estimates {
    /// `sqrt(Σ|SE|² / Σ|L|²)`: the reference's own contribution to a relative
    /// L2 error measured against it.
    pub fn relative_noise(&self) -> f32 {
        let se: f64 = self
            .std_error
            .iter()
            .map(|s| s.length_squared() as f64)
            .sum();
        let signal: f64 = self.mean.iter().map(|m| m.length_squared() as f64).sum();
        if signal == 0.0 {
            0.0
        } else {
            (se / signal).sqrt() as f32
        }
    }
}

/// Runs the estimator at every point, in rounds, in parallel.
pub fn estimate(
    points: &[ShadingPoint],
    estimator: &Estimator,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Estimates {
    let mut acc = vec![Accumulator::default(); points.len()];
    let mut budget = vec![settings.min_iterations.min(settings.max_iterations); points.len()];
    let mut rays = 0u64;
    progress.set_length(budget.iter().map(|&b| b as u64).sum());
    for round in 0u32.. {
        rays += acc
            .par_iter_mut()
            .zip(points.par_iter())
            .zip(budget.par_iter())
            .enumerate()
            .filter(|(_, ((a, _), b))| **b > a.count)
            .map(|(i, ((a, p), &b))| {
                let mut rng = stream(settings.seed, i, round);
                let todo = b - a.count;
                let r = estimator.accumulate(p, &mut rng, todo, a);
                progress.inc(todo as u64);
                r
            })
            .sum::<u64>();

        let Some(target) = settings.target_noise else {
            break;
        };
        let mean_sq = acc
            .iter()
            .map(|a| a.mean().length_squared() as f64)
            .sum::<f64>()
            / acc.len().max(1) as f64;
        let threshold = (target as f64).powi(2) * mean_sq;
        let mut more = 0u64;
        for (a, b) in acc.iter().zip(budget.iter_mut()) {
            if a.count < settings.max_iterations
                && a.std_error().length_squared() as f64 > threshold
            {
                let next = (a.count * 2).min(settings.max_iterations);
                more += (next - a.count) as u64;
                *b = next;
            }
        }
        if more == 0 {
            break;
        }
        progress.inc_length(more);
    }
    Estimates {
        mean: acc.iter().map(Accumulator::mean).collect(),
        std_error: acc.iter().map(Accumulator::std_error).collect(),
        iterations: acc.iter().map(|a| a.count).collect(),
        rays,
    }
}

/// The shading points of every vertex of a frame, seen from `eye`.
pub fn vertex_points(scene: &Scene, frame: &FrameGeometry, eye: Vec3) -> Vec<ShadingPoint> {
    frame
        .objects
        .iter()
        .zip(scene.objects())
        .flat_map(|(posed, object)| {
            posed
                .positions()
                .iter()
                .zip(posed.normals())
                .map(move |(&position, &normal)| ShadingPoint {
                    position,
                    normal,
                    view: (eye - position).normalize_or(normal),
                    material: object.material,
                })
        })
        .collect()
}

/// The surface point seen through the centre of every pixel, if any. Normals
/// are interpolated from the vertices and, where the camera sees the back of a
/// surface (open meshes), flipped to face it: surfaces are two-sided.
pub fn pixel_points(
    scene: &Scene,
    frame: &FrameGeometry,
    bvh: &SceneBvh,
    camera: &Camera,
) -> Vec<Option<ShadingPoint>> {
    let (w, h) = (camera.width, camera.height);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let dir = camera.ray_direction(i % w, i / w);
            let hit = bvh.closest_hit(camera.eye, dir, f32::INFINITY)?;
            let object = &frame.objects[hit.object as usize];
            let tri = object.triangles()[hit.triangle as usize];
            let [a, b, c] = tri.map(|v| v as usize);
            let (p, n) = (object.positions(), object.normals());
            let bary = hit.barycentric;
            let position = camera.eye + dir * hit.t;
            let geometric = (p[b] - p[a]).cross(p[c] - p[a]);
            let mut normal =
                (n[a] * bary.x + n[b] * bary.y + n[c] * bary.z).normalize_or(geometric.normalize());
            if geometric.dot(dir) > 0.0 {
                normal = -normal;
            }
            Some(ShadingPoint {
                position,
                normal,
                view: -dir,
                material: scene.objects()[hit.object as usize].material,
            })
        })
        .collect()
}

/// A reference (or a low-sample ray-traced estimate) per vertex.
#[derive(Clone, Debug)]
pub struct VertexReference {
    pub radiance: VertexRadiance,
    pub iterations: Vec<u32>,
    pub rays: u64,
    pub noise: f32,
    pub seconds: f64,
}

/// Everything the estimator needs for one frame under one environment.
pub struct Setup {
    pub bvh: SceneBvh,
    pub sampler: EnvironmentSampler,
}

impl Setup {
    pub fn new(frame: &FrameGeometry, environment: &Environment) -> Result<Setup> {
        Ok(Setup {
            bvh: SceneBvh::build(frame)?,
            sampler: EnvironmentSampler::new(environment),
        })
    }

    pub fn estimator<'a>(&'a self, environment: &'a Environment) -> Estimator<'a> {
        Estimator {
            bvh: &self.bvh,
            environment,
            sampler: &self.sampler,
            offset: self.bvh.ray_offset(),
        }
    }
}

/// Estimates outgoing radiance toward `eye` at every vertex of `frame`.
pub fn vertex_reference(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    eye: Vec3,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<VertexReference> {
    let start = Instant::now();
    let setup = Setup::new(frame, environment)?;
    let points = vertex_points(scene, frame, eye);
    let est = estimate(&points, &setup.estimator(environment), settings, progress);
    Ok(VertexReference {
        radiance: split_per_object(frame, &est),
        noise: est.relative_noise(),
        iterations: est.iterations,
        rays: est.rays,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Estimates outgoing radiance at the surface seen through every pixel; also
/// returns the estimate's relative noise.
pub fn pixel_reference(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<(Image, f32)> {
    let setup = Setup::new(frame, environment)?;
    let pixels = pixel_points(scene, frame, &setup.bvh, camera);
    Ok(image_from_points(
        camera,
        &pixels,
        &setup.estimator(environment),
        settings,
        progress,
    ))
}

/// Runs the estimator at the covered pixels of `pixels` and assembles the image
/// and its relative noise.
pub fn image_from_points(
    camera: &Camera,
    pixels: &[Option<ShadingPoint>],
    estimator: &Estimator,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> (Image, f32) {
    let covered: Vec<bool> = pixels.iter().map(Option::is_some).collect();
    let points: Vec<ShadingPoint> = pixels.iter().flatten().copied().collect();
    let est = estimate(&points, estimator, settings, progress);
    let mut image = Image {
        width: camera.width,
        height: camera.height,
        pixels: vec![Vec3::ZERO; covered.len()],
        covered,
        std_error: Some(vec![Vec3::ZERO; pixels.len()]),
    };
    let slots = image
        .covered
        .iter()
        .enumerate()
        .filter(|(_, c)| **c)
        .map(|(i, _)| i);
    let errors = image.std_error.as_mut().expect("set above");
    for ((slot, mean), se) in slots.zip(&est.mean).zip(&est.std_error) {
        image.pixels[slot] = *mean;
        errors[slot] = *se;
    }
    (image, est.relative_noise())
}

/// Splits flat per-point estimates into per-object vectors.
pub fn split_per_object(frame: &FrameGeometry, est: &Estimates) -> VertexRadiance {
    let mut radiance = Vec::with_capacity(frame.objects.len());
    let mut std_error = Vec::with_capacity(frame.objects.len());
    let mut start = 0;
    for object in &frame.objects {
        let end = start + object.vertex_count();
        radiance.push(est.mean[start..end].to_vec());
        std_error.push(est.std_error[start..end].to_vec());
        start = end;
    }
    VertexRadiance {
        radiance,
        std_error: Some(std_error),
    }
}

/// The vertex reference of every frame of `scene` under `environment`, seen
/// from the scene's camera, from `cache` where present (and stored there when
/// computed). Also says whether every frame came from the cache.
pub fn scene_references(
    scene: &Scene,
    environment: &Environment,
    settings: &ReferenceSettings,
    cache: Option<&ReferenceCache>,
    progress: &ProgressBar,
) -> Result<(Vec<VertexReference>, bool)> {
    let eye = scene.camera().eye;
    let mut all_cached = true;
    let mut out = Vec::with_capacity(scene.frames().len());
    for index in 0..scene.frames().len() {
        let frame = scene.frame_geometry(index)?;
        let compute = || vertex_reference(scene, &frame, environment, eye, settings, progress);
        let (reference, cached) = match cache {
            Some(cache) => cache.get_or_compute(
                &cache_key(scene, &frame, environment, eye, settings),
                &frame,
                compute,
            )?,
            None => (compute()?, false),
        };
        all_cached &= cached;
        out.push(reference);
    }
    Ok((out, all_cached))
}
