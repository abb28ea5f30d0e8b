//! The corners of a frame's clusters by column, for setting up a whole
//! cluster in SIMD registers, and each cluster's bounding box (§3.2,
//! "Hierarchical Culling").

use glam::Vec3;

use super::LANES;
use super::setup::Frame;
use crate::blockers::Layout;

/// A [`Layout`]'s corners as struct of arrays (ax, ay, az, bx, …, cz in
/// world space, by slot), and per cluster the world bounding box of its
/// corners, (centre, half size), computed per frame, so that it holds for
/// rigid, skinned and deformed poses alike. Empty when only listed
/// triangles are read (potentially visible sets), which need neither.
#[derive(Clone, Debug, Default)]
pub(crate) struct Columns {
    corners: [Vec<f32>; 9],
    boxes: Vec<(Vec3, Vec3)>,
}

impl Columns {
    /// The columns and boxes of every cluster of `layout`.
    pub(crate) fn new(layout: &Layout) -> Columns {
        let by_slot = layout.by_slot();
        let corners: [Vec<f32>; 9] =
            std::array::from_fn(|k| by_slot.iter().map(|slot| slot[k]).collect());
        let boxes = (0..by_slot.len() / LANES)
            .map(|cluster| {
                let lanes = cluster * LANES..(cluster + 1) * LANES;
                // `f32::min`/`max` skip the NaN padding.
                let extent = |axis: usize| {
                    (0..3).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), k| {
                        let column = &corners[3 * k + axis][lanes.clone()];
                        (
                            column.iter().copied().fold(lo, f32::min),
                            column.iter().copied().fold(hi, f32::max),
                        )
                    })
                };
                let [(x0, x1), (y0, y1), (z0, z1)] = [0, 1, 2].map(extent);
                let (lo, hi) = (Vec3::new(x0, y0, z0), Vec3::new(x1, y1, z1));
                ((lo + hi) * 0.5, (hi - lo) * 0.5)
            })
            .collect();
        Columns { corners, boxes }
    }

    /// Whether `cluster`'s box lies below the receiver's tangent plane.
    #[inline(always)]
    pub(super) fn below(&self, cluster: usize, frame: &Frame) -> bool {
        let (centre, half) = self.boxes[cluster];
        frame.below(centre, half)
    }

    /// The nine corner columns of `cluster`.
    #[inline(always)]
    pub(super) fn cluster(&self, cluster: usize) -> [&[f32; LANES]; 9] {
        let lanes = cluster * LANES..(cluster + 1) * LANES;
        std::array::from_fn(|k| {
            self.corners[k][lanes.clone()]
                .try_into()
                .expect("columns are whole clusters")
        })
    }
}
