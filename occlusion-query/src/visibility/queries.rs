//! The paper's test (§3.2, Fig. 2): for each direction, every listed vertex
//! drawn as a point against that direction's map (its region's,
//! [`crate::views::Regions`]) with its own occlusion query, the sample
//! counts resolved on the GPU and turned into bits there (convert.wgsl).
//! The maps are drawn here, between the queries, one at a time.

use std::ops::Range;

use glam::Vec4;
use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::{
    compute_pipeline, dynamic_uniform, entry, group, group_layout, storage,
};
use shadow_core::gpu::depth::{DepthOnly, DepthUse, OcclusionQueries};
use shadow_core::gpu::uniforms::Slots;
use shadow_core::gpu::wgsl::Source;

use super::maps::DepthMaps;
use super::{Geometry, Shared};
use crate::views::MAX_REGIONS;

shadow_core::wgsl_struct! {
    /// One direction's sample counts to convert, as convert.wgsl reads it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct Convert {
        /// Listed vertices whose queries were drawn, in list order from
        /// `first`.
        vertices: u32,
        direction: u32,
        words: u32,
        first: u32,
        light: Vec4,
    }
}

pub(super) struct QueryTest {
    point: wgpu::RenderPipeline,
    convert: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    queries: OcclusionQueries,
    conversions: Slots<Convert>,
    words: u32,
}

impl QueryTest {
    /// The pipelines, room for a query per vertex of `geometry`, and a
    /// uniform slot for each of `directions` in each of [`MAX_REGIONS`].
    pub fn new(
        ctx: &GpuContext,
        maps: &DepthMaps,
        shared: &Shared,
        geometry: &Geometry,
        directions: usize,
    ) -> QueryTest {
        let point = DepthOnly {
            module: maps.module(),
            entry: "point",
            layout: maps.layout(),
            buffers: &[
                Some(Geometry::POSITIONS),
                Some(Geometry::NORMALS),
                Some(Geometry::PUSH),
            ],
            topology: wgpu::PrimitiveTopology::PointList,
        }
        .pipeline(ctx, DepthUse::Test);
        let module = Source::new()
            .declare::<Convert>()
            .body(include_str!("../shaders/convert.wgsl"))
            .module(ctx, "convert");
        let compute = wgpu::ShaderStages::COMPUTE;
        let layout = group_layout(
            ctx,
            "convert",
            &[
                dynamic_uniform(0, compute),
                storage(1, true, compute),
                storage(2, true, compute),
                storage(3, true, compute),
                storage(4, false, compute),
                storage(5, true, compute),
            ],
        );
        let queries = OcclusionQueries::new(
            ctx,
            "vertex queries",
            geometry.vertices,
            wgpu::BufferUsages::STORAGE,
        );
        let conversions = Slots::new(ctx, "conversions", directions * MAX_REGIONS);
        let group = group(
            ctx,
            "convert",
            &layout,
            &[
                entry(0, conversions.binding()),
                entry(1, geometry.normals.as_entire_binding()),
                entry(2, shared.list.as_entire_binding()),
                entry(3, queries.samples().as_entire_binding()),
                entry(4, shared.bits.as_entire_binding()),
                entry(5, shared.blocked.as_entire_binding()),
            ],
        );
        QueryTest {
            point,
            convert: compute_pipeline(ctx, &layout, &module, "main"),
            group,
            queries,
            conversions,
            words: shared.words,
        }
    }

    /// For each direction `j` (toward `light`) of `directions` and each
    /// region of `regions` (the ranges of the `listed` vertices, sorted by
    /// region, that lie in each): the region's map of `j`, its vertices'
    /// queries against it, and their conversion to bits. One map at a
    /// time, as in the paper's loop (Fig. 2). Returns the maps drawn.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        maps: &DepthMaps,
        geometry: &Geometry,
        listed: &[u32],
        regions: &[Range<usize>],
        stride: u32,
        push: &wgpu::Buffer,
        directions: impl Iterator<Item = (usize, Vec4)>,
    ) -> u64 {
        let mut drawn = 0;
        for (j, light) in directions {
            for (r, range) in regions.iter().enumerate() {
                if range.is_empty() {
                    continue;
                }
                let view = r as u32 * stride + j as u32;
                maps.record(encoder, geometry, std::iter::once((0, view)));
                drawn += 1;
                let j = j as u32;
                self.queries.record(
                    encoder,
                    "vertex queries",
                    maps.view(),
                    &listed[range.clone()],
                    |pass| {
                        pass.set_pipeline(&self.point);
                        pass.set_bind_group(0, maps.group(), &[]);
                        pass.set_vertex_buffer(0, geometry.positions.slice(..));
                        pass.set_vertex_buffer(1, geometry.normals.slice(..));
                        pass.set_vertex_buffer(2, push.slice(..));
                    },
                    |pass, v| pass.draw(v..v + 1, j..j + 1),
                );
                let block = Convert {
                    vertices: range.len() as u32,
                    direction: j,
                    words: self.words,
                    first: range.start as u32,
                    light,
                };
                let slot = self
                    .conversions
                    .write(ctx, j as usize * MAX_REGIONS + r, &block);
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.convert);
                pass.set_bind_group(0, &self.group, &[slot]);
                pass.dispatch_workgroups(range.len().div_ceil(64) as u32, 1, 1);
            }
        }
        drawn
    }
}
