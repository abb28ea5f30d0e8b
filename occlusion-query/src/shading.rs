//! Outgoing radiance per vertex from the visibility matrix on the GPU (§3.3):
//! c_i = Σ_j M_ij I_j, with the BRDF and the directions' weights inside the
//! sum (shade.wgsl).

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use shadow_core::{Brdf, gpu::GpuContext};

use crate::visibility::{Geometry, Visibility};
use shadow_core::gpu::uniforms::storage;

/// `Shade` in shade.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ShadeBlock {
    vertices: u32,
    directions: u32,
    words: u32,
    normalize: u32,
    eye: Vec4,
}

/// `Material` in shade.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GpuMaterial {
    diffuse: Vec4,
    specular: Vec4,
}

impl GpuMaterial {
    fn new(brdf: &Brdf) -> GpuMaterial {
        match *brdf {
            Brdf::Lambert { albedo } => GpuMaterial {
                diffuse: albedo.extend(0.0),
                specular: Vec4::ZERO,
            },
            Brdf::Phong {
                diffuse,
                specular,
                exponent,
            } => GpuMaterial {
                diffuse: diffuse.extend(0.0),
                specular: specular.extend(exponent),
            },
        }
    }
}

/// The top bit of a vertex's info word: its visibility was computed.
pub const EVALUATED: u32 = 0x8000_0000;

/// The shading pipeline and its buffers.
pub struct Shading {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    params: wgpu::Buffer,
    incoming: wgpu::Buffer,
    vertex_info: wgpu::Buffer,
    radiance: wgpu::Buffer,
    /// Per vertex, its object's index (the material).
    objects: Vec<u32>,
    vertices: usize,
}

impl Shading {
    /// Buffers for `geometry` and up to `directions` directions; `materials`
    /// per object, `objects[v]` the object of vertex `v`.
    pub fn new(
        ctx: &GpuContext,
        geometry: &Geometry,
        visibility: &Visibility,
        directions_buffer: &wgpu::Buffer,
        materials: &[Brdf],
        objects: Vec<u32>,
        directions: usize,
    ) -> Shading {
        let device = &ctx.device;
        let compute = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shade"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: compute,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(1, true, compute),
                storage(2, true, compute),
                storage(3, true, compute),
                storage(4, true, compute),
                storage(5, true, compute),
                storage(6, true, compute),
                storage(7, true, compute),
                storage(8, false, compute),
            ],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shade"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/shade.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("shade"),
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: None,
                    bind_group_layouts: &[Some(&layout)],
                    immediate_size: 0,
                }),
            ),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let write = wgpu::BufferUsages::COPY_DST;
        let params = buffer(
            "shade",
            size_of::<ShadeBlock>() as u64,
            wgpu::BufferUsages::UNIFORM | write,
        );
        let incoming = buffer(
            "incoming",
            16 * directions as u64,
            wgpu::BufferUsages::STORAGE | write,
        );
        let vertex_info = buffer(
            "vertex info",
            4 * geometry.vertices as u64,
            wgpu::BufferUsages::STORAGE | write,
        );
        let radiance = buffer(
            "radiance",
            16 * geometry.vertices as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let gpu_materials: Vec<GpuMaterial> = materials.iter().map(GpuMaterial::new).collect();
        let materials =
            ctx.create_buffer_init("materials", &gpu_materials, wgpu::BufferUsages::STORAGE);
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &layout,
            entries: &[
                entry(0, params.as_entire_binding()),
                entry(1, directions_buffer.as_entire_binding()),
                entry(2, incoming.as_entire_binding()),
                entry(3, geometry.positions.as_entire_binding()),
                entry(4, geometry.normals.as_entire_binding()),
                entry(5, visibility.bits().as_entire_binding()),
                entry(6, materials.as_entire_binding()),
                entry(7, vertex_info.as_entire_binding()),
                entry(8, radiance.as_entire_binding()),
            ],
        });
        Shading {
            pipeline,
            group,
            params,
            incoming,
            vertex_info,
            radiance,
            objects,
            vertices: geometry.vertices,
        }
    }

    /// Sets the radiance arriving from each direction of the shaded level
    /// and the solid angle each stands for at that level.
    pub fn set_incoming(&self, ctx: &GpuContext, radiance: &[Vec3], weights: &[f32]) {
        let values: Vec<Vec4> = radiance
            .iter()
            .zip(weights)
            .map(|(r, &w)| r.extend(w))
            .collect();
        ctx.queue
            .write_buffer(&self.incoming, 0, bytemuck::cast_slice(&values));
    }

    /// Sets which vertices have their visibility.
    pub fn set_evaluated(&self, ctx: &GpuContext, evaluated: &[bool]) {
        let info: Vec<u32> = self
            .objects
            .iter()
            .zip(evaluated)
            .map(|(&object, &e)| object | if e { EVALUATED } else { 0 })
            .collect();
        ctx.queue
            .write_buffer(&self.vertex_info, 0, bytemuck::cast_slice(&info));
    }

    /// Records the shading toward `eye` (in the positions' space) with the
    /// first `directions` directions; the result is [`Shading::radiance`].
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        directions: usize,
        words: u32,
        normalize: bool,
        eye: Vec3,
    ) {
        let block = ShadeBlock {
            vertices: self.vertices as u32,
            directions: directions as u32,
            words,
            normalize: normalize as u32,
            eye: eye.extend(1.0),
        };
        // Copied inside the encoder, not written to the queue: a
        // `write_buffer` lands before the whole submission, so two shadings
        // recorded into one encoder would both read the last eye.
        let staging =
            ctx.create_buffer_init("shade parameters", &[block], wgpu::BufferUsages::COPY_SRC);
        encoder.copy_buffer_to_buffer(&staging, 0, &self.params, 0, size_of::<ShadeBlock>() as u64);
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[]);
        pass.dispatch_workgroups(self.vertices.div_ceil(64) as u32, 1, 1);
    }

    /// One `vec4<f32>` per vertex: radiance (rgb), evaluated (w = 1) or not
    /// (all 0).
    pub fn radiance(&self) -> &wgpu::Buffer {
        &self.radiance
    }
}
