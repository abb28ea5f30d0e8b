//! Copies from GPU buffers and textures to the CPU, waiting for the GPU.

use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

use super::GpuContext;
use crate::{Error, Result};

impl GpuContext {
    /// Copies `count` values of `T` starting `offset` bytes into `buffer`
    /// (which needs `COPY_SRC`) to the CPU: through a mappable staging buffer,
    /// waiting for the GPU. Fails on an out-of-range or misaligned request
    /// (offsets must be multiples of 4 bytes) and on any GPU error of the
    /// copy.
    pub fn read_buffer<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        offset: u64,
        count: usize,
    ) -> Result<Vec<T>> {
        self.capture("read_buffer", || {
            self.read_buffer_uncaptured(buffer, offset, count)
        })
    }

    /// Copies mip level 0 of a 2D `texture` (which needs `COPY_SRC`) to the
    /// CPU: `width × height` texels of `T`, row 0 first (the top row of a
    /// render target), each row unpadded. `T` must have the size of one texel
    /// of the format (e.g. `[f32; 4]` for `Rgba32Float`, `f32` for `R32Float`
    /// or the depth of `Depth32Float`). The 256-byte row alignment of
    /// texture-to-buffer copies is handled here.
    pub fn read_texture<T: bytemuck::Pod>(&self, texture: &wgpu::Texture) -> Result<Vec<T>> {
        self.capture("read_texture", || self.read_texture_uncaptured(texture))
    }

    fn read_buffer_uncaptured<T: bytemuck::Pod>(
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

    fn read_texture_uncaptured<T: bytemuck::Pod>(&self, texture: &wgpu::Texture) -> Result<Vec<T>> {
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
        // Another user polling the same device may be the one to run the
        // callback, a moment after our own wait returns: wait for it.
        let mapped = loop {
            self.wait()?;
            match receiver.recv_timeout(Duration::from_millis(5)) {
                Ok(result) => break result,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(Error::Gpu(
                        "the read-back buffer's mapping was dropped unanswered".into(),
                    ));
                }
            }
        };
        mapped.map_err(|e| Error::Gpu(format!("mapping the read-back buffer: {e}")))?;
        staging
            .get_mapped_range(..)
            .map_err(|e| Error::Gpu(format!("reading the mapped buffer: {e}")))
    }
}
