//! From a visibility mask to shading (Kautz et al. 2004, §3, eq. 3, and §3.2).
//!
//! For a Lambert surface the transfer vector is
//! T_k = ∫ V(ω) max(0, n·ω) Y_k(ω) dω, and the exit radiance ρ/π Σ_k L_k T_k
//! (eq. 2). Writing V = 1 − B (B the blocked directions),
//!
//! ```text
//! T_k = Λ_l Y_k(n)  −  ∫ B(ω) max(0, n·ω) Y_k(ω) dω,
//! ```
//!
//! the first term being the clamped cosine turned to the normal, exact by the
//! Funk–Hecke theorem ([`Zonal::project_along`]). Only the blocked part is
//! integrated over the mask: a vertex with nothing above it gets the exact
//! unshadowed transfer (the white furnace holds to rounding), and the
//! quadrature error is confined to the blocked directions. In the disk
//! parameterization the cosine is already in the pixel weights (Nusselt),
//! so the blocked integral is Σ_{blocked pixels} w · Y_k(ω_pixel).
//!
//! The basis is evaluated at **world-space** directions (tangent direction
//! times the vertex's frame), so the transfer vector comes out in world space
//! and no per-vertex SH rotation is needed: rotating the vector instead would
//! cost an O(n³) rotation build per vertex ([`shadow_core::sh::ShRotation`]),
//! where the paper's downsampling makes the direct evaluation cheap.
//!
//! - [`Integration::ShBlocks`] (the paper's §3.2, the default): the mask is
//!   downsampled in 4×4 blocks to a grey occlusion level, and each block's
//!   blocked pixels are evaluated at the block's mean direction: 64 blocks at
//!   32×32, one basis evaluation per block that has a blocked pixel.
//! - [`Integration::ShPixels`]: one basis evaluation per blocked pixel.
//! - [`Integration::Direct`] (§3, "integrate the lighting directly"): no SH;
//!   the environment's radiance summed over the visible pixels.

use glam::Vec3;
use shadow_core::Environment;
use shadow_core::sh::{ShOrder, Zonal, eval_basis};

use crate::disk::{BLOCK, DiskGrid};
use crate::mask::{Mask, MaskRow};
use crate::rasterize::TangentFrame;

/// How a mask becomes shading (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integration {
    /// SH transfer from the 4×4-block grey downsample (§3.2).
    #[default]
    ShBlocks,
    /// SH transfer from every pixel.
    ShPixels,
    /// No SH: the environment integrated over the visible pixels directly.
    Direct,
}

/// Stack room for one basis evaluation of any order.
const MAX_COEFFS: usize = ShOrder::MAX.coeff_count();

/// Writes the world-space Lambert transfer vector of a vertex with tangent
/// frame `frame` and visibility `mask` into `out[..order.coeff_count()]`
/// (without ρ/π). `lambert` must be `Zonal::lambert` of `order`; `blocks`
/// selects the 4×4 downsample. Allocation-free.
///
/// # Panics
/// If `out` is shorter than the order's coefficient count.
pub fn sh_transfer<W: MaskRow>(
    grid: &DiskGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    lambert: &Zonal,
    blocks: bool,
    out: &mut [f32],
) {
    let order = lambert.order();
    let n = order.coeff_count();
    let out = &mut out[..n];
    lambert.project_along(frame.normal(), out);
    let to_world = frame.to_world();
    let mut basis = [0.0f32; MAX_COEFFS];
    let mut subtract = |weight: f32, tangent_dir: Vec3| {
        eval_basis(order, to_world * tangent_dir, &mut basis);
        for (o, b) in out.iter_mut().zip(&basis[..n]) {
            *o -= weight * b;
        }
    };
    let blocked = mask.and(grid.disk());
    if blocks {
        let side = grid.blocks();
        for br in 0..side {
            for bc in 0..side {
                let count = blocked.block_count(br, bc);
                if count > 0 {
                    subtract(count as f32 * grid.weight(), grid.block_direction(br, bc));
                }
            }
        }
    } else {
        for (r, c) in blocked.pixels() {
            subtract(grid.weight(), grid.direction(r, c));
        }
    }
}

/// The irradiance ∫ L(ω) V(ω) max(0, n·ω) dω by direct quadrature over the
/// visible pixels: Σ_visible w · L(ω_pixel), L read with
/// [`Environment::lookup`] (bilinear). Pass an environment prefiltered to
/// about the pixel size, or the point samples alias (the paper's reason to
/// prefer SH).
pub fn direct_irradiance<W: MaskRow>(
    grid: &DiskGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    environment: &Environment,
) -> Vec3 {
    let to_world = frame.to_world();
    grid.visible(mask)
        .pixels()
        .map(|(r, c)| environment.lookup(to_world * grid.direction(r, c)))
        .sum::<Vec3>()
        * grid.weight()
}

