//! Phase 1 of the loop, the paper's "transform": blockers moved into the
//! receiver's frame and culled, [`LANES`] triangles at a time (a cluster, or
//! as many listed triangles) with no per-triangle branch, and the
//! plane-table cells of the survivors' three edge planes.

use glam::{Mat3, Vec3};

use super::LANES;
use crate::blockers::{Candidates, Entry, Layout};
use crate::hierarchy::replaced;
use crate::mask::MaskRow;
use crate::raster::{edge_planes, plane_code, row_code};

/// The receiver's origin and the rows of world-to-tangent, with what the
/// box test needs of them computed once per receiver.
#[derive(Clone, Copy)]
pub(super) struct Frame {
    o: Vec3,
    t: Vec3,
    b: Vec3,
    n: Vec3,
    /// |n| componentwise, and Σ|o|: the box test's reach and rounding scale.
    n_abs: Vec3,
    o_scale: f32,
    /// The receiver's contact reach
    /// ([`TangentFrame::contact`](crate::TangentFrame::contact)).
    contact: f32,
}

impl Frame {
    pub(super) fn new(o: Vec3, to_world: Mat3, contact: f32) -> Frame {
        let n = to_world.z_axis;
        Frame {
            o,
            t: to_world.x_axis,
            b: to_world.y_axis,
            n,
            n_abs: n.abs(),
            o_scale: o.abs().element_sum(),
            contact,
        }
    }

    /// World point (x, y, z) in tangent coordinates: the arithmetic of
    /// [`TangentFrame::to_local`](crate::TangentFrame::to_local), term for
    /// term.
    #[inline(always)]
    pub(super) fn local(&self, x: f32, y: f32, z: f32) -> Vec3 {
        let (t, b, n, o) = (self.t, self.b, self.n, self.o);
        let (dx, dy, dz) = (x - o.x, y - o.y, z - o.z);
        Vec3::new(
            t.x * dx + t.y * dy + t.z * dz,
            b.x * dx + b.y * dy + b.z * dz,
            n.x * dx + n.y * dy + n.z * dz,
        )
    }

    /// Whether the box (centre, half size) lies below the tangent plane with
    /// a margin far above the rounding of [`Frame::local`] (module docs of
    /// [`crate::engine`], "Clusters").
    #[inline(always)]
    pub(super) fn below(&self, centre: Vec3, half: Vec3) -> bool {
        let top = self.n.dot(centre - self.o) + self.n_abs.dot(half);
        let scale = self.o_scale + centre.abs().element_sum() + half.element_sum();
        top < -1e-5 * scale
    }
}

/// Per lane of a setup chunk: whether back faces are culled, whether near
/// chords are dropped (and replaced), and (one bit per lane) whether the
/// receiver skips the triangle outright.
pub(super) struct LaneFlags {
    pub(super) cull: [bool; LANES],
    pub(super) chords: [bool; LANES],
    pub(super) skip: u32,
}

impl LaneFlags {
    #[inline(always)]
    pub(super) fn splat(cull: bool, chords: bool) -> LaneFlags {
        LaneFlags {
            cull: [cull; LANES],
            chords: [chords; LANES],
            skip: 0,
        }
    }
}

/// Makes room for three codes per slot.
pub(super) fn fit(survivors: &mut Vec<u32>, slots: usize) {
    let need = 3 * slots;
    if survivors.len() < need {
        survivors.resize(need, 0);
    }
}

