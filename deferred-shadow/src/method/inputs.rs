//! The inputs of `relight` and `update`: the area lights and the poses,
//! each marking stale what it changes.

use std::time::Instant;

use glam::{Affine3A, Mat3, Mat4, Quat};
use shadow_core::{
    Capability, Environment, Error, FrameGeometry, Result, Stage, contact::Contacts,
};

use super::refresh::world_bounds;
use super::{DeferredShadow, Lit, Posed};
use crate::Grouping;
use crate::gpu::GpuObject;
use crate::groups::Groups;
use crate::lights::decompose;
use crate::maps::GpuLight;
use crate::name::NAME;
use crate::transfer::Lighting;

impl DeferredShadow {
    /// The pose of every object of `frame`: refused unless rigid with a
    /// uniform scale (the precomputed self-visibility holds for nothing
    /// else).
    pub(super) fn poses_of(frame: &FrameGeometry) -> Result<Vec<(Affine3A, Mat3)>> {
        frame
            .objects
            .iter()
            .map(|o| match o.transform {
                Some(t) => rigid(o.name(), t),
                None => Err(Error::Unsupported {
                    method: NAME.to_string(),
                    capability: Capability::DeformingMeshes,
                }),
            })
            .collect()
    }

    /// The area lights and the lighting of `environment`; what depended on
    /// the previous lights is marked stale.
    pub(super) fn light(&mut self, environment: &Environment) -> Result<()> {
        let start = Instant::now();
        let lights = decompose(environment, self.config.lights)?;
        let gpu: Vec<GpuLight> = lights.iter().map(GpuLight::new).collect();
        self.profile
            .seconds(Stage::Relight, "area lights", start.elapsed().as_secs_f64());
        let start = Instant::now();
        let lighting = Lighting::new(environment, self.config.window);
        self.profile.seconds(
            Stage::Relight,
            "SH lighting and matrix",
            start.elapsed().as_secs_f64(),
        );
        if let Some(scene) = &mut self.scene {
            scene.gpu.set_lights(&gpu)?;
        }
        self.lit = Some(Lit {
            lights,
            gpu,
            lighting,
        });
        if let Some(posed) = &mut self.posed {
            posed.radiance.iter_mut().for_each(|r| *r = None);
            posed.weights_stale.iter_mut().for_each(|s| *s = true);
            posed.maps_ready = false;
            posed.planned = None;
        }
        Ok(())
    }

    /// Takes the poses of `frame`; under [`Grouping::Overlapping`] the
    /// objects are regrouped when any of them moved.
    pub(super) fn pose(&mut self, frame: &FrameGeometry) -> Result<()> {
        let scene = self
            .scene
            .as_mut()
            .ok_or_else(|| Error::stage(NAME, "update before prepare"))?;
        if frame.objects.len() != scene.parts.len() {
            return Err(Error::stage(
                NAME,
                format!(
                    "a frame of {} objects for a scene of {}",
                    frame.objects.len(),
                    scene.parts.len()
                ),
            ));
        }
        let poses = Self::poses_of(frame)?;
        let q = self.config.lights;
        let vertices = scene.gpu.vertex_count();
        // v_s max(0, n·ω_i) per vertex and light, made once.
        let weights = match self.posed {
            None => Some(light_weights(vertices, q)?),
            Some(_) => None,
        };
        let posed = self.posed.get_or_insert_with(|| Posed {
            transforms: Vec::new(),
            rotations: Vec::new(),
            radiance: Vec::new(),
            weights: weights.unwrap_or_default(),
            weights_stale: Vec::new(),
            enclosed: Vec::new(),
            uploaded: None,
            maps_ready: false,
            planned: None,
        });
        let fresh = posed.transforms.len() != poses.len();
        if fresh {
            posed.radiance = (0..poses.len()).map(|_| None).collect();
            posed.weights_stale = vec![true; poses.len()];
        }
        let mut moved = fresh;
        for (o, &(t, r)) in poses.iter().enumerate() {
            if fresh || posed.transforms[o] != t {
                moved = true;
            }
            if fresh || posed.rotations[o] != r {
                posed.radiance[o] = None;
                posed.weights_stale[o] = true;
            }
        }
        posed.transforms = poses.iter().map(|p| p.0).collect();
        posed.rotations = poses.iter().map(|p| p.1).collect();
        if moved {
            posed.maps_ready = false;
            // Vertices pressed on another object or buried in a closed one
            // receive nothing, as the reference has it (shadow-core's
            // `contact`): objects in one group cast no maps on each other,
            // and the paper has no rule for one sunk into another.
            let start = Instant::now();
            let closed: Vec<bool> = scene.parts.iter().map(|p| p.mesh.is_closed()).collect();
            let enclosed = Contacts::new(frame, &closed)?.enclosed_vertices();
            if enclosed != posed.enclosed {
                posed.enclosed = enclosed;
                posed.uploaded = None;
            }
            self.profile.seconds(
                Stage::Update,
                "pressed and buried vertices (CPU)",
                start.elapsed().as_secs_f64(),
            );
            // The groups follow the poses (§4.2.3 clusters the occluders
            // that are near each other, wherever they are now): objects
            // that came together or apart are regrouped, and no map of the
            // old groups is kept.
            if matches!(self.config.grouping, Grouping::Overlapping { .. }) {
                let start = Instant::now();
                let bounds = world_bounds(&scene.parts, &posed.transforms);
                let groups = Groups::new(&self.config.grouping, &bounds)?;
                if groups != scene.groups {
                    scene.groups = groups;
                    posed.planned = None;
                }
                self.profile.seconds(
                    Stage::Update,
                    "occluder groups (CPU)",
                    start.elapsed().as_secs_f64(),
                );
            }
        }
        let objects: Vec<GpuObject> = scene
            .parts
            .iter()
            .zip(&posed.transforms)
            .zip(&scene.groups.of_object)
            .map(|((part, t), &g)| GpuObject::new(Mat4::from(*t), &part.material, g))
            .collect();
        scene.gpu.set_objects(&objects)
    }
}

