//! Projection onto the basis: c_i = ∫ f(ω) Y_i(ω) dω.

use std::f64::consts::{PI, TAU};

use glam::Vec3;
use rayon::prelude::*;

use super::basis::{Legendre, eval_basis, tri};
use super::quadrature::{SphereQuadrature, gauss_legendre};
use super::{MAX_COEFFS, ShOrder, ShRgb};
use crate::Environment;

/// The SH coefficients of a lat-long environment, each texel standing for its
/// whole cell (the lat-long rectangle around [`Environment::direction`], of
/// solid angle [`Environment::solid_angle`]) with constant radiance:
/// c_lm = Σ_texels L_t ∫_cell(t) Y_lm dω.
///
/// This is the exact projection of the map as a piecewise-constant function,
/// not a sampled estimate: a constant map projects onto band 0 alone, however
/// coarse it is (the furnace stays a furnace). It differs from the midpoint
/// sum Σ L_t Y(ω_t) Ω_t by O((π/H)²). The cell integral separates,
/// Y_lm = Θ_lm(θ) · trig(mφ): the φ integral is closed-form, the θ integral
/// uses Gauss–Legendre nodes, accurate to rounding for these band-limited
/// integrands, so the cost is O(W·H·n) rather than O(W·H·n²). Rows are
/// summed in parallel, in f64.
pub fn project_environment(env: &Environment, order: ShOrder) -> ShRgb {
    let (width, height) = (env.width(), env.height());
    let bands = order.bands();
    // Azimuthal factor ∫_cell trig(mφ) dφ of column j at index m + bands − 1:
    // sin(|m|φ) for m < 0, cos(mφ) for m ≥ 0. Over a cell of width Δ centred
    // on φ_c this is (2/m) sin(mΔ/2) · cos(mφ_c) (resp. sin), and Δ for m = 0.
    let span = 2 * bands - 1;
    let dphi = TAU / width as f64;
    let mut azimuth = vec![0.0f64; width * span];
    for (col, factors) in azimuth.chunks_exact_mut(span).enumerate() {
        let phi = TAU * (col as f64 + 0.5) / width as f64;
        factors[bands - 1] = dphi;
        for m in 1..bands {
            let mf = m as f64;
            let width_factor = 2.0 / mf * (mf * dphi / 2.0).sin();
            let (s, c) = (mf * phi).sin_cos();
            factors[bands - 1 + m] = width_factor * c;
            factors[bands - 1 - m] = width_factor * s;
        }
    }
    // Θ_lm(θ) sin θ is a trigonometric polynomial of degree ≤ bands, entire
    // and smooth: 2·bands + 4 nodes per row integrate it to f32 rounding even
    // when one row spans the whole sphere.
    let nodes = gauss_legendre(2 * bands + 4);
    let legendre = Legendre::get();
    let n = order.coeff_count();

    let sums = (0..height)
        .into_par_iter()
        .fold(
            || vec![[0.0f64; 3]; n],
            |mut acc, row| {
                // A_lm = ∫_row Θ_lm(θ) sin θ dθ, m ≥ 0, triangular layout.
                let mut polar = [0.0f64; MAX_TRI];
                let theta0 = PI * row as f64 / height as f64;
                let half = PI / height as f64 / 2.0;
                for &(x, w) in &nodes {
                    let (st, ct) = (theta0 + half * (1.0 + x)).sin_cos();
                    let weight = w * half * st;
                    let mut sin_m = 1.0f32;
                    for m in 0..bands {
                        let start = legendre.diag(m) * sin_m;
                        legendre.column(bands, m, ct as f32, start, |l, p| {
                            polar[tri(l, m)] += p as f64 * weight;
                        });
                        sin_m *= st as f32;
                    }
                }
                // Radiance of the row weighted by each azimuthal factor.
                let mut ring = [[0.0f64; 3]; 2 * MAX_BANDS - 1];
                let texels = &env.texels()[row * width..(row + 1) * width];
                for (l_t, factors) in texels.iter().zip(azimuth.chunks_exact(span)) {
                    let rgb = [l_t.x as f64, l_t.y as f64, l_t.z as f64];
                    for (r, &f) in ring.iter_mut().zip(factors) {
                        for c in 0..3 {
                            r[c] += rgb[c] * f;
                        }
                    }
                }
                for l in 0..bands {
                    for m in -(l as i64)..=l as i64 {
                        let a = polar[tri(l, m.unsigned_abs() as usize)];
                        let r = ring[(m + bands as i64 - 1) as usize];
                        let out = &mut acc[l * l + (l as i64 + m) as usize];
                        for c in 0..3 {
                            out[c] += a * r[c];
                        }
                    }
                }
                acc
            },
        )
        .reduce(|| vec![[0.0f64; 3]; n], add_into);
    ShRgb::from_parts(order, sums.iter().map(to_vec3).collect())
}

