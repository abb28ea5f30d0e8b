//! Tamura et al.'s Table 1 and Fig. 7 on this machine's wgpu adapter, and
//! the `chess` scene against the ray-tracing baseline.
//!
//! - `table1`: precomputation time and data size (printed, one run each) of
//!   the 5k-vertex dragon (for the paper's 5.8k-vertex Venus) and the
//!   35k-vertex bunny (for its 45k-vertex Buddha), each on a floor.
//! - `fig7/<model>-<material>`: one 512×512 frame (update with the object
//!   moved, so every map is rebuilt, then render) for q = 16, 32, 64 area
//!   lights and maps of 32², 64², 128², diffuse and glossy.
//! - `chess`: a 512-wide frame of the chess scene under its `interior`
//!   map, frames in turn (three pieces move), at 32 lights and 64² maps,
//!   with each piece its own occluder group and with the eight pieces as
//!   one (§4.2.3); each beside the per-pixel ray tracer at the fewest
//!   iterations whose image error is no larger (against a 1%-noise
//!   reference of frame 0, cached in `.cache/reference`).
//!
//! Run with `cargo bench -p benches --bench deferred_shadow`. Without a GPU
//! the adapter is Mesa's software rasterizer: the times are CPU times.
#![forbid(unsafe_code)]

use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use deferred_shadow::{Config, DeferredShadow, Grouping};
use glam::{Affine3A, Vec3};
use harness::{
    baselines::RayTrace,
    reference::{ReferenceCache, ReferenceSettings, scene_image_references},
    report::MachineInfo,
    scenes, score,
};
use indicatif::ProgressBar;
use shadow_core::{
    Brdf, Camera, Frame, FrameGeometry, Object, Pose, Scene, ShadowMethod, gpu::GpuContext, shapes,
};

/// Image side of the paper's measurements.
const SIDE: u32 = 512;

/// `path`'s mesh with `material` on a two-triangle floor, moving sideways
/// over two frames, seen in a `SIDE`² image.
fn moving_on_floor(name: &str, path: &str, material: Brdf) -> Scene {
    let meshes = scenes::assets_dir().join("meshes");
    let asset = scenes::asset_scene(name, &meshes.join(path), 1, material).expect("shipped mesh");
    let object = asset.objects()[0].clone();
    let bounds = object.mesh.bounds();
    let size = bounds.extent().max_element();
    let foot = Vec3::new(bounds.center().x, bounds.min.y, bounds.center().z);
    let floor = shapes::floor("floor", foot, size, 1).expect("floor");
    let frames = [-0.05, 0.05]
        .into_iter()
        .enumerate()
        .map(|(i, dx)| Frame {
            time: i as f32,
            poses: vec![
                Pose::Rigid(Affine3A::from_translation(Vec3::X * dx * size)),
                Pose::Rigid(Affine3A::IDENTITY),
            ],
        })
        .collect();
    let camera = Camera::framing(
        bounds.center(),
        0.8 * size,
        Vec3::new(0.8, 0.6, 1.0),
        SIDE,
        SIDE,
    )
    .expect("camera");
    let objects = vec![
        object,
        Object {
            mesh: Arc::new(floor),
            material: scenes::white(),
        },
    ];
    Scene::new(name, objects, frames, camera).expect("scene")
}

fn frames(scene: &Scene) -> Vec<FrameGeometry> {
    (0..scene.frames().len())
        .map(|i| scene.frame_geometry(i).expect("frame"))
        .collect()
}

fn models() -> [(&'static str, &'static str); 2] {
    [
        ("dragon-5k", "dragon_vrip_res4.glb"),
        ("bunny-35k", "bunny_stanford_bun_zipper.glb"),
    ]
}

fn glossy() -> Brdf {
    Brdf::phong(Vec3::splat(0.5), Vec3::splat(0.3), 30.0).expect("plausible Phong")
}

fn table1(ctx: &Arc<GpuContext>) {
    println!("Table 1 (one run each): model, vertices, precomputation s, data KB");
    for (name, path) in models() {
        for (material, brdf) in [("diffuse", scenes::white()), ("glossy", glossy())] {
            let scene = moving_on_floor(name, path, brdf);
            let mut method =
                DeferredShadow::new(Arc::clone(ctx), Config::default()).expect("config");
            method.prepare(&scene).expect("prepare");
            let (seconds, bytes) = method.precomputation().expect("prepared");
            println!(
                "  {name} {material}: {} vertices, {seconds:.2} s, {} KB",
                scene.vertex_count(),
                bytes / 1024
            );
        }
    }
}

/// One new frame, frames in turn: update then render.
fn frame_loop(
    method: &mut DeferredShadow,
    scene: &Scene,
    frames: &[FrameGeometry],
    next: &mut usize,
) -> shadow_core::Image {
    let frame = &frames[*next % frames.len()];
    *next += 1;
    method.update(frame, scene.camera()).expect("update");
    method.render(scene.camera()).expect("render")
}

