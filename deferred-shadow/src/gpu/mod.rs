//! The method's GPU side: the scene's vertices and triangles, the occlusion
//! maps (rendered into an atlas batch by batch and blurred into one array),
//! the visible-surface pass and the deferred pass, per pixel and per vertex.
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

use std::num::NonZeroU64;
use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3, Vec4};
use shadow_core::{
    Brdf, Camera, Error, Mesh, Result,
    gpu::{
        GpuContext,
        uniforms::{dynamic_uniform, storage, uniform},
    },
    raster::clip_from_world,
};

use crate::config::MAX_LIGHTS;
use crate::maps::{GpuLight, MapWindow, Plan};

/// `Object` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuObject {
    pub model: Mat4,
    pub normal: Mat4,
    pub diffuse: Vec4,
    pub specular: Vec4,
}

impl GpuObject {
    /// An object of occluder group `group`.
    pub fn new(model: Mat4, material: &Brdf, group: u32) -> GpuObject {
        let (diffuse, specular) = match *material {
            Brdf::Lambert { albedo } => (albedo.extend(0.0), Vec4::ZERO),
            Brdf::Phong {
                diffuse,
                specular,
                exponent,
            } => (diffuse.extend(0.0), specular.extend(exponent)),
        };
        let normal = Mat4::from_mat3(glam::Mat3::from_mat4(model).inverse().transpose());
        GpuObject {
            model,
            normal,
            diffuse: diffuse.truncate().extend(group as f32),
            specular,
        }
    }
}

/// `Atlas` in maps.wgsl: one batch of maps in the atlas.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct AtlasBlock {
    resolution: u32,
    per_row: u32,
    side: f32,
    first: u32,
}

/// `Params` in deferred.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Params {
    eye: Vec4,
    lights: u32,
    resolution: u32,
    self_visibility: u32,
    vertices: u32,
    width: u32,
    height: u32,
    stride: u32,
    masks: u32,
}

/// The scene's static data, in model space.
pub struct Geometry {
    /// Model-space position (w: the object's index as a float) and normal
    /// of every vertex.
    pub vertices: Vec<[Vec4; 2]>,
    /// Global vertex indices of each triangle's corners, and its object.
    pub triangles: Vec<[u32; 4]>,
    /// Each object's range of triangles.
    pub triangle_ranges: Vec<std::ops::Range<u32>>,
}

impl Geometry {
    /// The meshes of a scene's objects, in order, one after another.
    pub fn new<'a>(meshes: impl IntoIterator<Item = &'a Mesh>) -> Geometry {
        let mut geometry = Geometry {
            vertices: Vec::new(),
            triangles: Vec::new(),
            triangle_ranges: Vec::new(),
        };
        for (o, mesh) in meshes.into_iter().enumerate() {
            let base = geometry.vertices.len() as u32;
            geometry.vertices.extend(
                mesh.positions()
                    .iter()
                    .zip(mesh.normals())
                    .map(|(p, n)| [p.extend(o as f32), n.extend(0.0)]),
            );
            let first = geometry.triangles.len() as u32;
            geometry.triangles.extend(
                mesh.triangles()
                    .iter()
                    .map(|t| [t[0] + base, t[1] + base, t[2] + base, o as u32]),
            );
            geometry
                .triangle_ranges
                .push(first..geometry.triangles.len() as u32);
        }
        geometry
    }
}

/// Maps rendered and blurred in one batch: the atlas holds this many
/// tiles.
#[derive(Clone, Debug, Default, PartialEq)]
struct Batch {
    /// Its first entry in the list of drawn maps.
    first: u32,
    count: u32,
    /// (object, first instance, instance count): the object drawn into the
    /// maps `instances[first..first + count]` name.
    draws: Vec<(usize, u32, u32)>,
}

/// Largest dispatch along y (WebGPU's default limit).
const MAX_DISPATCH: u32 = 65_535;

/// Side of the atlas the maps are rendered into, at most.
const MAX_ATLAS: u32 = 8192;

/// The smallest buffer: larger than any one element a shader binds.
const MIN_BUFFER: u64 = 256;

/// The most bytes one storage buffer may hold on a device of `limits`:
/// the method binds each whole.
fn storage_limit(limits: &wgpu::Limits) -> u64 {
    limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
}

