//! Helpers shared by the SH tests: deterministic random coefficients and
//! environments sampled from analytic functions.

use glam::Vec3;

use super::{ShOrder, sh_index};
use crate::Environment;

/// A deterministic pseudo-random sequence in [−1, 1) (tests only need
/// variety, not quality).
pub(super) fn noise(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

/// Random coefficients of `order` with c_00 raised so the function is
/// positive everywhere (|Y_l^m| ≤ √((2l+1)/4π)), as radiance must be.
pub(super) fn positive_band_limited(order: ShOrder, seed: u64) -> Vec<Vec3> {
    let mut rand = noise(seed);
    let mut coeffs: Vec<Vec3> = (0..order.coeff_count())
        .map(|_| Vec3::new(rand(), rand(), rand()))
        .collect();
    let mut bound = 0.0;
    for l in 0..order.get() {
        for m in -(l as i32)..=l as i32 {
            let c = coeffs[sh_index(l, m)].abs().max_element();
            bound += c * ((2 * l + 1) as f32 / (4.0 * std::f32::consts::PI)).sqrt();
        }
    }
    coeffs[0] = Vec3::splat((bound + 0.1) * (4.0 * std::f32::consts::PI).sqrt());
    coeffs
}

/// A `w`×`h` map holding `f` at every texel centre.
pub(super) fn environment_of(
    name: &str,
    w: usize,
    h: usize,
    f: impl Fn(Vec3) -> Vec3,
) -> Environment {
    let env = Environment::new(name, w, h, vec![Vec3::ZERO; w * h]).unwrap();
    let texels = (0..h)
        .flat_map(|r| (0..w).map(move |c| (r, c)))
        .map(|(r, c)| f(env.direction(r, c)))
        .collect();
    Environment::new(name, w, h, texels).unwrap()
}
