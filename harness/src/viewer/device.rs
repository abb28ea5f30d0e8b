//! The viewer's device: one adapter and device for the window (or the
//! offscreen target) and for every GPU method it shows.

use std::sync::Arc;

use anyhow::{Context, Result};
use shadow_core::gpu::{GpuContext, INSTALL_HINT, device_limits};

/// Opens the adapter that can present to `surface` (any, offscreen) and a
/// device with the limits the methods need ([`device_limits`]); GPU errors
/// raised outside the methods' own captures are printed, not fatal.
pub fn open(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface<'_>>,
) -> Result<(wgpu::Adapter, Arc<GpuContext>)> {
    let options = wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: surface,
        apply_limit_buckets: false,
    };
    let adapter = pollster::block_on(instance.request_adapter(&options))
        .map_err(|e| anyhow::anyhow!("no GPU adapter for the viewer ({e}). {INSTALL_HINT}"))?;
    let descriptor = wgpu::DeviceDescriptor {
        label: Some("viewer"),
        required_features: wgpu::Features::empty(),
        required_limits: device_limits(&adapter),
        ..Default::default()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&descriptor))
        .with_context(|| format!("opening a device on {}", adapter.get_info().name))?;
    device.on_uncaptured_error(Arc::new(|error: wgpu::Error| {
        eprintln!("GPU error: {error}");
    }));
    Ok((adapter, Arc::new(GpuContext::from_device(device, queue))))
}
