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
//! An object whose target is not below its triangle count is used whole, and
//! a receiver then sees exactly the triangles of [`crate::Hierarchy::Flat`]:
//! nothing is dropped for it, nor listed.
//!
//! # Bodies
//! Objects that are not used whole, cull alike and touch in the reference
//! pose (a vertex of one within the other's near reach) are parts of one
//! model, a *body*: the human of the harness comes as three open parts,
//! Torso (with the arms), Head and Legs, where the paper's Fight was one
//! mesh. Everything below is per body, not per object. Distances are
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
//! ([`crate::rasterize`]'s `is_near_chord`), every coarse triangle of the
//! receiver's body
//!
//! - that it sees from behind with its centroid closer than twice its radius
//!   (a chord of a fold, which the fine surface bends around), or
//! - whose *envelope* holds the receiver ([`in_envelope`] with
//!   [`ENVELOPE`] κ = 0.5: within κ·r of its plane and (1 + κ)·r of its
//!   centroid, r its radius), whichever way it faces.
//!
//! Dropping alone leaves a hole where the triangle's far part was. So each
//! fine triangle is given to the coarse triangle closest to its centroid
//! (its *region*; meshopt does not report which vertices collapsed where),
//! and the loop replaces each coarse triangle it drops by its region
//! ([`crate::rasterize`]'s `replaced`), in the frame it drops it: the
//! replacement follows deformation as the test does, and a coarse triangle
//! is never replaced where it is not dropped.
//!
//! # Measurements
//! `harness accuracy` (transfer error per vertex, the paper's Table 1
//! measure, against the ray-traced reference, and the exit-radiance error),
//! and blockers per vertex (Table 1's "Avg. #Tris"):
//!
//! | scene | lists from the reference pose | replaced per frame | flat |
//! |---|---:|---:|---:|
//! | human, transfer | 1.85% | 1.73% | 1.49% |
//! | human, global transfer | 7.89% | 2.13% | 1.47% |
//! | human, radiance | 6.18% | 2.19% | 1.96% |
//! | human, blockers per vertex | 1,571 | 1,507 | 5,126 |
//! | cloth, transfer | 1.40% | 1.37% | 1.19% |
//! | chess, transfer | 1.68% | 1.68% | 1.75% |
//!
//! Before, a receiver listed the regions of the coarse triangles whose
//! envelope, widened by half, held it in the reference pose (311 fine
//! triangles per vertex on the human), and no others: a coarse triangle
//! that the deformation brought from beyond that margin was dropped with
//! nothing in its place, and the human's folds and the seams of its parts,
//! which the animation closes, were lit where the fine surface encloses
//! them (its global transfer error, dominated by those vertex-frames, was
//! 7.9%). Replaced per frame, the human's dropped coarse triangles bring 302
//! fine triangles per vertex and frame (15.6 regions), 243 of them not
//! already near; 54 coarse triangles per vertex are skipped as already near.
//!
//! # What was tried
//! Before the per-frame replacement, with lists from the reference pose,
//! most of it on the human, measured as the per-vertex transfer difference
//! from flat mode (the same measure as above with flat mode as the
//! reference), 6.76% with the chord rule alone.
//!
//! - Splitting the blame: the own object at full resolution (other parts
//!   coarse) gave 3.10%, the other parts at full resolution 4.26%: both the
//!   receiver's own coarse triangles and those of the touching parts matter.
//! - Other simplifier options (old rule): `Regularize` 6.17%,
//!   `RegularizeLight` 6.18%, `LockBorder` 6.72%, `PreserveFolds` 6.76%; with
//!   the rule above, 2.19%, 1.48%, 1.97% against 1.51%, and none moved the
//!   global error. Slivers are not the simplifier's fault: a strip along a
//!   straight arm is a good approximation until the elbow bends.
//! - The chord rule for front faces too (within 1 or 2 radii), or skipping
//!   the own coarse triangles within 0.2 radii, without substitution: 5.7% to
//!   6.2% of transfer error (measured before the lift and the block
//!   integration, against 7.9%). Adding the other parts' fine triangles to
//!   the near lists alone: 7.6–7.8% then, 5.58% now.
//! - Substituting statically, by region only (every coarse triangle that
//!   owns a near triangle of the receiver, no per-frame test): own object
//!   4.35%; with the touching parts' near triangles and coarse triangles
//!   too, 2.74%; also those within the near reach, 2.02% (1,347 blockers).
//!   Lists rebuilt every frame from that frame's pose (not implementable in
//!   the static lists the loop reads) would give 1.84%: the envelope test
//!   per frame does better than either.
//! - The envelope test for the receiver's own object only (other parts'
//!   near triangles listed): 2.21% (1,462 blockers); per body, as above:
//!   1.51% (1,571). Per body with no margin (envelope 0.5 in both places):
//!   1.99% (1,424); with a margin of 2 (1.0): 1.21% (1,753); κ 0.25 and
//!   0.5: 2.23%. `near_reach` 1 instead of 2: 1.66% (1,490).
//! - The exact closest-point distance instead of the plane-and-sphere
//!   envelope (own object, κ 0.5 listed within 1.0): 2.30% against 2.11%,
//!   and it branches.
//! - Giving a fine triangle to the closest coarse triangle facing its way
//!   rather than to the closest: no difference.
//!
//! Earlier, on the test's bumpy sphere (5,120 → 512 triangles, two-ring
//! only), skipping the coarse triangles that touch the near rings without
//! listing what they stand for took the mean difference of the blocked
//! fraction from flat mode from 0.0047 to 0.026 (0.038 when also skipping
//! those facing the receiver closer than the rings reach): that hole is what
//! the regions fill. On the open wavy cloth of the
//! `frame_timing` example (rings only), keeping the chords over the valleys
//! darkened the mean radiance from 0.651 (flat) to 0.405; the chord test
//! was first run once in the rest pose, which on the deforming `cloth` left
//! chords over the folds that formed later (18% against 3.8% flat).
//!
//! The near lists are computed once, in the reference pose, and kept under
//! deformation: rings are topological; spatial neighbours that a
//! deformation brings close are seen through the coarse mesh, and through
//! the regions that replace it once they are close enough to be dropped.

