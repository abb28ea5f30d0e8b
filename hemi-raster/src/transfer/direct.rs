//! Direct integration (§3, "integrate the lighting directly"): the
//! environment summed over a mask's visible pixels, without SH.

use glam::Vec3;
use shadow_core::Environment;

use super::glossy::{LobeGrid, PhongLobe};
use crate::mask::{DiskGrid, Mask, MaskRow};
use crate::raster::TangentFrame;

#[cfg(doc)]
use crate::config::Integration;

/// Σ_visible f(row, col, ω_p) · L(ω_p) over the visible pixels, L read with
/// [`Environment::lookup`] (bilinear) at world-space directions, f given
/// the pixel and its tangent-frame direction; pixels where f is zero skip
/// the look-up.
fn direct_sum<W: MaskRow>(
    grid: &DiskGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    environment: &Environment,
    f: impl Fn(usize, usize, Vec3) -> f32,
) -> Vec3 {
    let to_world = frame.to_world();
    grid.visible(mask)
        .pixels()
        .map(|(r, c)| {
            let d = grid.direction(r, c);
            let f = f(r, c, d);
            if f > 0.0 {
                f * environment.lookup(to_world * d)
            } else {
                Vec3::ZERO
            }
        })
        .sum()
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
    direct_sum(grid, mask, frame, environment, |_, _, _| 1.0) * grid.weight()
}

/// The glossy analogue of [`direct_irradiance`]: the specular radiance
/// ∫ L(ω) V(ω) lobe(ω) max(0, n·ω) dω (without ρ_s) by the same quadrature
/// with the lobe's weights, Σ_visible w_p · lobe(ω_p) · L(ω_p), and the same
/// need for a prefiltered environment.
pub fn direct_glossy<W: MaskRow>(
    lobes: &LobeGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    lobe: &PhongLobe,
    environment: &Environment,
) -> Vec3 {
    direct_sum(lobes.grid(), mask, frame, environment, |r, c, d| {
        lobe.eval(d) * lobes.weight(r, c)
    })
}

/// The angular width (radians) of a pixel at the zenith, 2/R: the blur that
/// [`Integration::Direct`] applies to the environment.
pub fn pixel_angle<W: MaskRow>() -> f32 {
    2.0 / W::RESOLUTION as f32
}
