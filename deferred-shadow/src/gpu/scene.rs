//! The scene on the GPU: every object's vertices and triangles, poses and
//! materials, the area lights and the per-vertex shading, pulled from
//! storage buffers by every shader (no vertex buffers); and what every
//! shader of the method shares.

use std::ops::Range;

use bytemuck::Zeroable;
use glam::{Mat4, Vec4};
use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::pipeline_layout;
use shadow_core::gpu::buffer::upload;
use shadow_core::gpu::wgsl::Source;
use shadow_core::{Brdf, Mesh};

use crate::config::MAX_LIGHTS;
use crate::maps::{GpuLight, MapWindow};

shadow_core::wgsl_struct! {
    /// An object's pose and material as the shaders read it (diffuse.w: its
    /// occluder group, exact in f32; specular.w: the Phong exponent).
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct GpuObject {
        pub model: Mat4,
        pub normal: Mat4,
        pub diffuse: Vec4,
        pub specular: Vec4,
    }
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

shadow_core::wgsl_struct! {
    /// A vertex in model space; position.w is its object's index (exact in
    /// f32).
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct GpuVertex {
        pub position: Vec4,
        pub normal: Vec4,
    }
}

/// The scene's static data, in model space.
pub struct Geometry {
    /// Every object's vertices, one object after another.
    pub vertices: Vec<GpuVertex>,
    /// Global vertex indices of each triangle's corners, and its object.
    pub triangles: Vec<[u32; 4]>,
    /// Each object's range of triangles.
    pub triangle_ranges: Vec<Range<u32>>,
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
            geometry
                .vertices
                .extend(
                    mesh.positions()
                        .iter()
                        .zip(mesh.normals())
                        .map(|(p, n)| GpuVertex {
                            position: p.extend(o as f32),
                            normal: n.extend(0.0),
                        }),
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

/// The scene's buffers, as every pass binds them.
pub(super) struct Scene {
    pub vertices: wgpu::Buffer,
    pub triangles: wgpu::Buffer,
    /// The triangles' global vertex indices, for indexed draws.
    pub indices: wgpu::Buffer,
    pub triangle_ranges: Vec<Range<u32>>,
    pub vertex_count: u32,
    pub objects: wgpu::Buffer,
    /// [`MAX_LIGHTS`] lights (a uniform array), the first `light_count` set.
    pub lights: wgpu::Buffer,
    pub light_count: u32,
    /// Per vertex, L_s and the lights' weights ([`super::Gpu::set_shading`]).
    pub shading: wgpu::Buffer,
}

impl Scene {
    pub fn new(ctx: &GpuContext, geometry: &Geometry, objects: &[GpuObject]) -> Scene {
        let storage = wgpu::BufferUsages::STORAGE;
        let indices: Vec<u32> = geometry
            .triangles
            .iter()
            .flat_map(|t| [t[0], t[1], t[2]])
            .collect();
        let none: &[u32] = &[];
        Scene {
            vertices: upload(ctx, "vertices", &geometry.vertices, storage),
            triangles: upload(ctx, "triangles", &geometry.triangles, storage),
            indices: upload(ctx, "indices", &indices, wgpu::BufferUsages::INDEX),
            triangle_ranges: geometry.triangle_ranges.clone(),
            vertex_count: geometry.vertices.len() as u32,
            objects: upload(ctx, "objects", objects, storage),
            lights: upload(
                ctx,
                "lights",
                &[GpuLight::zeroed(); MAX_LIGHTS],
                wgpu::BufferUsages::UNIFORM,
            ),
            light_count: 0,
            shading: upload(ctx, "vertex shading", none, storage),
        }
    }

    pub fn triangle_count(&self) -> u32 {
        self.triangle_ranges.last().map_or(0, |r| r.end)
    }
}

/// A shader of the method: the declarations every shader shares (from
/// Rust, then common.wgsl), then `body`.
pub(super) fn shader(ctx: &GpuContext, label: &str, body: Source) -> wgpu::ShaderModule {
    Source::new()
        .constant("MAX_LIGHTS", MAX_LIGHTS as u32)
        .declare::<GpuLight>()
        .declare::<MapWindow>()
        .declare::<GpuObject>()
        .declare::<GpuVertex>()
        .body(include_str!("../shaders/common.wgsl"))
        .body(body.as_str())
        .module(ctx, label)
}

/// A render pipeline of the `(vertex, fragment)` entries of `module`
/// pulling its vertices from storage (no vertex buffers), into one
/// `target` (none: depth only), with `depth_stencil` when given.
pub(super) fn pulled_pipeline(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    (vertex, fragment): (&str, &str),
    target: Option<wgpu::TextureFormat>,
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
                targets: &target
                    .map(|t| Some(t.into()))
                    .into_iter()
                    .collect::<Vec<_>>(),
            }),
            multiview_mask: None,
            cache: None,
        })
}
