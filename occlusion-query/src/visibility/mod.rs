//! The visibility matrix on the GPU (§3.1–3.2, §8.1): depth maps of the
//! occluders from a batch of light directions ([`maps`]), and the vertices
//! tested against them by a compute pass ([`compare`]) or by the paper's
//! per-vertex occlusion queries ([`queries`]), only the chosen test built.
//! The result is one bit per vertex and direction (set where the vertex
//! sees the light and faces it), in a GPU buffer: M_ij = max(0, n_i·l_j)
//! where the bit is set, 0 elsewhere.

mod compare;
mod maps;
mod queries;

use std::ops::Range;

use glam::{Vec3, Vec4};
use shadow_core::gpu::{GpuContext, buffer::blank};
use shadow_core::{Error, Result};

use crate::config::{Config, VertexTest};
use crate::views::{Atlas, GpuDirection};
use compare::CompareTest;
use maps::DepthMaps;
use queries::QueryTest;

/// The geometry the maps and tests read, one buffer each, every object's
/// vertices one after another.
pub struct Geometry {
    /// Positions (xyz, w = 1): the vertex buffer of the depth maps too.
    pub positions: wgpu::Buffer,
    pub normals: wgpu::Buffer,
    /// Occluder triangles, as indices into `positions`.
    pub occluders: wgpu::Buffer,
    pub occluder_indices: u32,
    pub vertices: usize,
}

impl Geometry {
    /// Uploads positions and normals (as vec4) and the occluder triangles.
    pub fn new(
        ctx: &GpuContext,
        positions: &[Vec4],
        normals: &[Vec4],
        occluders: &[u32],
    ) -> Geometry {
        let usage =
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::VERTEX;
        Geometry {
            positions: ctx.create_buffer_init("positions", positions, usage),
            normals: ctx.create_buffer_init("normals", normals, usage),
            occluders: ctx.create_buffer_init("occluders", occluders, wgpu::BufferUsages::INDEX),
            occluder_indices: occluders.len() as u32,
            vertices: positions.len(),
        }
    }

    /// Replaces positions and normals of the same count.
    pub fn write(&self, ctx: &GpuContext, positions: &[Vec4], normals: &[Vec4]) {
        ctx.queue
            .write_buffer(&self.positions, 0, bytemuck::cast_slice(positions));
        ctx.queue
            .write_buffer(&self.normals, 0, bytemuck::cast_slice(normals));
    }

    /// The vertex buffer of positions (location 0).
    pub(crate) const POSITIONS: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: 16,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x4],
    };

    /// The vertex buffer of normals (location 1).
    pub(crate) const NORMALS: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: 16,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![1 => Float32x4],
    };
}

shadow_core::wgsl_struct! {
    /// How far each tested vertex moves before it is compared with a map, in
    /// world units (see [`crate::DepthOffset`]): `toward_light` plus `slope`
    /// times tan θ (θ between its normal and the light, tan θ at most
    /// `max_tan`) toward the light, and `along_normal` along its normal.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct TestOffset {
        pub toward_light: f32,
        pub along_normal: f32,
        pub slope: f32,
        pub max_tan: f32,
    }
}

impl TestOffset {
    /// Where a vertex at `p` with unit normal `n` is compared for light `l`.
    pub fn moved(&self, p: Vec3, n: Vec3, l: Vec3) -> Vec3 {
        let c = n.dot(l).max(1e-6);
        let tan = ((1.0 - c * c).max(0.0).sqrt() / c).min(self.max_tan);
        p + l * (self.toward_light + self.slope * tan) + n * self.along_normal
    }
}

/// What one job of tests recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Depth maps rendered.
    pub maps: u64,
    /// Vertex-direction pairs tested.
    pub tests: u64,
}

/// What the maps and both tests share: the directions' views, the offset,
/// the list of tested vertices and the bits they set.
struct Shared {
    directions: wgpu::Buffer,
    offset: wgpu::Buffer,
    list: wgpu::Buffer,
    bits: wgpu::Buffer,
    /// 32-bit words of visibility per vertex.
    words: u32,
}

/// The configured vertex test and what it alone needs.
enum Test {
    Compare(CompareTest),
    Queries(QueryTest),
}

/// The pipelines, the atlas and the per-scene buffers of the visibility
/// matrix.
pub struct Visibility {
    shared: Shared,
    maps: DepthMaps,
    test: Test,
    /// The current list of tested vertices, directions' lights and offset,
    /// as last written.
    listed: Vec<u32>,
    lights: Vec<Vec4>,
    test_offset: TestOffset,
}

