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
//! ```text
//! let ctx = Arc::new(GpuContext::from_device(device.clone(), queue.clone()));
//! let mut method = harness::methods::parse("deferred-shadow")?
//!     .build_stages(&SharedGpu::with(ctx))?;
//! method.method_mut().prepare(&scene)?;            // once per scene
//! // every frame:
//! let mut encoder = device.create_command_encoder(&Default::default());
//! let work = Work { relight: changed_env, update: changed_frame, camera: &camera, per_pixel: true };
//! let output = drive(&mut method, &mut encoder, &work)?;   // records, or calls
//! // … the host's passes read `output` …
//! queue.submit([encoder.finish()]);
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

/// A frame's result, where the method left it.
pub enum Output<'m> {
    /// Per-vertex radiance on the GPU: one `vec4<f32>` per vertex, every
    /// object's vertices one after another, written when the encoder runs.
    GpuVertices(&'m wgpu::Buffer),
    /// A per-pixel image on the GPU (`Rgba32Float`, alpha 1 where covered),
    /// written when the encoder runs.
    GpuImage(&'m wgpu::Texture),
    /// A CPU method's per-vertex radiance.
    Vertices(VertexRadiance),
    /// A CPU method's image.
    Image(Image),
}

/// The stages run for a frame, with the time each call took on the CPU:
/// for a GPU method the recording only (its GPU work runs when the host
/// submits the encoder).
pub type StageTimes = Vec<(Stage, Duration)>;

/// Runs (CPU) or records into `encoder` (GPU) the stages `work` asks for:
/// relight, update, then shade or render.
pub fn drive<'m>(
    method: &'m mut Built,
    encoder: &mut wgpu::CommandEncoder,
    work: &Work,
) -> Result<(Output<'m>, StageTimes)> {
    let mut times = StageTimes::new();
    let mut timed = |stage, call: &mut dyn FnMut() -> Result<()>| {
        let start = Instant::now();
        call()?;
        times.push((stage, start.elapsed()));
        Ok::<_, shadow_core::Error>(())
    };
    match method {
        Built::Gpu(m) => {
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
            let start = Instant::now();
            let output = if work.per_pixel {
                let texture = m.record_render(work.camera, encoder)?;
                times.push((Stage::Render, start.elapsed()));
                Output::GpuImage(texture)
            } else {
                let buffer = m.record_shade(work.camera.eye, encoder)?;
                times.push((Stage::Shade, start.elapsed()));
                Output::GpuVertices(buffer)
            };
            Ok((output, times))
        }
        Built::Cpu(m) => {
            if let Some(environment) = work.relight {
                timed(Stage::Relight, &mut || m.relight(environment))?;
            }
            if let Some(frame) = work.update {
                timed(Stage::Update, &mut || m.update(frame, work.camera))?;
            }
            let start = Instant::now();
            let output = if work.per_pixel {
                let image = m.render(work.camera)?;
                times.push((Stage::Render, start.elapsed()));
                Output::Image(image)
            } else {
                let radiance = m.shade(work.camera.eye)?;
                times.push((Stage::Shade, start.elapsed()));
                Output::Vertices(radiance)
            };
            Ok((output, times))
        }
    }
}
