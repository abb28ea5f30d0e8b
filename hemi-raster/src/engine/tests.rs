//! Every SIMD path against the scalar rasterizer and the scalar
//! integration.

use std::sync::Arc;

use glam::Vec3;
use shadow_core::sh::ShOrder;
use shadow_core::{Brdf, Camera, Mesh, Object, Scene};

use super::pipeline::lambert_transfer;
use super::simd::SimdToken;
use super::*;
use crate::blockers::{Blockers, CoarseLevel};
use crate::csr::Csr;
use crate::hierarchy::replaced;
use crate::mask::DiskGrid;
use crate::raster::{Rasterizer, edge_planes};
use crate::test_util::{grid, icosphere};
use crate::transfer::TangentBasis;

const FAR: Vec3 = Vec3::new(40.0, -3.0, 25.0);

/// A bumpy closed sphere over an open floor, with a second small sphere
/// sunk into the floor (interpenetration), far from the origin so that
/// rounding in the frame transform is exercised.
fn scene() -> Scene {
    let bumpy = icosphere(Vec3::new(0.0, 0.7, 0.0), 0.5, 3);
    let positions = bumpy
        .positions()
        .iter()
        .map(|p| {
            let d = *p - Vec3::new(0.0, 0.7, 0.0);
            Vec3::new(0.0, 0.7, 0.0) + d * (1.0 + 0.25 * (9.0 * d.x).sin() * (7.0 * d.z).cos())
        })
        .collect();
    let bumpy = Mesh::new("bumpy", positions, None, bumpy.triangles().to_vec()).unwrap();
    let material = Brdf::lambert(Vec3::splat(0.5)).unwrap();
    let objects = [
        bumpy,
        grid(0.0, 1.5, 12),
        icosphere(Vec3::new(0.8, 0.05, 0.3), 0.2, 1),
    ]
    .into_iter()
    .map(|m| {
        let far = m.positions().iter().map(|&p| p + FAR).collect();
        Object {
            mesh: Arc::new(Mesh::new(m.name(), far, None, m.triangles().to_vec()).unwrap()),
            material,
        }
    })
    .collect();
    let camera = Camera::new(FAR + Vec3::new(0.0, 3.0, 5.0), FAR, Vec3::Y, 0.8, 8, 8).unwrap();
    Scene::still("kernel test", objects, camera).unwrap()
}

/// The scalar reference: every candidate triangle through
/// [`Rasterizer::draw`].
fn reference<W: MaskRow>(
    raster: &Rasterizer<W>,
    frame: &TangentFrame,
    triangles: impl IntoIterator<Item = ([Vec3; 3], bool)>,
) -> Mask<W> {
    let mut mask = Mask::EMPTY;
    for (t, cull) in triangles {
        raster.draw(
            t.map(|p| frame.to_local(p)),
            cull,
            frame.contact(),
            &mut mask,
        );
    }
    mask
}

