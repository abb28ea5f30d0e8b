//! A method in a renderer's frame: the part of the viewer a renderer author
//! copies.
//!
//! Each frame the host says what changed (the lighting, the geometry) and
//! what it shows (vertices or pixels); [`drive`] runs the method's stages for
//! it. A GPU method ([`Built::Gpu`]) records them into the host's own
//! command encoder on the host's device ([`GpuStages`]): nothing is
//! submitted or waited for, and the result stays on the GPU as a buffer of
//! per-vertex radiance or an image texture that the host's own passes read
//! (`draw.wgsl` here). A CPU method's stages are plain calls, and its result
//! is uploaded.
//!
//! ```no_run
//! use std::sync::Arc;
//!
//! use harness::methods::{self, SharedGpu};
//! use harness::viewer::host::{Output, Work, drive};
//! use shadow_core::{Environment, Scene, gpu::GpuContext};
//!
//! fn first_frame(
//!     device: &wgpu::Device,
//!     queue: &wgpu::Queue,
//!     scene: &Scene,
//!     environment: &Environment,
//! ) -> shadow_core::Result<()> {
//!     // The methods live on the renderer's own device.
//!     let ctx = Arc::new(GpuContext::from_device(device.clone(), queue.clone()));
//!     let mut method = methods::parse("deferred-shadow")?.build_stages(&SharedGpu::with(ctx))?;
//!     method.method_mut().prepare(scene)?; // once per scene
//!
//!     // Every frame: what changed, what is shown.
//!     let (frame, camera) = (scene.frame_geometry(0)?, *scene.camera());
//!     let mut encoder = device.create_command_encoder(&Default::default());
//!     let work = Work {
//!         relight: Some(environment),
//!         update: Some(&frame),
//!         camera: &camera,
//!         per_pixel: true,
//!     };
//!     let (output, _times) = drive(&mut method, &mut encoder, &work, false)?;
//!     if let Output::GpuImage(texture) = output {
//!         // … the renderer's passes bind `texture` (Rgba32Float, alpha = coverage) …
//!         let _ = texture;
//!     }
//!     queue.submit([encoder.finish()]);
//!     Ok(())
//! }
//! ```
//!
//! [`GpuStages`]: shadow_core::gpu::GpuStages

use std::time::{Duration, Instant};

use shadow_core::{Camera, Environment, FrameGeometry, Image, Result, Stage, VertexRadiance};

use crate::methods::Built;

/// What a frame asks of the method.
pub struct Work<'a> {
    /// The lighting, when it changed since the last frame (relight).
    pub relight: Option<&'a Environment>,
    /// The geometry, when it changed (update).
    pub update: Option<&'a FrameGeometry>,
    /// The view: its eye for per-vertex radiance, the whole camera per pixel.
    pub camera: &'a Camera,
    /// An image per pixel (render) instead of radiance per vertex (shade).
    pub per_pixel: bool,
}

/// A frame's result, where the method left it. GPU buffers and textures are
/// handles to the method's own (cloning one copies no data); each is
/// rewritten by the method's next recording.
pub enum Output {
    /// Per-vertex radiance on the GPU: one `vec4<f32>` per vertex, every
    /// object's vertices one after another, written when the encoder runs.
    GpuVertices(wgpu::Buffer),
    /// A per-pixel image on the GPU (`Rgba32Float`, alpha 1 where covered),
    /// written when the encoder runs.
    GpuImage(wgpu::Texture),
    /// Per-vertex radiance computed by the stages' calls.
    Vertices(VertexRadiance),
    /// An image computed by the stages' calls.
    Image(Image),
}

/// A stage run for a frame and the time its call took on the CPU: for a
/// recorded stage the recording only (its GPU work runs when the host
/// submits the encoder).
pub type StageTime = (Stage, Duration);

/// Records into `encoder` (a GPU method, unless `blocking`) or calls (a CPU
/// method, or any method when `blocking`) the stages `work` asks for:
/// relight, update, then shade or render. Called, `render` of a per-vertex
/// method follows a `shade` toward the camera's eye, as `harness run` scores
/// it.
pub fn drive(
    method: &mut Built,
    encoder: &mut wgpu::CommandEncoder,
    work: &Work,
    blocking: bool,
) -> Result<(Output, Vec<StageTime>)> {
    let mut times = Vec::new();
    let mut timed = |stage, call: &mut dyn FnMut() -> Result<()>| {
        let start = Instant::now();
        call()?;
        times.push((stage, start.elapsed()));
        Ok::<_, shadow_core::Error>(())
    };
    let output = match method {
        Built::Gpu(m) if !blocking => {
            if let Some(environment) = work.relight {
                timed(Stage::Relight, &mut || {
                    m.record_relight(environment, encoder)
                })?;
            }
            if let Some(frame) = work.update {
                timed(Stage::Update, &mut || {
                    m.record_update(frame, work.camera, encoder)
                })?;
            }
            let mut output = None;
            if work.per_pixel {
                timed(Stage::Render, &mut || {
                    let texture = m.record_render(work.camera, encoder)?;
                    output = Some(Output::GpuImage(texture.clone()));
                    Ok(())
                })?;
            } else {
                timed(Stage::Shade, &mut || {
                    let buffer = m.record_shade(work.camera.eye, encoder)?;
                    output = Some(Output::GpuVertices(buffer.clone()));
                    Ok(())
                })?;
            }
            output
        }
        _ => {
            let m = method.method_mut();
            if let Some(environment) = work.relight {
                timed(Stage::Relight, &mut || m.relight(environment))?;
            }
            if let Some(frame) = work.update {
                timed(Stage::Update, &mut || m.update(frame, work.camera))?;
            }
            let mut output = None;
            if !work.per_pixel || !m.capabilities().per_pixel {
                timed(Stage::Shade, &mut || {
                    output = Some(Output::Vertices(m.shade(work.camera.eye)?));
                    Ok(())
                })?;
            }
            if work.per_pixel {
                timed(Stage::Render, &mut || {
                    output = Some(Output::Image(m.render(work.camera)?));
                    Ok(())
                })?;
            }
            output
        }
    };
    Ok((output.expect("every branch runs shade or render"), times))
}
