//! Tamura et al.'s Table 1 and Fig. 7 on this machine's wgpu adapter, and
//! the `chess` scene against the ray-tracing baseline.
//!
//! - `table1`: precomputation time and data size (printed, one run each) of
//!   the 5k-vertex dragon (for the paper's 5.8k-vertex Venus) and the
//!   35k-vertex bunny (for its 45k-vertex Buddha), each on a floor.
//! - `fig7/<model>-<material>`: one 512×512 frame (update with the object
//!   moved, so every map is rebuilt, then render) for q = 16, 32, 64 area
//!   lights and maps of 32², 64², 128², diffuse and glossy.
//! - equal error (printed): deferred-shadow against the per-pixel ray
//!   tracer at the same image error on `chess` (each piece apart, and the
//!   pieces as one group, §4.2.3) and `bunny`, at 160, 512 and 1024 pixels
//!   wide, the ray tracer's time interpolated along its settings' errors
//!   (references of frame 0 at each width, 1% noise, cached in the
//!   workspace's `.cache/reference`).
//! - `chess`: a 512-wide frame of the chess scene under its `interior`
//!   map, frames in turn (three pieces move), at 32 lights and 64² maps,
//!   with each piece its own occluder group and with the eight pieces as
//!   one.
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
    reference::{ImageReference, ReferenceCache, ReferenceSettings, frame_image_reference},
    report::{MachineInfo, Overtakes, equal_error_ms, overtakes},
    scaling, scenes, score,
    timing::Timing,
};
use indicatif::ProgressBar;
use shadow_core::{
    Brdf, Camera, Environment, Frame, FrameGeometry, Object, Pose, Scene, ShadowMethod,
    gpu::GpuContext, shapes,
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

/// The `chess` scene at `width` pixels wide (its camera's aspect kept) and
/// its shipped environment.
fn chess_scene(width: u32) -> (Scene, Environment) {
    let scene = scenes::builtin("chess").expect("built-in scene");
    let camera = scene.camera().with_width(width).expect("camera");
    let env = scenes::environment(environment_of("chess")).expect("shipped environment");
    (scene.with_camera(camera), env)
}

fn environment_of(scene: &str) -> &'static str {
    scenes::SCENES
        .iter()
        .find(|s| s.name == scene)
        .expect("built-in scene")
        .environment
}

/// A `SIDE`-wide frame of `chess`, frames in turn, each piece apart and
/// the pieces grouped.
fn chess(c: &mut Criterion, ctx: &Arc<GpuContext>) {
    let (scene, env) = chess_scene(SIDE);
    let frames = frames(&scene);
    let mut group = c.benchmark_group("chess");
    group.sample_size(20);
    for (name, grouping) in chess_groupings(&scene) {
        let config = Config {
            grouping,
            ..Config::default()
        };
        let mut method = DeferredShadow::new(Arc::clone(ctx), config).expect("config");
        method.prepare(&scene).expect("prepare");
        method.relight(&env).expect("relight");
        method.update(&frames[0], scene.camera()).expect("update");
        println!(
            "chess, {name}: {} maps at {}×{}",
            method.map_count().unwrap_or(0),
            scene.camera().width,
            scene.camera().height
        );
        let mut next = 0;
        group.bench_function(name, |b| {
            b.iter(|| frame_loop(&mut method, &scene, &frames, &mut next))
        });
    }
    group.finish();
}

/// Widths of the equal-error comparison: the report's, the paper's and a
/// renderer's.
const WIDTHS: [u32; 3] = [160, 512, 1024];

/// Iterations per pixel of the ray tracer settings whose errors bracket
/// deferred-shadow's on `chess` and `bunny`.
const TRACER_ITERATIONS: [u32; 3] = [16, 64, 256];

/// A setting's image error on the first frame and its time per image
/// (update + render of a fresh frame), per width of [`WIDTHS`].
struct Curve {
    name: String,
    points: Vec<(f32, Timing)>,
}

fn curve(
    name: String,
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    env: &Environment,
    references: &[ImageReference],
) -> Curve {
    let times = scaling::time_images(method, scene, env, &WIDTHS, 3).expect("timed images");
    let frame = scene.frame_geometry(0).expect("frame");
    let points = times
        .into_iter()
        .zip(references)
        .map(|(at, reference)| {
            let camera = scene.camera().with_width(at.width).expect("camera");
            method.update(&frame, &camera).expect("update");
            let image = method.render(&camera).expect("render");
            let error = score::image(&image, reference).expect("score").relative_l2;
            (error, at.time)
        })
        .collect();
    Curve { name, points }
}

