//! GPU device setup and read-back shared by the wgpu method crates
//! (`occlusion-query`, `deferred-shadow`), so that both pick adapters, report
//! them and surface GPU errors the same way (DESIGN.md, "Layout").
//!
//! # Errors on the GPU
//!
//! wgpu reports most errors (shader compilation, validation, out of memory)
//! asynchronously to the device's *uncaptured error handler*, whose default
//! panics from whichever thread noticed. [`GpuContext::new`] installs a handler
//! that records the error instead (and a device-lost callback that does the
//! same), and [`GpuContext::take_error`] turns what was recorded into an
//! [`Error::Gpu`]. The read-back helpers ([`GpuContext::read_buffer`],
//! [`GpuContext::read_texture`]) and [`GpuContext::submit_and_wait`] call it
//! after waiting on the device, so a failed submission surfaces as an error at
//! the moment its numbers would be used, never as silent zeros. We chose this
//! over error scopes because wgpu's scopes are thread-local and must be popped
//! in order, which is easy to get wrong in code that mixes rayon and the GPU;
//! the price is that two users sharing one context concurrently may see each
//! other's errors.

use std::fmt;
use std::sync::{Arc, Mutex, mpsc};

use serde::Serialize;
use wgpu::util::DeviceExt;

use crate::{Error, Result};

/// What the harness reports about the adapter a run used (DESIGN.md, "Time":
/// a software adapter such as lavapipe is named as such).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct AdapterSummary {
    /// The adapter's name, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
    pub name: String,
    /// The graphics API wgpu drives it through, e.g. "Vulkan".
    pub backend: String,
    /// "discrete GPU", "integrated GPU", "virtual GPU", "software rasterizer"
    /// or "unknown device type".
    pub device_type: String,
    /// Driver name and version information, as the driver reports them.
    pub driver: String,
    /// True for CPU (software) adapters: timings are then CPU timings.
    pub is_software: bool,
}

impl AdapterSummary {
    fn new(info: &wgpu::AdapterInfo) -> AdapterSummary {
        let backend = match info.backend {
            wgpu::Backend::Noop => "no-op",
            wgpu::Backend::Vulkan => "Vulkan",
            wgpu::Backend::Metal => "Metal",
            wgpu::Backend::Dx12 => "DirectX 12",
            wgpu::Backend::Gl => "OpenGL",
            wgpu::Backend::BrowserWebGpu => "WebGPU",
        };
        let device_type = match info.device_type {
            wgpu::DeviceType::DiscreteGpu => "discrete GPU",
            wgpu::DeviceType::IntegratedGpu => "integrated GPU",
            wgpu::DeviceType::VirtualGpu => "virtual GPU",
            wgpu::DeviceType::Cpu => "software rasterizer",
            wgpu::DeviceType::Other => "unknown device type",
        };
        let driver = [info.driver.as_str(), info.driver_info.as_str()]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(", ");
        AdapterSummary {
            name: info.name.clone(),
            backend: backend.to_string(),
            device_type: device_type.to_string(),
            driver,
            is_software: info.device_type == wgpu::DeviceType::Cpu,
        }
    }
}

impl fmt::Display for AdapterSummary {
    /// E.g. "llvmpipe (LLVM 15.0.6, 256 bits), Vulkan, software rasterizer".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, {}, {}", self.name, self.backend, self.device_type)
    }
}

/// The errors the device reported since they were last taken.
#[derive(Debug, Default)]
struct ErrorLog {
    first: Option<String>,
    more: usize,
}

impl ErrorLog {
    fn record(log: &Mutex<ErrorLog>, message: String) {
        // A poisoned lock only means another thread panicked while recording;
        // the log itself is still usable.
        let mut log = log.lock().unwrap_or_else(|e| e.into_inner());
        if log.first.is_none() {
            log.first = Some(message);
        } else {
            log.more += 1;
        }
    }
}

