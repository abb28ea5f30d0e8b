//! Zonal kernels and convolution by the Funk–Hecke theorem (see [`Zonal`]).

use std::f64::consts::TAU;

use glam::Vec3;

use super::{ShOrder, eval_basis};

/// A zonal kernel, truncated to an order, stored by its Funk–Hecke
/// eigenvalues Λ_l (one per band).
///
/// A zonal kernel k(cos θ) depends only on the angle to an axis. By the
/// Funk–Hecke theorem, for every band-l function Y_lm,
/// ∫ k(n·ω) Y_lm(ω) dω = Λ_l Y_lm(n), with
///
/// ```text
/// Λ_l = 2π ∫_{−1}^{1} k(t) P_l(t) dt = √(4π/(2l+1)) · z_l,
/// ```
///
/// z_l being the kernel's own projection coefficient onto Y_l^0 when its axis
/// is +Y ([`Zonal::kernel_coeff`]). So convolving f with k multiplies band l
/// of f by Λ_l: the Λ_l are the Â_l of Ramamoorthi and Hanrahan ("An
/// efficient representation for irradiance environment maps", 2001), and
/// [`ShRgb::convolve`](super::ShRgb::convolve) uses them directly. For
/// example the irradiance E(n) = ∫ L(ω) max(0, n·ω) dω is
/// `project_environment(&env, order).convolve(&Zonal::lambert(order)).eval(n)`.
///
/// Both kernels offered are clamped cosine powers, k(t) = max(0, t)^s, for
/// which I_l(s) = ∫_0^1 t^s P_l(t) dt obeys, for any real s ≥ 0,
///
/// ```text
/// I_0 = 1/(s+1),   I_1 = 1/(s+2),   I_l = (s − l + 2)/(s + l + 1) · I_{l−2}
/// ```
///
/// (the ratio of consecutive values of the closed form
/// √π Γ(s+1) / (2^(s+1) Γ(1 + (s−l)/2) Γ((s+l+3)/2))), and Λ_l = 2π I_l
/// times the kernel's scale.
#[derive(Clone, Debug, PartialEq)]
pub struct Zonal {
    order: ShOrder,
    eigenvalues: Vec<f32>,
}

impl Zonal {
    /// Lambert's clamped cosine max(0, cos θ). Its eigenvalues are
    /// Λ_0 = π, Λ_1 = 2π/3, Λ_l = 0 for odd l > 1, and for even l ≥ 2
    ///
    /// ```text
    /// Λ_l = 2π (−1)^(l/2+1) / ((l+2)(l−1)) · l! / (2^l ((l/2)!)²)
    /// ```
    ///
    /// (π/4, −π/24, π/64, ...). Convolving radiance with it gives irradiance,
    /// E(n) = ∫ L(ω) max(0, n·ω) dω; a Lambert surface of albedo ρ then
    /// reflects ρ E / π.
    pub fn lambert(order: ShOrder) -> Zonal {
        Zonal::clamped_cosine_power(order, 1.0, 1.0)
    }

    /// The normalized Phong lobe (s+2)/(2π) · max(0, cos α)^s of
    /// [`Brdf::Phong`](crate::Brdf::Phong), α measured from the lobe's axis
    /// (the mirror direction), as the BRDF's specular term without ρ_s and
    /// without the cosine factor. `None` unless the exponent is finite and
    /// non-negative.
    ///
    /// The factor normalizes the lobe *with* the cosine at normal incidence
    /// (∫ lobe · cos = 1 there), so the lobe alone integrates to
    /// Λ_0 = (s+2)/(s+1): convolving a uniform unit environment gives
    /// (s+2)/(s+1), not 1. Lighting convolved with this kernel and evaluated
    /// at the mirror direction is the prefiltered specular of the
    /// reflection-map approximation (cos θ_i taken out of the integral).
    pub fn phong(order: ShOrder, exponent: f32) -> Option<Zonal> {
        if !(exponent.is_finite() && exponent >= 0.0) {
            return None;
        }
        let s = exponent as f64;
        Some(Zonal::clamped_cosine_power(order, s, (s + 2.0) / TAU))
    }

    /// The kernel whose Funk–Hecke eigenvalues are `eigenvalues`, one per
    /// band of `order` (as a [`Window`](super::Window) gives them).
    pub(super) fn from_eigenvalues(order: ShOrder, eigenvalues: Vec<f32>) -> Zonal {
        debug_assert_eq!(eigenvalues.len(), order.bands());
        Zonal { order, eigenvalues }
    }

