//! The per-frame test that drops a coarse triangle too close to the
//! receiver for the fine triangles it stands for (module docs, "Coarse
//! triangles too close to the receiver"). Branch-free, so that the engine's
//! loop evaluates it a cluster at a time.

use glam::Vec3;
use shadow_core::triangle;

/// κ of the envelope test that drops a coarse triangle for a receiver too
/// close to it, per frame (module docs).
pub(crate) const ENVELOPE: f32 = 0.5;

/// The centroid of `corners` as (a + b + c) · ⅓, and the squared distance
/// from it to the farthest corner. A multiply, where [`triangle::centroid`]
/// divides: the two differ in the last bit, and these tests are defined
/// with this rounding (the other would move masks on the boundary).
#[inline(always)]
fn sphere(corners: [Vec3; 3]) -> (Vec3, f32) {
    let [a, b, c] = corners;
    let centroid = (a + b + c) * (1.0 / 3.0);
    (centroid, triangle::radius_squared(corners, centroid))
}

/// Whether the receiver, at the origin, lies inside the envelope of triangle
/// (a, b, c): within `envelope` × r of its plane and within
/// (1 + `envelope`) × r of its centroid, r being the distance from the
/// centroid to the farthest corner. Branch-free; false for degenerate and
/// NaN triangles.
#[inline(always)]
pub(crate) fn in_envelope(corners: [Vec3; 3], envelope: f32) -> bool {
    let [a, b, c] = corners;
    let (centroid, radius2) = sphere(corners);
    // |n·a| is the receiver's height over the plane times |n|.
    let n = (b - a).cross(c - a);
    let height = n.dot(a);
    let reach = 1.0 + envelope;
    (height * height < envelope * envelope * radius2 * n.length_squared())
        & (centroid.length_squared() < reach * reach * radius2)
}

/// Whether coarse triangle (a, b, c) of the receiver's body (its object and
/// the parts touching it), given in tangent coordinates, is too close to
/// stand for the fine surface it approximates (§3.2; module docs), either
/// because
///
/// - it is seen from behind (`behind`) with its centroid closer than twice
///   its radius: the chord of a fold that the fine surface, not the coarse
///   one, bends around; or
/// - the receiver lies inside its envelope ([`in_envelope`] with
///   [`ENVELOPE`]): close to its plane compared with its size, where its
///   direction errs by as much as the triangle spans.
///
/// Tested per frame, so it follows deformation. See [`replaced`] for what
/// takes its place.
#[inline(always)]
pub(crate) fn is_near_chord(corners: [Vec3; 3], behind: bool) -> bool {
    let (centroid, radius2) = sphere(corners);
    let chord = behind & (centroid.length_squared() < 4.0 * radius2);
    chord | in_envelope(corners, ENVELOPE)
}

/// Whether coarse triangle `corners` of the receiver's body (tangent
/// coordinates; `above` and `behind` as its
/// [`edge_planes`](crate::raster::edge_planes) found) is dropped in this
/// frame and replaced by the fine triangles it stands for (its region,
/// module docs): it is a near chord ([`is_near_chord`]) that shows above
/// the horizon. Below it, the triangle is culled as any other (and with it
/// the region, whose fine triangles stray from it by a fraction of its
/// size): so the engine's loop, which skips whole clusters below the
/// horizon unseen, replaces exactly the same triangles.
#[inline(always)]
pub(crate) fn replaced(corners: [Vec3; 3], above: bool, behind: bool) -> bool {
    above & is_near_chord(corners, behind)
}
