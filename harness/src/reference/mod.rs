//! The Monte-Carlo reference every method is scored against (DESIGN.md,
//! "Scoring"): an unbiased estimate of outgoing radiance per vertex or per
//! pixel, with its standard error, optionally run until its own noise is a
//! given fraction of the signal, and cached on disk by content hash.

mod cache;
mod estimator;
mod info;
pub mod transfer;
mod unoccluded;

use std::cell::OnceCell;
use std::time::Instant;

use glam::Vec3;
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use shadow_core::{
    Camera, Environment, Error, FrameGeometry, Image, Result, Scene, VertexRadiance, bvh::SceneBvh,
    environment::EnvironmentSampler,
};

pub use cache::{Domain, ReferenceCache, cache_key};
pub use estimator::{Accumulator, Estimator, Known, ShadingPoint, stream};
pub use info::{ImageReferenceInfo, ReferenceInfo};
pub use unoccluded::Unoccluded;

/// How long the estimator runs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceSettings {
    /// Seed of every random stream: same seed, same result.
    pub seed: u64,
    /// MIS iterations per replicate (each iteration draws one cosine and one
    /// environment sample); a power of two keeps the Sobol' points stratified.
    pub replicate_size: u32,
    /// Replicates per point in the first round. Standard errors need two.
    pub min_replicates: u32,
    /// No point gets more replicates than this.
    pub max_replicates: u32,
    /// Run until the relative L2 noise `sqrt(Σ|SE|² / Σ|L|²)` is at most this,
    /// giving each point the replicates its own variance calls for (see
    /// `allocate`; at most `max_replicates`). `None` runs exactly
    /// `min_replicates` per point.
    pub target_noise: Option<f32>,
}

impl ReferenceSettings {
    /// A converged reference: 0.5% relative noise, replicates of 128
    /// iterations, at most 2¹⁴ replicates (2²¹ iterations) a point.
    pub const CONVERGED: ReferenceSettings = ReferenceSettings {
        seed: 0x5eed,
        replicate_size: 128,
        min_replicates: 4,
        max_replicates: 1 << 14,
        target_noise: Some(0.005),
    };

    /// A bake ([`crate::bake`]): 1% relative noise, the first round two
    /// replicates of 64 iterations. Smaller replicates make the standard
    /// error an underestimate: on the 35k bunny's ambient occlusion against
    /// a 0.14% reference, 2 × 64 claimed 0.94% and erred by 0.92%, while
    /// 2 × 32 claimed 0.83% for 1.22%, 3 × 32 0.82% for 1.02% and 4 × 16
    /// 0.95% for 1.07%.
    pub const BAKE: ReferenceSettings = ReferenceSettings {
        replicate_size: 64,
        min_replicates: 2,
        target_noise: Some(0.01),
        ..ReferenceSettings::CONVERGED
    };

    /// A converged image: 1% relative noise over the covered pixels,
    /// replicates of 64 iterations, at most 2¹² replicates a pixel. Pixels
    /// are many and each one's noise is averaged with its neighbours' by
    /// the eye, so the target is looser than per vertex.
    pub const IMAGE: ReferenceSettings = ReferenceSettings {
        seed: 0x5eed,
        replicate_size: 64,
        min_replicates: 4,
        max_replicates: 1 << 12,
        target_noise: Some(0.01),
    };

    /// A picture's reference ([`crate::pictures`]): 3% relative noise, the
    /// first round two replicates of 64 iterations. Pictures have ten times
    /// the scored images' pixels and are for the eye and the error maps
    /// (whose scale starts at 0.1%), and their cost is mostly the first
    /// round: four replicates of 128 left the default report's pictures at
    /// 0.2–1.3% noise. Smaller replicates claim too little: the bunny's
    /// 512-wide picture under `courtyard`, against a 0.54% reference, erred
    /// by 2.47% with 2 × 64 (claimed 2.46%) but by 3.43% with 2 × 32
    /// (claimed 2.34%).
    pub const PICTURE: ReferenceSettings = ReferenceSettings {
        replicate_size: 64,
        min_replicates: 2,
        target_noise: Some(0.03),
        ..ReferenceSettings::IMAGE
    };

