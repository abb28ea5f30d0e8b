//! The frame a vertex looks from: an orthonormal tangent frame about its
//! normal, and the point along the normal its rays start from.
//!
//! Every method that looks from a vertex (the Monte-Carlo reference and its
//! transfer, hemi-raster's receivers, deferred-shadow's precomputation)
//! builds the same frame from the same normal and lifts the vertex by the
//! same distance ([`LIFT`] of the local size of its surface), so that all
//! see the same hemisphere from the same point.

use glam::{DVec3, Mat3, Vec3};

/// An orthonormal, right-handed frame (tangent, bitangent, normal) about a
/// unit normal: local z is the normal.
///
/// The tangents are glam's [`Vec3::any_orthonormal_pair`], a continuous
/// choice except near −z. Only the normal is meaningful; what the tangents
/// are matters to the bit, since directions are drawn or tabled in local
/// coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentSpace {
    pub tangent: Vec3,
    pub bitangent: Vec3,
    pub normal: Vec3,
}

impl TangentSpace {
    /// The frame about the unit `normal`.
    #[inline]
    pub fn new(normal: Vec3) -> TangentSpace {
        let (tangent, bitangent) = normal.any_orthonormal_pair();
        TangentSpace {
            tangent,
            bitangent,
            normal,
        }
    }

    /// The world-space direction of `local` (z along the normal):
    /// t·x + b·y + n·z.
    #[inline]
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.tangent * local.x + self.bitangent * local.y + self.normal * local.z
    }

    /// The rotation from local to world coordinates: columns t, b, n.
    #[inline]
    pub fn matrix(&self) -> Mat3 {
        Mat3::from_cols(self.tangent, self.bitangent, self.normal)
    }
}

/// How far a surface point's rays start off its surface, as a fraction of
/// the local size of the surface there ([`vertex_lifts`]): 1%, 10 µm on a
/// surface of 1 mm triangles, 1 cm on one of 1 m triangles. Large enough
/// that a ray meets neither the triangles through its own origin nor the
/// facets of a mesh whose file quantized its positions (glTF Transform's
/// 14-bit `quantize` moves the skinned human's vertices by up to 0.1 mm,
/// its lift is 0.2 mm; at 10⁻⁴ of the local size its occlusion moved by
/// 0.6%, at 1% by less than 0.5%), nor the wedge of a coarse polygon's
/// smooth-normal hemisphere that dips under the facet; small enough that
/// contacts stay sharp, where the rules of
/// [`SceneBvh::unoccluded_from`](crate::bvh::SceneBvh::unoccluded_from) and
/// [`SceneBvh::pressed`](crate::bvh::SceneBvh::pressed) take over. It
/// follows the local size and never the scene's, so that a small object on
/// a large floor, or a scene moved far from the origin, looks from the same
/// points (DESIGN.md, "Robust at any scale").
pub const LIFT: f32 = 1e-2;

/// The rounding floor of a lift: 2⁻¹⁹ (16 units in the last place) of the
/// largest coordinate of the point in the space the arithmetic is done in
/// (centred on the frame's bounds, [`lift_at`]). A lift below it would be
/// lost in the rounding of the point's own coordinates; in scenes of
/// ordinary proportions it is far below [`LIFT`] of the local size.
pub const LIFT_PRECISION: f32 = 1.0 / 524_288.0;

/// Per vertex, [`LIFT`] times the longest edge of the triangles that use it
/// (the local size of the surface there); a vertex no triangle uses gets
/// [`LIFT`] of the longest edge of the mesh. Computed in a space scaled by
/// a power of two, so that no product overflows or underflows f32 whatever
/// the units.
pub fn vertex_lifts(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<f32> {
    let scale = unit_scale(positions);
    let mut longest = vec![0.0f32; positions.len()];
    let mut overall = 0.0f32;
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize] * scale);
        let edge = (b - a).length().max((c - b).length()).max((a - c).length());
        overall = overall.max(edge);
        for &i in t {
            longest[i as usize] = longest[i as usize].max(edge);
        }
    }
    longest
        .into_iter()
        .map(|l| LIFT * if l > 0.0 { l } else { overall } / scale)
        .collect()
}

/// A power of two that brings the largest coordinate of `points` near 1:
/// multiplying by it is exact.
pub(crate) fn unit_scale(points: &[Vec3]) -> f32 {
    let largest = points
        .iter()
        .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
    if largest > 0.0 && largest.is_finite() {
        (-largest.log2().round()).exp2()
    } else {
        1.0
    }
}

/// The lift a point uses whose own lift is `lift` and whose coordinates,
/// in the space the arithmetic is done in, are `offset` from that space's
/// centre: the larger of its own and [`LIFT_PRECISION`] of `offset`'s
/// largest coordinate.
#[inline]
pub fn lift_at(lift: f32, offset: Vec3) -> f32 {
    lift.max(LIFT_PRECISION * offset.abs().max_element())
}

