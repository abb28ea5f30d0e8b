//! The floor beside a wall (`scenes::wall_scene`): the fraction of a
//! uniform sky each floor point sees, exactly, from Lambert's formula.

use glam::Vec3;
use shadow_core::Mesh;

/// `1 − F` at floor point `p` (normal +Y), F the form factor to the wall's
/// face toward the floor; `None` on the line under the wall, where the
/// answer is singular.
pub fn open_fraction(wall: &Mesh, p: Vec3) -> Option<f32> {
    if (p.x - 0.5).abs() < 0.1 {
        return None;
    }
    let b = wall.bounds();
    let face = [
        Vec3::new(b.min.x, b.min.y, b.min.z),
        Vec3::new(b.min.x, b.max.y, b.min.z),
        Vec3::new(b.min.x, b.max.y, b.max.z),
        Vec3::new(b.min.x, b.min.y, b.max.z),
    ];
    Some(1.0 - polygon_form_factor(p, Vec3::Y, &face))
}

/// Lambert's formula: the form factor from a differential area at `point`
/// with normal `n` to a polygon wholly above its tangent plane,
/// F = (1/2π) |Σ_i Θ_i γ_i·n| (Θ_i the angle an edge subtends, γ_i the unit
/// normal of the plane through the edge and the point).
fn polygon_form_factor(point: Vec3, n: Vec3, polygon: &[Vec3]) -> f32 {
    let mut sum = 0.0;
    for i in 0..polygon.len() {
        let a = (polygon[i] - point).normalize();
        let b = (polygon[(i + 1) % polygon.len()] - point).normalize();
        sum += a.dot(b).clamp(-1.0, 1.0).acos() * a.cross(b).normalize().dot(n);
    }
    (sum / std::f32::consts::TAU).abs()
}
