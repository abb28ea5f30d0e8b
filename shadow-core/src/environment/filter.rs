//! Resampling an environment: rotation, integral-preserving downsampling and
//! a Gaussian-like blur on the sphere.
//!
//! Derived maps keep the source's name (with what was done appended) and its
//! [`EnvironmentReport`](super::EnvironmentReport): they are the same lighting,
//! and the report says what loading it changed. Every output texel is a convex
//! combination of input texels, so the results stay finite and non-negative.

use std::f64::consts::{PI, TAU};

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use super::Environment;

/// Matrix entries within this of a rotation about +Y count as one.
const Y_ROTATION_TOLERANCE: f32 = 1e-5;
/// A Y rotation within this many columns of a whole number is a column shift.
const COLUMN_SHIFT_TOLERANCE: f64 = 1e-3;
/// The blur kernel is cut off at this many σ (the vMF weight there is
/// e^(−4.5) ≈ 1% of its peak).
const KERNEL_RADIUS_SIGMAS: f64 = 3.0;

impl Environment {
    /// The map lit by `rotation` applied to the lighting: the new radiance
    /// toward ω is the old radiance toward R⁻¹ω, so a feature the old map
    /// shows in direction d appears in direction R·d.
    ///
    /// A rotation about +Y by a whole number of columns (2π/W each, within
    /// 10⁻³ of a column; this includes the identity and rotations by 360°
    /// about any axis) is an exact column shift. Any other rotation samples
    /// the bilinear [`Environment::lookup`] at the rotated texel centres: exact
    /// for radiance that is linear across a texel, with an error O(h²·|∇²L|)
    /// for smooth maps (h the texel size), while features of one texel are
    /// spread over up to 2×2 texels. Each such rotation blurs a little, so a
    /// chain of rotations back to the start does not return the input exactly;
    /// the integral is kept to within the same interpolation error (a few
    /// parts in a thousand on texel-sized noise).
    ///
    /// # Panics
    /// If `rotation` is not a rotation (orthonormal with determinant +1, to
    /// 10⁻³): the inverse used is its transpose.
    pub fn rotated(&self, rotation: Mat3) -> Environment {
        let orthonormality = (rotation.transpose() * rotation - Mat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f32, |m, e| m.max(e.abs()));
        assert!(
            orthonormality < 1e-3 && rotation.determinant() > 0.0,
            "Environment::rotated needs a rotation matrix, got {rotation:?}"
        );
        let name = format!("{} (rotated)", self.name);
        if let Some(shift) = self.whole_column_y_rotation(rotation) {
            let texels = (0..self.height)
                .flat_map(|row| (0..self.width).map(move |col| (row, col)))
                .map(|(row, col)| self.texel(row, (col + shift) % self.width))
                .collect();
            return self.derived(name, self.width, self.height, texels);
        }
        let inverse = rotation.transpose();
        let mut texels = vec![Vec3::ZERO; self.width * self.height];
        texels
            .par_chunks_mut(self.width)
            .enumerate()
            .for_each(|(row, out)| {
                for (col, t) in out.iter_mut().enumerate() {
                    *t = self.lookup((inverse * self.direction(row, col)).normalize());
                }
            });
        self.derived(name, self.width, self.height, texels)
    }

    /// If `rotation` turns about +Y by k whole columns, the column shift k
    /// such that new column j is old column j + k (mod W).
    ///
    /// `Mat3::from_rotation_y(α)` maps φ to φ − α (its z axis is
    /// (sin α, 0, cos α)), so the new map at φ reads the old one at φ + α.
    fn whole_column_y_rotation(&self, r: Mat3) -> Option<usize> {
        let close = |a: f32, b: f32| (a - b).abs() < Y_ROTATION_TOLERANCE;
        let about_y = close(r.y_axis.x, 0.0)
            && close(r.y_axis.y, 1.0)
            && close(r.y_axis.z, 0.0)
            && close(r.x_axis.y, 0.0)
            && close(r.z_axis.y, 0.0)
            && close(r.x_axis.x, r.z_axis.z)
            && close(r.x_axis.z, -r.z_axis.x);
        if !about_y {
            return None;
        }
        let alpha = (r.z_axis.x as f64).atan2(r.z_axis.z as f64);
        let columns = alpha / TAU * self.width as f64;
        let whole = columns.round();
        ((columns - whole).abs() < COLUMN_SHIFT_TOLERANCE)
            .then(|| (whole as i64).rem_euclid(self.width as i64) as usize)
    }

