//! A triangle's centre and size: its centroid and the distance from it to
//! the farthest corner, the sphere around it that culling and proximity
//! tests compare against.
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

#[cfg(test)]
mod tests {
    use super::*;

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
