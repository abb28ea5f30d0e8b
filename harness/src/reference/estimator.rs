//! The Monte-Carlo estimator of outgoing radiance (DESIGN.md, "The quantity every
//! method returns"):
//!
//! `L_o(x, v) = ∫ L_env(ω) V(x, ω) f_r(ω, v) max(0, n·ω) dω`.
//!
//! Each iteration draws one direction from each of two strategies, cosine-
//! weighted hemisphere sampling (p_c = max(0, n·ω)/π) and environment
//! importance sampling (p_e, [`EnvironmentSampler`]), and combines them with
//! the balance heuristic (Veach 1997, §9.2): a sample ω of either strategy
//! contributes f(ω) / (p_c(ω) + p_e(ω)). Both densities are non-zero wherever the
//! integrand is, so the estimator is unbiased; each iteration is one
//! independent, identically distributed draw, so the sample variance of the
//! iterations gives an honest standard error.
//!
//! The environment is treated as piecewise constant per texel
//! ([`Environment::texel_radiance`]), which is exactly the function the sampler
//! draws from: the reference integrates the map as stored, with no filtering.

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};
use rand_core::Rng;
use rand_pcg::Pcg32;
use shadow_core::{Brdf, Environment, bvh::SceneBvh, environment::EnvironmentSampler};

/// A point to shade: where, which way the surface faces, toward whom, with what.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadingPoint {
    pub position: Vec3,
    /// Unit shading normal.
    pub normal: Vec3,
    /// Unit direction from the point toward the viewer.
    pub view: Vec3,
    pub material: Brdf,
}

/// Running sums of iteration values, per channel, in f64.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Accumulator {
    pub count: u32,
    sum: [f64; 3],
    sum_sq: [f64; 3],
}

impl Accumulator {
    #[inline]
    pub fn add(&mut self, x: Vec3) {
        self.count += 1;
        for c in 0..3 {
            let v = x[c] as f64;
            self.sum[c] += v;
            self.sum_sq[c] += v * v;
        }
    }

    pub fn mean(&self) -> Vec3 {
        let n = self.count.max(1) as f64;
        Vec3::from_array(self.sum.map(|s| (s / n) as f32))
    }

    /// The standard error of the mean, from the unbiased sample variance.
    pub fn std_error(&self) -> Vec3 {
        if self.count < 2 {
            return Vec3::INFINITY;
        }
        let n = self.count as f64;
        let se = |c: usize| {
            let mean = self.sum[c] / n;
            let var = ((self.sum_sq[c] / n - mean * mean) * n / (n - 1.0)).max(0.0);
            (var / n).sqrt() as f32
        };
        Vec3::new(se(0), se(1), se(2))
    }
}

/// What one pass of the estimator reads: the scene's rays and the lighting.
pub struct Estimator<'a> {
    pub bvh: &'a SceneBvh,
    pub environment: &'a Environment,
    pub sampler: &'a EnvironmentSampler,
    /// Shadow rays start at `x + offset·n` (see [`SceneBvh::ray_offset`]).
    pub offset: f32,
}

impl Estimator<'_> {
    /// Adds `iterations` MIS iterations at `point` to `acc`; returns the number
    /// of shadow rays traced (directions with zero integrand cast none).
    pub fn accumulate(
        &self,
        point: &ShadingPoint,
        rng: &mut Pcg32,
        iterations: u32,
        acc: &mut Accumulator,
    ) -> u64 {
        let n = point.normal;
        let (t, b) = n.any_orthonormal_pair();
        let origin = point.position + n * self.offset;
        let mut rays = 0u64;
        for _ in 0..iterations {
            let mut x = Vec3::ZERO;

            // Strategy 1: cosine-weighted hemisphere.
            let local = cosine_hemisphere(uniform2(rng));
            let w = t * local.x + b * local.y + n * local.z;
            let cos = n.dot(w);
            if cos > 0.0 {
                let le = self.environment.texel_radiance(w);
                if le != Vec3::ZERO {
                    let f = le * point.material.eval(n, w, point.view) * cos;
                    if f != Vec3::ZERO {
                        rays += 1;
                        if self.bvh.unoccluded(origin, w, f32::INFINITY) {
                            x += f / (cos * FRAC_1_PI + self.sampler.pdf(w));
                        }
                    }
                }
            }

            // Strategy 2: the environment's own distribution.
            let s = self.sampler.sample(uniform2(rng));
            let cos = n.dot(s.dir);
            if cos > 0.0 && s.radiance != Vec3::ZERO {
                let f = s.radiance * point.material.eval(n, s.dir, point.view) * cos;
                if f != Vec3::ZERO {
                    rays += 1;
                    if self.bvh.unoccluded(origin, s.dir, f32::INFINITY) {
                        x += f / (s.pdf + cos * FRAC_1_PI);
                    }
                }
            }
            acc.add(x);
        }
        rays
    }
}

/// Two uniform numbers in [0, 1).
#[inline]
fn uniform2(rng: &mut Pcg32) -> Vec2 {
    const SCALE: f32 = 1.0 / (1u32 << 24) as f32;
    Vec2::new(
        (rng.next_u32() >> 8) as f32 * SCALE,
        (rng.next_u32() >> 8) as f32 * SCALE,
    )
}

/// Malley's method: a uniform disk sample lifted to the hemisphere (z up) has
/// density cos θ / π.
#[inline]
fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let phi = std::f32::consts::TAU * u.y;
    let (s, c) = phi.sin_cos();
    Vec3::new(r * c, r * s, (1.0 - u.x).max(0.0).sqrt())
}

/// The random stream of one (seed, point, round): independent of thread
/// scheduling, so results are deterministic for a seed.
pub fn stream(seed: u64, point: usize, round: u32) -> Pcg32 {
    let mix = |mut z: u64| {
        // SplitMix64 finalizer.
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
        z ^ (z >> 31)
    };
    let state = mix(seed ^ mix(point as u64 ^ ((round as u64) << 40)));
    Pcg32::new(state, point as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn cosine_samples_have_mean_cosine_two_thirds() {
        let mut rng = stream(1, 0, 0);
        let n = 200_000;
        let mean: f32 = (0..n)
            .map(|_| cosine_hemisphere(uniform2(&mut rng)).z)
            .sum::<f32>()
            / n as f32;
        // E[cos θ] under p = cos θ/π is 2/3.
        assert_relative_eq!(mean, 2.0 / 3.0, epsilon = 3e-3);
    }

    #[test]
    fn accumulator_standard_error_matches_formula() {
        let mut acc = Accumulator::default();
        for x in [1.0, 2.0, 3.0, 4.0] {
            acc.add(Vec3::splat(x));
        }
        assert_relative_eq!(acc.mean(), Vec3::splat(2.5));
        // sample variance 5/3, SE = sqrt(5/3 / 4)
        assert_relative_eq!(acc.std_error().x, (5.0f32 / 12.0).sqrt(), epsilon = 1e-6);
    }

    #[test]
    fn streams_differ_per_point_and_round() {
        let a = stream(7, 0, 0).next_u64();
        assert_ne!(a, stream(7, 1, 0).next_u64());
        assert_ne!(a, stream(7, 0, 1).next_u64());
        assert_ne!(a, stream(8, 0, 0).next_u64());
        assert_eq!(a, stream(7, 0, 0).next_u64());
    }
}