/// Refuses, before anything is allocated, a plan whose storage does not fit
/// a device of `limits`: `maps` occlusion maps of `resolution`² texels, one
/// `f32` each, in one buffer (the paper's q lights times the pairs of
/// occluder and receiving groups, §4.2.2–4.2.3), and a mask word per
/// triangle and light (`triangles` × `lights`, after `ranges` words of map
/// ranges). The [`Error::InvalidConfig`] names the settings (`q`, `map`, as
/// the harness spells them), the bytes they need and the device's limit.
pub fn check_storage(
    lights: u32,
    resolution: u32,
    maps: usize,
    ranges: usize,
    triangles: usize,
    limits: &wgpu::Limits,
) -> Result<()> {
    let limit = storage_limit(limits);
    let what = format!(
        "the device binds at most {limit} bytes in one storage buffer \
         (the smaller of its max_storage_buffer_binding_size and max_buffer_size)"
    );
    let map_bytes = 4 * u64::from(resolution).pow(2) * maps as u64;
    if map_bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "q = {lights} area lights and {resolution}×{resolution}-texel occlusion maps \
                 (map = {resolution}) need {maps} maps on this scene, {map_bytes} bytes, and {what}: \
                 fewer lights, smaller maps or occluders grouped (§4.2.3) need fewer"
            ),
        ));
    }
    let mask_bytes = 4 * (ranges as u64 + triangles as u64 * u64::from(lights));
    if mask_bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "q = {lights} area lights need a mask word per light for each of the scene's \
                 {triangles} triangles, {mask_bytes} bytes, and {what}: fewer lights need fewer"
            ),
        ));
    }
    Ok(())
}

/// A buffer made for `values` (at least [`MIN_BUFFER`] bytes, zero past
/// them), with `usage` and `COPY_DST`: nothing recorded before reads it, so
/// the write, which lands before the next submission, is seen by exactly
/// the commands recorded from now on that bind it.
fn upload<T: Pod>(
    ctx: &GpuContext,
    label: &str,
    values: &[T],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(values);
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (bytes.len() as u64).max(MIN_BUFFER),
        usage: usage | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    if !bytes.is_empty() {
        ctx.queue.write_buffer(&buffer, 0, bytes);
    }
    buffer
}

/// A storage buffer the GPU writes (by shaders, or copies: `COPY_DST`),
/// which grows to fit.
struct Growing {
    buffer: wgpu::Buffer,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl Growing {
    fn new(ctx: &GpuContext, label: &'static str, usage: wgpu::BufferUsages) -> Growing {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        Growing {
            buffer: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: MIN_BUFFER,
                usage,
                mapped_at_creation: false,
            }),
            label,
            usage,
        }
    }

    /// At least `bytes` long (contents lost when it grows): the next power
    /// of two, or what the device binds when that is less.
    fn reserve(&mut self, ctx: &GpuContext, bytes: u64) {
        if self.buffer.size() < bytes {
            let room = bytes
                .next_power_of_two()
                .min(storage_limit(&ctx.device.limits()));
            self.buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: room.max(bytes),
                usage: self.usage,
                mapped_at_creation: false,
            });
        }
    }
}

/// Targets of one image size.
struct Targets {
    width: u32,
    height: u32,
    surface: wgpu::TextureView,
    depth: wgpu::TextureView,
    image: wgpu::Texture,
}

/// Pipelines and buffers.
pub struct Gpu {
    ctx: Arc<GpuContext>,
    cover: wgpu::RenderPipeline,
    cover_layout: wgpu::BindGroupLayout,
    blur_rows: wgpu::ComputePipeline,
    blur_columns: wgpu::ComputePipeline,
    blur_layout: wgpu::BindGroupLayout,
    surface: wgpu::RenderPipeline,
    surface_layout: wgpu::BindGroupLayout,
    pixels: wgpu::ComputePipeline,
    vertices_pipeline: wgpu::ComputePipeline,
    deferred_layout: wgpu::BindGroupLayout,

    vertices: wgpu::Buffer,
    triangles: wgpu::Buffer,
    /// The triangles' global vertex indices, for indexed draws.
    indices: wgpu::Buffer,
    triangle_ranges: Vec<std::ops::Range<u32>>,
    vertex_count: u32,
    objects: wgpu::Buffer,
    lights: wgpu::Buffer,
    maps: wgpu::Buffer,
    /// The maps' ranges per receiving group and light, then the triangles'
    /// masks (deferred.wgsl's `culling`).
    culling: wgpu::Buffer,
    masks_offset: u32,
    instances: wgpu::Buffer,
    blurred: Growing,
    /// The previous frame's maps, from which kept maps are copied.
    previous: Growing,
    /// (previous index, index, count) of each run of kept maps.
    copies: Vec<(u32, u32, u32)>,
    /// The maps drawn, tile after tile.
    drawn: wgpu::Buffer,
    rows: Growing,
    shading: wgpu::Buffer,
    vertex_radiance: wgpu::Buffer,
    coverage: Option<(u32, wgpu::TextureView)>,
    /// The image's targets (1×1 until an image is recorded).
    targets: Targets,