use std::collections::HashMap;
use std::ops::Range;

use glam::Vec3;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use rayon::prelude::*;
use shadow_core::{Adjacency, Error, Mesh, Result, Scene};

use crate::config::NearRings;
use crate::csr::Csr;
use crate::kernel::{Candidates, CoarseLevel, Corners, Entry, LANES};
use crate::rasterize::Blockers;

/// κ of the envelope test that drops a coarse triangle for a receiver too
/// close to it, per frame (module docs, "Coarse triangles too close to the
/// receiver").
pub(crate) const ENVELOPE: f32 = 0.5;

/// The group of receivers whose object is used whole: none, so that no
/// coarse triangle is dropped for them.
const NO_GROUP: u32 = u32::MAX;

/// Whether the receiver, at the origin, lies inside the envelope of triangle
/// (a, b, c): within `envelope` × r of its plane and within
/// (1 + `envelope`) × r of its centroid, r being the distance from the
/// centroid to the farthest corner. Branch-free; false for degenerate and
/// NaN triangles.
#[inline(always)]
pub(crate) fn in_envelope([a, b, c]: [Vec3; 3], envelope: f32) -> bool {
    let centroid = (a + b + c) * (1.0 / 3.0);
    let radius2 = (a - centroid)
        .length_squared()
        .max((b - centroid).length_squared())
        .max((c - centroid).length_squared());
    // |n·a| is the receiver's height over the plane times |n|.
    let n = (b - a).cross(c - a);
    let height = n.dot(a);
    let reach = 1.0 + envelope;
    (height * height < envelope * envelope * radius2 * n.length_squared())
        & (centroid.length_squared() < reach * reach * radius2)
}

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
    /// the frame's fine [`Corners`], sorted.
    near: Csr<Entry>,
    /// Per global vertex: the coarse triangles of its body that it skips,
    /// because every fine triangle they stand for is among its near ones;
    /// by their slot in the coarse level (from its first slot), sorted.
    excluded: Csr<u32>,
    /// Per slot of the coarse level: the fine triangles the coarse triangle
    /// there stands for (its region), which replace it for a receiver that
    /// drops it as too close (padding slots: none).
    regions: Csr<Entry>,
}