fn fig7(c: &mut Criterion, ctx: &Arc<GpuContext>) {
    let env = scenes::environment("courtyard").expect("shipped environment");
    for (name, path) in models() {
        for (material, brdf) in [("diffuse", scenes::white()), ("glossy", glossy())] {
            let scene = moving_on_floor(name, path, brdf);
            let frames = frames(&scene);
            let mut group = c.benchmark_group(format!("fig7/{name}-{material}"));
            group
                .sample_size(10)
                .warm_up_time(std::time::Duration::from_secs(1))
                .measurement_time(std::time::Duration::from_secs(3));
            for lights in [16, 32, 64] {
                for map_resolution in [32, 64, 128] {
                    let config = Config {
                        lights,
                        map_resolution,
                        ..Config::default()
                    };
                    let mut method = DeferredShadow::new(Arc::clone(ctx), config).expect("config");
                    method.prepare(&scene).expect("prepare");
                    method.relight(&env).expect("relight");
                    let mut next = 0;
                    let id = BenchmarkId::new(format!("q{lights}"), map_resolution);
                    group.bench_function(id, |b| {
                        b.iter(|| frame_loop(&mut method, &scene, &frames, &mut next))
                    });
                }
            }
            group.finish();
        }
    }
}

/// The chess scene's occluder groups: each piece apart (the default), or
/// the eight pieces as one group beside the board's (§4.2.3).
fn chess_groupings(scene: &Scene) -> [(&'static str, Grouping); 2] {
    let pieces: Vec<usize> = (0..scene.objects().len())
        .filter(|&o| !scene.objects()[o].mesh.name().contains("squares"))
        .collect();
    let board = (0..scene.objects().len())
        .filter(|o| !pieces.contains(o))
        .collect();
    [
        ("deferred-shadow", Config::default().grouping),
        (
            "deferred-shadow, pieces grouped",
            Grouping::Explicit(vec![board, pieces]),
        ),
    ]
}

fn chess(c: &mut Criterion, ctx: &Arc<GpuContext>) {
    let spec = scenes::SCENES
        .iter()
        .find(|s| s.name == "chess")
        .expect("built-in scene");
    let scene = scenes::builtin(spec.name).expect("built-in scene");
    let camera = scene.camera().with_width(SIDE).expect("camera");
    let scene = scene.with_camera(camera);
    let env = scenes::environment(spec.environment).expect("shipped environment");
    let frames = frames(&scene);
    let cache = ReferenceCache::new(".cache/reference");
    let (references, _) = scene_image_references(
        &scene,
        &env,
        &camera,
        &ReferenceSettings::IMAGE,
        Some(&cache),
        &ProgressBar::hidden(),
    )
    .expect("image reference");
    let reference = &references[0];
    let mut group = c.benchmark_group("chess");
    for (name, grouping) in chess_groupings(&scene) {
        let config = Config {
            grouping,
            ..Config::default()
        };
        let mut method = DeferredShadow::new(Arc::clone(ctx), config).expect("config");
        method.prepare(&scene).expect("prepare");
        method.relight(&env).expect("relight");
        method.update(&frames[0], &camera).expect("update");
        let ours = score::image(&method.render(&camera).expect("render"), reference)
            .expect("score")
            .relative_l2;
        println!(
            "chess, {name}: {} maps, image error {:.2}% on frame 0 at {}×{}",
            method.map_count().unwrap_or(0),
            100.0 * ours,
            camera.width,
            camera.height
        );
        group.sample_size(20);
        let mut next = 0;
        group.bench_function(name, |b| {
            b.iter(|| frame_loop(&mut method, &scene, &frames, &mut next))
        });
        // The per-pixel ray tracer at the fewest iterations that reach the
        // same image error.
        let mut iterations = 1;
        let (mut tracer, error) = loop {
            let mut tracer = RayTrace::new(iterations, 7);
            tracer.prepare(&scene).expect("prepare");
            tracer.relight(&env).expect("relight");
            tracer.update(&frames[0], &camera).expect("update");
            let error = score::image(&tracer.render(&camera).expect("render"), reference)
                .expect("score")
                .relative_l2;
            if error <= ours || iterations >= 1 << 12 {
                break (tracer, error);
            }
            iterations *= 2;
        };
        println!(
            "chess, {name}: raytrace:{iterations} reaches {:.2}%",
            100.0 * error
        );
        group.sample_size(10);
        group.bench_function(format!("raytrace:{iterations} ({name})"), |b| {
            b.iter(|| {
                tracer.update(&frames[0], &camera).expect("update");
                tracer.render(&camera).expect("render")
            })
        });
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    let ctx = Arc::new(GpuContext::new().expect("a wgpu adapter (Mesa's lavapipe without a GPU)"));
    println!(
        "adapter: {}; CPU: {}",
        ctx.adapter,
        MachineInfo::cpu_generation()
    );
    table1(&ctx);
    chess(c, &ctx);
    fig7(c, &ctx);
}

criterion_group!(deferred, benches);
criterion_main!(deferred);
