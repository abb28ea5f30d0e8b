//! The seam GPU methods plug into, exercised by a trivial compute method on
//! the shared test context (lavapipe where there is no GPU): every stage
//! through the harness, honest timing, recording into a caller's encoder,
//! errors kept to the user that raised them, and the device checked for what
//! a method needs.

use shadow_core::shapes;
use std::sync::{
    Arc,
    atomic::{AtomicBool, Ordering},
};

use glam::Vec3;
use harness::{
    reference::{self, ReferenceSettings},
    run::{self, References},
};
use indicatif::ProgressBar;
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, FrameGeometry, Image, Object, Result, Scene,
    ShadowMethod, VertexRadiance,
    gpu::{GpuContext, GpuStages, test_context},
    sh::{self, ShOrder, Zonal},
};

/// Unshadowed Lambert shading on the GPU: per vertex, ρ/π times the
/// order-3 SH irradiance at its normal, in a compute shader. With `faulty`
/// set, its shading records work the device rejects.
struct GpuLambert {
    ctx: Arc<GpuContext>,
    faulty: bool,
    pipeline: wgpu::ComputePipeline,
    lighting: wgpu::Buffer,
    /// Per vertex: the normal, and ρ/π.
    vertices: Option<wgpu::Buffer>,
    radiance: Option<wgpu::Buffer>,
    albedo: Vec<Vec3>,
    frame: Option<FrameGeometry>,
}

const SHADER: &str = "
struct Vertex { normal: vec4<f32>, rho: vec4<f32> }
@group(0) @binding(0) var<storage, read> lighting: array<vec4<f32>, 9>;
@group(0) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(0) @binding(2) var<storage, read_write> radiance: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&vertices) { return; }
    let n = vertices[i].normal.xyz;
    // Real SH to band 2, +Y polar axis (shadow_core::sh).
    let y = array<f32, 9>(
        0.282095, 0.488603 * n.z, 0.488603 * n.y, 0.488603 * n.x,
        1.092548 * n.x * n.z, 1.092548 * n.y * n.z, 0.315392 * (3.0 * n.y * n.y - 1.0),
        1.092548 * n.x * n.y, 0.546274 * (n.x * n.x - n.z * n.z));
    var e = vec3<f32>(0.0);
    for (var k = 0u; k < 9u; k++) { e += lighting[k].xyz * y[k]; }
    radiance[i] = vec4<f32>(vertices[i].rho.xyz * max(e, vec3<f32>(0.0)), 1.0);
}";

impl GpuLambert {
    fn new(ctx: Arc<GpuContext>, faulty: bool) -> Result<GpuLambert> {
        let needs = wgpu::Limits {
            max_storage_buffers_per_shader_stage: 3,
            max_compute_workgroup_size_x: 64,
            max_compute_invocations_per_workgroup: 64,
            max_compute_workgroups_per_dimension: 1 << 15,
            ..wgpu::Limits::downlevel_webgl2_defaults()
        };
        ctx.require("gpu-lambert", wgpu::Features::empty(), &needs)?;
        let (pipeline, lighting) = ctx.capture("gpu-lambert: prepare", || {
            let module = ctx
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("gpu-lambert"),
                    source: wgpu::ShaderSource::Wgsl(SHADER.into()),
                });
            let pipeline = ctx
                .device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("gpu-lambert"),
                    layout: None,
                    module: &module,
                    entry_point: Some("main"),
                    compilation_options: Default::default(),
                    cache: None,
                });
            let lighting = ctx.create_buffer_init(
                "lighting",
                &[[0f32; 4]; 9],
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            );
            Ok((pipeline, lighting))
        })?;
        Ok(GpuLambert {
            ctx,
            faulty,
            pipeline,
            lighting,
            vertices: None,
            radiance: None,
            albedo: Vec::new(),
            frame: None,
        })
    }

    fn vertex_count(&self) -> usize {
        self.frame
            .as_ref()
            .map_or(0, |f| f.objects.iter().map(|o| o.vertex_count()).sum())
    }
}

impl ShadowMethod for GpuLambert {
    fn name(&self) -> &str {
        "gpu-lambert"
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            per_pixel: false,
            export: false,
            ..Capabilities::ALL
        }
    }

    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.albedo = scene
            .objects()
            .iter()
            .map(|o| o.material.diffuse())
            .collect();
        Ok(())
    }

    fn relight(&mut self, environment: &Environment) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.run("gpu-lambert: relight", |encoder| {
            self.record_relight(environment, encoder)
        })
    }

    fn update(&mut self, frame: &FrameGeometry, camera: &Camera) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        ctx.run("gpu-lambert: update", |encoder| {
            self.record_update(frame, camera, encoder)
        })
    }

    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        let ctx = Arc::clone(&self.ctx);
        ctx.run("gpu-lambert: shade", |encoder| {
            self.record_shade(eye, encoder).map(drop)
        })?;
        let buffer = self.radiance.as_ref().expect("shaded");
        let values: Vec<[f32; 4]> = self.ctx.read_buffer(buffer, 0, self.vertex_count())?;
        let frame = self.frame.as_ref().expect("updated");
        let mut values = values.into_iter().map(|v| Vec3::new(v[0], v[1], v[2]));
        let radiance = frame
            .objects
            .iter()
            .map(|o| values.by_ref().take(o.vertex_count()).collect())
            .collect();
        Ok(VertexRadiance::new(radiance))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        shadow_core::raster::render_shading("gpu-lambert", camera, self.frame.as_ref(), &shading)
    }
}

