//! The map pass (§4.2.2, §6.2.1): the occlusion maps of a plan, rendered
//! into a depth atlas batch by batch (each occluder drawn once per map it
//! covers, instanced), summed into tables and filtered by boxes of the
//! light's size times each texel's occluder distance into one array of
//! maps, which the deferred pass reads; maps kept from the previous frame
//! are copied, not drawn.

use std::num::NonZeroU64;
use std::ops::Range;

use shadow_core::gpu::GpuContext;
use shadow_core::gpu::binding::{
    compute_pipeline, dynamic_uniform, entry, group_layout, storage, texture, uniform,
};
use shadow_core::gpu::buffer::{Growing, storage_limit, upload};
use shadow_core::gpu::depth::DEPTH_FORMAT;
use shadow_core::gpu::wgsl::Source;
use shadow_core::{Error, Result};

use super::scene::{Scene, level_for, pulled_pipeline, shader};
use crate::maps::{AXIS_EPSILON, Plan, TIE};

shadow_core::wgsl_struct! {
    /// One batch of maps in the atlas, as maps.wgsl reads it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    struct Atlas {
        /// Texels per map side.
        resolution: u32,
        /// Tiles per atlas row.
        per_row: u32,
        /// Texels per atlas side.
        side: f32,
        /// The batch's first entry in the list of drawn maps.
        first: u32,
    }
}

/// Maps rendered and blurred in one batch: the atlas holds this many
/// tiles.
#[derive(Clone, Debug, Default, PartialEq)]
struct Batch {
    /// Its first entry in the list of drawn maps.
    first: u32,
    count: u32,
    /// (indices, first instance, instance count): an object at one of its
    /// levels ([`level_for`]) drawn into the maps
    /// `instances[first..first + count]` name.
    draws: Vec<(Range<u32>, u32, u32)>,
}

/// An object as the map pass draws it: its occluder group, and its scale
/// (world units per model unit), which sets the level it is drawn at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedObject {
    pub group: u32,
    pub scale: f32,
}

/// Largest dispatch along y (WebGPU's default limit).
const MAX_DISPATCH: u32 = 65_535;

/// Side of the atlas the maps are rendered into, at most.
const MAX_ATLAS: u32 = 8192;

/// Refuses, before anything is allocated, a plan whose storage does not fit
/// a device of `limits`: `maps` occlusion maps of `texels` texels in all
/// (at most `resolution`² each), one `f32` each, in one buffer (the paper's
/// q lights times the pairs of occluder and receiving groups,
/// §4.2.2–4.2.3), and a mask word per triangle and light (`triangles` ×
/// `lights`, after `ranges` words of map ranges), each batch's summed-area
/// tables ((n + 1)² pairs of `f32` a map) at least one map's. The
/// [`Error::InvalidConfig`] names the settings (`q`, `map`, as the harness
/// spells them), the bytes they need and the device's limit.
pub fn check_storage(
    lights: u32,
    resolution: u32,
    (maps, texels): (usize, u64),
    ranges: usize,
    triangles: usize,
    limits: &wgpu::Limits,
) -> Result<()> {
    // The maps' texels are indexed by u32.
    let limit = storage_limit(limits).min(4 * u64::from(u32::MAX));
    let what = format!(
        "the device binds at most {limit} bytes in one storage buffer \
         (the smaller of its max_storage_buffer_binding_size and max_buffer_size)"
    );
    // A tile's summed-area table, (n + 1)² corners of 8 bytes.
    let table_bytes = 8 * (u64::from(resolution) + 1).pow(2);
    if table_bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "occlusion maps of up to {resolution}×{resolution} texels (map = {resolution}) \
                 need summed-area tables of {table_bytes} bytes each, and {what}: smaller maps \
                 need less"
            ),
        ));
    }
    let map_bytes = 4 * texels;
    if map_bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "q = {lights} area lights and occlusion maps of up to {resolution}×{resolution} \
                 texels (map = {resolution}) need {maps} maps on this scene, {map_bytes} bytes, \
                 and {what}: \
                 fewer lights, smaller maps or occluders grouped (§4.2.3) need fewer"
            ),
        ));
    }
    let mask_bytes = 4 * (ranges as u64 + triangles as u64 * u64::from(lights));
    if mask_bytes > limit {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "q = {lights} area lights need a mask word per light for each of the scene's \
                 {triangles} triangles, {mask_bytes} bytes, and {what}: fewer lights need fewer"
            ),
        ));
    }
    Ok(())
}

