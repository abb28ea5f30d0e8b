//! GPU device setup, error capture and read-back shared by the wgpu method
//! crates (`occlusion-query`, `deferred-shadow`), so that both open devices,
//! report adapters and surface GPU errors the same way (DESIGN.md, "Layout"),
//! and the plumbing both build on: layout entries and pipelines
//! ([`binding`]), uploads and growing buffers ([`buffer`]), depth-only
//! passes and occlusion queries ([`depth`]), per-dispatch uniform blocks
//! ([`uniforms`]) and WGSL declarations generated from Rust ([`wgsl`]).
//!
//! # One device, many users
//!
//! A [`GpuContext`] is a device and its queue, shared as `Arc<GpuContext>`:
//! the harness opens one ([`GpuContext::new`]) and hands it to every GPU
//! method of a run; a host renderer hands over its own device and queue
//! ([`GpuContext::from_device`]), and the methods then record into its command
//! encoders ([`GpuStages`]).
//!
//! # Errors on the GPU
//!
//! wgpu reports most errors (validation, out of memory, shader compilation)
//! to an error sink rather than as return values. Every GPU call of a method
//! runs inside [`GpuContext::capture`], which opens wgpu error scopes around
//! it and turns what they caught into an [`Error::Gpu`] of that call. Error
//! scopes belong to the thread that opened them, so two users of one context,
//! on one thread or on several, never see each other's errors; the price is
//! that a method makes its GPU calls on the thread that runs its stage, not
//! from worker threads.
//!
//! On a host's device nothing else is touched: the host's uncaptured-error
//! handler and device-lost callback stay as they were. On a device
//! [`GpuContext::new`] opened, an error raised outside every capture (by a
//! caller using the device directly) is printed to standard error instead of
//! wgpu's default panic, and a lost device is reported to every later capture.

pub mod binding;
pub mod buffer;
pub mod depth;
mod readback;
mod stages;
pub mod uniforms;
pub mod wgsl;

use std::fmt;
use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use crate::{Error, Result};

pub use stages::GpuStages;

/// How to get an adapter the methods run on where there is no GPU.
pub const INSTALL_HINT: &str = "On Linux without a GPU install Mesa's software Vulkan driver: \
     apt-get install mesa-vulkan-drivers libvulkan1";

/// The instance settings [`GpuContext::new`] opens adapters with: the
/// primary backends (Vulkan, Metal, DirectX 12), or those `WGPU_BACKEND`
/// names but OpenGL, and wgpu's other environment variables. A host that
/// opens its own device for the methods can start from it.
pub fn instance_descriptor() -> wgpu::InstanceDescriptor {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = wgpu::Backends::PRIMARY;
    let mut descriptor = descriptor.with_env();
    // OpenGL's shading language cannot read depth textures as the methods
    // do, so it is never tried, even where `WGPU_BACKEND` names it.
    descriptor.backends.remove(wgpu::Backends::GL);
    descriptor
}

/// The limits [`GpuContext::new`] opens its device with, for a host that
/// opens its own device for the methods: WebGPU's defaults (or the
/// adapter's, where lower) with the buffer and 2D texture sizes raised to
/// what `adapter` supports (the methods keep one storage buffer per scene).
pub fn device_limits(adapter: &wgpu::Adapter) -> wgpu::Limits {
    let supported = adapter.limits();
    wgpu::Limits {
        max_buffer_size: supported.max_buffer_size,
        max_storage_buffer_binding_size: supported.max_storage_buffer_binding_size,
        max_texture_dimension_2d: supported.max_texture_dimension_2d,
        // Downlevel adapters (GL) support less than WebGPU's defaults.
        ..wgpu::Limits::default().or_worse_values_from(&supported)
    }
}

/// What the harness reports about the adapter a run used (DESIGN.md, "Time":
/// a software adapter such as lavapipe is named as such).
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
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

/// A wgpu device and queue, with the adapter they came from (see the module
/// docs for how errors are captured).
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    /// The adapter, when this context opened the device itself.
    wgpu_adapter: Option<wgpu::Adapter>,
    /// Why the device was lost, when this context opened it and it was.
    lost: Option<Arc<Mutex<Option<String>>>>,
}