impl GpuStages for GpuLambert {
    fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    fn record_relight(
        &mut self,
        environment: &Environment,
        _encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        let order = ShOrder::new(3).expect("order 3");
        let light = sh::project_environment(environment, order).convolve(&Zonal::lambert(order));
        let coeffs: Vec<[f32; 4]> = light
            .coeffs()
            .iter()
            .map(|c| c.extend(0.0).to_array())
            .collect();
        self.ctx
            .queue
            .write_buffer(&self.lighting, 0, bytemuck::cast_slice(&coeffs));
        Ok(())
    }

    fn record_update(
        &mut self,
        frame: &FrameGeometry,
        _camera: &Camera,
        _encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        let data: Vec<[[f32; 4]; 2]> = frame
            .objects
            .iter()
            .zip(&self.albedo)
            .flat_map(|(o, rho)| {
                let rho = (*rho * std::f32::consts::FRAC_1_PI).extend(0.0).to_array();
                o.normals()
                    .iter()
                    .map(move |n| [n.extend(0.0).to_array(), rho])
            })
            .collect();
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        self.vertices = Some(self.ctx.create_buffer_init("vertices", &data, usage));
        self.radiance = Some(self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("radiance"),
            size: (data.len() * 16) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        }));
        self.frame = Some(frame.clone());
        Ok(())
    }

    fn record_shade(
        &mut self,
        _eye: Vec3,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Buffer> {
        let (Some(vertices), Some(radiance)) = (&self.vertices, &self.radiance) else {
            return Err(Error::stage("gpu-lambert", "shade before update"));
        };
        // The faulty user binds the lighting where a read-write buffer goes:
        // a validation error.
        let output = if self.faulty {
            &self.lighting
        } else {
            radiance
        };
        let bind_group = self
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.lighting.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: vertices.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: output.as_entire_binding(),
                    },
                ],
            });
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(self.vertex_count().div_ceil(64) as u32, 1, 1);
        drop(pass);
        Ok(radiance)
    }

    fn record_render(
        &mut self,
        _camera: &Camera,
        _encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Texture> {
        Err(Error::Unsupported {
            method: self.name().into(),
            capability: shadow_core::Capability::PerPixel,
        })
    }
}

