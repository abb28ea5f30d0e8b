//! The method's GPU side: the scene's vertices and triangles ([`scene`]),
//! the occlusion maps, rendered into an atlas batch by batch and blurred
//! into one array ([`map_pass`]), and the visible-surface pass and the
//! deferred pass, per pixel and per vertex ([`deferred_pass`]).
//!
//! Vertices are pulled from storage buffers in every shader (no vertex
//! buffers): a triangle's corners are `triangles[t]` (x, y, z, its object in
//! w), model-space positions carry their object's index in w, and each
//! object's pose is a matrix of `objects`. Moving an object uploads the
//! matrices; nothing else.
//!
//! # Uploads
//!
//! Every upload from the CPU (poses, lights, the plan of the maps, the
//! per-vertex shading, a recording's camera and parameters) goes into a
//! buffer made for it, written by `queue.write_buffer`: that lands before
//! the next submission, and a buffer that commands already recorded read is
//! never written again. Several recordings into one encoder
//! ([`shadow_core::gpu::GpuStages`]: two cameras, a render and a shade)
//! each read their own data; what the GPU writes (maps, images) is ordered
//! by the encoder itself.
//!
//! # Errors
//!
//! Every method that creates or writes a resource runs inside
//! [`GpuContext::capture`], so that a validation or out-of-memory error is
//! that call's [`Error::Gpu`] on any device, never a message on standard
//! error (the device [`GpuContext::new`] opens) or a panic (wgpu's default
//! handler on a host's device). Plans larger than a storage buffer of the
//! device may hold are refused before anything is allocated
//! ([`check_storage`]).

mod deferred_pass;
mod map_pass;
mod scene;

use std::sync::Arc;

use bytemuck::Zeroable;
use glam::{Vec3, Vec4};
use shadow_core::gpu::{
    GpuContext,
    buffer::{storage_limit, upload},
};
use shadow_core::{Camera, Error, Result};

use crate::Config;
use crate::config::MAX_LIGHTS;
use crate::maps::{GpuLight, MapWindow, Plan};
use deferred_pass::DeferredPass;
use map_pass::MapPass;
pub use map_pass::{PlacedObject, check_storage};
use scene::Scene;
pub use scene::{Geometry, GpuObject, LEVELS};

/// Pipelines and buffers.
pub struct Gpu {
    ctx: Arc<GpuContext>,
    scene: Scene,
    maps: MapPass,
    deferred: DeferredPass,
}

impl Gpu {
    /// Pipelines for `config`, and the scene's geometry uploaded.
    pub fn new(
        ctx: Arc<GpuContext>,
        geometry: &Geometry,
        objects: &[GpuObject],
        config: &Config,
    ) -> Result<Gpu> {
        let owner = Arc::clone(&ctx);
        ctx.capture("deferred-shadow: pipelines and buffers", || {
            let scene = Scene::new(&ctx, geometry, objects);
            Ok(Gpu {
                maps: MapPass::new(&ctx, config.map_resolution),
                deferred: DeferredPass::new(&ctx, scene.vertex_count, config),
                scene,
                ctx: owner,
            })
        })
    }

    /// Fails with [`Error::InvalidConfig`] when the maps of `plan`, or the
    /// masks of its lights, would not fit in one storage buffer of the
    /// device ([`check_storage`]).
    pub fn check_plan(&self, plan: &Plan) -> Result<()> {
        check_storage(
            self.scene.light_count,
            self.maps.resolution(),
            (plan.maps.len(), plan.texels()),
            2 * plan.ranges.len(),
            self.scene.triangle_count() as usize,
            &self.ctx.device.limits(),
        )
    }

    /// [`check_shading`] on this device.
    pub fn check_shading(&self, lights: usize) -> Result<()> {
        check_shading(
            lights,
            self.scene.vertex_count as u64,
            &self.ctx.device.limits(),
        )
    }

    /// Maps of the current plan.
    pub fn map_count(&self) -> u32 {
        self.maps.map_count
    }