const MAX_BANDS: usize = ShOrder::MAX.bands();
const MAX_TRI: usize = MAX_BANDS * (MAX_BANDS + 1) / 2;

/// The SH coefficients of a scalar function of direction (a transfer
/// function, a kernel, a test signal) by Gauss–Legendre quadrature: N rings in
/// cos θ times 2N azimuths, N = max(`resolution`, order), and f64 sums.
///
/// For f band-limited to bands < B the result is exact to rounding when
/// B + order ≤ 2N; for other functions the error falls as N grows (fast for
/// smooth f, as 1/N² for f with kinks such as a clamped cosine). Rings are
/// evaluated in parallel, so `f` must be `Sync`.
pub fn project_fn(order: ShOrder, resolution: usize, f: impl Fn(Vec3) -> f32 + Sync) -> Vec<f32> {
    quadrature_projection(order, resolution, |d| [f(d)])
        .iter()
        .map(|[c]| *c as f32)
        .collect()
}

/// [`project_fn`] for an RGB function (radiance from an analytic sky, say).
pub fn project_fn_rgb(order: ShOrder, resolution: usize, f: impl Fn(Vec3) -> Vec3 + Sync) -> ShRgb {
    let sums = quadrature_projection(order, resolution, |d| f(d).to_array());
    ShRgb::from_parts(order, sums.iter().map(to_vec3).collect())
}

fn quadrature_projection<const C: usize>(
    order: ShOrder,
    resolution: usize,
    f: impl Fn(Vec3) -> [f32; C] + Sync,
) -> Vec<[f64; C]> {
    let n = order.coeff_count();
    let quad = SphereQuadrature::new(resolution.max(order.bands()));
    (0..quad.ring_count())
        .into_par_iter()
        .fold(
            || vec![[0.0f64; C]; n],
            |mut acc, k| {
                let mut basis = [0.0f32; MAX_COEFFS];
                for (dir, weight) in quad.ring(k) {
                    let value = f(dir);
                    eval_basis(order, dir, &mut basis);
                    for (a, &y) in acc.iter_mut().zip(&basis[..n]) {
                        let yw = y as f64 * weight;
                        for c in 0..C {
                            a[c] += value[c] as f64 * yw;
                        }
                    }
                }
                acc
            },
        )
        .reduce(|| vec![[0.0f64; C]; n], add_into)
}

fn add_into<const C: usize>(mut a: Vec<[f64; C]>, b: Vec<[f64; C]>) -> Vec<[f64; C]> {
    for (x, y) in a.iter_mut().zip(&b) {
        for c in 0..C {
            x[c] += y[c];
        }
    }
    a
}

