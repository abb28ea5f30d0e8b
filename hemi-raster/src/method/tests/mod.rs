//! The method through its stages: the white furnace, a contact shadow,
//! motion and relighting, and what is refused.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::Affine3A;
use shadow_core::{Frame, Mesh, Object, Pose};

use super::*;
use crate::test_util::{grid, icosphere, projected_solid_angle};

mod contacts;
mod glossy;

pub(super) fn lambert(rho: f32) -> Brdf {
    Brdf::lambert(Vec3::splat(rho)).unwrap()
}

pub(super) fn camera() -> Camera {
    Camera::new(Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 32, 24).unwrap()
}

/// A 0.6 m square at height 0.3 over the centre of a 2 m floor.
fn floor_and_square(frames: Vec<Frame>) -> Scene {
    floor_of(lambert(0.8), frames)
}

/// [`floor_and_square`] with a floor of `material`.
pub(super) fn floor_of(material: Brdf, frames: Vec<Frame>) -> Scene {
    let square = Mesh::new(
        "square",
        vec![
            Vec3::new(-0.3, 0.3, -0.3),
            Vec3::new(-0.3, 0.3, 0.3),
            Vec3::new(0.3, 0.3, 0.3),
            Vec3::new(0.3, 0.3, -0.3),
        ],
        None,
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap();
    let objects = vec![
        Object {
            mesh: Arc::new(grid(0.0, 1.0, 8)),
            material,
        },
        Object {
            mesh: Arc::new(square),
            material: lambert(0.5),
        },
    ];
    Scene::new("floor and square", objects, frames, camera()).unwrap()
}

pub(super) fn still() -> Vec<Frame> {
    vec![Frame {
        time: 0.0,
        poses: vec![Pose::Rigid(Affine3A::IDENTITY); 2],
    }]
}

pub(super) fn run(method: &mut HemiRaster, scene: &Scene, env: &Environment) -> VertexRadiance {
    method.prepare(scene).unwrap();
    method
        .update(&scene.frame_geometry(0).unwrap(), scene.camera())
        .unwrap();
    method.relight(env).unwrap();
    method.shade(scene.camera().eye).unwrap()
}

/// The white furnace on a closed convex mesh: nothing blocks any vertex's
/// upper hemisphere, so every vertex reflects its albedo, for every
/// resolution, integration and culling mode.
#[test]
fn white_furnace_on_a_sphere() {
    let scene = Scene::still(
        "sphere",
        vec![Object {
            mesh: Arc::new(icosphere(Vec3::new(0.0, 1.0, 0.0), 0.5, 2)),
            material: lambert(0.7),
        }],
        camera(),
    )
    .unwrap();
    let furnace = Environment::uniform(Vec3::ONE);
    for (mask_resolution, integration, backface_culling) in [
        (
            MaskResolution::R32,
            Integration::ShBlocks,
            BackfaceCulling::Auto,
        ),
        (
            MaskResolution::R16,
            Integration::ShPixels,
            BackfaceCulling::Off,
        ),
        (
            MaskResolution::R64,
            Integration::Direct,
            BackfaceCulling::On,
        ),
    ] {
        let mut method = HemiRaster::new(Config {
            mask_resolution,
            lut_resolution: 32,
            integration,
            backface_culling,
            ..Config::default()
        });
        let shaded = run(&mut method, &scene, &furnace);
        for (v, l) in shaded.flat().enumerate() {
            assert!(
                (l - Vec3::splat(0.7)).abs().max_element() < 1e-4,
                "{mask_resolution:?} {integration:?}: vertex {v} reflects {l}"
            );
            assert_eq!(method.blocked_fraction(0, v), Some(0.0));
        }
    }
}

#[test]
fn the_square_shadows_the_floor() {
    let scene = floor_and_square(still());
    let mut method = HemiRaster::default();
    let sky = Environment::uniform(Vec3::ONE);
    let shaded = run(&mut method, &scene, &sky);
    let floor = &shaded.radiance[0];
    // Vertex 40 is the floor's centre (row 4 of 9, column 4), 0 a corner.
    let (centre, corner) = (floor[40], floor[0]);
    assert!(centre.x < 0.6 * corner.x, "{centre} vs {corner}");
    // The corner sees the square low on its horizon: nearly unshadowed.
    assert!((corner.x - 0.8).abs() < 0.01, "{corner}");
    // Under the centre the blocked fraction is the square's form factor.
    let square = [
        Vec3::new(-0.3, -0.3, 0.3),
        Vec3::new(0.3, -0.3, 0.3),
        Vec3::new(0.3, 0.3, 0.3),
        Vec3::new(-0.3, 0.3, 0.3),
    ];
    let form_factor = projected_solid_angle(&square) / PI;
    let blocked = method.blocked_fraction(0, 40).unwrap();
    assert!(
        (blocked - form_factor).abs() < 0.01,
        "{blocked} vs {form_factor}"
    );
    // Uniform sky: the SH shading is ρ(1 − blocked) up to the transfer's
    // quadrature of the blocked part.
    assert!(
        (centre.x - 0.8 * (1.0 - form_factor)).abs() < 0.01,
        "{centre}"
    );
    // The square's top sees the open sky; its underside normal is up too
    // (computed from the winding), so it is unshadowed.
    assert!(shaded.radiance[1].iter().all(|l| (l.x - 0.5).abs() < 0.01));
    // The direct integration agrees.
    let mut direct = HemiRaster::new(Config {
        integration: Integration::Direct,
        ..Config::default()
    });
    let d = run(&mut direct, &scene, &sky);
    assert!((d.radiance[0][40].x - centre.x).abs() < 0.01);
    let image = method.render(&camera()).unwrap();
    assert!(image.covered.iter().any(|&c| c));
}

/// `update` recomputes visibility when the square moves away; `relight`
/// changes lighting without touching visibility.
#[test]
fn update_follows_motion_and_relight_keeps_visibility() {
    let away = Affine3A::from_translation(Vec3::new(0.0, 5.0, 0.0));
    let frames = vec![
        still().remove(0),
        Frame {
            time: 1.0,
            poses: vec![Pose::Rigid(Affine3A::IDENTITY), Pose::Rigid(away)],
        },
    ];
    let scene = floor_and_square(frames);
    let mut method = HemiRaster::default();
    let shaded = run(&mut method, &scene, &Environment::uniform(Vec3::ONE));
    let before = shaded.radiance[0][40].x;
    let transfer = method.transfer(0, 40).unwrap().to_vec();
    method
        .relight(&Environment::uniform(Vec3::splat(2.0)))
        .unwrap();
    assert_eq!(method.transfer(0, 40).unwrap(), &transfer[..]);
    let brighter = method.shade(Vec3::ZERO).unwrap().radiance[0][40].x;
    assert!((brighter - 2.0 * before).abs() < 1e-5);
    method
        .update(&scene.frame_geometry(1).unwrap(), scene.camera())
        .unwrap();
    let after = method.shade(Vec3::ZERO).unwrap().radiance[0][40].x;
    assert!(after > 1.5 * before && after > 1.55, "{before} → {after}");
}

#[test]
fn stages_out_of_order_and_bad_input_are_errors() {
    let scene = floor_and_square(still());
    let frame = scene.frame_geometry(0).unwrap();
    let mut method = HemiRaster::default();
    let stage = |e: Error| matches!(e, Error::Stage { .. });
    assert!(stage(method.update(&frame, scene.camera()).unwrap_err()));
    assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
    method.prepare(&scene).unwrap();
    assert!(method.lut_build_time().is_some());
    assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
    assert!(stage(method.render(&camera()).unwrap_err()));
    method.update(&frame, scene.camera()).unwrap();
    assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
    method.relight(&Environment::uniform(Vec3::ONE)).unwrap();
    assert!(method.shade(Vec3::ZERO).is_ok());
    assert!(method.transfer(2, 0).is_none() && method.transfer(1, 4).is_none());
    // A frame of another scene.
    let other = Scene::still(
        "sphere",
        vec![Object {
            mesh: Arc::new(icosphere(Vec3::ZERO, 1.0, 1)),
            material: lambert(0.5),
        }],
        camera(),
    )
    .unwrap();
    let msg = method
        .update(&other.frame_geometry(0).unwrap(), other.camera())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("vertex counts"), "{msg}");
    // A NaN eye.
    method.prepare(&scene).unwrap();
    method.update(&frame, scene.camera()).unwrap();
    let msg = method.shade(Vec3::NAN).unwrap_err().to_string();
    assert!(msg.contains("eye"), "{msg}");
    // A table too large to build.
    let mut huge = HemiRaster::new(Config {
        lut_resolution: 100_000,
        ..Config::default()
    });
    assert!(huge.prepare(&scene).is_err());
}
