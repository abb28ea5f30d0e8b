//! Vertex filtering by temporal coherence (§4.1): the list U of triangles the
//! camera has not seen yet, and per frame the triangles of U that it sees
//! now, found as the paper does: the scene into the camera's depth buffer,
//! then every triangle still in U with its own occlusion query (same
//! vertex shader, `LessEqual`, no depth writes). The query results come
//! back to the CPU, which keeps the lists.

use glam::Mat4;
use shadow_core::gpu::binding::{entry, group, group_layout, uniform};
use shadow_core::gpu::buffer::blank;
use shadow_core::gpu::depth::{DEPTH_FORMAT, DepthOnly, DepthUse, OcclusionQueries, depth_pass};
use shadow_core::{Camera, Result, gpu::GpuContext, raster};

use crate::visibility::Geometry;

/// The unseen list and the camera pass that shortens it.
pub struct CameraFilter {
    prepass: wgpu::RenderPipeline,
    queries_pipeline: wgpu::RenderPipeline,
    group: wgpu::BindGroup,
    camera: wgpu::Buffer,
    triangles: wgpu::Buffer,
    queries: OcclusionQueries,
    depth: Option<(u32, u32, wgpu::TextureView)>,
    /// Per triangle: still in U.
    unseen: Vec<bool>,
    remaining: usize,
    /// Once set, U has been emptied below the threshold: filtering is over.
    finished: bool,
}