    /// scale · max(0, t)^s: Λ_l = 2π · scale · I_l(s) (module docs).
    fn clamped_cosine_power(order: ShOrder, s: f64, scale: f64) -> Zonal {
        let bands = order.bands();
        let mut integrals = vec![1.0 / (s + 1.0), 1.0 / (s + 2.0)];
        for l in 2..bands {
            let lf = l as f64;
            integrals.push((s - lf + 2.0) / (s + lf + 1.0) * integrals[l - 2]);
        }
        let eigenvalues = integrals[..bands]
            .iter()
            .map(|i| (TAU * scale * i) as f32)
            .collect();
        Zonal { order, eigenvalues }
    }

    pub fn order(&self) -> ShOrder {
        self.order
    }

    /// Λ_l for l = 0..n−1: what band l of a function is multiplied by when
    /// convolved with this kernel.
    pub fn eigenvalues(&self) -> &[f32] {
        &self.eigenvalues
    }

    /// z_l = √((2l+1)/(4π)) Λ_l: the coefficient of Y_l^0 in the projection
    /// of the kernel about +Y (all its other coefficients are zero).
    ///
    /// # Panics
    /// If `l` is not below the order.
    pub fn kernel_coeff(&self, l: usize) -> f32 {
        ((2 * l + 1) as f32 / (4.0 * std::f32::consts::PI)).sqrt() * self.eigenvalues[l]
    }

