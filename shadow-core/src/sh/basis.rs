//! Evaluation of the basis without trigonometry.
//!
//! Following Sloan ("Efficient spherical harmonic evaluation", JCGT 2013):
//! sin^m θ cos(mφ) and sin^m θ sin(mφ) are the real and imaginary parts of
//! (x + i z)^m (our x, z span the azimuth plane), built by complex
//! multiplication; what remains, K_l^m P_l^m(cos θ) / sin^m θ, is a polynomial
//! in y = cos θ computed with the three-term recurrence in l for fixed m. The
//! recurrence runs on the *normalized* functions, so no factorials appear and
//! nothing overflows or cancels at high l.

use std::sync::LazyLock;

use glam::Vec3;

use super::ShOrder;

/// Coefficients of the normalized associated Legendre recurrences up to
/// [`ShOrder::MAX`]. With N_l^m = s_m K_l^m P_l^m(y) / sin^m θ, s_m = √2 for
/// m > 0 and 1 for m = 0:
///
/// ```text
/// N_m^m     = diag[m]                 (s_m K_m^m (2m−1)!!)
/// N_{m+1}^m = next[m] · y · N_m^m     (next[m] = √(2m+3))
/// N_l^m     = a_l^m (y N_{l−1}^m − b_l^m N_{l−2}^m),
///             a_l^m = √((4l²−1)/(l²−m²)),  b_l^m = √(((l−1)²−m²)/(4(l−1)²−1))
/// ```
pub(super) struct Legendre {
    diag: [f32; MAX_BANDS],
    next: [f32; MAX_BANDS],
    /// Indexed by [`tri`]; only entries with l ≥ m + 2 are used.
    a: [f32; MAX_TRI],
    b: [f32; MAX_TRI],
}

const MAX_BANDS: usize = ShOrder::MAX.bands();
const MAX_TRI: usize = MAX_BANDS * (MAX_BANDS + 1) / 2;

/// Index of (l, m ≥ 0) in a triangular table.
pub(super) const fn tri(l: usize, m: usize) -> usize {
    l * (l + 1) / 2 + m
}

static LEGENDRE: LazyLock<Legendre> = LazyLock::new(|| {
    let mut t = Legendre {
        diag: [0.0; MAX_BANDS],
        next: [0.0; MAX_BANDS],
        a: [0.0; MAX_TRI],
        b: [0.0; MAX_TRI],
    };
    // N_0^0 = 1/√(4π); N_m^m = √((2m+1)/(2m)) N_{m−1}^{m−1}, and √2 for m > 0.
    let mut diag = 1.0 / (4.0 * std::f64::consts::PI).sqrt();
    for m in 0..MAX_BANDS {
        if m > 0 {
            diag *= ((2 * m + 1) as f64 / (2 * m) as f64).sqrt();
        }
        let sqrt2 = if m > 0 { std::f64::consts::SQRT_2 } else { 1.0 };
        t.diag[m] = (diag * sqrt2) as f32;
        t.next[m] = ((2 * m + 3) as f64).sqrt() as f32;
        for l in m + 2..MAX_BANDS {
            let (lf, mf) = (l as f64, m as f64);
            t.a[tri(l, m)] = ((4.0 * lf * lf - 1.0) / (lf * lf - mf * mf)).sqrt() as f32;
            t.b[tri(l, m)] = (((lf - 1.0) * (lf - 1.0) - mf * mf)
                / (4.0 * (lf - 1.0) * (lf - 1.0) - 1.0))
                .sqrt() as f32;
        }
    }
    t
});

