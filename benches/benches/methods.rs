//! The methods side by side: one frame (update, then shade) of every setting
//! of the default report suite on the same scenes under the same environment.
//! Criterion groups by scene, so each group is a comparison table.
//!
//! A method that cannot shade a scene (deferred shadowing on the skinned
//! human) is left out of its group, with a line saying why.
//!
//! Before timing, each method runs once over every frame of the scene and is
//! scored as `harness report` scores it: relative L2 error per vertex against
//! the converged Monte-Carlo reference (cached in `.cache/reference` at the
//! workspace root), mean over frames. The errors are written beside
//! criterion's results, to `<criterion dir>/frame_<scene>/errors.json`, and
//! `harness::bench_table` prints them beside the medians.
//!
//! Run with `cargo bench -p benches --bench methods`.
#![forbid(unsafe_code)]

use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use harness::{
    bench_table::{self, GroupErrors},
    methods,
    reference::{self, ReferenceCache, ReferenceSettings},
    run::{self, References},
    scenes,
    suite::Suite,
};
use indicatif::ProgressBar;

/// What `errors.json` holds.
const MEASURE: &str = "relative L2 error per vertex against the converged Monte-Carlo \
                       reference, mean over the scene's frames (as `harness report` scores it)";

fn frame_per_method(c: &mut Criterion) {
    let gpu = methods::SharedGpu::new();
    let cache =
        ReferenceCache::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("../.cache/reference"));
    let criterion_dir = bench_table::criterion_dir();
    for spec in scenes::SCENES
        .iter()
        .filter(|s| ["bunny", "human"].contains(&s.name))
    {
        let scene = scenes::builtin(spec.name).expect("built-in scene");
        let env = scenes::environment(spec.environment).expect("shipped environment");
        let (references, _) = reference::scene_references(
            &scene,
            &env,
            &ReferenceSettings::CONVERGED,
            Some(&cache),
            &ProgressBar::hidden(),
        )
        .expect("vertex references");
        let frame = scene
            .frame_geometry(scene.frames().len() / 2)
            .expect("a middle frame");
        let eye = scene.camera().eye;
        let group_id = format!("frame/{}", spec.name);
        let mut errors = GroupErrors::new(&group_id, MEASURE);
        let mut group = c.benchmark_group(&group_id);
        group.sample_size(10);
        let settings = Suite::Default
            .families()
            .into_iter()
            .flat_map(|f| f.methods);
        for spec in settings {
            let name = spec.name();
            let mut method = spec.build(&gpu).expect("the suite's methods build");
            if let Err(why) = method.capabilities().check(name, &scene) {
                println!("{group_id}/{name}: not run ({why})");
                continue;
            }
            // Prepares, relights and scores every frame once.
            let scored = run::run(
                method.as_mut(),
                &scene,
                &env,
                References::vertices(&references),
                1,
            )
            .expect("scored run");
            errors.insert(name, f64::from(scored.mean_error()));
            group.bench_function(BenchmarkId::from_parameter(name), |b| {
                b.iter(|| {
                    method.update(&frame, scene.camera()).expect("update");
                    method.shade(eye).expect("shade")
                })
            });
        }
        group.finish();
        errors.write(&criterion_dir).expect("errors.json written");
    }
}

criterion_group!(benches, frame_per_method);
criterion_main!(benches);
