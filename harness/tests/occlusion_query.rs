//! occlusion-query against the Monte-Carlo reference: accuracy as the
//! lightsphere grows on the 35k-vertex bunny, a glossy object, and the depth
//! offset and map resolution on scenes built to make acne and light leaks
//! show.

use std::sync::Arc;

use glam::Vec3;
use harness::{
    reference::{self, ReferenceSettings, Setup, ShadingPoint},
    scenes,
    score::{ErrorStats, compare},
};
use indicatif::ProgressBar;
use occlusion_query::{Config, DepthOffset, Level, OcclusionQuery};
use shadow_core::{
    Brdf, Camera, Environment, Object, Scene, ShadowMethod,
    gpu::{GpuContext, test_context},
    shapes,
};

/// The reference at every `stride`-th vertex of frame 0, converged to
/// `noise`: (vertex indices, radiance, standard errors).
fn subset_reference(
    scene: &Scene,
    env: &Environment,
    stride: usize,
    noise: f32,
) -> (Vec<usize>, Vec<Vec3>, Vec<Vec3>) {
    let frame = scene.frame_geometry(0).unwrap();
    let all = reference::vertex_points(scene, &frame, scene.camera().eye);
    let picked: Vec<usize> = (0..all.len()).step_by(stride).collect();
    let points: Vec<ShadingPoint> = picked.iter().map(|&i| all[i]).collect();
    let setup = Setup::new(&frame, env).unwrap();
    let settings = ReferenceSettings {
        target_noise: Some(noise),
        ..ReferenceSettings::CONVERGED
    };
    let est = reference::estimate(
        &points,
        &setup.estimator(),
        &settings,
        &ProgressBar::hidden(),
    );
    (picked, est.mean, est.std_error.unwrap())
}

/// `config`'s radiance at the picked vertices of frame 0 against the reference.
fn score(
    ctx: &Arc<GpuContext>,
    config: Config,
    scene: &Scene,
    env: &Environment,
    reference: &(Vec<usize>, Vec<Vec3>, Vec<Vec3>),
) -> ErrorStats {
    let mut method = OcclusionQuery::new(Arc::clone(ctx), config).unwrap();
    method.prepare(scene).unwrap();
    method.relight(env).unwrap();
    method
        .update(&scene.frame_geometry(0).unwrap(), scene.camera())
        .unwrap();
    let shaded: Vec<Vec3> = method.shade(scene.camera().eye).unwrap().flat().collect();
    let values: Vec<Vec3> = reference.0.iter().map(|&i| shaded[i]).collect();
    compare(&values, &reference.1, Some(&reference.2))
}

fn level(s: u8) -> Level {
    Level::new(s).unwrap()
}

/// Sattler et al.'s 35k-vertex bunny under `forest`: the error falls as the
/// lightsphere grows from 6 to 1026 directions. At 258 it is about 3%: the
/// binary visibility of each direction's cell, which more directions
/// reduce, not the depth maps (every offset and resolution that avoids
/// acne gives 2.9–3.2% there).
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn bunny_error_falls_as_the_lightsphere_grows() {
    let ctx = test_context();
    let scene = scenes::builtin("bunny-35k").unwrap();
    let env = scenes::environment("forest").unwrap();
    let reference = subset_reference(&scene, &env, 31, 0.005);
    let errors: Vec<f32> = (0..=4)
        .map(|s| {
            let config = Config {
                level: level(s),
                ..Config::default()
            };
            score(&ctx, config, &scene, &env, &reference).relative_l2
        })
        .collect();
    println!("relative L2 error at k = 6, 18, 66, 258, 1026: {errors:?}");
    assert!(errors.windows(2).all(|e| e[1] < e[0]), "{errors:?}");
    assert!(errors[3] < 0.035, "k = 258: {}", errors[3]);
}

