//! The receiver's tangent frame (§3.1: "a local tangent frame of the
//! vertex, so that the vertex normal coincides with the z axis").

use glam::{Mat3, Vec3};
use shadow_core::TangentSpace;

/// A receiver's tangent frame: origin at the receiver, z along its normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentFrame {
    origin: Vec3,
    /// Columns: tangent, bitangent, normal (world space, orthonormal).
    to_world: Mat3,
    /// How far the origin was lifted off its surface.
    lift: f32,
}

impl TangentFrame {
    /// The frame at `origin` with z along the unit `normal`, not on any
    /// surface (no contact reach); the tangents are [`TangentSpace`]'s,
    /// those the Monte-Carlo reference draws its directions in.
    pub fn new(origin: Vec3, normal: Vec3) -> TangentFrame {
        TangentFrame::lifted(origin, normal, 0.0)
    }

    /// The frame of a receiver lifted by `lift` off its surface along the
    /// unit `normal`: its origin is `origin`, already lifted.
    pub fn lifted(origin: Vec3, normal: Vec3, lift: f32) -> TangentFrame {
        TangentFrame {
            origin,
            to_world: TangentSpace::new(normal).matrix(),
            lift,
        }
    }

    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// How far behind the receiver a triangle's plane may pass and still
    /// count as through it (the module docs of [`crate::raster`]): a
    /// quarter of its lift, half the distance the reference backs its
    /// shadow rays up by.
    pub fn contact(&self) -> f32 {
        0.25 * self.lift
    }

    pub fn normal(&self) -> Vec3 {
        self.to_world.z_axis
    }

    /// The rotation from tangent to world coordinates (columns t, b, n).
    pub fn to_world(&self) -> Mat3 {
        self.to_world
    }

    /// A world-space point in tangent coordinates.
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        self.to_world.transpose() * (p - self.origin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangent_frames_are_orthonormal() {
        for n in [Vec3::Y, -Vec3::Y, Vec3::new(0.3, -0.9, 0.1).normalize()] {
            let f = TangentFrame::new(Vec3::ONE, n);
            let m = f.to_world();
            assert!((m.transpose() * m - Mat3::IDENTITY).abs_diff_eq(Mat3::ZERO, 1e-5));
            assert!(m.determinant() > 0.0);
            assert!(
                f.to_local(Vec3::ONE + 2.0 * n)
                    .abs_diff_eq(2.0 * Vec3::Z, 1e-5)
            );
        }
    }
}