    /// The objects' poses and materials.
    pub fn set_objects(&mut self, objects: &[GpuObject]) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: object poses", || {
            self.scene.objects = upload(&ctx, "objects", objects, wgpu::BufferUsages::STORAGE);
            Ok(())
        })
    }

    /// At most [`MAX_LIGHTS`] (the shaders' uniform array).
    pub fn set_lights(&mut self, lights: &[GpuLight]) -> Result<()> {
        if lights.len() > MAX_LIGHTS {
            return Err(Error::config(
                "deferred-shadow",
                format!("{} area lights, over {MAX_LIGHTS}", lights.len()),
            ));
        }
        let mut array = [GpuLight::zeroed(); MAX_LIGHTS];
        array[..lights.len()].copy_from_slice(lights);
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: area lights", || {
            self.scene.lights = upload(&ctx, "lights", &array, wgpu::BufferUsages::UNIFORM);
            self.scene.light_count = lights.len() as u32;
            Ok(())
        })
    }

    /// Per vertex, the self-shadowed radiance L_s (rgb and a pad), then the
    /// weight v_s max(0, n·ω_i) of each light (eq. 8's T): `4 + lights`
    /// floats per vertex.
    pub fn set_shading(&mut self, shading: &[f32]) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: vertex shading", || {
            let storage = wgpu::BufferUsages::STORAGE;
            self.scene.shading = upload(&ctx, "vertex shading", shading, storage);
            Ok(())
        })
    }

    /// Takes `plan` for the next [`Gpu::record_maps`]: uploads its windows
    /// and ranges and lays its maps out in atlas batches. `masks` are the
    /// plan's ([`Plan::masks`]), `objects[o]` says object o's group and
    /// scale and `reuse[k]` where map k lies in the previous plan's array
    /// (its first texel) when it is kept.
    /// The plan must fit the device: [`Gpu::check_plan`], which the method
    /// runs before it computes the masks.
    pub fn set_plan(
        &mut self,
        plan: &Plan,
        masks: &[u32],
        objects: &[PlacedObject],
        reuse: &[Option<u32>],
    ) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: occlusion map plan", || {
            self.maps
                .lay_out(&ctx, (plan, masks), &self.scene, objects, reuse);
            Ok(())
        })
    }

    /// Renders and blurs every map of the plan.
    pub fn record_maps(&self, encoder: &mut wgpu::CommandEncoder) -> Result<()> {
        self.ctx.capture("deferred-shadow: occlusion maps", || {
            self.maps.record(&self.ctx, &self.scene, encoder);
            Ok(())
        })
    }

    /// The radiance of every vertex toward `eye`, into
    /// [`Gpu::vertex_radiance`].
    pub fn record_vertices(&self, encoder: &mut wgpu::CommandEncoder, eye: Vec3) -> Result<()> {
        self.ctx
            .capture("deferred-shadow: deferred pass, vertices", || {
                let (ctx, scene, maps) = (&*self.ctx, &self.scene, &self.maps);
                self.deferred
                    .record_vertices(ctx, scene, maps, encoder, eye);
                Ok(())
            })
    }

    /// The visible surface of `camera`'s image and the deferred pass over
    /// it, into [`Gpu::image`]. Targets the device cannot make (an image
    /// wider than its largest texture) are an error before anything is
    /// recorded, and the previous targets are kept.
    pub fn record_image(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        near: f32,
    ) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        let resized = ctx.capture("deferred-shadow: image targets", || {
            Ok(self.deferred.resized(&ctx, camera.width, camera.height))
        })?;
        if let Some(targets) = resized {
            self.deferred.use_targets(targets);
        }
        ctx.capture("deferred-shadow: visible surface and deferred pass", || {
            let (scene, maps) = (&self.scene, &self.maps);
            self.deferred
                .record_image(&ctx, scene, maps, encoder, (camera, near));
            Ok(())
        })
    }

    /// Runs every pipeline once on stand-in data (one map of the first
    /// object, a 4×4 image), so that a driver that compiles shaders on
    /// first use (Mesa's lavapipe does) does so now and not in the first
    /// frame. Leaves no maps planned.
    pub fn warm_up(&mut self) -> Result<()> {
        let plan = Plan {
            maps: vec![MapWindow {
                centre: glam::Vec2::ZERO,
                inverse_side: 1.0,
                spread: 1.5,
                light: 0,
                occluder: 0,
                receiver: 0,
                tile: 0,
                receiver_min: Vec4::splat(-1.0),
                receiver_max: Vec4::ZERO,
                near: 0.0,
                far: 1.0,
                resolution: self.maps.resolution(),
                offset: 0,
            }],
            ranges: vec![[0, 1]],
        };
        let masks = vec![u32::MAX; self.scene.triangle_count() as usize];
        let first = PlacedObject {
            group: 0,
            scale: 1.0,
        };
        self.set_plan(&plan, &masks, &[first], &[None])?;
        self.set_shading(&vec![0.0; 4 * self.scene.vertex_count as usize])?;
        let camera = Camera::new(Vec3::Z, Vec3::ZERO, Vec3::Y, 1.0, 4, 4)?;
        let ctx = Arc::clone(&self.ctx);
        ctx.run("deferred-shadow: warm-up", |encoder| {
            self.record_maps(encoder)?;
            self.record_vertices(encoder, Vec3::Z)?;
            self.record_image(encoder, &camera, 0.1)
        })?;
        self.maps.clear();
        Ok(())
    }

    /// One `vec4` per vertex: radiance, and 1 in w.
    pub fn vertex_radiance(&self) -> &wgpu::Buffer {
        &self.deferred.vertex_radiance
    }

    /// The last image: `Rgba32Float`, radiance and 1 in alpha where a
    /// surface is seen, zero elsewhere.
    pub fn image(&self) -> &wgpu::Texture {
        self.deferred.image()
    }

    pub fn vertex_count(&self) -> usize {
        self.scene.vertex_count as usize
    }
}

/// Refuses, before anything is computed, `lights` area lights whose
/// per-vertex shading data for `vertices` vertices (L_s and a weight per
/// light: (4 + q) `f32` each) does not fit one storage buffer of a device
/// of `limits`, naming the setting, the bytes and the limit.
pub fn check_shading(lights: usize, vertices: u64, limits: &wgpu::Limits) -> Result<()> {
    let limit = storage_limit(limits);
    let bytes = 4 * vertices * (4 + lights as u64);
    if bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "q = {lights} area lights need {bytes} bytes of shading data for the \
                 scene's {vertices} vertices ((4 + q) floats each), and the device binds at \
                 most {limit} bytes in one storage buffer: fewer lights need fewer"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