impl Visibility {
    /// Pipelines and buffers for `geometry` and up to `directions` light
    /// directions. Checks the device can hold the atlas and the buffers.
    pub fn new(
        ctx: &GpuContext,
        config: &Config,
        geometry: &Geometry,
        directions: usize,
    ) -> Result<Visibility> {
        let limits = ctx.device.limits();
        // The queries' render passes load and store their depth attachment,
        // which costs as much as the attachment is large: one map at a
        // time, as in the paper's loop (Fig. 2). The compute pass reads a
        // whole atlas after one render pass.
        let atlas = match config.test {
            VertexTest::DepthCompare => Atlas::new(
                config.map_resolution,
                directions,
                limits.max_texture_dimension_2d,
            ),
            VertexTest::OcclusionQuery => Atlas {
                map: config.map_resolution,
                grid: 1,
            },
        };
        let needs = wgpu::Limits {
            max_texture_dimension_2d: atlas.side(),
            max_storage_buffers_per_shader_stage: 4,
            max_compute_workgroup_size_x: 64,
            max_compute_invocations_per_workgroup: 64,
            max_compute_workgroups_per_dimension: (geometry.vertices.div_ceil(64) as u32).max(1),
            ..wgpu::Limits::downlevel_webgl2_defaults()
        };
        ctx.require("occlusion-query", wgpu::Features::empty(), &needs)?;
        let words = directions.div_ceil(32) as u32;
        let copy_dst = wgpu::BufferUsages::COPY_DST;
        let storage = wgpu::BufferUsages::STORAGE;
        let shared = Shared {
            directions: blank(
                ctx,
                "directions",
                (directions * size_of::<GpuDirection>()) as u64,
                storage | copy_dst,
            ),
            offset: blank(ctx, "offset", 16, wgpu::BufferUsages::UNIFORM | copy_dst),
            list: blank(
                ctx,
                "vertex list",
                4 * geometry.vertices as u64,
                storage | copy_dst,
            ),
            bits: blank(
                ctx,
                "visibility bits",
                4 * words as u64 * geometry.vertices as u64,
                storage | wgpu::BufferUsages::COPY_SRC | copy_dst,
            ),
            words,
        };
        let maps = DepthMaps::new(ctx, config, atlas, &shared);
        let test = match config.test {
            VertexTest::DepthCompare => Test::Compare(CompareTest::new(
                ctx,
                &maps,
                &shared,
                geometry,
                directions.div_ceil(atlas.batch()),
            )),
            VertexTest::OcclusionQuery => {
                Test::Queries(QueryTest::new(ctx, &maps, &shared, geometry, directions))
            }
        };
        Ok(Visibility {
            shared,
            maps,
            test,
            listed: Vec::new(),
            lights: Vec::new(),
            test_offset: TestOffset::default(),
        })
    }

    /// Every direction's view and light (`GpuDirection` in the shaders).
    pub fn directions(&self) -> &wgpu::Buffer {
        &self.shared.directions
    }

    /// 32-bit words of visibility per vertex.
    pub fn words(&self) -> u32 {
        self.shared.words
    }

    /// The visibility bits: `words` per vertex, bit `j % 32` of word
    /// `i · words + j / 32` for vertex `i` and direction `j`.
    pub fn bits(&self) -> &wgpu::Buffer {
        &self.shared.bits
    }

    /// Sets where the maps look from (every direction) and how far tested
    /// vertices move.
    pub fn set_view(&mut self, ctx: &GpuContext, directions: &[GpuDirection], offset: TestOffset) {
        ctx.queue
            .write_buffer(&self.shared.directions, 0, bytemuck::cast_slice(directions));
        ctx.queue
            .write_buffer(&self.shared.offset, 0, bytemuck::bytes_of(&offset));
        self.lights = directions.iter().map(|d| d.light).collect();
        self.test_offset = offset;
    }

    /// Sets which vertices the next tests test (written before the next
    /// submission: one list per submission).
    pub fn set_list(&mut self, ctx: &GpuContext, list: &[u32]) {
        if !list.is_empty() {
            ctx.queue
                .write_buffer(&self.shared.list, 0, bytemuck::cast_slice(list));
        }
        self.listed = list.to_vec();
    }

    /// The batches of directions `directions` falls into: each a range of
    /// at most one atlas of maps.
    pub fn batches(&self, directions: Range<usize>) -> Vec<Range<usize>> {
        let step = self.maps.atlas().batch();
        directions
            .clone()
            .step_by(step)
            .map(|first| first..(first + step).min(directions.end))
            .collect()
    }

    /// Records the depth maps of the directions of `batch` into the atlas:
    /// one render pass, one indexed draw of every occluder per map.
    pub fn record_maps(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        geometry: &Geometry,
        batch: Range<usize>,
    ) -> Counts {
        self.maps.record(encoder, geometry, batch.clone());
        Counts {
            maps: batch.len() as u64,
            tests: 0,
        }
    }

    /// Records the tests of the listed vertices (set with
    /// [`Visibility::set_list`]) against the maps of `batch`, the
    /// `index`-th batch of this submission, with the configured test.
    pub fn record_tests(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        geometry: &Geometry,
        batch: Range<usize>,
        index: usize,
    ) -> Result<Counts> {
        let vertices = self.listed.len();
        let counts = Counts {
            maps: 0,
            tests: (vertices * batch.len()) as u64,
        };
        match &self.test {
            Test::Compare(test) => {
                if index >= test.capacity() {
                    return Err(Error::stage(
                        "occlusion-query",
                        "more batches than the lightsphere holds",
                    ));
                }
                if vertices > 0 {
                    test.record(ctx, encoder, vertices, batch, index, self.test_offset);
                }
            }
            Test::Queries(test) => {
                if vertices > 0 {
                    let directions = batch.map(|j| (j, self.lights[j]));
                    test.record(ctx, encoder, &self.maps, geometry, &self.listed, directions);
                }
            }
        }
        Ok(counts)
    }
}
