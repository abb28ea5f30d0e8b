//! What the viewer shows and how it gets there: the scene and its current
//! frame, the environment and its turn, the method, the camera, the
//! exposure and the heat map; each frame it drives the method
//! ([`super::host`]) and records the picture ([`super::draw`]).

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{Mat3, Vec3};
use shadow_core::{
    Camera, Environment, Error, FrameGeometry, Image, ProfileValue, Result, Scene, Stage,
    gpu::GpuContext,
};

use super::{
    clock::Clock,
    draw::{Content, Renderer, Viewpoint},
    host::{Output, Work, drive},
};
use crate::{
    images::{Exposure, error_colour, pixel_errors},
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

pub struct Session {
    scene: Scene,
    base_environment: Environment,
    environment: Environment,
    /// Degrees the environment is turned about +Y, on top of the command line's.
    turn: f32,
    methods: Methods,
    spec: MethodSpec,
    method: Option<Built>,
    ctx: Arc<GpuContext>,
    renderer: Renderer,
    frame_index: usize,
    frame: FrameGeometry,
    /// The camera as the user left it; its size follows the target's.
    pub camera: Camera,
    home: Camera,
    /// The camera of the last update.
    updated_camera: Option<Camera>,
    /// The camera of the previous frame: the camera is at rest when equal.
    previous_camera: Option<Camera>,
    /// Display exposure in EV on top of the base.
    pub exposure_ev: f32,
    base_exposure: Option<f32>,
    pub playing: bool,
    pub heat_map: bool,
    heat: Option<Heat>,
    cache: ReferenceCache,
    reference_settings: ReferenceSettings,
    needs_relight: bool,
    needs_update: bool,
    pub clock: Clock,
    /// The last error a stage or a method name gave, shown until the next
    /// change.
    pub error: Option<String>,
}

impl Session {
    /// The session on `ctx`'s device, drawing into targets of `format`,
    /// `size` pixels; fails on a bad method name or a method that cannot
    /// take the scene.
    pub fn new(
        setup: Setup,
        ctx: Arc<GpuContext>,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<Session> {
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
        let mut session = Session {
            environment: setup.environment.clone(),
            base_environment: setup.environment,
            scene: setup.scene,
            turn: 0.0,
            methods: setup.methods,
            spec,
            method: None,
            ctx,
            renderer,
            frame_index: 0,
            frame,
            camera: home,
            home,
            updated_camera: None,
            previous_camera: None,
            exposure_ev: 0.0,
            base_exposure: None,
            playing: false,
            heat_map: false,
            heat: None,
            cache: setup.cache,
            reference_settings: setup.reference,
            needs_relight: true,
            needs_update: true,
            clock: Clock::default(),
            error: None,
        };
        session.open_method()?;
        Ok(session)
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

    pub fn heat(&self) -> Option<&Heat> {
        self.heat.as_ref()
    }

    pub fn adapter(&self) -> String {
        self.ctx.adapter.to_string()
    }

    /// Switches to the method `name` (any name the harness reads); on an
    /// error the current method stays.
    pub fn switch_method(&mut self, name: &str) -> Result<()> {
        let spec = self.methods.parse(name)?;
        let previous = std::mem::replace(&mut self.spec, spec);
        match self.open_method() {
            Ok(()) => {
                self.clock.clear();
                self.error = None;
                Ok(())
            }
            Err(e) => {
                self.spec = previous;
                self.open_method()?;
                Err(e)
            }
        }
    }

    /// Builds and prepares the method of `spec` on the viewer's device.
    fn open_method(&mut self) -> Result<()> {
        self.method = None;
        let mut built = self
            .spec
            .build_stages(&SharedGpu::with(Arc::clone(&self.ctx)))?;
        let start = Instant::now();
        built.method_mut().prepare(&self.scene)?;
        let prepared = start.elapsed();
        self.method = Some(built);
        self.needs_relight = true;
        self.needs_update = true;
        self.heat = None;
        self.clock.clear();
        self.clock.add("prepare (once)", prepared);
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
        self.heat = None;
    }

    /// Moves the animation by `frames` (wrapping).
    pub fn step(&mut self, frames: isize) -> Result<()> {
        let count = self.scene.frames().len() as isize;
        let index = (self.frame_index as isize + frames).rem_euclid(count) as usize;
        if index != self.frame_index {
            self.frame = self.scene.frame_geometry(index)?;
            self.frame_index = index;
            self.renderer.set_frame(&self.ctx, &self.frame);
            self.needs_update = true;
            self.heat = None;
        }
        Ok(())
    }

    /// Back to the scene's own camera, at the current size.
    pub fn reset_camera(&mut self) {
        self.camera = Camera {
            width: self.camera.width,
            height: self.camera.height,
            ..self.home
        };
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

    /// Runs or records what this frame needs, then records the picture
    /// into `target` (`camera.width × camera.height`, the renderer's
    /// format). The GPU work is in `encoder`, for the caller to submit.
    pub fn draw(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
    ) -> Result<()> {
        let camera = self.camera;
        let at_rest = self.previous_camera == Some(camera);
        self.previous_camera = Some(camera);
        if self.updated_camera.is_some_and(|c| c != camera) && at_rest {
            self.needs_update = true;
        }
        let reference = if self.heat_map {
            self.reference_for(&camera)
        } else {
            None
        };
        if self.base_exposure.is_none() {
            self.base_exposure = Some(self.initial_exposure()?);
        }
        if self.heat_map {
            self.heat = Some(Heat::NoReference);
        }
        let exposure = self.exposure();
        let viewpoint = Viewpoint {
            camera: &camera,
            near: near_plane(&camera, &self.frame),
            exposure,
        };
        let per_pixel = self.method()?.capabilities().per_pixel;
        let work = Work {
            relight: self.needs_relight.then_some(&self.environment),
            update: self.needs_update.then_some(&self.frame),
            camera: &camera,
            per_pixel,
        };
        let ctx = Arc::clone(&self.ctx);
        let method = self
            .method
            .as_mut()
            .ok_or_else(|| Error::stage("viewer", "no method"))?;
        if let Some(reference) = reference {
            // What the report scores: the method's own blocking stages and
            // its image of this camera, against the cached reference.
            let (image, times) = scored_image(method, &work)?;
            let stats = score::image(&image, &reference)?;
            self.heat = Some(Heat::Error(stats.relative_l2));
            let map = heat_image(&image, &reference.image);
            let texture = self.renderer.upload_image(&ctx, &map);
            let content = Content::Pixels {
                texture: &texture,
                scale: 1.0,
            };
            self.renderer
                .record(&ctx, encoder, target, &viewpoint, content);
            self.record_times(&times, false);
        } else {
            let recorded = matches!(method, Built::Gpu(_));
            let (output, times) = drive(method, encoder, &work)?;
            // GPU results are read where the method left them; CPU ones
            // are uploaded (buffers and textures are handles: cloning one
            // copies no data).
            let (buffer, texture) = match output {
                Output::GpuVertices(buffer) => (Some(buffer.clone()), None),
                Output::GpuImage(texture) => (None, Some(texture.clone())),
                Output::Vertices(radiance) => (
                    Some(self.renderer.upload_vertices(&ctx, radiance.flat())),
                    None,
                ),
                Output::Image(image) => (None, Some(self.renderer.upload_image(&ctx, &image))),
            };
            let content = match (&buffer, &texture) {
                (Some(buffer), _) => Content::Vertices(buffer),
                (_, Some(texture)) => Content::Pixels {
                    texture,
                    scale: exposure,
                },
                _ => unreachable!("every output is a buffer or a texture"),
            };
            self.renderer
                .record(&ctx, encoder, target, &viewpoint, content);
            self.record_times(&times, recorded);
        }
        self.needs_relight = false;
        if self.needs_update {
            self.needs_update = false;
            self.updated_camera = Some(camera);
        }
        Ok(())
    }

    fn method(&self) -> Result<&dyn shadow_core::ShadowMethod> {
        self.method
            .as_ref()
            .map(Built::method)
            .ok_or_else(|| Error::stage("viewer", "no method"))
    }

    /// Adds the stages' times to the clock; a GPU method's recorded stages
    /// are named as such (their GPU work is in the frame's "GPU work").
    fn record_times(&mut self, times: &[(Stage, Duration)], recorded: bool) {
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
        self.method()
            .map(|m| {
                m.profile()
                    .entries()
                    .iter()
                    .map(|e| (e.stage, e.name.to_string(), e.value))
                    .collect()
            })
            .unwrap_or_default()
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

    /// The exposure `harness run --images` shows the scene's images with
    /// (from the reference of the scene's own camera at this size, if
    /// cached); else one mapping the 99th percentile of the method's
    /// per-vertex luminance to white.
    fn initial_exposure(&mut self) -> Result<f32> {
        if let Some(reference) = self.reference_for(&self.home_at_size()) {
            return Ok(Exposure::of(&reference.image).0);
        }
        let camera = self.camera;
        let method = self
            .method
            .as_mut()
            .ok_or_else(|| Error::stage("viewer", "no method"))?
            .method_mut();
        method.relight(&self.environment)?;
        method.update(&self.frame, &camera)?;
        let radiance = method.shade(camera.eye)?;
        self.needs_relight = false;
        self.needs_update = false;
        self.updated_camera = Some(camera);
        let mut luminance: Vec<f32> = radiance
            .flat()
            .map(|r| r.dot(Vec3::new(0.2126, 0.7152, 0.0722)))
            .collect();
        luminance.sort_unstable_by(f32::total_cmp);
        let p99 = luminance
            .get(luminance.len() * 99 / 100)
            .copied()
            .unwrap_or(0.0);
        Ok(if p99 > 0.0 { 1.0 / p99 } else { 1.0 })
    }

    fn home_at_size(&self) -> Camera {
        Camera {
            width: self.camera.width,
            height: self.camera.height,
            ..self.home
        }
    }
}

/// Runs the stages `work` asks for through the method's blocking calls and
/// returns its image of the camera (for a per-vertex method, its shading
/// toward the eye interpolated, as `harness run` renders it).
fn scored_image(method: &mut Built, work: &Work) -> Result<(Image, Vec<(Stage, Duration)>)> {
    let method = method.method_mut();
    let mut times = Vec::new();
    let start = Instant::now();
    if let Some(environment) = work.relight {
        method.relight(environment)?;
        times.push((Stage::Relight, start.elapsed()));
    }
    if let Some(frame) = work.update {
        let start = Instant::now();
        method.update(frame, work.camera)?;
        times.push((Stage::Update, start.elapsed()));
    }
    if !work.per_pixel {
        let start = Instant::now();
        method.shade(work.camera.eye)?;
        times.push((Stage::Shade, start.elapsed()));
    }
    let start = Instant::now();
    let image = method.render(work.camera)?;
    times.push((Stage::Render, start.elapsed()));
    Ok((image, times))
}

/// The heat map of `image` against `reference` as an image of linear
/// colours (the sRGB target encodes them back to the heat map's colours),
/// covered where the reference is.
fn heat_image(image: &Image, reference: &Image) -> Image {
    let errors = pixel_errors(image, reference);
    let linear = |c: u8| {
        let v = c as f32 / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    Image {
        width: reference.width,
        height: reference.height,
        pixels: errors
            .iter()
            .map(|e| Vec3::from_array(error_colour(*e).map(linear)))
            .collect(),
        covered: reference.covered.clone(),
        std_error: None,
    }
}

/// The near plane of the perspective the picture is drawn with: 10⁻⁵ of
/// the distance from the eye to the farthest corner of the frame's bounds,
/// as the CPU rasterizer places it.
fn near_plane(camera: &Camera, frame: &FrameGeometry) -> f32 {
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for p in frame.objects.iter().flat_map(|o| o.positions()) {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let far = (0..8)
        .map(|i| {
            let corner = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            (corner - camera.eye).length()
        })
        .fold(0.0f32, f32::max);
    (far * 1e-5).max(f32::MIN_POSITIVE)
}
