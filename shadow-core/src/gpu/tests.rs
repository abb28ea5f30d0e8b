//! GPU tests: on lavapipe where there is no GPU (`test_context`).

use super::*;

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn context_reports_its_adapter() {
    let ctx = test_context();
    let text = ctx.adapter.to_string();
    println!("adapter: {text} (driver {})", ctx.adapter.driver);
    assert!(text.starts_with(&ctx.adapter.name));
    assert!(text.contains(&ctx.adapter.backend));
    if ctx.adapter.name.contains("llvmpipe") {
        assert!(ctx.adapter.is_software);
        assert!(text.ends_with("software rasterizer"), "{text}");
    }
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn compute_shader_round_trip_doubles_values() {
    let ctx = test_context();
    let input: Vec<f32> = (0..1000).map(|i| i as f32 * 0.25 - 7.0).collect();
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    let buffer = ctx.create_buffer_init("values", &input, usage);
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("double"),
            source: wgpu::ShaderSource::Wgsl(
                "@group(0) @binding(0) var<storage, read_write> values: array<f32>;
             @compute @workgroup_size(64)
             fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                 if id.x < arrayLength(&values) { values[id.x] = 2.0 * values[id.x]; }
             }"
                .into(),
            ),
        });
    let pipeline = ctx
        .device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("double"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
    let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: buffer.as_entire_binding(),
        }],
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(input.len().div_ceil(64) as u32, 1, 1);
    }
    ctx.submit_and_wait([encoder.finish()]).unwrap();
    let output: Vec<f32> = ctx.read_buffer(&buffer, 0, input.len()).unwrap();
    let expected: Vec<f32> = input.iter().map(|v| v * 2.0).collect();
    assert_eq!(output, expected);
    // A sub-range at an offset.
    let tail: Vec<f32> = ctx.read_buffer(&buffer, 400, 3).unwrap();
    assert_eq!(tail, expected[100..103]);
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn bad_read_back_requests_are_errors_not_panics() {
    let ctx = test_context();
    let buffer = ctx.create_buffer_init("small", &[1u32, 2, 3], wgpu::BufferUsages::COPY_SRC);
    assert!(ctx.read_buffer::<u32>(&buffer, 0, 4).is_err());
    assert!(ctx.read_buffer::<u32>(&buffer, 2, 1).is_err());
    assert_eq!(ctx.read_buffer::<u32>(&buffer, 4, 2).unwrap(), vec![2, 3]);
    let no_copy = ctx.create_buffer_init("no copy", &[1u32], wgpu::BufferUsages::STORAGE);
    assert!(ctx.read_buffer::<u32>(&no_copy, 0, 1).is_err());
}

/// Work the device rejects: a shader that does not compile.
fn broken_shader(ctx: &GpuContext) -> wgpu::ShaderModule {
    ctx.device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("broken"),
            source: wgpu::ShaderSource::Wgsl("fn main( {".into()),
        })
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn errors_are_captured_by_the_call_that_raised_them() {
    let ctx = test_context();
    let message = ctx
        .capture("compiling", || {
            broken_shader(&ctx);
            Ok(())
        })
        .unwrap_err()
        .to_string();
    assert!(message.starts_with("GPU: compiling: "), "{message}");
    // Nothing carries over to the next capture.
    ctx.capture("nothing", || Ok(())).unwrap();
    // Nested captures: the inner one takes its own error.
    let outer = ctx.capture("outer", || {
        let inner = ctx.capture("inner", || {
            broken_shader(&ctx);
            Ok(())
        });
        assert!(inner.is_err());
        Ok(7)
    });
    assert_eq!(outer.unwrap(), 7);
}