    /// The map at a lower resolution, each new texel the solid-angle-weighted
    /// mean of the old texels it overlaps (partial overlaps weighted by the
    /// overlapping solid angle), so the integral ([`Environment::integral`])
    /// is preserved to rounding. The ratios need not be whole numbers.
    ///
    /// Overlaps are separable: a texel spans a φ interval times a cos θ
    /// interval and solid angle is dφ·d(cos θ), so columns are averaged by φ
    /// overlap and then rows by cos θ overlap.
    ///
    /// # Panics
    /// If a size is zero or larger than the map's (use
    /// [`Environment::lookup`] to upsample).
    pub fn downsampled(&self, width: usize, height: usize) -> Environment {
        assert!(
            (1..=self.width).contains(&width) && (1..=self.height).contains(&height),
            "cannot downsample a {}×{} environment to {width}×{height}",
            self.width,
            self.height
        );
        if (width, height) == (self.width, self.height) {
            return self.clone();
        }
        let col_edges = |n: usize| (0..=n).map(move |k| k as f64 / n as f64);
        let row_edges = |n: usize| (0..=n).map(move |k| (PI * k as f64 / n as f64).cos());
        let col_taps = overlaps(
            &col_edges(self.width).collect::<Vec<_>>(),
            &col_edges(width).collect::<Vec<_>>(),
        );
        let row_taps = overlaps(
            &row_edges(self.height).collect::<Vec<_>>(),
            &row_edges(height).collect::<Vec<_>>(),
        );

        // Columns first: every source row to the new width.
        let mut narrow = vec![Vec3::ZERO; width * self.height];
        narrow
            .par_chunks_mut(width)
            .enumerate()
            .for_each(|(row, out)| {
                let src = &self.texels[row * self.width..(row + 1) * self.width];
                for (t, taps) in out.iter_mut().zip(&col_taps) {
                    *t = taps.iter().map(|&(j, w)| src[j] * w).sum();
                }
            });
        let mut texels = vec![Vec3::ZERO; width * height];
        texels
            .par_chunks_mut(width)
            .zip(&row_taps)
            .for_each(|(out, taps)| {
                for &(i, w) in taps {
                    for (t, s) in out.iter_mut().zip(&narrow[i * width..(i + 1) * width]) {
                        *t += *s * w;
                    }
                }
            });
        let name = format!("{} (downsampled to {width}×{height})", self.name);
        self.derived(name, width, height, texels)
    }