impl Legendre {
    pub(super) fn get() -> &'static Legendre {
        &LEGENDRE
    }

    /// Runs the recurrence of column m for bands m..`bands`, starting from
    /// `start` = N_m^m times any factor (the factor carries through, as the
    /// recurrence is linear), and hands each (l, value) to `emit`.
    #[inline(always)]
    pub(super) fn column(
        &self,
        bands: usize,
        m: usize,
        y: f32,
        start: f32,
        mut emit: impl FnMut(usize, f32),
    ) {
        emit(m, start);
        if m + 1 >= bands {
            return;
        }
        let mut p0 = start;
        let mut p1 = self.next[m] * y * start;
        emit(m + 1, p1);
        for l in m + 2..bands {
            let k = tri(l, m);
            let p2 = self.a[k] * (y * p1 - self.b[k] * p0);
            emit(l, p2);
            p0 = p1;
            p1 = p2;
        }
    }

    /// [`Legendre::column`] for `L` values of y at once, writing
    /// Y_l^{±m} = N_l^m · (c, s) into `out` (just N_l^0 for m = 0). Plain
    /// loops, no closure: inlined whole into the caller's instruction set.
    #[inline(always)]
    fn column_lanes<const L: usize>(
        &self,
        bands: usize,
        m: usize,
        y: &[f32; L],
        c: &[f32; L],
        s: &[f32; L],
        out: &mut [[f32; L]],
    ) {
        #[inline(always)]
        fn emit<const L: usize>(
            l: usize,
            m: usize,
            p: &[f32; L],
            c: &[f32; L],
            s: &[f32; L],
            out: &mut [[f32; L]],
        ) {
            let centre = l * l + l;
            if m == 0 {
                out[centre] = *p;
                return;
            }
            for k in 0..L {
                out[centre + m][k] = p[k] * c[k];
                out[centre - m][k] = p[k] * s[k];
            }
        }
        let mut p0 = [self.diag[m]; L];
        emit(m, m, &p0, c, s, out);
        if m + 1 >= bands {
            return;
        }
        let mut p1 = [0.0f32; L];
        for k in 0..L {
            p1[k] = self.next[m] * y[k] * p0[k];
        }
        emit(m + 1, m, &p1, c, s, out);
        for l in m + 2..bands {
            let (a, b) = (self.a[tri(l, m)], self.b[tri(l, m)]);
            let mut p2 = [0.0f32; L];
            for k in 0..L {
                p2[k] = a * (y[k] * p1[k] - b * p0[k]);
            }
            emit(l, m, &p2, c, s, out);
            p0 = p1;
            p1 = p2;
        }
    }

    /// N_m^m (with the √2 of m > 0).
    pub(super) fn diag(&self, m: usize) -> f32 {
        self.diag[m]
    }
}

/// Writes the n² basis values Y_l^m(`dir`) of `order` into `out[..n²]`, in
/// the order of [`sh_index`](super::sh_index). `dir` must be unit length: the polynomials are
/// evaluated as they stand, so another length gives other numbers.
///
/// Allocation-free and without trigonometry: sin^m θ (cos mφ, sin mφ) is
/// (x + i z)^m, the rest a normalized Legendre recurrence in y, about two
/// multiply-adds per value: the one-lane case of [`eval_basis_lanes`].
///
/// # Panics
/// If `out` is shorter than `order.coeff_count()`.
pub fn eval_basis(order: ShOrder, dir: Vec3, out: &mut [f32]) {
    let out = &mut out[..order.coeff_count()];
    debug_assert!(
        (dir.length_squared() - 1.0).abs() < 1e-3,
        "eval_basis needs a unit direction, got {dir}"
    );
    let (lanes, _) = out.as_chunks_mut::<1>();
    eval_basis_lanes(order, [&[dir.x], &[dir.y], &[dir.z]], lanes);
}

