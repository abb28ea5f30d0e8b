//! Outgoing radiance per vertex from the visibility matrix on the GPU (§3.3):
//! c_i = Σ_j M_ij I_j, with the BRDF and the directions' weights inside the
//! sum (shade.wgsl).

use glam::{Vec3, Vec4};
use shadow_core::gpu::binding::{compute_pipeline, entry, group, group_layout, storage, uniform};
use shadow_core::gpu::buffer::blank;
use shadow_core::gpu::wgsl::Source;
use shadow_core::{Brdf, gpu::GpuContext};

use crate::views::GpuDirection;
use crate::visibility::{Geometry, Visibility};

shadow_core::wgsl_struct! {
    /// One shading's parameters, as shade.wgsl reads them.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct Shade {
        vertices: u32,
        /// Directions in use: the first `directions` of the lightsphere.
        directions: u32,
        words: u32,
        /// 1: scale by π / Σ_j w_j max(0, n·l_j).
        normalize: u32,
        /// The viewer, in the space of the positions.
        eye: Vec4,
    }
}

shadow_core::wgsl_struct! {
    /// An object's BRDF, as shade.wgsl reads it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct GpuMaterial {
        /// Diffuse albedo ρ_d (rgb).
        diffuse: Vec4,
        /// Specular albedo ρ_s (rgb) and the Phong exponent (w).
        specular: Vec4,
    }
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
        let compute = wgpu::ShaderStages::COMPUTE;
        let mut entries = vec![uniform(0, compute)];
        entries.extend((1..=7).map(|b| storage(b, true, compute)));
        entries.push(storage(8, false, compute));
        let layout = group_layout(ctx, "shade", &entries);
        let module = Source::new()
            .declare::<Shade>()
            .declare::<GpuDirection>()
            .declare::<GpuMaterial>()
            .body(include_str!("shaders/shade.wgsl"))
            .module(ctx, "shade");
        let pipeline = compute_pipeline(ctx, &layout, &module, "main");
        let write = wgpu::BufferUsages::COPY_DST;
        let storage = wgpu::BufferUsages::STORAGE;
        let params = blank(
            ctx,
            "shade",
            size_of::<Shade>() as u64,
            wgpu::BufferUsages::UNIFORM | write,
        );
        let incoming = blank(ctx, "incoming", 16 * directions as u64, storage | write);
        let vertex_info = blank(
            ctx,
            "vertex info",
            4 * geometry.vertices as u64,
            storage | write,
        );
        let radiance = blank(
            ctx,
            "radiance",
            16 * geometry.vertices as u64,
            storage | wgpu::BufferUsages::COPY_SRC,
        );
        let gpu_materials: Vec<GpuMaterial> = materials.iter().map(GpuMaterial::new).collect();
        let materials = ctx.create_buffer_init("materials", &gpu_materials, storage);
        let group = group(
            ctx,
            "shade",
            &layout,
            &[
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
        );
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
        let block = Shade {
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
        encoder.copy_buffer_to_buffer(&staging, 0, &self.params, 0, size_of::<Shade>() as u64);
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