impl TwoLevel {
    /// Simplifies every object to max(triangles / `divisor`,
    /// `min_triangles`) triangles and gathers the per-vertex lists in the
    /// scene's first frame, the reference pose; `cull` says per object
    /// whether its back faces are culled.
    pub(crate) fn new(
        scene: &Scene,
        cull: &[bool],
        divisor: u32,
        min_triangles: u32,
        rings: NearRings,
        reach: u8,
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
            Corners::slot_bases(scene.objects().iter().map(|o| o.mesh.triangle_count()));
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
        // `Corners::new` lays out: group after group, each padded to whole
        // chunks.
        let mut coarse_slot = vec![0u32; coarse_triangles.len()];
        let mut slots = 0;
        for (range, _) in &groups {
            for (k, t) in range.clone().enumerate() {
                coarse_slot[t] = (slots + k) as u32;
            }
            slots += range.len().next_multiple_of(LANES);
        }
        // Each fine triangle in the region of its owner (padding slots stay
        // empty; objects used whole own nothing).
        let mut regions = vec![Vec::new(); slots];
        for (q, part) in parts.iter().enumerate() {
            for (f, &c) in part.owners.iter().enumerate() {
                let slot = coarse_slot[coarse_objects[q].start + c as usize] as usize;
                regions[slot].push(Entry::new(f as u32 + slot_bases[q], cull[q], false));
            }
        }
        let mut near = Csr::default();
        let mut excluded = Csr::default();
        let mut vertex_group = Vec::new();
        for (o, part) in parts.iter().enumerate() {
            // Objects used whole list nothing and drop nothing.
            let (body, group): (Vec<usize>, u32) = match part.coarse {
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
                        !region.is_empty() && region.iter().all(|e| list.binary_search(e).is_ok())
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
    /// [`Corners::new`]: the coarse triangles index the original vertices,
    /// so they follow every pose.
    pub(crate) fn coarse_level(&self, blockers: &Blockers) -> CoarseLevel<'_> {
        CoarseLevel {
            triangles: &self.coarse_triangles,
            groups: (self.groups.iter())
                .map(|(range, o)| (range.clone(), blockers.objects[*o].1))
                .collect(),
        }
    }

    /// What global vertex `v` rasterizes in a frame laid out as `corners`
    /// (with this hierarchy's coarse level): its near triangles at full
    /// resolution and every coarse triangle but those of its body that are
    /// too close ([`crate::rasterize`]'s `is_near_chord`, tested per frame
    /// by the loop). Triangles through `v` itself subtend no solid angle
    /// and are culled by the loop.
    pub(crate) fn candidates<'a>(&'a self, corners: &'a Corners, v: usize) -> Candidates<'a> {
        Candidates::TwoLevel {
            corners,
            // `NO_GROUP` matches no group.
            own: self.vertex_group[v] as usize,
            near: self.near.of(v),
            excluded: self.excluded.of(v),
            regions: &self.regions,
        }
    }
}

/// Per object, the representative of its body: objects that are not used
/// whole, cull alike and touch in the reference pose (a vertex of one lies
/// within the other's near reach) are parts of one model, as the human's
/// torso, head and legs are; each object used whole is a body of its own.
fn bodies(parts: &[Part], cull: &[bool]) -> Vec<usize> {
    let mut root: Vec<usize> = (0..parts.len()).collect();
    fn find(root: &mut [usize], mut i: usize) -> usize {
        while root[i] != i {
            root[i] = root[root[i]];
            i = root[i];
        }
        i
    }
    for o in 0..parts.len() {
        for q in o + 1..parts.len() {
            let joinable =
                parts[o].coarse.is_some() && parts[q].coarse.is_some() && cull[o] == cull[q];
            if joinable && (parts[o].touches(&parts[q]) || parts[q].touches(&parts[o])) {
                let (a, b) = (find(&mut root, o), find(&mut root, q));
                root[a.max(b)] = a.min(b);
            }
        }
    }
    (0..parts.len()).map(|o| find(&mut root, o)).collect()
}

/// One object's share of the hierarchy, in its own indices, measured in
/// the reference pose.
struct Part<'a> {
    /// Its vertices in the reference pose.
    positions: &'a [Vec3],
    /// Its triangles, for the objects used whole.
    triangles: &'a [[u32; 3]],
    /// The coarse mesh over the (welded) vertices; `None` when the object is
    /// used whole.
    coarse: Option<Vec<[u32; 3]>>,
    /// The welded mesh's adjacency, for the rings; vertex v is welded to
    /// `weld[v]`.
    adjacency: Option<(Vec<u32>, Adjacency)>,
    /// The fine triangles, for spatial queries, and the distance within
    /// which they are near: `near_reach` × the mean coarse radius.
    fine: Sorted,
    spatial: f32,
    /// Per fine triangle: the coarse triangle closest to its centroid, which
    /// stands for it (its *region* is the fine triangles it owns); empty
    /// when the object is used whole.
    owners: Vec<u32>,
}

impl<'a> Part<'a> {
    fn new(
        mesh: &'a Mesh,
        positions: &'a [Vec3],
        divisor: u32,
        min_triangles: u32,
        reach: u8,
    ) -> Result<Part<'a>> {
        let triangles = mesh.triangles();
        let whole = Part {
            positions,
            triangles,
            coarse: None,
            adjacency: None,
            fine: Sorted::default(),
            spatial: 0.0,
            owners: Vec::new(),
        };
        let target = (triangles.len() / divisor as usize).max(min_triangles as usize);
        if target >= triangles.len() {
            return Ok(whole);
        }
        // Weld copies of a rest position to the first one.
        let rest = mesh.positions();
        let mut first = HashMap::new();
        let weld: Vec<u32> = rest
            .iter()
            .enumerate()
            .map(|(i, p)| {
                *first
                    .entry(p.to_array().map(f32::to_bits))
                    .or_insert(i as u32)
            })
            .collect();
        let welded: Vec<[u32; 3]> = triangles
            .iter()
            .map(|t| t.map(|i| weld[i as usize]))
            .collect();
        let floats: Vec<f32> = rest.iter().flat_map(|p| p.to_array()).collect();
        let adapter =
            VertexDataAdapter::new(meshopt::typed_to_bytes(&floats), 12, 0).map_err(|e| {
                Error::InvalidMesh {
                    name: mesh.name().into(),
                    what: format!("meshopt refused the positions: {e}"),
                }
            })?;
        let indices = meshopt::simplify(
            welded.as_flattened(),
            &adapter,
            3 * target,
            // Relative to the mesh's extent: let the triangle target decide.
            1.0,
            SimplifyOptions::None,
            None,
        );
        // In space-filling-curve order, so that each run of 16 (a cluster of
        // the per-receiver loop, culled whole below the horizon) is compact:
        // on the human, 6% fewer clusters reach the per-triangle tests than
        // in the simplifier's order.
        let indices = meshopt::spatial_sort_triangles(&indices, &adapter);
        let coarse: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if coarse.is_empty() || coarse.len() >= triangles.len() {
            return Ok(whole);
        }
        let adjacency = Adjacency::new(mesh.vertex_count(), &welded);
        let fine = Sorted::new(positions, triangles);
        let coarse_sorted = Sorted::new(positions, &coarse);
        let mean_radius = coarse_sorted.mean_radius();
        // Each fine triangle to the coarse triangle closest to its centroid.
        let owners: Vec<u32> = triangles
            .par_iter()
            .map(|t| {
                let (centre, _) = bounding_sphere(t.map(|i| positions[i as usize]));
                coarse_sorted.nearest(centre, mean_radius)
            })
            .collect();
        Ok(Part {
            coarse: Some(coarse),
            adjacency: Some((weld, adjacency)),
            fine,
            spatial: f32::from(reach) * mean_radius,
            owners,
            ..whole
        })
    }

