//! An RGB coefficient vector: projected lighting, or any coloured function.

use glam::Vec3;

use super::basis::eval_sum;
use super::{ShOrder, ShRotation, Zonal};

/// The SH coefficients of an RGB function of direction (radiance, usually),
/// one [`Vec3`] per basis function in [`sh_index`](super::sh_index) order.
///
/// The length always matches the order; build one with
/// [`project_environment`](super::project_environment),
/// [`project_fn_rgb`](super::project_fn_rgb), [`ShRgb::zeros`] or
/// [`ShRgb::from_coeffs`].
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ShRgb {
    order: ShOrder,
    coeffs: Vec<Vec3>,
}

impl ShRgb {
    /// All coefficients zero.
    pub fn zeros(order: ShOrder) -> ShRgb {
        ShRgb::from_parts(order, vec![Vec3::ZERO; order.coeff_count()])
    }

    /// Wraps coefficients whose count is the square of an order (n², 1 ≤ n ≤
    /// 16); `None` for any other count.
    pub fn from_coeffs(coeffs: Vec<Vec3>) -> Option<ShRgb> {
        let order = ShOrder::from_coeff_count(coeffs.len())?;
        Some(ShRgb::from_parts(order, coeffs))
    }

    /// Callers guarantee `coeffs.len() == order.coeff_count()`.
    pub(super) fn from_parts(order: ShOrder, coeffs: Vec<Vec3>) -> ShRgb {
        debug_assert_eq!(coeffs.len(), order.coeff_count());
        ShRgb { order, coeffs }
    }

    pub fn order(&self) -> ShOrder {
        self.order
    }

    pub fn coeffs(&self) -> &[Vec3] {
        &self.coeffs
    }

    /// Mutable access to the coefficients (their count cannot change).
    pub fn coeffs_mut(&mut self) -> &mut [Vec3] {
        &mut self.coeffs
    }

    /// The band-limited function at unit direction `dir`: Σ c_i Y_i(dir).
    /// Allocation-free.
    pub fn eval(&self, dir: Vec3) -> Vec3 {
        eval_sum(self.order, &self.coeffs, dir)
    }

    /// Σ c_i t_i: for lighting L and a transfer vector t (the projection of
    /// the visibility- and cosine-weighted transfer function), the exit
    /// radiance ∫ L(ω) T(ω) dω of Kautz et al. 2004, eq. 2, by orthonormality.
    ///
    /// Vectors of different orders are summed over the shorter one, which is
    /// the exact integral when the missing coefficients are zero (a transfer
    /// vector of order 5 against lighting of order 9 gives the integral of
    /// the order-5 transfer function against the full lighting).
    pub fn dot(&self, transfer: &[f32]) -> Vec3 {
        self.coeffs
            .iter()
            .zip(transfer)
            .fold(Vec3::ZERO, |acc, (&c, &t)| acc + c * t)
    }

    /// The coefficients of the rotated function g(ω) = f(R⁻¹ω).
    ///
    /// # Panics
    /// If `rotation` was built for a lower order than this vector's.
    pub fn rotated(&self, rotation: &ShRotation) -> ShRgb {
        let mut out = ShRgb::zeros(self.order);
        rotation.apply(&self.coeffs, &mut out.coeffs);
        out
    }

    /// The convolution (k ⋆ f)(n) = ∫ k(n·ω) f(ω) dω with a zonal kernel, by
    /// the Funk–Hecke theorem: coefficient (l, m) is scaled by the kernel's
    /// eigenvalue Λ_l ([`Zonal::eigenvalues`]). With [`Zonal::lambert`] the
    /// result evaluated at a normal n is the irradiance
    /// E(n) = ∫ L(ω) max(0, n·ω) dω.
    ///
    /// The result has the lower of the two orders: bands the kernel does not
    /// cover are not set to zero silently, they are dropped.
    pub fn convolve(&self, kernel: &Zonal) -> ShRgb {
        let order = self.order.min(kernel.order());
        let coeffs = (0..order.bands())
            .flat_map(|l| {
                let lambda = kernel.eigenvalues()[l];
                self.coeffs[l * l..(l + 1) * (l + 1)]
                    .iter()
                    .map(move |&c| c * lambda)
            })
            .collect();
        ShRgb::from_parts(order, coeffs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::{eval_basis, project_fn, sh_index};
    use approx::assert_relative_eq;

    #[test]
    fn only_square_counts_make_a_vector() {
        assert!(ShRgb::from_coeffs(vec![Vec3::ONE; 9]).is_some());
        assert!(ShRgb::from_coeffs(vec![Vec3::ONE; 10]).is_none());
        assert!(ShRgb::from_coeffs(vec![]).is_none());
    }

    #[test]
    fn eval_sums_the_basis() {
        let order = ShOrder::new(4).unwrap();
        let coeffs: Vec<Vec3> = (0..16)
            .map(|i| Vec3::new(i as f32, 1.0, -(i as f32)))
            .collect();
        let sh = ShRgb::from_coeffs(coeffs.clone()).unwrap();
        let dir = Vec3::new(0.3, -0.5, 0.7).normalize();
        let mut y = [0.0; 16];
        eval_basis(order, dir, &mut y);
        let want = coeffs
            .iter()
            .zip(&y)
            .fold(Vec3::ZERO, |a, (c, y)| a + *c * *y);
        assert_relative_eq!(sh.eval(dir), want, max_relative = 1e-5);
    }

    /// Kautz eq. 2: the dot product of two projections is the integral of the
    /// product of the two functions (exact when both are band-limited).
    #[test]
    fn dot_is_the_integral_of_the_product() {
        let order = ShOrder::new(3).unwrap();
        // L = (1 + y) per channel scaled, T = x² (band ≤ 2).
        let light =
            crate::sh::project_fn_rgb(order, 8, |d| Vec3::new(1.0, 2.0, 3.0) * (1.0 + d.y + d.x));
        let transfer = project_fn(order, 8, |d| d.x * d.x);
        // ∫ (1 + y + x) x² dω = 4π/3.
        let want = Vec3::new(1.0, 2.0, 3.0) * (4.0 * std::f32::consts::PI / 3.0);
        assert_relative_eq!(light.dot(&transfer), want, max_relative = 1e-5);
        // A shorter transfer vector is zero-padded: band 0 of x² alone.
        let short = &transfer[..1];
        assert_relative_eq!(
            light.dot(short),
            light.coeffs()[0] * transfer[0],
            max_relative = 1e-6
        );
    }

    #[test]
    fn convolution_keeps_the_common_order() {
        let sh = ShRgb::from_coeffs(vec![Vec3::ONE; 25]).unwrap();
        let out = sh.convolve(&Zonal::lambert(ShOrder::new(3).unwrap()));
        assert_eq!(out.order(), ShOrder::new(3).unwrap());
        assert_relative_eq!(
            out.coeffs()[sh_index(1, 1)].x,
            2.0 * std::f32::consts::PI / 3.0
        );
    }
}