/// Phase 1 on one chunk, given by its nine corner columns: appends the plane
/// codes of its surviving triangles at `survivors[*count..]`, culling back
/// faces and the skipped lanes, and dropping near chords, in the lanes
/// `flags` says. Returns the lanes [`replaced`] (one bit each).
/// Straight-line code over fixed-size arrays: the compiler turns the first
/// loop into SIMD instructions, 16 triangles per pass.
#[inline(always)]
pub(super) fn setup<W: MaskRow>(
    c: [&[f32; LANES]; 9],
    flags: &LaneFlags,
    frame: &Frame,
    resolution: u32,
    survivors: &mut [u32],
    count: &mut usize,
) -> u32 {
    // Each step is a short loop over the lanes with arrays in and out: the
    // shape the vectorizer turns into a few SIMD instructions per step.
    let mut local = [[0.0f32; LANES]; 9];
    for k in 0..3 {
        for l in 0..LANES {
            let p = frame.local(c[3 * k][l], c[3 * k + 1][l], c[3 * k + 2][l]);
            local[3 * k][l] = p.x;
            local[3 * k + 1][l] = p.y;
            local[3 * k + 2][l] = p.z;
        }
    }
    let mut planes = [[0.0f32; LANES]; 9];
    let mut keep = [false; LANES];
    let mut above = [false; LANES];
    let mut behind = [false; LANES];
    for l in 0..LANES {
        let e = edge_planes(lane(&local, l), flags.cull[l], frame.contact);
        for (k, m) in e.normals.iter().enumerate() {
            planes[3 * k][l] = m.x;
            planes[3 * k + 1][l] = m.y;
            planes[3 * k + 2][l] = m.z;
        }
        keep[l] = e.kept & (flags.skip >> l & 1 == 0);
        above[l] = e.above;
        behind[l] = e.behind;
    }
    // The chord test only where a lane asks for it (the receiver's own
    // coarse body): most chunks skip it.
    let mut chords = false;
    for &c in &flags.chords {
        chords |= c;
    }
    let mut gone = 0u32;
    if chords {
        for l in 0..LANES {
            let swap = flags.chords[l]
                & (flags.skip >> l & 1 == 0)
                & replaced(lane(&local, l), above[l], behind[l]);
            gone |= u32::from(swap) << l;
            keep[l] &= !swap;
        }
    }
    // Coherent chunks are often culled whole (a back-facing patch, a patch
    // edge-on): then the plane codes are not needed.
    let mut survived = 0u32;
    for (l, &k) in keep.iter().enumerate() {
        survived |= u32::from(k) << l;
    }
    if survived == 0 {
        return gone;
    }
    let mut codes = [[0u32; LANES]; 3];
    for (e, codes) in codes.iter_mut().enumerate() {
        for (l, code) in codes.iter_mut().enumerate() {
            let m = Vec3::new(planes[3 * e][l], planes[3 * e + 1][l], planes[3 * e + 2][l]);
            *code = row_code::<W>(plane_code(m, resolution));
        }
    }
    // Compaction, survivor by survivor.
    let mut bits = survived;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        survivors[*count..*count + 3].copy_from_slice(&[codes[0][l], codes[1][l], codes[2][l]]);
        *count += 3;
    }
    gone
}

/// Lane `l`'s triangle from nine corner columns.
#[inline(always)]
fn lane(columns: &[[f32; LANES]; 9], l: usize) -> [Vec3; 3] {
    let corner = |k: usize| Vec3::new(columns[k][l], columns[k + 1][l], columns[k + 2][l]);
    [corner(0), corner(3), corner(6)]
}

/// Phase 1 on the listed triangles in `queue`, 16 at a time, read by
/// slot. A near chord the frame replaces (only visible sets list near
/// chords; the hierarchy queues its replacements before) queues what
/// replaces it, so that only the queue's last chunk is partly empty.
#[inline(always)]
pub(super) fn listed<W: MaskRow>(
    candidates: &Candidates,
    queue: &mut Vec<Entry>,
    frame: &Frame,
    resolution: u32,
    survivors: &mut Vec<u32>,
    count: &mut usize,
) {
    let layout = candidates.layout();
    let mut columns = [[0.0f32; LANES]; 9];
    let mut flags = LaneFlags::splat(false, false);
    let mut next = 0;
    while next < queue.len() {
        let end = queue.len().min(next + LANES);
        gather(layout, &queue[next..end], &mut columns, &mut flags);
        fit(survivors, *count / 3 + LANES);
        let c = [0, 1, 2, 3, 4, 5, 6, 7, 8].map(|k| &columns[k]);
        let mut bits = setup::<W>(c, &flags, frame, resolution, survivors, count);
        while bits != 0 {
            let position = next + bits.trailing_zeros() as usize;
            queue.extend_from_slice(candidates.kept(position));
            bits &= bits - 1;
        }
        next = end;
    }
}

/// Reads the triangles at `entries`' slots (at most [`LANES`]) into
/// `columns` and their culling into `flags`; lanes past the end get NaN
/// corners, which every test culls.
#[inline(always)]
fn gather(
    layout: &Layout,
    entries: &[Entry],
    columns: &mut [[f32; LANES]; 9],
    flags: &mut LaneFlags,
) {
    for (l, entry) in entries.iter().enumerate() {
        let corners = layout.corners(entry.slot());
        for k in 0..9 {
            columns[k][l] = corners[k];
        }
        flags.cull[l] = entry.cull();
        flags.chords[l] = entry.chords();
    }
    for l in entries.len()..LANES {
        for column in columns.iter_mut() {
            column[l] = f32::NAN;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Clusters below the horizon are skipped whole: for a receiver on top
    /// of a floor-level sphere looking up, the floor's boxes are all below.
    #[test]
    fn boxes_below_the_tangent_plane_are_found() {
        let frame = Frame::new(
            Vec3::new(0.0, 1.0, 0.0),
            Mat3::from_cols(Vec3::X, Vec3::NEG_Z, Vec3::Y),
            0.0,
        );
        assert!(frame.below(Vec3::ZERO, Vec3::new(5.0, 0.5, 5.0)));
        assert!(!frame.below(Vec3::ZERO, Vec3::new(5.0, 1.0, 5.0)));
        assert!(!frame.below(Vec3::new(0.0, 2.0, 0.0), Vec3::splat(0.1)));
    }
}
