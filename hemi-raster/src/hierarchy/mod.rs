//! The two-level mesh hierarchy of Kautz et al. 2004, §3.2: near a receiver
//! the full-resolution mesh, elsewhere a coarse version of every object.
//!
//! # The coarse mesh
//! Built once per object by `prepare` with meshoptimizer's edge-collapse
//! simplifier. Its index buffer refers to the original vertices, so each
//! frame's coarse triangles are made of that frame's posed positions: the
//! coarse mesh follows rigid motion, skinning and morphs for free. Vertices
//! at the same position (UV or normal seams) are welded to their first copy
//! before simplifying, otherwise the simplifier would keep every seam; the
//! copies move together under any pose that gives equal inputs equal outputs.
//! A simplification that keeps less than [`MIN_AREA_KEPT`](parts::MIN_AREA_KEPT)
//! (90%) of the object's surface area has cut holes or flattened its shape,
//! and is redone with twice the triangles: the far field must block what
//! the object blocks. An object whose simplified triangle count would not
//! be below its own is used whole, and a receiver then sees exactly the
//! triangles of [`crate::Hierarchy::Flat`]: nothing is dropped for it, nor
//! listed.
//!
//! # Bodies
//! Objects that are not used whole, cull alike and touch in the reference
//! pose (a vertex of one within the other's near reach) are parts of one
//! model, a *body* (a character modelled as torso, head and legs, where
//! the paper's Fight was one mesh). Everything below is per body, not per object. Distances are
//! measured in the reference pose, the scene's first frame, the one pose in
//! which all objects share a space.
//!
//! # Near and far
//! A receiver rasterizes, at full resolution, the triangles of its one- or
//! two-ring (found on the welded mesh, so that they continue across seams)
//! and the triangles of its body that come within `near_reach` × their
//! object's mean coarse-triangle radius of it (close in space but maybe far
//! along the surface: the paper's §4.1 "Accuracy of Local Geometry"); and
//! the coarse triangles of every object, but those of its body whose whole
//! region (below) is among its near triangles, which would only cover them
//! again, less exactly. Near and coarse triangles over the same region
//! overlap otherwise, which the OR of the mask absorbs (§3.2).
//!
//! # Coarse triangles too close to the receiver
//! A coarse triangle strays from the fine surface by a fraction of its own
//! size. Seen from farther than its size the error is a fraction of a
//! pixel's angle; seen from inside that distance it is as large as the
//! triangle itself, and a meshopt sliver tens of centimetres long that
//! passes millimetres over a receiver covers most of a hemisphere that the
//! fine surface leaves open. So the per-receiver loop drops, per frame
//! ([`is_near_chord`](near::is_near_chord)), every coarse triangle of the
//! receiver's body
//!
//! - that it sees from behind with its centroid closer than twice its radius
//!   (a chord of a fold, which the fine surface bends around), or
//! - whose *envelope* holds the receiver ([`in_envelope`](near::in_envelope)
//!   with [`ENVELOPE`](near::ENVELOPE) κ = 0.5: within κ·r of its plane and
//!   (1 + κ)·r of its centroid, r its radius), whichever way it faces.
//!
//! Dropping alone leaves a hole where the triangle's far part was. So each
//! fine triangle is given to the coarse triangle closest to its centroid
//! (its *region*; meshopt does not report which vertices collapsed where),
//! and the loop replaces each coarse triangle it drops by its region and
//! that region's fringe (below; [`replaced`]), in the frame it drops it: the
//! replacement follows deformation as the test does, and a coarse triangle
//! is never replaced where it is not dropped.
//!
//! The near lists are computed once, in the reference pose, and kept under
//! deformation: rings are topological; spatial neighbours that a
//! deformation brings close are seen through the coarse mesh, and through
//! the regions that replace it once they are close enough to be dropped.
//!
//! # Cracks between the levels
//! Where the fine triangles of a region replacing a coarse triangle meet
//! the coarse triangles kept around it, the two surfaces do not join: a
//! coarse edge lies off the fine surface by the simplification error, and
//! the mask sees sky through the crack. A lit receiver barely notices; a
//! receiver its body encloses (a fold, a contact, a vertex buried in an
//! interpenetrating part), which the full mesh blocks in every direction,
//! sees nothing else, and its radiance, near zero, becomes a few percent
//! of the sky's. So a region also holds its *fringe*, the fine triangles
//! of other regions that share a vertex with it: they reach under the
//! neighbouring coarse triangles and close the crack (the OR of the mask
//! absorbs the overlap). The same cracks at the edge of the near list
//! subtend less the farther it reaches:
//! [`Hierarchy::WIDE_NEAR_REACH`](crate::Hierarchy::WIDE_NEAR_REACH) radii
//! instead of 2 narrows them further (test
//! `receivers_enclosed_by_their_body_see_no_cracks`; the human's figures in
//! the crate README).

