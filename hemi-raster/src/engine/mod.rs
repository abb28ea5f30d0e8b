//! The throughput engine: how the method runs fast, which the paper leaves
//! to the implementer. Every receiver's blockers go through the arithmetic
//! of the scalar [`Rasterizer::draw`](crate::Rasterizer::draw), bit for
//! bit, but in two phases, so that the first runs a cluster of 16
//! triangles wide in SIMD registers:
//!
//! 1. **Setup** (the paper's Table 2 "transform": moving blockers into the
//!    receiver's frame and culling them), 16 triangles at a time with no
//!    per-triangle branch: the three corners go into the tangent frame, the
//!    triangle is culled below the horizon, through the receiver, as a back
//!    face, as one the receiver skips, or as a near chord of the receiver's
//!    own body (its object, or the touching parts it belongs to), which is
//!    replaced by the fine triangles it stands for
//!    ([`replaced`](crate::hierarchy::replaced)); the three edge-plane
//!    normals are computed and turned into plane-table cells (skipped when
//!    the whole cluster is culled), and the survivors' cells are appended
//!    to a list.
//! 2. **Lookup** (the paper's "rasterization"): per survivor, the three plane
//!    masks are ANDed and ORed into the visibility mask, one whole mask row
//!    per SIMD lane.
//!
//! A frame's triangles of both levels sit in one layout, fine then coarse,
//! so a triangle is known by its slot alone; whole clusters are read from
//! columns, listed triangles (near ones, potentially visible sets, the fine
//! triangles that replace a coarse one) by slot.
//!
//! # Clusters
//! Each cluster's world bounding box is computed per frame, and a receiver
//! skips every cluster whose box lies below its tangent plane (§3.2,
//! hierarchical culling). The test keeps a margin of 10⁻⁵ of the magnitude
//! of the coordinates involved, far above the rounding of the per-triangle
//! test, so that a skipped cluster holds only triangles the per-triangle
//! test would cull too: the masks are identical with and without it.
//!
//! # Instruction sets
//! The loop and the SH integration are written once and compiled for
//! AVX-512, for AVX2 + FMA, and for the baseline of the build target; the
//! [`simd`] module picks the widest the running CPU has (never what the
//! build machine had), so a plain `cargo build --release` is fast
//! everywhere, and all give the same masks.
//!
//! # Profile
//! [`HemiRaster::profile_update`](crate::HemiRaster::profile_update) runs
//! an update on one thread with the two phases timed ([`UpdateProfile`]).

use std::time::Instant;

use crate::blockers::{CLUSTER, Candidates, Entry, Layout};
use crate::mask::{Mask, MaskRow};
use crate::raster::{PlaneLut, TangentFrame};

mod columns;
mod lookup;
mod pipeline;
mod profile;
mod setup;
// The one place that enters `#[target_feature]` code, and the prefetch.
#[allow(unsafe_code)]
pub(crate) mod simd;
#[cfg(test)]
mod tests;

pub(crate) use columns::Columns;
#[cfg(test)]
pub(crate) use pipeline::Pipeline;
pub(crate) use pipeline::{Engine, Lighting, with_pipeline};
pub(crate) use profile::{LoopProfile, UpdateProfile};
use setup::{Frame, LaneFlags, fit, listed, setup};
use simd::{Kernel, SimdToken};

/// Triangles per setup pass, one per SIMD lane: a cluster.
const LANES: usize = CLUSTER;

/// Per-thread buffers of the loop, reused from receiver to receiver: after
/// the first few receivers it allocates nothing.
#[derive(Default)]
pub(crate) struct Scratch {
    /// Three plane-cell codes per surviving triangle.
    survivors: Vec<u32>,
    /// The listed triangles: near ones or a visible set, and the fine
    /// triangles that replace near chords.
    queue: Vec<Entry>,
    /// Time and counts of the two phases, when profiling.
    profile: Option<LoopProfile>,
}

impl Scratch {
    /// Buffers that also time the loop's phases.
    pub(crate) fn profiling() -> Scratch {
        Scratch {
            profile: Some(LoopProfile::default()),
            ..Scratch::default()
        }
    }

    /// What the phases took so far, when profiling.
    pub(crate) fn profile(&self) -> Option<LoopProfile> {
        self.profile
    }
}

