//! The depth-compare test (§8.1's future work): one compute invocation per
//! listed vertex reads the atlas of a batch's maps and sets the bits where
//! the vertex passes (the occlusion query's `LessEqual`) and faces the
//! light.

use std::ops::Range;

use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::{
    compute_pipeline, dynamic_uniform, entry, group, group_layout, storage, texture,
};
use shadow_core::gpu::uniforms::Slots;
use shadow_core::gpu::wgsl::Source;

use super::maps::DepthMaps;
use super::{Geometry, Shared, TestOffset};
use crate::views::{Atlas, GpuDirection};

shadow_core::wgsl_struct! {
    /// One batch of tests, as compare.wgsl reads it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct Batch {
        /// Listed vertices to test.
        vertices: u32,
        /// Directions `first..first + count`, whose maps sit in the atlas
        /// from slot 0 on, row by row.
        first: u32,
        count: u32,
        /// 32-bit words of visibility per vertex.
        words: u32,
        /// Side of one map, and maps per atlas row.
        map: u32,
        grid: u32,
        _pad: [u32; 2],
        offset: TestOffset,
    }
}

pub(super) struct CompareTest {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    batches: Slots<Batch>,
    atlas: Atlas,
    words: u32,
}

impl CompareTest {
    /// The pipeline, and a uniform slot for each of `batches` batches of a
    /// submission.
    pub fn new(
        ctx: &GpuContext,
        maps: &DepthMaps,
        shared: &Shared,
        geometry: &Geometry,
        batches: usize,
    ) -> CompareTest {
        let module = Source::new()
            .declare::<GpuDirection>()
            .declare::<TestOffset>()
            .declare::<Batch>()
            .body(include_str!("../shaders/compare.wgsl"))
            .module(ctx, "compare");
        let compute = wgpu::ShaderStages::COMPUTE;
        let depth = wgpu::TextureSampleType::Depth;
        let layout = group_layout(
            ctx,
            "compare",
            &[
                dynamic_uniform(0, compute),
                storage(1, true, compute),
                storage(2, true, compute),
                storage(3, true, compute),
                storage(4, true, compute),
                storage(5, false, compute),
                texture(6, depth, compute),
                storage(7, true, compute),
                storage(8, true, compute),
            ],
        );
        let batches = Slots::new(ctx, "batches", batches);
        let group = group(
            ctx,
            "compare",
            &layout,
            &[
                entry(0, batches.binding()),
                entry(1, shared.directions.as_entire_binding()),
                entry(2, geometry.positions.as_entire_binding()),
                entry(3, geometry.normals.as_entire_binding()),
                entry(4, shared.list.as_entire_binding()),
                entry(5, shared.bits.as_entire_binding()),
                entry(6, wgpu::BindingResource::TextureView(maps.view())),
                entry(7, shared.blocked.as_entire_binding()),
                entry(8, shared.push.as_entire_binding()),
            ],
        );
        CompareTest {
            pipeline: compute_pipeline(ctx, &layout, &module, "main"),
            group,
            batches,
            atlas: maps.atlas(),
            words: shared.words,
        }
    }

    /// Batches one submission may record.
    pub fn capacity(&self) -> usize {
        self.batches.capacity()
    }

    /// The tests of the first `vertices` listed vertices against the maps
    /// of `batch`, the `index`-th batch of this submission.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        vertices: usize,
        batch: Range<usize>,
        index: usize,
        offset: TestOffset,
    ) {
        let block = Batch {
            vertices: vertices as u32,
            first: batch.start as u32,
            count: batch.len() as u32,
            words: self.words,
            map: self.atlas.map,
            grid: self.atlas.grid,
            _pad: [0; 2],
            offset,
        };
        let slot = self.batches.write(ctx, index, &block);
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[slot]);
        pass.dispatch_workgroups(vertices.div_ceil(64) as u32, 1, 1);
    }
}
