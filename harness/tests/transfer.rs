//! The transfer reference against cases whose answer is known, the transfer
//! scores on hand-made vectors, and hemi-raster against the reference.

use shadow_core::shapes;
use std::{f32::consts::PI, sync::Arc};

use approx::assert_relative_eq;
use glam::Vec3;
use harness::{
    accuracy::{self, AccuracyReport, TransferScore},
    methods::SharedGpu,
    reference::{
        self, ReferenceInfo, ReferenceSettings,
        transfer::{TransferSettings, scene_transfer_references, transfer_reference},
    },
    report::MachineInfo,
};
use hemi_raster::HemiRaster;
use indicatif::ProgressBar;
use shadow_core::{
    Brdf, Camera, Environment, Mesh, Object, Scene, ShadowMethod,
    sh::{ShOrder, Zonal},
};

/// Y_0^0 = 1/(2√π).
const Y00: f32 = 0.282_094_8;

/// The two-sided 10⁻⁴ quantile of Student's t with 31 degrees of freedom
/// (32 replicates): a coefficient further than this many standard errors
/// from its expectation is one chance in 10⁴.
const T31: f32 = 4.46;

fn replicated(size: u32) -> TransferSettings {
    TransferSettings {
        replicate_size: size,
        replicates: 32,
        seed: 42,
        ..TransferSettings::CONVERGED
    }
}

fn scene_of(meshes: Vec<Mesh>) -> Scene {
    let camera = Camera::new(Vec3::new(3.0, 2.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 32, 24).unwrap();
    let objects = meshes
        .into_iter()
        .map(|m| Object {
            mesh: Arc::new(m),
            material: Brdf::lambert(Vec3::splat(0.8)).unwrap(),
        })
        .collect();
    Scene::still("test", objects, camera).unwrap()
}

/// A 2 m floor of 8×8 cells at y = 0 and, facing down at height `H`, the
/// square [−S, S]² (in x and z).
const H: f32 = 0.3;
const S: f32 = 0.3;

fn floor_and_square() -> Scene {
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 8).unwrap();
    let square = shapes::grid(
        "square",
        Vec3::new(-S, H, -S),
        Vec3::X * 2.0 * S,
        Vec3::Z * 2.0 * S,
        1,
        1,
    )
    .unwrap();
    scene_of(vec![floor, square])
}

/// The form factor from a point of a plane to a rectangle parallel to it at
/// distance h, with the point's normal through one corner and sides a and b
/// (Howell's catalogue, "plane element parallel to a rectangle, normal through
/// a corner"): F = 1/(2π) [X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²))],
/// X = a/h, Y = b/h. It is odd in a and in b, so signed sides give any
/// rectangle by inclusion–exclusion over its four corners.
fn corner_form_factor(a: f32, b: f32, h: f32) -> f32 {
    let (x, y) = (a / h, b / h);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI)
}

/// The form factor from `p` (facing up or down) to the horizontal rectangle
/// [x0, x1] × [z0, z1] at distance `h` above or below it.
fn rectangle_form_factor(p: Vec3, h: f32, [x0, x1]: [f32; 2], [z0, z1]: [f32; 2]) -> f32 {
    let f = |x: f32, z: f32| corner_form_factor(x - p.x, z - p.z, h);
    f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0)
}

#[test]
fn an_unoccluded_vertex_gets_the_clamped_cosine() {
    // A tilted quad: nothing above any of its vertices, every band non-zero.
    let quad = shapes::grid(
        "quad",
        Vec3::ZERO,
        Vec3::new(1.0, 0.4, 0.0),
        Vec3::new(0.2, 0.3, -1.0),
        1,
        1,
    )
    .unwrap();
    let normals = quad.normals().to_vec();
    let scene = scene_of(vec![quad]);
    let order = ShOrder::new(5).unwrap();
    let r = transfer_reference(
        &scene.frame_geometry(0).unwrap(),
        &replicated(64),
        &ProgressBar::hidden(),
    )
    .unwrap();
    assert_eq!(r.vertex_count(), 4);
    assert_eq!(r.rays, 4 * 32 * 64);
    let lambert = Zonal::lambert(order);
    let mut exact = [0.0; 25];
    for (v, n) in normals.iter().enumerate() {
        lambert.project_along(*n, &mut exact);
        let se = &r.std_error()[v * 25..(v + 1) * 25];
        for (k, ((&x, &e), &s)) in r.transfer(v).iter().zip(&exact).zip(se).enumerate() {
            assert!(
                (x - e).abs() <= T31 * s + 1e-5,
                "vertex {v} coefficient {k}: {x} vs {e} (SE {s})"
            );
        }
        // Band 0 is π·Y_0 whatever the direction: exact. The other bands
        // carry error bars, small ones: stratified points integrate the
        // smooth basis nearly exactly.
        assert_relative_eq!(r.transfer(v)[0], PI * Y00, max_relative = 1e-5);
        assert!(se[1..].iter().all(|&s| s > 0.0 && s < 0.02), "{se:?}");
    }
    assert!(r.noise() > 0.0 && r.noise() < 0.02, "{}", r.noise());
}