/// The visibility mask of the receiver with tangent frame `frame`, whose
/// `candidates` are read from a frame's `columns` (whole clusters) and
/// layout (listed triangles), compiled for `simd`.
pub(crate) fn receiver_mask<W: MaskRow>(
    simd: SimdToken,
    lut: &PlaneLut<W>,
    frame: &TangentFrame,
    candidates: &Candidates,
    columns: &Columns,
    scratch: &mut Scratch,
) -> Mask<W> {
    simd.run(Receiver {
        lut,
        frame,
        candidates,
        columns,
        scratch,
    })
}

/// One receiver's work, for [`SimdToken::run`].
struct Receiver<'a, W: MaskRow> {
    lut: &'a PlaneLut<W>,
    frame: &'a TangentFrame,
    candidates: &'a Candidates<'a>,
    columns: &'a Columns,
    scratch: &'a mut Scratch,
}

impl<W: MaskRow> Kernel for Receiver<'_, W> {
    type Output = Mask<W>;

    #[inline(always)]
    fn run(self) -> Mask<W> {
        let m = self.frame.to_world();
        let frame = Frame::new(self.frame.origin(), m, self.frame.contact());
        let resolution = self.lut.resolution() as u32;
        let columns = self.columns;
        let start = self.scratch.profile.is_some().then(Instant::now);
        let Scratch {
            survivors,
            queue,
            profile,
        } = self.scratch;
        let slots = match *self.candidates {
            Candidates::All(layout) => Layout::slots(layout.fine()),
            Candidates::TwoLevel { layout, .. } => Layout::slots(layout.coarse()),
            Candidates::Listed { .. } => 0,
        };
        // Listed triangles make room for themselves as they come.
        fit(survivors, slots);
        // Plain loops and direct calls only: a closure or an iterator
        // adaptor here would be compiled apart from the `target_feature`
        // function, for the baseline instruction set.
        let mut count = 0;
        queue.clear();
        let listed_count = match *self.candidates {
            Candidates::All(layout) => {
                for g in layout.fine() {
                    for cluster in g.clusters.clone() {
                        if !columns.below(cluster, &frame) {
                            let c = columns.cluster(cluster);
                            let flags = LaneFlags::splat(g.cull, false);
                            setup::<W>(c, &flags, &frame, resolution, survivors, &mut count);
                        }
                    }
                }
                0
            }
            Candidates::TwoLevel {
                layout,
                own,
                near,
                excluded,
                regions,
            } => {
                let first = layout.coarse_base() / LANES;
                let mut next = 0;
                for (o, g) in layout.coarse().iter().enumerate() {
                    for cluster in g.clusters.clone() {
                        // The cluster's excluded lanes (the list is sorted).
                        let base = (cluster - first) * LANES;
                        let mut skip = 0u32;
                        while next < excluded.len() && (excluded[next] as usize) < base + LANES {
                            skip |= 1 << (excluded[next] as usize - base);
                            next += 1;
                        }
                        if !columns.below(cluster, &frame) {
                            let c = columns.cluster(cluster);
                            let mut flags = LaneFlags::splat(g.cull, o == own);
                            flags.skip = skip;
                            let mut bits =
                                setup::<W>(c, &flags, &frame, resolution, survivors, &mut count);
                            while bits != 0 {
                                let slot = base + bits.trailing_zeros() as usize;
                                queue.extend_from_slice(regions.of(slot));
                                bits &= bits - 1;
                            }
                        }
                    }
                }
                // Near triangles and replacements are read by slot; their
                // boxes would not cull them.
                queue.extend_from_slice(near);
                near.len()
            }
            Candidates::Listed { entries, .. } => {
                queue.extend_from_slice(entries);
                entries.len()
            }
        };
        listed::<W>(
            self.candidates,
            queue,
            &frame,
            resolution,
            survivors,
            &mut count,
        );
        if let Some(p) = profile.as_mut() {
            p.replacements += (queue.len() - listed_count) as u64;
        }
        let setup_end = start.map(|_| Instant::now());
        let mut mask = Mask::EMPTY;
        lookup::lookup(self.lut, &survivors[..count], &mut mask);
        if let (Some(p), Some(start), Some(setup_end)) = (profile, start, setup_end) {
            p.transform += setup_end - start;
            p.rasterization += setup_end.elapsed();
            p.survivors += (count / 3) as u64;
        }
        mask
    }
}
