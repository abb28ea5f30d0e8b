//! Buffers made for what they hold: uploads written once, and storage the
//! GPU writes that grows to fit.

use bytemuck::Pod;

use super::GpuContext;

/// The smallest buffer made here: larger than any one element a shader
/// binds, so that an empty upload still binds.
pub const MIN_BUFFER: u64 = 256;

/// The most bytes one storage buffer may hold on a device of `limits`, bound
/// whole: the smaller of its binding and buffer limits.
pub fn storage_limit(limits: &wgpu::Limits) -> u64 {
    limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
}

/// A buffer of `bytes` (at least [`MIN_BUFFER`]), zeroed.
pub fn blank(ctx: &GpuContext, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(MIN_BUFFER),
        usage,
        mapped_at_creation: false,
    })
}

/// A buffer made for `values` (at least [`MIN_BUFFER`] bytes, zero past
/// them), with `usage` and `COPY_DST`: nothing recorded before reads it, so
/// the write, which lands before the next submission, is seen by exactly
/// the commands recorded from now on that bind it.
pub fn upload<T: Pod>(
    ctx: &GpuContext,
    label: &str,
    values: &[T],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(values);
    let buffer = blank(
        ctx,
        label,
        bytes.len() as u64,
        usage | wgpu::BufferUsages::COPY_DST,
    );
    if !bytes.is_empty() {
        ctx.queue.write_buffer(&buffer, 0, bytes);
    }
    buffer
}

/// A storage buffer the GPU writes (by shaders, or copies: `COPY_DST`),
/// which grows to fit; its contents are lost when it grows.
pub struct Growing {
    buffer: wgpu::Buffer,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl Growing {
    /// [`MIN_BUFFER`] bytes until [`Growing::reserve`] asks for more.
    pub fn new(ctx: &GpuContext, label: &'static str, usage: wgpu::BufferUsages) -> Growing {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        Growing {
            buffer: blank(ctx, label, MIN_BUFFER, usage),
            label,
            usage,
        }
    }

    /// At least `bytes` long: the next power of two, or what the device
    /// binds when that is less (a plan checked against
    /// [`storage_limit`] fits).
    pub fn reserve(&mut self, ctx: &GpuContext, bytes: u64) {
        if self.buffer.size() < bytes {
            let room = bytes
                .next_power_of_two()
                .min(storage_limit(&ctx.device.limits()));
            self.buffer = blank(ctx, self.label, room.max(bytes), self.usage);
        }
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}