/// A wgpu device and queue, with the adapter they came from and a record of
/// asynchronous GPU errors (see the module docs).
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    wgpu_adapter: wgpu::Adapter,
    errors: Arc<Mutex<ErrorLog>>,
}

impl fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter)
            .finish_non_exhaustive()
    }
}

/// The names of the backends in `backends`, e.g. "VULKAN | GL".
fn backend_names(backends: wgpu::Backends) -> String {
    let names: Vec<&str> = backends.iter_names().map(|(name, _)| name).collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(" | ")
    }
}

impl GpuContext {
    /// Opens the high-performance adapter of the backends `WGPU_BACKEND`
    /// allows (all by default; e.g. `WGPU_BACKEND=gl` forces OpenGL), without
    /// a surface, and a device with default limits except the buffer and 2D
    /// texture sizes, which are raised to what the adapter supports (the
    /// methods keep one storage buffer per scene). No optional features are
    /// needed: occlusion queries are core WebGPU.
    ///
    /// Fails with [`Error::Gpu`] when there is no adapter, saying how to get a
    /// software one, or when the device cannot be created.
    pub fn new() -> Result<GpuContext> {
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle().with_env();
        let requested = descriptor.backends;
        let instance = wgpu::Instance::new(descriptor);
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        };
        let adapter = pollster::block_on(instance.request_adapter(&options)).map_err(|e| {
            let env = std::env::var("WGPU_BACKEND").unwrap_or_else(|_| "unset".to_string());
            Error::Gpu(format!(
                "no GPU adapter found ({e}; backends requested: {}, compiled in: {}, WGPU_BACKEND={env}). \
                 On Linux without a GPU install Mesa's software Vulkan driver: \
                 apt-get install mesa-vulkan-drivers libvulkan1",
                backend_names(requested),
                backend_names(wgpu::Instance::enabled_backend_features())
            ))
        })?;
        let summary = AdapterSummary::new(&adapter.get_info());
        let supported = adapter.limits();
        let limits = wgpu::Limits {
            max_buffer_size: supported.max_buffer_size,
            max_storage_buffer_binding_size: supported.max_storage_buffer_binding_size,
            max_texture_dimension_2d: supported.max_texture_dimension_2d,
            // Downlevel adapters (GL) support less than WebGPU's defaults.
            ..wgpu::Limits::default().or_worse_values_from(&supported)
        };
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("shadow-core"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&descriptor))
            .map_err(|e| Error::Gpu(format!("cannot open a device on {summary}: {e}")))?;

        let errors = Arc::new(Mutex::new(ErrorLog::default()));
        let log = Arc::clone(&errors);
        device.on_uncaptured_error(Arc::new(move |error: wgpu::Error| {
            ErrorLog::record(&log, error_message(&error));
        }));
        let log = Arc::clone(&errors);
        device.set_device_lost_callback(move |reason, message| {
            ErrorLog::record(&log, format!("device lost ({reason:?}): {message}"));
        });
        Ok(GpuContext {
            device,
            queue,
            adapter: summary,
            wgpu_adapter: adapter,
            errors,
        })
    }

    /// What the adapter can do with textures of `format`: downlevel backends
    /// (OpenGL) cannot render to `Rgba32Float`, for instance, so a method
    /// picks its render-target formats with this.
    pub fn format_features(&self, format: wgpu::TextureFormat) -> wgpu::TextureFormatFeatures {
        self.wgpu_adapter.get_texture_format_features(format)
    }

    /// The GPU errors recorded since the last call, as one [`Error::Gpu`]
    /// naming the first and counting the rest; `Ok` when there were none.
    pub fn take_error(&self) -> Result<()> {
        let mut log = self.errors.lock().unwrap_or_else(|e| e.into_inner());
        let taken = std::mem::take(&mut *log);
        match taken.first {
            None => Ok(()),
            Some(first) if taken.more == 0 => Err(Error::Gpu(first)),
            Some(first) => Err(Error::Gpu(format!(
                "{first} (and {} more errors)",
                taken.more
            ))),
        }
    }

    /// Blocks until the device has finished all submitted work, then reports
    /// any GPU error recorded meanwhile.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::Gpu(format!("waiting for the device: {e}")))?;
        self.take_error()
    }

    /// Submits `commands`, waits for them to finish and reports any GPU error.
    pub fn submit_and_wait(
        &self,
        commands: impl IntoIterator<Item = wgpu::CommandBuffer>,
    ) -> Result<()> {
        self.queue.submit(commands);
        self.wait()
    }

    /// A buffer holding `contents`, with `usage` (plus nothing implicit).
    pub fn create_buffer_init<T: bytemuck::Pod>(
        &self,
        label: &str,
        contents: &[T],
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(contents),
                usage,
            })
    }

    /// Copies `count` values of `T` starting `offset` bytes into `buffer`
    /// (which needs `COPY_SRC`) to the CPU: through a mappable staging buffer,
    /// waiting for the GPU. Fails on an out-of-range or misaligned request
    /// (offsets must be multiples of 4 bytes) and on any GPU error recorded
    /// before the copy finished.
    pub fn read_buffer<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        offset: u64,
        count: usize,
    ) -> Result<Vec<T>> {
        let bytes = (count as u64).checked_mul(size_of::<T>() as u64);
        let Some(bytes) = bytes else {
            return Err(Error::Gpu(format!("read_buffer: {count} values overflow")));
        };
        if bytes == 0 {
            return Ok(Vec::new());
        }
        // Copies move whole 4-byte words; a request ending mid-word reads the
        // word and drops the extra bytes.
        let copy = bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        if !offset.is_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT) {
            return Err(Error::Gpu(format!(
                "read_buffer: offset {offset} is not a multiple of 4 bytes"
            )));
        }
        if offset
            .checked_add(copy)
            .is_none_or(|end| end > buffer.size())
        {
            return Err(Error::Gpu(format!(
                "read_buffer: {copy} bytes at offset {offset} exceed the buffer's {} bytes",
                buffer.size()
            )));
        }
        if !buffer.usage().contains(wgpu::BufferUsages::COPY_SRC) {
            return Err(Error::Gpu(
                "read_buffer: the buffer lacks COPY_SRC usage".into(),
            ));
        }
        let staging = self.staging_buffer(copy);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("read_buffer"),
            });
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, copy);
        self.queue.submit([encoder.finish()]);
        let mapped = self.map_staging(&staging)?;
        Ok(bytemuck::pod_collect_to_vec(&mapped[..bytes as usize]))
    }

    /// Copies mip level 0 of a 2D `texture` (which needs `COPY_SRC`) to the
    /// CPU: `width × height` texels of `T`, row 0 first (the top row of a
    /// render target), each row unpadded. `T` must have the size of one texel
    /// of the format (e.g. `[f32; 4]` for `Rgba32Float`, `f32` for `R32Float`
    /// or the depth of `Depth32Float`). The 256-byte row alignment of
    /// texture-to-buffer copies is handled here.
    pub fn read_texture<T: bytemuck::Pod>(&self, texture: &wgpu::Texture) -> Result<Vec<T>> {
        let format = texture.format();
        let aspect = if format.has_depth_aspect() {
            wgpu::TextureAspect::DepthOnly
        } else {
            wgpu::TextureAspect::All
        };
        let texel = format.block_copy_size(Some(aspect)).ok_or_else(|| {
            Error::Gpu(format!(
                "read_texture: {format:?} textures cannot be copied to buffers"
            ))
        })?;
        if format.block_dimensions() != (1, 1) || texel as usize != size_of::<T>() {
            return Err(Error::Gpu(format!(
                "read_texture: {format:?} has {texel}-byte texels, the requested type {} bytes",
                size_of::<T>()
            )));
        }
        if texture.dimension() != wgpu::TextureDimension::D2 || texture.sample_count() != 1 {
            return Err(Error::Gpu(
                "read_texture: only single-sampled 2D textures are read back".into(),
            ));
        }
        if !texture.usage().contains(wgpu::TextureUsages::COPY_SRC) {
            return Err(Error::Gpu(
                "read_texture: the texture lacks COPY_SRC usage".into(),
            ));
        }
        let (width, height) = (texture.width(), texture.height());
        let row = width * texel;
        let padded_row = row.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = self.staging_buffer(u64::from(padded_row) * u64::from(height));
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("read_texture"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_row),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        self.queue.submit([encoder.finish()]);
        let mapped = self.map_staging(&staging)?;
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for bytes in mapped.chunks_exact(padded_row as usize) {
            texels.extend(bytemuck::pod_collect_to_vec::<u8, T>(
                &bytes[..row as usize],
            ));
        }
        Ok(texels)
    }

    fn staging_buffer(&self, size: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back staging"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Maps the whole of `staging` for reading once the submitted copies into
    /// it are done.
    fn map_staging(&self, staging: &wgpu::Buffer) -> Result<wgpu::BufferView> {
        let (sender, receiver) = mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |result| {
            // The receiver outlives the poll below; a send can only fail
            // after this function returned, when nobody needs the result.
            let _ = sender.send(result);
        });
        self.wait()?;
        match receiver.try_recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(Error::Gpu(format!("mapping the read-back buffer: {e}"))),
            Err(_) => {
                return Err(Error::Gpu(
                    "the read-back buffer was not mapped after waiting".into(),
                ));
            }
        }
        staging
            .get_mapped_range(..)
            .map_err(|e| Error::Gpu(format!("reading the mapped buffer: {e}")))
    }
}

