//! Property tests of the rasterizer and the transfer.

use std::sync::OnceLock;

use glam::{Quat, Vec3};
use proptest::prelude::*;
use shadow_core::sh::{ShOrder, ShRgb, ShRotation, project_fn_rgb};

use crate::mask::Mask;
use crate::raster::{Rasterizer, TangentFrame};
use crate::transfer::{LobeGrid, PhongLobe, TangentBasis, glossy_transfer};

fn raster() -> &'static Rasterizer<u32> {
    static RASTER: OnceLock<Rasterizer<u32>> = OnceLock::new();
    RASTER.get_or_init(|| Rasterizer::new(128).unwrap())
}

fn point() -> impl Strategy<Value = Vec3> {
    (-1.5f32..1.5, -1.5f32..1.5, -0.5f32..1.5).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn triangle() -> impl Strategy<Value = [Vec3; 3]> {
    [point(), point(), point()]
}

fn rotation() -> impl Strategy<Value = Quat> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("non-zero", |(a, b, c, d)| {
            a * a + b * b + c * c + d * d > 0.1
        })
        .prop_map(|(a, b, c, d)| Quat::from_xyzw(a, b, c, d).normalize())
}

/// Blockers over a receiver at the origin with normal +y (world space).
fn blockers() -> Vec<[Vec3; 3]> {
    vec![
        [
            Vec3::new(-0.5, 0.6, -0.2),
            Vec3::new(0.4, 0.5, -0.3),
            Vec3::new(0.1, 0.7, 0.5),
        ],
        [
            Vec3::new(0.6, 0.2, 0.1),
            Vec3::new(1.2, 0.9, -0.4),
            Vec3::new(0.9, 0.3, 0.8),
        ],
        [
            Vec3::new(-1.0, 0.1, -1.0),
            Vec3::new(-0.8, 0.4, 0.9),
            Vec3::new(-0.3, 0.9, 0.0),
        ],
    ]
}

/// Irradiance at a receiver, through mask and SH transfer (order 5).
fn irradiance(normal: Vec3, tris: &[[Vec3; 3]], light: &ShRgb, blocks: bool) -> Vec3 {
    let raster = raster();
    let frame = TangentFrame::new(Vec3::ZERO, normal);
    let mask = raster.mask(&frame, tris, false);
    let mut t = vec![0.0; light.order().coeff_count()];
    TangentBasis::new(raster.grid(), light.order()).lambert(&mask, &frame, blocks, &mut t);
    light.dot(&t)
}

/// Specular radiance (without ρ_s) toward `view` at a receiver, through
/// mask and glossy transfer (order 5, exponent 20).
fn glossy(normal: Vec3, view: Vec3, tris: &[[Vec3; 3]], light: &ShRgb, blocks: bool) -> Vec3 {
    let raster = raster();
    let frame = TangentFrame::new(Vec3::ZERO, normal);
    let mask = raster.mask(&frame, tris, false);
    let lobe = PhongLobe::new(&frame, view, 20.0);
    let mut t = vec![0.0; light.order().coeff_count()];
    let lobes = LobeGrid::new(raster.grid());
    let basis = TangentBasis::new(raster.grid(), light.order());
    glossy_transfer(&basis, &lobes, &mask, &frame, &lobe, blocks, &mut t);
    light.dot(&t)
}

/// A lighting with detail: brighter up and toward +x, and a spot near the
/// mirror direction of the glossy test's view.
fn lighting(order: ShOrder) -> ShRgb {
    project_fn_rgb(order, 32, |d| {
        let spot = (6.0 * (d.dot(Vec3::new(-0.5, 0.8, -0.3).normalize()) - 1.0)).exp();
        Vec3::new(
            1.0 + d.y.max(0.0) * 2.0,
            0.6 + 0.4 * d.x,
            0.8 + 0.5 * d.z * d.z,
        ) + 3.0 * spot
    })
}

/// The view of the glossy test, at a receiver with normal +y.
fn glossy_view() -> Vec3 {
    Vec3::new(0.5, 0.8, 0.3).normalize()
}

