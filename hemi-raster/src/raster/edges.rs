//! The three edge planes of a blocker triangle, and the culling decided
//! with them (§3.1.1; the module docs of [`crate::raster`] say why these
//! planes are enough, and how a triangle through the receiver is drawn).

use glam::Vec3;

/// What culling decides about triangle (a, b, c) in tangent coordinates,
/// and its three plane normals, oriented so that what the triangle blocks
/// is on their positive sides (meaningless when the triangle is culled).
#[derive(Clone, Copy, Debug)]
pub(crate) struct EdgePlanes {
    /// Survives culling (module docs: below the horizon, through the
    /// receiver beside it, back-facing while culling back faces).
    pub(crate) kept: bool,
    /// Some corner is above the horizon (z > 0).
    pub(crate) above: bool,
    /// The receiver is behind the triangle's plane (det > 0).
    pub(crate) behind: bool,
    pub(crate) normals: [Vec3; 3],
}

/// Culls triangle (a, b, c), given in tangent coordinates, and computes its
/// edge planes; `contact` is the receiver's contact reach
/// ([`TangentFrame::contact`](crate::TangentFrame::contact)): a triangle
/// whose plane passes within it of the receiver, over the receiver, blocks
/// the half of the hemisphere that sees its front, or the part of it across
/// the edges the receiver's foot lies on (module docs). Branch-free,
/// so that the per-receiver loop evaluates it 16 triangles at a time.
#[inline(always)]
pub(crate) fn edge_planes([a, b, c]: [Vec3; 3], cull_back_faces: bool, contact: f32) -> EdgePlanes {
    // Bitwise `|`/`&`: no branches in the vectorized loop.
    let above = (a.z > 0.0) | (b.z > 0.0) | (c.z > 0.0);
    let (ab, bc, ca) = (a.cross(b), b.cross(c), c.cross(a));
    let det = ab.dot(c);
    // (b − a) × (c − a): the counter-clockwise normal, twice the area long;
    // the receiver's distance to the plane is det / |n|.
    let n = ab + bc + ca;
    let n2 = n.length_squared();
    let reach2 = contact * contact;
    // The receiver on the plane or behind it within the reach (false for
    // NaN), over the triangle: a contact (module docs).
    let through = (det >= 0.0) & (det * det <= reach2 * n2) & (n2 > 0.0);
    // The receiver's foot on the plane is inside the triangle, or within the
    // reach of its edges: (a × b)·n is the foot's distance from edge ab
    // times |b − a| |n|.
    let on = |edge: Vec3, from: Vec3, to: Vec3| {
        let d = edge.dot(n);
        (
            d >= 0.0,
            d * d <= reach2 * (to - from).length_squared() * n2,
        )
    };
    let edges = [(ab, a, b), (bc, b, c), (ca, c, a)];
    let [(in_ab, on_ab), (in_bc, on_bc), (in_ca, on_ca)] = edges.map(|(e, f, t)| on(e, f, t));
    let contact = above & through & (in_ab | on_ab) & (in_bc | on_bc) & (in_ca | on_ca);
    // Anywhere else off the plane the cone is exact, however close: its
    // three planes tend to the triangle's own. Exactly on the plane and
    // beside the triangle it is empty (false for NaN too).
    let spans_a_cone = det.abs() > 0.0;
    let behind = det > 0.0;
    let s = if det < 0.0 { -1.0 } else { 1.0 };
    let normals = if contact {
        // The directions that see the front face, d·n < 0, and across each
        // edge the foot lies on enter the triangle: n × (b − a) points from
        // ab toward c (shadow-core's `ContactCone`); all three edges within
        // the reach (a triangle smaller than it), the front half.
        let all = on_ab & on_bc & on_ca;
        let plane = |on: bool, (_, from, to): (Vec3, Vec3, Vec3)| {
            if on & !all { n.cross(to - from) } else { -n }
        };
        [
            plane(on_ab, edges[0]),
            plane(on_bc, edges[1]),
            plane(on_ca, edges[2]),
        ]
    } else {
        [s * ab, s * bc, s * ca]
    };
    EdgePlanes {
        kept: contact | (above & spans_a_cone & !(cull_back_faces & behind)),
        above,
        behind,
        normals,
    }
}
