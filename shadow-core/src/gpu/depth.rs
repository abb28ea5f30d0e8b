//! Depth-only passes: depth maps of occluders, and primitives tested
//! against them one occlusion query each (Sattler et al. §3.2, §4.1).

use super::GpuContext;
use super::binding::pipeline_layout;

/// The depth format of every depth buffer the GPU methods draw (maps,
/// query passes, visible surfaces). Float depth, so that a shader comparing
/// against a map sees what an occlusion query's fragment would: 16-bit
/// depth made occlusion-query's maps 4–6% faster on lavapipe, but its
/// rounding made its two vertex tests disagree away from texel edges.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Occlusion queries one query set (and so one render pass) holds at most.
pub const QUERIES_PER_PASS: usize = wgpu::QUERY_SET_MAX_QUERIES as usize;

/// What a depth-only pipeline does with the depth buffer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DepthUse {
    /// Keeps the nearest depth (`Less`, written), moved by `bias` (the
    /// polygon offset of §3.2): occluders into a map.
    Write { bias: wgpu::DepthBiasState },
    /// Passes where a primitive lies at or in front of the stored depth
    /// (`LessEqual`, nothing written, no offset): what an occlusion query
    /// counts.
    Test,
}

/// A depth-only render pipeline: one vertex entry, no fragment stage, no
/// culling.
pub struct DepthOnly<'a> {
    pub module: &'a wgpu::ShaderModule,
    pub entry: &'a str,
    pub layout: &'a wgpu::BindGroupLayout,
    pub buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    pub topology: wgpu::PrimitiveTopology,
}

impl DepthOnly<'_> {
    pub fn pipeline(&self, ctx: &GpuContext, depth: DepthUse) -> wgpu::RenderPipeline {
        let (write, bias) = match depth {
            DepthUse::Write { bias } => (true, bias),
            DepthUse::Test => (false, wgpu::DepthBiasState::default()),
        };
        ctx.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(self.entry),
                layout: Some(&pipeline_layout(ctx, self.layout)),
                vertex: wgpu::VertexState {
                    module: self.module,
                    entry_point: Some(self.entry),
                    compilation_options: Default::default(),
                    buffers: self.buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology: self.topology,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
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
    }
}

/// A render pass into the depth buffer `view` alone, which it clears or
/// loads and keeps, counting into `queries` when given.
pub fn depth_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    view: &wgpu::TextureView,
    load: wgpu::LoadOp<f32>,
    queries: Option<&wgpu::QuerySet>,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view,
            depth_ops: Some(wgpu::Operations {
                load,
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: queries,
        multiview_mask: None,
    })
}

/// A query set and the buffer its sample counts resolve into: one
/// occlusion query per drawn item, [`QUERIES_PER_PASS`] to a render pass.
pub struct OcclusionQueries {
    set: wgpu::QuerySet,
    samples: wgpu::Buffer,
}

impl OcclusionQueries {
    /// Room for the sample counts of `capacity` items; `usage` is what else
    /// reads the counts (`STORAGE` for a shader, `COPY_SRC` for the host).
    pub fn new(
        ctx: &GpuContext,
        label: &str,
        capacity: usize,
        usage: wgpu::BufferUsages,
    ) -> OcclusionQueries {
        OcclusionQueries {
            set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(label),
                ty: wgpu::QueryType::Occlusion,
                count: QUERIES_PER_PASS as u32,
            }),
            samples: super::buffer::blank(
                ctx,
                label,
                8 * capacity.next_multiple_of(QUERIES_PER_PASS) as u64,
                usage | wgpu::BufferUsages::QUERY_RESOLVE,
            ),
        }
    }

    /// The sample counts: a `u64` per item, in the order drawn.
    pub fn samples(&self) -> &wgpu::Buffer {
        &self.samples
    }

    /// Records one query per item of `items` against the depth buffer
    /// `depth` (loaded and kept), in passes of [`QUERIES_PER_PASS`], each
    /// resolved into [`OcclusionQueries::samples`]: `begin` sets up every
    /// pass (pipeline, bindings, buffers) and `draw` draws one item.
    pub fn record<T: Copy>(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        depth: &wgpu::TextureView,
        items: &[T],
        begin: impl Fn(&mut wgpu::RenderPass<'_>),
        draw: impl Fn(&mut wgpu::RenderPass<'_>, T),
    ) {
        debug_assert!(8 * items.len() as u64 <= self.samples.size());
        for (chunk, part) in items.chunks(QUERIES_PER_PASS).enumerate() {
            let mut pass = depth_pass(encoder, label, depth, wgpu::LoadOp::Load, Some(&self.set));
            begin(&mut pass);
            for (query, &item) in part.iter().enumerate() {
                pass.begin_occlusion_query(query as u32);
                draw(&mut pass, item);
                pass.end_occlusion_query();
            }
            drop(pass);
            let offset = (chunk * QUERIES_PER_PASS * 8) as u64;
            encoder.resolve_query_set(&self.set, 0..part.len() as u32, &self.samples, offset);
        }
    }
}
