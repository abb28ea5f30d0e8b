//! Throughput of the Monte-Carlo reference's shadow rays on Sattler et al.'s
//! 35k-vertex bunny under a captured HDR environment.
//!
//! Run with `cargo bench -p benches --bench reference`. The figure that matters
//! is rays per second (criterion's "thrpt", in elements/s).
#![forbid(unsafe_code)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use harness::{
    reference::{self, ReferenceSettings, Setup},
    scenes,
};
use indicatif::ProgressBar;

fn shadow_rays(c: &mut Criterion) {
    let scene = scenes::builtin("bunny-35k").expect("the bunny asset loads");
    let env = scenes::environment("forest").expect("the forest environment loads");
    let frame = scene.frame_geometry(0).expect("frame 0");
    let setup = Setup::new(&frame, &env).expect("BVH and sampler");
    let estimator = setup.estimator();
    let points = reference::vertex_points(&scene, &frame, scene.camera().eye);
    let settings = ReferenceSettings::replicated(4, 2, 1);
    let bar = ProgressBar::hidden();
    let rays = reference::estimate(&points, &estimator, &settings, &bar).rays;

    let mut group = c.benchmark_group("reference");
    group.sample_size(10);
    group.throughput(Throughput::Elements(rays));
    group.bench_function("bunny-35k forest, 8 MIS iterations per vertex", |b| {
        b.iter(|| reference::estimate(&points, &estimator, &settings, &bar))
    });
    group.finish();

    c.bench_function("reference/BVH build, bunny-35k", |b| {
        b.iter(|| shadow_core::bvh::SceneBvh::build(&frame).expect("BVH"))
    });
}

criterion_group!(benches, shadow_rays);
criterion_main!(benches);
