//! What one receiver rasterizes of a frame's blockers (§3.2): every
//! triangle, the two levels of the mesh hierarchy, or a potentially visible
//! set. The engine's loop reads them; the visible sets are built from them.

use std::ops::Range;

use super::{Entry, Layout};
use crate::csr::Csr;

/// What one receiver rasterizes, from one frame's [`Layout`].
pub(crate) enum Candidates<'a> {
    /// Every fine triangle of the frame.
    All(&'a Layout),
    /// §3.2's two levels: the coarse triangles of every body (coarse group)
    /// but those the receiver skips (`excluded`, by slot from the coarse
    /// level's first) and the near chords of its own (coarse group `own`),
    /// which the hierarchy's `replaced` swaps for their `regions`; and the near fine
    /// triangles, listed by slot.
    TwoLevel {
        layout: &'a Layout,
        own: usize,
        near: &'a [Entry],
        excluded: &'a [u32],
        regions: &'a Csr<Entry>,
    },
    /// A potentially visible set (§3.2, the `pvs` module): listed triangles
    /// of either level; with two levels, what replaces the listed near
    /// chords: rows `kept.1` of `kept.0`, one for each of the first entries
    /// (the others replace nothing).
    Listed {
        layout: &'a Layout,
        entries: &'a [Entry],
        kept: Option<(&'a Csr<Entry>, Range<usize>)>,
    },
}

impl Candidates<'_> {
    /// How many triangles the receiver considers before any frame is seen
    /// (the paper's Table 1 "Avg. #Tris" per vertex, but for the fine
    /// triangles that replace near chords, which the loop counts per frame).
    pub(crate) fn count(&self) -> usize {
        match self {
            Candidates::All(layout) => layout.fine_triangles(),
            Candidates::TwoLevel {
                layout,
                near,
                excluded,
                ..
            } => layout.coarse_triangles() - excluded.len() + near.len(),
            Candidates::Listed { entries, .. } => entries.len(),
        }
    }

    /// Every candidate that does not depend on the frame: what the
    /// per-receiver loop considers, for building visible sets (not for the
    /// loop itself). With two levels, add the [`Candidates::replacements`]
    /// of the coarse triangles the frame replaces.
    pub(crate) fn entries(&self) -> Vec<Entry> {
        match *self {
            Candidates::All(layout) => (layout.fine().iter())
                .flat_map(|g| Layout::group_entries(g, false))
                .collect(),
            Candidates::TwoLevel {
                layout,
                own,
                near,
                excluded,
                ..
            } => {
                let base = layout.coarse_base();
                (layout.coarse().iter().enumerate())
                    .flat_map(|(o, g)| Layout::group_entries(g, o == own))
                    .filter(|e| excluded.binary_search(&((e.slot() - base) as u32)).is_err())
                    .chain(near.iter().copied())
                    .collect()
            }
            Candidates::Listed { entries, .. } => entries.to_vec(),
        }
    }

    /// The fine triangles that replace candidate `entry` when the frame
    /// replaces it: its region for a coarse triangle of the
    /// receiver's own body, nothing otherwise.
    pub(crate) fn replacements(&self, entry: Entry) -> &[Entry] {
        match *self {
            Candidates::TwoLevel {
                layout, regions, ..
            } if entry.chords() => regions.of(entry.slot() - layout.coarse_base()),
            _ => &[],
        }
    }

    /// What replaces the near chord listed at `position`, when the frame
    /// replaces it (only visible sets list near chords).
    #[inline(always)]
    pub(crate) fn kept(&self, position: usize) -> &[Entry] {
        match self {
            Candidates::Listed {
                kept: Some((rows, range)),
                ..
            } if position < range.len() => rows.of(range.start + position),
            _ => &[],
        }
    }

    /// The frame's layout the candidates are read from.
    #[inline(always)]
    pub(crate) fn layout(&self) -> &Layout {
        match *self {
            Candidates::All(layout)
            | Candidates::TwoLevel { layout, .. }
            | Candidates::Listed { layout, .. } => layout,
        }
    }
}
