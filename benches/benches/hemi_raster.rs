//! Kautz, Lehtinen and Aila 2004's Tables 1 and 2 on this machine.
//!
//! - Table 1 (criterion, per scene): one animation frame of `hemi-raster`
//!   (the frame's posed geometry, visibility, SH integration and shading),
//!   cycling through the scene's frames, with the two-level hierarchy and
//!   flat, each with and without potentially visible sets built from the
//!   scene's frames (§3.2), on every SIMD path the CPU runs, and with a
//!   64² plane table (§3.1.1) instead of 128²; and the skinning of the human
//!   (glTF joints and morphs to posed vertices), which a renderer adds per
//!   frame.
//! - Table 2 (printed before the measurements): where one update's time goes
//!   on one thread (transform, rasterization, integration, other) and the
//!   average number of blocker triangles per vertex, from
//!   [`HemiRaster::profile_update`].
//!
//! Run with `cargo bench -p benches --bench hemi_raster`. Timings on a
//! software-only machine are CPU timings; nothing here uses the GPU.
#![forbid(unsafe_code)]

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use harness::gltf::GltfAsset;
use harness::report::MachineInfo;
use harness::scenes;
use hemi_raster::{Config, HemiRaster, Hierarchy, Pvs, Simd};
use shadow_core::{Scene, ShadowMethod, Stage};

/// The paper's three scene kinds that we have: cloth, a skinned character
/// (its "Fight"), moving chess pieces.
const SCENES: [&str; 3] = ["cloth", "human", "chess"];

fn scenes() -> Vec<Scene> {
    SCENES
        .iter()
        .filter(|name| scenes::SCENES.iter().any(|s| s.name == **name))
        .map(|name| scenes::builtin(name).expect("built-in scene"))
        .collect()
}

/// Each setup timed, labelled "name/SIMD path", without and with potentially
/// visible sets from every frame ([`with_sets`]): the two-level hierarchy on every path the
/// CPU runs; on the widest, the 64² plane table (the fastest setup found
/// that stays near the default's accuracy: hemi-raster's README, "Speed
/// and accuracy") and the flat mesh.
fn configs() -> Vec<(String, Config)> {
    let two_level = Config::default();
    let mut setups: Vec<(&str, Config)> = Simd::available()
        .into_iter()
        .rev()
        .map(|simd| ("two-level", Config { simd, ..two_level }))
        .collect();
    setups.push((
        "two-level+lut64",
        Config {
            lut_resolution: 64,
            ..two_level
        },
    ));
    setups.push((
        "flat",
        Config {
            hierarchy: Hierarchy::Flat,
            ..two_level
        },
    ));
    setups
        .into_iter()
        .flat_map(|(name, config)| {
            let pvs = with_sets(config);
            let path = config.simd;
            [
                (format!("{name}/{path:?}"), config),
                (format!("{name}+pvs/{path:?}"), pvs),
            ]
        })
        .collect()
}

/// `config` with visible sets from every frame, and with two levels, the
/// wider near field of [`Config::fast`].
fn with_sets(config: Config) -> Config {
    Config {
        pvs: Pvs::EVERY_FRAME,
        hierarchy: match config.hierarchy {
            Hierarchy::Flat => Hierarchy::Flat,
            Hierarchy::TwoLevel { .. } => Config::fast().hierarchy,
        },
        ..config
    }
}

/// Table 2, printed: one profiled update per scene and hierarchy.
fn print_split() {
    println!(
        "\nhemi-raster on {}, SIMD paths {:?}",
        MachineInfo::cpu_generation(),
        Simd::available()
    );
    println!(
        "time split on one thread (Kautz et al. Table 2), {:?} path",
        Simd::Auto.resolve().expect("a path")
    );
    println!(
        "{:<8} {:<10} {:>6} {:>7} {:>10} {:>9} {:>9} {:>11} {:>7} {:>9}",
        "scene",
        "hierarchy",
        "verts",
        "tris",
        "avg #tris",
        "survive",
        "transform",
        "rasterize",
        "integr.",
        "other"
    );
    for scene in scenes() {
        let frame = scene.frame_geometry(0).expect("frame 0");
        for (label, config) in [
            ("two-level", Config::default()),
            ("two-l.+pvs", Config::fast()),
            ("flat", Config::accurate()),
            ("flat+pvs", with_sets(Config::accurate())),
        ] {
            let mut method = HemiRaster::new(config);
            method.prepare(&scene).expect("prepare");
            method
                .update(&frame, scene.camera())
                .expect("warm-up update");
            let p = method.profile_update(&frame).expect("profiled update");
            let seconds = |name| p.seconds_in(Stage::Update, name).expect("profiled part");
            let count = |name| p.count_in(Stage::Update, name).expect("profiled count");
            let parts = ["gather", "transform", "rasterization", "integration"];
            let total: f64 = parts.iter().map(|name| seconds(name)).sum();
            let share = |name| 100.0 * seconds(name) / total;
            let per_vertex = |n: u64| n as f64 / count("receivers") as f64;
            println!(
                "{:<8} {:<10} {:>6} {:>7} {:>10.1} {:>8.1}% {:>8.1}% {:>10.1}% {:>6.1}% {:>8.1}%   {:.1} ms, {:.2} ns per pair",
                scene.name(),
                label,
                scene.vertex_count(),
                scene.triangle_count(),
                per_vertex(count("candidates")),
                100.0 * count("survivors") as f64 / count("candidates") as f64,
                share("transform"),
                share("rasterization"),
                share("integration"),
                share("gather"),
                total * 1e3,
                (seconds("transform") + seconds("rasterization")) * 1e9
                    / count("candidates") as f64,
            );
        }
    }
    println!();
}

fn table1(c: &mut Criterion) {
    print_split();
    for scene in scenes() {
        let frames: Vec<_> = (0..scene.frames().len())
            .map(|i| scene.frame_geometry(i).expect("frame"))
            .collect();
        let mut group = c.benchmark_group(format!("hemi-raster/{}", scene.name()));
        group.sample_size(10);
        for (label, config) in configs() {
            let mut method = HemiRaster::new(config);
            method.prepare(&scene).expect("prepare");
            method
                .relight(&scenes::environment("uniform").expect("uniform"))
                .expect("relight");
            let mut next = 0;
            group.bench_function(BenchmarkId::from_parameter(label), |b| {
                b.iter(|| {
                    let i = next % frames.len();
                    next += 1;
                    let geometry = scene.frame_geometry(i).expect("frame");
                    method.update(&geometry, scene.camera()).expect("update");
                    method.shade(scene.camera().eye).expect("shade")
                })
            });
        }
        group.finish();
    }
}

/// Posing the skinned human: what a renderer adds to every frame.
fn skinning(c: &mut Criterion) {
    let path = scenes::assets_dir().join("meshes/BCN_Epileptic_skinned_animated.glb");
    let asset = GltfAsset::load(&path).expect("the shipped human");
    let duration = asset.duration();
    let mut t = 0.0;
    c.bench_function("hemi-raster/human/skinning", |b| {
        b.iter(|| {
            t = (t + duration / 7.0) % duration.max(f32::MIN_POSITIVE);
            asset.pose_at(t).expect("pose")
        })
    });
}

criterion_group!(benches, table1, skinning);
criterion_main!(benches);
