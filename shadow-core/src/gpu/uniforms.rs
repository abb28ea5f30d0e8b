//! Uniform blocks written once per recorded dispatch or draw: slots 256
//! bytes apart in one buffer, bound with a dynamic offset, so that several
//! dispatches recorded into one encoder each read their own values (a
//! `write_buffer` lands before the whole submission, not between commands).

use std::marker::PhantomData;
use std::num::NonZeroU64;

use super::GpuContext;
use bytemuck::Pod;

/// A buffer of `slots` uniform blocks of type `T`.
pub struct Slots<T> {
    buffer: wgpu::Buffer,
    slots: usize,
    _block: PhantomData<T>,
}

/// Distance between slots: wgpu's largest minimum uniform offset alignment.
pub const STRIDE: u64 = 256;

impl<T: Pod> Slots<T> {
    pub fn new(ctx: &GpuContext, label: &str, slots: usize) -> Slots<T> {
        assert!(
            size_of::<T>() as u64 <= STRIDE,
            "a uniform block over 256 bytes"
        );
        Slots {
            buffer: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: STRIDE * slots.max(1) as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            slots: slots.max(1),
            _block: PhantomData,
        }
    }

    /// How many slots the buffer holds (at least one).
    pub fn capacity(&self) -> usize {
        self.slots
    }

    /// Writes `value` into `slot` (before the next submission) and returns
    /// the dynamic offset that binds it.
    pub fn write(&self, ctx: &GpuContext, slot: usize, value: &T) -> u32 {
        assert!(slot < self.slots, "uniform slot {slot} of {}", self.slots);
        let offset = STRIDE * slot as u64;
        ctx.queue
            .write_buffer(&self.buffer, offset, bytemuck::bytes_of(value));
        offset as u32
    }

    /// The binding of one slot, for a bind group entry with a dynamic
    /// offset ([`super::binding::dynamic_uniform`]).
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: 0,
            size: NonZeroU64::new(size_of::<T>() as u64),
        })
    }
}