/// The map pass's pipelines, the plan's buffers and the maps.
pub(super) struct MapPass {
    cover: wgpu::RenderPipeline,
    cover_layout: wgpu::BindGroupLayout,
    /// Summed-area tables, rows then columns, then the filter.
    filter_steps: [wgpu::ComputePipeline; 3],
    filter_layout: wgpu::BindGroupLayout,
    /// Texels per map side.
    resolution: u32,
    /// The plan's windows.
    pub maps: wgpu::Buffer,
    /// The maps' ranges per receiving group and light, then the triangles'
    /// masks (deferred.wgsl's `culling`), which start at `masks_offset`.
    pub culling: wgpu::Buffer,
    pub masks_offset: u32,
    instances: wgpu::Buffer,
    /// The filtered maps, one after another.
    pub blurred: Growing,
    /// The previous frame's maps, from which kept maps are copied.
    previous: Growing,
    /// (previous first texel, first texel, texels) of each run of kept
    /// maps.
    copies: Vec<(u32, u32, u32)>,
    /// The maps drawn, tile after tile.
    drawn: wgpu::Buffer,
    /// The summed-area tables of a batch's tiles.
    tables: Growing,
    /// The depth atlas: its side and view.
    depth: Option<(u32, wgpu::TextureView)>,
    batches: Vec<Batch>,
    /// Maps of the current plan.
    pub map_count: u32,
}