    /// The map blurred on the sphere with the von Mises–Fisher kernel
    /// K(ω, ω') = exp(κ(ω·ω' − 1)), κ = 1/σ² (σ in radians). For small σ this
    /// is the Gaussian exp(−γ²/(2σ²)) in the angle γ between the directions
    /// (cos γ − 1 ≈ −γ²/2) without an arccosine per tap; unlike the Gaussian
    /// it stays a smooth function on the whole sphere when σ is large. The
    /// kernel is cut off at γ = 3σ.
    ///
    /// Each output texel is Σ K·L·Ω / Σ K·Ω over the input texels, so a
    /// uniform map stays uniform exactly. The kernel is symmetric and its
    /// discrete normalization varies little between rows, so the integral is
    /// kept too (to ~10⁻⁵ relative in the tests, σ from 0.06 to 1 rad).
    ///
    /// To stay affordable the map is first [`downsampled`](Self::downsampled)
    /// (integral-preserving) to a resolution where a texel spans at most σ/2
    /// (at least ⌈2π/σ⌉ rows and ⌈4π/σ⌉ columns, never more than the input),
    /// and the result is returned **at that reduced resolution**: the blurred
    /// signal has no detail finer than σ, and [`Environment::lookup`]
    /// interpolates it. The box filter of the downsampling adds a variance of
    /// at most (σ/2)²/12 per axis, 2% of σ². `sigma = 0` returns the map
    /// unchanged; `sigma = ∞` gives the uniform map of the mean radiance.
    ///
    /// Cost: per output row, only the input rows within 3σ, and in each only
    /// the columns within 3σ; the kernel depends on the two rows and the
    /// column offset only, so each (row, row) pair is one small circular
    /// convolution.
    ///
    /// # Panics
    /// If `sigma` is negative or NaN.
    pub fn prefiltered(&self, sigma: f32) -> Environment {
        assert!(sigma >= 0.0, "blur width σ must be ≥ 0, got {sigma}");
        if sigma == 0.0 {
            return self.clone();
        }
        let name = format!("{} (prefiltered, σ = {sigma} rad)", self.name);
        let sigma = sigma as f64;
        let size = |texels_per_turn: f64, full: usize| {
            ((texels_per_turn / sigma).ceil().max(1.0) as usize).min(full)
        };
        let (w, h) = (size(2.0 * TAU, self.width), size(TAU, self.height));
        let src = self.downsampled(w, h);

        let kappa = 1.0 / (sigma * sigma);
        let radius = KERNEL_RADIUS_SIGMAS * sigma;
        let cos_cut = if radius >= PI { -1.0 } else { radius.cos() };
        let theta = |row: usize| PI * (row as f64 + 0.5) / h as f64;
        let dphi = TAU / w as f64;
        // Column offsets −lo..=hi cover each column of a row once.
        let (lo, hi) = ((w - 1) / 2, w / 2);

        let mut texels = vec![Vec3::ZERO; w * h];
        texels.par_chunks_mut(w).enumerate().for_each(|(ro, out)| {
            let (st_o, ct_o) = theta(ro).sin_cos();
            let mut norm = 0.0f64;
            let mut taps: Vec<(isize, f32)> = Vec::with_capacity(w);
            for rs in 0..h {
                // Every pair of points of two rows is at least |Δθ| apart.
                if (theta(rs) - theta(ro)).abs() > radius {
                    continue;
                }
                let (st_s, ct_s) = theta(rs).sin_cos();
                let omega = src.solid_angle(rs) as f64;
                taps.clear();
                // cos γ = cos θo cos θs + sin θo sin θs cos Δφ falls as |Δφ|
                // grows to π, so the taps stop at the first one past the cut.
                for d in 0..=hi {
                    let cos_gamma = ct_o * ct_s + st_o * st_s * (d as f64 * dphi).cos();
                    if cos_gamma < cos_cut {
                        break;
                    }
                    let k = (kappa * (cos_gamma - 1.0)).exp() * omega;
                    taps.push((d as isize, k as f32));
                    norm += k;
                    if d > 0 && d <= lo {
                        taps.push((-(d as isize), k as f32));
                        norm += k;
                    }
                }
                let row = &src.texels[rs * w..(rs + 1) * w];
                for &(d, k) in &taps {
                    // out[c] += k · row[(c + d) mod w], as two straight runs.
                    let d = d.rem_euclid(w as isize) as usize;
                    let (head, tail) = out.split_at_mut(w - d);
                    for (t, s) in head.iter_mut().zip(&row[d..]) {
                        *t += *s * k;
                    }
                    for (t, s) in tail.iter_mut().zip(&row[..d]) {
                        *t += *s * k;
                    }
                }
            }
            // The output texel's own row and column always contribute, so
            // norm > 0.
            let inv = (1.0 / norm) as f32;
            for t in out.iter_mut() {
                *t *= inv;
            }
        });
        self.derived(name, w, h, texels)
    }

    /// A map computed from this one by a convex combination of texels, which
    /// keeps texels finite and non-negative (so `Environment::new`'s checks
    /// cannot fail) and keeps this map's report.
    fn derived(&self, name: String, width: usize, height: usize, texels: Vec<Vec3>) -> Environment {
        debug_assert_eq!(texels.len(), width * height);
        Environment {
            name,
            width,
            height,
            texels,
            report: self.report,
        }
    }
}