/// [`eval_basis`] for `L` directions at once, given by their coordinates
/// `x`, `y`, `z` (unit length): `out[i][lane]` = Y_i(direction `lane`).
/// Every lane goes through the same operations in the same order, so the
/// values do not depend on the width (tested); written as fixed-width loops
/// over the lanes, which the compiler turns into SIMD instructions (inline it
/// into a `#[target_feature]` function for wider ones than the build's).
///
/// # Panics
/// If `out` is shorter than `order.coeff_count()`.
#[inline(always)]
pub fn eval_basis_lanes<const L: usize>(
    order: ShOrder,
    [x, y, z]: [&[f32; L]; 3],
    out: &mut [[f32; L]],
) {
    let bands = order.bands();
    let out = &mut out[..order.coeff_count()];
    let t = Legendre::get();
    // (c, s) = sin^m θ (cos mφ, sin mφ) = (x + i z)^m.
    let (mut c, mut s) = ([1.0f32; L], [0.0f32; L]);
    t.column_lanes(bands, 0, y, &c, &s, out);
    for m in 1..bands {
        for k in 0..L {
            (c[k], s[k]) = (x[k] * c[k] - z[k] * s[k], x[k] * s[k] + z[k] * c[k]);
        }
        t.column_lanes(bands, m, y, &c, &s, out);
    }
}