/// The angular width (radians) of a pixel at the zenith, 2/R: the blur that
/// [`Integration::Direct`] applies to the environment.
pub fn pixel_angle<W: MaskRow>() -> f32 {
    2.0 / W::RESOLUTION as f32
}

const _: () = assert!(BLOCK == 4);

#[cfg(test)]
mod tests {
    use super::*;
    use shadow_core::sh::{ShRgb, project_fn_rgb};
    use std::f32::consts::PI;

    fn order5() -> ShOrder {
        ShOrder::new(5).unwrap()
    }

    /// A smooth, non-constant sky: brighter toward +y and toward +x.
    fn sky(d: Vec3) -> Vec3 {
        Vec3::new(1.0 + d.y.max(0.0), 0.5 + 0.5 * d.x, 0.8 + 0.3 * d.z * d.y)
    }

    #[test]
    fn empty_and_full_masks() {
        let grid = DiskGrid::<u32>::new();
        let lambert = Zonal::lambert(order5());
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::new(0.2, 0.9, -0.3).normalize());
        let mut t = [0.0; 25];
        sh_transfer(&grid, &Mask::EMPTY, &frame, &lambert, true, &mut t);
        let mut exact = [0.0; 25];
        lambert.project_along(frame.normal(), &mut exact);
        assert_eq!(t, exact);
        // Fully blocked: the quadrature of the whole hemisphere cancels the
        // exact term up to the disk quadrature error.
        for blocks in [false, true] {
            sh_transfer(&grid, grid.disk(), &frame, &lambert, blocks, &mut t);
            let worst = t.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(t[0].abs() < 1e-5, "band 0 is exact: {}", t[0]);
            eprintln!("fully blocked, blocks {blocks}: worst |T_k| {worst}");
            assert!(
                worst < if blocks { 0.04 } else { 0.015 },
                "{blocks}: {worst}"
            );
        }
    }

    /// Half the hemisphere blocked (a plane through the normal): the SH paths
    /// and the direct path agree with an exact quadrature of the lighting.
    #[test]
    fn half_blocked_paths_agree() {
        let grid = DiskGrid::<u64>::new();
        let order = ShOrder::new(8).unwrap();
        let lambert = Zonal::lambert(order);
        let light: ShRgb = project_fn_rgb(order, 64, sky);
        let normal = Vec3::new(0.3, 0.8, 0.2).normalize();
        let frame = TangentFrame::new(Vec3::ZERO, normal);
        // Block the tangent half-space x > 0, pixel by pixel.
        let mut blocked = Mask::EMPTY;
        for (r, c) in grid.disk().pixels() {
            if grid.direction(r, c).x > 0.0 {
                blocked.set(r, c);
            }
        }
        let mut t = vec![0.0; order.coeff_count()];
        // Reference: fine quadrature of L·cos over the visible half.
        let to_world = frame.to_world();
        let mut reference = Vec3::ZERO;
        let steps = 600;
        for i in 0..steps {
            for j in 0..steps {
                let x = -1.0 + 2.0 * (i as f32 + 0.5) / steps as f32;
                let y = -1.0 + 2.0 * (j as f32 + 0.5) / steps as f32;
                if x * x + y * y < 1.0 && x <= 0.0 {
                    let d = Vec3::new(x, y, (1.0 - x * x - y * y).sqrt());
                    reference += light.eval(to_world * d) * (2.0 / steps as f32).powi(2);
                }
            }
        }
        for blocks in [false, true] {
            sh_transfer(&grid, &blocked, &frame, &lambert, blocks, &mut t);
            let e = light.dot(&t);
            let rel = (e - reference).length() / reference.length();
            eprintln!("half blocked, blocks {blocks}: relative error {rel}");
            assert!(
                rel < if blocks { 0.004 } else { 0.002 },
                "{blocks}: {e} vs {reference}"
            );
        }
        let env = Environment::new(
            "sky",
            256,
            128,
            (0..128)
                .flat_map(|r| (0..256).map(move |c| (r, c)))
                .map(|(r, c)| {
                    let theta = PI * (r as f32 + 0.5) / 128.0;
                    let phi = 2.0 * PI * (c as f32 + 0.5) / 256.0;
                    light.eval(shadow_core::environment::direction_from_angles(theta, phi))
                })
                .collect(),
        )
        .unwrap();
        let e = direct_irradiance(&grid, &blocked, &frame, &env);
        let rel = (e - reference).length() / reference.length();
        eprintln!("half blocked, direct: relative error {rel}");
        assert!(rel < 0.004, "direct: {e} vs {reference}");
    }
}