impl MapPass {
    pub fn new(ctx: &GpuContext, resolution: u32) -> MapPass {
        let vertex = wgpu::ShaderStages::VERTEX;
        let cs = wgpu::ShaderStages::COMPUTE;
        let body = Source::new()
            .float("AXIS_EPSILON", AXIS_EPSILON)
            .float("TIE", TIE)
            .declare::<Atlas>()
            .body(include_str!("../shaders/receiver.wgsl"))
            .body(include_str!("../shaders/maps.wgsl"));
        let module = shader(ctx, "occlusion maps", body);
        let cover_layout = group_layout(
            ctx,
            "cover",
            &[
                dynamic_uniform(0, vertex),
                storage(1, true, vertex),
                storage(3, true, vertex),
                uniform(4, vertex),
                storage(5, true, vertex),
                storage(6, true, vertex),
            ],
        );
        let cover = pulled_pipeline(
            ctx,
            &cover_layout,
            &module,
            ("cover", "covered"),
            None,
            Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            }),
        );
        let filter_layout = group_layout(
            ctx,
            "filter",
            &[
                dynamic_uniform(0, cs),
                uniform(4, cs),
                storage(5, true, cs),
                texture(7, wgpu::TextureSampleType::Depth, cs),
                storage(8, false, cs),
                storage(9, false, cs),
                storage(10, true, cs),
            ],
        );
        let storage_usage = wgpu::BufferUsages::STORAGE;
        let none: &[u32] = &[];
        MapPass {
            filter_steps: ["sum_rows", "sum_columns", "filter_maps"]
                .map(|step| compute_pipeline(ctx, &filter_layout, &module, step)),
            cover,
            cover_layout,
            filter_layout,
            resolution,
            maps: upload(ctx, "maps", none, storage_usage),
            culling: upload(ctx, "map ranges and masks", none, storage_usage),
            masks_offset: 0,
            instances: upload(ctx, "map instances", none, storage_usage),
            blurred: Growing::new(
                ctx,
                "occlusion maps",
                storage_usage | wgpu::BufferUsages::COPY_SRC,
            ),
            previous: Growing::new(
                ctx,
                "previous occlusion maps",
                storage_usage | wgpu::BufferUsages::COPY_SRC,
            ),
            copies: Vec::new(),
            drawn: upload(ctx, "maps drawn", none, storage_usage),
            tables: Growing::new(ctx, "summed-area tables", storage_usage),
            depth: None,
            batches: Vec::new(),
            map_count: 0,
        }
    }

    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Forgets the plan: nothing to draw or copy.
    pub fn clear(&mut self) {
        self.batches.clear();
        self.copies.clear();
        self.map_count = 0;
    }

    /// Takes `plan`: uploads its windows and ranges and lays its maps out
    /// in atlas batches, each object drawn at the level each map needs
    /// ([`super::Gpu::set_plan`]).
    pub fn lay_out(
        &mut self,
        ctx: &GpuContext,
        (plan, masks): (&Plan, &[u32]),
        scene: &Scene,
        objects: &[PlacedObject],
        reuse: &[Option<u32>],
    ) {
        let n = self.resolution;
        let limit = ctx.device.limits().max_texture_dimension_2d.min(MAX_ATLAS);
        let per_row = (limit / n).max(1);
        // A batch's summed-area tables, 8 bytes per corner, in one binding.
        let table = 8 * u64::from(n + 1).pow(2);
        let tables = (storage_limit(&ctx.device.limits()) / table).max(1) as u32;
        let capacity = (per_row * per_row).min(MAX_DISPATCH).min(tables);
        let count = plan.maps.len() as u32;
        // Kept maps are copied from the previous frame's array, runs of
        // consecutive texels in one copy each.
        self.copies.clear();
        for (map, old) in plan.maps.iter().zip(reuse) {
            let Some(from) = *old else { continue };
            match self.copies.last_mut() {
                Some((start, to, len)) if *start + *len == from && *to + *len == map.offset => {
                    *len += map.texels()
                }
                _ => self.copies.push((from, map.offset, map.texels())),
            }
        }
        if !self.copies.is_empty() {
            std::mem::swap(&mut self.blurred, &mut self.previous);
        }
        self.map_count = count;
        self.blurred.reserve(ctx, 4 * plan.texels().max(1));
        let drawn: Vec<u32> = (0..count)
            .filter(|&k| reuse[k as usize].is_none())
            .collect();
        let mut maps = plan.maps.clone();
        let mut instances: Vec<u32> = Vec::new();
        self.batches.clear();
        for (b, batch) in drawn.chunks(capacity as usize).enumerate() {
            let first = b as u32 * capacity;
            for (tile, &k) in batch.iter().enumerate() {
                maps[k as usize].tile = tile as u32;
            }
            let mut draws = Vec::new();
            for (object, levels) in objects.iter().zip(&scene.occluder_levels) {
                let mut by_level = vec![Vec::new(); levels.len()];
                for &k in batch {
                    let map = &maps[k as usize];
                    if map.occluder == object.group {
                        by_level[level_for(levels, object.scale, map.texel())].push(k);
                    }
                }
                for (level, drawn) in levels.iter().zip(by_level) {
                    if !drawn.is_empty() {
                        let start = instances.len() as u32;
                        draws.push((level.indices.clone(), start, drawn.len() as u32));
                        instances.extend(drawn);
                    }
                }
            }
            self.batches.push(Batch {
                first,
                count: batch.len() as u32,
                draws,
            });
        }
        self.tables
            .reserve(ctx, table * (drawn.len() as u32).clamp(1, capacity) as u64);
        let storage_usage = wgpu::BufferUsages::STORAGE;
        self.maps = upload(ctx, "maps", &maps, storage_usage);
        let mut culling: Vec<u32> = plan.ranges.iter().flatten().copied().collect();
        self.masks_offset = culling.len() as u32;
        culling.extend_from_slice(masks);
        self.culling = upload(ctx, "map ranges and masks", &culling, storage_usage);
        self.drawn = upload(ctx, "maps drawn", &drawn, storage_usage);
        self.instances = upload(ctx, "map instances", &instances, storage_usage);
        // The atlas: as many tiles as the largest batch needs, square.
        let largest = self.batches.iter().map(|b| b.count).max().unwrap_or(1);
        let tiles = (largest as f64).sqrt().ceil() as u32;
        let side = (tiles * n).min(per_row * n);
        if self.depth.as_ref().is_none_or(|(s, _)| *s < side) {
            let texture = ctx.create_texture_2d(
                "depth atlas",
                (side, side),
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            );
            self.depth = Some((side, texture.create_view(&Default::default())));
        }
    }

    /// Renders and filters every map of the plan: per batch, the
    /// occluders' heights onto their tiles of the depth atlas, then the
    /// tiles' summed-area tables, rows then columns, then the filter into
    /// the array of maps.
    pub fn record(&self, ctx: &GpuContext, scene: &Scene, encoder: &mut wgpu::CommandEncoder) {
        let Some((side, depth)) = &self.depth else {
            return;
        };
        let n = self.resolution;
        // One uniform block per batch, bound at its dynamic offset.
        let stride = u64::from(ctx.device.limits().min_uniform_buffer_offset_alignment)
            .max(size_of::<Atlas>() as u64) as usize;
        let mut blocks = vec![0u8; stride * self.batches.len().max(1)];
        for (block, batch) in blocks.chunks_exact_mut(stride).zip(&self.batches) {
            let atlas = Atlas {
                resolution: n,
                per_row: side / n,
                side: *side as f32,
                first: batch.first,
            };
            block[..size_of::<Atlas>()].copy_from_slice(bytemuck::bytes_of(&atlas));
        }
        let atlas = upload(ctx, "atlas", &blocks, wgpu::BufferUsages::UNIFORM);
        let atlas_binding = || {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &atlas,
                offset: 0,
                size: NonZeroU64::new(size_of::<Atlas>() as u64),
            })
        };
        let cover_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cover"),
            layout: &self.cover_layout,
            entries: &[
                entry(0, atlas_binding()),
                entry(1, scene.vertices.as_entire_binding()),
                entry(3, scene.objects.as_entire_binding()),
                entry(4, scene.lights.as_entire_binding()),
                entry(5, self.maps.as_entire_binding()),
                entry(6, self.instances.as_entire_binding()),
            ],
        });
        let filter_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("filter"),
            layout: &self.filter_layout,
            entries: &[
                entry(0, atlas_binding()),
                entry(4, scene.lights.as_entire_binding()),
                entry(5, self.maps.as_entire_binding()),
                entry(7, wgpu::BindingResource::TextureView(depth)),
                entry(8, self.tables.buffer().as_entire_binding()),
                entry(9, self.blurred.buffer().as_entire_binding()),
                entry(10, self.drawn.as_entire_binding()),
            ],
        });
        for &(old, new, texels) in &self.copies {
            encoder.copy_buffer_to_buffer(
                self.previous.buffer(),
                4 * u64::from(old),
                self.blurred.buffer(),
                4 * u64::from(new),
                4 * u64::from(texels),
            );
        }
        for (b, batch) in self.batches.iter().enumerate() {
            let offset = (b * stride) as u32;
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("occluders onto maps"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: depth,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(0.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.cover);
                pass.set_bind_group(0, &cover_group, &[offset]);
                pass.set_index_buffer(scene.occluders.slice(..), wgpu::IndexFormat::Uint32);
                for (indices, first, count) in &batch.draws {
                    pass.draw_indexed(indices.clone(), 0, *first..first + count);
                }
            }
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("filter"),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, &filter_group, &[offset]);
            let [rows, columns, filter] = &self.filter_steps;
            for pipeline in [rows, columns] {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups((n + 1).div_ceil(64), batch.count, 1);
            }
            pass.set_pipeline(filter);
            pass.dispatch_workgroups(n.div_ceil(64), batch.count, 1);
        }
    }
}
