//! A triangle's centre and size: its centroid and the distance from it to
//! the farthest corner, the sphere around it that culling and proximity
//! tests compare against; and where a ray crosses it, for the few tests
//! that trace single rays without a tree.
//!
//! Branch-free and always inlined, so that loops over many triangles
//! evaluate them several lanes at a time.

use glam::Vec3;

/// The centroid (a + b + c) / 3 of triangle (a, b, c).
#[inline(always)]
pub fn centroid([a, b, c]: [Vec3; 3]) -> Vec3 {
    (a + b + c) / 3.0
}

/// The squared distance from `centre` to the farthest corner of triangle
/// (a, b, c). A NaN corner is skipped (`f32::max`), unless all are NaN.
#[inline(always)]
pub fn radius_squared([a, b, c]: [Vec3; 3], centre: Vec3) -> f32 {
    (a - centre)
        .length_squared()
        .max((b - centre).length_squared())
        .max((c - centre).length_squared())
}

/// A sphere around triangle `corners`: its [`centroid`] and the distance
/// from it to the farthest corner (the square root of [`radius_squared`]).
#[inline(always)]
pub fn bounding_sphere(corners: [Vec3; 3]) -> (Vec3, f32) {
    let centre = centroid(corners);
    (centre, radius_squared(corners, centre).sqrt())
}

/// The distance t ≥ 0 along the ray from `origin` in direction `dir` at
/// which it crosses triangle (a, b, c) from either side (Möller and
/// Trumbore), or `None`. The edges are closed: a ray through an edge or a
/// corner crosses.
#[inline]
pub fn ray_crossing(origin: Vec3, dir: Vec3, [a, b, c]: [Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - a;
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    let t = e2.dot(q) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t >= 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_cross_triangles_from_either_side() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Z];
        let above = Vec3::new(0.25, 2.0, 0.25);
        assert_eq!(ray_crossing(above, Vec3::NEG_Y, t), Some(2.0));
        assert_eq!(ray_crossing(-above, Vec3::Y, t), None);
        let below = Vec3::new(0.25, -0.5, 0.25);
        assert_eq!(ray_crossing(below, Vec3::Y, t), Some(0.5));
        assert_eq!(ray_crossing(below, Vec3::NEG_Y, t), None);
        // Beside it, and along its plane.
        assert_eq!(ray_crossing(Vec3::new(0.9, 1.0, 0.9), Vec3::NEG_Y, t), None);
        assert_eq!(ray_crossing(Vec3::new(-1.0, 0.0, 0.1), Vec3::X, t), None);
    }

    #[test]
    fn centroid_and_radius_of_a_right_triangle() {
        let t = [
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        assert_eq!(centroid(t), Vec3::new(1.0, 1.0, 0.0));
        // The far corners (3, 0, 0) and (0, 3, 0) are √5 from (1, 1, 0).
        assert_eq!(radius_squared(t, centroid(t)), 5.0);
        let (centre, radius) = bounding_sphere(t);
        assert_eq!(centre, centroid(t));
        assert_eq!(radius, 5.0f32.sqrt());
        // Every corner is inside the sphere, one on it.
        let far = t.iter().map(|p| p.distance(centre)).fold(0.0, f32::max);
        assert_eq!(far, radius);
    }

    #[test]
    fn degenerate_triangles_have_a_centre_and_a_radius() {
        let p = Vec3::new(-2.0, 0.5, 7.0);
        assert_eq!(bounding_sphere([p; 3]), (p, 0.0));
        let segment = [Vec3::ZERO, Vec3::X, Vec3::new(2.0, 0.0, 0.0)];
        assert_eq!(bounding_sphere(segment), (Vec3::X, 1.0));
    }
}
