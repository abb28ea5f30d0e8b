//! Throughput of the Monte-Carlo reference's shadow rays on Sattler et al.'s
//! 35k-vertex bunny under a captured HDR environment.
//!
//! Run with `cargo bench -p benches --bench reference`. The figure that matters
//! is rays per second (criterion's "thrpt", in elements/s). Beside the
//! ambient-occlusion rays and bakes it runs MeshLab's ambient occlusion
//! (Embree inside) on the same meshes, through `meshlab/ambient_occlusion.py`
//! (`pip install pymeshlab`; `SOFT_SHADOWS_SKIP=meshlab` leaves it out), and
//! prints its rays per second and times.
#![forbid(unsafe_code)]

use std::{collections::HashMap, path::Path, process::Command, sync::Arc};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use harness::{
    bake,
    reference::{self, ReferenceSettings, Setup},
    scenes,
};
use indicatif::ProgressBar;
use rayon::prelude::*;
use shadow_core::qmc::{cosine_hemisphere, sobol2};
use shadow_core::{Mesh, Object, Scene};

fn shadow_rays(c: &mut Criterion) {
    let scene = scenes::builtin("bunny-35k").expect("the bunny asset loads");
    let env = scenes::environment("forest").expect("the forest environment loads");
    let frame = scene.frame_geometry(0).expect("frame 0");
    let setup = Setup::new(&frame, &env).expect("BVH and sampler");
    // Rays alone: the control variate's exact integral per vertex (a
    // fixed cost per vertex, not per ray) is left out.
    let estimator = reference::Estimator {
        unoccluded: None,
        ..setup.estimator()
    };
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

/// Ambient-occlusion shadow rays alone: from every vertex of the 35k bunny,
/// 128 cosine-distributed directions (Sobol', one shift per vertex), the
/// workload of a bake under the uniform sky.
fn ambient_occlusion_rays(c: &mut Criterion) {
    let scene = scenes::builtin("bunny-35k").expect("the bunny asset loads");
    let frame = scene.frame_geometry(0).expect("frame 0");
    let bvh = shadow_core::bvh::SceneBvh::build(&frame).expect("BVH");
    let points = reference::vertex_points(&scene, &frame, scene.camera().eye);
    let per_point = 128u32;
    let trace = || {
        points
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let tangents = shadow_core::TangentSpace::new(p.normal);
                let shift = [
                    (i as u32).wrapping_mul(0x9e3779b9),
                    (i as u32).wrapping_mul(0x85ebca6b),
                ];
                (0..per_point)
                    .filter(|&k| {
                        let d = tangents.to_world(cosine_hemisphere(sobol2(k, shift)));
                        bvh.unoccluded_from(&p.surface(), d, f32::INFINITY)
                    })
                    .count() as u64
            })
            .sum::<u64>()
    };
    let mut group = c.benchmark_group("reference");
    group.sample_size(10);
    group.throughput(Throughput::Elements(points.len() as u64 * per_point as u64));
    group.bench_function("bunny-35k ambient occlusion, 128 rays per vertex", |b| {
        b.iter(trace)
    });
    group.finish();
    if let Some(run) = meshlab(256, 0, 5) {
        println!(
            "MeshLab (Embree), bunny-35k ambient occlusion, 256 directions per face: \
             {:.2} M rays/s (median of {}; {:.2}–{:.2}), {:.1} M closest-hit rays",
            run.rays as f64 / run.median() * 1e-6,
            run.seconds.len(),
            run.rays as f64 / run.slowest() * 1e-6,
            run.rays as f64 / run.fastest() * 1e-6,
            run.rays as f64 * 1e-6,
        );
    }
}