    /// The coarse triangles (all of them for an object used whole).
    fn coarse_triangles(&self) -> &[[u32; 3]] {
        self.coarse.as_deref().unwrap_or(self.triangles)
    }

    /// The triangles of vertex `v`'s one- or two-ring, found on the welded
    /// mesh so that they continue across seams.
    fn rings(&self, v: usize, rings: NearRings) -> Vec<u32> {
        let Some((weld, adjacency)) = &self.adjacency else {
            return Vec::new();
        };
        let r = weld[v] as usize;
        let mut near = adjacency.triangles_of(r).to_vec();
        if rings == NearRings::Two {
            for &u in adjacency.one_ring(r) {
                near.extend_from_slice(adjacency.triangles_of(u as usize));
            }
        }
        near
    }

    /// The fine triangles of this object within the spatial reach of a
    /// receiver at `p` (reference pose).
    fn near(&self, p: Vec3) -> Vec<u32> {
        if self.spatial > 0.0 {
            self.fine.within(p, self.spatial).collect()
        } else {
            Vec::new()
        }
    }

    /// Whether a vertex of this object lies within `other`'s spatial reach
    /// of one of its triangles.
    fn touches(&self, other: &Part) -> bool {
        other.spatial > 0.0
            && self
                .positions
                .par_iter()
                .any(|&p| other.fine.within(p, other.spatial).next().is_some())
    }
}

