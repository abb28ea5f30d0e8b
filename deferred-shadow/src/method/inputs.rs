//! The inputs of `relight` and `update`: the area lights and the poses,
//! each marking stale what it changes.

use std::time::Instant;

use glam::{Affine3A, Mat3, Mat4};
use shadow_core::{Capability, Environment, Error, FrameGeometry, Result, Stage};

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
        let posed = self.posed.get_or_insert_with(|| Posed {
            transforms: Vec::new(),
            rotations: Vec::new(),
            radiance: Vec::new(),
            weights: vec![0.0; vertices * q],
            weights_stale: Vec::new(),
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

/// A rigid transform's rotation, refused unless it scales evenly.
pub(super) fn rigid(name: &str, t: Affine3A) -> Result<(Affine3A, Mat3)> {
    let (scale, rotation, _) = t.to_scale_rotation_translation();
    if scale.max_element() > scale.min_element() * (1.0 + 1e-3) {
        return Err(Error::InvalidScene(format!(
            "{NAME}: object {name} is scaled unevenly ({scale}), which changes its self-shadowing"
        )));
    }
    Ok((t, Mat3::from_quat(rotation)))
}
