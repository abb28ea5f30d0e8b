//! What the viewer shows and how it gets there: the scene and its current
//! frame, the environment and its turn, the method, the camera, the
//! exposure and the heat map; each frame it drives the method
//! ([`super::host`]) where something changed, and records the picture
//! ([`super::draw`]).

use std::sync::Arc;
use std::time::Instant;

use glam::Mat3;
use shadow_core::{
    Camera, Environment, Error, FrameGeometry, Image, ProfileValue, Result, Scene, Stage,
    gpu::GpuContext, raster::near_plane,
};

use super::{
    clock::Clock,
    draw::{Content, Renderer, Viewpoint},
    host::{Output, StageTime, Work, drive},
};
use crate::{
    images::{Exposure, error_colour, linear_from_srgb, pixel_errors},
    methods::{Built, MethodSpec, Methods, SharedGpu},
    reference::{Domain, ImageReference, ReferenceCache, ReferenceSettings, cache_key},
    score,
};

/// What the viewer opens with.
pub struct Setup {
    pub scene: Scene,
    /// The environment as loaded (turned and exposed as the command line
    /// said); the viewer's own turn comes on top.
    pub environment: Environment,
    pub methods: Methods,
    pub method: String,
    /// Where `harness run` and `harness report` keep image references: the
    /// heat map reads them, and never computes one.
    pub cache: ReferenceCache,
    /// The image references' settings (`harness run`'s by default).
    pub reference: ReferenceSettings,
}

/// The heat map's state for the current view.
#[derive(Clone, Debug, PartialEq)]
pub enum Heat {
    /// No cached image reference for this camera, frame and lighting.
    NoReference,
    /// The method's relative L2 error against the reference, per pixel.
    Error(f32),
}

/// Everything the picture over the background depends on but the
/// exposure: while it stays the same, the last picture is drawn again.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PictureKey {
    camera: Camera,
    frame: usize,
    turn: f32,
    /// Counts the methods opened.
    method: u64,
    heat_map: bool,
}

/// The picture over the background, where it is on the GPU.
enum Shown {
    /// Per-vertex radiance, one `vec4<f32>` per vertex.
    Vertices(wgpu::Buffer),
    /// An image of radiance (`true`, drawn times the exposure) or of
    /// colours (the heat map).
    Pixels(wgpu::Texture, bool),
    /// Nothing: the stages failed.
    Nothing,
}

pub struct ViewState {
    scene: Scene,
    base_environment: Environment,
    environment: Environment,
    /// Degrees the environment is turned about +Y, on top of the command line's.
    turn: f32,
    methods: Methods,
    spec: MethodSpec,
    method: Built,
    /// Methods opened so far.
    generation: u64,
    /// The method's stages are called rather than recorded: it refused a
    /// recording (a setting only its calls support).
    blocking: bool,
    ctx: Arc<GpuContext>,
    renderer: Renderer,
    frame_index: usize,
    frame: FrameGeometry,
    /// The camera as the user left it; its size follows the target's.
    pub camera: Camera,
    home: Camera,
    /// Display exposure in EV on top of the base.
    pub exposure_ev: f32,
    base_exposure: Option<f32>,
    pub playing: bool,
    pub heat_map: bool,
    heat: Heat,
    cache: ReferenceCache,
    reference_settings: ReferenceSettings,
    needs_relight: bool,
    needs_update: bool,
    shown: Option<(PictureKey, Shown)>,
    pub clock: Clock,
    /// The last error a stage or a method name gave, shown until the next
    /// change.
    pub error: Option<String>,
}