fn to_vec3(c: &[f64; 3]) -> Vec3 {
    Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::basis::eval_sum;
    use crate::sh::test_util::{environment_of, positive_band_limited};
    use approx::assert_relative_eq;

    /// Random coefficients of magnitude ≤ 1 (c_00 ≈ 45 to keep radiance
    /// positive) come back to within the O((π/H)²) error of representing the
    /// function by its texel-centre values (measured 4e-4).
    #[test]
    fn band_limited_environment_is_recovered() {
        let truth_order = ShOrder::new(5).unwrap();
        let truth = positive_band_limited(truth_order, 7);
        let env = environment_of("band-limited", 256, 128, |d| {
            eval_sum(truth_order, &truth, d)
        });
        assert_eq!(env.report().negative_clamped, 0);
        let order = ShOrder::new(8).unwrap();
        let got = project_environment(&env, order);
        for (i, c) in got.coeffs().iter().enumerate() {
            let want = truth.get(i).copied().unwrap_or(Vec3::ZERO);
            assert!(
                (*c - want).abs().max_element() < 2e-3,
                "coefficient {i}: {c} vs {want}"
            );
        }
    }

    #[test]
    fn constant_environment_projects_onto_band_0_exactly() {
        // Environment::uniform is a coarse 16×8 map: a midpoint sum would leak
        // ~0.05 into Y_2^0, the cell-exact projection leaks nothing.
        let env = Environment::uniform(Vec3::new(1.0, 2.0, 0.5));
        let sh = project_environment(&env, ShOrder::MAX);
        let c00 = (4.0 * std::f32::consts::PI).sqrt();
        assert_relative_eq!(
            sh.coeffs()[0],
            Vec3::new(1.0, 2.0, 0.5) * c00,
            max_relative = 1e-6
        );
        for (i, c) in sh.coeffs().iter().enumerate().skip(1) {
            assert!(c.abs().max_element() < 1e-5, "coefficient {i}: {c}");
        }
        // Also for a single-row map, where each cell spans the whole θ range.
        let env = Environment::new("one row", 3, 1, vec![Vec3::ONE; 3]).unwrap();
        let sh = project_environment(&env, ShOrder::MAX);
        assert_relative_eq!(sh.coeffs()[0].x, c00, max_relative = 1e-6);
        for (i, c) in sh.coeffs().iter().enumerate().skip(1) {
            assert!(
                c.abs().max_element() < 1e-5,
                "one row, coefficient {i}: {c}"
            );
        }
    }

    /// Ties the cell geometry to the shared mapping: the cell-exact projection
    /// must agree with the midpoint sum over `direction` and `solid_angle`.
    #[test]
    fn agrees_with_midpoint_sum_over_texel_centres() {
        let (w, h) = (128, 64);
        let f = |d: Vec3| {
            Vec3::new(
                (2.0 * d.x + d.y).exp(),
                1.0 + d.z * d.y,
                (d.x - d.z).max(0.0),
            )
        };
        let env = environment_of("smooth", w, h, f);
        let order = ShOrder::new(6).unwrap();
        let exact = project_environment(&env, order);
        let mut midpoint = vec![Vec3::ZERO; order.coeff_count()];
        let mut y = vec![0.0; order.coeff_count()];
        for r in 0..h {
            for c in 0..w {
                eval_basis(order, env.direction(r, c), &mut y);
                for (m, &yi) in midpoint.iter_mut().zip(&y) {
                    *m += env.texel(r, c) * yi * env.solid_angle(r);
                }
            }
        }
        let scale = exact.coeffs()[0].max_element();
        for (i, (a, b)) in exact.coeffs().iter().zip(&midpoint).enumerate() {
            assert!(
                (*a - *b).abs().max_element() < 1e-3 * scale,
                "coefficient {i}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn quadrature_projection_is_exact_for_band_limited_functions() {
        let truth_order = ShOrder::new(7).unwrap();
        let truth = positive_band_limited(truth_order, 3);
        let order = ShOrder::new(9).unwrap();
        // Bands < 7 times bands < 9: 8 rings suffice.
        let got = project_fn_rgb(order, 8, |d| eval_sum(truth_order, &truth, d));
        for (i, c) in got.coeffs().iter().enumerate() {
            let want = truth.get(i).copied().unwrap_or(Vec3::ZERO);
            assert!(
                (*c - want).abs().max_element() < 2e-5 * truth[0].x,
                "coefficient {i}: {c} vs {want}"
            );
        }
        let scalar = project_fn(order, 8, |d| eval_sum(truth_order, &truth, d).y);
        for (i, c) in scalar.iter().enumerate() {
            let want = truth.get(i).map_or(0.0, |t| t.y);
            assert!(
                (c - want).abs() < 2e-5 * truth[0].y,
                "coefficient {i}: {c} vs {want}"
            );
        }
    }

    #[test]
    fn too_low_a_resolution_is_raised_to_the_order() {
        // One ring cannot integrate band 2 products; the order's own ring
        // count can, so Y_2^0 itself is recovered.
        let order = ShOrder::new(3).unwrap();
        let got = project_fn(order, 1, |d| 0.315_391_57 * (3.0 * d.y * d.y - 1.0));
        assert_relative_eq!(got[crate::sh::sh_index(2, 0)], 1.0, epsilon = 1e-5);
    }
}
