//! The visibility matrix on the GPU (§3.1–3.2, §8.1): depth maps of the
//! occluders from a batch of light directions, tiled in one atlas, and the
//! vertices tested against them, by a compute pass or by the paper's
//! per-vertex occlusion queries. The result is one bit per vertex and
//! direction (set where the vertex sees the light and faces it), in a GPU
//! buffer: M_ij = max(0, n_i·l_j) where the bit is set, 0 elsewhere.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use shadow_core::{Error, Result, gpu::GpuContext};

use crate::config::{Config, VertexTest};
use crate::views::{Atlas, GpuDirection};
use shadow_core::gpu::uniforms::{Slots, dynamic_uniform, storage};

/// Occlusion queries a query set (and so a render pass) holds at most.
pub const QUERIES_PER_PASS: usize = wgpu::QUERY_SET_MAX_QUERIES as usize;

/// Float depth, so that the compute pass compares exactly what a query's
/// point would: 16-bit depth made the maps 4–6% faster on lavapipe, but its
/// rounding made the two tests disagree away from texel edges.
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// `Batch` in compare.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct BatchBlock {
    vertices: u32,
    first: u32,
    count: u32,
    words: u32,
    map: u32,
    grid: u32,
    _pad: [u32; 2],
    offset: TestOffset,
}

/// `Convert` in convert.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ConvertBlock {
    vertices: u32,
    direction: u32,
    words: u32,
    _pad: u32,
    light: Vec4,
}

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
}

/// The pipelines, the atlas and the per-scene buffers of the visibility
/// matrix.
pub struct Visibility {
    test: VertexTest,
    atlas: Atlas,
    atlas_view: wgpu::TextureView,
    occluder: wgpu::RenderPipeline,
    point: wgpu::RenderPipeline,
    compare: wgpu::ComputePipeline,
    convert: wgpu::ComputePipeline,
    draw_group: wgpu::BindGroup,
    compare_group: wgpu::BindGroup,
    convert_group: wgpu::BindGroup,
    directions: wgpu::Buffer,
    offset_uniform: wgpu::Buffer,
    list: wgpu::Buffer,
    bits: wgpu::Buffer,
    samples: wgpu::Buffer,
    queries: wgpu::QuerySet,
    batches: Slots<BatchBlock>,
    conversions: Slots<ConvertBlock>,
    words: u32,
    /// The current list of tested vertices, directions' lights and offset,
    /// as last written.
    listed: Vec<u32>,
    lights: Vec<Vec4>,
    test_offset: TestOffset,
}

/// How far each tested vertex moves before it is compared with a map, in
/// world units (see [`crate::DepthOffset`]): `toward_light` plus `slope`
/// times tan θ (θ between its normal and the light, tan θ at most
/// `max_tan`) toward the light, and `along_normal` along its normal.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TestOffset {
    pub toward_light: f32,
    pub along_normal: f32,
    pub slope: f32,
    pub max_tan: f32,
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

