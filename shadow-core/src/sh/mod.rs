//! Real spherical harmonics: the one SH convention of the workspace.
//!
//! # Convention
//!
//! Real, orthonormal over the unit sphere (∫ Y_i Y_j dω = δ_ij), **without**
//! the Condon–Shortley phase (−1)^m. The polar axis is **+Y** (our "up"), so
//! that the angles are those of the environment map (`crate::environment`):
//! θ is measured from +Y and φ from +X towards +Z,
//! ω = (sin θ cos φ, cos θ, sin θ sin φ). With
//! K_l^m = √((2l+1)/(4π) · (l−m)!/(l+m)!) and P_l^m the associated Legendre
//! functions without the (−1)^m phase,
//!
//! ```text
//! Y_l^m  = √2 K_l^m  cos(m φ)   P_l^m(cos θ)    m > 0
//! Y_l^0  =    K_l^0             P_l^0(cos θ)    (depends on ω.y only)
//! Y_l^m  = √2 K_l^|m| sin(|m| φ) P_l^|m|(cos θ)  m < 0
//! ```
//!
//! Coefficient (l, m) is stored at index l² + l + m ([`sh_index`]). An
//! [`ShOrder`] of n means bands 0..n−1 and n² coefficients: order 5 is the
//! 25-term basis of Kautz et al. 2004. The first bands, in our axes:
//!
//! | index | (l, m) | Y |
//! |---|---|---|
//! | 0 | (0, 0) | 1/(2√π) ≈ 0.282095 |
//! | 1 | (1, −1) | √(3/4π) z ≈ 0.488603 z |
//! | 2 | (1, 0) | √(3/4π) y |
//! | 3 | (1, 1) | √(3/4π) x |
//! | 4 | (2, −2) | ½√(15/π) x z ≈ 1.092548 x z |
//! | 5 | (2, −1) | ½√(15/π) y z |
//! | 6 | (2, 0) | ¼√(5/π) (3y² − 1) ≈ 0.315392 (3y² − 1) |
//! | 7 | (2, 1) | ½√(15/π) x y |
//! | 8 | (2, 2) | ¼√(15/π) (x² − z²) ≈ 0.546274 (x² − z²) |
//!
//! This is the textbook z-up basis (as in Sloan's "Stupid SH tricks") with the
//! textbook (x, y, z) replaced by our (x, z, y). That swap is a reflection, but
//! it is applied to the *axes of the basis*, not to functions: rotations in our
//! frame stay rotations, and [`ShRotation`] maps them to the basis explicitly.
//!
//! # What is here
//!
//! - evaluation: [`eval_basis`] (allocation-free, no trigonometry; and
//!   [`eval_basis_lanes`], many directions at once in SIMD lanes),
//! - projection: [`project_environment`] (the exact projection of a lat-long
//!   map), [`project_fn`] and [`project_fn_rgb`] (Gauss–Legendre quadrature of
//!   any function, exact for band-limited ones),
//! - rotation: [`ShRotation`] (Ivanic and Ruedenberg's recurrence) and
//!   [`EulerShRotation`] (applied without a matrix, for per-vertex frames),
//! - convolution with zonal kernels: [`Zonal`] (Lambert's clamped cosine and
//!   the normalized Phong lobe, by the Funk–Hecke theorem),
//! - windowing: [`Window`] (Hanning and Lanczos σ-factors against the
//!   ringing of truncated expansions of small bright sources),
//! - [`ShRgb`], an RGB coefficient vector: lighting, evaluated, dotted with a
//!   transfer vector (Kautz et al. eq. 2), rotated and convolved.

mod basis;
mod projection;
mod quadrature;
mod rgb;
mod rotation;
#[cfg(test)]
mod test_util;
mod window;
mod zonal;

use std::fmt;

pub use basis::{eval_basis, eval_basis_lanes};
pub use projection::{project_environment, project_fn, project_fn_rgb};
pub use rgb::ShRgb;
pub use rotation::{CHUNK, Chunk, EulerShRotation, ShRotation};
pub use window::Window;
pub use zonal::Zonal;

/// A validated SH order: the number of bands n, 1 ≤ n ≤ [`ShOrder::MAX`],
/// covering bands l = 0..n−1 and n² coefficients.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ShOrder(u32);

impl ShOrder {
    /// The highest supported order: 16 bands, 256 coefficients. The
    /// recurrences are stable well beyond this; the bound keeps the scratch
    /// buffers of the allocation-free paths on the stack.
    pub const MAX: ShOrder = ShOrder(16);

    /// `None` unless 1 ≤ `order` ≤ 16.
    pub const fn new(order: u32) -> Option<ShOrder> {
        if order >= 1 && order <= Self::MAX.0 {
            Some(ShOrder(order))
        } else {
            None
        }
    }

    /// The order whose coefficient count is `count` (a square n² with
    /// 1 ≤ n ≤ 16), or `None`.
    pub fn from_coeff_count(count: usize) -> Option<ShOrder> {
        let n = count.isqrt();
        if n * n == count {
            ShOrder::new(u32::try_from(n).ok()?)
        } else {
            None
        }
    }

    /// The number of bands n.
    pub const fn get(self) -> u32 {
        self.0
    }

    /// The number of bands n, as an index bound.
    pub const fn bands(self) -> usize {
        self.0 as usize
    }

    /// n², the number of coefficients.
    pub const fn coeff_count(self) -> usize {
        (self.0 * self.0) as usize
    }
}

impl fmt::Display for ShOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "order {} ({} coefficients)", self.0, self.coeff_count())
    }
}

/// The index l² + l + m of coefficient (l, m), −l ≤ m ≤ l.
pub const fn sh_index(l: u32, m: i32) -> usize {
    ((l * l + l) as i64 + m as i64) as usize
}

/// The largest coefficient count of any order: the size of the stack scratch
/// buffers used where an evaluation must not allocate.
const MAX_COEFFS: usize = ShOrder::MAX.coeff_count();

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orders_are_validated() {
        assert_eq!(ShOrder::new(0), None);
        assert_eq!(ShOrder::new(17), None);
        assert_eq!(ShOrder::new(5).unwrap().coeff_count(), 25);
        assert_eq!(ShOrder::MAX.coeff_count(), 256);
        assert_eq!(ShOrder::from_coeff_count(36), ShOrder::new(6));
        assert_eq!(ShOrder::from_coeff_count(35), None);
        assert_eq!(ShOrder::from_coeff_count(0), None);
        assert_eq!(ShOrder::from_coeff_count(17 * 17), None);
    }

    #[test]
    fn index_runs_band_by_band() {
        assert_eq!(sh_index(0, 0), 0);
        assert_eq!(sh_index(1, -1), 1);
        assert_eq!(sh_index(1, 1), 3);
        assert_eq!(sh_index(2, -2), 4);
        assert_eq!(sh_index(4, 4), 24);
    }
}