/// The light weights of `vertices` vertices under `q` lights, zeroed:
/// refused, not aborted, where memory cannot hold them.
fn light_weights(vertices: usize, q: usize) -> Result<Vec<f32>> {
    let count = vertices.saturating_mul(q);
    let mut weights = Vec::new();
    weights.try_reserve_exact(count).map_err(|_| {
        Error::config(
            NAME,
            format!(
                "q = {q} area lights need {} bytes of light weights for the scene's \
                 {vertices} vertices, more than this machine's memory gives",
                (count as u64).saturating_mul(4)
            ),
        )
    })?;
    weights.resize(count, 0.0);
    Ok(weights)
}

/// A rigid transform's rotation: refused, naming what is wrong, unless the
/// transform is finite, turns without mirroring and scales evenly (to 1e-3
/// of its scale), the only poses under which the precomputed
/// self-shadowing holds. The rotation is re-normalized, so that the SH
/// rotations built from it always exist.
pub(super) fn rigid(name: &str, t: Affine3A) -> Result<(Affine3A, Mat3)> {
    let refuse = |what: String| {
        Err(Error::InvalidScene(format!(
            "{NAME}: object {name} {what}, which changes its self-shadowing"
        )))
    };
    let m = Mat3::from(t.matrix3);
    let det = m.determinant();
    if !(m.is_finite() && t.translation.is_finite() && det.is_finite()) {
        return refuse("has a pose that is not finite".into());
    }
    if det.abs() < f32::MIN_POSITIVE {
        return refuse(format!("has a pose of zero scale (determinant {det})"));
    }
    if det < 0.0 {
        return refuse(format!("is mirrored (determinant {det})"));
    }
    let r = m * det.cbrt().recip();
    let gram = r.transpose() * r - Mat3::IDENTITY;
    if gram.to_cols_array().iter().any(|e| e.abs() > 2e-3) {
        let lengths = [m.x_axis, m.y_axis, m.z_axis].map(|c| c.length());
        return refuse(format!(
            "is sheared or scaled unevenly (columns {lengths:?} long, {:.3} from orthogonal)",
            gram.to_cols_array()
                .iter()
                .fold(0.0f32, |a, e| a.max(e.abs()))
        ));
    }
    Ok((t, Mat3::from_quat(Quat::from_mat3(&r).normalize())))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use shadow_core::sh::ShRotation;

    use super::*;

    fn refusal(t: Affine3A) -> String {
        match rigid("box", t) {
            Err(Error::InvalidScene(message)) => message,
            other => panic!("{other:?}"),
        }
    }

    /// Zero scale gave a NaN rotation, a shear with equal column lengths a
    /// non-unit quaternion (both panicked in the SH rotation), a mirror was
    /// called uneven scaling.
    /// Light weights beyond memory are a configuration error, not an abort.
    #[test]
    fn light_weights_beyond_memory_are_refused() {
        assert_eq!(light_weights(3, 2).unwrap(), vec![0.0; 6]);
        let refused = light_weights(usize::MAX / 2, 256);
        assert!(
            matches!(refused, Err(Error::InvalidConfig { .. })),
            "{refused:?}"
        );
    }

    #[test]
    fn poses_that_are_not_rigid_are_refused_by_what_they_are() {
        assert!(refusal(Affine3A::from_scale(Vec3::ZERO)).contains("zero scale"));
        let shear =
            Affine3A::from_mat3(Mat3::from_cols(Vec3::X, Vec3::new(0.6, 0.8, 0.0), Vec3::Z));
        assert!(refusal(shear).contains("sheared"), "{}", refusal(shear));
        let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        assert!(refusal(mirror).contains("mirrored"));
        assert!(refusal(Affine3A::from_scale(Vec3::new(1.0, 2.0, 1.0))).contains("unevenly"));
        let nan = Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
        assert!(refusal(nan).contains("not finite"));
    }

    /// Every accepted pose, however large, small or turned, gives a rotation
    /// the SH rotations accept.
    #[test]
    fn rigid_poses_give_proper_rotations_at_any_scale() {
        for scale in [1e-7, 1.0, 3.5, 1e7] {
            for turn in [0.0, 0.3, 2.9] {
                let rotation = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), turn);
                let t = Affine3A::from_scale_rotation_translation(
                    Vec3::splat(scale),
                    rotation,
                    Vec3::new(1e4, 0.0, -3.0),
                );
                let (_, r) = rigid("box", t).unwrap();
                assert!(
                    r.abs_diff_eq(Mat3::from_quat(rotation), 1e-5),
                    "{scale} {turn}"
                );
                assert!(ShRotation::from_mat3(crate::DIFFUSE_ORDER, r).is_some());
            }
        }
    }
}
