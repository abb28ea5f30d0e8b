//! A frame's blocker triangles (§3: "for each vertex, we clear the
//! visibility mask and rasterize all blocking triangles into it"): every
//! object's posed vertices and triangles together ([`Blockers`]), numbered
//! in clusters with the coarse level of the mesh hierarchy ([`Layout`]),
//! and what each receiver rasterizes of them ([`Candidates`]).
//!
//! # The receiver: the vertex, lifted
//! A receiver looks from its vertex lifted along the normal by its lift
//! ([`Mesh::lifts`](shadow_core::Mesh::lifts): 10⁻⁴ of the longest edge
//! of its triangles, the local size of its surface, raised where needed
//! to the rounding of its coordinates, [`shadow_core::frame::lift_at`]),
//! the point the Monte-Carlo reference shoots its rays from. From the
//! vertex itself the faces that meet there would subtend no solid angle
//! (they pass through it), and at a concave crease, where the averaged
//! normal tilts the hemisphere into the object, the directions into those
//! faces would see through the solid: its inner walls are back faces,
//! culled. From the lifted point the faces meeting at a concave crease
//! rise above the tangent plane and block, as they do for any point of
//! the surface beside the vertex; at convex and flat vertices they lie
//! below it and are culled as before. Another surface through the lifted
//! point blocks the half it covers (the module docs of [`crate::raster`]),
//! and a receiver pressed on another object or buried in a closed one
//! sees nothing ([`shadow_core::contact`]).
//!
//! # The space
//! Positions are held relative to the centre of the frame's bounds and
//! scaled by a power of two to about [`Blockers::SIZE`] across (exact), the
//! space the reference's rays are traced in too: masks depend on
//! directions alone, and there neither the products of the edge planes
//! overflow nor a lift is lost in the rounding of coordinates far from the
//! world's origin, whatever the scene's units and place.

use std::ops::Range;

use glam::Vec3;
use shadow_core::frame::{lift_at, ray_origin};
use shadow_core::{FrameGeometry, Result};

use crate::raster::TangentFrame;

mod candidates;
mod layout;

pub(crate) use candidates::Candidates;
pub(crate) use layout::{CLUSTER, CoarseLevel, Entry, Layout};

/// Every triangle of a frame, all objects together, laid out for the
/// per-receiver loop: positions in struct-of-arrays form (so that moving them
/// into a tangent frame is three independent vectorizable streams) and
/// triangles as indices into them, in the frame's centred space (module
/// docs, "The space").
#[derive(Clone, Debug)]
pub(crate) struct Blockers {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    normals: Vec<Vec3>,
    /// Per vertex, how far its receiver sits above it along its normal, in
    /// the centred space: its mesh's lift, raised to the rounding of its
    /// coordinates (module docs).
    lifts: Vec<f32>,
    pub(crate) triangles: Vec<[u32; 3]>,
    /// Per object: its triangles' range and whether its back faces are culled.
    pub(crate) objects: Vec<(Range<usize>, bool)>,
    /// World to centred space: `(p − centre) · scale`.
    centre: Vec3,
    scale: f32,
}

impl Blockers {
    /// The size of a frame in the centred space, within a factor of two:
    /// large enough that no triangle a frame can hold in f32 is below the
    /// range of the edge planes' products, small enough that none of them
    /// overflows (the module docs of [`crate::raster`]).
    pub(crate) const SIZE: f32 = 1024.0;

    /// Gathers a frame's vertices and triangles; `cull[o]` says whether
    /// object o's back faces are culled. Fails on a frame whose extent f32
    /// cannot hold.
    pub(crate) fn new(frame: &FrameGeometry, cull: &[bool]) -> Result<Blockers> {
        let total: usize = frame.objects.iter().map(|o| o.vertex_count()).sum();
        let bounds = frame.bounds();
        let diagonal = bounds.diagonal();
        let scale = if diagonal > 0.0 {
            (Blockers::SIZE / diagonal).log2().round().exp2()
        } else {
            1.0
        };
        if !(scale.is_finite() && scale > 0.0) {
            return Err(shadow_core::Error::InvalidScene(format!(
                "a frame {diagonal} across cannot be rasterized in f32"
            )));
        }
        let mut b = Blockers {
            x: Vec::with_capacity(total),
            y: Vec::with_capacity(total),
            z: Vec::with_capacity(total),
            normals: Vec::with_capacity(total),
            lifts: Vec::with_capacity(total),
            triangles: Vec::new(),
            objects: Vec::with_capacity(frame.objects.len()),
            centre: bounds.center(),
            scale,
        };
        for (object, &cull) in frame.objects.iter().zip(cull) {
            let base = b.x.len() as u32;
            for (&p, &lift) in object.positions().iter().zip(object.lifts()) {
                let local = b.to_local(p);
                b.x.push(local.x);
                b.y.push(local.y);
                b.z.push(local.z);
                b.lifts.push(lift_at(lift * scale, local));
            }
            b.normals.extend_from_slice(object.normals());
            let start = b.triangles.len();
            b.triangles
                .extend(object.triangles().iter().map(|t| t.map(|i| i + base)));
            b.objects.push((start..b.triangles.len(), cull));
        }
        Ok(b)
    }

    /// A world-space point in the centred space.
    #[inline]
    pub(crate) fn to_local(&self, p: Vec3) -> Vec3 {
        (p - self.centre) * self.scale
    }

    /// Number of vertices, all objects together.
    pub(crate) fn vertex_count(&self) -> usize {
        self.x.len()
    }

    /// Vertex `i` (a global index), in the centred space.
    #[inline(always)]
    pub(crate) fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    /// Vertex `v`'s unit normal and lift (in the centred space).
    pub(crate) fn surface(&self, v: usize) -> (Vec3, f32) {
        (self.normals[v], self.lifts[v])
    }

    /// The tangent frame of the receiver at vertex `v` (a global index):
    /// the vertex lifted along its normal by its lift (module docs), in the
    /// centred space.
    pub(crate) fn frame(&self, v: usize) -> TangentFrame {
        let (n, lift) = self.surface(v);
        TangentFrame::lifted(ray_origin(self.position(v), n, lift), n, lift)
    }
}