/// T_0 = Y_0 ∫ V max(0, n·ω) dω = Y_0 π (1 − F), F the form factor to the
/// blockers: from the floor up to the square, and from the square's corners
/// down to the floor (all they see of the sky is a grazing sliver beyond the
/// floor's edge).
#[test]
fn a_floor_under_a_square_matches_the_form_factor() {
    let scene = floor_and_square();
    let frame = scene.frame_geometry(0).unwrap();
    let r = transfer_reference(&frame, &replicated(256), &ProgressBar::hidden()).unwrap();
    let receivers = [
        (&frame.objects[0], [-S, S], 0),
        (&frame.objects[1], [-1.0, 1.0], 81),
    ];
    for (object, extent, first) in receivers {
        for (i, p) in object.positions().iter().enumerate() {
            let v = first + i;
            // Seen from the ray origins, the vertex lifted along its normal
            // (toward the other plane, H away).
            let lift = object.lifts()[i];
            let expected = Y00 * PI * (1.0 - rectangle_form_factor(*p, H - lift, extent, extent));
            let (x, se) = (r.transfer(v)[0], r.std_error()[v * 25]);
            // Slack: the origins back up by half a lift along each ray,
            // which moves the blocker by that much relative to its distance.
            assert!(
                (x - expected).abs() <= T31 * se + 2e-4,
                "vertex {v} at {p}: T_0 {x} vs {expected} (SE {se})"
            );
        }
    }
    // The floor's centre (vertex 40) under the square: four corners of
    // X = Y = 1, F = (4/π)(1/√2) atan(1/√2), from the vertex itself; its
    // receiver sits a lift (1% of its 0.35 m edges) closer.
    let centre = r.transfer(40)[0] / (Y00 * PI);
    let lifted = rectangle_form_factor(
        Vec3::ZERO,
        H - frame.objects[0].lifts()[40],
        [-S, S],
        [-S, S],
    );
    assert_relative_eq!(
        rectangle_form_factor(Vec3::ZERO, H, [-S, S], [-S, S]),
        0.5541,
        epsilon = 1e-4
    );
    assert_relative_eq!(1.0 - centre, lifted, epsilon = 5e-3);
}

#[test]
fn the_same_seed_gives_the_same_reference() {
    let scene = floor_and_square();
    let frame = scene.frame_geometry(0).unwrap();
    let settings = replicated(16);
    let a = transfer_reference(&frame, &settings, &ProgressBar::hidden()).unwrap();
    let b = transfer_reference(&frame, &settings, &ProgressBar::hidden()).unwrap();
    assert_eq!(a.mean(), b.mean());
    assert_eq!(a.std_error(), b.std_error());
    let c = transfer_reference(
        &frame,
        &TransferSettings {
            seed: 43,
            ..settings
        },
        &ProgressBar::hidden(),
    )
    .unwrap();
    assert_ne!(a.mean(), c.mean());
    // Different seeds differ by about their noise, not more.
    let mut score = TransferScore::default();
    score.add(c.mean(), a.mean(), None, 25).unwrap();
    assert!(
        score.summary().global < 5.0 * a.noise(),
        "{:?} vs noise {}",
        score.summary(),
        a.noise()
    );
    let all = scene_transfer_references(&scene, &settings, &ProgressBar::hidden()).unwrap();
    assert_eq!(all.len(), 1);
    assert_eq!(all[0].mean(), a.mean());
}

