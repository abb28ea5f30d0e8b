//! The depth maps of a batch of light directions, tiled in one atlas
//! (§3.2): the occluders drawn once per map, each into its own square.

use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::{entry, group, group_layout, storage, uniform};
use shadow_core::gpu::depth::{DEPTH_FORMAT, DepthOnly, DepthUse, depth_pass};
use shadow_core::gpu::wgsl::Source;

use super::{Geometry, Shared, TestOffset};
use crate::config::Config;
use crate::views::{Atlas, GpuDirection};

/// The atlas, the occluders' pipeline and the bindings the depth shader
/// (depth.wgsl: the maps, and the queries' points) reads.
pub(super) struct DepthMaps {
    atlas: Atlas,
    view: wgpu::TextureView,
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    group: wgpu::BindGroup,
    occluder: wgpu::RenderPipeline,
}

impl DepthMaps {
    pub fn new(ctx: &GpuContext, config: &Config, atlas: Atlas, shared: &Shared) -> DepthMaps {
        let module = Source::new()
            .declare::<GpuDirection>()
            .declare::<TestOffset>()
            .body(include_str!("../shaders/depth.wgsl"))
            .module(ctx, "depth");
        let vertex = wgpu::ShaderStages::VERTEX;
        let layout = group_layout(
            ctx,
            "depth maps",
            &[storage(0, true, vertex), uniform(1, vertex)],
        );
        let group = group(
            ctx,
            "depth maps",
            &layout,
            &[
                entry(0, shared.directions.as_entire_binding()),
                entry(1, shared.offset.as_entire_binding()),
            ],
        );
        // The polygon offset (§3.2) on the occluders: factor × depth slope +
        // units × the depth format's step. The clamp is in 1/map of a
        // map's depth range: texels where the view volume is the cube
        // around the sphere (one region in a scene the region holds), a
        // fraction of one where the depth reaches farther toward the light.
        let bias = wgpu::DepthBiasState {
            constant: config.offset.occluder_units as i32,
            slope_scale: config.offset.occluder_slope,
            clamp: config.offset.occluder_clamp / config.map_resolution as f32,
        };
        let occluder = DepthOnly {
            module: &module,
            entry: "occluder",
            layout: &layout,
            buffers: &[Some(Geometry::POSITIONS)],
            topology: wgpu::PrimitiveTopology::TriangleList,
        }
        .pipeline(ctx, DepthUse::Write { bias });
        let texture = ctx.create_texture_2d(
            "depth atlas",
            (atlas.side(), atlas.side()),
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        DepthMaps {
            atlas,
            view: texture.create_view(&Default::default()),
            module,
            layout,
            group,
            occluder,
        }
    }

    pub fn atlas(&self) -> Atlas {
        self.atlas
    }

    /// The atlas's depth.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    /// The depth shader, for the queries' points.
    pub fn module(&self) -> &wgpu::ShaderModule {
        &self.module
    }

    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    /// The directions and offset, as the depth shader binds them.
    pub fn group(&self) -> &wgpu::BindGroup {
        &self.group
    }

    /// The maps of `views`, each (slot of the atlas, view), in one render
    /// pass: one indexed draw of every occluder per map, its viewport the
    /// map's square of the atlas (one instanced draw into the whole atlas
    /// measured 30% slower on lavapipe).
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        geometry: &Geometry,
        views: impl Iterator<Item = (usize, u32)>,
    ) {
        let clear = wgpu::LoadOp::Clear(1.0);
        let mut pass = depth_pass(encoder, "depth maps", &self.view, clear, None);
        pass.set_pipeline(&self.occluder);
        pass.set_bind_group(0, &self.group, &[]);
        pass.set_vertex_buffer(0, geometry.positions.slice(..));
        pass.set_index_buffer(geometry.occluders.slice(..), wgpu::IndexFormat::Uint32);
        for (slot, view) in views {
            let (x, y) = self.atlas.origin(slot);
            let size = self.atlas.map;
            pass.set_viewport(x as f32, y as f32, size as f32, size as f32, 0.0, 1.0);
            pass.set_scissor_rect(x, y, size, size);
            pass.draw_indexed(0..geometry.occluder_indices, 0, view..view + 1);
        }
    }
}
