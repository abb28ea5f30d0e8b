//! The deferred pass (§4.2, §6.2.2–6.2.3): the visible surface of a camera
//! (position bits and triangle per pixel), then at each visible pixel, or
//! at each vertex, the self-shadowed radiance less what the occluders take
//! away through the occlusion maps.

use glam::{Mat4, Vec3, Vec4};
use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::{
    compute_pipeline, entry, group, group_layout, storage, texture, uniform, written_texture,
};
use shadow_core::gpu::buffer::{blank, upload};
use shadow_core::gpu::depth::DEPTH_FORMAT;
use shadow_core::gpu::wgsl::Source;
use shadow_core::{Camera, raster::reversed_clip_from_world};

use super::map_pass::MapPass;
use super::scene::{Scene, pulled_pipeline, shader};
use crate::Config;

shadow_core::wgsl_struct! {
    /// A recording's parameters of the deferred pass, as deferred.wgsl
    /// reads them.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct Params {
        /// The eye; w: a pixel's width at unit distance from it.
        eye: Vec4,
        lights: u32,
        self_visibility: u32,
        vertices: u32,
        width: u32,
        height: u32,
        /// Floats per vertex in `shading`: L_s (4), then one weight per
        /// light.
        stride: u32,
        /// Where the triangles' masks start in `culling`.
        masks: u32,
        /// 1: the outgoing light's loss is evaluated per 2×2 block of
        /// pixels and shared ([`Config::blocks`]).
        blocks: u32,
    }
}

shadow_core::wgsl_struct! {
    /// The camera of the visible surface, as gbuffer.wgsl reads it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct View {
        clip_from_world: Mat4,
    }
}

/// The visible surface: position bits and triangle id.
const SURFACE: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

/// The image the pass writes: radiance, and 1 in alpha where a surface is
/// seen.
const IMAGE: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Targets of one image size.
pub(super) struct Targets {
    width: u32,
    height: u32,
    surface: wgpu::TextureView,
    depth: wgpu::TextureView,
    image: wgpu::Texture,
    /// deferred.wgsl's `Block` (two `vec4`) per 2×2 block of pixels.
    blocks: wgpu::Buffer,
}

/// What a recording of the deferred pass shades: the vertices (the image
/// targets bound unused), or an image of `width` × `height` whose pixels
/// are `pixel` wide at unit distance from the eye.
#[derive(Clone, Copy, Debug)]
enum Target {
    Vertices,
    Image { width: u32, height: u32, pixel: f32 },
}

/// Blocks of 2×2 pixels across and down an image.
fn blocks(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(2), height.div_ceil(2))
}

impl Targets {
    fn new(ctx: &GpuContext, width: u32, height: u32) -> Targets {
        let texture =
            |label, format, usage| ctx.create_texture_2d(label, (width, height), format, usage);
        let attach = wgpu::TextureUsages::RENDER_ATTACHMENT;
        Targets {
            width,
            height,
            surface: texture(
                "visible surface",
                SURFACE,
                attach | wgpu::TextureUsages::TEXTURE_BINDING,
            )
            .create_view(&Default::default()),
            depth: texture("depth", DEPTH_FORMAT, attach).create_view(&Default::default()),
            image: texture(
                "image",
                IMAGE,
                wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            ),
            blocks: {
                let (wide, high) = blocks(width, height);
                blank(
                    ctx,
                    "blocks",
                    32 * u64::from(wide) * u64::from(high),
                    wgpu::BufferUsages::STORAGE,
                )
            },
        }
    }
}

/// The visible-surface and deferred pipelines, the image's targets and the
/// per-vertex radiance.
pub(super) struct DeferredPass {
    surface: wgpu::RenderPipeline,
    surface_layout: wgpu::BindGroupLayout,
    /// L_o at one pixel of each 2×2 block, then the pixels.
    blocks: wgpu::ComputePipeline,
    pixels: wgpu::ComputePipeline,
    vertices: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    /// One `vec4` per vertex: radiance, and 1 in w.
    pub vertex_radiance: wgpu::Buffer,
    /// The image's targets (1×1 until an image is recorded).
    targets: Targets,
    self_visibility: bool,
    /// [`Config::blocks`].
    blocks_on: bool,
}

impl DeferredPass {
    pub fn new(ctx: &GpuContext, vertex_count: u32, config: &Config) -> DeferredPass {
        let vertex = wgpu::ShaderStages::VERTEX;
        let cs = wgpu::ShaderStages::COMPUTE;
        let surface_body = Source::new()
            .declare::<View>()
            .body(include_str!("../shaders/gbuffer.wgsl"));
        let surface_module = shader(ctx, "visible surface", surface_body);
        let surface_layout = group_layout(
            ctx,
            "visible surface",
            &[
                uniform(0, vertex),
                storage(1, true, vertex),
                storage(2, true, vertex),
                storage(3, true, vertex),
            ],
        );
        let depth = wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            // Reversed depth (`reversed_clip_from_world`): nearer is greater.
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        };
        let surface = pulled_pipeline(
            ctx,
            &surface_layout,
            &surface_module,
            ("surface", "visible"),
            Some(SURFACE),
            Some(depth),
        );

