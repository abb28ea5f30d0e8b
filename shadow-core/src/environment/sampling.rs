//! Importance sampling of an environment, for the Monte-Carlo reference.
//!
//! The reference treats the environment as **piecewise constant per texel**:
//! the radiance toward ω is the value of the texel whose cell holds ω
//! ([`Environment::texel_radiance`]), not the bilinear [`Environment::lookup`].
//! That is exactly the function [`EnvironmentSampler`] draws from (a texel,
//! then a direction uniformly in solid angle inside it), so an estimator that
//! uses both integrates the map as stored, without filtering, and one that
//! samples a texel with probability proportional to its L·Ω has zero variance
//! (up to the uniform share below) on the integral of a grey map.

use std::f64::consts::{PI, TAU};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::{Environment, luminance};

/// The share of samples drawn uniformly by solid angle rather than by
/// luminance. Rec. 709 luminance has positive weights, so it is positive
/// wherever any channel is and the luminance term alone already covers every
/// lit direction; the uniform share makes the density positive everywhere
/// (pdf ≥ 0.01/4π), which caps the weight L/pdf of texels that are dim in the
/// map but matter to a shading point whose bright directions are blocked or
/// below its horizon, at the cost of 1% of the samples.
const UNIFORM_FRACTION: f64 = 0.01;

/// The largest f64 below 1: the CDFs end at exactly 1, so a random number
/// must stay below it.
const BELOW_ONE: f64 = 1.0 - f64::EPSILON / 2.0;

/// The density per steradian of the uniform distribution over the sphere.
const UNIFORM_PDF: f32 = (1.0 / (4.0 * PI)) as f32;

/// One direction drawn by [`EnvironmentSampler::sample`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvSample {
    /// Unit direction toward the light.
    pub dir: Vec3,
    /// Probability density of `dir` per steradian: P(texel) / Ω(texel).
    pub pdf: f32,
    /// The radiance of the texel `dir` lies in (piecewise constant).
    pub radiance: Vec3,
}

/// A piecewise-constant 2-D distribution over the texels of an environment,
/// proportional to luminance × solid angle, mixed with 1% uniform by solid
/// angle; within a texel, directions are uniform in solid angle.
///
/// Rows are drawn from a marginal CDF and columns from the row's conditional
/// CDF, both f64 (so that the uniform share of a tiny polar texel next to a
/// sun is still resolved), by inversion: monotone in `u`, so stratified
/// numbers stay stratified. A guide table per CDF (Chen & Asau 1974; Devroye
/// 1986, ch. III: for each of n equal steps of u, the first interval it can
/// fall in)
/// narrows each bisection to a few entries; on a 1024×512 map a plain
/// bisection chased ~8 dependent cache misses through the 4 MB of column
/// CDFs. [`sample`](Self::sample) and [`pdf`](Self::pdf) allocate nothing
/// and compute the density from the same CDF entries, so they agree bit for
/// bit.
///
/// The sampler keeps its own copy of the map (for the radiance of a sample
/// and the texel mapping), so it does not borrow the [`Environment`].
#[derive(Clone, Debug)]
pub struct EnvironmentSampler {
    env: Environment,
    /// cos θ at the H + 1 row edges, from +1 (top) to −1.
    cos_edges: Vec<f64>,
    /// Solid angle of one texel of each row.
    solid_angles: Vec<f64>,
    /// Marginal CDF over rows: H + 1 entries, 0 first and exactly 1 last.
    row_cdf: Vec<f64>,
    /// Guide table of `row_cdf`: H entries.
    row_guide: Vec<u32>,
    /// Conditional CDFs over columns: W + 1 entries per row, row-major.
    col_cdf: Vec<f64>,
    /// Guide tables of the conditional CDFs: W entries per row.
    col_guide: Vec<u32>,
    /// The radiance of every texel, where all are equal: the distribution
    /// is then uniform over the sphere, and sampling and densities need no
    /// tables (the uniform sky of ambient occlusion, whose reference
    /// traces most of a bake's rays).
    constant: Option<Vec3>,
}

