//! `harness view`: the window, its controls and its panel.
//!
//! Mouse: left drag orbits, right (or middle) drag pans, the wheel zooms.
//! Keys: 1–5 the method families (unshadowed, hemi-raster, occlusion-query,
//! deferred-shadow, raytrace:16), ← → turn the environment by 15°, ↑ ↓
//! change the exposure by ½ EV, space plays and pauses the animation, `.`
//! and `,` step it, H toggles the error heat map, R resets the camera, Q or
//! Esc quits.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use shadow_core::gpu::GpuContext;
use winit::{
    application::ApplicationHandler,
    dpi::{PhysicalPosition, PhysicalSize},
    event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent},
    event_loop::{ActiveEventLoop, EventLoop},
    keyboard::{Key, NamedKey},
    window::{Window, WindowId},
};

use super::{
    device, orbit, panel,
    state::{Setup, ViewState},
};

/// The methods keys 1–5 switch to: each family's standard setting.
pub const KEYED_METHODS: [&str; 5] = [
    "unshadowed",
    "hemi-raster",
    "occlusion-query",
    "deferred-shadow",
    "raytrace:16",
];

/// Degrees the arrow keys turn the environment by.
const TURN_STEP: f32 = 15.0;

/// Opens the window and runs until it is closed, starting with the heat map
/// on or off and the display exposure at `exposure_ev`; prints the frame
/// times.
pub fn run(setup: Setup, size: (u32, u32), heat_map: bool, exposure_ev: f32) -> Result<()> {
    let event_loop = EventLoop::new().context(
        "cannot open a window (no display: set DISPLAY, run under xvfb-run, or use --screenshot)",
    )?;
    let mut app = App {
        setup: Some(setup),
        size,
        start: (heat_map, exposure_ev),
        open: None,
        failure: None,
    };
    event_loop.run_app(&mut app)?;
    if let Some(failure) = app.failure {
        return Err(failure);
    }
    if let Some(open) = &app.open {
        println!(
            "{} on {} ({}):",
            open.state.method_name(),
            open.state.scene().name(),
            open.state.adapter()
        );
        for s in open.state.clock.summaries() {
            println!(
                "  {:<16} {:>9.2} ms  ({:.2}–{:.2}, last {} frames)",
                s.name, s.median_ms, s.min_ms, s.max_ms, s.samples
            );
        }
    }
    Ok(())
}

