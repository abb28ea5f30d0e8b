//! The integrations against each other and against per-pixel sums.

use std::f32::consts::PI;

use glam::Vec3;
use shadow_core::Environment;
use shadow_core::sh::{ShOrder, ShRgb, Zonal, eval_basis, project_fn_rgb};

use super::*;
use crate::mask::{DiskGrid, Mask, MaskRow};
use crate::raster::TangentFrame;

/// A smooth, non-constant sky: brighter toward +y and toward +x.
fn sky(d: Vec3) -> Vec3 {
    Vec3::new(1.0 + d.y.max(0.0), 0.5 + 0.5 * d.x, 0.8 + 0.3 * d.z * d.y)
}

/// The tables and the turn to world space give, to rounding, the sums
/// they stand for: Σ w_p Y_k over the blocked pixels, and over the lit
/// ones weighted by the lobe, evaluated at world-space directions.
#[test]
fn tables_equal_the_per_pixel_sums_in_world_space() {
    fn check<W: MaskRow>(order: u32) {
        let order = ShOrder::new(order).unwrap();
        let n = order.coeff_count();
        let grid = DiskGrid::<W>::new();
        let basis = TangentBasis::new(&grid, order);
        let lobes = LobeGrid::new(&grid);
        let mut state = 7u64;
        for normal in [Vec3::Y, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8), Vec3::X] {
            let frame = TangentFrame::new(Vec3::ZERO, normal.normalize());
            let to_world = frame.to_world();
            let mut mask = Mask::<W>::EMPTY;
            for r in 0..W::RESOLUTION {
                for c in 0..W::RESOLUTION {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                    if state >> 62 != 0 {
                        mask.set(r, c);
                    }
                }
            }
            let sum = |weight: &dyn Fn(usize, usize, Vec3) -> f32, pixels: &Mask<W>| {
                let mut out = vec![0.0; n];
                let mut y = vec![0.0; n];
                for (r, c) in pixels.and(grid.disk()).pixels() {
                    let d = grid.direction(r, c);
                    eval_basis(order, to_world * d, &mut y);
                    let w = weight(r, c, d);
                    for (o, y) in out.iter_mut().zip(&y) {
                        *o += w * y;
                    }
                }
                out
            };
            let mut want = sum(&|_, _, _| -grid.weight(), &mask);
            let mut exact = vec![0.0; n];
            Zonal::lambert(order).project_along(frame.normal(), &mut exact);
            for (w, e) in want.iter_mut().zip(&exact) {
                *w += e;
            }
            let mut got = vec![0.0; n];
            basis.lambert(&mask, &frame, false, &mut got);
            for (k, (a, b)) in got.iter().zip(&want).enumerate() {
                assert!(
                    (a - b).abs() < 2e-5,
                    "lambert {order} {normal}: {k}: {a} vs {b}"
                );
            }
            let lobe = PhongLobe::new(&frame, Vec3::new(0.2, 0.9, 0.1).normalize(), 8.0);
            let want = sum(
                &|r, c, d| lobe.eval(d) * lobes.weight(r, c),
                &grid.visible(&mask),
            );
            glossy_transfer(&basis, &lobes, &mask, &frame, &lobe, false, &mut got);
            for (k, (a, b)) in got.iter().zip(&want).enumerate() {
                assert!(
                    (a - b).abs() < 2e-5,
                    "glossy {order} {normal}: {k}: {a} vs {b}"
                );
            }
        }
    }
    check::<u16>(3);
    check::<u32>(5);
    check::<u64>(9);
}

/// Half the hemisphere blocked (a plane through the normal): the SH paths
/// and the direct path agree with an exact quadrature of the lighting.
#[test]
fn half_blocked_paths_agree() {
    let grid = DiskGrid::<u64>::new();
    let order = ShOrder::new(8).unwrap();
    let basis = TangentBasis::new(&grid, order);
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
        basis.lambert(&blocked, &frame, blocks, &mut t);
        let e = light.dot(&t);
        let rel = (e - reference).length() / reference.length();
        eprintln!("half blocked, blocks {blocks}: relative error {rel}");
        assert!(rel < 0.002, "{blocks}: {e} vs {reference}");
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