impl fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter)
            .field("owned", &self.wgpu_adapter.is_some())
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
    /// Opens the high-performance adapter of the primary backends (Vulkan,
    /// Metal, DirectX 12; `WGPU_BACKEND` picks others), without a surface,
    /// and a device with default limits except the buffer and 2D texture
    /// sizes, which are raised to what the adapter supports (the methods
    /// keep one storage buffer per scene). No optional features are
    /// requested: occlusion queries are core WebGPU.
    ///
    /// OpenGL is not among the backends tried: the methods' shaders read
    /// depth textures with `textureLoad`, which GLSL cannot; with
    /// `WGPU_BACKEND=gl` there is no adapter, and the error says so.
    ///
    /// Fails with [`Error::Gpu`] when there is no suitable adapter, saying
    /// how to get a software one ([`INSTALL_HINT`]), or when the device
    /// cannot be created.
    pub fn new() -> Result<GpuContext> {
        let descriptor = instance_descriptor();
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
                "no GPU adapter found ({e}; backends requested: {}, compiled in: {}, WGPU_BACKEND={env}; \
                 OpenGL is never used). {INSTALL_HINT}",
                backend_names(requested),
                backend_names(wgpu::Instance::enabled_backend_features())
            ))
        })?;
        let summary = AdapterSummary::new(&adapter.get_info());
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("shadow-core"),
            required_features: wgpu::Features::empty(),
            required_limits: device_limits(&adapter),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&descriptor))
            .map_err(|e| Error::Gpu(format!("cannot open a device on {summary}: {e}")))?;

        device.on_uncaptured_error(Arc::new(|error: wgpu::Error| {
            eprintln!(
                "GPU error outside every captured stage: {}",
                error_message(&error)
            );
        }));
        let lost = Arc::new(Mutex::new(None));
        let record = Arc::clone(&lost);
        device.set_device_lost_callback(move |reason, message| {
            let mut lost = record.lock().unwrap_or_else(|e| e.into_inner());
            lost.get_or_insert(format!("device lost ({reason:?}): {message}"));
        });
        Ok(GpuContext {
            device,
            queue,
            adapter: summary,
            wgpu_adapter: Some(adapter),
            lost: Some(lost),
        })
    }

    /// A context on a device and queue the caller opened (a host renderer's),
    /// without an adapter. The device's uncaptured-error handler and
    /// device-lost callback are left as the host set them; errors of the
    /// methods' own calls are captured per call ([`GpuContext::capture`]).
    /// Methods check what they need of the device with
    /// [`GpuContext::require`].
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> GpuContext {
        GpuContext {
            adapter: AdapterSummary::new(&device.adapter_info()),
            device,
            queue,
            wgpu_adapter: None,
            lost: None,
        }
    }

    /// Fails with an [`Error::Gpu`] naming `user`, each missing feature and
    /// each limit of `limits` the device does not reach (with the device's
    /// value). Build `limits` from a low baseline such as
    /// `wgpu::Limits::downlevel_webgl2_defaults()` with the fields the user
    /// needs raised, so that only those can fail.
    pub fn require(
        &self,
        user: &str,
        features: wgpu::Features,
        limits: &wgpu::Limits,
    ) -> Result<()> {
        let mut missing = Vec::new();
        let absent = features - self.device.features();
        if !absent.is_empty() {
            missing.push(format!("features {absent:?}"));
        }
        limits.check_limits_with_fail_fn(&self.device.limits(), false, |name, needed, has| {
            missing.push(format!("{name} {needed} (the device has {has})"))
        });
        if missing.is_empty() {
            Ok(())
        } else {
            Err(Error::Gpu(format!(
                "{user} needs {} of the device on {}",
                missing.join(", "),
                self.adapter
            )))
        }
    }

    /// What the adapter can do with textures of `format`: downlevel backends
    /// (OpenGL) cannot render to `Rgba32Float`, for instance, so a method
    /// picks its render-target formats with this. On a host's device, whose
    /// adapter is not known, what WebGPU guarantees for the device's
    /// features.
    pub fn format_features(&self, format: wgpu::TextureFormat) -> wgpu::TextureFormatFeatures {
        match &self.wgpu_adapter {
            Some(adapter) => adapter.get_texture_format_features(format),
            None => format.guaranteed_format_features(self.device.features()),
        }
    }

    /// Runs `work` with every GPU error its calls raise on this thread
    /// captured: the result of `work`, or the first GPU error (naming `what`
    /// and the count of further ones), or a lost device. Captures nest.
    pub fn capture<T>(&self, what: &str, work: impl FnOnce() -> Result<T>) -> Result<T> {
        let scopes = Scopes::push(&self.device);
        let result = work();
        let errors = scopes.pop();
        if let Some(reason) = self.lost_reason() {
            return Err(Error::Gpu(format!("{what}: {reason}")));
        }
        match errors.split_first() {
            None => result,
            Some((first, [])) => Err(Error::Gpu(format!("{what}: {first}"))),
            Some((first, rest)) => Err(Error::Gpu(format!(
                "{what}: {first} (and {} more errors)",
                rest.len()
            ))),
        }
    }

    fn lost_reason(&self) -> Option<String> {
        let lost = self.lost.as_ref()?;
        lost.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Blocks until the queue has finished all submitted work.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(drop)
            .map_err(|e| Error::Gpu(format!("waiting for the device: {e}")))
    }

    /// Submits `commands` and waits for them to finish, with errors captured.
    pub fn submit_and_wait(
        &self,
        commands: impl IntoIterator<Item = wgpu::CommandBuffer>,
    ) -> Result<()> {
        self.capture("submitting work", || {
            self.queue.submit(commands);
            self.wait()
        })
    }

    /// A blocking stage: records with `record` into a new command encoder,
    /// submits it and waits until the queue is idle, with every error
    /// captured as `what`'s. What [`GpuStages`] records, the
    /// [`ShadowMethod`](crate::ShadowMethod) stages run through this.
    pub fn run<T>(
        &self,
        what: &str,
        record: impl FnOnce(&mut wgpu::CommandEncoder) -> Result<T>,
    ) -> Result<T> {
        self.capture(what, || {
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(what) });
            let value = record(&mut encoder)?;
            self.queue.submit([encoder.finish()]);
            self.wait()?;
            Ok(value)
        })
    }

    /// A single-level, single-sample 2D texture of `width` × `height`.
    pub fn create_texture_2d(
        &self,
        label: &str,
        (width, height): (u32, u32),
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> wgpu::Texture {
        self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
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
}

/// The three wgpu error scopes of one capture, popped in reverse order of
/// pushing (as wgpu requires) even when the work between them panics.
struct Scopes(Vec<wgpu::ErrorScopeGuard>);

impl Scopes {
    fn push(device: &wgpu::Device) -> Scopes {
        Scopes(
            [
                wgpu::ErrorFilter::Validation,
                wgpu::ErrorFilter::OutOfMemory,
                wgpu::ErrorFilter::Internal,
            ]
            .map(|filter| device.push_error_scope(filter))
            .into(),
        )
    }

    /// The errors caught, innermost scope first.
    fn pop(mut self) -> Vec<String> {
        let mut errors = Vec::new();
        while let Some(scope) = self.0.pop() {
            // wgpu-core resolves a popped scope at once.
            if let Some(error) = pollster::block_on(scope.pop()) {
                errors.push(error_message(&error));
            }
        }
        errors
    }
}

impl Drop for Scopes {
    fn drop(&mut self) {
        while let Some(scope) = self.0.pop() {
            drop(scope);
        }
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

/// The variable that lets the tests skip what the machine lacks: a
/// comma-separated list of `gpu` (no adapter), `gltf-tools` (the npm glTF
/// tools), `browser` (Chromium and playwright-core), `display` (Xvfb and
/// xdotool, for the viewer's window), or `all`. The build
/// script of each crate with such tests reads it and marks the tests that
/// need a listed thing as ignored, so that `cargo test` reports them as
/// skipped, not passed; a README example that needs a GPU is then left out
/// of the doctests.
pub const SKIP_VARIABLE: &str = "SOFT_SHADOWS_SKIP";

/// The context every GPU test in the workspace runs on: one per process,
/// shared by the tests (as the harness shares one between methods).
///
/// Without a suitable adapter it panics, naming what to install and how to
/// skip the GPU tests instead ([`SKIP_VARIABLE`]): a GPU test never passes
/// without having run.
pub fn test_context() -> Arc<GpuContext> {
    static CONTEXT: std::sync::OnceLock<std::result::Result<Arc<GpuContext>, String>> =
        std::sync::OnceLock::new();
    match CONTEXT.get_or_init(|| GpuContext::new().map(Arc::new).map_err(|e| e.to_string())) {
        Ok(context) => Arc::clone(context),
        Err(e) => panic!(
            "this test needs a GPU adapter: {e}\n\
             To skip the GPU tests instead (reported as ignored), set {SKIP_VARIABLE}=gpu."
        ),
    }
}

/// A context of its own on the test adapter, its device created with the
/// adapter's limits lowered by `lower`: what a host renderer's device at low
/// limits gives a method. Created after [`test_context`], so that a missing
/// adapter fails as there; wgpu's default handler panics on any error
/// raised outside a capture on this device.
pub fn limited_test_context(lower: impl FnOnce(&mut wgpu::Limits)) -> Arc<GpuContext> {
    let _shared = test_context();
    let instance = wgpu::Instance::new(instance_descriptor());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
        .expect("the adapter test_context found");
    let mut limits = wgpu::Limits::default().or_worse_values_from(&adapter.limits());
    lower(&mut limits);
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits,
        ..Default::default()
    }))
    .expect("a device with lower limits");
    Arc::new(GpuContext::from_device(device, queue))
}

#[cfg(test)]
mod tests;