impl CameraFilter {
    /// The pipelines, and U holding every one of the `triangles` (indices
    /// into the geometry's positions, three per triangle).
    pub fn new(ctx: &GpuContext, triangles: &[u32]) -> CameraFilter {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("camera"),
                source: wgpu::ShaderSource::Wgsl(include_str!("shaders/camera.wgsl").into()),
            });
        let layout = group_layout(ctx, "camera", &[uniform(0, wgpu::ShaderStages::VERTEX)]);
        let pipeline = DepthOnly {
            module: &module,
            entry: "main",
            layout: &layout,
            buffers: &[Some(Geometry::POSITIONS)],
            topology: wgpu::PrimitiveTopology::TriangleList,
        };
        let camera = blank(
            ctx,
            "camera",
            64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let group = group(
            ctx,
            "camera",
            &layout,
            &[entry(0, camera.as_entire_binding())],
        );
        let count = triangles.len() / 3;
        CameraFilter {
            prepass: pipeline.pipeline(
                ctx,
                DepthUse::Write {
                    bias: Default::default(),
                },
            ),
            queries_pipeline: pipeline.pipeline(ctx, DepthUse::Test),
            group,
            camera,
            triangles: ctx.create_buffer_init(
                "camera triangles",
                triangles,
                wgpu::BufferUsages::INDEX,
            ),
            queries: OcclusionQueries::new(
                ctx,
                "triangle queries",
                count,
                wgpu::BufferUsages::COPY_SRC,
            ),
            depth: None,
            unseen: vec![true; count],
            remaining: count,
            finished: false,
        }
    }

    /// Puts every triangle back in U (the geometry changed: §6).
    pub fn reset(&mut self) {
        self.unseen.fill(true);
        self.remaining = self.unseen.len();
        self.finished = false;
    }

    /// Triangles still unseen.
    pub fn remaining(&self) -> usize {
        self.remaining
    }

    /// The triangles of U that `camera` sees now (or, once fewer than
    /// `threshold` of all triangles remain, every one left, after which
    /// filtering stops), taken out of U. `model` places the positions in
    /// the world.
    pub fn newly_seen(
        &mut self,
        ctx: &GpuContext,
        geometry: &Geometry,
        camera: &Camera,
        model: Mat4,
        threshold: f32,
    ) -> Result<Vec<u32>> {
        if self.finished || self.remaining == 0 {
            return Ok(Vec::new());
        }
        if (self.remaining as f32) < threshold * self.unseen.len() as f32 {
            self.finished = true;
            return Ok(self.take(|_| true));
        }
        let candidates: Vec<u32> = (0..self.unseen.len() as u32)
            .filter(|&t| self.unseen[t as usize])
            .collect();
        let samples: Vec<u64> = ctx.capture("occlusion-query: camera queries", || {
            self.record(ctx, geometry, camera, model, &candidates)
        })?;
        let seen: Vec<bool> = samples.iter().map(|&s| s > 0).collect();
        let mut seen_by_index = vec![false; self.unseen.len()];
        for (&t, &s) in candidates.iter().zip(&seen) {
            seen_by_index[t as usize] = s;
        }
        Ok(self.take(|t| seen_by_index[t]))
    }

    /// Removes from U the triangles `pick` chooses and returns them.
    fn take(&mut self, pick: impl Fn(usize) -> bool) -> Vec<u32> {
        let mut taken = Vec::new();
        for (t, unseen) in self.unseen.iter_mut().enumerate() {
            if *unseen && pick(t) {
                *unseen = false;
                taken.push(t as u32);
            }
        }
        self.remaining -= taken.len();
        taken
    }

    /// The camera pass: depth of every triangle, then the candidates with
    /// their queries; returns each candidate's sample count.
    fn record(
        &mut self,
        ctx: &GpuContext,
        geometry: &Geometry,
        camera: &Camera,
        model: Mat4,
        candidates: &[u32],
    ) -> Result<Vec<u64>> {
        let (width, height) = (camera.width, camera.height);
        if self
            .depth
            .as_ref()
            .is_none_or(|(w, h, _)| (*w, *h) != (width, height))
        {
            let texture = ctx.create_texture_2d(
                "camera depth",
                (width, height),
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            );
            self.depth = Some((width, height, texture.create_view(&Default::default())));
        }
        let view = &self.depth.as_ref().expect("made above").2;
        let clip = raster::clip_from_world(camera, near_plane(camera)) * model;
        ctx.queue
            .write_buffer(&self.camera, 0, bytemuck::bytes_of(&clip));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let clear = wgpu::LoadOp::Clear(1.0);
            let mut pass = depth_pass(&mut encoder, "camera depth", view, clear, None);
            pass.set_pipeline(&self.prepass);
            pass.set_bind_group(0, &self.group, &[]);
            pass.set_vertex_buffer(0, geometry.positions.slice(..));
            pass.set_index_buffer(self.triangles.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..3 * self.unseen.len() as u32, 0, 0..1);
        }
        self.queries.record(
            &mut encoder,
            "triangle queries",
            view,
            candidates,
            |pass| {
                pass.set_pipeline(&self.queries_pipeline);
                pass.set_bind_group(0, &self.group, &[]);
                pass.set_vertex_buffer(0, geometry.positions.slice(..));
                pass.set_index_buffer(self.triangles.slice(..), wgpu::IndexFormat::Uint32);
            },
            |pass, t| pass.draw_indexed(3 * t..3 * t + 3, 0, 0..1),
        );
        ctx.queue.submit([encoder.finish()]);
        ctx.read_buffer(self.queries.samples(), 0, candidates.len())
    }
}

/// The camera pass's near plane: a thousandth of the distance from the eye
/// to its target, close enough to clip nothing a scene frames and far
/// enough to keep a float depth buffer's precision over the scene.
fn near_plane(camera: &Camera) -> f32 {
    (camera.eye.distance(camera.target) * 1e-3).max(1e-6)
}

/// The vertices of `triangles` (indices into `indices`, three per
/// triangle), marked in `evaluated`-sized flags.
pub fn vertices_of(triangles: &[u32], indices: &[u32], vertex_count: usize) -> Vec<bool> {
    let mut touched = vec![false; vertex_count];
    for &t in triangles {
        for &v in &indices[3 * t as usize..3 * t as usize + 3] {
            touched[v as usize] = true;
        }
    }
    touched
}