impl EnvironmentSampler {
    /// Builds the distribution of `env`. A map whose luminance is zero
    /// everywhere is sampled uniformly by solid angle.
    pub fn new(env: &Environment) -> EnvironmentSampler {
        let (w, h) = (env.width, env.height);
        let cos_edges: Vec<f64> = (0..=h).map(|i| (PI * i as f64 / h as f64).cos()).collect();
        let solid_angles: Vec<f64> = cos_edges
            .windows(2)
            .map(|c| (c[0] - c[1]) * TAU / w as f64)
            .collect();
        let sphere: f64 = solid_angles.iter().sum::<f64>() * w as f64;

        // Total luminance of each row, then of the map (× solid angle).
        let row_luminance: Vec<f64> = env
            .texels
            .par_chunks(w)
            .map(|texels| texels.iter().map(|t| luminance(*t) as f64).sum())
            .collect();
        let total: f64 = row_luminance
            .iter()
            .zip(&solid_angles)
            .map(|(l, omega)| l * omega)
            .sum();
        let (lum_share, uniform_share) = if total > 0.0 {
            ((1.0 - UNIFORM_FRACTION) / total, UNIFORM_FRACTION / sphere)
        } else {
            (0.0, 1.0 / sphere)
        };

        // P(row, col) = lum_share·L·Ω + uniform_share·Ω. Each row becomes a
        // normalized conditional CDF with its guide table; its mass is kept
        // for the marginal.
        let mut col_cdf = vec![0.0f64; h * (w + 1)];
        let mut col_guide = vec![0u32; h * w];
        let row_mass: Vec<f64> = col_cdf
            .par_chunks_mut(w + 1)
            .zip(col_guide.par_chunks_mut(w))
            .enumerate()
            .map(|(row, (cdf, guide))| {
                let texels = &env.texels[row * w..(row + 1) * w];
                let (a, b) = (
                    lum_share * solid_angles[row],
                    uniform_share * solid_angles[row],
                );
                let mut sum = 0.0;
                for (c, t) in cdf[1..].iter_mut().zip(texels) {
                    sum += a * luminance(*t) as f64 + b;
                    *c = sum;
                }
                // Division is monotone and sum/sum = 1: the CDF stays ≤ 1.
                for c in cdf.iter_mut() {
                    *c /= sum;
                }
                fill_guide(cdf, guide);
                sum
            })
            .collect();
        let mut row_cdf = Vec::with_capacity(h + 1);
        row_cdf.push(0.0);
        let mut sum = 0.0;
        for m in &row_mass {
            sum += m;
            row_cdf.push(sum);
        }
        for c in &mut row_cdf {
            *c /= sum;
        }
        row_cdf[h] = 1.0;

        let mut row_guide = vec![0u32; h];
        fill_guide(&row_cdf, &mut row_guide);

        let first = env.texels[0];
        EnvironmentSampler {
            constant: env.texels.iter().all(|t| *t == first).then_some(first),
            env: env.clone(),
            cos_edges,
            solid_angles,
            row_cdf,
            row_guide,
            col_cdf,
            col_guide,
        }
    }

