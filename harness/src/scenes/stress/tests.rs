use std::f32::consts::PI;

use super::*;

fn bounds(scene: &Scene) -> shadow_core::Aabb {
    scene.frame_geometry(0).unwrap().bounds()
}

#[test]
fn every_stress_scene_builds_small_with_its_frames() {
    let all = stress_scenes().unwrap();
    assert_eq!(all.len(), STRESS_SCENES.len());
    for stress in &all {
        let scene = &stress.scene;
        assert_eq!(scene.name(), stress.name);
        assert!(!stress.breaks.is_empty());
        let frames = if stress.name == "interpenetrating" {
            4
        } else {
            1
        };
        assert_eq!(scene.frames().len(), frames, "{}", stress.name);
        assert!(!scene.deforms(), "{}", stress.name);
        let vertices = scene.vertex_count();
        let small = if stress.name == "coarse" {
            20..=40
        } else {
            200..=3000
        };
        assert!(small.contains(&vertices), "{}: {vertices}", stress.name);
        for f in 0..frames {
            let geometry = scene.frame_geometry(f).unwrap();
            assert!(geometry.bounds().diagonal().is_finite());
        }
    }
    let msg = stress_scene("nonesuch").unwrap_err().to_string();
    assert!(msg.contains("thin-sheets"), "{msg}");
}

#[test]
fn scales_are_as_stated() {
    for (name, size) in [
        ("tiny-scale", TINY_SIZE),
        ("huge-scale", HUGE_SIZE),
        ("near-contact", 2.0),
        ("sun-only", 1.0),
    ] {
        let b = bounds(&stress_scene(name).unwrap().scene);
        let extent = b.extent().max_element();
        approx::assert_relative_eq!(extent, size, max_relative = 1e-5);
        assert_eq!(b.min.y, 0.0, "{name} rests on y = 0");
    }
    // The tiny and huge scenes are the same scene 1e7 apart.
    let tiny = stress_scene("tiny-scale").unwrap().scene;
    let huge = stress_scene("huge-scale").unwrap().scene;
    assert_eq!(tiny.vertex_count(), huge.vertex_count());
    for (t, h) in tiny.objects().iter().zip(huge.objects()) {
        for (pt, ph) in t.mesh.positions().iter().zip(h.mesh.positions()) {
            approx::assert_relative_eq!(*pt * 1e7, *ph, max_relative = 1e-4, epsilon = 1e-3);
        }
    }
}

#[test]
fn thin_sheets_are_1_and_2_mm_apart() {
    let scene = stress_scene("thin-sheets").unwrap().scene;
    let thickness = |o: usize| scene.objects()[o].mesh.bounds().extent().y;
    approx::assert_relative_eq!(thickness(1), 1e-3, max_relative = 1e-3);
    approx::assert_relative_eq!(thickness(2), 2e-3, max_relative = 1e-3);
    assert!(scene.objects()[1].mesh.is_closed());
    let faces = &scene.objects()[2].mesh;
    assert!(!faces.is_closed());
    // The lower face faces down, the upper up.
    for (p, n) in faces.positions().iter().zip(faces.normals()) {
        let up = if p.y > 0.251 { 1.0 } else { -1.0 };
        assert!(n.abs_diff_eq(Vec3::Y * up, 1e-6), "{p}: {n}");
    }
}

#[test]
fn the_horizon_wall_stays_within_degrees_of_the_floor_plane() {
    let scene = stress_scene("horizon-blocker").unwrap().scene;
    let (floor, wall) = (&scene.objects()[0].mesh, &scene.objects()[1].mesh);
    assert!(wall.is_closed());
    let wall_bounds = wall.bounds();
    let elevations: Vec<f32> = floor
        .positions()
        .iter()
        .map(|p| {
            let inside = (wall_bounds.min.x..=wall_bounds.max.x).contains(&p.x);
            assert!(!inside, "floor vertex {p} is under the wall");
            let distance = (wall_bounds.min.x - p.x).max(p.x - wall_bounds.max.x);
            (wall_bounds.max.y / distance).atan().to_degrees()
        })
        .collect();
    let lowest = elevations.iter().copied().fold(f32::INFINITY, f32::min);
    let low = elevations.iter().filter(|e| **e < 5.0).count();
    assert!(lowest < 1.0, "{lowest}°");
    assert!(
        low * 4 > elevations.len() * 3,
        "{low} of {}",
        elevations.len()
    );
    // Most of the light a floor vertex receives comes from the band.
    let env = stress_scene("horizon-blocker").unwrap().environment;
    let (mut band, mut all) = (0.0, 0.0);
    for row in 0..env.height() {
        let d = env.direction(row, 0);
        let irradiance = env.texel(row, 0).x * d.y.max(0.0) * env.solid_angle(row);
        all += irradiance;
        if d.y < 0.08 {
            band += irradiance;
        }
    }
    assert!(band > 0.5 * all, "{band} of {all}");
}