/// A point on a surface that rays leave from: where it is, which way the
/// surface faces there, and how far its rays start off it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// In f64: a point inside a triangle 10 km from the origin is 1 mm off
    /// its surface in f32, a thousand lifts; in f64 it stays on it until it
    /// is taken into the space rays are traced in, centred on the frame.
    pub position: DVec3,
    /// Unit normal.
    pub normal: Vec3,
    /// The point's lift: a vertex's [`Mesh::lifts`](crate::Mesh::lifts)
    /// entry, or their barycentric blend inside a triangle (never below
    /// [`LIFT`] of the triangle's longest edge, since each of its vertices'
    /// is at least that).
    pub lift: f32,
}

/// The four probes that decide whether a surface point lies pressed on
/// another surface (a box's bottom face on the floor): segments along the
/// unit `normal`, 1.5 `lift` long, each starting a lift from the point in
/// the tangent plane (off the mesh's edges through it: the directions avoid
/// the tangent axes) and half a lift behind it. The point is pressed when
/// each crosses another object's surface, from either side
/// ([`SceneBvh::pressed`](crate::bvh::SceneBvh::pressed)). Returns the
/// starts; the same in any space, given the point and lift in it.
pub fn press_probes(position: Vec3, normal: Vec3, lift: f32) -> [Vec3; 4] {
    let tangents = TangentSpace::new(normal);
    [(0.83, 0.31), (-0.29, 0.87), (-0.81, -0.37), (0.33, -0.79)].map(|(u, v)| {
        let side = tangents.tangent * u + tangents.bitangent * v;
        position + side * lift - normal * (0.5 * lift)
    })
}

/// How far each of the [`press_probes`] reaches along the normal, in lifts.
pub const PRESS_REACH: f32 = 1.5;

/// Where rays from a vertex at `position` with unit `normal` start: lifted
/// along the normal by `lift` ([`lift_at`] of its [`vertex_lifts`]).
#[inline]
pub fn ray_origin(position: Vec3, normal: Vec3, lift: f32) -> Vec3 {
    position + normal * lift
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangent_spaces_are_orthonormal_and_right_handed() {
        for n in [
            Vec3::Y,
            -Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.9, 0.1).normalize(),
        ] {
            let s = TangentSpace::new(n);
            let m = s.matrix();
            assert!((m.transpose() * m).abs_diff_eq(Mat3::IDENTITY, 1e-6), "{n}");
            assert!((m.determinant() - 1.0).abs() < 1e-6, "{n}");
            assert_eq!(s.normal, n);
            assert_eq!(s.to_world(Vec3::Z), n);
            // The same as the matrix, to the bit.
            let local = Vec3::new(0.3, -0.4, 0.866);
            assert_eq!(s.to_world(local), m * local);
        }
    }

    /// Lifts follow the triangles at each vertex, not the mesh's extent,
    /// and do not change when the units do.
    #[test]
    fn lifts_follow_the_local_size_of_the_surface() {
        // A small triangle and a large one sharing no vertex, and a vertex
        // no triangle uses.
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(0.01, 0.0, 0.0),
            Vec3::new(0.0, 0.02, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(20.0, 0.0, 0.0),
            Vec3::new(10.0, 5.0, 0.0),
            Vec3::splat(3.0),
        ];
        let triangles = [[0, 1, 2], [3, 4, 5]];
        let lifts = vertex_lifts(&positions, &triangles);
        let small = (0.01f32.powi(2) + 0.02f32.powi(2)).sqrt();
        let large = (10.0f32.powi(2) + 5.0f32.powi(2)).sqrt();
        for v in 0..3 {
            assert!(
                (lifts[v] - LIFT * small).abs() < 1e-6 * lifts[v],
                "{lifts:?}"
            );
        }
        for v in 3..7 {
            assert!(
                (lifts[v] - LIFT * large).abs() < 1e-6 * lifts[v],
                "{lifts:?}"
            );
        }
        // The same mesh in units 10³⁰ and 10⁻³⁰ times larger.
        for factor in [1e30f32, 1e-30] {
            let scaled: Vec<Vec3> = positions.iter().map(|&p| p * factor).collect();
            let got = vertex_lifts(&scaled, &triangles);
            for (g, l) in got.iter().zip(&lifts) {
                assert!(g.is_finite() && *g > 0.0);
                assert!(
                    (g / factor - l).abs() < 1e-5 * l,
                    "{factor}: {g} against {l}"
                );
            }
        }
    }

    #[test]
    fn lifts_stay_above_the_rounding_of_the_coordinates() {
        assert_eq!(lift_at(1e-3, Vec3::new(1.0, -2.0, 0.5)), 1e-3);
        let far = lift_at(1e-6, Vec3::new(0.0, -1e4, 3.0));
        assert_eq!(far, 1e4 * LIFT_PRECISION);
        // 16 units in the last place of the coordinate.
        assert!(far >= 16.0 * (1e4f32.next_up() - 1e4));
    }

    #[test]
    fn rays_start_above_the_vertex_along_its_normal() {
        let n = Vec3::new(0.0, 0.6, 0.8);
        let o = ray_origin(Vec3::new(1.0, 2.0, 3.0), n, 0.5);
        assert_eq!(o, Vec3::new(1.0, 2.3, 3.4));
        assert_eq!(ray_origin(Vec3::ONE, n, 0.0), Vec3::ONE);
    }
}
