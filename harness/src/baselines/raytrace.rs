//! The ray-tracing baseline: the reference's own Monte-Carlo estimator at a low,
//! fixed sample count — what a user would reach for today instead of any of the
//! papers. A method is worth its complexity where it beats this at equal error
//! (DESIGN.md, "Scoring").

use glam::Vec3;
use indicatif::ProgressBar;
use shadow_core::{
    Camera, Capabilities, Environment, Error, FrameGeometry, Image, Result, Scene, ShadowMethod,
    VertexRadiance, bvh::SceneBvh, environment::EnvironmentSampler,
};

use crate::reference::{self, Estimator, ReferenceSettings};

/// Monte-Carlo ray tracing with `iterations` MIS iterations per point (two
/// shadow rays each at most). Its images trace every pixel, or, made with
/// [`RayTrace::per_vertex`], interpolate the vertices' results as the
/// per-vertex methods do.
pub struct RayTrace {
    name: String,
    settings: ReferenceSettings,
    per_pixel: bool,
    scene: Option<Scene>,
    frame: Option<(FrameGeometry, SceneBvh)>,
    sampler: Option<EnvironmentSampler>,
}

impl RayTrace {
    /// The seed of the harness's `raytrace` settings.
    pub const SEED: u64 = 0xba5e;

    /// Images traced per pixel.
    pub fn new(iterations: u32, seed: u64) -> RayTrace {
        RayTrace {
            name: format!("raytrace:{iterations}"),
            settings: ReferenceSettings::fixed(iterations, seed),
            per_pixel: true,
            scene: None,
            frame: None,
            sampler: None,
        }
    }

    /// Images interpolated from the vertices' results.
    pub fn per_vertex(iterations: u32, seed: u64) -> RayTrace {
        RayTrace {
            name: format!("raytrace:{iterations}:vertex"),
            per_pixel: false,
            ..RayTrace::new(iterations, seed)
        }
    }

    fn ready(&self) -> Result<(&Scene, &FrameGeometry, Estimator<'_>)> {
        let scene = self
            .scene
            .as_ref()
            .ok_or_else(|| Error::stage(&self.name, "shade before prepare"))?;
        let (frame, bvh) = self
            .frame
            .as_ref()
            .ok_or_else(|| Error::stage(&self.name, "shade before update"))?;
        let sampler = self
            .sampler
            .as_ref()
            .ok_or_else(|| Error::stage(&self.name, "shade before relight"))?;
        Ok((
            scene,
            frame,
            Estimator {
                bvh,
                sampler,
                unoccluded: None,
            },
        ))
    }
}

impl ShadowMethod for RayTrace {
    fn name(&self) -> &str {
        &self.name
    }

    /// Any scene; no export (its result is radiance, not visibility).
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            per_pixel: self.per_pixel,
            export: false,
            ..Capabilities::ALL
        }
    }

    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.scene = Some(scene.clone());
        self.frame = None;
        Ok(())
    }

    /// Builds the BVH of the frame: all the visibility work that can be done
    /// before rays are traced.
    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        self.frame = Some((frame.clone(), SceneBvh::build(frame)?));
        Ok(())
    }

    /// Builds the environment's sampling tables.
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.sampler = Some(EnvironmentSampler::new(environment));
        Ok(())
    }

    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        let (scene, frame, estimator) = self.ready()?;
        let points = reference::vertex_points(scene, frame, eye);
        let est = reference::estimate(&points, &estimator, &self.settings, &ProgressBar::hidden());
        Ok(reference::split_per_object(frame, &est))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        if !self.per_pixel {
            let shading = self.shade(camera.eye)?;
            let (_, frame, _) = self.ready()?;
            return shadow_core::raster::render_vertex_colors(camera, frame, &shading.radiance);
        }
        let (scene, frame, estimator) = self.ready()?;
        let points = reference::pixel_points(scene, frame, estimator.bvh, camera);
        Ok(reference::image_from_points(
            camera,
            &points,
            &estimator,
            &self.settings,
            &ProgressBar::hidden(),
        )
        .image)
    }
}
