//! A frame's blocker triangles of both levels, numbered: each triangle has
//! a *slot*, fine triangles object by object, then coarse ones group by
//! group, each object or group padded to whole clusters of [`CLUSTER`]
//! triangles (§3.2, "Hierarchical Culling": the clusters' boxes are updated
//! per frame and tested against the horizon). Per-receiver lists name
//! triangles by slot ([`Entry`]).

use std::ops::Range;

use glam::Vec3;

use super::Blockers;

/// Triangles per cluster: consecutive in their object's index buffer, which
/// for scanned and authored meshes (and meshoptimizer's simplified ones)
/// keeps them close in space. The engine sets up one cluster per pass, one
/// triangle per SIMD lane.
pub(crate) const CLUSTER: usize = 16;

/// A frame's blocker triangles by slot: every triangle of the frame (the
/// fine level, object by object), then, with the mesh hierarchy, its coarse
/// triangles (group by group), each group padded to whole clusters with NaN
/// triangles, which every test culls. One numbering, so that a triangle of
/// either level is known by its slot alone. Built once per frame.
#[derive(Clone, Debug, Default)]
pub(crate) struct Layout {
    /// The world-space corners of each slot's triangle (ax, ay, az, bx, …,
    /// cz): one bounds check and one or two cache lines per listed triangle.
    by_slot: Vec<[f32; 9]>,
    /// Real (unpadded) fine triangles.
    fine_triangles: usize,
    /// Real coarse triangles.
    coarse_triangles: usize,
    /// Per group, fine (one per object) then coarse: its clusters and
    /// whether its back faces are culled.
    groups: Vec<Group>,
    /// How many of `groups` are fine.
    fine_groups: usize,
}

/// An object's or a body's triangles in a [`Layout`].
#[derive(Clone, Debug)]
pub(crate) struct Group {
    pub(crate) clusters: Range<usize>,
    pub(crate) cull: bool,
}

/// A frame's coarse level: triangles (vertex indices into the frame's
/// [`Blockers`]) and their groups, (triangle range, back-face culling).
pub(crate) struct CoarseLevel<'a> {
    pub(crate) triangles: &'a [[u32; 3]],
    pub(crate) groups: Vec<(Range<usize>, bool)>,
}

impl Layout {
    /// Numbers `blockers`' triangles, object by object, and then those of
    /// `coarse`, group by group.
    pub(crate) fn new(blockers: &Blockers, coarse: Option<&CoarseLevel>) -> Layout {
        let mut out = Layout::default();
        for (range, cull) in &blockers.objects {
            out.push(blockers, &blockers.triangles[range.clone()], *cull);
        }
        out.fine_groups = out.groups.len();
        out.fine_triangles = blockers.triangles.len();
        if let Some(coarse) = coarse {
            for (range, cull) in &coarse.groups {
                out.push(blockers, &coarse.triangles[range.clone()], *cull);
            }
            out.coarse_triangles = coarse.triangles.len();
        }
        out
    }

    /// Appends one group's `triangles`, padded to whole clusters.
    fn push(&mut self, blockers: &Blockers, triangles: &[[u32; 3]], cull: bool) {
        let start = self.by_slot.len();
        let padded = (start + triangles.len()).next_multiple_of(CLUSTER);
        self.by_slot.resize(padded, [f32::NAN; 9]);
        for (slot, t) in (start..).zip(triangles) {
            for (k, &i) in t.iter().enumerate() {
                let p = blockers.position(i as usize);
                self.by_slot[slot][3 * k..3 * k + 3].copy_from_slice(&p.to_array());
            }
        }
        self.groups.push(Group {
            clusters: start / CLUSTER..padded / CLUSTER,
            cull,
        });
    }

    /// Where triangle `t` of object `o` goes when a scene whose objects
    /// have `triangle_counts` is laid out by [`Layout::new`], one object
    /// after another.
    pub(crate) fn slot_bases(triangle_counts: impl IntoIterator<Item = usize>) -> Vec<u32> {
        let mut base = 0;
        triangle_counts
            .into_iter()
            .map(|n| {
                let b = base as u32;
                base += n.next_multiple_of(CLUSTER);
                b
            })
            .collect()
    }

    /// Every slot's corners, padding included.
    pub(crate) fn by_slot(&self) -> &[[f32; 9]] {
        &self.by_slot
    }

    /// The corners of the triangle at `slot`, as [`Layout::by_slot`] holds
    /// them.
    #[inline(always)]
    pub(crate) fn corners(&self, slot: usize) -> &[f32; 9] {
        &self.by_slot[slot]
    }

    /// The world-space corners of the triangle at `slot`.
    pub(crate) fn triangle(&self, slot: usize) -> [Vec3; 3] {
        let c = &self.by_slot[slot];
        [0, 3, 6].map(|k| Vec3::new(c[k], c[k + 1], c[k + 2]))
    }

    /// Real (unpadded) fine triangles.
    pub(crate) fn fine_triangles(&self) -> usize {
        self.fine_triangles
    }

    /// Real coarse triangles.
    pub(crate) fn coarse_triangles(&self) -> usize {
        self.coarse_triangles
    }

    /// The fine groups (one per object).
    pub(crate) fn fine(&self) -> &[Group] {
        &self.groups[..self.fine_groups]
    }

    /// The coarse groups (one per body, or per object used whole).
    pub(crate) fn coarse(&self) -> &[Group] {
        &self.groups[self.fine_groups..]
    }

    /// The slot of the coarse level's first triangle: coarse triangles are
    /// known to the hierarchy by their slot from there.
    pub(crate) fn coarse_base(&self) -> usize {
        Layout::slots(self.fine())
    }

    /// The slots of `groups`, padding included.
    pub(crate) fn slots(groups: &[Group]) -> usize {
        groups.iter().map(|g| g.clusters.len() * CLUSTER).sum()
    }

    /// The entries of `group`'s triangles (padding included, which every
    /// test culls), with near chords culled when `chords`.
    pub(crate) fn group_entries(group: &Group, chords: bool) -> impl Iterator<Item = Entry> + '_ {
        let slots = group.clusters.start * CLUSTER..group.clusters.end * CLUSTER;
        slots.map(move |slot| Entry::new(slot as u32, group.cull, chords))
    }
}

/// A triangle of a per-receiver list: its slot in a frame's [`Layout`],
/// and how it is culled (back faces; near chords of the receiver's own
/// body, which the hierarchy's `replaced` swaps for fine triangles),
/// packed in one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct Entry(u32);

impl Entry {
    const CULL: u32 = 1 << 31;
    const CHORDS: u32 = 1 << 30;

    /// `slot` must be below 2³⁰: a billion triangles, far beyond any frame.
    pub(crate) fn new(slot: u32, cull: bool, chords: bool) -> Entry {
        debug_assert!(slot < Entry::CHORDS, "slot {slot} out of range");
        Entry(slot | u32::from(cull) << 31 | u32::from(chords) << 30)
    }

    #[inline(always)]
    pub(crate) fn slot(self) -> usize {
        (self.0 & !(Entry::CULL | Entry::CHORDS)) as usize
    }

    #[inline(always)]
    pub(crate) fn cull(self) -> bool {
        self.0 & Entry::CULL != 0
    }

    #[inline(always)]
    pub(crate) fn chords(self) -> bool {
        self.0 & Entry::CHORDS != 0
    }
}