/// A glossy sphere (normalized Phong, exponent 20) on a Lambert floor under
/// `courtyard`: the error per lightsphere level, which a lobe of that width
/// needs many directions to follow.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn glossy_error_falls_with_more_directions() {
    let ctx = test_context();
    let scene = glossy_scene();
    let env = scenes::environment("courtyard").unwrap();
    let reference = subset_reference(&scene, &env, 3, 0.01);
    let errors: Vec<f32> = (1..=4)
        .map(|s| {
            let config = Config {
                level: level(s),
                ..Config::default()
            };
            score(&ctx, config, &scene, &env, &reference).relative_l2
        })
        .collect();
    println!("glossy relative L2 error at k = 18, 66, 258, 1026: {errors:?}");
    assert!(errors.windows(2).all(|e| e[1] < e[0]), "{errors:?}");
    assert!(errors[3] < 0.1, "{errors:?}");
}

/// A Phong sphere resting on a Lambert floor.
fn glossy_scene() -> Scene {
    let sphere = shapes::uv_sphere("sphere", Vec3::new(0.0, 0.5, 0.0), 0.5, 24, 48).unwrap();
    let floor = shapes::floor("floor", Vec3::ZERO, 1.5, 24).unwrap();
    let camera = Camera::new(
        Vec3::new(1.2, 1.6, 2.4),
        Vec3::new(0.0, 0.4, 0.0),
        Vec3::Y,
        0.8,
        64,
        48,
    )
    .unwrap();
    let objects = vec![
        Object {
            mesh: Arc::new(sphere),
            material: Brdf::phong(Vec3::splat(0.3), Vec3::splat(0.5), 20.0).unwrap(),
        },
        Object {
            mesh: Arc::new(floor),
            material: scenes::white(),
        },
    ];
    Scene::still("glossy", objects, camera).unwrap()
}

/// A ball resting on a floor (contact) and a 1 cm slab floating 2 cm above
/// it (a thin occluder close to a receiver), under a uniform sky.
fn stress_scene() -> Scene {
    let meshes = [
        shapes::floor("floor", Vec3::ZERO, 1.0, 32).unwrap(),
        shapes::uv_sphere("ball", Vec3::new(-0.45, 0.3, 0.0), 0.3, 16, 32).unwrap(),
        shapes::cuboid(
            "slab",
            Vec3::new(0.1, 0.02, -0.3),
            Vec3::new(0.7, 0.03, 0.3),
            false,
        )
        .unwrap(),
    ];
    let camera = Camera::new(Vec3::new(0.0, 2.0, 2.5), Vec3::ZERO, Vec3::Y, 0.8, 64, 48).unwrap();
    let objects = meshes
        .into_iter()
        .map(|mesh| Object {
            mesh: Arc::new(mesh),
            material: scenes::white(),
        })
        .collect();
    Scene::still("stress", objects, camera).unwrap()
}

/// The offsets the sweep tries: (occluder slope, units, its clamp, receiver
/// slope, toward light, along normal), in texels but for the units (steps
/// of the depth buffer).
const OFFSETS: [(f32, u32, f32, f32, f32, f32); 17] = [
    (0.0, 0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 1, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0, 0.0, 0.0, 1.0, 0.0),
    (1.0, 0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0, 1.0, 0.0, 0.0, 0.0),
    (1.0, 0, 2.0, 0.0, 0.0, 0.0),
    (1.0, 0, 4.0, 0.0, 0.0, 0.0),
    (2.0, 0, 2.0, 0.0, 0.0, 0.0),
    (1.0, 0, 2.0, 0.0, 0.0, 0.25),
    (0.0, 0, 0.0, 0.0, 1.0, 0.0),
    (0.0, 0, 0.0, 0.75, 0.0, 0.0),
    (0.0, 0, 0.0, 1.0, 0.0, 0.0),
    (0.0, 0, 0.0, 1.5, 0.0, 0.0),
    (0.0, 0, 0.0, 0.5, 0.0, 0.25),
    (0.0, 0, 0.0, 0.0, 0.0, 0.5),
    (0.0, 0, 0.0, 0.0, 0.0, 0.75),
    (0.0, 0, 0.0, 0.0, 0.0, 1.0),
];