use std::ops::Range;

use rayon::prelude::*;
use shadow_core::{Result, Scene};

use crate::blockers::{Blockers, CLUSTER, Candidates, CoarseLevel, Entry, Layout};
use crate::config::NearRings;
use crate::csr::Csr;

mod near;
mod parts;
mod spatial;
#[cfg(test)]
mod tests;

pub(crate) use near::replaced;
use parts::{Part, bodies};

/// The group of receivers whose object is used whole: none, so that no
/// coarse triangle is dropped for them.
const NO_GROUP: u32 = u32::MAX;

/// The static part of the hierarchy of a scene: coarse meshes and, per
/// receiver, its near triangles. Vertex and triangle indices are global
/// (all objects one after another, as in [`Blockers`]).
#[derive(Clone, Debug)]
pub(crate) struct TwoLevel {
    /// All objects' coarse triangles, over global vertex indices, so that
    /// each frame's posed positions make them; grouped by body.
    coarse_triangles: Vec<[u32; 3]>,
    /// Per object: the range of its coarse triangles.
    coarse_objects: Vec<Range<usize>>,
    /// Per group of the coarse layout (a body, or an object used whole):
    /// the range of its coarse triangles and an object of it, whose
    /// back-face culling the group has.
    groups: Vec<(Range<usize>, usize)>,
    /// Per global vertex: the group whose coarse triangles its envelope and
    /// chord tests drop, or [`NO_GROUP`].
    vertex_group: Vec<u32>,
    /// Per global vertex: its near full-resolution triangles, as entries of
    /// the frame's fine [`Layout`], sorted.
    near: Csr<Entry>,
    /// Per global vertex: the coarse triangles of its body that it skips,
    /// because every fine triangle they stand for is among its near ones;
    /// by their slot in the coarse level (from its first slot), sorted.
    excluded: Csr<u32>,
    /// Per slot of the coarse level: the fine triangles the coarse triangle
    /// there stands for (its region) and the region's fringe, which replace
    /// it for a receiver that drops it as too close (padding slots: none).
    regions: Csr<Entry>,
}

