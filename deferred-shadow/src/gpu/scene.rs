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
use shadow_core::simplify::simplified;
use shadow_core::{Brdf, Mesh, Result};

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
    /// The triangles drawn into the occlusion maps, as global vertex
    /// indices: each object at every level of [`occluder_levels`].
    pub occluders: Vec<u32>,
    /// Per object, its levels: their ranges of `occluders` and how far
    /// each surface may lie from the mesh's, finest first.
    pub occluder_levels: Vec<Vec<OccluderLevel>>,
}

/// One simplification of an occluder: its range of the occluder indices
/// and how far its surface may lie from the mesh's, in the mesh's units.
#[derive(Clone, Debug, PartialEq)]
pub struct OccluderLevel {
    pub indices: Range<u32>,
    pub error: f32,
}

/// Levels of each occluder: the mesh itself, then simplified within
/// [`LEVEL_TEXELS`] of the finest texel its maps can have, and twice as far
/// at each next one.
pub const LEVELS: u32 = 6;

/// The error bounds of an occluder's levels for maps of at most `largest`
/// texels a side, in the mesh's units: 0 (the mesh, less only the
/// collapses that move nothing), then [`LEVEL_TEXELS`] of the diagonal /
/// `largest`, the finest texel of a map sized to the occluder (maps.rs;
/// a map sized to a smaller receiver can be finer, and [`level_for`] then
/// draws the mesh), doubling.
pub fn occluder_levels(mesh: &Mesh, largest: u32) -> impl Iterator<Item = f32> {
    let finest = mesh.bounds().diagonal() / largest as f32;
    (0..LEVELS).map(move |l| match l {
        0 => 0.0,
        _ => LEVEL_TEXELS * finest * (1u32 << (l - 1)) as f32,
    })
}

/// How far, in texels of a map, the surface drawn into it may lie from
/// the occluder's. Measured at 512×384 (per-pixel error against the
/// reference): on `bunny` ¼ texel gave 4.48% and ½ 4.68% against 4.25%
/// with every triangle, ⅛ 4.25% with the maps drawn in half the time; on
/// `chess` all gave 3.9–4.1%. Where a penumbra is narrow, at a contact, a
/// surface moved by a fraction of a texel moves the shadow's edge.
pub const LEVEL_TEXELS: f32 = 0.125;

/// The coarsest of `levels` (finest first) whose surface lies within
/// [`LEVEL_TEXELS`] of a map with texels `texel` wide (world units), for an
/// object of `scale` world units per model unit. The depth render of the
/// maps is bound by triangle setup, one per occluder triangle and map: a
/// wide light's coarse map needs few triangles, the sun's fine one keeps
/// them.
pub fn level_for(levels: &[OccluderLevel], scale: f32, texel: f32) -> usize {
    levels
        .iter()
        .rposition(|l| l.error * scale <= LEVEL_TEXELS * texel)
        .unwrap_or(0)
}

impl Geometry {
    /// The meshes of a scene's objects, in order, one after another, their
    /// occluders simplified for maps of at most `largest` texels a side.
    pub fn new<'a>(meshes: impl IntoIterator<Item = &'a Mesh>, largest: u32) -> Result<Geometry> {
        let mut geometry = Geometry {
            vertices: Vec::new(),
            triangles: Vec::new(),
            triangle_ranges: Vec::new(),
            occluders: Vec::new(),
            occluder_levels: Vec::new(),
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
            let mut levels: Vec<OccluderLevel> = Vec::new();
            for error in occluder_levels(mesh, largest) {
                let drawn = simplified(mesh, error)?.triangles;
                let count = 3 * drawn.len() as u32;
                // A level that simplifies no further shares the one before.
                let indices = match levels.last() {
                    Some(last) if last.indices.len() as u32 == count => last.indices.clone(),
                    _ => {
                        let first = geometry.occluders.len() as u32;
                        let ordered = meshopt::optimize_vertex_cache(
                            drawn.as_flattened(),
                            mesh.vertex_count(),
                        );
                        geometry.occluders.extend(ordered.iter().map(|&v| v + base));
                        first..first + count
                    }
                };
                levels.push(OccluderLevel { indices, error });
            }
            geometry.occluder_levels.push(levels);
        }
        Ok(geometry)
    }
}