struct App {
    setup: Option<Setup>,
    size: (u32, u32),
    /// The heat map and display exposure to start with.
    start: (bool, f32),
    open: Option<Open>,
    failure: Option<anyhow::Error>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        let Some(setup) = self.setup.take() else {
            return;
        };
        match Open::new(event_loop, setup, self.size) {
            Ok(mut open) => {
                (open.state.heat_map, open.state.exposure_ev) = self.start;
                self.open = Some(open);
            }
            Err(e) => {
                self.failure = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(open) = &mut self.open else {
            return;
        };
        if let Err(e) = open.event(event_loop, event) {
            self.failure = Some(e);
            event_loop.exit();
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(open) = &self.open
            && (open.state.playing || open.redraw)
        {
            open.window.request_redraw();
        }
    }
}

/// Mouse buttons held and where the pointer was.
#[derive(Default)]
struct Drag {
    orbit: bool,
    pan: bool,
    last: Option<PhysicalPosition<f64>>,
}

struct Open {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: Arc<GpuContext>,
    state: ViewState,
    egui: egui::Context,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    panel: panel::Panel,
    drag: Drag,
    redraw: bool,
}

impl Open {
    fn new(
        event_loop: &ActiveEventLoop,
        setup: Setup,
        (width, height): (u32, u32),
    ) -> Result<Open> {
        let attributes = Window::default_attributes()
            .with_title(format!("harness view: {}", setup.scene.name()))
            .with_inner_size(PhysicalSize::new(width, height));
        let window = Arc::new(event_loop.create_window(attributes)?);
        let instance = wgpu::Instance::new(shadow_core::gpu::instance_descriptor());
        let surface = instance.create_surface(Arc::clone(&window))?;
        let (adapter, ctx) = device::open(&instance, Some(&surface))?;
        let capabilities = surface.get_capabilities(&adapter);
        let format = capabilities
            .formats
            .iter()
            .copied()
            .find(wgpu::TextureFormat::is_srgb)
            .context("the window's surface offers no sRGB format")?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            desired_maximum_frame_latency: 2,
            present_mode: wgpu::PresentMode::AutoNoVsync,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: vec![],
        };
        surface.configure(&ctx.device, &config);
        let state = ViewState::new(
            setup,
            Arc::clone(&ctx),
            format,
            (config.width, config.height),
        )?;
        let egui = egui::Context::default();
        let egui_state = egui_winit::State::new(
            egui.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(ctx.device.limits().max_texture_dimension_2d as usize),
        );
        let egui_renderer = egui_wgpu::Renderer::new(&ctx.device, format, Default::default());
        let panel = panel::Panel::new(state.method_name());
        Ok(Open {
            window,
            surface,
            config,
            ctx,
            state,
            egui,
            egui_state,
            egui_renderer,
            panel,
            drag: Drag::default(),
            redraw: true,
        })
    }

    fn event(&mut self, event_loop: &ActiveEventLoop, event: WindowEvent) -> Result<()> {
        let response = self.egui_state.on_window_event(&self.window, &event);
        if response.repaint {
            self.redraw = true;
        }
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                self.config.width = size.width.max(1);
                self.config.height = size.height.max(1);
                self.surface.configure(&self.ctx.device, &self.config);
                self.state.resize((self.config.width, self.config.height));
                self.redraw = true;
            }
            WindowEvent::RedrawRequested => self.frame()?,
            _ if response.consumed => {}
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, &event.logical_key);
                self.redraw = true;
            }
            WindowEvent::MouseInput { state, button, .. } => {
                let pressed = state == ElementState::Pressed;
                match button {
                    MouseButton::Left => self.drag.orbit = pressed,
                    MouseButton::Right | MouseButton::Middle => self.drag.pan = pressed,
                    _ => {}
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let Some(last) = self.drag.last {
                    let height = self.config.height as f32;
                    let (dx, dy) = ((position.x - last.x) as f32, (position.y - last.y) as f32);
                    let camera = &mut self.state.camera;
                    if self.drag.orbit {
                        *camera = orbit::orbit(camera, -dx * 0.01, dy * 0.01);
                        self.redraw = true;
                    } else if self.drag.pan {
                        *camera = orbit::pan(camera, -dx / height, dy / height);
                        self.redraw = true;
                    }
                }
                self.drag.last = Some(position);
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                self.state.camera = orbit::zoom(&self.state.camera, 0.9f32.powf(lines));
                self.redraw = true;
            }
            _ => {}
        }
        Ok(())
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: &Key) {
        let state = &mut self.state;
        let outcome = match key.as_ref() {
            Key::Character(c) => match c {
                "1" | "2" | "3" | "4" | "5" => {
                    let index = c.parse::<usize>().unwrap_or(1) - 1;
                    let switched = state.switch_method(KEYED_METHODS[index]);
                    self.panel.name = state.method_name().to_string();
                    switched
                }
                "." => state.step(1),
                "," => state.step(-1),
                "h" | "H" => {
                    state.heat_map = !state.heat_map;
                    Ok(())
                }
                "r" | "R" => {
                    state.reset_camera();
                    Ok(())
                }
                "q" | "Q" => {
                    event_loop.exit();
                    Ok(())
                }
                _ => Ok(()),
            },
            Key::Named(NamedKey::Space) => {
                state.playing = !state.playing;
                Ok(())
            }
            Key::Named(NamedKey::ArrowLeft) => {
                state.set_turn(state.turn() - TURN_STEP);
                Ok(())
            }
            Key::Named(NamedKey::ArrowRight) => {
                state.set_turn(state.turn() + TURN_STEP);
                Ok(())
            }
            Key::Named(NamedKey::ArrowUp) => {
                state.exposure_ev += 0.5;
                Ok(())
            }
            Key::Named(NamedKey::ArrowDown) => {
                state.exposure_ev -= 0.5;
                Ok(())
            }
            Key::Named(NamedKey::Escape) => {
                event_loop.exit();
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(e) = outcome {
            eprintln!("error: {e}");
            state.error = Some(e.to_string());
        }
    }

    /// Draws one frame: the method's stages and the picture, the panel over
    /// it, submitted and waited for (so that the frame's time is its work's).
    fn frame(&mut self) -> Result<()> {
        self.redraw = false;
        let start = Instant::now();
        // The panel first: what it changes is drawn in this frame.
        let input = self.egui_state.take_egui_input(&self.window);
        let mut output = self
            .egui
            .run_ui(input, |ui| self.panel.show(ui, &mut self.state));
        self.egui_state
            .handle_platform_output(&self.window, output.platform_output);
        if self.state.playing
            && let Err(e) = self.state.step(1)
        {
            self.state.error = Some(e.to_string());
        }
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                self.redraw = true;
                return Ok(());
            }
            _ => {
                self.surface.configure(&self.ctx.device, &self.config);
                self.redraw = true;
                return Ok(());
            }
        };
        let view = texture.texture.create_view(&Default::default());
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let drawn = self
            .ctx
            .capture("viewer frame", || self.state.draw(&mut encoder, &view));
        let ran = drawn.unwrap_or_else(|e| {
            eprintln!("error: {e}");
            self.state.error = Some(e.to_string());
            false
        });

        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point: output.pixels_per_point,
        };
        let primitives = self.egui.tessellate(output.shapes, output.pixels_per_point);
        for (id, deltas) in &output.textures_delta.set {
            for delta in deltas {
                self.egui_renderer
                    .update_texture(&self.ctx.device, &self.ctx.queue, *id, delta);
            }
        }
        let extra = self.egui_renderer.update_buffers(
            &self.ctx.device,
            &self.ctx.queue,
            &mut encoder,
            &primitives,
            &screen,
        );
        {
            let pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("panel"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.egui_renderer
                .render(&mut pass.forget_lifetime(), &primitives, &screen);
        }
        for id in &output.textures_delta.free {
            self.egui_renderer.free_texture(id);
        }
        output.textures_delta.clear();
        let submitted = Instant::now();
        self.ctx
            .queue
            .submit(extra.into_iter().chain([encoder.finish()]));
        self.ctx.wait()?;
        if ran {
            self.state.clock.add("GPU work", submitted.elapsed());
        }
        self.window.pre_present_notify();
        self.ctx.queue.present(texture);
        // A frame that drew the last picture again (the panel, the exposure)
        // is not the method's.
        let row = if ran { "frame" } else { "redraw" };
        self.state.clock.add(row, start.elapsed());
        if output
            .viewport_output
            .get(&egui::ViewportId::ROOT)
            .is_some_and(|v| v.repaint_delay.is_zero())
        {
            self.redraw = true;
        }
        Ok(())
    }
}