/// The exact specular radiance of [`glossy`] at the unturned setup, with
/// visibility by ray casting against the blockers instead of a mask: a
/// 1024² grid over the disk (cosine-weighted solid angle by area).
fn exact_glossy() -> Vec3 {
    static EXACT: OnceLock<Vec3> = OnceLock::new();
    *EXACT.get_or_init(|| {
        let light = lighting(ShOrder::new(5).unwrap());
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::Y);
        let r = shadow_core::reflect(glossy_view(), Vec3::Y);
        let n = 1024;
        let step = 2.0 / n as f32;
        let hits = |d: Vec3| {
            blockers().iter().any(|&[a, b, c]| {
                // Möller–Trumbore from the origin along d.
                let (e1, e2) = (b - a, c - a);
                let p = d.cross(e2);
                let det = e1.dot(p);
                let s = -a;
                let u = s.dot(p) / det;
                let q = s.cross(e1);
                let v = d.dot(q) / det;
                let t = e2.dot(q) / det;
                u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0
            })
        };
        let mut sum = Vec3::ZERO;
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (
                    -1.0 + (j as f32 + 0.5) * step,
                    -1.0 + (i as f32 + 0.5) * step,
                );
                let rho2 = x * x + y * y;
                if rho2 >= 1.0 {
                    continue;
                }
                let w = frame.to_world() * Vec3::new(x, y, (1.0 - rho2).sqrt());
                let lobe = r.dot(w).max(0.0).powi(20) * 22.0 / std::f32::consts::TAU;
                if lobe > 1e-7 && !hits(w) {
                    sum += lobe * light.eval(w);
                }
            }
        }
        sum * step * step
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Occluder fusion only adds: a mask with one more blocker is a bitwise
    /// superset of the mask without it.
    #[test]
    fn adding_a_blocker_never_shrinks_the_mask(
        tris in prop::collection::vec(triangle(), 1..6),
        extra in triangle(),
        cull in any::<bool>(),
    ) {
        let raster = raster();
        let mut mask = Mask::EMPTY;
        for t in &tris {
            raster.draw(*t, cull, 0.0, &mut mask);
        }
        let before = mask;
        raster.draw(extra, cull, 0.0, &mut mask);
        prop_assert!(mask.contains(&before));
        prop_assert!(raster.grid().disk().contains(&mask));
    }

    /// Turning receiver, blockers and lighting together leaves the exit
    /// radiance unchanged up to the discretization: the tangent frame's twist
    /// about the normal changes, so the pixels sample other directions and the
    /// planes fall in other table cells.
    #[test]
    fn rotating_the_whole_setup_keeps_the_radiance(q in rotation(), blocks in any::<bool>()) {
        let order = ShOrder::new(5).unwrap();
        let light = project_fn_rgb(order, 32, |d| {
            Vec3::new(1.0 + d.y.max(0.0) * 2.0, 0.6 + 0.4 * d.x, 0.8 + 0.5 * d.z * d.z)
        });
        let e0 = irradiance(Vec3::Y, &blockers(), &light, blocks);
        let turned: Vec<[Vec3; 3]> = blockers().iter().map(|t| t.map(|p| q * p)).collect();
        let rotated = light.rotated(&ShRotation::from_quat(order, q).unwrap());
        let e1 = irradiance(q * Vec3::Y, &turned, &rotated, blocks);
        let rel = (e1 - e0).length() / e0.length();
        // The blockers hide 37% of the cosine-weighted hemisphere, some of
        // it near the horizon where pixels are coarse; over 40 fixed
        // rotations the spread was 1.7% (2.0% under uniform light, i.e. in
        // the coverage itself: 1.2% of π, three triangles' quantization).
        prop_assert!(rel < 0.025, "{e0} vs {e1}: {rel}");
    }

    /// The glossy transfer, the view turned with the setup, against the
    /// exact integral with ray-cast visibility: the lobe's axis and the SH
    /// basis are handled in world space consistently (unoccluded, the turn
    /// changes the result by 10⁻⁵), and what remains is the mask's
    /// quantization of the blocker edges. Two thirds of this lobe
    /// (exponent 20) are blocked, and edges crossing it weigh far more
    /// than for the cosine: over 600 rotations the error was 2.3% median,
    /// 5.8% at p90, 12% at most, the same with every pixel classified
    /// exactly by ray casting (so it is the 32×32 pixels, not the table).
    #[test]
    fn turned_glossy_setups_match_the_exact_integral(
        q in rotation(),
        blocks in any::<bool>(),
    ) {
        let order = ShOrder::new(5).unwrap();
        let (light, view) = (lighting(order), glossy_view());
        let rotated = light.rotated(&ShRotation::from_quat(order, q).unwrap());
        let open = glossy(Vec3::Y, view, &[], &light, blocks);
        let turned_open = glossy(q * Vec3::Y, q * view, &[], &rotated, blocks);
        let rel = (turned_open - open).length() / open.length();
        prop_assert!(rel < 1e-4, "unoccluded: {open} vs {turned_open}: {rel}");
        let turned: Vec<[Vec3; 3]> = blockers().iter().map(|t| t.map(|p| q * p)).collect();
        let g = glossy(q * Vec3::Y, q * view, &turned, &rotated, blocks);
        let exact = exact_glossy();
        let rel = (g - exact).length() / exact.length();
        prop_assert!(rel < 0.15, "{g} vs {exact}: {rel}");
    }
}