fn offset(
    (occluder_slope, occluder_units, occluder_clamp, receiver_slope, toward_light, along_normal): (
        f32,
        u32,
        f32,
        f32,
        f32,
        f32,
    ),
) -> DepthOffset {
    DepthOffset {
        occluder_slope,
        occluder_units,
        occluder_clamp,
        receiver_slope,
        toward_light,
        along_normal,
    }
}

/// The acne / light-leak trade-off: no offset lets surfaces shadow
/// themselves (acne), the paper's polygon offset lets vertices close under
/// a thin occluder see through it, and too coarse a map blurs contact. The default offset
/// and resolution sit at the smallest error of the sweep.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn default_offset_and_resolution_sit_at_the_error_minimum() {
    let ctx = test_context();
    let scene = stress_scene();
    let env = Environment::uniform(Vec3::ONE);
    let reference = subset_reference(&scene, &env, 1, 0.005);
    // The ball's pole lies pressed on the floor: the reference gives it no
    // light (exactly 0, no standard error), and no depth offset can (the
    // map holds the floor at the pole's own depth). Scored apart.
    let open: Vec<usize> = (0..reference.0.len())
        .filter(|&i| reference.1[i] != Vec3::ZERO || reference.2[i] != Vec3::ZERO)
        .collect();
    let pressed = reference.0.len() - open.len();
    println!("{pressed} vertices pressed on the floor, scored apart");
    assert!(pressed > 0 && pressed < 64, "{pressed} pressed vertices");
    let reference = (
        open.iter().map(|&i| reference.0[i]).collect(),
        open.iter().map(|&i| reference.1[i]).collect(),
        open.iter().map(|&i| reference.2[i]).collect(),
    );
    let defaults = Config::default();
    let mut rows = Vec::new();
    for map in [128, 256, 512] {
        for terms in OFFSETS {
            let config = Config {
                map_resolution: map,
                offset: offset(terms),
                ..defaults
            };
            let error = score(&ctx, config, &scene, &env, &reference);
            rows.push((map, config.offset, error.relative_l2, error.p99));
        }
    }
    println!(
        "map  occluder slope  units  clamp  receiver slope  toward light  along normal  error   p99"
    );
    for (map, o, l2, p99) in &rows {
        println!(
            "{map:>4}  {:>14}  {:>5}  {:>5}  {:>14}  {:>12}  {:>12}  {:>5.2}%  {:>6.1}%",
            o.occluder_slope,
            o.occluder_units,
            o.occluder_clamp,
            o.receiver_slope,
            o.toward_light,
            o.along_normal,
            l2 * 100.0,
            p99 * 100.0
        );
    }
    let at = |map: u32, offset: DepthOffset| {
        let row = rows.iter().find(|r| (r.0, r.1) == (map, offset)).unwrap();
        (row.2, row.3)
    };
    let best = rows.iter().map(|r| r.2).fold(f32::INFINITY, f32::min);
    let (default, default_p99) = at(defaults.map_resolution, defaults.offset);
    assert!(
        default <= best * 1.05,
        "default {:.3}% against the sweep's best {:.3}%",
        default * 100.0,
        best * 100.0
    );
    // Both failure modes show at 512² maps: no offset at all (acne: measured
    // 46% against the default's 1.1%), and the paper's glPolygonOffset(1, 1),
    // whose slope term lets vertices close under the slab see through it
    // (measured 2.6%, p99 1379% against the default's 29%).
    let map = defaults.map_resolution;
    let (none, _) = at(map, DepthOffset::NONE);
    assert!(none > 10.0 * default, "no offset: {none}");
    let (paper, paper_p99) = at(map, DepthOffset::PAPER);
    assert!(paper > 1.5 * default, "the paper's offset: {paper}");
    assert!(
        paper_p99 > 10.0 * default_p99,
        "the paper's offset: p99 {paper_p99}"
    );
}