/// Two users of one context on two threads: one keeps raising errors, the
/// other never sees them.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn one_users_errors_never_reach_another() {
    let ctx = test_context();
    std::thread::scope(|s| {
        let faulty = s.spawn(|| {
            (0..20)
                .filter(|_| {
                    ctx.capture("faulty user", || {
                        broken_shader(&ctx);
                        Ok(())
                    })
                    .is_err()
                })
                .count()
        });
        let sound = s.spawn(|| {
            (0..20).all(|i| {
                let buffer =
                    ctx.create_buffer_init("sound", &[i as u32; 64], wgpu::BufferUsages::COPY_SRC);
                ctx.read_buffer::<u32>(&buffer, 0, 64).unwrap() == vec![i as u32; 64]
            })
        });
        assert_eq!(faulty.join().unwrap(), 20);
        assert!(sound.join().unwrap());
    });
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn missing_limits_and_features_are_named() {
    let ctx = test_context();
    let modest = wgpu::Limits {
        max_storage_buffers_per_shader_stage: 4,
        ..wgpu::Limits::downlevel_webgl2_defaults()
    };
    ctx.require("a modest user", wgpu::Features::empty(), &modest)
        .unwrap();
    let greedy = wgpu::Limits {
        max_texture_dimension_2d: u32::MAX,
        ..modest
    };
    let message = ctx
        .require("a greedy user", wgpu::Features::empty(), &greedy)
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("a greedy user") && message.contains("max_texture_dimension_2d"),
        "{message}"
    );
    let features = wgpu::Features::all() - ctx.device.features();
    if !features.is_empty() {
        let message = ctx
            .require("a picky user", features, &modest)
            .unwrap_err()
            .to_string();
        assert!(message.contains("features"), "{message}");
    }
}

/// A host's device: its own handler keeps receiving its own uncaptured
/// errors, and none of the context's captured ones.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn a_hosts_device_keeps_its_handlers() {
    let _context = test_context();
    // The host opens its own device, as a renderer would.
    let instance = wgpu::Instance::new(super::instance_descriptor());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default())).unwrap();
    let (host_device, host_queue) =
        pollster::block_on(adapter.request_device(&Default::default())).unwrap();
    let seen = Arc::new(Mutex::new(Vec::<String>::new()));
    let log = Arc::clone(&seen);
    host_device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        log.lock().unwrap().push(e.to_string())
    }));
    let ctx = GpuContext::from_device(host_device.clone(), host_queue);
    assert_eq!(ctx.adapter.name, adapter.get_info().name);
    assert!(
        ctx.capture("method", || {
            broken_shader(&ctx);
            Ok(())
        })
        .is_err()
    );
    assert!(
        seen.lock().unwrap().is_empty(),
        "the host saw the method's error"
    );
    broken_shader(&ctx);
    assert_eq!(
        seen.lock().unwrap().len(),
        1,
        "the host's handler was replaced"
    );
}

fn texture(
    ctx: &GpuContext,
    width: u32,
    height: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    ctx.create_texture_2d("test texture", (width, height), format, usage)
}

/// Rows of 13 Rgba32Float texels (208 bytes) and 37 R32Float texels
/// (148 bytes) are not multiples of 256 bytes.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn texture_read_back_handles_row_padding() {
    let ctx = test_context();
    let (width, height) = (37, 5);
    let values: Vec<f32> = (0..width * height).map(|i| i as f32).collect();
    let usage = wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST;
    let r32 = texture(&ctx, width, height, wgpu::TextureFormat::R32Float, usage);
    ctx.queue.write_texture(
        r32.as_image_copy(),
        bytemuck::cast_slice(&values),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * 4),
            rows_per_image: Some(height),
        },
        r32.size(),
    );
    assert_eq!(ctx.read_texture::<f32>(&r32).unwrap(), values);
    assert!(ctx.read_texture::<[f32; 4]>(&r32).is_err());

    // A render target whose fragment shader writes the pixel position:
    // texel (x, y) of the read-back must hold the centre (x + ½, y + ½),
    // row 0 at the top.
    let (width, height) = (13, 6);
    let format = wgpu::TextureFormat::Rgba32Float;
    let renderable = wgpu::TextureUsages::RENDER_ATTACHMENT;
    if !ctx
        .format_features(format)
        .allowed_usages
        .contains(renderable)
    {
        eprintln!(
            "{} cannot render to {format:?}; render read-back not tested",
            ctx.adapter
        );
        return;
    }
    let target = texture(
        &ctx,
        width,
        height,
        format,
        wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("position"),
            source: wgpu::ShaderSource::Wgsl(
                "@vertex fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
                 let xy = vec2<f32>(f32(i & 1u) * 4.0 - 1.0, f32(i >> 1u) * 4.0 - 1.0);
                 return vec4<f32>(xy, 0.5, 1.0);
             }
             @fragment fn fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
                 return vec4<f32>(p.xy, 0.0, 1.0);
             }"
                .into(),
            ),
        });
    let pipeline = ctx
        .device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("position"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
    let view = target.create_view(&Default::default());
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: None,
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.draw(0..3, 0..1);
    }
    ctx.submit_and_wait([encoder.finish()]).unwrap();
    let texels = ctx.read_texture::<[f32; 4]>(&target).unwrap();
    assert_eq!(texels.len(), (width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let t = texels[(y * width + x) as usize];
            assert_eq!(
                t,
                [x as f32 + 0.5, y as f32 + 0.5, 0.0, 1.0],
                "texel ({x}, {y})"
            );
        }
    }
}