/// Deferred-shadow against the per-pixel ray tracer at equal image error,
/// as the image grows: per scene and width, both scored against that
/// width's reference and timed in this process, the ray tracer's time read
/// off its settings' (error, time) curve at deferred-shadow's error
/// (log-log between the settings around it, [`equal_error_ms`]). Printed
/// as a table; each time a median of three samples with its range.
fn equal_error(ctx: &Arc<GpuContext>) {
    // The workspace's cache, which `harness report` shares (benches run in
    // their package's folder).
    let cache = ReferenceCache::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.cache/reference"));
    println!("Equal image error (frame 0; ms per image, update + render, median of 3 and range):");
    println!(
        "| scene | setting | width | error | ms | ray tracer at that error, ms | times faster |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|");
    let mut notes = Vec::new();
    for name in ["chess", "bunny"] {
        let scene = scenes::builtin(name).expect("built-in scene");
        let env = scenes::environment(environment_of(name)).expect("shipped environment");
        let groupings = match name {
            "chess" => chess_groupings(&scene).to_vec(),
            _ => vec![("deferred-shadow", Config::default().grouping)],
        };
        let frame = scene.frame_geometry(0).expect("frame");
        let references: Vec<ImageReference> = WIDTHS
            .iter()
            .map(|&width| {
                let camera = scene.camera().with_width(width).expect("camera");
                frame_image_reference(
                    &scene,
                    &frame,
                    &env,
                    &camera,
                    &ReferenceSettings::IMAGE,
                    Some(&cache),
                    &ProgressBar::hidden(),
                )
                .expect("image reference")
                .0
            })
            .collect();
        let tracers: Vec<Curve> = TRACER_ITERATIONS
            .iter()
            .map(|&iterations| {
                let mut tracer = RayTrace::new(iterations, 7);
                curve(
                    format!("raytrace:{iterations}"),
                    &mut tracer,
                    &scene,
                    &env,
                    &references,
                )
            })
            .collect();
        for (name, grouping) in groupings {
            let config = Config {
                grouping,
                ..Config::default()
            };
            let mut method = DeferredShadow::new(Arc::clone(ctx), config).expect("config");
            let ours = curve(name.to_string(), &mut method, &scene, &env, &references);
            let mut ratios = Vec::new();
            for (w, (error, time)) in ours.points.iter().enumerate() {
                let at: Vec<(f32, f64)> = tracers
                    .iter()
                    .map(|t| (t.points[w].0, t.points[w].1.median() * 1e3))
                    .collect();
                let (tracer_ms, beyond) = equal_error_ms(&at, *error).expect("ray tracer timed");
                let ms = time.median() * 1e3;
                ratios.push((f64::from(WIDTHS[w]), ms / tracer_ms));
                println!(
                    "| {} | {} | {} | {:.2}% | {:.1} ({:.1}–{:.1}) | {}{:.1} | {:.1}× |",
                    scene.name(),
                    ours.name,
                    WIDTHS[w],
                    100.0 * error,
                    ms,
                    time.min() * 1e3,
                    time.max() * 1e3,
                    if beyond { "≈" } else { "" },
                    tracer_ms,
                    tracer_ms / ms
                );
            }
            let wins = match overtakes(&ratios) {
                Overtakes::Everywhere => format!("at every width from {}", WIDTHS[0]),
                Overtakes::From(w) => format!("from about {w:.0} pixels wide"),
                Overtakes::Never => format!("at no width up to {}", WIDTHS[WIDTHS.len() - 1]),
            };
            notes.push(format!(
                "- {}, {}: faster than the ray tracer {wins}",
                scene.name(),
                ours.name
            ));
        }
        for t in &tracers {
            let errors: Vec<String> = t
                .points
                .iter()
                .zip(WIDTHS)
                .map(|((e, time), w)| {
                    format!("{w}: {:.2}% {:.1} ms", 100.0 * e, time.median() * 1e3)
                })
                .collect();
            notes.push(format!(
                "- {}, {}: {}",
                scene.name(),
                t.name,
                errors.join(", ")
            ));
        }
    }
    // After the table, which they would break.
    println!();
    for note in notes {
        println!("{note}");
    }
}

fn benches(c: &mut Criterion) {
    let ctx = Arc::new(GpuContext::new().expect("a wgpu adapter (Mesa's lavapipe without a GPU)"));
    println!(
        "adapter: {}; CPU: {}",
        ctx.adapter,
        MachineInfo::cpu_generation()
    );
    table1(&ctx);
    equal_error(&ctx);
    chess(c, &ctx);
    fig7(c, &ctx);
}

criterion_group!(deferred, benches);
criterion_main!(deferred);