    /// Writes the n² coefficients of the kernel turned to `axis` (unit),
    /// k(axis·ω): Λ_l Y_lm(axis). With [`Zonal::lambert`] and the surface
    /// normal as axis this is the transfer vector of an unshadowed diffuse
    /// vertex (Kautz et al. 2004 without visibility), up to ρ/π.
    ///
    /// # Panics
    /// If `out` is shorter than the order's coefficient count.
    pub fn project_along(&self, axis: Vec3, out: &mut [f32]) {
        eval_basis(self.order, axis, out);
        for (l, &lambda) in self.eigenvalues.iter().enumerate() {
            for c in &mut out[l * l..(l + 1) * (l + 1)] {
                *c *= lambda;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Environment;
    use crate::environment::direction_from_angles;
    use crate::sh::quadrature::gauss_legendre;
    use crate::sh::test_util::environment_of;
    use crate::sh::{project_environment, project_fn, project_fn_rgb};
    use approx::assert_relative_eq;
    use std::f32::consts::PI;

    fn legendre(l: usize, t: f64) -> f64 {
        let (mut p0, mut p1) = (1.0, t);
        if l == 0 {
            return 1.0;
        }
        for k in 2..=l {
            let k = k as f64;
            (p0, p1) = (p1, ((2.0 * k - 1.0) * t * p1 - (k - 1.0) * p0) / k);
        }
        p1
    }

    fn factorial(n: usize) -> f64 {
        (1..=n).map(|k| k as f64).product()
    }

    #[test]
    fn lambert_eigenvalues_follow_the_closed_form() {
        let z = Zonal::lambert(ShOrder::new(12).unwrap());
        let lambda = z.eigenvalues();
        let pi = std::f64::consts::PI;
        let expected_start = [
            pi,
            2.0 * pi / 3.0,
            pi / 4.0,
            0.0,
            -pi / 24.0,
            0.0,
            pi / 64.0,
        ];
        for (l, want) in expected_start.iter().enumerate() {
            assert_relative_eq!(lambda[l] as f64, *want, epsilon = 1e-6);
        }
        for l in (2..12).step_by(2) {
            let h = l / 2;
            let sign = if h % 2 == 1 { 1.0 } else { -1.0 };
            let want = TAU * sign / (((l + 2) * (l - 1)) as f64) * factorial(l)
                / (2f64.powi(l as i32) * factorial(h).powi(2));
            assert_relative_eq!(lambda[l] as f64, want, max_relative = 1e-5);
        }
        for l in (3..12).step_by(2) {
            assert_eq!(lambda[l], 0.0);
        }
    }

    /// Λ_l = 2π ∫ k(t) P_l(t) dt by 200-point Gauss–Legendre on [0, 1],
    /// independent of the recurrence.
    #[test]
    fn phong_eigenvalues_match_quadrature_of_the_lobe() {
        let rule = gauss_legendre(200);
        for exponent in [0.0f32, 1.0, 7.5, 32.0, 200.0] {
            let z = Zonal::phong(ShOrder::new(12).unwrap(), exponent).unwrap();
            let s = exponent as f64;
            for l in 0..12 {
                let integral: f64 = rule
                    .iter()
                    .map(|&(x, w)| {
                        let t = 0.5 * (x + 1.0);
                        0.5 * w * (s + 2.0) / TAU * t.powf(s) * legendre(l, t)
                    })
                    .sum();
                let want = TAU * integral;
                assert!(
                    (z.eigenvalues()[l] as f64 - want).abs() < 1e-5 * (1.0 + want.abs()),
                    "exponent {exponent}, band {l}: {} vs {want}",
                    z.eigenvalues()[l]
                );
            }
        }
        assert!(Zonal::phong(ShOrder::new(3).unwrap(), -1.0).is_none());
        assert!(Zonal::phong(ShOrder::new(3).unwrap(), f32::NAN).is_none());
    }

    /// The kernel turned to an arbitrary axis, projected on the sphere by
    /// quadrature, equals `project_along`, and about +Y only m = 0 survives.
    #[test]
    fn phong_lobe_projection_matches_quadrature() {
        let order = ShOrder::new(9).unwrap();
        for exponent in [1.0f32, 20.0] {
            let z = Zonal::phong(order, exponent).unwrap();
            let lobe = |axis: Vec3| {
                move |d: Vec3| (exponent + 2.0) / (2.0 * PI) * axis.dot(d).max(0.0).powf(exponent)
            };
            let mut along = [0.0; 81];
            for axis in [Vec3::Y, Vec3::new(0.4, -0.3, 0.8).normalize()] {
                let numeric = project_fn(order, 200, lobe(axis));
                z.project_along(axis, &mut along);
                for (i, (a, b)) in numeric.iter().zip(&along).enumerate() {
                    assert!(
                        (a - b).abs() < 2e-4 * z.kernel_coeff(0),
                        "exponent {exponent}, {i}: {a} vs {b}"
                    );
                }
            }
            let numeric = project_fn(order, 200, lobe(Vec3::Y));
            for l in 0..9 {
                let i = crate::sh::sh_index(l as u32, 0);
                assert_relative_eq!(numeric[i], z.kernel_coeff(l), epsilon = 2e-4);
            }
        }
    }

    #[test]
    fn uniform_environment_has_irradiance_pi_everywhere() {
        let order = ShOrder::new(9).unwrap();
        let irradiance = project_environment(&Environment::uniform(Vec3::ONE), order)
            .convolve(&Zonal::lambert(order));
        for i in 0..40 {
            let n = direction_from_angles(PI * (i as f32 + 0.5) / 40.0, 2.4 * i as f32);
            assert_relative_eq!(irradiance.eval(n), Vec3::splat(PI), max_relative = 1e-5);
        }
    }

    /// E(n) = ∫ max(0, ω.y) max(0, n·ω) dω by brute force (a 1024×2048
    /// midpoint grid), against the order-9 SH irradiance. The SH error is the
    /// truncation of Λ_l² ~ l^(−5): about 1e-3 of E's range at order 9.
    #[test]
    fn irradiance_of_a_sky_matches_brute_force() {
        let order = ShOrder::new(9).unwrap();
        let lambert = Zonal::lambert(order);
        let sky = |d: Vec3| d.y.max(0.0);
        let by_quadrature = project_fn_rgb(order, 256, |d| Vec3::splat(sky(d))).convolve(&lambert);
        let by_map = project_environment(
            &environment_of("sky", 512, 256, |d| Vec3::splat(sky(d))),
            order,
        )
        .convolve(&lambert);
        let (rows, cols) = (1024, 2048);
        for k in 0..9 {
            let n = direction_from_angles(PI * k as f32 / 8.0, 0.7 * k as f32);
            let mut brute = 0.0f64;
            for r in 0..rows {
                let theta = PI * (r as f32 + 0.5) / rows as f32;
                let d_omega = theta.sin() as f64
                    * (PI / rows as f32) as f64
                    * (2.0 * PI / cols as f32) as f64;
                for c in 0..cols {
                    let d = direction_from_angles(theta, 2.0 * PI * (c as f32 + 0.5) / cols as f32);
                    brute += (sky(d) * n.dot(d).max(0.0)) as f64 * d_omega;
                }
            }
            let brute = brute as f32;
            if k == 0 {
                assert_relative_eq!(brute, 2.0 * PI / 3.0, epsilon = 1e-4);
            }
            for sh in [&by_quadrature, &by_map] {
                let e = sh.eval(n).x;
                assert!(
                    (e - brute).abs() < 2e-3,
                    "normal {n}: SH {e}, brute force {brute}"
                );
            }
        }
    }
}
