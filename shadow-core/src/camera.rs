//! A pinhole camera: where the viewer is, and the pixels of an image.

use glam::{Mat4, Vec3};

use crate::{Error, Result};

/// A perspective pinhole camera looking from `eye` at `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// A camera, rejecting a zero-size image, a degenerate frame (eye on target,
    /// up parallel to the view direction) or a field of view outside (0, π).
    pub fn new(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_y: f32,
        width: u32,
        height: u32,
    ) -> Result<Camera> {
        let forward = target - eye;
        if width == 0 || height == 0 {
            return Err(Error::InvalidScene(format!(
                "camera image {width}×{height} is empty"
            )));
        }
        if !(fov_y > 0.0 && fov_y < std::f32::consts::PI) {
            return Err(Error::InvalidScene(format!(
                "camera field of view {fov_y} rad is outside (0, π)"
            )));
        }
        if !eye.is_finite()
            || !target.is_finite()
            || forward.cross(up).length_squared() <= 1e-12 * forward.length_squared()
        {
            return Err(Error::InvalidScene(format!(
                "camera frame is degenerate (eye {eye}, target {target}, up {up})"
            )));
        }
        Ok(Camera {
            eye,
            target,
            up,
            fov_y,
            width,
            height,
        })
    }

    /// A camera framing a bounding sphere from direction `from` (pointing from
    /// the centre to the eye), +Y up, 40° vertical field of view.
    pub fn framing(
        center: Vec3,
        radius: f32,
        from: Vec3,
        width: u32,
        height: u32,
    ) -> Result<Camera> {
        let fov_y = 40f32.to_radians();
        let distance = radius / (fov_y * 0.5).sin() * 1.05;
        let from = from.normalize_or(Vec3::Z);
        let up = if from.cross(Vec3::Y).length_squared() < 1e-6 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        Camera::new(center + from * distance, center, up, fov_y, width, height)
    }

    /// The same view with an image `width` pixels wide, the height following
    /// the aspect ratio (rounded, at least one pixel). Fails for a zero width.
    pub fn with_width(&self, width: u32) -> Result<Camera> {
        let height = (f64::from(width) * f64::from(self.height) / f64::from(self.width))
            .round()
            .max(1.0) as u32;
        Camera::new(self.eye, self.target, self.up, self.fov_y, width, height)
    }

    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    pub fn view(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.eye, self.target, self.up)
    }

    /// The unit direction of the ray through the centre of pixel (x, y), pixel
    /// (0, 0) at the top left.
    pub fn ray_direction(&self, x: u32, y: u32) -> Vec3 {
        self.direction_at(x as f32 + 0.5, y as f32 + 0.5)
    }

    /// The unit direction through image point (x, y), in pixels from the
    /// top left corner of the image.
    pub fn direction_at(&self, x: f32, y: f32) -> Vec3 {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let half_h = (self.fov_y * 0.5).tan();
        let half_w = half_h * self.aspect();
        let sx = (x / self.width as f32 * 2.0 - 1.0) * half_w;
        let sy = (1.0 - y / self.height as f32 * 2.0) * half_h;
        (forward + right * sx + up * sy).normalize()
    }

    /// The same eye turned toward image point `center` (pixels from the top
    /// left) and zoomed until the window `fraction` of the image's height
    /// around it fills the frame; same size and aspect. A turn, not an
    /// off-axis crop: the window's centre is exact, its edges move by the
    /// cosine of the turn. Fails unless `0 < fraction <= 1`.
    pub fn zoomed(&self, center: (f32, f32), fraction: f32) -> Result<Camera> {
        if !(fraction > 0.0 && fraction <= 1.0) {
            return Err(Error::InvalidScene(format!(
                "camera zoom onto {fraction} of the frame is outside (0, 1]"
            )));
        }
        let distance = (self.target - self.eye).length();
        let direction = self.direction_at(center.0, center.1);
        let fov_y = 2.0 * ((self.fov_y * 0.5).tan() * fraction).atan();
        Camera::new(
            self.eye,
            self.eye + direction * distance,
            self.up,
            fov_y,
            self.width,
            self.height,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn centre_ray_looks_at_target_and_top_row_looks_up() {
        let cam =
            Camera::new(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 1.0, 101, 101).unwrap();
        assert_relative_eq!(cam.ray_direction(50, 50), Vec3::NEG_Z, epsilon = 1e-6);
        assert!(cam.ray_direction(50, 0).y > 0.0);
        assert!(cam.ray_direction(100, 50).x > 0.0);
    }

    #[test]
    fn a_zoom_looks_through_the_window_it_frames() {
        let cam =
            Camera::new(Vec3::new(0.0, 1.0, 5.0), Vec3::ZERO, Vec3::Y, 0.8, 160, 120).unwrap();
        // The whole frame around its centre is the same view.
        let same = cam.zoomed((80.0, 60.0), 1.0).unwrap();
        assert_relative_eq!(same.target, cam.target, epsilon = 1e-5);
        assert_relative_eq!(same.fov_y, cam.fov_y, epsilon = 1e-6);
        // A quarter of the frame around a point: the new centre ray is the
        // old ray through that point, the view four times narrower.
        let zoomed = cam.zoomed((40.0, 90.0), 0.25).unwrap();
        let centre = (zoomed.target - zoomed.eye).normalize();
        assert_relative_eq!(centre, cam.direction_at(40.0, 90.0), epsilon = 1e-5);
        assert_relative_eq!(
            (zoomed.fov_y * 0.5).tan(),
            0.25 * (cam.fov_y * 0.5).tan(),
            epsilon = 1e-6
        );
        assert_eq!((zoomed.width, zoomed.height), (160, 120));
        assert!(cam.zoomed((80.0, 60.0), 0.0).is_err());
        assert!(cam.zoomed((80.0, 60.0), 1.5).is_err());
    }

    #[test]
    fn a_new_width_keeps_the_aspect() {
        let cam = Camera::new(Vec3::Z, Vec3::ZERO, Vec3::Y, 1.0, 640, 480).unwrap();
        let small = cam.with_width(160).unwrap();
        assert_eq!((small.width, small.height), (160, 120));
        assert_eq!(cam.with_width(1).unwrap().height, 1);
        assert!(cam.with_width(0).is_err());
    }

    #[test]
    fn degenerate_cameras_are_rejected() {
        assert!(Camera::new(Vec3::ZERO, Vec3::ZERO, Vec3::Y, 1.0, 8, 8).is_err());
        assert!(Camera::new(Vec3::Y, Vec3::ZERO, Vec3::Y, 1.0, 8, 8).is_err());
        assert!(Camera::new(Vec3::Z, Vec3::ZERO, Vec3::Y, 1.0, 0, 8).is_err());
    }
}
