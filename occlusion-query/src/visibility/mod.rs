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
use crate::views::{Atlas, GpuDirection, MAX_REGIONS};
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

    /// The vertex buffer of contact pushes (location 2).
    pub(crate) const PUSH: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: 16,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![2 => Float32x4],
    };

    /// The vertex buffer of normals (location 1).
    pub(crate) const NORMALS: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: 16,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![1 => Float32x4],
    };
}

shadow_core::wgsl_struct! {
    /// How far each tested vertex moves before it is compared with a map
    /// (see [`crate::DepthOffset`]), in texels of that map
    /// ([`GpuDirection::light`]'s w): `toward_light` plus `slope` times
    /// tan θ (θ between its normal and the light, tan θ at most `max_tan`)
    /// toward the light, and `along_normal` along its normal, where
    /// `simplification` adds the simplified occluders' bound in world
    /// units; and where a region's views start (view `region · stride + j`
    /// for direction j).
    #[repr(C)]
    #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct TestOffset {
        pub toward_light: f32,
        pub along_normal: f32,
        pub slope: f32,
        pub max_tan: f32,
        pub simplification: f32,
        pub stride: u32,
        pub _pad: [u32; 2],
    }
}

impl TestOffset {
    /// Where a vertex at `p` with unit normal `n` is compared for light `l`
    /// on a map of texel `texel`, given its contact `push` (the direction
    /// it moves off the surfaces it touches, and how much of its move along
    /// `n` is cut short: [`Visibility::set_contacts`]).
    pub fn moved(&self, p: Vec3, n: Vec3, l: Vec3, texel: f32, push: Vec4) -> Vec3 {
        let c = n.dot(l).max(1e-6);
        let tan = ((1.0 - c * c).max(0.0).sqrt() / c).min(self.max_tan);
        let along = (self.along_normal * texel + self.simplification) * (1.0 - push.w);
        p + l * ((self.toward_light + self.slope * tan) * texel)
            + n * along
            + push.truncate() * (self.along_normal * texel)
    }