impl TwoLevel {
    /// Simplifies every object to max(triangles / `divisor`,
    /// `min_triangles`) triangles and gathers the per-vertex lists in the
    /// scene's first frame, the reference pose; `cull` says per object
    /// whether its back faces are culled, `replace` whether coarse
    /// triangles too close to a receiver are replaced
    /// ([`Hierarchy::TwoLevel`](crate::Hierarchy::TwoLevel)).
    pub(crate) fn new(
        scene: &Scene,
        cull: &[bool],
        divisor: u32,
        min_triangles: u32,
        rings: NearRings,
        reach: u8,
        replace: bool,
    ) -> Result<TwoLevel> {
        let reference = scene.frame_geometry(0)?;
        let parts = scene
            .objects()
            .iter()
            .zip(&reference.objects)
            .map(|(object, posed)| {
                Part::new(
                    &object.mesh,
                    posed.positions(),
                    divisor,
                    min_triangles,
                    reach,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let bodies = bodies(&parts, cull);
        let slot_bases =
            Layout::slot_bases(scene.objects().iter().map(|o| o.mesh.triangle_count()));
        let vertex_bases: Vec<u32> = parts
            .iter()
            .scan(0, |base, part| {
                let b = *base;
                *base += part.positions.len() as u32;
                Some(b)
            })
            .collect();
        let mut coarse_triangles = Vec::new();
        let mut coarse_objects = vec![0..0; parts.len()];
        let mut groups = Vec::new();
        // Coarse triangles body by body, so that each body is one group.
        let mut object_group = vec![NO_GROUP; parts.len()];
        for o in 0..parts.len() {
            if object_group[o] != NO_GROUP {
                continue;
            }
            let group = groups.len() as u32;
            let start = coarse_triangles.len();
            for q in (o..parts.len()).filter(|&q| bodies[q] == bodies[o]) {
                object_group[q] = group;
                let first = coarse_triangles.len();
                coarse_triangles.extend(
                    parts[q]
                        .coarse_triangles()
                        .iter()
                        .map(|t| t.map(|i| i + vertex_bases[q])),
                );
                coarse_objects[q] = first..coarse_triangles.len();
            }
            groups.push((start..coarse_triangles.len(), o));
        }
        // Where each coarse triangle sits in the coarse level that
        // `Layout::new` lays out: group after group, each padded to whole
        // clusters.
        let mut coarse_slot = vec![0u32; coarse_triangles.len()];
        let mut slots = 0;
        for (range, _) in &groups {
            for (k, t) in range.clone().enumerate() {
                coarse_slot[t] = (slots + k) as u32;
            }
            slots += range.len().next_multiple_of(CLUSTER);
        }
        let mut regions = vec![Vec::new(); slots];
        // Each fine triangle in the region of its owner, with its fringe
        // (padding slots stay empty; objects used whole own nothing).
        for (q, part) in parts.iter().enumerate() {
            for (f, &c) in part.owners.iter().enumerate() {
                let slot = coarse_slot[coarse_objects[q].start + c as usize] as usize;
                let entry = |t: u32| Entry::new(t + slot_bases[q], cull[q], false);
                regions[slot].push(entry(f as u32));
                for &v in &part.triangles[f] {
                    let fringe = part
                        .around(v)
                        .iter()
                        .filter(|&&u| part.owners[u as usize] != c);
                    regions[slot].extend(fringe.map(|&u| entry(u)));
                }
            }
        }
        for region in &mut regions {
            region.sort_unstable();
            region.dedup();
        }
        let mut near = Csr::default();
        let mut excluded = Csr::default();
        let mut vertex_group = Vec::new();
        for (o, part) in parts.iter().enumerate() {
            // Objects used whole list nothing and drop nothing; without
            // replacement nothing is dropped either.
            let (body, group): (Vec<usize>, u32) = match part.coarse {
                Some(_) if !replace => (vec![o], NO_GROUP),
                Some(_) => (
                    (0..parts.len())
                        .filter(|&q| bodies[q] == bodies[o])
                        .collect(),
                    object_group[o],
                ),
                None => (Vec::new(), NO_GROUP),
            };
            let lists: Vec<(Vec<Entry>, Vec<u32>)> = (0..part.positions.len())
                .into_par_iter()
                .map(|v| {
                    let mut list = Vec::new();
                    for t in part.rings(v, rings) {
                        list.push(Entry::new(t + slot_bases[o], cull[o], false));
                    }
                    for &q in &body {
                        for t in parts[q].near(part.positions[v]) {
                            list.push(Entry::new(t + slot_bases[q], cull[q], false));
                        }
                    }
                    list.sort_unstable();
                    list.dedup();
                    // The coarse triangles whose whole region is listed:
                    // among the owners of the listed fine triangles.
                    let mut skip = Vec::new();
                    for e in &list {
                        let slot = e.slot() as u32;
                        let Some(&q) = body.iter().find(|&&q| {
                            (slot_bases[q]..slot_bases[q] + parts[q].triangles.len() as u32)
                                .contains(&slot)
                        }) else {
                            continue;
                        };
                        let owner = parts[q].owners[(slot - slot_bases[q]) as usize];
                        skip.push(coarse_slot[coarse_objects[q].start + owner as usize]);
                    }
                    skip.sort_unstable();
                    skip.dedup();
                    skip.retain(|&s| {
                        let region = &regions[s as usize];
                        replace
                            && !region.is_empty()
                            && region.iter().all(|e| list.binary_search(e).is_ok())
                    });
                    (list, skip)
                })
                .collect();
            for (list, skip) in lists {
                near.push(&list);
                excluded.push(&skip);
                vertex_group.push(group);
            }
        }
        Ok(TwoLevel {
            coarse_triangles,
            coarse_objects,
            groups,
            vertex_group,
            near,
            excluded,
            regions: Csr::from_lists(regions),
        })
    }

    /// Number of coarse triangles of `object`.
    pub(crate) fn coarse_triangle_count(&self, object: usize) -> Option<usize> {
        self.coarse_objects.get(object).map(|r| r.len())
    }

    /// The coarse level of a frame whose blockers are `blockers`, for
    /// [`Layout::new`]: the coarse triangles index the original vertices,
    /// so they follow every pose.
    pub(crate) fn coarse_level(&self, blockers: &Blockers) -> CoarseLevel<'_> {
        CoarseLevel {
            triangles: &self.coarse_triangles,
            groups: (self.groups.iter())
                .map(|(range, o)| (range.clone(), blockers.objects[*o].1))
                .collect(),
        }
    }

    /// What global vertex `v` rasterizes in a frame laid out as `layout`
    /// (with this hierarchy's coarse level): its near triangles at full
    /// resolution and every coarse triangle but those of its body that are
    /// too close ([`is_near_chord`](near::is_near_chord), tested per frame by the
    /// loop). Triangles through `v` itself subtend no solid angle
    /// and are culled by the loop.
    pub(crate) fn candidates<'a>(&'a self, layout: &'a Layout, v: usize) -> Candidates<'a> {
        Candidates::TwoLevel {
            layout,
            // `NO_GROUP` matches no group.
            own: self.vertex_group[v] as usize,
            near: self.near.of(v),
            excluded: self.excluded.of(v),
            regions: &self.regions,
        }
    }
}