/// A wgpu error with its chain of causes: the top-level description alone
/// often omits which resource or shader line was at fault.
fn error_message(error: &wgpu::Error) -> String {
    let mut message = error.to_string();
    let mut source = std::error::Error::source(error);
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !message.contains(&cause_text) {
            message.push_str(": ");
            message.push_str(&cause_text);
        }
        source = cause.source();
    }
    message
}

/// The context every GPU test in the workspace runs on.
///
/// Without an adapter it prints why and returns `None`, so that the tests pass
/// on machines without a GPU or Mesa. When the environment variable `CI` is
/// set, a missing adapter panics instead: on CI the GPU tests must run, and a
/// broken driver setup must fail the build rather than skip them quietly.
pub fn test_context() -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(context) => Some(context),
        Err(e) if std::env::var_os("CI").is_some() => {
            panic!("CI is set and GPU tests cannot run: {e}")
        }
        Err(e) => {
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_reports_its_adapter() {
        let Some(ctx) = test_context() else { return };
        let text = ctx.adapter.to_string();
        println!("adapter: {text} (driver {})", ctx.adapter.driver);
        assert!(text.starts_with(&ctx.adapter.name));
        assert!(text.contains(&ctx.adapter.backend));
        if ctx.adapter.name.contains("llvmpipe") {
            assert!(ctx.adapter.is_software);
            assert!(text.ends_with("software rasterizer"), "{text}");
        }
        ctx.take_error().unwrap();
    }

    #[test]
    fn compute_shader_round_trip_doubles_values() {
        let Some(ctx) = test_context() else { return };
        let input: Vec<f32> = (0..1000).map(|i| i as f32 * 0.25 - 7.0).collect();
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let buffer = ctx.create_buffer_init("values", &input, usage);
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("double"),
                source: wgpu::ShaderSource::Wgsl(
                    "@group(0) @binding(0) var<storage, read_write> values: array<f32>;
                 @compute @workgroup_size(64)
                 fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                     if id.x < arrayLength(&values) { values[id.x] = 2.0 * values[id.x]; }
                 }"
                    .into(),
                ),
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("double"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: buffer.as_entire_binding(),
            }],
        });
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(input.len().div_ceil(64) as u32, 1, 1);
        }
        ctx.submit_and_wait([encoder.finish()]).unwrap();
        let output: Vec<f32> = ctx.read_buffer(&buffer, 0, input.len()).unwrap();
        let expected: Vec<f32> = input.iter().map(|v| v * 2.0).collect();
        assert_eq!(output, expected);
        // A sub-range at an offset.
        let tail: Vec<f32> = ctx.read_buffer(&buffer, 400, 3).unwrap();
        assert_eq!(tail, expected[100..103]);
    }

    #[test]
    fn bad_read_back_requests_are_errors_not_panics() {
        let Some(ctx) = test_context() else { return };
        let buffer = ctx.create_buffer_init("small", &[1u32, 2, 3], wgpu::BufferUsages::COPY_SRC);
        assert!(ctx.read_buffer::<u32>(&buffer, 0, 4).is_err());
        assert!(ctx.read_buffer::<u32>(&buffer, 2, 1).is_err());
        assert_eq!(ctx.read_buffer::<u32>(&buffer, 4, 2).unwrap(), vec![2, 3]);
        let no_copy = ctx.create_buffer_init("no copy", &[1u32], wgpu::BufferUsages::STORAGE);
        assert!(ctx.read_buffer::<u32>(&no_copy, 0, 1).is_err());
    }

    #[test]
    fn uncaptured_errors_are_recorded_and_taken() {
        let Some(ctx) = test_context() else { return };
        // A shader that does not compile is reported asynchronously.
        let _module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("broken"),
                source: wgpu::ShaderSource::Wgsl("fn main( {".into()),
            });
        let message = ctx.wait().unwrap_err().to_string();
        assert!(message.starts_with("GPU: "), "{message}");
        ctx.take_error().unwrap();
    }

    fn texture(
        ctx: &GpuContext,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> wgpu::Texture {
        ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    }

    /// Rows of 13 Rgba32Float texels (208 bytes) and 37 R32Float texels
    /// (148 bytes) are not multiples of 256 bytes.
    #[test]
    fn texture_read_back_handles_row_padding() {
        let Some(ctx) = test_context() else { return };
        let (width, height) = (37, 5);
        let values: Vec<f32> = (0..width * height).map(|i| i as f32).collect();
        let usage = wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST;
        let r32 = texture(&ctx, width, height, wgpu::TextureFormat::R32Float, usage);
        ctx.queue.write_texture(
            r32.as_image_copy(),
            bytemuck::cast_slice(&values),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 4),
                rows_per_image: Some(height),
            },
            r32.size(),
        );
        assert_eq!(ctx.read_texture::<f32>(&r32).unwrap(), values);
        assert!(ctx.read_texture::<[f32; 4]>(&r32).is_err());

        // A render target whose fragment shader writes the pixel position:
        // texel (x, y) of the read-back must hold the centre (x + ½, y + ½),
        // row 0 at the top.
        let (width, height) = (13, 6);
        let format = wgpu::TextureFormat::Rgba32Float;
        let renderable = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if !ctx
            .format_features(format)
            .allowed_usages
            .contains(renderable)
        {
            eprintln!(
                "{} cannot render to {format:?}; render read-back not tested",
                ctx.adapter
            );
            return;
        }
        let target = texture(
            &ctx,
            width,
            height,
            format,
            wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("position"),
                source: wgpu::ShaderSource::Wgsl(
                    "@vertex fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
                     let xy = vec2<f32>(f32(i & 1u) * 4.0 - 1.0, f32(i >> 1u) * 4.0 - 1.0);
                     return vec4<f32>(xy, 0.5, 1.0);
                 }
                 @fragment fn fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
                     return vec4<f32>(p.xy, 0.0, 1.0);
                 }"
                    .into(),
                ),
            });
        let pipeline = ctx
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("position"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(format.into())],
                }),
                multiview_mask: None,
                cache: None,
            });
        let view = target.create_view(&Default::default());
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: None,
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.draw(0..3, 0..1);
        }
        ctx.submit_and_wait([encoder.finish()]).unwrap();
        let texels = ctx.read_texture::<[f32; 4]>(&target).unwrap();
        assert_eq!(texels.len(), (width * height) as usize);
        for y in 0..height {
            for x in 0..width {
                let t = texels[(y * width + x) as usize];
                assert_eq!(
                    t,
                    [x as f32 + 0.5, y as f32 + 0.5, 0.0, 1.0],
                    "texel ({x}, {y})"
                );
            }
        }
    }

    /// A quad at depth ½ fills the depth buffer; a point drawn at depth ¼
    /// passes the depth test (query > 0: visible), one at ¾ does not. The
    /// points sit on pixel centres, inside the view volume (crates.md).
    #[test]
    fn occlusion_queries_see_points_in_front_of_a_quad() {
        let Some(ctx) = test_context() else { return };
        let (size, depth_format) = (8, wgpu::TextureFormat::Depth32Float);
        let centre = (2.0 * 3.5) / size as f32 - 1.0;
        #[rustfmt::skip]
        let vertices: [[f32; 4]; 8] = [
            [-1.0, -1.0, 0.5, 1.0], [1.0, -1.0, 0.5, 1.0], [1.0, 1.0, 0.5, 1.0],
            [-1.0, -1.0, 0.5, 1.0], [1.0, 1.0, 0.5, 1.0], [-1.0, 1.0, 0.5, 1.0],
            [centre, centre, 0.25, 1.0], [centre, centre, 0.75, 1.0],
        ];
        let vertex_buffer =
            ctx.create_buffer_init("vertices", &vertices, wgpu::BufferUsages::VERTEX);
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth"),
            source: wgpu::ShaderSource::Wgsl(
                "@vertex fn vs(@location(0) p: vec4<f32>) -> @builtin(position) vec4<f32> { return p; }".into(),
            ),
        });
        let layout = [Some(wgpu::VertexBufferLayout {
            array_stride: 16,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x4],
        })];
        let pipeline = |topology, write| {
            ctx.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: None,
                    layout: None,
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs"),
                        compilation_options: Default::default(),
                        buffers: &layout,
                    },
                    primitive: wgpu::PrimitiveState {
                        topology,
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: depth_format,
                        depth_write_enabled: Some(write),
                        depth_compare: Some(wgpu::CompareFunction::Less),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: Default::default(),
                    fragment: None,
                    multiview_mask: None,
                    cache: None,
                })
        };
        let quad = pipeline(wgpu::PrimitiveTopology::TriangleList, true);
        let points = pipeline(wgpu::PrimitiveTopology::PointList, false);
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let depth = texture(&ctx, size, size, depth_format, usage);
        let depth_view = depth.create_view(&Default::default());
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: None,
            ty: wgpu::QueryType::Occlusion,
            count: 2,
        });
        let results = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: 2 * u64::from(wgpu::QUERY_SIZE),
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: None,
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: Some(&queries),
                multiview_mask: None,
            });
            pass.set_vertex_buffer(0, vertex_buffer.slice(..));
            pass.set_pipeline(&quad);
            pass.draw(0..6, 0..1);
            pass.set_pipeline(&points);
            for (query, vertex) in [6u32, 7].into_iter().enumerate() {
                pass.begin_occlusion_query(query as u32);
                pass.draw(vertex..vertex + 1, 0..1);
                pass.end_occlusion_query();
            }
        }
        encoder.resolve_query_set(&queries, 0..2, &results, 0);
        ctx.submit_and_wait([encoder.finish()]).unwrap();
        let samples: Vec<u64> = ctx.read_buffer(&results, 0, 2).unwrap();
        assert!(samples[0] > 0, "point in front of the quad: {samples:?}");
        assert_eq!(samples[1], 0, "point behind the quad: {samples:?}");

        // The GL backend cannot copy depth textures (crates.md).
        if ctx.adapter.backend != "OpenGL" {
            let depths = ctx.read_texture::<f32>(&depth).unwrap();
            assert_eq!(depths, vec![0.5; (size * size) as usize]);
        }
    }
}
