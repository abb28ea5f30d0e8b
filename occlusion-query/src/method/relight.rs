//! `relight`: the radiance arriving along each lightsphere direction, from
//! the environment prefiltered for the level (§5).

use std::time::Instant;

use glam::{Affine3A, Mat3, Vec3};
use shadow_core::{Result, Stage};

use super::OcclusionQuery;
use crate::lightsphere::Level;

impl OcclusionQuery {
    /// The width of the Gaussian the environment is blurred with for
    /// `level` (§5): `prefilter` times the level's spacing √(4π/k).
    pub(super) fn sigma(&self, level: Level) -> f32 {
        let k = level.directions() as f32;
        self.config.prefilter * (4.0 * std::f32::consts::PI / k).sqrt()
    }

    /// Looks up the radiance arriving from each direction of the current
    /// level, turned by the rigid object's rotation, when either changed.
    pub(super) fn light(&mut self) -> Result<()> {
        let (Some(state), Some(env), Some(scene)) = (&self.state, &self.environment, &self.scene)
        else {
            return Ok(());
        };
        let rotation = rotation_of(state.transform);
        let wanted = (state.level, rotation);
        if state.lit == Some(wanted) {
            return Ok(());
        }
        let level = state.level;
        let start = Instant::now();
        let sigma = self.sigma(level);
        if !self.prefiltered.iter().any(|(l, _)| *l == level) {
            self.prefiltered.push((level, env.prefiltered(sigma)));
        }
        let map = &self
            .prefiltered
            .iter()
            .find(|(l, _)| *l == level)
            .expect("added above")
            .1;
        let sphere = self.sphere(level);
        let incoming: Vec<Vec3> = sphere
            .directions()
            .iter()
            .map(|&l| map.lookup(rotation * l))
            .collect();
        scene
            .gpu
            .shading
            .set_incoming(&self.ctx, &incoming, sphere.weights());
        self.profile
            .seconds(Stage::Relight, "look-ups", start.elapsed().as_secs_f64());
        self.state.as_mut().expect("present").lit = Some(wanted);
        Ok(())
    }
}

/// The rotation part of a similarity transform.
pub(super) fn rotation_of(transform: Affine3A) -> Mat3 {
    let m: Mat3 = transform.matrix3.into();
    let scale = m.x_axis.length();
    if scale > 0.0 {
        m * (1.0 / scale)
    } else {
        Mat3::IDENTITY
    }
}
