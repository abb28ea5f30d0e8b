//! The Monte-Carlo reference of per-vertex SH transfer vectors, the quantity
//! whose error Kautz, Lehtinen and Aila 2004 report in Table 1 ("Average L2
//! error in V*", §4): for a Lambert vertex with normal n,
//!
//! ```text
//! T_k = ∫ V(ω) max(0, n·ω) Y_k(ω) dω
//! ```
//!
//! in world space, without ρ/π, in [`shadow_core::sh`]'s basis: exactly what
//! `hemi_raster::HemiRaster::transfer` returns, so the two compare
//! coefficient by coefficient.
//!
//! Directions are drawn with density p(ω) = max(0, n·ω)/π (Malley's method),
//! which cancels the cosine: T_k ≈ π/N Σ_i V(ω_i) Y_k(ω_i), one shadow ray and
//! one basis evaluation per direction. As in the radiance reference
//! ([`super::Estimator`]), a replicate takes the first N points of the 2-D
//! Sobol' sequence under a random digital shift: the points are stratified, so
//! the smooth factor Y_k is integrated almost exactly and the noise comes from
//! the visibility edges; replicates with independent shifts are independent,
//! and the spread of their means is an honest standard error per coefficient.
//! Vertex normals and shadow rays ([`SceneBvh::unoccluded_from`], and a
//! vertex pressed on another surface unlit, [`SceneBvh::pressed`]) are those
//! of the radiance reference, so the two references see the same
//! visibility, self-shadowing by neighbouring faces and contacts included.

use std::{f64::consts::PI, time::Instant};

use indicatif::ProgressBar;
use rand_core::Rng;
use rayon::prelude::*;
use shadow_core::{
    Error, FrameGeometry, Result, Scene, SurfacePoint, TangentSpace,
    bvh::SceneBvh,
    sh::{ShOrder, eval_basis},
};

use super::estimator::stream;
use shadow_core::qmc::{cosine_hemisphere, sobol2};

/// How many rays the transfer reference traces.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TransferSettings {
    /// SH order of the transfer vectors (order 5: the paper's 25 terms).
    pub order: ShOrder,
    /// Seed of every random stream: same seed, same result.
    pub seed: u64,
    /// Rays per replicate; a power of two keeps the Sobol' points stratified.
    pub replicate_size: u32,
    /// Independent replicates per vertex, at least 2 (for a standard error).
    pub replicates: u32,
}

impl TransferSettings {
    /// 16 replicates of 1024 rays per vertex: about 20 s a frame on the
    /// human (3k vertices, two cores), for a relative noise of 0.18–0.29%
    /// (per vertex and global, human, cloth and chess). Added in quadrature
    /// to the smallest error it has judged (1.8% per vertex, cloth), that
    /// inflates it by 0.5% of its value; the others by less. The noise falls
    /// as N^−¾ (stratified points, visibility edges): 4× the rays, about ⅓
    /// the noise. The seed differs from
    /// [`super::ReferenceSettings::CONVERGED`]'s so that the two references'
    /// noise is independent.
    pub const CONVERGED: TransferSettings = TransferSettings {
        order: ShOrder::new(5).expect("5 is a valid order"),
        seed: 0x7a4e_5fe4,
        replicate_size: 1024,
        replicates: 16,
    };

    fn validate(&self) -> Result<()> {
        if self.replicates < 2 || self.replicate_size == 0 {
            return Err(Error::InvalidScene(format!(
                "a transfer reference needs at least 2 replicates of at least one ray, \
                 got {} of {}",
                self.replicates, self.replicate_size
            )));
        }
        Ok(())
    }
}

/// The reference transfer vectors of every vertex of one frame, objects one
/// after another as in [`FrameGeometry::objects`].
#[derive(Clone, Debug, PartialEq)]
pub struct TransferReference {
    order: ShOrder,
    /// `order.coeff_count()` coefficients per vertex.
    mean: Vec<f32>,
    /// The standard error of each coefficient, same layout.
    std_error: Vec<f32>,
    /// Shadow rays traced.
    pub rays: u64,
    /// Wall-clock seconds, BVH build included.
    pub seconds: f64,
}

impl TransferReference {
    pub fn order(&self) -> ShOrder {
        self.order
    }

    pub fn vertex_count(&self) -> usize {
        self.mean.len() / self.order.coeff_count()
    }

    /// Every vertex's transfer vector, one after another.
    pub fn mean(&self) -> &[f32] {
        &self.mean
    }

    /// Every coefficient's standard error, laid out as [`Self::mean`].
    pub fn std_error(&self) -> &[f32] {
        &self.std_error
    }