/// The bake's default (the reference to 1%) on the 35k bunny subdivided
/// once and twice at edge midpoints (278k and 1.1M triangles), beside
/// MeshLab's 256-ray ambient occlusion of the same meshes.
fn bakes(c: &mut Criterion) {
    let bunny = scenes::builtin("bunny-35k").expect("the bunny asset loads");
    let env = shadow_core::Environment::uniform(Vec3::ONE);
    let mut group = c.benchmark_group("bake");
    group.sample_size(10);
    let mut mesh = bunny.objects()[0].mesh.as_ref().clone();
    for subdivisions in 1..=2 {
        mesh = subdivided(&mesh);
        let object = Object {
            mesh: Arc::new(mesh.clone()),
            material: bunny.objects()[0].material,
        };
        let scene = Scene::still("bunny", vec![object], *bunny.camera()).expect("scene");
        let triangles = mesh.triangles().len();
        let bar = ProgressBar::hidden();
        let settings = ReferenceSettings::BAKE;
        let first = bake::reference_frame(&scene, &env, 0, &settings, &bar).expect("bake");
        println!(
            "bake of {triangles} triangles: error bound {:.3}%, {:.1} M rays",
            first.noise * 100.0,
            first.rays as f64 * 1e-6
        );
        group.bench_function(
            format!("bunny {triangles} triangles, ambient occlusion to 1%"),
            |b| b.iter(|| bake::reference_frame(&scene, &env, 0, &settings, &bar).expect("bake")),
        );
        if let Some(run) = meshlab(256, subdivisions, 3) {
            println!(
                "MeshLab (Embree), {} triangles, 256 directions per face: {:.2} s \
                 (median of {}; {:.2}–{:.2})",
                run.faces,
                run.median(),
                run.seconds.len(),
                run.fastest(),
                run.slowest()
            );
        }
    }
    group.finish();
}

/// Each triangle split into four at its edges' midpoints, as MeshLab's
/// midpoint subdivision with no length threshold does.
fn subdivided(mesh: &Mesh) -> Mesh {
    let mut positions = mesh.positions().to_vec();
    let mut midpoints = HashMap::new();
    let mut midpoint = |a: u32, b: u32| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
            positions.len() as u32 - 1
        })
    };
    let triangles = mesh
        .triangles()
        .iter()
        .flat_map(|&[a, b, c]| {
            let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
            [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        })
        .collect();
    Mesh::new(mesh.name(), positions, None, triangles).expect("a subdivided mesh")
}

/// What MeshLab's run printed.
struct MeshLabRun {
    faces: u64,
    rays: u64,
    seconds: Vec<f64>,
}

impl MeshLabRun {
    fn sorted(&self) -> Vec<f64> {
        let mut s = self.seconds.clone();
        s.sort_by(f64::total_cmp);
        s
    }
    fn median(&self) -> f64 {
        let s = self.sorted();
        s[s.len() / 2]
    }
    fn fastest(&self) -> f64 {
        self.sorted()[0]
    }
    fn slowest(&self) -> f64 {
        *self.sorted().last().expect("runs")
    }
}

/// Runs MeshLab's ambient occlusion on the shipped 35k bunny subdivided
/// `subdivisions` times, `repeats` times; `None` where `SOFT_SHADOWS_SKIP`
/// lists `meshlab`. Without Python or PyMeshLab it stops the bench, naming
/// what to install.
fn meshlab(rays: u32, subdivisions: u32, repeats: u32) -> Option<MeshLabRun> {
    let skip = std::env::var("SOFT_SHADOWS_SKIP").unwrap_or_default();
    if skip
        .split(',')
        .any(|s| matches!(s.trim(), "meshlab" | "all"))
    {
        println!("MeshLab side-by-side skipped (SOFT_SHADOWS_SKIP lists meshlab)");
        return None;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let script = root.join("meshlab/ambient_occlusion.py");
    let mesh = root.join("../assets/meshes/bunny_stanford_bun_zipper.glb");
    let output = Command::new("python3")
        .arg(&script)
        .arg(&mesh)
        .args([rays, subdivisions, repeats].map(|n| n.to_string()))
        .output()
        .expect("python3 runs (install Python 3, or set SOFT_SHADOWS_SKIP=meshlab)");
    assert!(
        output.status.success(),
        "{} failed (pip install pymeshlab, or set SOFT_SHADOWS_SKIP=meshlab): {}",
        script.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    let run: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("the script prints one JSON object");
    let count = |name: &str| run[name].as_u64().expect(name);
    Some(MeshLabRun {
        faces: count("faces"),
        rays: count("rays"),
        seconds: run["seconds"]
            .as_array()
            .expect("seconds")
            .iter()
            .map(|s| s.as_f64().expect("seconds"))
            .collect(),
    })
}

criterion_group!(benches, shadow_rays, ambient_occlusion_rays, bakes);
criterion_main!(benches);
