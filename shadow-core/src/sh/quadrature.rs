//! Gauss–Legendre quadrature, on an interval and over the sphere.
//!
//! The sphere rule is Gauss–Legendre in cos θ times a uniform rule in φ: with
//! N rings and 2N azimuths it integrates every spherical polynomial of degree
//! ≤ 2N − 1 exactly, so products of two functions of bands < N (the
//! projection of a band-limited function, a Gram matrix) come out exact to
//! rounding.

use std::f64::consts::{PI, TAU};

use glam::Vec3;

/// Nodes and weights of the n-point Gauss–Legendre rule on [−1, 1]
/// (nodes descending), by Newton's iteration on P_n.
pub(super) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            // Tricomi's first guess, then Newton to full double precision.
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                let (p, dp) = legendre_and_derivative(n, x);
                let step = p / dp;
                x -= step;
                if step.abs() < 1e-15 {
                    break;
                }
            }
            let (_, dp) = legendre_and_derivative(n, x);
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// (P_n(x), P_n'(x)) by Bonnet's recurrence.
fn legendre_and_derivative(n: usize, x: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, x);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let k = k as f64;
        (p0, p1) = (p1, ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k);
    }
    (p1, n as f64 * (x * p1 - p0) / (x * x - 1.0))
}

/// Gauss–Legendre rings in cos θ × 2N uniform azimuths.
pub(super) struct SphereQuadrature {
    /// (cos θ, Gauss weight) per ring.
    rings: Vec<(f64, f64)>,
    azimuths: usize,
}

impl SphereQuadrature {
    /// `rings` ≥ 1 rings (callers keep it so).
    pub(super) fn new(rings: usize) -> SphereQuadrature {
        SphereQuadrature {
            rings: gauss_legendre(rings),
            azimuths: 2 * rings,
        }
    }

    pub(super) fn ring_count(&self) -> usize {
        self.rings.len()
    }

    /// The nodes of ring `k`: unit directions and their weights (solid
    /// angles; all nodes together weigh 4π).
    pub(super) fn ring(&self, k: usize) -> impl Iterator<Item = (Vec3, f64)> + '_ {
        let (y, w) = self.rings[k];
        let r = (1.0 - y * y).max(0.0).sqrt();
        let weight = w * TAU / self.azimuths as f64;
        (0..self.azimuths).map(move |j| {
            let phi = TAU * (j as f64 + 0.5) / self.azimuths as f64;
            let dir = Vec3::new((r * phi.cos()) as f32, y as f32, (r * phi.sin()) as f32);
            (dir, weight)
        })
    }

    #[cfg(test)]
    pub(super) fn nodes(&self) -> impl Iterator<Item = (Vec3, f64)> + '_ {
        (0..self.ring_count()).flat_map(|k| self.ring(k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn gauss_legendre_is_exact_for_degree_2n_minus_1() {
        for n in [1, 2, 5, 12, 40] {
            let rule = gauss_legendre(n);
            for k in 0..2 * n {
                let got: f64 = rule.iter().map(|&(x, w)| w * x.powi(k as i32)).sum();
                let want = if k % 2 == 1 {
                    0.0
                } else {
                    2.0 / (k as f64 + 1.0)
                };
                assert!(
                    (got - want).abs() < 1e-13,
                    "n = {n}, x^{k}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn sphere_rule_integrates_monomials() {
        let q = SphereQuadrature::new(6);
        let total: f64 = q.nodes().map(|(_, w)| w).sum();
        assert_relative_eq!(total, 4.0 * PI, epsilon = 1e-12);
        // ∫ x² = ∫ y² = ∫ z² = 4π/3, ∫ x²y²z² = 4π/105, ∫ x y = 0.
        let moment = |f: &dyn Fn(Vec3) -> f64| q.nodes().map(|(d, w)| f(d) * w).sum::<f64>();
        for axis in 0..3 {
            assert_relative_eq!(
                moment(&|d| (d[axis] as f64).powi(2)),
                4.0 * PI / 3.0,
                epsilon = 1e-6
            );
        }
        assert_relative_eq!(
            moment(&|d| (d.x as f64 * d.y as f64 * d.z as f64).powi(2)),
            4.0 * PI / 105.0,
            epsilon = 1e-7
        );
        assert!(moment(&|d| d.x as f64 * d.y as f64).abs() < 1e-7);
    }
}