/// For each target interval [t_k, t_k+1] of a partition, the source
/// intervals [s_i, s_i+1] it overlaps and the overlap as a fraction of the
/// target interval. Both partitions are monotonic (either direction) and span
/// the same range, so the fractions of each target add up to 1.
fn overlaps(source: &[f64], target: &[f64]) -> Vec<Vec<(usize, f32)>> {
    let lo = |a: f64, b: f64| a.min(b);
    let hi = |a: f64, b: f64| a.max(b);
    target
        .windows(2)
        .map(|t| {
            let (t0, t1) = (lo(t[0], t[1]), hi(t[0], t[1]));
            let len = t1 - t0;
            source
                .windows(2)
                .enumerate()
                .filter_map(|(i, s)| {
                    let overlap = hi(s[0], s[1]).min(t1) - lo(s[0], s[1]).max(t0);
                    (overlap > 0.0).then(|| (i, (overlap / len) as f32))
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::environment::luminance;
    use approx::assert_relative_eq;
    use std::f32::consts::{FRAC_PI_2, TAU as TAU32};

    /// A small reproducible random stream (xorshift64*), for test data.
    pub(crate) struct TestRng(u64);

    impl TestRng {
        pub(crate) fn new(seed: u64) -> TestRng {
            TestRng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1)
        }

        /// Uniform in [0, 1), 24 bits.
        pub(crate) fn next_f32(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// A reproducible map of independent texels with values in
    /// [0.05, 1.05) per channel, shared by the sampling tests.
    pub(crate) fn random_map(width: usize, height: usize, seed: u64) -> Environment {
        let mut rng = TestRng::new(seed);
        let texels = (0..width * height)
            .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) + 0.05)
            .collect();
        Environment::new(format!("random({seed})"), width, height, texels).unwrap()
    }

    /// A smooth radiance function and the map of its values at texel centres.
    fn smooth(dir: Vec3) -> Vec3 {
        let a = dir.dot(Vec3::new(0.3, 0.8, -0.5));
        let b = dir.dot(Vec3::new(-0.6, 0.1, 0.7));
        Vec3::new(2.0 + a, 1.5 + b * b, 1.0 + 0.5 * a * b)
    }

    fn smooth_map(width: usize, height: usize) -> Environment {
        let mut texels = Vec::with_capacity(width * height);
        for row in 0..height {
            for col in 0..width {
                let theta = std::f32::consts::PI * (row as f32 + 0.5) / height as f32;
                let phi = TAU32 * (col as f32 + 0.5) / width as f32;
                texels.push(smooth(super::super::direction_from_angles(theta, phi)));
            }
        }
        Environment::new("smooth", width, height, texels).unwrap()
    }

    fn single_texel(width: usize, height: usize, row: usize, col: usize) -> Environment {
        let mut texels = vec![Vec3::ZERO; width * height];
        texels[row * width + col] = Vec3::splat(100.0);
        Environment::new("spot", width, height, texels).unwrap()
    }

    fn brightest(env: &Environment) -> (usize, usize) {
        let i = (0..env.texels().len())
            .max_by(|&a, &b| luminance(env.texels()[a]).total_cmp(&luminance(env.texels()[b])))
            .unwrap();
        (i / env.width(), i % env.width())
    }

    /// Solid-angle-weighted mean direction of a map's luminance.
    fn centroid(env: &Environment) -> Vec3 {
        let mut sum = Vec3::ZERO;
        for row in 0..env.height() {
            for col in 0..env.width() {
                let m = luminance(env.texel(row, col)) * env.solid_angle(row);
                sum += env.direction(row, col) * m;
            }
        }
        sum.normalize()
    }

    fn max_abs_difference(a: &Environment, b: &Environment) -> f32 {
        a.texels()
            .iter()
            .zip(b.texels())
            .map(|(x, y)| (*x - *y).abs().max_element())
            .fold(0.0, f32::max)
    }

    #[test]
    fn y_rotation_by_whole_columns_is_an_exact_shift() {
        let env = random_map(32, 16, 1);
        let rotated = env.rotated(Mat3::from_rotation_y(5.0 * TAU32 / 32.0));
        for row in 0..16 {
            for col in 0..32 {
                assert_eq!(rotated.texel(row, col), env.texel(row, (col + 5) % 32));
            }
        }
        let back = rotated.rotated(Mat3::from_rotation_y(-5.0 * TAU32 / 32.0));
        assert_eq!(back.texels(), env.texels());
    }

    #[test]
    fn full_turns_are_the_identity() {
        let env = random_map(48, 24, 2);
        let axis = Vec3::new(1.0, -2.0, 0.5).normalize();
        for rotation in [
            Mat3::from_rotation_x(TAU32),
            Mat3::from_rotation_y(TAU32),
            Mat3::from_rotation_z(TAU32),
            Mat3::from_axis_angle(axis, TAU32),
            Mat3::from_rotation_y(-3.0 * TAU32),
        ] {
            assert_eq!(env.rotated(rotation).texels(), env.texels(), "{rotation:?}");
        }
    }

    #[test]
    fn quarter_turn_about_y_moves_a_feature_from_plus_x_to_minus_z() {
        // Row 16 of 32 is just below the horizon, column 0 just past φ = 0.
        let env = single_texel(64, 32, 16, 0);
        let d = env.direction(16, 0);
        assert!(d.x > 0.99);
        let r = Mat3::from_rotation_y(FRAC_PI_2);
        let moved = env.rotated(r);
        assert!((r * d).z < -0.99);
        assert_eq!(brightest(&moved), moved.texel_of(r * d));
        assert_eq!(moved.integral(), env.integral());
    }

    #[test]
    fn general_rotation_moves_a_feature_to_r_d() {
        let env = single_texel(64, 32, 8, 8);
        let d = env.direction(8, 8);
        let r = Mat3::from_rotation_x(FRAC_PI_2);
        let moved = env.rotated(r);
        assert_eq!(brightest(&moved), moved.texel_of(r * d));
        // Bilinear resampling spreads the texel but keeps it centred within
        // a fraction of a texel (π/32 ≈ 0.1 rad).
        let miss = centroid(&moved).angle_between(r * d);
        assert!(miss < 0.03, "centroid {miss} rad from R·d");
    }

    #[test]
    fn general_rotation_of_a_smooth_map_matches_the_rotated_function() {
        let env = smooth_map(128, 64);
        let r = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let rotated = env.rotated(r);
        let mut worst = 0.0f32;
        for row in 0..64 {
            for col in 0..128 {
                let expected = smooth(r.transpose() * env.direction(row, col));
                worst = worst.max((rotated.texel(row, col) - expected).abs().max_element());
            }
        }
        // Bilinear error on a quadratic with texels of ~0.05 rad.
        assert!(worst < 2e-3, "worst error {worst}");
        let back = rotated.rotated(r.transpose());
        assert!(max_abs_difference(&back, &env) < 4e-3);
    }

    #[test]
    fn rotation_keeps_the_integral() {
        let r = Mat3::from_axis_angle(Vec3::new(-0.4, 1.0, 0.3).normalize(), 1.1);
        let smooth = smooth_map(128, 64);
        assert_relative_eq!(
            smooth.rotated(r).integral(),
            smooth.integral(),
            max_relative = 1e-4
        );
        let noisy = random_map(128, 64, 3);
        assert_relative_eq!(
            noisy.rotated(r).integral(),
            noisy.integral(),
            max_relative = 3e-3
        );
    }

    #[test]
    fn downsampling_keeps_the_integral_for_any_ratio() {
        let env = random_map(64, 32, 4);
        for (w, h) in [(32, 16), (16, 8), (20, 7), (63, 31), (1, 1)] {
            let small = env.downsampled(w, h);
            assert_eq!((small.width(), small.height()), (w, h));
            assert_relative_eq!(small.integral(), env.integral(), max_relative = 1e-5);
        }
        let uniform = Environment::uniform(Vec3::new(1.0, 2.0, 3.0)).downsampled(5, 3);
        for t in uniform.texels() {
            assert_relative_eq!(*t, Vec3::new(1.0, 2.0, 3.0), max_relative = 1e-5);
        }
    }

    #[test]
    fn halving_is_the_solid_angle_weighted_mean_of_two_by_two_blocks() {
        let env = random_map(16, 8, 5);
        let half = env.downsampled(8, 4);
        for row in 0..4 {
            for col in 0..8 {
                let (a, b) = (env.solid_angle(2 * row), env.solid_angle(2 * row + 1));
                let top = env.texel(2 * row, 2 * col) + env.texel(2 * row, 2 * col + 1);
                let bottom = env.texel(2 * row + 1, 2 * col) + env.texel(2 * row + 1, 2 * col + 1);
                let expected = (top * a + bottom * b) / (2.0 * (a + b));
                assert_relative_eq!(half.texel(row, col), expected, max_relative = 1e-5);
            }
        }
    }

    #[test]
    fn prefiltering_keeps_uniform_maps_uniform_and_the_integral() {
        let uniform = Environment::uniform(Vec3::new(0.5, 1.0, 2.0));
        for sigma in [0.05, 0.4, 2.0, f32::INFINITY] {
            for t in uniform.prefiltered(sigma).texels() {
                assert_relative_eq!(*t, Vec3::new(0.5, 1.0, 2.0), max_relative = 1e-5);
            }
        }
        let env = random_map(128, 64, 6);
        for sigma in [0.06, 0.1, 0.3, 1.0] {
            let blurred = env.prefiltered(sigma);
            assert_relative_eq!(blurred.integral(), env.integral(), max_relative = 1e-4);
        }
        let mean = env.integral() / (4.0 * std::f32::consts::PI);
        let flat = env.prefiltered(f32::INFINITY);
        assert_eq!((flat.width(), flat.height()), (1, 1));
        assert_relative_eq!(flat.texel(0, 0), mean, max_relative = 1e-5);
        assert_eq!(env.prefiltered(0.0).texels(), env.texels());
    }

    #[test]
    fn prefiltering_reduces_the_resolution_to_half_sigma_texels() {
        let env = random_map(256, 128, 7);
        let blurred = env.prefiltered(0.1);
        // ⌈4π/0.1⌉ × ⌈2π/0.1⌉
        assert_eq!((blurred.width(), blurred.height()), (126, 63));
        let sharp = env.prefiltered(0.01);
        assert_eq!((sharp.width(), sharp.height()), (256, 128));
    }

    #[test]
    fn a_bright_texel_blurs_into_a_symmetric_spot_of_width_sigma() {
        // At σ = 0.197 a 64×32 map already has texels of ≤ σ/2, so the spot
        // is the kernel itself sampled at texel centres.
        let sigma = 0.197f32;
        let env = single_texel(64, 32, 12, 20);
        let spot = env.prefiltered(sigma);
        assert_eq!((spot.width(), spot.height()), (64, 32));
        let d = env.direction(12, 20);
        let (theta, phi) = super::super::angles_from_direction(d);
        let e_theta = Vec3::new(
            theta.cos() * phi.cos(),
            -theta.sin(),
            theta.cos() * phi.sin(),
        );
        let e_phi = Vec3::new(-phi.sin(), 0.0, phi.cos());
        let (mut m0, mut xx, mut yy, mut xy) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for row in 0..32 {
            for col in 0..64 {
                let m = (luminance(spot.texel(row, col)) * spot.solid_angle(row)) as f64;
                let w = spot.direction(row, col);
                let (x, y) = (w.dot(e_theta) as f64, w.dot(e_phi) as f64);
                m0 += m;
                xx += m * x * x;
                yy += m * y * y;
                xy += m * x * y;
            }
        }
        assert!(centroid(&spot).angle_between(d) < 1e-3);
        let (sx, sy) = ((xx / m0).sqrt() as f32, (yy / m0).sqrt() as f32);
        // vMF and the 3σ cut make the spread ≈ 0.95σ per axis.
        assert_relative_eq!(sx, sigma, max_relative = 0.08);
        assert_relative_eq!(sy, sigma, max_relative = 0.08);
        assert_relative_eq!(sx, sy, max_relative = 0.03);
        assert!((xy / m0).abs() < 1e-4 * (sigma * sigma) as f64);
    }
}
