//! The method against its device: GPU errors come back as the stage's
//! error, plans larger than the device can hold are refused before anything
//! is allocated, and recordings into one encoder each keep their own camera.

use std::sync::Arc;

mod support;

use deferred_shadow::{Config, DeferredShadow};
use glam::{Vec3, Vec4};
use shadow_core::{
    Brdf, Camera, Environment, Error, Object, Scene, ShadowMethod,
    gpu::{GpuStages, limited_test_context, test_context},
    shapes,
};
use support::patchy;

fn camera(eye: Vec3) -> Camera {
    Camera::new(eye, Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 0.8, 48, 32).unwrap()
}

/// A ball of `material` over a floor of white Lambert.
fn ball_on_floor(material: Brdf) -> Scene {
    let ball = shapes::uv_sphere("ball", Vec3::new(0.0, 0.5, 0.0), 0.5, 12, 24).unwrap();
    let floor = shapes::floor("floor", Vec3::ZERO, 2.0, 8).unwrap();
    let objects = vec![
        Object {
            mesh: Arc::new(ball),
            material,
        },
        Object {
            mesh: Arc::new(floor),
            material: Brdf::lambert(Vec3::splat(0.8)).unwrap(),
        },
    ];
    Scene::still("ball on a floor", objects, camera(Vec3::new(0.0, 2.0, 3.0))).unwrap()
}

fn run(method: &mut DeferredShadow, scene: &Scene, env: &Environment) -> shadow_core::Result<()> {
    method.prepare(scene)?;
    method.relight(env)?;
    method.update(&scene.frame_geometry(0)?, scene.camera())
}

/// A resource the device cannot make (the image of a camera one texel
/// wider than the device's widest texture) is the stage's `Error::Gpu`,
/// recorded or blocking, and the method renders again afterwards.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn an_image_too_wide_for_the_device_is_an_error_of_the_stage() {
    let ctx = test_context();
    let scene = ball_on_floor(Brdf::lambert(Vec3::splat(0.8)).unwrap());
    let mut method = DeferredShadow::new(Arc::clone(&ctx), Config::default()).unwrap();
    run(&mut method, &scene, &patchy()).unwrap();
    let wide = ctx.device.limits().max_texture_dimension_2d + 1;
    let too_wide =
        Camera::new(Vec3::new(0.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y, 0.8, wide, 1).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let recorded = method.record_render(&too_wide, &mut encoder).map(drop);
    assert!(matches!(recorded, Err(Error::Gpu(_))), "{recorded:?}");
    drop(encoder);
    let rendered = method.render(&too_wide).map(drop);
    assert!(matches!(rendered, Err(Error::Gpu(_))), "{rendered:?}");
    let image = method.render(scene.camera()).unwrap();
    assert!(image.covered.iter().filter(|c| **c).count() > 100);
}

/// More map storage than the device binds is refused as a configuration
/// error that names the settings, the bytes needed and the limit, before
/// anything is allocated; settings that fit run on the same device.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn maps_beyond_the_device_limit_are_refused_by_name() {
    let limit = 1 << 20;
    let ctx = limited_test_context(|l| l.max_storage_buffer_binding_size = limit);
    let scene = ball_on_floor(Brdf::lambert(Vec3::splat(0.8)).unwrap());
    // 128 lights and maps of up to 256² texels: more than 1 MiB of maps
    // on this scene (the message names the bytes).
    let config = Config {
        lights: 128,
        map_resolution: 256,
        ..Config::default()
    };
    let mut method = DeferredShadow::new(Arc::clone(&ctx), config).unwrap();
    let refused = run(&mut method, &scene, &patchy());
    let Err(Error::InvalidConfig { what, .. }) = refused else {
        panic!("{refused:?}")
    };
    for named in ["q = 128", "256×256", &format!("{limit} bytes")] {
        assert!(what.contains(named), "{named:?} not in {what:?}");
    }
    let fits = Config {
        lights: 32,
        map_resolution: 16,
        ..Config::default()
    };
    let mut method = DeferredShadow::new(ctx, fits).unwrap();
    run(&mut method, &scene, &patchy()).unwrap();
    assert!(method.map_count().unwrap() > 16);
    let image = method.render(scene.camera()).unwrap();
    assert!(image.covered.iter().filter(|c| **c).count() > 100);
}