    /// Exactly `iterations` per point in one stratified replicate, no
    /// adaptivity and no standard error (the ray-tracing baseline).
    pub fn fixed(iterations: u32, seed: u64) -> ReferenceSettings {
        ReferenceSettings {
            seed,
            replicate_size: iterations,
            min_replicates: 1,
            max_replicates: 1,
            target_noise: None,
        }
    }

    /// `replicates` independent replicates of `size` iterations each, no
    /// adaptivity: results carry standard errors.
    pub fn replicated(size: u32, replicates: u32, seed: u64) -> ReferenceSettings {
        ReferenceSettings {
            seed,
            replicate_size: size,
            min_replicates: replicates,
            max_replicates: replicates,
            target_noise: None,
        }
    }
}

/// Estimates at a list of points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Estimates {
    pub mean: Vec<Vec3>,
    /// Standard errors, when every point had at least two replicates.
    pub std_error: Option<Vec<Vec3>>,
    /// Replicates per point.
    pub replicates: Vec<u32>,
    /// Shadow rays traced in all.
    pub rays: u64,
}

impl Estimates {
    /// `sqrt(Σ|SE|² / Σ|L|²)`: the reference's own contribution to a relative
    /// L2 error measured against it; `None` without standard errors.
    pub fn relative_noise(&self) -> Option<f32> {
        let se: f64 = self
            .std_error
            .as_ref()?
            .iter()
            .map(|s| s.length_squared() as f64)
            .sum();
        let signal: f64 = self.mean.iter().map(|m| m.length_squared() as f64).sum();
        Some(if signal == 0.0 {
            0.0
        } else {
            (se / signal).sqrt() as f32
        })
    }
}

