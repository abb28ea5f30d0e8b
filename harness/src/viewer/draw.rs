//! The viewer's passes: the environment as the background, then a method's
//! result over it: per-vertex radiance interpolated over the triangles, or a
//! per-pixel image as large as the picture. Everything is linear radiance
//! times an exposure, written to an sRGB target (the encoding of
//! `harness run --images`' PNGs).

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use shadow_core::{
    Camera, Environment, FrameGeometry, Image,
    gpu::{
        GpuContext,
        binding::{entry, group, group_layout, pipeline_layout, storage, texture, uniform},
    },
};

/// The depth buffer's format.
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The uniform block of `draw.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewBlock {
    clip_from_world: [[f32; 4]; 4],
    forward: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    size: [f32; 4],
}

/// What covers the background.
pub enum Content<'a> {
    /// Per-vertex radiance: one `vec4<f32>` per vertex of the frame, the
    /// objects' vertices one after another (`STORAGE`).
    Vertices(&'a wgpu::Buffer),
    /// A per-pixel image as large as the picture (`Rgba32Float`, alpha 1
    /// where covered), scaled by `scale` (the exposure for radiance, 1 for
    /// colours already in display range).
    Pixels {
        texture: &'a wgpu::Texture,
        scale: f32,
    },
    /// Nothing: the environment alone.
    Background,
}

/// How the picture is seen: through `camera` (its size the target's), the
/// perspective's near plane at `near`, radiance times `exposure`.
pub struct Viewpoint<'a> {
    pub camera: &'a Camera,
    pub near: f32,
    pub exposure: f32,
}

/// The pipelines and the scene's buffers on the viewer's device.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    background: wgpu::RenderPipeline,
    mesh: wgpu::RenderPipeline,
    picture: wgpu::RenderPipeline,
    view: wgpu::Buffer,
    environment: Option<wgpu::Texture>,
    positions: Option<wgpu::Buffer>,
    indices: Option<(wgpu::Buffer, u32)>,
    /// A CPU method's per-vertex radiance, uploaded.
    colours: Option<wgpu::Buffer>,
    /// A CPU method's image, or the heat map, uploaded.
    image: Option<wgpu::Texture>,
    depth: Option<wgpu::Texture>,
    /// Bound where the content leaves a binding unused.
    empty_buffer: wgpu::Buffer,
    empty_texture: wgpu::Texture,
}

impl Renderer {
    /// Pipelines drawing into targets of `format` (an sRGB format, so that
    /// the hardware encodes as `images::write_png` does).
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Renderer {
        let fragment = wgpu::ShaderStages::FRAGMENT;
        let vertex = wgpu::ShaderStages::VERTEX;
        let unfilterable = wgpu::TextureSampleType::Float { filterable: false };
        let layout = group_layout(
            ctx,
            "viewer",
            &[
                uniform(0, vertex | fragment),
                texture(1, unfilterable, fragment),
                storage(2, true, vertex),
                storage(3, true, vertex),
                texture(4, unfilterable, fragment),
            ],
        );
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("viewer"),
                source: wgpu::ShaderSource::Wgsl(include_str!("draw.wgsl").into()),
            });
        let pipeline = |vs: &str, fs: &str, depth_write: bool| {
            ctx.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(fs),
                    layout: Some(&pipeline_layout(ctx, &layout)),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some(vs),
                        compilation_options: Default::default(),
                        buffers: &[],
                    },
                    // Both faces: scenes have open meshes.
                    primitive: wgpu::PrimitiveState::default(),
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH,
                        depth_write_enabled: Some(depth_write),
                        depth_compare: Some(if depth_write {
                            wgpu::CompareFunction::Greater
                        } else {
                            wgpu::CompareFunction::Always
                        }),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: wgpu::MultisampleState::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some(fs),
                        compilation_options: Default::default(),
                        targets: &[Some(format.into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
        };
        let background = pipeline("vs_screen", "fs_background", false);
        let mesh = pipeline("vs_mesh", "fs_mesh", true);
        let picture = pipeline("vs_screen", "fs_picture", false);
        let usage = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        let view = ctx.create_buffer_init("viewer view", &[ViewBlock::zeroed()], usage);
        let empty_buffer =
            ctx.create_buffer_init("viewer empty", &[[0f32; 4]], wgpu::BufferUsages::STORAGE);
        let empty_texture = ctx.create_texture_2d(
            "viewer empty",
            (1, 1),
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING,
        );
        Renderer {
            layout,
            background,
            mesh,
            picture,
            view,
            environment: None,
            positions: None,
            indices: None,
            colours: None,
            image: None,
            depth: None,
            empty_buffer,
            empty_texture,
        }
    }

    /// Uploads the environment drawn behind (after each turn).
    pub fn set_environment(&mut self, ctx: &GpuContext, environment: &Environment) {
        let texels: Vec<Vec4> = environment.texels().iter().map(|t| t.extend(1.0)).collect();
        let size = (environment.width() as u32, environment.height() as u32);
        let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let target = ctx.create_texture_2d(
            "viewer environment",
            size,
            wgpu::TextureFormat::Rgba32Float,
            usage,
        );
        write_texels(ctx, &target, &texels, size);
        self.environment = Some(target);
    }

    /// Uploads a frame's positions; the triangles once per scene (their
    /// indices do not change between frames).
    pub fn set_frame(&mut self, ctx: &GpuContext, frame: &FrameGeometry) {
        let positions: Vec<Vec4> = frame
            .objects
            .iter()
            .flat_map(|o| o.positions().iter().map(|p| p.extend(1.0)))
            .collect();
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        match &self.positions {
            Some(buffer) if buffer.size() == (positions.len() * 16) as u64 => {
                ctx.queue
                    .write_buffer(buffer, 0, bytemuck::cast_slice(&positions));
            }
            _ => {
                self.positions =
                    Some(ctx.create_buffer_init("viewer positions", &positions, usage));
                self.indices = None;
            }
        }
        if self.indices.is_none() {
            let mut first = 0u32;
            let mut indices = Vec::new();
            for object in &frame.objects {
                indices.extend(object.triangles().iter().flatten().map(|&v| first + v));
                first += object.vertex_count() as u32;
            }
            let buffer =
                ctx.create_buffer_init("viewer indices", &indices, wgpu::BufferUsages::INDEX);
            self.indices = Some((buffer, indices.len() as u32));
        }
    }

    /// Uploads a CPU method's per-vertex radiance (every object's vertices
    /// one after another) and returns the buffer [`Content::Vertices`] takes.
    pub fn upload_vertices(
        &mut self,
        ctx: &GpuContext,
        radiance: impl Iterator<Item = Vec3>,
    ) -> wgpu::Buffer {
        let values: Vec<Vec4> = radiance.map(|r| r.extend(1.0)).collect();
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let fits = self
            .colours
            .as_ref()
            .is_some_and(|b| b.size() == (values.len().max(1) * 16) as u64);
        if fits {
            let buffer = self.colours.as_ref().expect("checked");
            ctx.queue
                .write_buffer(buffer, 0, bytemuck::cast_slice(&values));
        } else {
            let values = if values.is_empty() {
                vec![Vec4::ZERO]
            } else {
                values
            };
            self.colours = Some(ctx.create_buffer_init("viewer colours", &values, usage));
        }
        self.colours.clone().expect("set above")
    }

    /// Uploads an image (radiance, or colours) and returns the texture
    /// [`Content::Pixels`] takes.
    pub fn upload_image(&mut self, ctx: &GpuContext, image: &Image) -> wgpu::Texture {
        let size = (image.width, image.height);
        let fits = self
            .image
            .as_ref()
            .is_some_and(|t| (t.width(), t.height()) == size);
        if !fits {
            let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
            self.image = Some(ctx.create_texture_2d(
                "viewer image",
                size,
                wgpu::TextureFormat::Rgba32Float,
                usage,
            ));
        }
        let texels: Vec<Vec4> = image
            .pixels
            .iter()
            .zip(&image.covered)
            .map(|(p, &c)| p.extend(if c { 1.0 } else { 0.0 }))
            .collect();
        let target = self.image.clone().expect("set above");
        write_texels(ctx, &target, &texels, size);
        target
    }

    /// Records the picture seen from `viewpoint` into `target` (a view of a
    /// texture of the renderer's format, as large as the camera's image):
    /// the environment behind, `content` over it.
    pub fn record(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        viewpoint: &Viewpoint,
        content: Content,
    ) {
        let Viewpoint {
            camera,
            near,
            exposure,
        } = *viewpoint;
        let Some(environment) = self.environment.clone() else {
            return;
        };
        let forward = (camera.target - camera.eye).normalize();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let half_h = (camera.fov_y * 0.5).tan();
        let half_w = half_h * camera.aspect();
        let picture_scale = match content {
            Content::Pixels { scale, .. } => scale,
            Content::Vertices(_) | Content::Background => 1.0,
        };
        let block = ViewBlock {
            clip_from_world: shadow_core::raster::reversed_clip_from_world(camera, near)
                .to_cols_array_2d(),
            forward: forward.extend(exposure).to_array(),
            right: (right * half_w).extend(picture_scale).to_array(),
            up: (up * half_h).extend(0.0).to_array(),
            size: [
                camera.width as f32,
                camera.height as f32,
                environment.width() as f32,
                environment.height() as f32,
            ],
        };
        ctx.queue
            .write_buffer(&self.view, 0, bytemuck::bytes_of(&block));

        let depth = self.depth_view(ctx, (camera.width, camera.height));
        let (colours, picture) = match content {
            Content::Vertices(buffer) => (buffer, &self.empty_texture),
            Content::Pixels { texture, .. } => (&self.empty_buffer, texture),
            Content::Background => (&self.empty_buffer, &self.empty_texture),
        };
        let positions = self.positions.as_ref().unwrap_or(&self.empty_buffer);
        let environment_view = environment.create_view(&Default::default());
        let picture_view = picture.create_view(&Default::default());
        let bind = group(
            ctx,
            "viewer",
            &self.layout,
            &[
                entry(0, self.view.as_entire_binding()),
                entry(1, wgpu::BindingResource::TextureView(&environment_view)),
                entry(2, positions.as_entire_binding()),
                entry(3, colours.as_entire_binding()),
                entry(4, wgpu::BindingResource::TextureView(&picture_view)),
            ],
        );
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("viewer"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth,
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
        pass.set_bind_group(0, &bind, &[]);
        pass.set_pipeline(&self.background);
        pass.draw(0..3, 0..1);
        match content {
            Content::Vertices(_) => {
                if let Some((indices, count)) = &self.indices {
                    pass.set_pipeline(&self.mesh);
                    pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..*count, 0, 0..1);
                }
            }
            Content::Pixels { .. } => {
                pass.set_pipeline(&self.picture);
                pass.draw(0..3, 0..1);
            }
            Content::Background => {}
        }
    }

    fn depth_view(&mut self, ctx: &GpuContext, size: (u32, u32)) -> wgpu::TextureView {
        let fits = self
            .depth
            .as_ref()
            .is_some_and(|t| (t.width(), t.height()) == size);
        if !fits {
            self.depth = Some(ctx.create_texture_2d(
                "viewer depth",
                size,
                DEPTH,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            ));
        }
        self.depth
            .as_ref()
            .expect("set above")
            .create_view(&Default::default())
    }
}

/// Writes `texels` (`Rgba32Float`, row 0 first) into `target`.
fn write_texels(
    ctx: &GpuContext,
    target: &wgpu::Texture,
    texels: &[Vec4],
    (width, height): (u32, u32),
) {
    ctx.queue.write_texture(
        target.as_image_copy(),
        bytemuck::cast_slice(texels),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * 16),
            rows_per_image: Some(height),
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
}