/// A quad at depth ½ fills the depth buffer; a point drawn at depth ¼
/// passes the depth test (query > 0: visible), one at ¾ does not. The
/// points sit on pixel centres, inside the view volume (crates.md).
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn occlusion_queries_see_points_in_front_of_a_quad() {
    let ctx = test_context();
    let (size, depth_format) = (8, wgpu::TextureFormat::Depth32Float);
    let centre = (2.0 * 3.5) / size as f32 - 1.0;
    #[rustfmt::skip]
    let vertices: [[f32; 4]; 8] = [
        [-1.0, -1.0, 0.5, 1.0], [1.0, -1.0, 0.5, 1.0], [1.0, 1.0, 0.5, 1.0],
        [-1.0, -1.0, 0.5, 1.0], [1.0, 1.0, 0.5, 1.0], [-1.0, 1.0, 0.5, 1.0],
        [centre, centre, 0.25, 1.0], [centre, centre, 0.75, 1.0],
    ];
    let vertex_buffer = ctx.create_buffer_init("vertices", &vertices, wgpu::BufferUsages::VERTEX);
    let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("depth"),
        source: wgpu::ShaderSource::Wgsl(
            "@vertex fn vs(@location(0) p: vec4<f32>) -> @builtin(position) vec4<f32> { return p; }".into(),
        ),
    });
    let layout = [Some(wgpu::VertexBufferLayout {
        array_stride: 16,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x4],
    })];
    let pipeline = |topology, write| {
        ctx.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: None,
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &layout,
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: depth_format,
                    depth_write_enabled: Some(write),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: None,
                multiview_mask: None,
                cache: None,
            })
    };
    let quad = pipeline(wgpu::PrimitiveTopology::TriangleList, true);
    let points = pipeline(wgpu::PrimitiveTopology::PointList, false);
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
    let depth = texture(&ctx, size, size, depth_format, usage);
    let depth_view = depth.create_view(&Default::default());
    let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
        label: None,
        ty: wgpu::QueryType::Occlusion,
        count: 2,
    });
    let results = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: 2 * u64::from(wgpu::QUERY_SIZE),
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: None,
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: Some(&queries),
            multiview_mask: None,
        });
        pass.set_vertex_buffer(0, vertex_buffer.slice(..));
        pass.set_pipeline(&quad);
        pass.draw(0..6, 0..1);
        pass.set_pipeline(&points);
        for (query, vertex) in [6u32, 7].into_iter().enumerate() {
            pass.begin_occlusion_query(query as u32);
            pass.draw(vertex..vertex + 1, 0..1);
            pass.end_occlusion_query();
        }
    }
    encoder.resolve_query_set(&queries, 0..2, &results, 0);
    ctx.submit_and_wait([encoder.finish()]).unwrap();
    let samples: Vec<u64> = ctx.read_buffer(&results, 0, 2).unwrap();
    assert!(samples[0] > 0, "point in front of the quad: {samples:?}");
    assert_eq!(samples[1], 0, "point behind the quad: {samples:?}");

    // The GL backend cannot copy depth textures (crates.md).
    if ctx.adapter.backend != "OpenGL" {
        let depths = ctx.read_texture::<f32>(&depth).unwrap();
        assert_eq!(depths, vec![0.5; (size * size) as usize]);
    }
}

/// Read-backs from several threads at once: whichever thread's poll runs a
/// mapping callback, every reader gets its own values.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn concurrent_read_backs_each_arrive() {
    let ctx = test_context();
    std::thread::scope(|s| {
        let readers: Vec<_> = (0..3u32)
            .map(|t| {
                let ctx = &ctx;
                s.spawn(move || {
                    (0..40u32).all(|i| {
                        let values = vec![t * 1000 + i; 256];
                        let buffer =
                            ctx.create_buffer_init("values", &values, wgpu::BufferUsages::COPY_SRC);
                        ctx.read_buffer::<u32>(&buffer, 0, 256).unwrap() == values
                    })
                })
            })
            .collect();
        for reader in readers {
            assert!(reader.join().unwrap());
        }
    });
}
