//! The baselines through the `ShadowMethod` stages, and the per-pixel and
//! glossy paths of the reference.

use shadow_core::shapes;
use std::sync::Arc;

use glam::{DVec3, Vec3};
use harness::{
    baselines::{RayTrace, Unshadowed},
    reference::{self, ReferenceSettings, Setup, ShadingPoint},
    run::{self, References},
    scenes,
};
use indicatif::ProgressBar;
use shadow_core::{Brdf, Camera, Environment, Error, Object, Scene, ShadowMethod, sh::ShOrder};

fn furnace(rho: f32) -> Scene {
    let sphere = shapes::uv_sphere("sphere", Vec3::ZERO, 1.0, 8, 16).unwrap();
    let camera = Camera::new(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 24, 24).unwrap();
    let object = Object {
        mesh: Arc::new(sphere),
        material: Brdf::lambert(Vec3::splat(rho)).unwrap(),
    };
    Scene::still("furnace", vec![object], camera).unwrap()
}

#[test]
fn pixel_reference_of_the_furnace_is_the_albedo_where_covered() {
    let scene = furnace(0.6);
    let env = Environment::uniform(Vec3::ONE);
    let frame = scene.frame_geometry(0).unwrap();
    // 16 replicates: the standard error of few replicates is itself noisy
    // (Student's t with R − 1 degrees of freedom).
    let settings = ReferenceSettings::replicated(16, 16, 7);
    let reference = reference::pixel_reference(
        &scene,
        &frame,
        &env,
        scene.camera(),
        &settings,
        &ProgressBar::hidden(),
    )
    .unwrap();
    let (image, noise) = (reference.image, reference.noise);
    let covered = image.covered.iter().filter(|c| **c).count();
    // The sphere's silhouette: a disc of angular radius asin(1/4) in a 0.8 rad field.
    assert!(
        covered > 100 && covered < 24 * 24,
        "{covered} pixels covered"
    );
    assert!(image.covered[12 * 24 + 12] && !image.covered[0]);
    let se = image.std_error.as_ref().unwrap();
    for (i, (pixel, se)) in image.pixels.iter().zip(se).enumerate() {
        if image.covered[i] {
            assert!(
                (pixel.x - 0.6).abs() <= 5.0 * se.x + 1e-4,
                "pixel {i}: {pixel} ± {se}"
            );
        } else {
            assert_eq!(*pixel, Vec3::ZERO);
        }
    }
    assert!(noise < 0.05);
}

#[test]
fn glossy_furnace_at_normal_view_reflects_diffuse_plus_specular() {
    // Uniform unit light, nothing occluding, viewed along the normal: the
    // normalized lobe's cosine-weighted integral is exactly ρ_s (brdf.rs).
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 1).unwrap();
    let camera = Camera::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
    let material = Brdf::phong(Vec3::splat(0.3), Vec3::splat(0.5), 20.0).unwrap();
    let scene = Scene::still(
        "floor",
        vec![Object {
            mesh: Arc::new(floor),
            material,
        }],
        camera,
    )
    .unwrap();
    let env = Environment::uniform(Vec3::ONE);
    let setup = Setup::new(&scene.frame_geometry(0).unwrap(), &env).unwrap();
    let point = ShadingPoint {
        position: DVec3::ZERO,
        normal: Vec3::Y,
        lift: shadow_core::frame::LIFT,
        view: Vec3::Y,
        material,
        object: 0,
    };
    let est = reference::estimate(
        &[point],
        &setup.estimator(),
        &ReferenceSettings::replicated(256, 16, 3),
        &ProgressBar::hidden(),
    );
    let (mean, se) = (est.mean[0], est.std_error.unwrap()[0]);
    assert!((mean.x - 0.8).abs() <= 4.0 * se.x + 1e-3, "{mean} ± {se}");
}

#[test]
fn baselines_run_through_every_stage_and_ray_tracing_converges() {
    let scene = scenes::builtin("wall").unwrap();
    let env = Environment::uniform(Vec3::ONE);
    let bar = ProgressBar::hidden();
    let settings = ReferenceSettings::replicated(64, 8, 11);
    let (refs, _) = reference::scene_references(&scene, &env, &settings, None, &bar).unwrap();

    let mut errors = Vec::new();
    for iterations in [4, 64] {
        let mut rt = RayTrace::new(iterations, 5);
        let result = run::run(&mut rt, &scene, &env, References::vertices(&refs), 1).unwrap();
        errors.push(result.mean_error());
    }
    assert!(
        errors[1] < errors[0] / 2.0,
        "more rays did not help: {errors:?}"
    );

    // Unshadowed sees no wall: it overestimates every shadowed vertex.
    let mut unshadowed = Unshadowed::new(ShOrder::new(5).unwrap());
    let result = run::run(
        &mut unshadowed,
        &scene,
        &env,
        References::vertices(&refs),
        1,
    )
    .unwrap();
    assert!(result.mean_error() > 0.1, "{}", result.mean_error());
    let shading = result.last_shading.unwrap();
    for (x, r) in shading.flat().zip(refs[0].radiance.flat()) {
        assert!(x.x >= r.x - 0.05, "unshadowed {x} below reference {r}");
    }
    let image = unshadowed.render(scene.camera()).unwrap();
    assert!(image.covered.iter().any(|c| *c));
}

#[test]
fn stages_out_of_order_are_errors_not_panics() {
    let mut rt = RayTrace::new(4, 1);
    assert!(matches!(rt.shade(Vec3::Z), Err(Error::Stage { .. })));
    let mut unshadowed = Unshadowed::new(ShOrder::new(3).unwrap());
    unshadowed.prepare(&furnace(0.5)).unwrap();
    assert!(matches!(
        unshadowed.shade(Vec3::Z),
        Err(Error::Stage { .. })
    ));
}

#[test]
fn harness_binary_lists_and_rejects_bad_input_clearly() {
    let exe = env!("CARGO_BIN_EXE_harness");
    let out = std::process::Command::new(exe)
        .arg("list")
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("furnace")
            && text.contains("thin-sheets")
            && text.contains("raytrace:16")
            && text.contains("k=N, queries"),
        "{text}"
    );

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.glb");
    std::fs::write(&bad, b"glTF\x02\x00\x00\x00garbage").unwrap();
    let out = std::process::Command::new(exe)
        .args(["reference", "--env", "uniform", "--mesh"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("broken.glb") && !err.contains("panicked"),
        "{err}"
    );
}
