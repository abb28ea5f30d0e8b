//! The stages of a GPU method recorded into a caller's command encoder.

use std::sync::Arc;

use glam::Vec3;

use super::GpuContext;
use crate::{Camera, Environment, FrameGeometry, Result, ShadowMethod};

/// A GPU method's stages as commands recorded into a caller's encoder, for a
/// host renderer that submits them with its own frame: nothing is submitted
/// and nothing waits, and the results stay on the GPU. Uploads go through
/// `queue.write_buffer`/`write_texture`, which wgpu orders before the next
/// submission, so the caller submits `encoder` after the calls (and before
/// recording the next frame's).
///
/// The [`ShadowMethod`] stages of such a method are these records run through
/// [`GpuContext::run`]: recorded, submitted, waited for.
///
/// Errors the recording can detect are returned; errors wgpu detects when
/// the caller finishes or submits the encoder go to the caller's error
/// scopes or handler, since the encoder is the caller's.
pub trait GpuStages: ShadowMethod {
    /// The device the method's resources live on: the encoders passed in
    /// must come from it.
    fn context(&self) -> &Arc<GpuContext>;

    /// [`ShadowMethod::relight`], recorded.
    fn record_relight(
        &mut self,
        environment: &Environment,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()>;

    /// [`ShadowMethod::update`], recorded.
    fn record_update(
        &mut self,
        frame: &FrameGeometry,
        camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()>;

    /// [`ShadowMethod::shade`], recorded: once the encoder has run, the
    /// returned buffer (`STORAGE | COPY_SRC`) holds one `vec4<f32>` per
    /// vertex, every object's vertices one after another: linear RGB radiance,
    /// and w = 1 where the vertex was evaluated, 0 where not.
    fn record_shade(
        &mut self,
        eye: Vec3,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Buffer>;

    /// [`ShadowMethod::render`], recorded: once the encoder has run, the
    /// returned texture (`camera.width × camera.height`, `Rgba32Float`,
    /// `TEXTURE_BINDING | COPY_SRC`, row 0 at the top) holds linear RGB
    /// radiance, and alpha = 1 where a surface covers the pixel, 0 where not.
    /// Methods without [`Capability::PerPixel`](crate::Capability::PerPixel)
    /// may answer [`Error::Unsupported`](crate::Error::Unsupported): a host
    /// draws their [`GpuStages::record_shade`] buffer as vertex colours.
    fn record_render(
        &mut self,
        camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Texture>;
}