/// Two cameras recorded into one encoder, each image copied out before the
/// next recording, give each camera's own image: what a recording alone
/// gives. The ball is glossy, so its self-shadowed radiance depends on the
/// eye too; the same holds for two eyes' vertex radiance.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn two_cameras_recorded_into_one_encoder_each_get_their_own_image() {
    let ctx = test_context();
    let glossy = Brdf::phong(Vec3::splat(0.3), Vec3::splat(0.5), 20.0).unwrap();
    let scene = ball_on_floor(glossy);
    let mut method = DeferredShadow::new(Arc::clone(&ctx), Config::default()).unwrap();
    run(&mut method, &scene, &patchy()).unwrap();
    let cameras = [
        camera(Vec3::new(0.0, 2.0, 3.0)),
        camera(Vec3::new(3.0, 1.0, -1.0)),
    ];

    let mut alone = Vec::new();
    for camera in &cameras {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let texture = method.record_render(camera, &mut encoder).unwrap().clone();
        ctx.submit_and_wait([encoder.finish()]).unwrap();
        alone.push(ctx.read_texture::<[f32; 4]>(&texture).unwrap());
    }
    let vertices: usize = scene.objects().iter().map(|o| o.mesh.vertex_count()).sum();
    let mut eyes_alone = Vec::new();
    for camera in &cameras {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let buffer = method
            .record_shade(camera.eye, &mut encoder)
            .unwrap()
            .clone();
        ctx.submit_and_wait([encoder.finish()]).unwrap();
        eyes_alone.push(ctx.read_buffer::<Vec4>(&buffer, 0, vertices).unwrap());
    }

    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let mut images = Vec::new();
    let mut radiances = Vec::new();
    for camera in &cameras {
        let texture = method.record_render(camera, &mut encoder).unwrap().clone();
        assert!(
            texture
                .usage()
                .contains(wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC)
        );
        let copy = ctx.create_texture_2d(
            "the caller's copy",
            (camera.width, camera.height),
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
        );
        encoder.copy_texture_to_texture(
            texture.as_image_copy(),
            copy.as_image_copy(),
            texture.size(),
        );
        images.push(copy);
        let buffer = method
            .record_shade(camera.eye, &mut encoder)
            .unwrap()
            .clone();
        let copy = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("the caller's copy"),
            size: buffer.size(),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(&buffer, 0, &copy, 0, buffer.size());
        radiances.push(copy);
    }
    ctx.submit_and_wait([encoder.finish()]).unwrap();

    let texels = |texture: &wgpu::Texture| -> Vec<Vec4> {
        let texels: Vec<[f32; 4]> = ctx.read_texture(texture).unwrap();
        texels.into_iter().map(Vec4::from).collect()
    };
    let alone: Vec<Vec<Vec4>> = alone
        .iter()
        .map(|image| image.iter().copied().map(Vec4::from).collect())
        .collect();
    for (image, expected) in images.iter().zip(&alone) {
        let apart = most_apart(&texels(image), expected);
        println!("image apart {apart}");
        // Measured: 0 (the same commands on the same data).
        assert!(apart < 1e-6, "{apart}");
    }
    for (radiance, expected) in radiances.iter().zip(&eyes_alone) {
        let values: Vec<Vec4> = ctx.read_buffer(radiance, 0, vertices).unwrap();
        let apart = most_apart(&values, expected);
        println!("radiance apart {apart}");
        // Measured: 0.
        assert!(apart < 1e-6, "{apart}");
    }
    // The two cameras see different images, and the ball's vertices
    // differ between the two eyes.
    let differ = |a: &[Vec4], b: &[Vec4]| {
        a.iter()
            .zip(b)
            .filter(|(a, b)| (**a - **b).abs().max_element() > 1e-3)
            .count()
    };
    let pixels = differ(&alone[0], &alone[1]);
    let ball = scene.objects()[0].mesh.vertex_count();
    let moved = differ(&eyes_alone[0][..ball], &eyes_alone[1][..ball]);
    println!(
        "{pixels} of {} pixels differ, {moved} of {ball} ball vertices",
        alone[0].len()
    );
    // Measured: 905 of 1536 pixels, 276 of 325 vertices.
    assert!(pixels > alone[0].len() / 4, "{pixels} pixels differ");
    assert!(moved > ball / 2, "{moved} of {ball} ball vertices differ");
}

/// The largest difference of any channel between two lists.
fn most_apart(a: &[Vec4], b: &[Vec4]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0, f32::max)
}

/// A device whose widest texture holds 2 × 2 tiles of 64² draws a plan's
/// maps in atlas batches of four: the image is the one a device with room
/// for all of them in one batch gives.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn maps_in_many_atlas_batches_match_one_batch() {
    let scene = ball_on_floor(Brdf::lambert(Vec3::splat(0.8)).unwrap());
    let image = |ctx| {
        let mut method = DeferredShadow::new(ctx, Config::default()).unwrap();
        run(&mut method, &scene, &patchy()).unwrap();
        (
            method.map_count().unwrap(),
            method.render(scene.camera()).unwrap(),
        )
    };
    let (maps, one) = image(test_context());
    let (same, batched) = image(limited_test_context(|l| l.max_texture_dimension_2d = 128));
    assert_eq!(maps, same);
    assert!(maps > 8, "{maps} maps: at least three batches of four");
    let brightest = (one.pixels.iter()).fold(0.0f32, |m, p| m.max(p.max_element()));
    let worst = (one.pixels.iter().zip(&batched.pixels))
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(worst <= 1e-5 * brightest, "{worst} of {brightest}");
}