    /// Draws a direction from two uniform numbers in [0, 1): `u.x` picks the
    /// row and the latitude inside it, `u.y` the column and the longitude.
    /// Numbers outside [0, 1) (or NaN) are clamped into it.
    /// A constant map is sampled uniformly over the sphere straight from
    /// `u` (cos θ = 1 − 2 u.x, φ = 2π u.y), the same distribution.
    #[inline]
    pub fn sample(&self, u: Vec2) -> EnvSample {
        if let Some(radiance) = self.constant {
            let u = u.clamp(Vec2::ZERO, Vec2::ONE);
            let cos_theta = 1.0 - 2.0 * u.x;
            let sin_theta = ((1.0 - cos_theta) * (1.0 + cos_theta)).max(0.0).sqrt();
            let (sin_phi, cos_phi) = (TAU as f32 * u.y).sin_cos();
            return EnvSample {
                dir: Vec3::new(sin_theta * cos_phi, cos_theta, sin_theta * sin_phi),
                pdf: UNIFORM_PDF,
                radiance,
            };
        }
        let (row, v) = pick(&self.row_cdf, &self.row_guide, u.x);
        let w = self.env.width;
        let (col, s) = pick(
            self.columns(row),
            &self.col_guide[row * w..(row + 1) * w],
            u.y,
        );

        // Uniform in cos θ between the row's edges and uniform in φ across
        // the column: uniform in solid angle (dω = d(cos θ) dφ).
        let (c0, c1) = (self.cos_edges[row], self.cos_edges[row + 1]);
        let cos_theta = c0 + v * (c1 - c0);
        let sin_theta = ((1.0 - cos_theta) * (1.0 + cos_theta)).max(0.0).sqrt();
        let phi = (TAU * (col as f64 + s) / self.env.width as f64) as f32;
        let (sin_phi, cos_phi) = phi.sin_cos();
        let (sin_theta, cos_theta) = (sin_theta as f32, cos_theta as f32);
        EnvSample {
            dir: Vec3::new(sin_theta * cos_phi, cos_theta, sin_theta * sin_phi),
            pdf: self.density(row, col),
            radiance: self.env.texel(row, col),
        }
    }

    /// The density per steradian with which [`sample`](Self::sample) draws
    /// the unit direction `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.constant.is_some() {
            return UNIFORM_PDF;
        }
        let (row, col) = self.env.texel_of(dir);
        self.density(row, col)
    }

    /// The density of `dir` together with the radiance of its texel: one
    /// direction-to-texel mapping for both, as an estimator that evaluates the
    /// map and weighs a sample from another strategy needs.
    #[inline]
    pub fn pdf_and_radiance(&self, dir: Vec3) -> (f32, Vec3) {
        if let Some(radiance) = self.constant {
            return (UNIFORM_PDF, radiance);
        }
        let (row, col) = self.env.texel_of(dir);
        (self.density(row, col), self.env.texel(row, col))
    }

    /// P(texel) / Ω(texel), from the CDF steps that `sample` walks.
    #[inline]
    fn density(&self, row: usize, col: usize) -> f32 {
        let columns = self.columns(row);
        let p_row = self.row_cdf[row + 1] - self.row_cdf[row];
        let p_col = columns[col + 1] - columns[col];
        (p_row * p_col / self.solid_angles[row]) as f32
    }

    #[inline]
    fn columns(&self, row: usize) -> &[f64] {
        let n = self.env.width + 1;
        &self.col_cdf[row * n..(row + 1) * n]
    }
}

/// Fills the guide table of a CDF of n intervals (non-decreasing, 0 first,
/// 1 last): for each k < n, the interval that holds u = k/n.
fn fill_guide(cdf: &[f64], guide: &mut [u32]) {
    let n = guide.len();
    let mut j = 0;
    for (k, g) in guide.iter_mut().enumerate() {
        let u = k as f64 / n as f64;
        while j + 1 < n && cdf[j + 1] <= u {
            j += 1;
        }
        *g = j as u32;
    }
}

/// The interval of `cdf` (non-decreasing, 0 first, 1 last) holding `u`, and
/// where in it `u` falls, in [0, 1). Zero-width intervals are never chosen.
#[inline]
fn pick(cdf: &[f64], guide: &[u32], u: f32) -> (usize, f64) {
    let u = if u > 0.0 {
        (u as f64).min(BELOW_ONE)
    } else {
        0.0
    };
    let n = cdf.len() - 1;
    // u lies in step k of the guide, so its interval is between the guides of
    // steps k and k + 1; rounding at a step edge can miss by one interval,
    // in which case the search widens to the whole CDF.
    let k = ((u * n as f64) as usize).min(n - 1);
    let mut lo = guide[k] as usize;
    let mut hi = guide.get(k + 1).map_or(n - 1, |&g| g as usize);
    if cdf[lo] > u {
        lo = 0;
    }
    if cdf[hi + 1] <= u {
        hi = n - 1;
    }
    // cdf[lo] ≤ u < cdf[hi + 1]: count the inner edges at or below u.
    let i = lo + cdf[lo + 1..=hi].partition_point(|&c| c <= u);
    let (a, b) = (cdf[i], cdf[i + 1]);
    (i, ((u - a) / (b - a)).min(BELOW_ONE))
}

