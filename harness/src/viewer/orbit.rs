//! Orbit, zoom and pan of a [`Camera`] about its target, keeping its up
//! direction: the viewer's mouse controls.

use glam::{Quat, Vec3};
use shadow_core::Camera;

/// The eye stays at least this far (radians) from the up axis through the
/// target, where the camera's frame would degenerate.
const POLE_MARGIN: f32 = 0.05;

/// The eye turned about the target by `yaw` radians about the up axis and
/// `pitch` radians over the top (positive: the eye rises), short of the
/// poles.
pub fn orbit(camera: &Camera, yaw: f32, pitch: f32) -> Camera {
    let up = camera.up.normalize();
    let offset = camera.eye - camera.target;
    let offset = Quat::from_axis_angle(up, yaw) * offset;
    let polar = offset.normalize().dot(up).clamp(-1.0, 1.0).acos();
    let turned = (polar - pitch).clamp(POLE_MARGIN, std::f32::consts::PI - POLE_MARGIN);
    let right = up.cross(offset).normalize_or(Vec3::X);
    let offset = Quat::from_axis_angle(right, turned - polar) * offset;
    Camera {
        eye: camera.target + offset,
        ..*camera
    }
}

/// The eye moved toward the target (`factor` < 1) or away (> 1).
pub fn zoom(camera: &Camera, factor: f32) -> Camera {
    let offset = (camera.eye - camera.target) * factor.clamp(0.05, 20.0);
    let least = 1e-4 * camera.target.length().max(1.0);
    Camera {
        eye: camera.target + offset.normalize_or(Vec3::Z) * offset.length().max(least),
        ..*camera
    }
}

/// Eye and target moved across the view by `dx`, `dy` image heights (right
/// and up), as far as the plane through the target moves on screen.
pub fn pan(camera: &Camera, dx: f32, dy: f32) -> Camera {
    let forward = camera.target - camera.eye;
    let distance = forward.length();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward.normalize());
    let height = 2.0 * distance * (camera.fov_y * 0.5).tan();
    let shift = (right * dx + up * dy) * height;
    Camera {
        eye: camera.eye + shift,
        target: camera.target + shift,
        ..*camera
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn camera() -> Camera {
        Camera::new(Vec3::new(0.0, 1.0, 4.0), Vec3::Y, Vec3::Y, 0.7, 64, 48).unwrap()
    }

    #[test]
    fn orbit_keeps_the_distance_and_stops_short_of_the_poles() {
        let c = camera();
        let d = (c.eye - c.target).length();
        let turned = orbit(&c, 1.0, 0.3);
        assert_relative_eq!((turned.eye - turned.target).length(), d, epsilon = 1e-5);
        assert!(turned.eye.y > c.eye.y);
        let top = orbit(&c, 0.0, 10.0);
        let polar = (top.eye - top.target).normalize().dot(Vec3::Y).acos();
        assert_relative_eq!(polar, POLE_MARGIN, epsilon = 1e-4);
        // A full turn about the up axis comes back.
        let round = orbit(&c, std::f32::consts::TAU, 0.0);
        assert_relative_eq!(round.eye, c.eye, epsilon = 1e-5);
    }

    #[test]
    fn zoom_and_pan_move_as_asked() {
        let c = camera();
        let closer = zoom(&c, 0.5);
        assert_relative_eq!((closer.eye - closer.target).length(), 2.0, epsilon = 1e-5);
        let moved = pan(&c, 0.5, 0.0);
        assert_relative_eq!(moved.eye - c.eye, moved.target - c.target, epsilon = 1e-6);
        let height = 2.0 * 4.0 * (0.35f32).tan();
        assert_relative_eq!((moved.eye - c.eye).length(), 0.5 * height, epsilon = 1e-5);
        assert!(moved.eye.x > 0.0, "right of a camera looking down -z is +x");
    }
}
