//! Quasi-Monte Carlo points shared by everything that samples directions:
//! the harness's Monte-Carlo reference and the precomputations that trace
//! rays (deferred-shadow's transfer).

use glam::{Vec2, Vec3};

/// Point `i` of the 2-D Sobol' sequence under the digital shift `shift`, in
/// [0, 1)². The first coordinate is the van der Corput radical inverse, the
/// second Sobol's second dimension (Kollig and Keller 2002, "Efficient
/// multidimensional sampling").
#[inline]
pub fn sobol2(i: u32, shift: [u32; 2]) -> Vec2 {
    let x = i.reverse_bits();
    let mut y = 0u32;
    let mut v = 1u32 << 31;
    let mut bits = i;
    while bits != 0 {
        if bits & 1 != 0 {
            y ^= v;
        }
        bits >>= 1;
        v ^= v >> 1;
    }
    // The top 24 bits, so that the f32 value stays below 1.
    let unit = |b: u32| (b >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    Vec2::new(unit(x ^ shift[0]), unit(y ^ shift[1]))
}

/// Malley's method: a uniform disk sample lifted to the hemisphere (z up) has
/// density cos θ / π.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let phi = std::f32::consts::TAU * u.y;
    let (s, c) = phi.sin_cos();
    Vec3::new(r * c, r * s, (1.0 - u.x).max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn cosine_samples_have_mean_cosine_two_thirds() {
        let shift = [0x0bad_cafe, 0x5eed_1234];
        let n = 4096;
        let mean: f32 = (0..n)
            .map(|i| cosine_hemisphere(sobol2(i, shift)).z)
            .sum::<f32>()
            / n as f32;
        // E[cos θ] under p = cos θ/π is 2/3; stratified points get very close.
        assert_relative_eq!(mean, 2.0 / 3.0, epsilon = 1e-4);
    }

    #[test]
    fn sobol_prefixes_are_stratified_in_every_dyadic_box() {
        // A (0,2)-sequence: the first 2^m points put exactly one point in each
        // box of area 2^-m, for every box shape, whatever the digital shift.
        let shift = [0x1234_5678, 0x9abc_def0];
        let m = 6;
        for k in 0..=m {
            let (nx, ny) = (1usize << k, 1usize << (m - k));
            let mut boxes = vec![0; nx * ny];
            for i in 0..(1u32 << m) {
                let p = sobol2(i, shift);
                boxes[(p.x * nx as f32) as usize * ny + (p.y * ny as f32) as usize] += 1;
            }
            assert!(boxes.iter().all(|&c| c == 1), "{nx}×{ny}: {boxes:?}");
        }
    }
}
