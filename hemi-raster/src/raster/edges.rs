//! The three edge planes of a blocker triangle, and the culling decided
//! with them (§3.1.1; the module docs of [`crate::raster`] say why these
//! planes are enough).

use glam::Vec3;

/// Triangles whose |det| falls below this fraction of |a||b||c| lie (nearly)
/// in a plane through the receiver and subtend no solid angle.
const DEGENERATE: f32 = 1e-6;

/// What culling decides about triangle (a, b, c) in tangent coordinates,
/// and its three edge-plane normals oriented so that the triangle's cone is
/// on their positive sides (meaningless when the triangle is culled).
#[derive(Clone, Copy, Debug)]
pub(crate) struct EdgePlanes {
    /// Survives culling (module docs: below the horizon, through the
    /// receiver, back-facing while culling back faces).
    pub(crate) kept: bool,
    /// Some corner is above the horizon (z > 0).
    pub(crate) above: bool,
    /// The receiver is behind the triangle's plane (det > 0).
    pub(crate) behind: bool,
    pub(crate) normals: [Vec3; 3],
}

/// Culls triangle (a, b, c), given in tangent coordinates, and computes its
/// edge planes. Branch-free, so that the per-receiver loop evaluates it 16
/// triangles at a time.
#[inline(always)]
pub(crate) fn edge_planes([a, b, c]: [Vec3; 3], cull_back_faces: bool) -> EdgePlanes {
    // Bitwise `|`/`&`: no branches in the vectorized loop.
    let above = (a.z > 0.0) | (b.z > 0.0) | (c.z > 0.0);
    let (ab, bc, ca) = (a.cross(b), b.cross(c), c.cross(a));
    let det = ab.dot(c);
    let scale = (a.length_squared() * b.length_squared() * c.length_squared()).sqrt();
    // False for NaN too.
    let spans_a_cone = det.abs() > DEGENERATE * scale;
    let behind = det > 0.0;
    let s = if det < 0.0 { -1.0 } else { 1.0 };
    EdgePlanes {
        kept: above & spans_a_cone & !(cull_back_faces & behind),
        above,
        behind,
        normals: [s * ab, s * bc, s * ca],
    }
}