/// Σ_i c_i Y_i(`dir`) for a coefficient vector of any element type
/// (f32 or RGB), through a stack buffer.
pub(super) fn eval_sum<T>(order: ShOrder, coeffs: &[T], dir: Vec3) -> T
where
    T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f32, Output = T>,
{
    let mut basis = [0.0f32; super::MAX_COEFFS];
    eval_basis(order, dir, &mut basis);
    coeffs
        .iter()
        .zip(&basis[..order.coeff_count()])
        .fold(T::default(), |acc, (&c, &y)| acc + c * y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::quadrature::SphereQuadrature;
    use crate::sh::sh_index;
    use approx::assert_relative_eq;
    use proptest::prelude::*;
    use std::f32::consts::PI;

    /// The lanes version gives [`eval_basis`]'s values to the bit.
    #[test]
    fn lanes_match_single_evaluation() {
        let dirs = random_dirs(40);
        for order in [1, 2, 5, 9, 16] {
            let order = ShOrder::new(order).unwrap();
            for batch in dirs.chunks_exact(8) {
                let coordinate = |axis: usize| std::array::from_fn(|k| batch[k][axis]);
                let (x, y, z): ([f32; 8], [f32; 8], [f32; 8]) =
                    (coordinate(0), coordinate(1), coordinate(2));
                let mut lanes = [[0.0f32; 8]; crate::sh::MAX_COEFFS];
                eval_basis_lanes(order, [&x, &y, &z], &mut lanes);
                for (k, &dir) in batch.iter().enumerate() {
                    let mut one = [0.0f32; crate::sh::MAX_COEFFS];
                    eval_basis(order, dir, &mut one);
                    for i in 0..order.coeff_count() {
                        assert_eq!(lanes[i][k].to_bits(), one[i].to_bits(), "{order}, {i}");
                    }
                }
            }
        }
    }

    fn random_dirs(count: usize) -> Vec<Vec3> {
        // A deterministic spread: a Fibonacci spiral, plus the poles and the
        // axes where sin θ = 0 or φ wraps.
        let golden = PI * (3.0 - 5.0f32.sqrt());
        let mut dirs: Vec<Vec3> = (0..count)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / count as f32;
                let r = (1.0 - y * y).sqrt();
                let phi = golden * i as f32;
                Vec3::new(r * phi.cos(), y, r * phi.sin())
            })
            .collect();
        dirs.extend([
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::NEG_X,
            Vec3::NEG_Y,
            Vec3::NEG_Z,
        ]);
        dirs
    }

    #[test]
    fn bands_0_to_2_match_closed_forms() {
        let order = ShOrder::new(3).unwrap();
        let mut y = [0.0; 9];
        for d in random_dirs(50) {
            eval_basis(order, d, &mut y);
            let (x, yy, z) = (d.x, d.y, d.z);
            let expected = [
                0.282_094_8,
                0.488_602_5 * z,
                0.488_602_5 * yy,
                0.488_602_5 * x,
                1.092_548_4 * x * z,
                1.092_548_4 * yy * z,
                0.315_391_57 * (3.0 * yy * yy - 1.0),
                1.092_548_4 * x * yy,
                0.546_274_2 * (x * x - z * z),
            ];
            for (i, (&got, &want)) in y.iter().zip(&expected).enumerate() {
                assert!(
                    (got - want).abs() < 1e-6,
                    "index {i} at {d}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn zonal_functions_depend_on_y_only() {
        let order = ShOrder::MAX;
        let mut a = [0.0; 256];
        let mut b = [0.0; 256];
        let (s, c) = 0.6f32.sin_cos();
        eval_basis(order, Vec3::new(c * 0.8, 0.6, s * 0.8), &mut a);
        eval_basis(order, Vec3::new(-0.8, 0.6, 0.0), &mut b);
        for l in 0..16 {
            let i = sh_index(l, 0);
            assert_relative_eq!(a[i], b[i], max_relative = 1e-5, epsilon = 1e-6);
        }
    }

    /// sphrs evaluates the z-up real basis without the Condon–Shortley phase;
    /// ours is the same basis with its (x, y, z) fed our (x, z, y). (sphrs
    /// computes (l+m)! in i64, which overflows beyond band 10.)
    #[test]
    fn matches_sphrs_up_to_band_10() {
        use sphrs::{Coordinates, RealSH, SHEval};
        let order = ShOrder::new(11).unwrap();
        let mut ours = [0.0; 121];
        for d in random_dirs(40) {
            eval_basis(order, d, &mut ours);
            let p = Coordinates::cartesian(d.x as f64, d.z as f64, d.y as f64);
            for l in 0..11i64 {
                for m in -l..=l {
                    let theirs = RealSH::Spherical.eval(l, m, &p);
                    let got = ours[sh_index(l as u32, m as i32)] as f64;
                    assert!(
                        (got - theirs).abs() < 2e-5 * (1.0 + theirs.abs()),
                        "Y_{l}^{m} at {d}: ours {got}, sphrs {theirs}"
                    );
                }
            }
        }
    }

    #[test]
    fn basis_is_orthonormal_up_to_order_9() {
        let order = ShOrder::new(9).unwrap();
        let n = order.coeff_count();
        // Products of band ≤ 8 functions are integrated exactly by 12 rings.
        let quad = SphereQuadrature::new(12);
        let mut gram = vec![0.0f64; n * n];
        let mut y = vec![0.0f32; n];
        for (dir, w) in quad.nodes() {
            eval_basis(order, dir, &mut y);
            for i in 0..n {
                for j in 0..n {
                    gram[i * n + j] += (y[i] * y[j]) as f64 * w;
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (gram[i * n + j] - want).abs() < 1e-4,
                    "<Y_{i}, Y_{j}> = {}",
                    gram[i * n + j]
                );
            }
        }
    }

    #[test]
    #[should_panic]
    fn short_output_buffer_panics_rather_than_truncating() {
        let mut out = [0.0; 8];
        eval_basis(ShOrder::new(3).unwrap(), Vec3::Y, &mut out);
    }

    proptest! {
        /// The addition theorem: Σ_m Y_l^m(ω)² = (2l+1)/(4π) for every
        /// direction and band, which fails if any normalization, sign-free
        /// recurrence step or azimuthal factor is off.
        #[test]
        fn addition_theorem_holds(theta in 0.0f32..PI, phi in 0.0f32..(2.0 * PI)) {
            let d = crate::environment::direction_from_angles(theta, phi);
            let mut y = [0.0; 256];
            eval_basis(ShOrder::MAX, d, &mut y);
            for l in 0..16u32 {
                let sum: f32 = (-(l as i32)..=l as i32).map(|m| y[sh_index(l, m)].powi(2)).sum();
                let want = (2 * l + 1) as f32 / (4.0 * PI);
                prop_assert!((sum - want).abs() < 2e-5 * want.max(1.0), "band {}: {} vs {}", l, sum, want);
            }
        }
    }
}