    resolution: u32,
    light_count: u32,
    self_visibility: bool,
    batches: Vec<Batch>,
    /// Maps of the current plan.
    pub map_count: u32,
}

fn shader(ctx: &GpuContext, label: &str, source: &str) -> wgpu::ShaderModule {
    let source = format!("{}\n{source}", include_str!("shaders/common.wgsl"));
    ctx.device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        })
}

fn layout(
    ctx: &GpuContext,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    ctx.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries,
        })
}

fn pipeline_layout(ctx: &GpuContext, layout: &wgpu::BindGroupLayout) -> wgpu::PipelineLayout {
    ctx.device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        })
}

fn compute(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    entry: &str,
) -> wgpu::ComputePipeline {
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout(ctx, layout)),
            module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
}

/// A render pipeline of vertex and fragment entries `entries` pulling its
/// vertices from storage (no vertex buffers), into one `target`.
fn render(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    (vertex, fragment): (&str, &str),
    target: wgpu::TextureFormat,
    depth_stencil: Option<wgpu::DepthStencilState>,
) -> wgpu::RenderPipeline {
    ctx.device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(vertex),
            layout: Some(&pipeline_layout(ctx, layout)),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some(vertex),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module,
                entry_point: Some(fragment),
                compilation_options: Default::default(),
                targets: &[Some(target.into())],
            }),
            multiview_mask: None,
            cache: None,
        })
}

fn texture_entry(
    binding: u32,
    sample_type: wgpu::TextureSampleType,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}

