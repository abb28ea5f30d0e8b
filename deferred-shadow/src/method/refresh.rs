//! What depends on the poses and the lights, brought up to date: the
//! self-shadowed radiance, the light weights and the occlusion maps.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Vec3};
use shadow_core::{Aabb, Result, Stage};

use super::{DeferredShadow, Part, SelfRadiance, Shading};
use crate::gpu::PlacedObject;
use crate::groups::posed_bounds;
use crate::maps::Plan;
use crate::transfer::{Lighting, diffuse, glossy};

impl DeferredShadow {
    /// Brings everything that depends on the poses and the lights up to
    /// date on the CPU and in GPU buffers; true when the maps must be
    /// (re)drawn, which the caller marks when it has ([`Self::maps_drawn`]).
    pub(super) fn refresh(&mut self, stage: Stage) -> Result<bool> {
        let (Some(scene), Some(lit), Some(posed)) = (&mut self.scene, &self.lit, &mut self.posed)
        else {
            return Ok(false);
        };
        let q = lit.gpu.len();
        let start = Instant::now();
        for (o, part) in scene.parts.iter().enumerate() {
            if posed.radiance[o].is_none() {
                posed.radiance[o] = Some(self_terms(part, &lit.lighting, posed.rotations[o]));
                posed.uploaded = None;
            }
        }
        let self_seconds = start.elapsed().as_secs_f64();
        let start = Instant::now();
        for (o, part) in scene.parts.iter().enumerate() {
            if posed.weights_stale[o] {
                let to_model = posed.rotations[o].transpose();
                let directions: Vec<Vec3> = lit
                    .lights
                    .iter()
                    .map(|l| (to_model * l.direction).normalize())
                    .collect();
                let range =
                    part.first_vertex * q..(part.first_vertex + part.mesh.vertex_count()) * q;
                part.transfer.expand(&directions, &mut posed.weights[range]);
                posed.weights_stale[o] = false;
                posed.uploaded = None;
            }
        }
        let weight_seconds = start.elapsed().as_secs_f64();
        self.profile
            .seconds(stage, "self-shadowed radiance (CPU)", self_seconds);
        self.profile
            .seconds(stage, "light weights (CPU)", weight_seconds);
        if posed.maps_ready {
            return Ok(false);
        }
        let start = Instant::now();
        let bounds = world_bounds(&scene.parts, &posed.transforms);
        let plan = Plan::new(&lit.gpu, &bounds, &scene.groups, self.config.map_resolution);
        // Refused before the masks are made, as before anything is allocated.
        scene.gpu.check_plan(&plan)?;
        // Maps between groups that did not move since they were drawn are
        // kept.
        let reuse = match &posed.planned {
            Some((previous, transforms)) => {
                let mut moved = vec![false; scene.groups.len()];
                for (o, (now, then)) in posed.transforms.iter().zip(transforms).enumerate() {
                    if now != then {
                        moved[scene.groups.of_object[o] as usize] = true;
                    }
                }
                plan.reuse(previous, &moved)
            }
            None => vec![None; plan.maps.len()],
        };
        let positions: Vec<Vec3> = scene
            .parts
            .iter()
            .zip(&posed.transforms)
            .flat_map(|(part, t)| part.mesh.positions().iter().map(|p| t.transform_point3(*p)))
            .collect();
        let masks = plan.masks(
            &lit.gpu,
            &positions,
            &scene.triangles,
            &scene.groups.of_object,
        );
        let objects: Vec<PlacedObject> = scene
            .groups
            .of_object
            .iter()
            .zip(&posed.transforms)
            .map(|(&group, t)| PlacedObject {
                group,
                scale: t.matrix3.x_axis.length(),
            })
            .collect();
        if let Err(e) = scene.gpu.set_plan(&plan, &masks, &objects, &reuse) {
            // The maps on the GPU may be partly this plan's: keep none.
            posed.planned = None;
            return Err(e);
        }
        self.profile
            .seconds(stage, "map planning (CPU)", start.elapsed().as_secs_f64());
        self.profile
            .count(stage, "occlusion maps", plan.maps.len() as u64);
        self.profile
            .count(stage, "occlusion map texels", plan.texels());
        self.profile.count(
            stage,
            "occlusion maps drawn",
            reuse.iter().filter(|r| r.is_none()).count() as u64,
        );
        posed.planned = Some((plan, posed.transforms.clone()));
        Ok(true)
    }

    /// After the maps of [`Self::refresh`] were drawn (`drawn`), or failed
    /// to be: they match the poses and lights, or the GPU may hold some of
    /// them and none is kept.
    fn maps_drawn(&mut self, drawn: bool) {
        if let Some(posed) = &mut self.posed {
            posed.maps_ready = drawn;
            if !drawn {
                posed.planned = None;
            }
        }
    }

    /// [`Self::refresh`], then the maps recorded into `encoder` if needed.
    pub(super) fn record_refresh(
        &mut self,
        stage: Stage,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        if self.refresh(stage)? {
            let recorded = self.prepared()?.gpu.record_maps(encoder);
            self.maps_drawn(recorded.is_ok());
            recorded?;
        }
        Ok(())
    }

    /// [`Self::refresh`] and the maps drawn, waiting for the GPU.
    pub(super) fn run_refresh(&mut self, stage: Stage) -> Result<()> {
        if self.refresh(stage)? {
            let start = Instant::now();
            let ctx = Arc::clone(&self.ctx);
            let gpu = &self.prepared()?.gpu;
            let drawn = ctx.run("deferred-shadow: occlusion maps", |encoder| {
                gpu.record_maps(encoder)
            });
            self.maps_drawn(drawn.is_ok());
            drawn?;
            self.profile
                .seconds(stage, "occlusion maps (GPU)", start.elapsed().as_secs_f64());
        }
        Ok(())
    }
}

/// The self-shadowed radiance of `part` turned by `rotation`, the
/// view-dependent part left for later.
fn self_terms(part: &Part, lighting: &Lighting, rotation: Mat3) -> SelfRadiance {
    match &part.shading {
        Shading::Glossy {
            diffuse,
            specular,
            lobe,
        } => SelfRadiance::Glossy {
            vertices: glossy(lighting, &part.transfer.rotated(rotation), *diffuse, lobe),
            specular: *specular,
        },
        Shading::Diffuse { albedo } => {
            SelfRadiance::Diffuse(diffuse(lighting, &part.transfer, rotation, *albedo))
        }
    }
}

/// World-space bounds of every part under `transforms`.
pub(super) fn world_bounds(parts: &[Part], transforms: &[Affine3A]) -> Vec<Aabb> {
    parts
        .iter()
        .zip(transforms)
        .map(|(part, t)| posed_bounds(part.bounds, t))
        .collect()
}