/// Triangles sorted by the x of their centroid, so that those within some
/// distance of a point lie in a window found by bisection.
#[derive(Default)]
struct Sorted {
    items: Vec<Item>,
    max_radius: f32,
}

struct Item {
    index: u32,
    corners: [Vec3; 3],
    centre: Vec3,
    radius: f32,
}

impl Sorted {
    fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Sorted {
        let mut items: Vec<Item> = triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let corners = tri.map(|i| positions[i as usize]);
                let (centre, radius) = bounding_sphere(corners);
                Item {
                    index: t as u32,
                    corners,
                    centre,
                    radius,
                }
            })
            .collect();
        items.sort_unstable_by(|x, y| x.centre.x.total_cmp(&y.centre.x));
        let max_radius = items.iter().map(|i| i.radius).fold(0.0, f32::max);
        Sorted { items, max_radius }
    }

    fn mean_radius(&self) -> f32 {
        self.items.iter().map(|i| i.radius).sum::<f32>() / self.items.len() as f32
    }

    /// The triangles whose centroid's x is within `reach` + the largest
    /// radius of `p`'s: among them, all those within `reach` of `p`.
    fn window(&self, p: Vec3, reach: f32) -> &[Item] {
        let margin = reach + self.max_radius;
        let from = self.items.partition_point(|i| i.centre.x < p.x - margin);
        let to = self.items.partition_point(|i| i.centre.x <= p.x + margin);
        &self.items[from..to]
    }

    /// The triangles within `reach` of `p`.
    fn within(&self, p: Vec3, reach: f32) -> impl Iterator<Item = u32> + '_ {
        self.window(p, reach)
            .iter()
            .filter(move |i| {
                let [a, b, c] = i.corners;
                p.distance(i.centre) - i.radius < reach
                    && closest_point(p, a, b, c).distance(p) < reach
            })
            .map(|i| i.index)
    }

    /// The triangle closest to `p`, searched within `reach`, then twice as
    /// far, and so on.
    fn nearest(&self, p: Vec3, reach: f32) -> u32 {
        let mut reach = reach.max(f32::MIN_POSITIVE);
        loop {
            let (distance, index) = self
                .window(p, reach)
                .iter()
                .map(|i| {
                    let [a, b, c] = i.corners;
                    (closest_point(p, a, b, c).distance(p), i.index)
                })
                .fold(
                    (f32::INFINITY, 0),
                    |best, x| if x.0 < best.0 { x } else { best },
                );
            // The window holds every triangle within `reach`; the whole list
            // once `reach` exceeds its span.
            if distance <= reach || self.window(p, reach).len() == self.items.len() {
                return index;
            }
            reach *= 2.0;
        }
    }
}

/// A sphere around a triangle: its centroid and the distance to the farthest
/// corner.
fn bounding_sphere(corners: [Vec3; 3]) -> (Vec3, f32) {
    let centre = (corners[0] + corners[1] + corners[2]) / 3.0;
    let radius = corners
        .iter()
        .map(|p| p.distance(centre))
        .fold(0.0, f32::max);
    (centre, radius)
}