/// The scene's buffers, as every pass binds them.
pub(super) struct Scene {
    pub vertices: wgpu::Buffer,
    pub triangles: wgpu::Buffer,
    pub triangle_ranges: Vec<Range<u32>>,
    /// The occluders' indices at every level ([`Geometry::occluders`]).
    pub occluders: wgpu::Buffer,
    pub occluder_levels: Vec<Vec<OccluderLevel>>,
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
        let none: &[u32] = &[];
        Scene {
            vertices: upload(ctx, "vertices", &geometry.vertices, storage),
            triangles: upload(ctx, "triangles", &geometry.triangles, storage),
            triangle_ranges: geometry.triangle_ranges.clone(),
            occluders: upload(
                ctx,
                "occluders",
                &geometry.occluders,
                wgpu::BufferUsages::INDEX,
            ),
            occluder_levels: geometry.occluder_levels.clone(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use shadow_core::shapes;

    /// Each level draws fewer triangles than the one before, or the same
    /// ones, within its bound; the mesh itself first.
    #[test]
    fn occluders_simplify_further_at_each_level() {
        let ball = shapes::uv_sphere("ball", Vec3::ZERO, 1.0, 32, 64).unwrap();
        let geometry = Geometry::new([&ball], 64).unwrap();
        let levels = &geometry.occluder_levels[0];
        assert_eq!(levels.len(), LEVELS as usize);
        let counts: Vec<usize> = levels.iter().map(|l| l.indices.len() / 3).collect();
        assert_eq!(levels[0].error, 0.0);
        assert!(counts.windows(2).all(|w| w[1] <= w[0]), "{counts:?}");
        // Measured: 3,955, 1,549, 685, 393, 239 and 157 triangles (the
        // coarsest within 2 texels of 64 over the ball's diagonal).
        assert!(counts[0] >= 3900, "{counts:?}");
        assert!(counts[LEVELS as usize - 1] < counts[0] / 8, "{counts:?}");
        for (level, bound) in levels.iter().zip(occluder_levels(&ball, 64)) {
            let simplified = simplified(&ball, bound).unwrap();
            assert!(simplified.error <= bound, "{} > {bound}", simplified.error);
            assert_eq!(level.indices.len(), 3 * simplified.triangles.len());
        }
    }

    /// A second object's levels index its own vertices, after the first's,
    /// and cover its surface as the mesh does.
    #[test]
    fn each_objects_levels_index_its_own_vertices() {
        let ball = shapes::uv_sphere("ball", Vec3::ZERO, 1.0, 16, 32).unwrap();
        let floor = shapes::floor("floor", Vec3::ZERO, 2.0, 8).unwrap();
        let geometry = Geometry::new([&ball, &floor], 64).unwrap();
        let first = ball.vertex_count() as u32;
        let area = |indices: &[u32], base: u32, mesh: &Mesh| -> f32 {
            let p = mesh.positions();
            indices
                .chunks_exact(3)
                .map(|t| {
                    let [a, b, c] = [0, 1, 2].map(|k| p[(t[k] - base) as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum()
        };
        for (o, (mesh, base)) in [(&ball, 0), (&floor, first)].into_iter().enumerate() {
            let end = base + mesh.vertex_count() as u32;
            let full: f32 = area(
                &mesh
                    .triangles()
                    .iter()
                    .flatten()
                    .map(|&v| v + base)
                    .collect::<Vec<_>>(),
                base,
                mesh,
            );
            for level in &geometry.occluder_levels[o] {
                let indices =
                    &geometry.occluders[level.indices.start as usize..level.indices.end as usize];
                assert!(
                    indices.iter().all(|&v| (base..end).contains(&v)),
                    "object {o}"
                );
                // Measured: the ball keeps 100, 99.97, 99.8, 98.8, 96.9 and
                // 90.7% of its area at 962 to 107 triangles (a polyhedron
                // inside the sphere), the floor all of it at 114 to 64.
                let drawn = area(indices, base, mesh);
                assert!(
                    (drawn - full).abs() < 0.12 * full,
                    "object {o}: {drawn} of {full}"
                );
            }
        }
    }

    /// A map draws the coarsest level within an eighth of its texel, in
    /// world units: twice the scale, one level finer; a map 16 times
    /// coarser than the finest, the coarsest level; the finest map, the
    /// first level past the mesh.
    #[test]
    fn a_map_draws_its_occluder_within_an_eighth_of_its_texel() {
        let ball = shapes::uv_sphere("ball", Vec3::ZERO, 1.0, 32, 64).unwrap();
        let geometry = Geometry::new([&ball], 64).unwrap();
        let levels = &geometry.occluder_levels[0];
        let finest = ball.bounds().diagonal() / 64.0;
        assert_eq!(level_for(levels, 1.0, finest), 1);
        assert_eq!(level_for(levels, 1.0, 16.0 * finest), 5);
        assert_eq!(level_for(levels, 1.0, 4.0 * finest), 3);
        assert_eq!(level_for(levels, 2.0, 4.0 * finest), 2);
        // Texels finer than the finest (a map scaled down): the mesh.
        assert_eq!(level_for(levels, 1.0, 0.5 * finest), 0);
        for level in 0..LEVELS as usize {
            let texel = 2f32.powi(level as i32 - 1) * finest;
            let chosen = &levels[level_for(levels, 3.0, texel)];
            assert!(chosen.error * 3.0 <= LEVEL_TEXELS * texel);
        }
    }
}