/// Runs the estimator at every point, in rounds of replicates, in parallel.
pub fn estimate(
    points: &[ShadingPoint],
    estimator: &Estimator,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Estimates {
    let size = settings.replicate_size.max(1);
    let mut acc = vec![Accumulator::default(); points.len()];
    let mut budget = vec![
        settings
            .min_replicates
            .clamp(1, settings.max_replicates.max(1));
        points.len()
    ];
    let mut rays = 0u64;
    let known: Vec<Option<Known>> = points.par_iter().map(|p| estimator.known(p)).collect();
    progress.set_length(budget.iter().map(|&b| b as u64 * size as u64).sum());
    loop {
        rays += acc
            .par_iter_mut()
            .zip(points.par_iter().zip(&known))
            .zip(budget.par_iter())
            .enumerate()
            .filter(|(_, ((a, _), b))| **b > a.replicates)
            .map(|(i, ((a, (p, &known)), &b))| {
                let mut rays = 0;
                progress.inc((b - a.replicates) as u64 * size as u64);
                while a.replicates < b {
                    let Some(known) = known else {
                        a.add(Vec3::ZERO);
                        continue;
                    };
                    let mut rng = stream(settings.seed, i, a.replicates);
                    let (mean, r) = estimator.replicate(p, known, &mut rng, size);
                    a.add(mean);
                    rays += r;
                }
                rays
            })
            .sum::<u64>();

        let Some(target) = settings.target_noise else {
            break;
        };
        let more = allocate(&acc, &mut budget, target, settings.max_replicates);
        progress.inc_length(more * size as u64);
        if more == 0 {
            break;
        }
    }
    let std_error = acc.iter().map(Accumulator::std_error).collect();
    Estimates {
        mean: acc.iter().map(Accumulator::mean).collect(),
        std_error,
        replicates: acc.iter().map(|a| a.replicates).collect(),
        rays,
    }
}

/// Sets each point's replicate budget for the next round so that the
/// relative L2 noise reaches `target` with the fewest samples; returns how many
/// replicates were added (0 when the target is met or no point can grow).
///
/// With σ_v the spread of one replicate at point v, n_v replicates leave a
/// variance σ_v²/n_v; minimizing Σ n_v subject to Σ σ_v²/n_v ≤ T, with
/// T = target² · Σ|L_v|², gives n_v = σ_v · Σσ_u / T (Neyman allocation):
/// noisy points get more replicates, but not so many that every point reaches
/// the same error. Budgets grow by at most 8× a round, because a σ estimated
/// from few replicates is itself noisy, and by 20% beyond the estimate.
fn allocate(acc: &[Accumulator], budget: &mut [u32], target: f32, max_replicates: u32) -> u64 {
    let signal: f64 = acc.iter().map(|a| a.mean().length_squared() as f64).sum();
    let variance: f64 = acc
        .iter()
        .map(|a| {
            a.std_error()
                .map_or(f64::INFINITY, |se| se.length_squared() as f64)
        })
        .sum();
    let allowed = (target as f64).powi(2) * signal;
    if variance <= allowed {
        return 0;
    }
    // σ_v = SE_v · √R_v; without a standard error yet, treat the point as noisy.
    let sigma: Vec<f64> = acc
        .iter()
        .map(|a| {
            a.std_error().map_or(f64::NAN, |se| {
                se.length() as f64 * (a.replicates as f64).sqrt()
            })
        })
        .collect();
    let total: f64 = sigma.iter().filter(|s| s.is_finite()).sum();
    let mut more = 0u64;
    for ((a, b), s) in acc.iter().zip(budget.iter_mut()).zip(&sigma) {
        let need = if s.is_finite() {
            (s * total / allowed * 1.2).ceil()
        } else {
            f64::INFINITY
        };
        let next = (need.min(u32::MAX as f64) as u32)
            .clamp(a.replicates, a.replicates.saturating_mul(8))
            .min(max_replicates)
            .max(a.replicates);
        more += (next - a.replicates) as u64;
        *b = next;
    }
    more
}

/// The shading points of every vertex of a frame, seen from `eye`.
pub fn vertex_points(scene: &Scene, frame: &FrameGeometry, eye: Vec3) -> Vec<ShadingPoint> {
    frame
        .objects
        .iter()
        .zip(scene.objects())
        .enumerate()
        .flat_map(|(index, (posed, object))| {
            (posed.positions().iter().zip(posed.normals()))
                .zip(posed.lifts())
                .map(move |((&position, &normal), &lift)| ShadingPoint {
                    position: position.as_dvec3(),
                    normal,
                    lift,
                    view: (eye - position).normalize_or(normal),
                    material: object.material,
                    object: index as u32,
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
            let (p, n, lifts) = (object.positions(), object.normals(), object.lifts());
            let bary = hit.barycentric;
            // On the triangle, in f64 ([`SurfacePoint::position`]), from its
            // first corner: weights that sum to 1 only in f32 would move a
            // point far from the origin off the surface.
            let (w, corner) = (bary.as_dvec3(), p[a].as_dvec3());
            let position =
                corner + (p[b].as_dvec3() - corner) * w.y + (p[c].as_dvec3() - corner) * w.z;
            let geometric = (p[b] - p[a]).cross(p[c] - p[a]);
            let mut normal =
                (n[a] * bary.x + n[b] * bary.y + n[c] * bary.z).normalize_or(geometric.normalize());
            if geometric.dot(dir) > 0.0 {
                normal = -normal;
            }
            Some(ShadingPoint {
                position,
                normal,
                lift: lifts[a] * bary.x + lifts[b] * bary.y + lifts[c] * bary.z,
                view: -dir,
                material: scene.objects()[hit.object as usize].material,
                object: hit.object,
            })
        })
        .collect()
}

/// A reference per vertex, with standard errors.
#[derive(Clone, Debug)]
pub struct VertexReference {
    pub radiance: VertexRadiance,
    /// Replicates per vertex.
    pub replicates: Vec<u32>,
    pub rays: u64,
    /// The relative L2 noise, `sqrt(Σ|SE|² / Σ|L|²)`.
    pub noise: f32,
    pub seconds: f64,
}

/// What the estimator reads of an environment: the same for every frame
/// under it, so built once for all of a scene's frames.
pub struct Lighting {
    pub sampler: EnvironmentSampler,
    pub unoccluded: Unoccluded,
}

impl Lighting {
    pub fn new(environment: &Environment) -> Lighting {
        Lighting {
            sampler: EnvironmentSampler::new(environment),
            unoccluded: Unoccluded::new(environment),
        }
    }

    /// The reference's estimator over `bvh`: MIS around the control variate.
    pub fn estimator<'a>(&'a self, bvh: &'a SceneBvh) -> Estimator<'a> {
        Estimator {
            bvh,
            sampler: &self.sampler,
            unoccluded: Some(&self.unoccluded),
        }
    }
}

/// Everything the estimator needs for one frame under one environment.
pub struct Setup {
    pub bvh: SceneBvh,
    pub lighting: Lighting,
}

impl Setup {
    pub fn new(frame: &FrameGeometry, environment: &Environment) -> Result<Setup> {
        Ok(Setup {
            bvh: SceneBvh::build(frame)?,
            lighting: Lighting::new(environment),
        })
    }

    /// The reference's estimator: MIS around the control variate.
    pub fn estimator(&self) -> Estimator<'_> {
        self.lighting.estimator(&self.bvh)
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
    let lighting = OnceCell::new();
    vertex_reference_under(
        scene,
        frame,
        environment,
        &lighting,
        eye,
        settings,
        progress,
    )
}

/// [`vertex_reference`] with the environment's [`Lighting`] taken from
/// `lighting`, built there if empty.
fn vertex_reference_under(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    lighting: &OnceCell<Lighting>,
    eye: Vec3,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<VertexReference> {
    if settings.min_replicates < 2 {
        return Err(Error::InvalidScene(format!(
            "a reference needs at least 2 replicates for its standard error, got {}",
            settings.min_replicates
        )));
    }
    let start = Instant::now();
    let bvh = SceneBvh::build(frame)?;
    let lighting = lighting.get_or_init(|| Lighting::new(environment));
    let points = vertex_points(scene, frame, eye);
    let est = estimate(&points, &lighting.estimator(&bvh), settings, progress);
    Ok(VertexReference {
        radiance: split_per_object(frame, &est),
        noise: est.relative_noise().unwrap_or(f32::INFINITY),
        replicates: est.replicates,
        rays: est.rays,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// A reference image: outgoing radiance at the surface seen through the
/// centre of every pixel, with standard errors.
#[derive(Clone, Debug)]
pub struct ImageReference {
    pub image: Image,
    pub rays: u64,
    /// The relative L2 noise over the covered pixels, `sqrt(Σ|SE|² / Σ|L|²)`
    /// (infinite without standard errors).
    pub noise: f32,
    pub seconds: f64,
}

/// Estimates outgoing radiance at the surface seen through every pixel.
pub fn pixel_reference(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<ImageReference> {
    let lighting = OnceCell::new();
    pixel_reference_under(
        scene,
        frame,
        environment,
        &lighting,
        camera,
        settings,
        progress,
    )
}

/// [`pixel_reference`] with the environment's [`Lighting`] taken from
/// `lighting`, built there if empty.
fn pixel_reference_under(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    lighting: &OnceCell<Lighting>,
    camera: &Camera,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<ImageReference> {
    let start = Instant::now();
    let bvh = SceneBvh::build(frame)?;
    let lighting = lighting.get_or_init(|| Lighting::new(environment));
    let pixels = pixel_points(scene, frame, &bvh, camera);
    let mut reference = image_from_points(
        camera,
        &pixels,
        &lighting.estimator(&bvh),
        settings,
        progress,
    );
    reference.seconds = start.elapsed().as_secs_f64();
    Ok(reference)
}

/// Runs the estimator at the covered pixels of `pixels` and assembles the
/// image, its noise and the rays it took (time not measured).
pub fn image_from_points(
    camera: &Camera,
    pixels: &[Option<ShadingPoint>],
    estimator: &Estimator,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> ImageReference {
    let covered: Vec<bool> = pixels.iter().map(Option::is_some).collect();
    let points: Vec<ShadingPoint> = pixels.iter().flatten().copied().collect();
    let est = estimate(&points, estimator, settings, progress);
    let mut image = Image {
        width: camera.width,
        height: camera.height,
        pixels: vec![Vec3::ZERO; covered.len()],
        covered,
        std_error: est
            .std_error
            .as_ref()
            .map(|_| vec![Vec3::ZERO; pixels.len()]),
    };
    let slots = image
        .covered
        .iter()
        .enumerate()
        .filter(|(_, c)| **c)
        .map(|(i, _)| i);
    for (k, slot) in slots.enumerate() {
        image.pixels[slot] = est.mean[k];
        if let (Some(errors), Some(se)) = (image.std_error.as_mut(), est.std_error.as_ref()) {
            errors[slot] = se[k];
        }
    }
    ImageReference {
        image,
        rays: est.rays,
        noise: est.relative_noise().unwrap_or(f32::INFINITY),
        seconds: 0.0,
    }
}

/// Splits flat per-point estimates into per-object vectors.
pub fn split_per_object(frame: &FrameGeometry, est: &Estimates) -> VertexRadiance {
    VertexRadiance {
        radiance: split(frame, &est.mean),
        std_error: est.std_error.as_ref().map(|se| split(frame, se)),
        evaluated: None,
    }
}

/// Splits a flat per-vertex list into per-object vectors.
pub fn split<T: Clone>(frame: &FrameGeometry, flat: &[T]) -> Vec<Vec<T>> {
    let mut start = 0;
    frame
        .objects
        .iter()
        .map(|object| {
            let end = start + object.vertex_count();
            let part = flat[start..end].to_vec();
            start = end;
            part
        })
        .collect()
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
    let lighting = OnceCell::new();
    per_frame(scene, |frame| {
        let compute = || {
            vertex_reference_under(
                scene,
                frame,
                environment,
                &lighting,
                eye,
                settings,
                progress,
            )
        };
        match cache {
            Some(cache) => {
                let domain = Domain::Vertices { eye };
                let key = cache_key(scene, frame, environment, domain, settings);
                cache.vertex(&key, frame, compute)
            }
            None => Ok((compute()?, false)),
        }
    })
}

/// The image reference of every frame of `scene` under `environment`, seen
/// through `camera`, cached as [`scene_references`].
pub fn scene_image_references(
    scene: &Scene,
    environment: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    cache: Option<&ReferenceCache>,
    progress: &ProgressBar,
) -> Result<(Vec<ImageReference>, bool)> {
    let lighting = OnceCell::new();
    per_frame(scene, |frame| {
        let compute = || {
            pixel_reference_under(
                scene,
                frame,
                environment,
                &lighting,
                camera,
                settings,
                progress,
            )
        };
        cached_image(scene, frame, environment, camera, settings, cache, compute)
    })
}

/// The image reference of one frame of `scene`, cached as
/// [`scene_image_references`]; says whether it came from the cache.
pub fn frame_image_reference(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    cache: Option<&ReferenceCache>,
    progress: &ProgressBar,
) -> Result<(ImageReference, bool)> {
    let compute = || pixel_reference(scene, frame, environment, camera, settings, progress);
    cached_image(scene, frame, environment, camera, settings, cache, compute)
}

/// `compute`'s image reference of one frame, from `cache` where present
/// (and stored there when computed); says whether it came from the cache.
fn cached_image(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    camera: &Camera,
    settings: &ReferenceSettings,
    cache: Option<&ReferenceCache>,
    compute: impl FnOnce() -> Result<ImageReference>,
) -> Result<(ImageReference, bool)> {
    match cache {
        Some(cache) => {
            let domain = Domain::Pixels { camera };
            let key = cache_key(scene, frame, environment, domain, settings);
            cache.image(&key, (camera.width, camera.height), compute)
        }
        None => Ok((compute()?, false)),
    }
}

/// `each` frame's result, and whether every one came from a cache.
fn per_frame<R>(
    scene: &Scene,
    mut each: impl FnMut(&FrameGeometry) -> Result<(R, bool)>,
) -> Result<(Vec<R>, bool)> {
    let mut all_cached = true;
    let mut out = Vec::with_capacity(scene.frames().len());
    for index in 0..scene.frames().len() {
        let (reference, cached) = each(&scene.frame_geometry(index)?)?;
        all_cached &= cached;
        out.push(reference);
    }
    Ok((out, all_cached))
}