    /// The farthest it moves a vertex, on a map of texel `texel`.
    pub fn reach(&self, texel: f32) -> f32 {
        (self.toward_light + self.slope * self.max_tan + self.along_normal) * texel
            + self.simplification
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
    /// Bits cleared whatever the maps say (laid out as `bits`): the
    /// directions another object's surface blocks at a contact, every
    /// direction of an enclosed vertex ([`shadow_core::contact`]).
    blocked: wgpu::Buffer,
    /// Per vertex (vec4, w unused), the direction a vertex at a contact is
    /// moved off the other surface before its tests, as far as along its
    /// own normal: the sum of the contact planes' front normals.
    push: wgpu::Buffer,
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
    /// The current list of tested vertices (sorted by region), the ranges
    /// of it in each region, the directions' lights, the regions, the
    /// offset and each vertex's region, as last written.
    listed: Vec<u32>,
    listed_regions: Vec<Range<usize>>,
    lights: Vec<Vec4>,
    regions: usize,
    test_offset: TestOffset,
    vertex_regions: Vec<u32>,
    /// Whether the blocked bits last written hold any set bit.
    any_blocked: bool,
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
        let words = directions.div_ceil(32) as u32;
        let bits = 4 * words as u64 * geometry.vertices as u64;
        let views = (MAX_REGIONS * directions * size_of::<GpuDirection>()) as u64;
        let largest = bits.max(views);
        let needs = wgpu::Limits {
            max_texture_dimension_2d: atlas.side(),
            // shade.wgsl binds 8 storage buffers in its compute stage.
            max_storage_buffers_per_shader_stage: 8,
            max_storage_buffer_binding_size: largest,
            max_buffer_size: largest,
            max_compute_workgroup_size_x: 64,
            max_compute_invocations_per_workgroup: 64,
            max_compute_workgroups_per_dimension: (geometry.vertices.div_ceil(64) as u32).max(1),
            ..wgpu::Limits::downlevel_webgl2_defaults()
        };
        ctx.require("occlusion-query", wgpu::Features::empty(), &needs)?;
        let copy_dst = wgpu::BufferUsages::COPY_DST;
        let storage = wgpu::BufferUsages::STORAGE;
        let shared = Shared {
            directions: blank(ctx, "directions", views, storage | copy_dst),
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
                bits,
                storage | wgpu::BufferUsages::COPY_SRC | copy_dst,
            ),
            blocked: blank(ctx, "blocked bits", bits, storage | copy_dst),
            push: blank(
                ctx,
                "contact push",
                16 * geometry.vertices as u64,
                storage | wgpu::BufferUsages::VERTEX | copy_dst,
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
                directions.div_ceil((atlas.batch() / MAX_REGIONS).max(1)),
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
            listed_regions: Vec::new(),
            lights: Vec::new(),
            regions: 1,
            test_offset: TestOffset::default(),
            vertex_regions: Vec::new(),
            any_blocked: false,
        })
    }

    /// Every region's views of every direction and their lights
    /// (`GpuDirection` in the shaders), region by region: the first region's
    /// are the directions' own.
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

    /// Sets where the maps look from (`views`: every region's view of every
    /// direction, [`crate::views::views`]), how far tested vertices move,
    /// and each vertex's region (also written as its normal's w).
    pub fn set_view(
        &mut self,
        ctx: &GpuContext,
        views: &[GpuDirection],
        offset: TestOffset,
        vertex_regions: Vec<u32>,
    ) {
        ctx.queue
            .write_buffer(&self.shared.directions, 0, bytemuck::cast_slice(views));
        ctx.queue
            .write_buffer(&self.shared.offset, 0, bytemuck::bytes_of(&offset));
        let stride = offset.stride as usize;
        self.regions = views.len() / stride.max(1);
        self.lights = views[..stride].iter().map(|d| d.light).collect();
        self.test_offset = offset;
        self.vertex_regions = vertex_regions;
    }

    /// Sets what contacts with other objects do to the tests
    /// ([`shadow_core::contact`]): the bits they clear whatever the maps say
    /// (`words` per vertex, as [`Visibility::bits`]), and per vertex the
    /// direction it is moved off the other surfaces (so that the surface it
    /// lies on, edge-on in the maps, does not shadow the half it does not
    /// block). Empty slices: no contacts.
    pub fn set_contacts(&mut self, ctx: &GpuContext, blocked: &[u32], push: &[Vec4]) {
        let any = !blocked.is_empty();
        if any {
            ctx.queue
                .write_buffer(&self.shared.blocked, 0, bytemuck::cast_slice(blocked));
            ctx.queue
                .write_buffer(&self.shared.push, 0, bytemuck::cast_slice(push));
        } else if self.any_blocked {
            let zeros = vec![0u8; self.shared.blocked.size() as usize];
            ctx.queue.write_buffer(&self.shared.blocked, 0, &zeros);
            let zeros = vec![0u8; self.shared.push.size() as usize];
            ctx.queue.write_buffer(&self.shared.push, 0, &zeros);
        }
        self.any_blocked = any;
    }

    /// Sets which vertices the next tests test (written before the next
    /// submission: one list per submission), sorted by region.
    pub fn set_list(&mut self, ctx: &GpuContext, list: &[u32]) {
        let mut sorted = list.to_vec();
        sorted.sort_by_key(|&v| self.vertex_regions[v as usize]);
        self.listed_regions = (0..self.regions as u32)
            .map(|r| {
                let of = |v: &u32| self.vertex_regions[*v as usize];
                sorted.partition_point(|v| of(v) < r)..sorted.partition_point(|v| of(v) <= r)
            })
            .collect();
        if !sorted.is_empty() {
            ctx.queue
                .write_buffer(&self.shared.list, 0, bytemuck::cast_slice(&sorted));
        }
        self.listed = sorted;
    }

    /// The batches of directions `directions` falls into: each a range whose
    /// maps of every region fit one atlas.
    pub fn batches(&self, directions: Range<usize>) -> Vec<Range<usize>> {
        let step = match self.test {
            Test::Compare(_) => (self.maps.atlas().batch() / self.regions).max(1),
            Test::Queries(_) => 1,
        };
        directions
            .clone()
            .step_by(step)
            .map(|first| first..(first + step).min(directions.end))
            .collect()
    }

    /// Records the depth maps of every region for the directions of `batch`
    /// into the atlas: one render pass, one indexed draw of every occluder
    /// per map. The paper's queries draw their maps with the tests
    /// ([`Visibility::record_tests`]), one at a time.
    pub fn record_maps(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        geometry: &Geometry,
        batch: Range<usize>,
    ) -> Counts {
        if let Test::Queries(_) = self.test {
            return Counts::default();
        }
        let (count, stride) = (batch.len(), self.test_offset.stride);
        let views = (0..self.regions).flat_map(|r| {
            let batch = batch.clone();
            batch
                .enumerate()
                .map(move |(i, j)| (r * count + i, r as u32 * stride + j as u32))
        });
        self.maps.record(encoder, geometry, views);
        Counts {
            maps: (self.regions * count) as u64,
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
        let mut counts = Counts {
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
                    counts.maps = test.record(
                        ctx,
                        encoder,
                        &self.maps,
                        geometry,
                        &self.listed,
                        &self.listed_regions,
                        self.test_offset.stride,
                        &self.shared.push,
                        directions,
                    );
                }
            }
        }
        Ok(counts)
    }
}