fn every_path_matches_draw<W: MaskRow>(lut_resolution: usize) {
    let scene = scene();
    let geometry = scene.frame_geometry(0).unwrap();
    let cull = [true, false, true];
    let blockers = Blockers::new(&geometry, &cull).unwrap();
    let raster = Rasterizer::<W>::new(lut_resolution).unwrap();
    let bases = Layout::slot_bases(blockers.objects.iter().map(|(r, _)| r.len()));
    let object_of = |t: usize| {
        blockers
            .objects
            .iter()
            .position(|(r, _)| r.contains(&t))
            .unwrap()
    };
    let entry = |t: usize, chords: bool| {
        let o = object_of(t);
        let slot = bases[o] as usize + t - blockers.objects[o].0.start;
        Entry::new(slot as u32, cull[o], chords)
    };
    // A coarse level: every third triangle of each object, standing for
    // itself and the two after it (its region), by coarse slot.
    let mut coarse_triangles = Vec::new();
    let mut groups = Vec::new();
    let mut regions = Vec::new();
    for (range, cull) in &blockers.objects {
        let start = coarse_triangles.len();
        for t in range.clone().step_by(3) {
            coarse_triangles.push(blockers.triangles[t]);
            regions.push((t..(t + 3).min(range.end)).collect::<Vec<_>>());
        }
        groups.push((start..coarse_triangles.len(), *cull));
        regions.resize(regions.len().next_multiple_of(LANES), Vec::new());
    }
    let region_entries = Csr::from_lists(
        (regions.iter()).map(|r| r.iter().map(|&t| entry(t, false)).collect::<Vec<_>>()),
    );
    let coarse = CoarseLevel {
        triangles: &coarse_triangles,
        groups: groups.clone(),
    };
    let layout = Layout::new(&blockers, Some(&coarse));
    let columns = Columns::new(&layout);
    let world = |t: [u32; 3]| t.map(|i| blockers.position(i as usize));
    let object_of_vertex = |v: usize| {
        let mut first = 0;
        geometry
            .objects
            .iter()
            .position(|o| {
                first += o.vertex_count();
                v < first
            })
            .unwrap()
    };
    let mut scratch = Scratch::default();
    let (mut blocked, mut swapped) = (0, 0);
    for v in (0..blockers.vertex_count()).step_by(7) {
        let frame = blockers.frame(v);
        let truth = reference(
            &raster,
            &frame,
            blockers
                .triangles
                .iter()
                .enumerate()
                .map(|(t, &tri)| (world(tri), cull[object_of(t)])),
        );
        blocked += usize::from(!truth.is_empty());
        // Two levels: the coarse triangles but every seventh coarse slot
        // (excluded), the own object's near chords replaced by their
        // regions, and every fifth triangle as "near".
        let own = object_of_vertex(v);
        let near: Vec<usize> = (0..blockers.triangles.len()).step_by(5).collect();
        let excluded: Vec<u32> = (v as u32 % 7..regions.len() as u32).step_by(7).collect();
        let local = |t: [u32; 3]| world(t).map(|p| frame.to_local(p));
        let mut listed = near.clone();
        let mut coarse_kept = Vec::new();
        let mut slot = 0;
        for (o, (range, cull)) in groups.iter().enumerate() {
            for (k, &t) in coarse_triangles[range.clone()].iter().enumerate() {
                if excluded.binary_search(&((slot + k) as u32)).is_ok() {
                    continue;
                }
                let planes = edge_planes(local(t), *cull, frame.contact());
                if o == own && replaced(local(t), planes.above, planes.behind) {
                    listed.extend(&regions[slot + k]);
                    swapped += 1;
                } else {
                    coarse_kept.push((world(t), *cull));
                }
            }
            slot += range.len().next_multiple_of(LANES);
        }
        let two_truth = reference(
            &raster,
            &frame,
            coarse_kept.into_iter().chain(
                listed
                    .iter()
                    .map(|&t| (world(blockers.triangles[t]), cull[object_of(t)])),
            ),
        );
        let near_slots: Vec<Entry> = near.iter().map(|&t| entry(t, false)).collect();
        let two_level = Candidates::TwoLevel {
            layout: &layout,
            own,
            near: &near_slots,
            excluded: &excluded,
            regions: &region_entries,
        };
        // The same candidates listed by slot, with and without the
        // columns, each near chord with its whole region kept: the listed
        // near chords are replaced as the frame finds them.
        let entries = two_level.entries();
        let kept = Csr::from_lists(entries.iter().map(|&e| two_level.replacements(e)));
        let rows = 0..entries.len();
        let listed = Candidates::Listed {
            layout: &layout,
            entries: &entries,
            kept: Some((&kept, rows.clone())),
        };
        for simd in SimdToken::available() {
            let path = simd.simd();
            let lut = raster.lut();
            let all = Candidates::All(&layout);
            let got = receiver_mask(simd, lut, &frame, &all, &columns, &mut scratch);
            assert_eq!(got, truth, "{path:?}, receiver {v}");
            let got = receiver_mask(simd, lut, &frame, &two_level, &columns, &mut scratch);
            assert_eq!(got, two_truth, "{path:?} two-level, receiver {v}");
            for columns in [&columns, &Columns::default()] {
                let got = receiver_mask(simd, lut, &frame, &listed, columns, &mut scratch);
                assert_eq!(got, two_truth, "{path:?} listed, receiver {v}");
            }
        }
    }
    assert!(blocked > 20, "the scene must shadow: {blocked}");
    assert!(swapped > 20, "near chords must be replaced: {swapped}");
}

#[test]
fn every_path_matches_the_scalar_rasterizer_bit_for_bit() {
    every_path_matches_draw::<u16>(32);
    every_path_matches_draw::<u32>(128);
    every_path_matches_draw::<u64>(64);
}

/// How far a path's SH integration may stray from the portable one's,
/// relative to the largest coefficient. Every path compiles the same float
/// operations in the same order (Rust neither fuses nor reorders them), so
/// the sums agree to the bit; the bound leaves room for a compiler that
/// would vectorize a sum differently.
const TRANSFER_TOLERANCE: f32 = 1e-6;

/// The Lambert transfer of random masks on every path the CPU runs, from
/// every pixel and from blocks, against the portable compilation.
#[test]
fn every_path_integrates_like_the_portable_one() {
    fn check<W: MaskRow>(order: u32) -> f32 {
        let order = ShOrder::new(order).unwrap();
        let n = order.coeff_count();
        let grid = DiskGrid::<W>::new();
        let basis = TangentBasis::new(&grid, order);
        let mut state = 11u64;
        let mut worst = 0.0f32;
        for normal in [Vec3::Y, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8), Vec3::X] {
            let frame = TangentFrame::new(Vec3::ONE, normal.normalize());
            for density in [1u64, 2, 3] {
                let mut mask = Mask::<W>::EMPTY;
                for r in 0..W::RESOLUTION {
                    for c in 0..W::RESOLUTION {
                        state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                        if state >> 62 < density {
                            mask.set(r, c);
                        }
                    }
                }
                for blocks in [false, true] {
                    let mut want = vec![0.0; n];
                    basis.lambert(&mask, &frame, blocks, &mut want);
                    let scale = want.iter().fold(1.0f32, |m, x| m.max(x.abs()));
                    for simd in SimdToken::available() {
                        let mut got = vec![0.0; n];
                        lambert_transfer(simd, &basis, &mask, &frame, blocks, &mut got);
                        let error = (got.iter().zip(&want))
                            .map(|(a, b)| (a - b).abs() / scale)
                            .fold(0.0f32, f32::max);
                        assert!(
                            error <= TRANSFER_TOLERANCE,
                            "{:?}, {normal}, blocks {blocks}: {error}",
                            simd.simd()
                        );
                        worst = worst.max(error);
                    }
                }
            }
        }
        worst
    }
    let worst = [check::<u16>(3), check::<u32>(5), check::<u64>(9)];
    eprintln!("largest difference from the portable path: {worst:?}");
}