/// The point of triangle (a, b, c) closest to `p` (Ericson, "Real-Time
/// Collision Detection", §5.1.5).
fn closest_point(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, Hierarchy};
    use crate::method::HemiRaster;
    use crate::test_util::{grid, icosphere, projected_solid_angle};
    use glam::Affine3A;
    use shadow_core::{Brdf, Camera, Frame, Object, Pose, ShadowMethod};
    use std::f32::consts::PI;
    use std::num::NonZeroU32;
    use std::sync::Arc;

    fn object(mesh: Mesh) -> Object {
        Object {
            mesh: Arc::new(mesh),
            material: Brdf::lambert(Vec3::splat(0.5)).unwrap(),
        }
    }

    fn camera() -> Camera {
        Camera::new(Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 32, 24).unwrap()
    }

    fn flat() -> Config {
        Config {
            hierarchy: Hierarchy::Flat,
            ..Config::default()
        }
    }

    fn two_level(near: NearRings, near_reach: u8) -> Config {
        Config {
            hierarchy: Hierarchy::TwoLevel {
                coarse_divisor: NonZeroU32::new(10).unwrap(),
                min_coarse_triangles: 100,
                near,
                near_reach,
            },
            ..Config::default()
        }
    }

    /// Blocked fractions of every vertex of frame `f`.
    fn blocked(config: Config, scene: &Scene, f: usize) -> (HemiRaster, Vec<f32>) {
        let mut method = HemiRaster::new(config);
        method.prepare(scene).unwrap();
        method
            .update(&scene.frame_geometry(f).unwrap(), scene.camera())
            .unwrap();
        let mut out = Vec::new();
        for (o, object) in scene.objects().iter().enumerate() {
            for v in 0..object.mesh.vertex_count() {
                out.push(method.blocked_fraction(o, v).unwrap());
            }
        }
        (method, out)
    }

    /// A unit sphere with radial bumps, `subdivisions` times subdivided:
    /// closed, with concave and convex regions.
    fn bumpy_sphere(subdivisions: u32) -> Mesh {
        let sphere = icosphere(Vec3::ZERO, 1.0, subdivisions);
        let positions = sphere
            .positions()
            .iter()
            .map(|p| {
                let n = p.normalize();
                n * (1.0 + 0.3 * (6.0 * n.x).sin() * (5.0 * n.y).cos() * (4.0 * n.z + 1.0).sin())
            })
            .collect();
        Mesh::new("bumpy", positions, None, sphere.triangles().to_vec()).unwrap()
    }

    /// Objects below the coarse target are used whole: the masks, hence the
    /// transfer vectors, are those of flat mode bit for bit.
    #[test]
    fn small_meshes_match_flat_mode_exactly() {
        let scene = Scene::still(
            "sphere over floor",
            vec![
                object(icosphere(Vec3::new(0.0, 0.6, 0.0), 0.4, 1)),
                object(grid(0.0, 1.0, 6)),
            ],
            camera(),
        )
        .unwrap();
        let whole = Config {
            hierarchy: Hierarchy::default().with_min_coarse_triangles(100),
            ..Config::default()
        };
        let (h, hb) = blocked(whole, &scene, 0);
        let (f, fb) = blocked(flat(), &scene, 0);
        assert_eq!(h.coarse_triangle_count(0), Some(80));
        assert_eq!(h.coarse_triangle_count(1), Some(72));
        assert_eq!(f.coarse_triangle_count(0), None);
        assert_eq!(hb, fb);
        assert!(hb.iter().any(|&b| b > 0.1));
        for v in 0..scene.objects()[1].mesh.vertex_count() {
            assert_eq!(h.transfer(1, v), f.transfer(1, v));
        }
    }

    /// On a closed bumpy sphere of 5,120 triangles simplified to 512, the
    /// self-shadowing stays close to flat mode's, with one ring or two, with
    /// or without spatial neighbours. Measured: mean |difference| of the
    /// blocked fraction 0.0013 (one ring), 0.0013 (two), 0.0011 (two and
    /// `near_reach` 2), worst vertex 0.022, 0.022, 0.023, against a
    /// flat-mode mean of 0.074; with the chord test alone (no envelope, no
    /// regions) 0.0062, 0.0040, 0.0029 and worst 0.14 to 0.15.
    #[test]
    fn bumpy_sphere_stays_close_to_flat_mode() {
        let scene = Scene::still("bumpy", vec![object(bumpy_sphere(4))], camera()).unwrap();
        let (_, fb) = blocked(flat(), &scene, 0);
        let n = fb.len() as f32;
        let flat_mean = fb.iter().sum::<f32>() / n;
        for (near, reach) in [
            (NearRings::One, 0),
            (NearRings::Two, 0),
            (NearRings::Two, 2),
        ] {
            let (h, hb) = blocked(two_level(near, reach), &scene, 0);
            assert_eq!(h.coarse_triangle_count(0), Some(512));
            let mean = hb.iter().sum::<f32>() / n;
            let mean_abs = fb.iter().zip(&hb).map(|(a, b)| (a - b).abs()).sum::<f32>() / n;
            let max_abs = fb
                .iter()
                .zip(&hb)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            eprintln!(
                "{near:?} reach {reach}: mean blocked {mean:.4} vs flat {flat_mean:.4}, mean |diff| {mean_abs:.4}, max {max_abs:.4}"
            );
            assert!(flat_mean > 0.02, "the bumps must shadow: {flat_mean}");
            assert!((mean - flat_mean).abs() < 0.01, "{mean} vs {flat_mean}");
            assert!(mean_abs < 0.003, "{mean_abs}");
            assert!(max_abs < 0.06, "{max_abs}");
        }
    }

    /// An open wavy sheet: no back-face culling hides the coarse chords over
    /// its valleys, the envelope and chord tests must. Measured: mean
    /// blocked 0.1783 against 0.1781 flat, mean |difference| 0.0021 (chord
    /// test alone: 0.1855 and 0.0085; without either test, before the
    /// receivers were lifted, 0.48 and 0.31).
    #[test]
    fn open_wavy_sheet_stays_close_to_flat_mode() {
        let flat_sheet = grid(0.0, 0.5, 28);
        let positions = flat_sheet
            .positions()
            .iter()
            .map(|p| {
                let y = 0.06 * (p.x * 19.0).sin() * (p.z * 7.0).cos() + 0.04 * (p.z * 23.0).sin();
                Vec3::new(p.x, y, p.z)
            })
            .collect();
        let sheet = Mesh::new("wavy", positions, None, flat_sheet.triangles().to_vec()).unwrap();
        let scene = Scene::still("wavy", vec![object(sheet)], camera()).unwrap();
        let (_, fb) = blocked(flat(), &scene, 0);
        let (h, hb) = blocked(two_level(NearRings::Two, 2), &scene, 0);
        assert_eq!(h.coarse_triangle_count(0), Some(156));
        let n = fb.len() as f32;
        let (flat_mean, mean) = (fb.iter().sum::<f32>() / n, hb.iter().sum::<f32>() / n);
        let mean_abs = fb.iter().zip(&hb).map(|(a, b)| (a - b).abs()).sum::<f32>() / n;
        eprintln!(
            "wavy sheet: mean blocked {mean:.4} vs flat {flat_mean:.4}, mean |diff| {mean_abs:.4}"
        );
        assert!(flat_mean > 0.05, "the waves must shadow: {flat_mean}");
        assert!((mean - flat_mean).abs() < 0.02, "{mean} vs {flat_mean}");
        assert!(mean_abs < 0.005, "{mean_abs}");
    }

    /// The coarse mesh indexes the original vertices, so it follows a
    /// deformation: a dense sheet over a small floor, shrunk by a
    /// `Pose::Deformed`, shadows the floor's centre by its form factor in
    /// both frames.
    #[test]
    fn coarse_mesh_follows_deformed_poses() {
        let sheet = grid(0.4, 0.6, 24);
        let shrunk: Arc<[Vec3]> = sheet
            .positions()
            .iter()
            .map(|p| Vec3::new(0.2 * p.x, p.y, 0.2 * p.z))
            .collect();
        let frames = vec![
            Frame {
                time: 0.0,
                poses: vec![Pose::Rigid(Affine3A::IDENTITY); 2],
            },
            Frame {
                time: 1.0,
                poses: vec![
                    Pose::Rigid(Affine3A::IDENTITY),
                    Pose::Deformed {
                        positions: shrunk,
                        normals: None,
                    },
                ],
            },
        ];
        let scene = Scene::new(
            "sheet over floor",
            vec![object(grid(0.0, 1.0, 4)), object(sheet)],
            frames,
            camera(),
        )
        .unwrap();
        for (f, half) in [(0, 0.6), (1, 0.12)] {
            let (h, hb) = blocked(two_level(NearRings::Two, 2), &scene, f);
            // 1,152 triangles to about 115.
            let coarse = h.coarse_triangle_count(1).unwrap();
            assert!((100..=115).contains(&coarse), "{coarse}");
            // The sheet in the tangent frame of the floor's centre (vertex 12).
            let square = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .map(|(x, y)| Vec3::new(half * x, half * y, 0.4));
            let form_factor = projected_solid_angle(&square) / PI;
            assert!(
                (hb[12] - form_factor).abs() < 0.02,
                "frame {f}: {} vs {form_factor}",
                hb[12]
            );
        }
    }

    /// An open tube along x (radius 0.1, 2,048 triangles), straight in
    /// frame 0 and bent by 120° just after its middle in frame 1
    /// (`Pose::Deformed`); one object, or two that meet at the bend as the
    /// human's parts do.
    fn bent_tube(split: bool) -> Scene {
        let (segments, sides, radius) = (64u32, 16u32, 0.1f32);
        // Rings 0..=32 and 32..=64 (the shared ring twice) when split.
        let parts = if split {
            vec![0..=segments / 2, segments / 2..=segments]
        } else {
            vec![0..=segments]
        };
        // Bent over x in [0, 0.3] around a centre 0.3 / (2π/3) above the
        // axis, then straight again.
        let (width, bend) = (0.3f32, 2.0 * PI / 3.0);
        let arc = width / bend;
        let bent = |p: Vec3| {
            let along = p.x.clamp(0.0, width);
            let angle = bend * along / width;
            let (sin, cos) = angle.sin_cos();
            let (direction, normal) = (Vec3::new(cos, sin, 0.0), Vec3::new(-sin, cos, 0.0));
            let axis = if p.x < 0.0 {
                Vec3::new(p.x, 0.0, 0.0)
            } else {
                Vec3::new(arc * sin, arc * (1.0 - cos), 0.0) + (p.x - along) * direction
            };
            axis + p.y * normal + Vec3::new(0.0, 0.0, p.z)
        };
        let mut objects = Vec::new();
        let mut poses = [Vec::new(), Vec::new()];
        for rings in parts {
            let mut straight = Vec::new();
            for i in rings.clone() {
                for j in 0..sides {
                    let angle = std::f32::consts::TAU * j as f32 / sides as f32;
                    let x = -1.0 + 2.0 * i as f32 / segments as f32;
                    straight.push(Vec3::new(x, radius * angle.cos(), radius * angle.sin()));
                }
            }
            let mut triangles = Vec::new();
            for i in 0..rings.end() - rings.start() {
                for j in 0..sides {
                    let at = |i: u32, j: u32| i * sides + j % sides;
                    let (a, b) = (at(i, j), at(i, j + 1));
                    let (c, d) = (at(i + 1, j + 1), at(i + 1, j));
                    triangles.extend([[a, b, c], [a, c, d]]);
                }
            }
            poses[0].push(Pose::Rigid(Affine3A::IDENTITY));
            poses[1].push(Pose::Deformed {
                positions: straight.iter().map(|&p| bent(p)).collect(),
                normals: None,
            });
            objects.push(object(
                Mesh::new("tube", straight, None, triangles).unwrap(),
            ));
        }
        let frames = poses
            .into_iter()
            .enumerate()
            .map(|(f, poses)| Frame {
                time: f as f32,
                poses,
            })
            .collect();
        Scene::new("bent tube", objects, frames, camera()).unwrap()
    }

    /// Simplified to about a tenth, the tube's coarse mesh is long strips
    /// along its length; bent, the strips crossing the elbow pass a few
    /// millimetres over the vertices on its inner side, facing them (the
    /// slivers of the human's arms, module docs). Without the envelope test
    /// and the substitution, the single tube's mean |difference| from flat
    /// mode in the bent frame was 0.056 and its worst vertex 0.94; with them,
    /// 0.0009 and 0.042 (replaced per frame; 0.0012 and 0.047 with regions
    /// listed from the straight pose). Split in two, without bodies (each
    /// part's rules for its own coarse triangles only) the worst vertex was
    /// 0.83; with them, mean 0.0012 and worst 0.069 (0.0020 and 0.095).
    #[test]
    fn coarse_slivers_over_a_bent_tube_are_replaced_by_fine_triangles() {
        for split in [false, true] {
            let scene = bent_tube(split);
            for f in 0..2 {
                let (_, fb) = blocked(flat(), &scene, f);
                let (h, hb) = blocked(two_level(NearRings::Two, 2), &scene, f);
                let coarse: usize = (0..scene.objects().len())
                    .map(|o| h.coarse_triangle_count(o).unwrap())
                    .sum();
                assert!((150..=210).contains(&coarse), "{coarse}");
                let n = fb.len() as f32;
                let flat_mean = fb.iter().sum::<f32>() / n;
                let diff: Vec<f32> = fb.iter().zip(&hb).map(|(a, b)| (a - b).abs()).collect();
                let mean_abs = diff.iter().sum::<f32>() / n;
                let max_abs = diff.iter().copied().fold(0.0, f32::max);
                eprintln!(
                    "bent tube (split {split}), frame {f}: flat mean blocked {flat_mean:.4}, \
                     mean |diff| {mean_abs:.4}, max {max_abs:.4}"
                );
                if f == 1 {
                    assert!(flat_mean > 0.02, "the bend must shadow: {flat_mean}");
                }
                assert!(mean_abs < 0.004, "split {split}, frame {f}: {mean_abs}");
                assert!(max_abs < 0.15, "split {split}, frame {f}: {max_abs}");
            }
        }
    }
}
