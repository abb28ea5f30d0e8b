//! `harness view --screenshot`: the viewer's frames drawn into a texture
//! instead of a window, the last one written as a PNG.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;

use super::{
    device,
    state::{Heat, Setup, ViewState},
};
use crate::io::write_png_atomic;

/// The offscreen target's format: sRGB, as the PNGs of `harness run --images`.
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// What a screenshot run asks for.
pub struct Shot<'a> {
    pub size: (u32, u32),
    /// Frames drawn; the animation advances one scene frame per drawn frame
    /// from the first, so the picture is of scene frame `(frames − 1) mod
    /// count`.
    pub frames: usize,
    pub heat_map: bool,
    pub exposure_ev: f32,
    pub out: &'a Path,
}

/// Draws `shot.frames` frames and writes the last as a PNG; prints the
/// frame times and, with the heat map, the error.
pub fn screenshot(setup: Setup, shot: &Shot) -> Result<()> {
    let instance = wgpu::Instance::new(shadow_core::gpu::instance_descriptor());
    let (_adapter, ctx) = device::open(&instance, None)?;
    let mut state = ViewState::new(setup, ctx.clone(), FORMAT, shot.size)?;
    state.heat_map = shot.heat_map;
    state.exposure_ev = shot.exposure_ev;
    let target = ctx.create_texture_2d(
        "viewer screenshot",
        shot.size,
        FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let view = target.create_view(&Default::default());
    // The exposure of the frame the picture shows, as `harness run
    // --images-dir` takes its last frame's.
    let shown = (shot.frames.max(1) - 1) as isize;
    state.step(shown)?;
    state.fix_exposure()?;
    state.step(-shown)?;
    for index in 0..shot.frames.max(1) {
        if index > 0 {
            state.step(1)?;
        }
        let start = Instant::now();
        let ran = ctx.capture("viewer frame", || {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let ran = state.draw(&mut encoder, &view)?;
            let submitted = Instant::now();
            ctx.queue.submit([encoder.finish()]);
            ctx.wait()?;
            if ran {
                state.clock.add("GPU work", submitted.elapsed());
            }
            Ok(ran)
        })?;
        let row = if ran { "frame" } else { "redraw" };
        state.clock.add(row, start.elapsed());
    }
    let texels: Vec<[u8; 4]> = ctx.read_texture(&target)?;
    let rgb: Vec<u8> = texels.iter().flat_map(|t| [t[0], t[1], t[2]]).collect();
    write_png_atomic(shot.out, &rgb, shot.size.0, shot.size.1)?;
    println!(
        "{} on {}, frame {} of {}, {}×{} ({}): wrote {}",
        state.method_name(),
        state.scene().name(),
        state.frame_index(),
        state.scene().frames().len(),
        shot.size.0,
        shot.size.1,
        state.adapter(),
        shot.out.display()
    );
    for s in state.clock.summaries() {
        println!(
            "  {:<16} {:>9.2} ms  ({:.2}–{:.2}, {} frames)",
            s.name, s.median_ms, s.min_ms, s.max_ms, s.samples
        );
    }
    match state.heat() {
        Some(Heat::Error(e)) => println!(
            "  error against the cached image reference: {:.2}%",
            e * 100.0
        ),
        Some(Heat::NoReference) => println!(
            "  no cached image reference for this view (run `harness run --images-dir` first)"
        ),
        None => {}
    }
    Ok(())
}
