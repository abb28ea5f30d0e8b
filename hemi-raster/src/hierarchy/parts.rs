//! One object's share of the hierarchy (its coarse mesh, rings, spatial
//! neighbours and regions), and the bodies objects form (module docs).

use glam::Vec3;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use rayon::prelude::*;
use shadow_core::triangle::centroid;
use shadow_core::{Adjacency, Error, Mesh, Result};

use super::spatial::Sorted;
use crate::config::NearRings;

/// The least share of an object's surface area its coarse mesh keeps; a
/// simplification that keeps less is redone with twice the triangles (or
/// the object used whole). A smooth closed surface loses area only as its
/// chords cut inside it: an icosphere of 1,280 triangles simplified to a
/// tenth keeps 95%, to a sixteenth 92%. A turned chess pawn of 352
/// triangles at a tenth keeps 78% (its collar and ball flattened), and a
/// checkerboard of 32 separate squares, which cannot be simplified without
/// removing squares, keeps 56% at any target: holes the far field would see
/// the sky through (on the chess scene, every piece's lower hemisphere).
pub(super) const MIN_AREA_KEPT: f32 = 0.9;

/// Per object, the representative of its body: objects that are not used
/// whole, cull alike and touch in the reference pose (a vertex of one lies
/// within the other's near reach) are parts of one model, as the human's
/// torso, head and legs are; each object used whole is a body of its own.
pub(super) fn bodies(parts: &[Part], cull: &[bool]) -> Vec<usize> {
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
pub(super) struct Part<'a> {
    /// Its vertices in the reference pose.
    pub(super) positions: &'a [Vec3],
    /// Its triangles, for the objects used whole.
    pub(super) triangles: &'a [[u32; 3]],
    /// The coarse mesh over the (welded) vertices; `None` when the object is
    /// used whole.
    pub(super) coarse: Option<Vec<[u32; 3]>>,
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
    pub(super) owners: Vec<u32>,
}

impl<'a> Part<'a> {
    pub(super) fn new(
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
        let rest = mesh.positions();
        let weld = mesh.welded_vertices();
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
        let area = |t: &[u32]| {
            let [a, b, c] = [0, 1, 2].map(|k| rest[t[k] as usize]);
            (b - a).cross(c - a).length()
        };
        let fine_area: f32 = welded.iter().map(|t| area(t)).sum();
        let mut target = (triangles.len() / divisor as usize).max(min_triangles as usize);
        let indices = loop {
            if target >= triangles.len() {
                return Ok(whole);
            }
            let indices = meshopt::simplify(
                welded.as_flattened(),
                &adapter,
                3 * target,
                // Relative to the mesh's extent: let the triangle target decide.
                1.0,
                SimplifyOptions::None,
                None,
            );
            if indices.is_empty() {
                return Ok(whole);
            }
            let coarse_area: f32 = indices.chunks_exact(3).map(area).sum();
            if coarse_area >= MIN_AREA_KEPT * fine_area {
                break indices;
            }
            target = 2 * target.max(indices.len() / 3);
        };
        // In space-filling-curve order, so that each run of 16 (a cluster of
        // the per-receiver loop, culled whole below the horizon) is compact:
        // on the human, 6% fewer clusters reach the per-triangle tests than
        // in the simplifier's order.
        let indices = meshopt::spatial_sort_triangles(&indices, &adapter);
        let coarse: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if coarse.len() >= triangles.len() {
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
                let centre = centroid(t.map(|i| positions[i as usize]));
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
    pub(super) fn coarse_triangles(&self) -> &[[u32; 3]] {
        self.coarse.as_deref().unwrap_or(self.triangles)
    }

    /// The triangles of vertex `v`'s one- or two-ring, found on the welded
    /// mesh so that they continue across seams.
    pub(super) fn rings(&self, v: usize, rings: NearRings) -> Vec<u32> {
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

    /// The fine triangles around vertex `v` (on the welded mesh).
    pub(super) fn around(&self, v: u32) -> &[u32] {
        match &self.adjacency {
            Some((weld, adjacency)) => adjacency.triangles_of(weld[v as usize] as usize),
            None => &[],
        }
    }

    /// The fine triangles of this object within the spatial reach of a
    /// receiver at `p` (reference pose).
    pub(super) fn near(&self, p: Vec3) -> Vec<u32> {
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