    /// The transfer vector of flat vertex `v`.
    ///
    /// # Panics
    /// If `v` is out of range.
    pub fn transfer(&self, v: usize) -> &[f32] {
        let n = self.order.coeff_count();
        &self.mean[v * n..(v + 1) * n]
    }

    /// `sqrt(Σ SE² / Σ T²)` over all coefficients of all vertices: the
    /// reference's own contribution to a global relative L2 error.
    pub fn noise(&self) -> f32 {
        let sum_sq = |x: &[f32]| x.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
        let signal = sum_sq(&self.mean);
        if signal == 0.0 {
            0.0
        } else {
            (sum_sq(&self.std_error) / signal).sqrt() as f32
        }
    }
}

/// Per-thread buffers, so that the per-vertex loop allocates nothing.
struct Scratch {
    basis: Vec<f32>,
    replicate: Vec<f64>,
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
}

impl Scratch {
    fn new(n: usize) -> Scratch {
        Scratch {
            basis: vec![0.0; n],
            replicate: vec![0.0; n],
            sum: vec![0.0; n],
            sum_sq: vec![0.0; n],
        }
    }
}

/// Estimates the transfer vector of every vertex of `frame`, in parallel over
/// vertices.
pub fn transfer_reference(
    frame: &FrameGeometry,
    settings: &TransferSettings,
    progress: &ProgressBar,
) -> Result<TransferReference> {
    settings.validate()?;
    let start = Instant::now();
    let bvh = SceneBvh::build(frame)?;
    let points: Vec<(u32, SurfacePoint)> = frame.object_vertices().collect();
    let n = settings.order.coeff_count();
    let mut mean = vec![0.0; points.len() * n];
    let mut std_error = vec![0.0; points.len() * n];
    progress.inc_length(points.len() as u64);
    let rays = mean
        .par_chunks_mut(n)
        .zip(std_error.par_chunks_mut(n))
        .zip(points.par_iter())
        .enumerate()
        .map_init(
            || Scratch::new(n),
            |scratch, (v, ((mean, se), &(object, at)))| {
                let rays = vertex_transfer(&bvh, (object, at), v, settings, scratch);
                let r = settings.replicates as f64;
                for ((m, e), (&s, &s2)) in mean
                    .iter_mut()
                    .zip(se.iter_mut())
                    .zip(scratch.sum.iter().zip(&scratch.sum_sq))
                {
                    let mu = s / r;
                    let var = ((s2 / r - mu * mu) * r / (r - 1.0)).max(0.0);
                    *m = mu as f32;
                    *e = (var / r).sqrt() as f32;
                }
                progress.inc(1);
                rays
            },
        )
        .sum::<u64>();
    Ok(TransferReference {
        order: settings.order,
        mean,
        std_error,
        rays,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Every replicate of flat vertex `v`: leaves the sums of the replicate means
/// and of their squares in `scratch.sum` and `scratch.sum_sq`; returns the
/// rays traced.
fn vertex_transfer(
    bvh: &SceneBvh,
    (object, at): (u32, SurfacePoint),
    v: usize,
    settings: &TransferSettings,
    scratch: &mut Scratch,
) -> u64 {
    let tangents = TangentSpace::new(at.normal);
    let weight = PI / settings.replicate_size as f64;
    scratch.sum.fill(0.0);
    scratch.sum_sq.fill(0.0);
    if bvh.pressed(&at, object) {
        return 0;
    }
    for r in 0..settings.replicates {
        let mut rng = stream(settings.seed, v, r);
        let shift = [rng.next_u32(), rng.next_u32()];
        scratch.replicate.fill(0.0);
        for i in 0..settings.replicate_size {
            let local = cosine_hemisphere(sobol2(i, shift));
            let dir = tangents.to_world(local);
            if bvh.unoccluded_from(&at, dir, f32::INFINITY) {
                eval_basis(settings.order, dir, &mut scratch.basis);
                for (acc, &y) in scratch.replicate.iter_mut().zip(&scratch.basis) {
                    *acc += y as f64;
                }
            }
        }
        for ((s, s2), &x) in scratch
            .sum
            .iter_mut()
            .zip(scratch.sum_sq.iter_mut())
            .zip(&scratch.replicate)
        {
            let x = x * weight;
            *s += x;
            *s2 += x * x;
        }
    }
    settings.replicates as u64 * settings.replicate_size as u64
}

/// The transfer reference of every frame of `scene`, kept in memory (it is
/// not cached on disk: [`super::ReferenceCache`] stores radiance only).
pub fn scene_transfer_references(
    scene: &Scene,
    settings: &TransferSettings,
    progress: &ProgressBar,
) -> Result<Vec<TransferReference>> {
    (0..scene.frames().len())
        .map(|index| transfer_reference(&scene.frame_geometry(index)?, settings, progress))
        .collect()
}