#[test]
fn the_interpenetrating_objects_overlap_in_every_frame() {
    let scene = stress_scene("interpenetrating").unwrap().scene;
    assert!(scene.moves());
    let mut centres = Vec::new();
    for f in 0..scene.frames().len() {
        let g = scene.frame_geometry(f).unwrap();
        let to_box = g.objects[0].transform.unwrap().inverse();
        let centre = g.objects[1].bounds().center();
        // Sphere vertices inside the box, and box vertices inside the sphere.
        let inside_box = g.objects[1]
            .positions()
            .iter()
            .map(|p| to_box.transform_point3(*p))
            .filter(|p| p.abs().max_element() < 0.25)
            .count();
        let inside_sphere = g.objects[0]
            .positions()
            .iter()
            .filter(|p| p.distance(centre) < 0.3)
            .count();
        assert!(inside_box > 0 && inside_sphere > 0, "frame {f}");
        centres.push(centre.x);
    }
    assert!(centres.windows(2).all(|w| w[1] > w[0]), "{centres:?}");
}

#[test]
fn near_contact_gaps_are_as_stated() {
    let scene = stress_scene("near-contact").unwrap().scene;
    let floor = &scene.objects()[0].mesh;
    for (o, gap) in [(1, CONTACT_RADIUS * 1e-3), (2, 0.0)] {
        let sphere = &scene.objects()[o].mesh;
        let lowest = sphere
            .positions()
            .iter()
            .min_by(|a, b| a.y.total_cmp(&b.y))
            .unwrap();
        approx::assert_relative_eq!(lowest.y, gap, epsilon = 1e-7);
        // A floor vertex lies right under the sphere's lowest point.
        assert!(
            floor
                .positions()
                .iter()
                .any(|p| (p.x - lowest.x).abs() < 1e-6 && p.z.abs() < 1e-6),
            "{lowest}"
        );
    }
}

#[test]
fn slivers_are_needles_and_the_degenerate_triangles_were_dropped() {
    let scene = stress_scene("slivers").unwrap().scene;
    let fan = &scene.objects()[1].mesh;
    assert_eq!(fan.triangle_count(), SLIVER_NEEDLES);
    assert_eq!(fan.report().degenerate_triangles, SLIVER_DEGENERATE);
    for t in fan.triangles() {
        let aspect = aspect_ratio(t.map(|i| fan.positions()[i as usize]));
        assert!(aspect >= 1e3, "{t:?}: aspect {aspect}");
    }
    assert!(fan.normals().iter().all(|n| n.abs_diff_eq(Vec3::Y, 1e-5)));
    let equilateral = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 0.0, -0.75f32.sqrt())];
    approx::assert_relative_eq!(
        aspect_ratio(equilateral),
        2.0 / 3f32.sqrt(),
        max_relative = 1e-5
    );
}

#[test]
fn coarse_is_two_floor_triangles_and_a_twelve_triangle_box() {
    let scene = stress_scene("coarse").unwrap().scene;
    let counts: Vec<usize> = scene
        .objects()
        .iter()
        .map(|o| o.mesh.triangle_count())
        .collect();
    assert_eq!(counts, [2, 12]);
}

#[test]
fn the_sun_holds_the_light_of_the_sun_only_sky() {
    let env = stress_scene("sun-only").unwrap().environment;
    let total = luminance(env.integral());
    assert!(total > 1.0, "{total}");
    let omega = solid_angle_holding(&env, 0.95);
    assert!(omega <= 0.01 * 4.0 * PI, "{omega} sr");
    // The sun is a few texels, toward its stated direction.
    let lit: Vec<(usize, usize)> = (0..env.height())
        .flat_map(|r| (0..env.width()).map(move |c| (r, c)))
        .filter(|&(r, c)| env.texel(r, c) != Vec3::ZERO)
        .collect();
    assert!((1..=32).contains(&lit.len()), "{} texels", lit.len());
    for (r, c) in lit {
        assert!(env.direction(r, c).dot(sun_direction()) > 0.99);
    }
    // A uniform sky spreads its light: 95% needs 95% of the sphere.
    let uniform = Environment::uniform(Vec3::ONE);
    assert!(solid_angle_holding(&uniform, 0.95) > 0.9 * 4.0 * PI);
}