/// A white sphere of `rings × 2·rings` quads under `camera`.
fn sphere(rings: u32, rho: f32) -> Scene {
    let mesh = shapes::uv_sphere("sphere", Vec3::ZERO, 1.0, rings, 2 * rings).unwrap();
    let camera = Camera::new(Vec3::new(0.0, 0.5, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 48, 36).unwrap();
    let object = Object {
        mesh: Arc::new(mesh),
        material: Brdf::lambert(Vec3::splat(rho)).unwrap(),
    };
    Scene::still("sphere", vec![object], camera).unwrap()
}

/// Whether the queue has finished everything submitted so far, asked
/// without waiting: the callback registered now refers to the last
/// submission, and a non-blocking poll runs it only if that is done.
fn queue_idle(ctx: &GpuContext) -> bool {
    let done = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&done);
    ctx.queue
        .on_submitted_work_done(move || flag.store(true, Ordering::SeqCst));
    ctx.device.poll(wgpu::PollType::Poll).unwrap();
    done.load(Ordering::SeqCst)
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn a_gpu_method_runs_through_every_stage_of_the_harness() {
    let ctx = test_context();
    let scene = sphere(16, 0.6);
    let env = Environment::uniform(Vec3::ONE);
    let bar = ProgressBar::hidden();
    let settings = ReferenceSettings::replicated(16, 4, 3);
    let (refs, _) = reference::scene_references(&scene, &env, &settings, None, &bar).unwrap();
    let camera = scene.camera().with_width(32).unwrap();
    let (images, _) =
        reference::scene_image_references(&scene, &env, &camera, &settings, None, &bar).unwrap();
    let mut method = GpuLambert::new(ctx, false).unwrap();
    let references = References {
        vertex: &refs,
        image: Some((&camera, &images)),
    };
    let result = run::run(&mut method, &scene, &env, references, 2).unwrap();
    // The white furnace: ρ everywhere, up to the order-3 truncation (< 1%).
    for x in result.last_shading.as_ref().unwrap().flat() {
        assert!((x.x - 0.6).abs() < 0.006, "{x}");
    }
    let frame = &result.frames[0];
    assert!(frame.vertex.relative_l2 < 0.02, "{:?}", frame.vertex);
    assert!(frame.image.unwrap().relative_l2 < 0.02, "{:?}", frame.image);
    assert!(frame.times.render.is_some());
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn a_timed_stage_returns_with_the_queue_idle() {
    let _context = test_context();
    // A device of its own: other tests submit to the shared one meanwhile.
    let ctx = Arc::new(GpuContext::new().unwrap());
    let scene = sphere(256, 0.5);
    let frame = scene.frame_geometry(0).unwrap();
    let mut method = GpuLambert::new(Arc::clone(&ctx), false).unwrap();
    method.prepare(&scene).unwrap();
    method.relight(&Environment::uniform(Vec3::ONE)).unwrap();
    assert!(queue_idle(&ctx), "relight returned with work pending");
    method.update(&frame, scene.camera()).unwrap();
    assert!(queue_idle(&ctx), "update returned with work pending");
    let runner = Arc::clone(&ctx);
    let heavy = |method: &mut GpuLambert, encoder: &mut wgpu::CommandEncoder| {
        for _ in 0..50 {
            method.record_shade(Vec3::Z, encoder)?;
        }
        Ok(())
    };
    runner
        .run("heavy stage", |encoder| heavy(&mut method, encoder))
        .unwrap();
    assert!(
        queue_idle(&ctx),
        "a blocking stage returned with work pending"
    );
    method.shade(Vec3::Z).unwrap();
    assert!(queue_idle(&ctx), "shade returned with work pending");

    // The check itself sees the same work pending when nobody waits for it.
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    heavy(&mut method, &mut encoder).unwrap();
    ctx.queue.submit([encoder.finish()]);
    assert!(!queue_idle(&ctx), "work not waited for was already done");
    ctx.wait().unwrap();
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn recording_into_a_callers_encoder_gives_what_the_stages_give() {
    let ctx = test_context();
    let scene = sphere(12, 0.8);
    let frame = scene.frame_geometry(0).unwrap();
    let env = Environment::uniform(Vec3::new(0.2, 0.5, 1.0));
    let mut method = GpuLambert::new(Arc::clone(&ctx), false).unwrap();
    method.prepare(&scene).unwrap();
    method.relight(&env).unwrap();
    method.update(&frame, scene.camera()).unwrap();
    let blocking: Vec<Vec3> = method.shade(scene.camera().eye).unwrap().flat().collect();

    // A host's own device, its own encoder, one submission for all stages.
    let host = Arc::new(GpuContext::from_device(
        ctx.device.clone(),
        ctx.queue.clone(),
    ));
    let mut method = GpuLambert::new(Arc::clone(&host), false).unwrap();
    method.prepare(&scene).unwrap();
    let mut encoder = host.device.create_command_encoder(&Default::default());
    method.record_relight(&env, &mut encoder).unwrap();
    method
        .record_update(&frame, scene.camera(), &mut encoder)
        .unwrap();
    let radiance = method
        .record_shade(scene.camera().eye, &mut encoder)
        .unwrap()
        .clone();
    assert!(method.record_render(scene.camera(), &mut encoder).is_err());
    host.queue.submit([encoder.finish()]);
    let recorded: Vec<[f32; 4]> = host.read_buffer(&radiance, 0, blocking.len()).unwrap();
    for (r, b) in recorded.iter().zip(&blocking) {
        assert_eq!(Vec3::new(r[0], r[1], r[2]), *b);
        assert_eq!(r[3], 1.0);
    }
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn one_users_gpu_errors_stay_with_that_user() {
    let ctx = test_context();
    let scene = sphere(12, 0.5);
    let frame = scene.frame_geometry(0).unwrap();
    let env = Environment::uniform(Vec3::ONE);
    let mut users: Vec<GpuLambert> = [true, false]
        .map(|faulty| GpuLambert::new(Arc::clone(&ctx), faulty).unwrap())
        .into();
    for user in &mut users {
        user.prepare(&scene).unwrap();
        user.relight(&env).unwrap();
        user.update(&frame, scene.camera()).unwrap();
    }
    let [faulty, sound] = users.as_mut_slice() else {
        unreachable!()
    };
    // Interleaved on one thread.
    for _ in 0..3 {
        let error = faulty.shade(Vec3::Z).unwrap_err().to_string();
        assert!(error.contains("gpu-lambert: shade"), "{error}");
        sound.shade(Vec3::Z).unwrap();
    }
    // Side by side on two threads: methods are Send.
    std::thread::scope(|s| {
        let a = s.spawn(|| (0..10).all(|_| faulty.shade(Vec3::Z).is_err()));
        let b = s.spawn(|| (0..10).all(|_| sound.shade(Vec3::Z).is_ok()));
        assert!(a.join().unwrap());
        assert!(b.join().unwrap());
    });
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn a_device_without_what_a_method_needs_is_a_clear_error() {
    let _context = test_context();
    let instance = wgpu::Instance::new(shadow_core::gpu::instance_descriptor());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default())).unwrap();
    let descriptor = wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits::downlevel_webgl2_defaults(),
        ..Default::default()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&descriptor)).unwrap();
    let host = Arc::new(GpuContext::from_device(device, queue));
    let error = GpuLambert::new(host, false).err().unwrap().to_string();
    assert!(
        error.contains("gpu-lambert") && error.contains("max_storage_buffers_per_shader_stage"),
        "{error}"
    );
}