impl Environment {
    /// The radiance of the texel whose cell holds `dir`: the map as a
    /// piecewise-constant function, the one [`EnvironmentSampler`] samples
    /// and the Monte-Carlo reference integrates.
    #[inline]
    pub fn texel_radiance(&self, dir: Vec3) -> Vec3 {
        let (row, col) = self.texel_of(dir);
        self.texel(row, col)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::environment::filter::tests::{TestRng, random_map};
    use approx::assert_relative_eq;
    use std::f32::consts::PI as PI32;

    /// A map like the sunrise asset: dim sky, one texel carrying most light.
    fn sun_map(width: usize, height: usize) -> Environment {
        let mut env = random_map(width, height, 11);
        for t in &mut env.texels {
            *t *= 0.1;
        }
        env.texels[(height / 3) * width + width / 5] = Vec3::new(5e4, 4e4, 2e4);
        env
    }

    fn rng_u(rng: &mut TestRng) -> Vec2 {
        Vec2::new(rng.next_f32(), rng.next_f32())
    }

    #[test]
    fn pdf_integrates_to_one() {
        for env in [
            random_map(16, 8, 1),
            sun_map(64, 32),
            Environment::uniform(Vec3::ONE),
        ] {
            let sampler = EnvironmentSampler::new(&env);
            let mut total = 0.0f64;
            for row in 0..env.height() {
                for col in 0..env.width() {
                    let p = sampler.pdf(env.direction(row, col));
                    assert!(p > 0.0);
                    total += p as f64 * env.solid_angle(row) as f64;
                }
            }
            assert_relative_eq!(total, 1.0, epsilon = 1e-5);
        }
    }

    #[test]
    fn uniform_map_has_density_one_over_four_pi() {
        let sampler = EnvironmentSampler::new(&Environment::uniform(Vec3::splat(3.0)));
        let mut rng = TestRng::new(2);
        for _ in 0..1000 {
            let s = sampler.sample(rng_u(&mut rng));
            assert_relative_eq!(s.pdf, 0.25 / PI32, max_relative = 1e-5);
            assert_relative_eq!(sampler.pdf(s.dir), 0.25 / PI32, max_relative = 1e-5);
            assert_eq!(s.radiance, Vec3::splat(3.0));
        }
        // A black map falls back to uniform.
        let black = Environment::new("black", 8, 4, vec![Vec3::ZERO; 32]).unwrap();
        let s = EnvironmentSampler::new(&black).sample(Vec2::new(0.3, 0.7));
        assert_relative_eq!(s.pdf, 0.25 / PI32, max_relative = 1e-5);
    }

    #[test]
    fn sample_agrees_with_pdf_and_texel_radiance() {
        for env in [random_map(16, 8, 3), sun_map(256, 128)] {
            let sampler = EnvironmentSampler::new(&env);
            let mut rng = TestRng::new(4);
            for _ in 0..50_000 {
                let s = sampler.sample(rng_u(&mut rng));
                assert_relative_eq!(s.dir.length(), 1.0, epsilon = 1e-6);
                assert_relative_eq!(sampler.pdf(s.dir), s.pdf, max_relative = 1e-4);
                assert_eq!(env.texel_radiance(s.dir), s.radiance);
            }
        }
    }

    #[test]
    fn extreme_radiance_gives_a_finite_distribution() {
        let mut texels = vec![Vec3::ONE; 8 * 4];
        texels[5] = Vec3::splat(f32::MAX);
        let env = Environment::new("extreme", 8, 4, texels).unwrap();
        let sampler = EnvironmentSampler::new(&env);
        let s = sampler.sample(Vec2::new(0.4, 0.6));
        assert_eq!(env.texel_of(s.dir), (0, 5));
        assert!(s.pdf.is_finite() && s.pdf > 0.0);
        assert!(sampler.pdf(env.direction(3, 3)) > 0.0);
    }

    #[test]
    fn out_of_range_numbers_still_give_valid_samples() {
        let env = sun_map(32, 16);
        let sampler = EnvironmentSampler::new(&env);
        for u in [
            Vec2::ZERO,
            Vec2::ONE,
            Vec2::new(-1.0, 2.0),
            Vec2::NAN,
            Vec2::new(1.0 - f32::EPSILON, 1.0 - f32::EPSILON),
        ] {
            let s = sampler.sample(u);
            assert!(
                s.dir.is_finite() && (s.dir.length() - 1.0).abs() < 1e-6,
                "{u}: {s:?}"
            );
            assert!(s.pdf > 0.0 && s.pdf.is_finite(), "{u}: {s:?}");
        }
    }

    #[test]
    fn guided_search_finds_the_interval_holding_u() {
        // Zero-width intervals, one interval spanning many guide steps, many
        // tiny ones inside one step, and values on the guide steps' edges.
        let mut weights = vec![0.0, 1.0, 0.0, 0.0, 40.0, 1e-9, 1e-9, 1e-9, 3.0];
        weights.extend(std::iter::repeat_n(1e-3, 20));
        weights.extend([0.0, 2.0, 0.0]);
        let total: f64 = weights.iter().sum();
        let mut cdf = vec![0.0];
        for w in &weights {
            cdf.push(cdf.last().unwrap() + w / total);
        }
        let n = weights.len();
        cdf[n] = 1.0;
        let mut guide = vec![0u32; n];
        fill_guide(&cdf, &mut guide);

        let mut us: Vec<f32> = (0..=n).map(|k| k as f32 / n as f32).collect();
        us.extend(cdf.iter().map(|&c| c as f32));
        let edges = us.clone();
        us.extend(edges.iter().map(|u| u.next_up()));
        us.extend(edges.iter().map(|u| u.next_down()));
        let mut rng = TestRng::new(12);
        us.extend((0..10_000).map(|_| rng.next_f32()));
        for u in us {
            let (i, t) = pick(&cdf, &guide, u);
            let x = (u as f64).clamp(0.0, BELOW_ONE);
            assert!(
                cdf[i] <= x && x < cdf[i + 1],
                "u = {u}: interval {i} {:?}",
                &cdf[i..=i + 1]
            );
            assert!((0.0..1.0).contains(&t), "u = {u}: {t}");
        }
    }

    /// Chi-square of observed against expected counts, over cells that
    /// expect at least 5.
    fn chi_square(observed: &[u32], expected: &[f64]) -> (f64, usize) {
        let mut chi2 = 0.0;
        let mut cells = 0;
        for (&o, &e) in observed.iter().zip(expected) {
            assert!(e >= 5.0, "cell expects only {e}");
            chi2 += (o as f64 - e).powi(2) / e;
            cells += 1;
        }
        (chi2, cells - 1)
    }

    #[test]
    fn texel_frequencies_match_their_probabilities() {
        let env = random_map(16, 8, 5);
        let sampler = EnvironmentSampler::new(&env);
        let n = 200_000;
        let mut counts = vec![0u32; 16 * 8];
        let mut rng = TestRng::new(6);
        for _ in 0..n {
            let (row, col) = env.texel_of(sampler.sample(rng_u(&mut rng)).dir);
            counts[row * 16 + col] += 1;
        }
        let expected: Vec<f64> = (0..16 * 8)
            .map(|i| {
                let (row, col) = (i / 16, i % 16);
                let p = sampler.pdf(env.direction(row, col)) as f64 * env.solid_angle(row) as f64;
                n as f64 * p
            })
            .collect();
        let (chi2, dof) = chi_square(&counts, &expected);
        // Mean dof, standard deviation √(2 dof): five of them is far out.
        let limit = dof as f64 + 5.0 * (2.0 * dof as f64).sqrt();
        assert!(chi2 < limit, "χ² = {chi2} for {dof} degrees of freedom");
    }

    #[test]
    fn directions_are_uniform_in_solid_angle_within_a_texel() {
        // Count on a grid twice as fine: each quarter of a texel must get its
        // share of the solid angle.
        let env = random_map(16, 8, 7);
        let fine = Environment::new("fine", 32, 16, vec![Vec3::ONE; 32 * 16]).unwrap();
        let sampler = EnvironmentSampler::new(&env);
        let n = 200_000;
        let mut counts = vec![0u32; 32 * 16];
        let mut rng = TestRng::new(8);
        for _ in 0..n {
            let (row, col) = fine.texel_of(sampler.sample(rng_u(&mut rng)).dir);
            counts[row * 32 + col] += 1;
        }
        let expected: Vec<f64> = (0..32 * 16)
            .map(|i| {
                let (row, col) = (i / 32, i % 32);
                let p = sampler.pdf(fine.direction(row, col)) as f64;
                n as f64 * p * fine.solid_angle(row) as f64
            })
            .collect();
        let (chi2, dof) = chi_square(&counts, &expected);
        let limit = dof as f64 + 5.0 * (2.0 * dof as f64).sqrt();
        assert!(chi2 < limit, "χ² = {chi2} for {dof} degrees of freedom");
    }

    /// Mean and standard error of L/pdf over n samples: an estimate of the
    /// integral of the map.
    fn estimate(sampler: &EnvironmentSampler, n: usize, seed: u64) -> (Vec3, Vec3) {
        let mut rng = TestRng::new(seed);
        let (mut sum, mut sum_sq) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
        for _ in 0..n {
            let s = sampler.sample(rng_u(&mut rng));
            let x = (s.radiance / s.pdf).as_dvec3();
            sum += x;
            sum_sq += x * x;
        }
        let mean = sum / n as f64;
        let var = (sum_sq / n as f64 - mean * mean) * (n as f64 / (n as f64 - 1.0));
        (
            mean.as_vec3(),
            (var.max(glam::DVec3::ZERO) / n as f64).sqrt().as_vec3(),
        )
    }

    #[test]
    fn importance_sampling_estimates_the_integral_with_tiny_variance() {
        // Grey: luminance-proportional sampling leaves only the 1% uniform
        // share as a source of variance.
        let mut grey = random_map(64, 32, 9);
        for t in &mut grey.texels {
            *t = Vec3::splat(t.x);
        }
        let n = 100_000;
        let exact = grey.integral();
        let (mean, se) = estimate(&EnvironmentSampler::new(&grey), n, 10);
        assert!(
            ((mean - exact).abs() - 4.0 * se).max_element() <= 0.0,
            "{mean} vs {exact} ± {se}"
        );
        // One sample has a relative spread of about 1%.
        let relative_spread = se.x * (n as f32).sqrt() / exact.x;
        assert!(
            relative_spread < 0.02,
            "relative spread per sample {relative_spread}"
        );

        // A sun map: still unbiased, and far better than uniform sampling.
        let sun = sun_map(64, 32);
        let exact = sun.integral();
        let (mean, se) = estimate(&EnvironmentSampler::new(&sun), n, 11);
        assert!(
            ((mean - exact).abs() - 4.0 * se).max_element() <= 0.0,
            "{mean} vs {exact} ± {se}"
        );
        assert!(
            (se / exact).max_element() < 1e-3,
            "relative standard error {se}"
        );
    }
}