        let deferred_body = Source::new()
            .declare::<Params>()
            .body(include_str!("../shaders/deferred.wgsl"));
        let module = shader(ctx, "deferred", deferred_body);
        let mut entries = vec![
            uniform(0, cs),
            storage(1, true, cs),
            storage(2, true, cs),
            storage(3, true, cs),
            uniform(4, cs),
        ];
        entries.extend((5..=8).map(|b| storage(b, true, cs)));
        entries.push(texture(9, wgpu::TextureSampleType::Uint, cs));
        entries.push(written_texture(10, IMAGE, cs));
        entries.push(storage(11, false, cs));
        let layout = group_layout(ctx, "deferred", &entries);
        DeferredPass {
            surface,
            surface_layout,
            blocks: compute_pipeline(ctx, &layout, &module, "at_blocks"),
            pixels: compute_pipeline(ctx, &layout, &module, "at_pixels"),
            vertices: compute_pipeline(ctx, &layout, &module, "at_vertices"),
            layout,
            vertex_radiance: blank(
                ctx,
                "vertex radiance",
                16 * vertex_count as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            ),
            targets: Targets::new(ctx, 1, 1),
            self_visibility: config.self_visibility,
            blocks_on: config.blocks,
        }
    }

    /// The last image: radiance and 1 in alpha where a surface is seen,
    /// zero elsewhere.
    pub fn image(&self) -> &wgpu::Texture {
        &self.targets.image
    }

    /// New targets for a `width` × `height` image, unless the current ones
    /// are that size; [`DeferredPass::use_targets`] puts them in place once
    /// the device has made them without error.
    pub fn resized(&self, ctx: &GpuContext, width: u32, height: u32) -> Option<Targets> {
        ((self.targets.width, self.targets.height) != (width, height))
            .then(|| Targets::new(ctx, width, height))
    }

    pub fn use_targets(&mut self, targets: Targets) {
        self.targets = targets;
    }

    /// The deferred pass's bindings, with this recording's parameters for
    /// `eye` and `target`.
    fn group(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        maps: &MapPass,
        eye: Vec3,
        target: Target,
    ) -> wgpu::BindGroup {
        let (width, height, pixel_angle) = match target {
            Target::Vertices => (0, 0, 0.0),
            Target::Image {
                width,
                height,
                pixel,
            } => (width, height, pixel),
        };
        let params = Params {
            eye: eye.extend(pixel_angle),
            lights: scene.light_count,
            self_visibility: self.self_visibility as u32,
            vertices: scene.vertex_count,
            width,
            height,
            stride: 4 + scene.light_count,
            masks: maps.masks_offset,
            blocks: self.blocks_on as u32,
        };
        let params = upload(
            ctx,
            "deferred parameters",
            &[params],
            wgpu::BufferUsages::UNIFORM,
        );
        let image = self.targets.image.create_view(&Default::default());
        // deferred.wgsl's `written`: the vertices' radiance, or the image's
        // blocks.
        let written = match target {
            Target::Vertices => &self.vertex_radiance,
            Target::Image { .. } => &self.targets.blocks,
        };
        group(
            ctx,
            "deferred",
            &self.layout,
            &[
                entry(0, params.as_entire_binding()),
                entry(1, scene.vertices.as_entire_binding()),
                entry(2, scene.triangles.as_entire_binding()),
                entry(3, scene.objects.as_entire_binding()),
                entry(4, scene.lights.as_entire_binding()),
                entry(5, maps.maps.as_entire_binding()),
                entry(6, maps.culling.as_entire_binding()),
                entry(7, maps.blurred.buffer().as_entire_binding()),
                entry(8, scene.shading.as_entire_binding()),
                entry(9, wgpu::BindingResource::TextureView(&self.targets.surface)),
                entry(10, wgpu::BindingResource::TextureView(&image)),
                entry(11, written.as_entire_binding()),
            ],
        )
    }

    /// The radiance of every vertex toward `eye`, into
    /// [`DeferredPass::vertex_radiance`].
    pub fn record_vertices(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        maps: &MapPass,
        encoder: &mut wgpu::CommandEncoder,
        eye: Vec3,
    ) {
        let group = self.group(ctx, scene, maps, eye, Target::Vertices);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("deferred pass, vertices"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.vertices);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(scene.vertex_count.div_ceil(64), 1, 1);
    }

    /// The visible surface of `camera`'s image (targets of its size, made
    /// with [`DeferredPass::resize`]) and the deferred pass over it.
    pub fn record_image(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        maps: &MapPass,
        encoder: &mut wgpu::CommandEncoder,
        (camera, near): (&Camera, f32),
    ) {
        let targets = &self.targets;
        let view = View {
            clip_from_world: reversed_clip_from_world(camera, near),
        };
        let view = upload(ctx, "view", &[view], wgpu::BufferUsages::UNIFORM);
        let surface_group = group(
            ctx,
            "visible surface",
            &self.surface_layout,
            &[
                entry(0, view.as_entire_binding()),
                entry(1, scene.vertices.as_entire_binding()),
                entry(2, scene.triangles.as_entire_binding()),
                entry(3, scene.objects.as_entire_binding()),
            ],
        );
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("visible surface"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &targets.surface,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &targets.depth,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.surface);
            pass.set_bind_group(0, &surface_group, &[]);
            pass.draw(0..3 * scene.triangle_count(), 0..1);
        }
        let target = Target::Image {
            width: camera.width,
            height: camera.height,
            pixel: 2.0 * (0.5 * camera.fov_y).tan() / camera.height as f32,
        };
        let group = self.group(ctx, scene, maps, camera.eye, target);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("deferred pass, pixels"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &group, &[]);
        if self.blocks_on {
            let (wide, high) = blocks(camera.width, camera.height);
            pass.set_pipeline(&self.blocks);
            pass.dispatch_workgroups(wide.div_ceil(8), high.div_ceil(8), 1);
        }
        pass.set_pipeline(&self.pixels);
        pass.dispatch_workgroups(camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
    }
}