impl Visibility {
    /// Pipelines and buffers for `geometry` and up to `directions` light
    /// directions. Checks the device can hold the atlas and the buffers.
    pub fn new(
        ctx: &GpuContext,
        config: &Config,
        geometry: &Geometry,
        directions: usize,
    ) -> Result<Visibility> {
        let device = &ctx.device;
        let limits = device.limits();
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
        let shader = |label, source: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let depth_shader = shader("depth", include_str!("shaders/depth.wgsl"));
        let compare_shader = shader("compare", include_str!("shaders/compare.wgsl"));
        let convert_shader = shader("convert", include_str!("shaders/convert.wgsl"));

        let vertex = wgpu::ShaderStages::VERTEX;
        let compute = wgpu::ShaderStages::COMPUTE;
        let draw_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth maps"),
            entries: &[
                storage(0, true, vertex),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: vertex,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let layout = |bind: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(bind)],
                immediate_size: 0,
            })
        };
        let draw_pipeline_layout = layout(&draw_layout);
        let positions = wgpu::VertexBufferLayout {
            array_stride: 16,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x4],
        };
        let normals = wgpu::VertexBufferLayout {
            attributes: &wgpu::vertex_attr_array![1 => Float32x4],
            ..positions.clone()
        };
        let render = |entry: &str, topology, write: bool, bias: wgpu::DepthBiasState| {
            let with_normals = [Some(positions.clone()), Some(normals.clone())];
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&draw_pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &depth_shader,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    buffers: if write {
                        &with_normals[..1]
                    } else {
                        &with_normals
                    },
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH,
                    depth_write_enabled: Some(write),
                    depth_compare: Some(if write {
                        wgpu::CompareFunction::Less
                    } else {
                        wgpu::CompareFunction::LessEqual
                    }),
                    stencil: Default::default(),
                    bias,
                }),
                multisample: Default::default(),
                fragment: None,
                multiview_mask: None,
                cache: None,
            })
        };
        // The polygon offset (§3.2) on the occluders: factor × depth slope +
        // units × the depth format's step. A texel is 1/map of the map's
        // depth range (the view volume is a cube around the bounding
        // sphere), so the clamp is in texels too.
        let polygon_offset = wgpu::DepthBiasState {
            constant: config.offset.occluder_units as i32,
            slope_scale: config.offset.occluder_slope,
            clamp: config.offset.occluder_clamp / config.map_resolution as f32,
        };
        let occluder = render(
            "occluder",
            wgpu::PrimitiveTopology::TriangleList,
            true,
            polygon_offset,
        );
        let point = render(
            "point",
            wgpu::PrimitiveTopology::PointList,
            false,
            Default::default(),
        );

        let compare_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("compare"),
            entries: &[
                dynamic_uniform(0, compute),
                storage(1, true, compute),
                storage(2, true, compute),
                storage(3, true, compute),
                storage(4, true, compute),
                storage(5, false, compute),
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: compute,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let convert_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("convert"),
            entries: &[
                dynamic_uniform(0, compute),
                storage(1, true, compute),
                storage(2, true, compute),
                storage(3, true, compute),
                storage(4, false, compute),
            ],
        });
        let compute_pipeline = |module: &wgpu::ShaderModule, bind: &wgpu::BindGroupLayout| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: None,
                layout: Some(&layout(bind)),
                module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let compare = compute_pipeline(&compare_shader, &compare_layout);
        let convert = compute_pipeline(&convert_shader, &convert_layout);

        let texture = ctx.create_texture_2d(
            "depth atlas",
            (atlas.side(), atlas.side()),
            DEPTH,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let atlas_view = texture.create_view(&Default::default());
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let copy_dst = wgpu::BufferUsages::COPY_DST;
        let directions_buffer = buffer(
            "directions",
            (directions * size_of::<GpuDirection>()) as u64,
            wgpu::BufferUsages::STORAGE | copy_dst,
        );
        let offset = buffer("offset", 16, wgpu::BufferUsages::UNIFORM | copy_dst);
        let list = buffer(
            "vertex list",
            4 * geometry.vertices as u64,
            wgpu::BufferUsages::STORAGE | copy_dst,
        );
        let bits = buffer(
            "visibility bits",
            4 * words as u64 * geometry.vertices as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | copy_dst,
        );
        let samples = buffer(
            "query samples",
            8 * geometry.vertices.next_multiple_of(QUERIES_PER_PASS) as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::QUERY_RESOLVE,
        );
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("vertex queries"),
            ty: wgpu::QueryType::Occlusion,
            count: QUERIES_PER_PASS as u32,
        });
        let batches = Slots::new(ctx, "batches", directions.div_ceil(atlas.batch()));
        let conversions = match config.test {
            VertexTest::OcclusionQuery => Slots::new(ctx, "conversions", directions),
            VertexTest::DepthCompare => Slots::new(ctx, "conversions", 1),
        };
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let draw_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth maps"),
            layout: &draw_layout,
            entries: &[
                entry(0, directions_buffer.as_entire_binding()),
                entry(1, offset.as_entire_binding()),
            ],
        });
        let compare_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("compare"),
            layout: &compare_layout,
            entries: &[
                entry(0, batches.binding()),
                entry(1, directions_buffer.as_entire_binding()),
                entry(2, geometry.positions.as_entire_binding()),
                entry(3, geometry.normals.as_entire_binding()),
                entry(4, list.as_entire_binding()),
                entry(5, bits.as_entire_binding()),
                entry(6, wgpu::BindingResource::TextureView(&atlas_view)),
            ],
        });
        let convert_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("convert"),
            layout: &convert_layout,
            entries: &[
                entry(0, conversions.binding()),
                entry(1, geometry.normals.as_entire_binding()),
                entry(2, list.as_entire_binding()),
                entry(3, samples.as_entire_binding()),
                entry(4, bits.as_entire_binding()),
            ],
        });
        Ok(Visibility {
            test: config.test,
            atlas,
            atlas_view,
            occluder,
            point,
            compare,
            convert,
            draw_group,
            compare_group,
            convert_group,
            directions: directions_buffer,
            offset_uniform: offset,
            list,
            bits,
            samples,
            queries,
            batches,
            conversions,
            words,
            listed: Vec::new(),
            lights: Vec::new(),
            test_offset: TestOffset::default(),
        })
    }

    /// Every direction's view and light (`Direction` in the shaders).
    pub fn directions(&self) -> &wgpu::Buffer {
        &self.directions
    }

    /// 32-bit words of visibility per vertex.
    pub fn words(&self) -> u32 {
        self.words
    }

    /// The visibility bits: `words` per vertex, bit `j % 32` of word
    /// `i · words + j / 32` for vertex `i` and direction `j`.
    pub fn bits(&self) -> &wgpu::Buffer {
        &self.bits
    }

    /// Sets where the maps look from (every direction) and how far tested
    /// vertices move.
    pub fn set_view(&mut self, ctx: &GpuContext, directions: &[GpuDirection], offset: TestOffset) {
        ctx.queue
            .write_buffer(&self.directions, 0, bytemuck::cast_slice(directions));
        ctx.queue
            .write_buffer(&self.offset_uniform, 0, bytemuck::bytes_of(&offset));
        self.lights = directions.iter().map(|d| d.light).collect();
        self.test_offset = offset;
    }

    /// Sets which vertices the next tests test (written before the next
    /// submission: one list per submission).
    pub fn set_list(&mut self, ctx: &GpuContext, list: &[u32]) {
        if !list.is_empty() {
            ctx.queue
                .write_buffer(&self.list, 0, bytemuck::cast_slice(list));
        }
        self.listed = list.to_vec();
    }

    /// The batches of directions `directions` falls into: each a range of
    /// at most one atlas of maps.
    pub fn batches(&self, directions: Range<usize>) -> Vec<Range<usize>> {
        let step = self.atlas.batch();
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
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth maps"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.atlas_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.occluder);
        pass.set_bind_group(0, &self.draw_group, &[]);
        pass.set_vertex_buffer(0, geometry.positions.slice(..));
        pass.set_index_buffer(geometry.occluders.slice(..), wgpu::IndexFormat::Uint32);
        // One draw per map, its viewport the map's square of the atlas: one
        // instanced draw into the whole atlas measured 30% slower on
        // lavapipe.
        for (slot, j) in batch.clone().enumerate() {
            self.select_map(&mut pass, slot);
            pass.draw_indexed(0..geometry.occluder_indices, 0, j as u32..j as u32 + 1);
        }
        Counts {
            maps: batch.len() as u64,
            tests: 0,
        }
    }

    fn select_map(&self, pass: &mut wgpu::RenderPass, slot: usize) {
        let (x, y) = self.atlas.origin(slot);
        let size = self.atlas.map;
        pass.set_viewport(x as f32, y as f32, size as f32, size as f32, 0.0, 1.0);
        pass.set_scissor_rect(x, y, size, size);
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
        if index >= self.batches.capacity() {
            return Err(Error::stage(
                "occlusion-query",
                "more batches than the lightsphere holds",
            ));
        }
        let counts = Counts {
            maps: 0,
            tests: (vertices * batch.len()) as u64,
        };
        if vertices == 0 {
            return Ok(counts);
        }
        match self.test {
            VertexTest::DepthCompare => {
                let block = BatchBlock {
                    vertices: vertices as u32,
                    first: batch.start as u32,
                    count: batch.len() as u32,
                    words: self.words,
                    map: self.atlas.map,
                    grid: self.atlas.grid,
                    _pad: [0; 2],
                    offset: self.test_offset,
                };
                let offset = self.batches.write(ctx, index, &block);
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.compare);
                pass.set_bind_group(0, &self.compare_group, &[offset]);
                pass.dispatch_workgroups(vertices.div_ceil(64) as u32, 1, 1);
            }
            VertexTest::OcclusionQuery => {
                for j in batch.clone() {
                    self.record_queries(ctx, encoder, geometry, j);
                }
            }
        }
        Ok(counts)
    }

    /// The paper's test for direction `j`: every
    /// listed vertex drawn as a point with its own occlusion query, 4096 to
    /// a render pass, the sample counts resolved on the GPU and turned into
    /// bits there.
    fn record_queries(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        geometry: &Geometry,
        j: usize,
    ) {
        for (chunk, part) in self.listed.chunks(QUERIES_PER_PASS).enumerate() {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("vertex queries"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.atlas_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: Some(&self.queries),
                multiview_mask: None,
            });
            pass.set_pipeline(&self.point);
            pass.set_bind_group(0, &self.draw_group, &[]);
            pass.set_vertex_buffer(0, geometry.positions.slice(..));
            pass.set_vertex_buffer(1, geometry.normals.slice(..));
            for (query, &v) in part.iter().enumerate() {
                pass.begin_occlusion_query(query as u32);
                pass.draw(v..v + 1, j as u32..j as u32 + 1);
                pass.end_occlusion_query();
            }
            drop(pass);
            let offset = (chunk * QUERIES_PER_PASS * 8) as u64;
            encoder.resolve_query_set(&self.queries, 0..part.len() as u32, &self.samples, offset);
        }
        let block = ConvertBlock {
            vertices: self.listed.len() as u32,
            direction: j as u32,
            words: self.words,
            _pad: 0,
            light: self.lights[j],
        };
        let offset = self.conversions.write(ctx, j, &block);
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.convert);
        pass.set_bind_group(0, &self.convert_group, &[offset]);
        pass.dispatch_workgroups(self.listed.len().div_ceil(64) as u32, 1, 1);
    }
}