#[test]
fn settings_without_a_standard_error_are_rejected() {
    let scene = floor_and_square();
    let frame = scene.frame_geometry(0).unwrap();
    for (replicates, size) in [(1, 64), (16, 0)] {
        let settings = TransferSettings {
            replicates,
            replicate_size: size,
            ..TransferSettings::CONVERGED
        };
        let err = transfer_reference(&frame, &settings, &ProgressBar::hidden()).unwrap_err();
        assert!(err.to_string().contains("replicates"), "{err}");
    }
}

#[test]
fn transfer_scores_on_hand_made_vectors() {
    // Two vertices of order 2 (4 coefficients).
    let reference = [3.0, 4.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let values = [3.0, 4.0, 0.5, 0.0, 0.0, 0.0, 1.1, 0.0];
    let se = [0.0, 0.0, 0.03, 0.04, 0.0, 0.0, 0.0, 0.0];
    let mut score = TransferScore::default();
    score.add(&values, &reference, Some(&se), 4).unwrap();
    let e = score.summary();
    // Per vertex 0.5/5 and 0.1/1.
    assert_relative_eq!(e.per_vertex, 0.1, epsilon = 1e-6);
    // Global sqrt((0.25 + 0.01) / 26).
    assert_relative_eq!(e.global, (0.26f32 / 26.0).sqrt(), epsilon = 1e-6);
    assert_relative_eq!(e.noise_per_vertex, 0.05 / 5.0 / 2.0, epsilon = 1e-6);
    assert_relative_eq!(e.noise_global, (0.0025f32 / 26.0).sqrt(), epsilon = 1e-6);
    assert_eq!(e.count, 2);

    // A second frame: the paper's measure averages over vertices and frames,
    // the global one pools the sums.
    score
        .add(&[2.0, 0.0, 0.0, 0.0], &[1.0, 0.0, 0.0, 0.0], None, 4)
        .unwrap();
    let e = score.summary();
    assert_relative_eq!(e.per_vertex, (0.1 + 0.1 + 1.0) / 3.0, epsilon = 1e-6);
    assert_relative_eq!(e.global, (1.26f32 / 27.0).sqrt(), epsilon = 1e-6);
    assert_eq!(e.count, 3);

    // A vertex that sees no sky has no relative error: it is counted as dark
    // and left out of the per-vertex mean, but not out of the global one.
    let mut dark = TransferScore::default();
    dark.add(&[0.0, 0.02, 1.0, 0.0], &[0.0, 0.0, 1.0, 0.0], None, 1)
        .unwrap();
    // So is one below 5% of an unoccluded vertex's |T| = π·Y_0 ≈ 0.886 in
    // order 1; one just above counts.
    dark.add(&[0.0], &[0.044], None, 1).unwrap();
    dark.add(&[0.0], &[0.045], None, 1).unwrap();
    let e = dark.summary();
    assert_eq!((e.count, e.dark), (6, 4));
    // Per vertex: 0 (T_ref = 1, exact) and 0.045/0.045, over 2.
    assert_relative_eq!(e.per_vertex, 0.5, epsilon = 1e-6);
    let global = ((0.02f32.powi(2) + 0.044f32.powi(2) + 0.045f32.powi(2))
        / (1.0 + 0.044f32.powi(2) + 0.045f32.powi(2)))
    .sqrt();
    assert_relative_eq!(e.global, global, epsilon = 1e-5);

    // Identical vectors score zero; shapes that do not match are errors.
    let mut same = TransferScore::default();
    same.add(&reference, &reference, None, 4).unwrap();
    assert_eq!(
        (same.summary().per_vertex, same.summary().global),
        (0.0, 0.0)
    );
    assert!(same.add(&values[..4], &reference, None, 4).is_err());
    assert!(same.add(&values, &reference, None, 3).is_err());
    assert!(same.add(&values[..6], &reference[..6], None, 2).is_err());
    assert!(same.add(&values, &reference, Some(&se[..4]), 4).is_err());
    assert!(same.add(&values, &reference, None, 0).is_err());
}

/// The transfer vectors of every vertex after `update`.
fn hemi_transfer(method: &HemiRaster, scene: &Scene) -> Vec<f32> {
    scene
        .objects()
        .iter()
        .enumerate()
        .flat_map(|(o, object)| {
            (0..object.mesh.vertex_count())
                .flat_map(move |v| method.transfer(o, v).unwrap().to_vec())
        })
        .collect()
}

/// On the floor the paper's configuration is within a few percent of the
/// reference. (The square's corners, which see only a grazing sliver of sky
/// below the floor's far edge, are off by far more: the mask's outermost
/// pixel ring decides them.)
#[test]
fn hemi_raster_agrees_with_the_reference() {
    let scene = floor_and_square();
    let frame = scene.frame_geometry(0).unwrap();
    let r = transfer_reference(&frame, &replicated(256), &ProgressBar::hidden()).unwrap();
    let mut method = HemiRaster::default();
    method.prepare(&scene).unwrap();
    method.update(&frame, scene.camera()).unwrap();
    let floor = 81 * 25;
    let mut score = TransferScore::default();
    score
        .add(
            &hemi_transfer(&method, &scene)[..floor],
            &r.mean()[..floor],
            Some(&r.std_error()[..floor]),
            25,
        )
        .unwrap();
    let e = score.summary();
    assert!(
        e.noise_global < 0.005 && e.noise_per_vertex < 0.005,
        "{e:?}"
    );
    assert!(e.global < 0.03 && e.per_vertex < 0.03, "{e:?}");
}

#[test]
fn the_accuracy_table_of_a_small_scene() {
    let scene = floor_and_square();
    let env = Environment::uniform(Vec3::ONE).renamed("uniform");
    let frame = scene.frame_geometry(0).unwrap();
    let radiance = reference::vertex_reference(
        &scene,
        &frame,
        &env,
        scene.camera().eye,
        &ReferenceSettings::replicated(64, 16, 7),
        &ProgressBar::hidden(),
    )
    .unwrap();
    let info = ReferenceInfo {
        scene: scene.name().into(),
        environment: env.name().into(),
        frames: 1,
        vertices: scene.vertex_count(),
        noise: radiance.noise,
        rays: radiance.rays,
        seconds: radiance.seconds,
        cached: false,
        image: None,
    };
    let plan = accuracy::Plan {
        transfer: replicated(64),
        variants: accuracy::variants()
            .into_iter()
            .filter(|v| ["hemi-raster", "hemi-raster:direct"].contains(&v.spec.name()))
            .collect(),
        repeats: 1,
    };
    let radiance = vec![radiance];
    let gpu = SharedGpu::new();
    let result = accuracy::evaluate(
        &scene,
        &env,
        &radiance,
        info.clone(),
        &plan,
        &gpu,
        &ProgressBar::hidden(),
    )
    .unwrap();
    let names: Vec<&str> = result.rows.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "unshadowed",
            "reference transfer",
            "hemi-raster",
            "hemi-raster:direct"
        ]
    );
    let [unshadowed, floor, default, direct] = &result.rows[..] else {
        unreachable!()
    };
    let (u, d) = (unshadowed.transfer.unwrap(), default.transfer.unwrap());
    assert!(u.global > 0.1 && d.global < 0.03, "{u:?} {d:?}");
    assert!(floor.transfer.is_none() && direct.transfer.is_none());
    // A uniform sky is band 0 alone: the reference transfer shades it
    // exactly, up to the two references' noise.
    assert!(floor.radiance.relative_l2 < 0.01, "{:?}", floor.radiance);
    assert!(
        unshadowed.radiance.relative_l2 > 0.1,
        "{:?}",
        unshadowed.radiance
    );
    assert!(
        default.radiance.relative_l2 < 0.03,
        "{:?}",
        default.radiance
    );
    assert!(direct.radiance.relative_l2 < 0.03, "{:?}", direct.radiance);
    assert!(default.frame_ms.is_some() && floor.frame_ms.is_none());
    assert_eq!(result.transfer_reference.rays, 85 * 32 * 64);

    let report = AccuracyReport {
        machine: MachineInfo::detect(None),
        repeats: 1,
        scenes: vec![result],
    };
    let dir = tempfile::tempdir().unwrap();
    report.write(dir.path()).unwrap();
    let md = std::fs::read_to_string(dir.path().join("accuracy.md")).unwrap();
    assert!(
        md.contains("| hemi-raster |") && md.contains("| reference transfer |"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("accuracy.json")).unwrap()).unwrap();
    assert_eq!(json["scenes"][0]["rows"].as_array().unwrap().len(), 4);

    // One radiance reference per frame, or a clear error.
    let err = accuracy::evaluate(&scene, &env, &[], info, &plan, &gpu, &ProgressBar::hidden())
        .unwrap_err();
    assert!(err.to_string().contains("radiance references"), "{err}");
}