impl ViewState {
    /// The state on `ctx`'s device, drawing into targets of `format`,
    /// `size` pixels; fails on a bad method name or a method that cannot
    /// take the scene.
    pub fn new(
        setup: Setup,
        ctx: Arc<GpuContext>,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<ViewState> {
        let spec = setup.methods.parse(&setup.method)?;
        let home = Camera {
            width: size.0.max(1),
            height: size.1.max(1),
            ..*setup.scene.camera()
        };
        let frame = setup.scene.frame_geometry(0)?;
        let mut renderer = Renderer::new(&ctx, format);
        renderer.set_environment(&ctx, &setup.environment);
        renderer.set_frame(&ctx, &frame);
        let mut clock = Clock::default();
        let method = open(&spec, &ctx, &setup.scene, &mut clock)?;
        Ok(ViewState {
            environment: setup.environment.clone(),
            base_environment: setup.environment,
            scene: setup.scene,
            turn: 0.0,
            methods: setup.methods,
            spec,
            method,
            generation: 0,
            blocking: false,
            ctx,
            renderer,
            frame_index: 0,
            frame,
            camera: home,
            home,
            exposure_ev: 0.0,
            base_exposure: None,
            playing: false,
            heat_map: false,
            heat: Heat::NoReference,
            cache: setup.cache,
            reference_settings: setup.reference,
            needs_relight: true,
            needs_update: true,
            shown: None,
            clock,
            error: None,
        })
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn method_name(&self) -> &str {
        self.spec.name()
    }

    pub fn frame_index(&self) -> usize {
        self.frame_index
    }

    pub fn turn(&self) -> f32 {
        self.turn
    }

    /// The heat map's state, while it is on.
    pub fn heat(&self) -> Option<&Heat> {
        self.heat_map.then_some(&self.heat)
    }

    pub fn adapter(&self) -> String {
        self.ctx.adapter.to_string()
    }

    /// Switches to the method `name` (any name the harness reads), built
    /// and prepared before the current one is let go: on an error the
    /// current method stays.
    pub fn switch_method(&mut self, name: &str) -> Result<()> {
        let spec = self.methods.parse(name)?;
        let mut clock = Clock::default();
        let method = open(&spec, &self.ctx, &self.scene, &mut clock)?;
        self.spec = spec;
        self.method = method;
        self.clock = clock;
        self.generation += 1;
        self.blocking = false;
        self.needs_relight = true;
        self.needs_update = true;
        self.error = None;
        Ok(())
    }

    /// Turns the environment to `degrees` about +Y (the relight stage).
    pub fn set_turn(&mut self, degrees: f32) {
        let degrees = degrees.rem_euclid(360.0);
        if degrees == self.turn {
            return;
        }
        self.turn = degrees;
        self.environment = if degrees == 0.0 {
            self.base_environment.clone()
        } else {
            self.base_environment
                .rotated(Mat3::from_rotation_y(degrees.to_radians()))
        };
        self.renderer.set_environment(&self.ctx, &self.environment);
        self.needs_relight = true;
    }

    /// Moves the animation by `frames` (wrapping): the update stage.
    pub fn step(&mut self, frames: isize) -> Result<()> {
        let count = self.scene.frames().len() as isize;
        let index = (self.frame_index as isize + frames).rem_euclid(count) as usize;
        if index != self.frame_index {
            self.frame = self.scene.frame_geometry(index)?;
            self.frame_index = index;
            self.renderer.set_frame(&self.ctx, &self.frame);
            self.needs_update = true;
        }
        Ok(())
    }

    /// Back to the scene's own camera, at the current size.
    pub fn reset_camera(&mut self) {
        self.camera = self.home_at_size();
    }

    /// The target's size changed.
    pub fn resize(&mut self, (width, height): (u32, u32)) {
        self.camera.width = width.max(1);
        self.camera.height = height.max(1);
    }

    /// The exposure radiance is multiplied by on screen.
    pub fn exposure(&self) -> f32 {
        self.base_exposure.unwrap_or(1.0) * self.exposure_ev.exp2()
    }

    /// Records the picture into `target` (`camera.width × camera.height`,
    /// the renderer's format): the environment, and over it the method's
    /// result, run or recorded into `encoder` where the camera, the frame,
    /// the lighting, the method or the heat map changed since the last
    /// picture (else the last one again). The GPU work is in `encoder`,
    /// for the caller to submit. Says whether the method ran (a frame to
    /// time as the method's); a failing stage leaves the background drawn
    /// and returns its error.
    pub fn draw(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
    ) -> Result<bool> {
        let camera = self.camera;
        let key = PictureKey {
            camera,
            frame: self.frame_index,
            turn: self.turn,
            method: self.generation,
            heat_map: self.heat_map,
        };
        let current = !self.needs_relight
            && !self.needs_update
            && self.shown.as_ref().is_some_and(|(k, _)| *k == key);
        let mut result = Ok(());
        if !current {
            let computed = self
                .base_exposure()
                .and_then(|()| self.compute(encoder, &camera));
            let shown = match computed {
                Ok(shown) => shown,
                Err(e) => {
                    result = Err(e);
                    Shown::Nothing
                }
            };
            self.shown = Some((key, shown));
            self.needs_relight = false;
            self.needs_update = false;
        }
        let exposure = self.exposure();
        let content = match self.shown.as_ref().map(|(_, s)| s) {
            Some(Shown::Vertices(buffer)) => Content::Vertices(buffer),
            Some(Shown::Pixels(texture, radiance)) => Content::Pixels {
                texture,
                scale: if *radiance { exposure } else { 1.0 },
            },
            Some(Shown::Nothing) | None => Content::Background,
        };
        let viewpoint = Viewpoint {
            camera: &camera,
            near: near_plane(&camera, &self.frame),
            exposure,
        };
        self.renderer
            .record(&self.ctx, encoder, target, &viewpoint, content);
        result.map(|()| !current)
    }

    /// Runs or records the stages this picture needs and returns it. With
    /// the heat map on and a cached reference of the view, the stages are
    /// the method's own calls and the image is the one `harness run`
    /// scores.
    fn compute(&mut self, encoder: &mut wgpu::CommandEncoder, camera: &Camera) -> Result<Shown> {
        let reference = if self.heat_map {
            self.reference_for(camera)
        } else {
            None
        };
        self.heat = Heat::NoReference;
        let work = Work {
            relight: self.needs_relight.then_some(&self.environment),
            update: self.needs_update.then_some(&self.frame),
            camera,
            per_pixel: reference.is_some() || self.method.method().capabilities().per_pixel,
        };
        let gpu = matches!(self.method, Built::Gpu(_));
        let blocking = self.blocking || reference.is_some();
        let (output, times) = match drive(&mut self.method, encoder, &work, blocking) {
            // A setting only the method's calls support: call it from now on.
            Err(Error::InvalidConfig { .. } | Error::Unsupported { .. }) if gpu && !blocking => {
                self.blocking = true;
                drive(&mut self.method, encoder, &work, true)?
            }
            other => other?,
        };
        self.record_times(&times, gpu && !self.blocking && reference.is_none());
        let ctx = Arc::clone(&self.ctx);
        Ok(match output {
            Output::GpuVertices(buffer) => Shown::Vertices(buffer),
            Output::GpuImage(texture) => Shown::Pixels(texture, true),
            Output::Vertices(radiance) => {
                Shown::Vertices(self.renderer.upload_vertices(&ctx, radiance.flat()))
            }
            Output::Image(image) => match reference {
                Some(reference) => {
                    let stats = score::image(&image, &reference)?;
                    self.heat = Heat::Error(stats.relative_l2);
                    let map = heat_image(&image, &reference.image);
                    Shown::Pixels(self.renderer.upload_image(&ctx, &map), false)
                }
                None => Shown::Pixels(self.renderer.upload_image(&ctx, &image), true),
            },
        })
    }

    /// Adds the stages' times to the clock; recorded stages are named as
    /// such (their GPU work is in the frame's "GPU work").
    fn record_times(&mut self, times: &[StageTime], recorded: bool) {
        for (stage, time) in times {
            let name = if recorded {
                format!("{stage} (recording)")
            } else {
                stage.to_string()
            };
            self.clock.add(&name, *time);
        }
    }

    /// The method's own profile of its last stages: the name and value of
    /// each entry, per stage.
    pub fn profile(&self) -> Vec<(Stage, String, ProfileValue)> {
        self.method
            .method()
            .profile()
            .entries()
            .iter()
            .map(|e| (e.stage, e.name.to_string(), e.value))
            .collect()
    }

    /// The cached image reference of this camera, frame and lighting.
    fn reference_for(&self, camera: &Camera) -> Option<ImageReference> {
        let domain = Domain::Pixels { camera };
        let key = cache_key(
            &self.scene,
            &self.frame,
            &self.environment,
            domain,
            &self.reference_settings,
        );
        self.cache.cached_image(&key, (camera.width, camera.height))
    }

    /// Fixes the base exposure now, from the current frame (else the first
    /// picture fixes it from its frame).
    pub fn fix_exposure(&mut self) -> Result<()> {
        self.base_exposure()
    }

    /// Sets the base exposure once: the one `harness run --images-dir`
    /// shows the scene's images with (from the cached reference of the
    /// scene's own camera at this size), else one mapping the 99th
    /// percentile of the method's evaluated per-vertex radiance to white.
    fn base_exposure(&mut self) -> Result<()> {
        if self.base_exposure.is_some() {
            return Ok(());
        }
        let exposure = match self.reference_for(&self.home_at_size()) {
            Some(reference) => Exposure::of(&reference.image),
            None => {
                let camera = self.camera;
                let method = self.method.method_mut();
                method.relight(&self.environment)?;
                method.update(&self.frame, &camera)?;
                let radiance = method.shade(camera.eye)?;
                self.needs_relight = false;
                self.needs_update = false;
                let values: Vec<_> = radiance
                    .flat()
                    .zip(radiance.flat_evaluated())
                    .filter_map(|(r, evaluated)| evaluated.then_some(r))
                    .collect();
                Exposure::of(&Image {
                    width: values.len().max(1) as u32,
                    height: 1,
                    covered: vec![true; values.len()],
                    pixels: values,
                    std_error: None,
                })
            }
        };
        self.base_exposure = Some(exposure.0);
        Ok(())
    }

    fn home_at_size(&self) -> Camera {
        Camera {
            width: self.camera.width,
            height: self.camera.height,
            ..self.home
        }
    }
}

/// Builds and prepares the method of `spec` on `ctx`'s device, its prepare
/// time on `clock`.
fn open(
    spec: &MethodSpec,
    ctx: &Arc<GpuContext>,
    scene: &Scene,
    clock: &mut Clock,
) -> Result<Built> {
    let mut method = spec.build_stages(&SharedGpu::with(Arc::clone(ctx)))?;
    let start = Instant::now();
    method.method_mut().prepare(scene)?;
    clock.add("prepare (once)", start.elapsed());
    Ok(method)
}

/// The heat map of `image` against `reference` as an image of linear
/// colours (the sRGB target encodes them back to the heat map's colours),
/// covered where the reference is.
fn heat_image(image: &Image, reference: &Image) -> Image {
    Image {
        width: reference.width,
        height: reference.height,
        pixels: pixel_errors(image, reference)
            .iter()
            .map(|e| glam::Vec3::from_array(error_colour(*e).map(linear_from_srgb)))
            .collect(),
        covered: reference.covered.clone(),
        std_error: None,
    }
}