/// The coverage atlas's format: one float per texel, rendered and read.
const COVERAGE: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
/// The visible surface: position bits and triangle id.
const SURFACE: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl Gpu {
    /// Pipelines, and the scene's geometry uploaded.
    pub fn new(
        ctx: Arc<GpuContext>,
        geometry: &Geometry,
        objects: &[GpuObject],
        resolution: u32,
        self_visibility: bool,
    ) -> Result<Gpu> {
        let owner = Arc::clone(&ctx);
        ctx.capture("deferred-shadow: pipelines and buffers", || {
            Ok(Gpu::build(
                owner,
                geometry,
                objects,
                resolution,
                self_visibility,
            ))
        })
    }

    fn build(
        ctx: Arc<GpuContext>,
        geometry: &Geometry,
        objects: &[GpuObject],
        resolution: u32,
        self_visibility: bool,
    ) -> Gpu {
        let c = &*ctx;
        let vertex = wgpu::ShaderStages::VERTEX;
        let cs = wgpu::ShaderStages::COMPUTE;
        let maps_module = shader(c, "occlusion maps", include_str!("shaders/maps.wgsl"));
        let cover_layout = layout(
            c,
            "cover",
            &[
                dynamic_uniform(0, vertex),
                storage(1, true, vertex),
                storage(3, true, vertex),
                uniform(4, vertex),
                storage(5, true, vertex),
                storage(6, true, vertex),
            ],
        );
        let cover = render(
            c,
            &cover_layout,
            &maps_module,
            ("cover", "covered"),
            COVERAGE,
            None,
        );
        let blur_layout = layout(
            c,
            "blur",
            &[
                dynamic_uniform(0, cs),
                storage(5, true, cs),
                texture_entry(7, wgpu::TextureSampleType::Float { filterable: false }, cs),
                storage(8, false, cs),
                storage(9, false, cs),
                storage(10, true, cs),
            ],
        );
        let blur_rows = compute(c, &blur_layout, &maps_module, "blur_rows");
        let blur_columns = compute(c, &blur_layout, &maps_module, "blur_columns");

        let surface_module = shader(c, "visible surface", include_str!("shaders/gbuffer.wgsl"));
        let surface_layout = layout(
            c,
            "visible surface",
            &[
                uniform(0, vertex),
                storage(1, true, vertex),
                storage(2, true, vertex),
                storage(3, true, vertex),
            ],
        );
        let depth = wgpu::DepthStencilState {
            format: DEPTH,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        };
        let surface = render(
            c,
            &surface_layout,
            &surface_module,
            ("surface", "visible"),
            SURFACE,
            Some(depth),
        );

        let deferred_module = shader(c, "deferred", include_str!("shaders/deferred.wgsl"));
        let mut deferred_entries = vec![
            uniform(0, cs),
            storage(1, true, cs),
            storage(2, true, cs),
            storage(3, true, cs),
            uniform(4, cs),
        ];
        deferred_entries.extend((5..=8).map(|b| storage(b, true, cs)));
        deferred_entries.push(texture_entry(9, wgpu::TextureSampleType::Uint, cs));
        deferred_entries.push(wgpu::BindGroupLayoutEntry {
            binding: 10,
            visibility: cs,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::Rgba32Float,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        });
        deferred_entries.push(storage(11, false, cs));
        let deferred_layout = layout(c, "deferred", &deferred_entries);
        let pixels = compute(c, &deferred_layout, &deferred_module, "at_pixels");
        let vertices_pipeline = compute(c, &deferred_layout, &deferred_module, "at_vertices");

        let storage_usage = wgpu::BufferUsages::STORAGE;
        let vertex_count = geometry.vertices.len() as u32;
        let none: &[u32] = &[];
        Gpu {
            vertices: upload(c, "vertices", &geometry.vertices, storage_usage),
            triangles: upload(c, "triangles", &geometry.triangles, storage_usage),
            indices: upload(
                c,
                "indices",
                &geometry
                    .triangles
                    .iter()
                    .flat_map(|t| [t[0], t[1], t[2]])
                    .collect::<Vec<u32>>(),
                wgpu::BufferUsages::INDEX,
            ),
            triangle_ranges: geometry.triangle_ranges.clone(),
            vertex_count,
            objects: upload(c, "objects", objects, storage_usage),
            lights: upload(
                c,
                "lights",
                &[GpuLight::zeroed(); MAX_LIGHTS],
                wgpu::BufferUsages::UNIFORM,
            ),
            maps: upload(c, "maps", none, storage_usage),
            culling: upload(c, "map ranges and masks", none, storage_usage),
            masks_offset: 0,
            instances: upload(c, "map instances", none, storage_usage),
            blurred: Growing::new(
                c,
                "occlusion maps",
                storage_usage | wgpu::BufferUsages::COPY_SRC,
            ),
            previous: Growing::new(
                c,
                "previous occlusion maps",
                storage_usage | wgpu::BufferUsages::COPY_SRC,
            ),
            copies: Vec::new(),
            drawn: upload(c, "maps drawn", none, storage_usage),
            rows: Growing::new(c, "blurred rows", storage_usage),
            shading: upload(c, "vertex shading", none, storage_usage),
            vertex_radiance: c.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("vertex radiance"),
                size: (16 * vertex_count as u64).max(MIN_BUFFER),
                usage: storage_usage | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            coverage: None,
            targets: Targets::new(c, 1, 1),
            cover,
            cover_layout,
            blur_rows,
            blur_columns,
            blur_layout,
            surface,
            surface_layout,
            pixels,
            vertices_pipeline,
            deferred_layout,
            resolution,
            light_count: 0,
            self_visibility,
            batches: Vec::new(),
            map_count: 0,
            ctx,
        }
    }

    /// Fails with [`Error::InvalidConfig`] when the maps of `plan`, or the
    /// masks of its lights, would not fit in one storage buffer of the
    /// device ([`check_storage`]).
    pub fn check_plan(&self, plan: &Plan) -> Result<()> {
        check_storage(
            self.light_count,
            self.resolution,
            plan.maps.len(),
            2 * plan.ranges.len(),
            self.triangle_count() as usize,
            &self.ctx.device.limits(),
        )
    }

    fn triangle_count(&self) -> u32 {
        self.triangle_ranges.last().map_or(0, |r| r.end)
    }

    /// The objects' poses and materials.
    pub fn set_objects(&mut self, objects: &[GpuObject]) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: object poses", || {
            self.objects = upload(&ctx, "objects", objects, wgpu::BufferUsages::STORAGE);
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
            self.lights = upload(&ctx, "lights", &array, wgpu::BufferUsages::UNIFORM);
            self.light_count = lights.len() as u32;
            Ok(())
        })
    }

    /// Per vertex, the self-shadowed radiance L_s (rgb and a pad), then the
    /// weight v_s max(0, n·ω_i) of each light (eq. 8's T): `4 + lights`
    /// floats per vertex.
    pub fn set_shading(&mut self, shading: &[f32]) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: vertex shading", || {
            self.shading = upload(&ctx, "vertex shading", shading, wgpu::BufferUsages::STORAGE);
            Ok(())
        })
    }

    /// Takes `plan` for the next [`Gpu::record_maps`]: uploads its windows
    /// and ranges and lays its maps out in atlas batches. `masks` are the
    /// plan's ([`Plan::masks`]), `groups[o]` is the group of object o and
    /// `reuse[k]` the index in the previous plan of map k when it is kept.
    /// The plan must fit the device: [`Gpu::check_plan`], which the method
    /// runs before it computes the masks.
    pub fn set_plan(
        &mut self,
        plan: &Plan,
        masks: &[u32],
        groups: &[u32],
        reuse: &[Option<u32>],
    ) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.capture("deferred-shadow: occlusion map plan", || {
            self.lay_out(plan, masks, groups, reuse);
            Ok(())
        })
    }

    /// [`Gpu::set_plan`]'s work.
    fn lay_out(&mut self, plan: &Plan, masks: &[u32], groups: &[u32], reuse: &[Option<u32>]) {
        let n = self.resolution;
        let limit = self
            .ctx
            .device
            .limits()
            .max_texture_dimension_2d
            .min(MAX_ATLAS);
        let per_row = (limit / n).max(1);
        let capacity = (per_row * per_row).min(MAX_DISPATCH);
        let count = plan.maps.len() as u32;
        let n2 = (n * n) as u64;
        // Kept maps are copied from the previous frame's array, runs of
        // consecutive maps in one copy each.
        self.copies.clear();
        for (k, old) in (0..count).zip(reuse) {
            let Some(old) = *old else { continue };
            match self.copies.last_mut() {
                Some((from, to, len)) if *from + *len == old && *to + *len == k => *len += 1,
                _ => self.copies.push((old, k, 1)),
            }
        }
        if !self.copies.is_empty() {
            std::mem::swap(&mut self.blurred, &mut self.previous);
        }
        self.map_count = count;
        self.blurred
            .reserve(&self.ctx, 4 * n2 * count.max(1) as u64);
        let drawn: Vec<u32> = (0..count)
            .filter(|&k| reuse[k as usize].is_none())
            .collect();
        let mut maps = plan.maps.clone();
        let mut instances: Vec<u32> = Vec::new();
        self.batches.clear();
        for (b, batch) in drawn.chunks(capacity as usize).enumerate() {
            let first = b as u32 * capacity;
            for (tile, &k) in batch.iter().enumerate() {
                maps[k as usize].tile = tile as u32;
            }
            let mut draws = Vec::new();
            for (object, &group) in groups.iter().enumerate() {
                let start = instances.len() as u32;
                instances.extend(
                    batch
                        .iter()
                        .filter(|&&k| maps[k as usize].occluder == group),
                );
                let drawn = instances.len() as u32 - start;
                if drawn > 0 {
                    draws.push((object, start, drawn));
                }
            }
            self.batches.push(Batch {
                first,
                count: batch.len() as u32,
                draws,
            });
        }
        self.rows.reserve(
            &self.ctx,
            4 * n2 * (drawn.len() as u32).clamp(1, capacity) as u64,
        );
        let storage_usage = wgpu::BufferUsages::STORAGE;
        self.maps = upload(&self.ctx, "maps", &maps, storage_usage);
        let mut culling: Vec<u32> = plan.ranges.iter().flatten().copied().collect();
        self.masks_offset = culling.len() as u32;
        culling.extend_from_slice(masks);
        self.culling = upload(&self.ctx, "map ranges and masks", &culling, storage_usage);
        self.drawn = upload(&self.ctx, "maps drawn", &drawn, storage_usage);
        self.instances = upload(&self.ctx, "map instances", &instances, storage_usage);
        // The atlas: as many tiles as the largest batch needs, square.
        let largest = self.batches.iter().map(|b| b.count).max().unwrap_or(1);
        let tiles = (largest as f64).sqrt().ceil() as u32;
        let side = (tiles * n).min(per_row * n);
        if self.coverage.as_ref().is_none_or(|(s, _)| *s < side) {
            let texture = self.ctx.create_texture_2d(
                "coverage atlas",
                (side, side),
                COVERAGE,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            );
            self.coverage = Some((side, texture.create_view(&Default::default())));
        }
    }

    /// Renders and blurs every map of the plan.
    pub fn record_maps(&self, encoder: &mut wgpu::CommandEncoder) -> Result<()> {
        self.ctx.capture("deferred-shadow: occlusion maps", || {
            self.record_maps_uncaptured(encoder);
            Ok(())
        })
    }

    fn record_maps_uncaptured(&self, encoder: &mut wgpu::CommandEncoder) {
        let Some((side, coverage)) = &self.coverage else {
            return;
        };
        let n = self.resolution;
        // One uniform block per batch, bound at its dynamic offset.
        let stride = u64::from(self.ctx.device.limits().min_uniform_buffer_offset_alignment)
            .max(size_of::<AtlasBlock>() as u64) as usize;
        let mut blocks = vec![0u8; stride * self.batches.len().max(1)];
        for (block, batch) in blocks.chunks_exact_mut(stride).zip(&self.batches) {
            let atlas = AtlasBlock {
                resolution: n,
                per_row: side / n,
                side: *side as f32,
                first: batch.first,
            };
            block[..size_of::<AtlasBlock>()].copy_from_slice(bytemuck::bytes_of(&atlas));
        }
        let atlas = upload(&self.ctx, "atlas", &blocks, wgpu::BufferUsages::UNIFORM);
        let atlas_binding = || {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &atlas,
                offset: 0,
                size: NonZeroU64::new(size_of::<AtlasBlock>() as u64),
            })
        };
        let cover_group = self
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("cover"),
                layout: &self.cover_layout,
                entries: &[
                    entry(0, atlas_binding()),
                    entry(1, self.vertices.as_entire_binding()),
                    entry(3, self.objects.as_entire_binding()),
                    entry(4, self.lights.as_entire_binding()),
                    entry(5, self.maps.as_entire_binding()),
                    entry(6, self.instances.as_entire_binding()),
                ],
            });
        let blur_group = self
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("blur"),
                layout: &self.blur_layout,
                entries: &[
                    entry(0, atlas_binding()),
                    entry(5, self.maps.as_entire_binding()),
                    entry(7, wgpu::BindingResource::TextureView(coverage)),
                    entry(8, self.rows.buffer.as_entire_binding()),
                    entry(9, self.blurred.buffer.as_entire_binding()),
                    entry(10, self.drawn.as_entire_binding()),
                ],
            });
        let bytes = 4 * (n * n) as u64;
        for &(old, new, count) in &self.copies {
            encoder.copy_buffer_to_buffer(
                &self.previous.buffer,
                old as u64 * bytes,
                &self.blurred.buffer,
                new as u64 * bytes,
                count as u64 * bytes,
            );
        }
        for (b, batch) in self.batches.iter().enumerate() {
            let offset = (b * stride) as u32;
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("occluders onto maps"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: coverage,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.cover);
                pass.set_bind_group(0, &cover_group, &[offset]);
                pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
                for &(object, first, count) in &batch.draws {
                    let range = &self.triangle_ranges[object];
                    pass.draw_indexed(3 * range.start..3 * range.end, 0, first..first + count);
                }
            }
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("box blur"),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, &blur_group, &[offset]);
            for pipeline in [&self.blur_rows, &self.blur_columns] {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(n.div_ceil(64), batch.count, 1);
            }
        }
    }

    /// The deferred pass's bindings, with `params` (this recording's) and
    /// the current image targets (the per-vertex pass binds them too,
    /// unused).
    fn deferred_group(&self, params: &wgpu::Buffer) -> wgpu::BindGroup {
        let image = self.targets.image.create_view(&Default::default());
        self.ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("deferred"),
                layout: &self.deferred_layout,
                entries: &[
                    entry(0, params.as_entire_binding()),
                    entry(1, self.vertices.as_entire_binding()),
                    entry(2, self.triangles.as_entire_binding()),
                    entry(3, self.objects.as_entire_binding()),
                    entry(4, self.lights.as_entire_binding()),
                    entry(5, self.maps.as_entire_binding()),
                    entry(6, self.culling.as_entire_binding()),
                    entry(7, self.blurred.buffer.as_entire_binding()),
                    entry(8, self.shading.as_entire_binding()),
                    entry(9, wgpu::BindingResource::TextureView(&self.targets.surface)),
                    entry(10, wgpu::BindingResource::TextureView(&image)),
                    entry(11, self.vertex_radiance.as_entire_binding()),
                ],
            })
    }

    /// A recording's own parameters of the deferred pass.
    fn params(&self, eye: Vec3, width: u32, height: u32) -> wgpu::Buffer {
        let params = Params {
            eye: eye.extend(1.0),
            lights: self.light_count,
            resolution: self.resolution,
            self_visibility: self.self_visibility as u32,
            vertices: self.vertex_count,
            width,
            height,
            stride: 4 + self.light_count,
            masks: self.masks_offset,
        };
        upload(
            &self.ctx,
            "deferred parameters",
            &[params],
            wgpu::BufferUsages::UNIFORM,
        )
    }

    /// The radiance of every vertex toward `eye`, into
    /// [`Gpu::vertex_radiance`].
    pub fn record_vertices(&self, encoder: &mut wgpu::CommandEncoder, eye: Vec3) -> Result<()> {
        self.ctx
            .capture("deferred-shadow: deferred pass, vertices", || {
                let group = self.deferred_group(&self.params(eye, 0, 0));
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("deferred pass, vertices"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.vertices_pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(self.vertex_count.div_ceil(64), 1, 1);
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
        let (width, height) = (camera.width, camera.height);
        if (self.targets.width, self.targets.height) != (width, height) {
            self.targets = self.ctx.capture("deferred-shadow: image targets", || {
                Ok(Targets::new(&self.ctx, width, height))
            })?;
        }
        self.ctx
            .capture("deferred-shadow: visible surface and deferred pass", || {
                self.record_image_uncaptured(encoder, camera, near);
                Ok(())
            })
    }

    fn record_image_uncaptured(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        near: f32,
    ) {
        let targets = &self.targets;
        let view = upload(
            &self.ctx,
            "view",
            &[clip_from_world(camera, near)],
            wgpu::BufferUsages::UNIFORM,
        );
        let surface_group = self
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("visible surface"),
                layout: &self.surface_layout,
                entries: &[
                    entry(0, view.as_entire_binding()),
                    entry(1, self.vertices.as_entire_binding()),
                    entry(2, self.triangles.as_entire_binding()),
                    entry(3, self.objects.as_entire_binding()),
                ],
            });
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
                        load: wgpu::LoadOp::Clear(1.0),
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
            pass.draw(0..3 * self.triangle_count(), 0..1);
        }
        let group = self.deferred_group(&self.params(camera.eye, camera.width, camera.height));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("deferred pass, pixels"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pixels);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
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
                blur: 1.5,
                light: 0,
                occluder: 0,
                receiver: 0,
                tile: 0,
            }],
            ranges: vec![[0, 1]],
        };
        let masks = vec![u32::MAX; self.triangle_count() as usize];
        self.set_plan(&plan, &masks, &[0], &[None])?;
        self.set_shading(&vec![0.0; 4 * self.vertex_count as usize])?;
        let camera = Camera::new(Vec3::Z, Vec3::ZERO, Vec3::Y, 1.0, 4, 4)?;
        let ctx = Arc::clone(&self.ctx);
        ctx.run("deferred-shadow: warm-up", |encoder| {
            self.record_maps(encoder)?;
            self.record_vertices(encoder, Vec3::Z)?;
            self.record_image(encoder, &camera, 0.1)
        })?;
        self.batches.clear();
        self.copies.clear();
        self.map_count = 0;
        Ok(())
    }

    /// One `vec4` per vertex: radiance, and 1 in w.
    pub fn vertex_radiance(&self) -> &wgpu::Buffer {
        &self.vertex_radiance
    }

    /// The last image: `Rgba32Float`, radiance and 1 in alpha where a
    /// surface is seen, zero elsewhere.
    pub fn image(&self) -> &wgpu::Texture {
        &self.targets.image
    }

    pub fn vertex_count(&self) -> usize {
        self.vertex_count as usize
    }
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
            depth: texture("depth", DEPTH, attach).create_view(&Default::default()),
            image: texture(
                "image",
                wgpu::TextureFormat::Rgba32Float,
                wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Grouping;
    use crate::groups::Groups;
    use crate::lights::AreaLight;
    use shadow_core::{Aabb, gpu::test_context, shapes};

    /// Where a continuous profile sampled at `values[k]` (k = 0, 1, ...)
    /// falling from 1 to 0 crosses `level`, by linear interpolation.
    fn crossing(values: &[f32], level: f32) -> f32 {
        let k = values
            .windows(2)
            .position(|w| w[0] >= level && w[1] < level)
            .expect("the profile crosses the level");
        k as f32 + (values[k] - level) / (values[k] - values[k + 1])
    }

    /// A half-plane's occlusion map (§4.2.2): a 2 × 2 sheet at height D = 1
    /// over a 4 × 4 floor, under a light straight above of Ω = 0.25 sr, its
    /// edges along the light's plane axes (u, v). Across an edge the blurred
    /// map falls from 1 to 0 linearly over the box's side s = √Ω · D = 0.5
    /// (eq. 5–6, D between the planes through the sheet's and the floor's
    /// centres), in the row pass (across u) as in the column pass (across
    /// v), centred on the edge.
    #[test]
    #[cfg_attr(
        skip_gpu_tests,
        ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
    )]
    fn the_blur_ramp_across_a_sheet_edge_is_s_wide() {
        let ctx = test_context();
        let (omega, height, n) = (0.25f32, 1.0f32, 64);
        let light = GpuLight::new(&AreaLight {
            direction: Vec3::Y,
            radiosity: Vec3::ONE,
            solid_angle: omega,
        });
        let (u, v) = (light.u.truncate(), light.v.truncate());
        // The sheet covers u ∈ [−2, 0], v ∈ [−1, 1].
        let sheet = shapes::grid(
            "sheet",
            height * Vec3::Y - 2.0 * u - v,
            2.0 * u,
            2.0 * v,
            1,
            1,
        )
        .unwrap();
        let floor = shapes::floor("floor", Vec3::ZERO, 2.0, 1).unwrap();
        let meshes = [floor, sheet];
        let bounds: Vec<Aabb> = meshes.iter().map(Mesh::bounds).collect();
        let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &bounds).unwrap();
        let plan = Plan::new(&[light], &bounds, &groups, n);
        assert_eq!(plan.maps.len(), 1, "the sheet onto the floor");
        let map = plan.maps[0];
        let s = omega.sqrt() * height;

        let geometry = Geometry::new(&meshes);
        let white = Brdf::lambert(Vec3::ONE).unwrap();
        let objects: Vec<GpuObject> = groups
            .of_object
            .iter()
            .map(|&g| GpuObject::new(Mat4::IDENTITY, &white, g))
            .collect();
        let mut gpu = Gpu::new(Arc::clone(&ctx), &geometry, &objects, n, true).unwrap();
        gpu.set_lights(&[light]).unwrap();
        let positions: Vec<Vec3> = meshes
            .iter()
            .flat_map(|m| m.positions().iter().copied())
            .collect();
        let masks = plan.masks(&[light], &positions, &geometry.triangles, &groups.of_object);
        gpu.set_plan(&plan, &masks, &groups.of_object, &[None])
            .unwrap();
        ctx.run("test: occlusion map", |encoder| gpu.record_maps(encoder))
            .unwrap();
        let blurred: Vec<f32> = ctx
            .read_buffer(&gpu.blurred.buffer, 0, (n * n) as usize)
            .unwrap();

        // Texel k's centre along either axis, in the light's plane.
        let texel = 1.0 / (map.inverse_side * n as f32);
        let at = |k: f32, centre: f32| centre + (k + 0.5 - 0.5 * n as f32) * texel;
        let middle = |centre: f32| ((0.5 * n as f32 - 0.5) - centre / texel).round() as usize;
        // Across u along the row through v = 0, then across v along the
        // column through u = −1 (rows go along +v).
        let row = middle(map.centre.y);
        let across_u: Vec<f32> = blurred[row * n as usize..(row + 1) * n as usize].to_vec();
        let column = middle(map.centre.x + 1.0);
        let across_v: Vec<f32> = (0..n as usize)
            .map(|r| blurred[r * n as usize + column])
            .collect();
        for (profile, centre, edge) in [
            (&across_u, map.centre.x, 0.0),
            (&across_v, map.centre.y, 1.0),
        ] {
            // From the inside (1) out: past the ramp's ends, then the ramp.
            let start = profile.iter().position(|&o| o > 0.999).unwrap();
            let falling = &profile[start..];
            let (high, low) = (crossing(falling, 0.75), crossing(falling, 0.25));
            let width = (low - high) / 0.5 * texel;
            let half_way = at(start as f32 + crossing(falling, 0.5), centre);
            println!(
                "ramp {width} wide (s = {s}, off by {:e}), half-way at {half_way} (edge {edge}, texel {texel})",
                width - s
            );
            // Measured: the width is s to f32 rounding (off by 0) on both
            // axes (the box blur integrates the texels exactly); half-way at
            // −0.012 and 0.988, 0.23 texel from the edges (the coverage's
            // step lies on a texel boundary).
            assert!((width - s).abs() < 1e-3 * s, "ramp {width}, s = {s}");
            assert!(
                (half_way - edge).abs() <= 0.5 * texel,
                "half-way at {half_way}"
            );
        }
    }

    /// 4,800 maps of 256² at q = 256, 1.26 GB: more than the 128 MiB a
    /// storage binding of lavapipe (and of WebGPU's defaults) holds.
    /// Refused naming the settings, the bytes and the limit; 597 maps of
    /// 64² at q = 32 fit. So do masks until q × triangles words pass the
    /// limit.
    #[test]
    fn plans_beyond_a_storage_binding_are_refused_by_name() {
        let limits = wgpu::Limits {
            max_storage_buffer_binding_size: 128 << 20,
            max_buffer_size: (1 << 31) - 1,
            ..wgpu::Limits::default()
        };
        let refused = check_storage(256, 256, 4800, 2 * 256 * 3, 20_000, &limits);
        let Err(Error::InvalidConfig { what, .. }) = refused else {
            panic!("{refused:?}")
        };
        for named in [
            "q = 256",
            "256×256",
            "4800 maps",
            "1258291200 bytes",
            "134217728 bytes",
        ] {
            assert!(what.contains(named), "{named:?} not in {what:?}");
        }
        check_storage(32, 64, 597, 2 * 32 * 3, 20_000, &limits).unwrap();
        let masks = check_storage(256, 32, 10, 0, 150_000, &limits);
        let Err(Error::InvalidConfig { what, .. }) = masks else {
            panic!("{masks:?}")
        };
        assert!(
            what.contains("q = 256") && what.contains("150000 triangles"),
            "{what}"
        );
    }
}
