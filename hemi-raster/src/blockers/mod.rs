//! A frame's blocker triangles (§3: "for each vertex, we clear the
//! visibility mask and rasterize all blocking triangles into it"): every
//! object's posed vertices and triangles together ([`Blockers`]), numbered
//! in clusters with the coarse level of the mesh hierarchy ([`Layout`]),
//! and what each receiver rasterizes of them ([`Candidates`]).
//!
//! # The receiver: the vertex, lifted
//! A receiver looks from its vertex lifted along the normal by the frame's
//! ray offset ([`Aabb::ray_offset`](shadow_core::Aabb::ray_offset), 10⁻⁴ of
//! the scene's diagonal, through [`shadow_core::ray_origin`]), the point
//! the Monte-Carlo reference shoots its rays from. From the vertex itself
//! the faces that meet there would subtend no solid angle (they pass
//! through it), and at a concave crease, where the averaged normal tilts
//! the hemisphere into the object, the directions into those faces would
//! see through the solid: its inner walls are back faces, culled. From the
//! lifted point the faces meeting at a concave crease rise above the
//! tangent plane and block, as they do for any point of the surface beside
//! the vertex; at convex and flat vertices they lie below it and are culled
//! as before. It also settles vertices lying a few µm behind another part's
//! surface (seams between the parts of a model) and rims touching a floor
//! the way the reference does.

use std::ops::Range;

use glam::Vec3;
use shadow_core::{FrameGeometry, ray_origin};

use crate::raster::TangentFrame;

mod candidates;
mod layout;

pub(crate) use candidates::Candidates;
pub(crate) use layout::{CLUSTER, CoarseLevel, Entry, Layout};

/// Every triangle of a frame, all objects together, laid out for the
/// per-receiver loop: positions in struct-of-arrays form (so that moving them
/// into a tangent frame is three independent vectorizable streams) and
/// triangles as indices into them.
#[derive(Clone, Debug)]
pub(crate) struct Blockers {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    normals: Vec<Vec3>,
    pub(crate) triangles: Vec<[u32; 3]>,
    /// Per object: its triangles' range and whether its back faces are culled.
    pub(crate) objects: Vec<(Range<usize>, bool)>,
    /// How far each receiver sits above its vertex, along its normal: the
    /// frame's [`Aabb::ray_offset`](shadow_core::Aabb::ray_offset), the
    /// Monte-Carlo reference's, so that both look from the same point
    /// (module docs).
    lift: f32,
}

impl Blockers {
    /// Gathers a frame's vertices and triangles; `cull[o]` says whether
    /// object o's back faces are culled.
    pub(crate) fn new(frame: &FrameGeometry, cull: &[bool]) -> Blockers {
        let total: usize = frame.objects.iter().map(|o| o.vertex_count()).sum();
        let mut b = Blockers {
            x: Vec::with_capacity(total),
            y: Vec::with_capacity(total),
            z: Vec::with_capacity(total),
            normals: Vec::with_capacity(total),
            triangles: Vec::new(),
            objects: Vec::with_capacity(frame.objects.len()),
            lift: frame.bounds().ray_offset(),
        };
        for (object, &cull) in frame.objects.iter().zip(cull) {
            let base = b.x.len() as u32;
            for p in object.positions() {
                b.x.push(p.x);
                b.y.push(p.y);
                b.z.push(p.z);
            }
            b.normals.extend_from_slice(object.normals());
            let start = b.triangles.len();
            b.triangles
                .extend(object.triangles().iter().map(|t| t.map(|i| i + base)));
            b.objects.push((start..b.triangles.len(), cull));
        }
        b
    }

    /// Number of vertices, all objects together.
    pub(crate) fn vertex_count(&self) -> usize {
        self.x.len()
    }

    /// Vertex `i` (a global index), world space.
    #[inline(always)]
    pub(crate) fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    /// The tangent frame of the receiver at vertex `v` (a global index):
    /// the vertex lifted along its normal by the frame's ray offset (module
    /// docs).
    pub(crate) fn frame(&self, v: usize) -> TangentFrame {
        let n = self.normals[v];
        TangentFrame::new(ray_origin(self.position(v), n, self.lift), n)
    }
}
