//! The frame a vertex looks from: an orthonormal tangent frame about its
//! normal, and the point along the normal its rays start from.
//!
//! Every method that looks from a vertex (the Monte-Carlo reference and its
//! transfer, hemi-raster's receivers, deferred-shadow's precomputation)
//! builds the same frame from the same normal and lifts the vertex by the
//! same offset, so that all see the same hemisphere from the same point.

use glam::{Mat3, Vec3};

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

/// Where rays from a vertex at `position` with unit `normal` start: lifted
/// along the normal by `offset`, the frame's
/// [`Aabb::ray_offset`](crate::Aabb::ray_offset) (see there for why).
#[inline]
pub fn ray_origin(position: Vec3, normal: Vec3, offset: f32) -> Vec3 {
    position + normal * offset
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

    #[test]
    fn rays_start_above_the_vertex_along_its_normal() {
        let n = Vec3::new(0.0, 0.6, 0.8);
        let o = ray_origin(Vec3::new(1.0, 2.0, 3.0), n, 0.5);
        assert_eq!(o, Vec3::new(1.0, 2.3, 3.4));
        assert_eq!(ray_origin(Vec3::ONE, n, 0.0), Vec3::ONE);
    }
}
