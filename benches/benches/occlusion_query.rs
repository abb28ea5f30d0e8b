//! Sattler et al. 2004's Table 1 on this machine's wgpu adapter: the time
//! to compute the visibility matrix, without and with vertex filtering
//! (time₁, time₂), on the 35k-vertex bunny (static: every iteration a
//! fresh method, so that nothing is reused) for k = 6 to 1026, and per frame
//! of the skinned human (its skeleton: the geometry changes every frame, so
//! M is recomputed), with update + shade for its frame rate.
//!
//! The paper's own test, per-vertex occlusion queries, costs about half a
//! second per direction for 35k points on a software rasterizer; it is
//! timed on the bunny at k = 6 and 18 and on the human at every k.
//!
//! Run with `cargo bench -p benches --bench occlusion_query`. On a machine
//! without a GPU the adapter is Mesa's software rasterizer, and the times
//! are CPU times: the bench prints which.
#![forbid(unsafe_code)]

use std::sync::Arc;

use criterion::{BatchSize, BenchmarkId, Criterion, criterion_group, criterion_main};
use harness::{report::MachineInfo, scenes};
use occlusion_query::{Config, Filtering, Level, OcclusionQuery, VertexTest};
use shadow_core::{Scene, ShadowMethod, gpu::GpuContext};

/// The setups timed: the default test and the paper's queries, each
/// without and with vertex filtering.
fn setups() -> [(&'static str, Config); 4] {
    let filtering = Some(Filtering { threshold: 0.05 });
    let queries = Config {
        test: VertexTest::OcclusionQuery,
        ..Config::default()
    };
    [
        ("compare", Config::default()),
        (
            "compare+filter",
            Config {
                filtering,
                ..Config::default()
            },
        ),
        ("queries", queries),
        (
            "queries+filter",
            Config {
                filtering,
                ..queries
            },
        ),
    ]
}

fn prepared(ctx: &Arc<GpuContext>, config: Config, scene: &Scene) -> OcclusionQuery {
    let mut method = OcclusionQuery::new(Arc::clone(ctx), config).expect("valid config");
    method.prepare(scene).expect("prepare");
    method
        .relight(&scenes::environment("forest").expect("shipped environment"))
        .expect("relight");
    method
}

fn table1(c: &mut Criterion) {
    let ctx = Arc::new(GpuContext::new().expect("a wgpu adapter (Mesa's lavapipe without a GPU)"));
    println!(
        "adapter: {}; CPU: {}",
        ctx.adapter,
        MachineInfo::cpu_generation()
    );

    // The static bunny: time₁ and time₂ of one fresh computation of M.
    let bunny = scenes::builtin("bunny-35k").expect("built-in scene");
    let frame = bunny.frame_geometry(0).expect("frame 0");
    let mut group = c.benchmark_group("table1/bunny-35k");
    group.sample_size(10);
    for s in 0..=4 {
        let level = Level::new(s).expect("level");
        for (name, config) in setups() {
            let queries = config.test == VertexTest::OcclusionQuery;
            if queries && s > 1 {
                continue;
            }
            let config = Config { level, ..config };
            let id = BenchmarkId::new(name, level.directions());
            group.bench_function(id, |b| {
                b.iter_batched(
                    || prepared(&ctx, config, &bunny),
                    |mut method| method.update(&frame, bunny.camera()).expect("update"),
                    BatchSize::PerIteration,
                )
            });
        }
    }
    group.finish();

    // The skinned human: one frame (update + shade) after another.
    let human = scenes::builtin("human").expect("built-in scene");
    let frames: Vec<_> = (0..human.frames().len())
        .map(|i| human.frame_geometry(i).expect("frame"))
        .collect();
    let mut group = c.benchmark_group("table1/human");
    group.sample_size(10);
    for s in 0..=3 {
        let level = Level::new(s).expect("level");
        for (name, config) in setups() {
            let config = Config { level, ..config };
            let mut method = prepared(&ctx, config, &human);
            let mut next = 0;
            group.bench_function(BenchmarkId::new(name, level.directions()), |b| {
                b.iter(|| {
                    let frame = &frames[next % frames.len()];
                    next += 1;
                    method.update(frame, human.camera()).expect("update");
                    method.shade(human.camera().eye).expect("shade")
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, table1);
criterion_main!(benches);
