//! The methods side by side: one frame (update, then shade) of every method
//! of the standard report on the same scenes under the same environment.
//! Criterion groups by scene, so each group is a comparison table.
//!
//! Run with `cargo bench -p benches --bench methods`. Error against the
//! reference is not measured here: `harness report` prints both.
#![forbid(unsafe_code)]

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use harness::{methods, scenes};

fn frame_per_method(c: &mut Criterion) {
    let gpu = methods::SharedGpu::new();
    for spec in scenes::SCENES
        .iter()
        .filter(|s| ["bunny", "human"].contains(&s.name))
    {
        let scene = scenes::builtin(spec.name).expect("built-in scene");
        let env = scenes::environment(spec.environment).expect("shipped environment");
        let frame = scene
            .frame_geometry(scene.frames().len() / 2)
            .expect("a middle frame");
        let eye = scene.camera().eye;
        let mut group = c.benchmark_group(format!("frame/{}", spec.name));
        group.sample_size(10);
        for name in methods::REPORT_METHODS {
            let mut method = methods::by_name(name, &gpu).expect("registered method");
            method.prepare(&scene).expect("prepare");
            method.relight(&env).expect("relight");
            group.bench_function(BenchmarkId::from_parameter(name), |b| {
                b.iter(|| {
                    method.update(&frame, scene.camera()).expect("update");
                    method.shade(eye).expect("shade")
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, frame_per_method);
criterion_main!(benches);
