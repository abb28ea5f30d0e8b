use super::*;
use crate::{Brdf, Mesh, Object, Scene};
use std::sync::Arc;

fn camera(eye: Vec3, target: Vec3, width: u32, height: u32) -> Camera {
    Camera::new(eye, target, Vec3::Y, 50f32.to_radians(), width, height).unwrap()
}

/// A frame of meshes given as (positions, triangles), at rest.
fn frame(meshes: Vec<(Vec<Vec3>, Vec<[u32; 3]>)>) -> FrameGeometry {
    let objects = meshes
        .into_iter()
        .enumerate()
        .map(|(i, (positions, triangles))| Object {
            mesh: Arc::new(Mesh::new(format!("m{i}"), positions, None, triangles).unwrap()),
            material: Brdf::lambert(Vec3::ONE).unwrap(),
        })
        .collect();
    let cam = camera(Vec3::Z, Vec3::ZERO, 4, 4);
    Scene::still("test", objects, cam)
        .unwrap()
        .frame_geometry(0)
        .unwrap()
}

fn quad(corners: [Vec3; 4]) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    (corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
}

/// Where the ray from `origin` along `dir` meets triangle `p`: (distance,
/// barycentric weights), double-sided, or None.
fn intersect(origin: Vec3, dir: Vec3, p: [Vec3; 3]) -> Option<(f32, Vec3)> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = origin - p[0];
    let u = s.dot(h) / det;
    let q = s.cross(e1);
    let v = dir.dot(q) / det;
    let t = e2.dot(q) / det;
    Some((t, Vec3::new(1.0 - u - v, u, v)))
}

fn corners(frame: &FrameGeometry, hit: &SurfaceHit) -> [Vec3; 3] {
    let mesh = &frame.objects[hit.object as usize];
    mesh.triangles()[hit.triangle as usize].map(|v| mesh.positions()[v as usize])
}

#[test]
fn full_screen_quad_interpolates_affine_colours_exactly() {
    // A slanted plane larger than the view: every pixel is covered, and a
    // colour that is an affine function of position must come out as that
    // function at the point the pixel's ray hits (perspective-correct).
    let corners = [
        Vec3::new(-60.0, -60.0, -5.0),
        Vec3::new(60.0, -60.0, -45.0),
        Vec3::new(60.0, 60.0, -45.0),
        Vec3::new(-60.0, 60.0, -5.0),
    ];
    let f = frame(vec![quad(corners)]);
    let colour = |p: Vec3| Vec3::new(0.1 * p.x + 3.0, 0.05 * p.y + 2.0, -0.1 * p.z);
    let colours = vec![
        f.objects[0]
            .positions()
            .iter()
            .map(|&p| colour(p))
            .collect(),
    ];
    let cam = camera(Vec3::ZERO, Vec3::new(0.2, 0.1, -1.0), 40, 30);
    let image = render_vertex_colors(&cam, &f, &colours).unwrap();
    assert!(image.covered.iter().all(|&c| c));
    for y in 0..cam.height {
        for x in 0..cam.width {
            let dir = cam.ray_direction(x, y);
            let (t, _) = [
                [corners[0], corners[1], corners[2]],
                [corners[0], corners[2], corners[3]],
            ]
            .iter()
            .filter_map(|&tri| intersect(cam.eye, dir, tri))
            .find(|(_, b)| b.min_element() >= -1e-4)
            .unwrap();
            let expected = colour(cam.eye + dir * t);
            let got = image.pixels[(y * cam.width + x) as usize];
            assert!(
                (got - expected).abs().max_element() < 2e-4 * expected.abs().max_element(),
                "({x}, {y}): {got} vs {expected}"
            );
        }
    }
    // A vertex-coloured corner trend: red toward the left, green toward the top.
    let trend = vec![vec![Vec3::X, Vec3::ZERO, Vec3::Y, Vec3::X + Vec3::Y]];
    let image = render_vertex_colors(&cam, &f, &trend).unwrap();
    let at = |x: u32, y: u32| image.pixels[(y * cam.width + x) as usize];
    assert!(at(0, 15).x > at(39, 15).x && at(20, 0).y > at(20, 29).y);
}

#[test]
fn nearer_triangle_wins_in_either_order() {
    let near = (
        vec![
            Vec3::new(-1.0, -1.0, -2.0),
            Vec3::new(1.0, -1.0, -2.0),
            Vec3::new(0.0, 1.0, -2.0),
        ],
        vec![[0, 1, 2]],
    );
    let far = (
        vec![
            Vec3::new(-3.0, -3.0, -4.0),
            Vec3::new(3.0, -3.0, -4.0),
            Vec3::new(0.0, 3.0, -4.0),
        ],
        vec![[0, 1, 2]],
    );
    let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 32, 32);
    for (nearer, f) in [
        (0, frame(vec![near.clone(), far.clone()])),
        (1, frame(vec![far, near])),
    ] {
        let hits = visible_surface(&cam, &f).unwrap();
        let centre = hits[16 * 32 + 16].unwrap();
        assert_eq!(centre.object, nearer);
        assert!((centre.position.z + 2.0).abs() < 1e-5);
        // Both objects are visible somewhere: the far one around the near one.
        assert!(hits.iter().flatten().any(|h| h.object != nearer));
    }
}

/// Pixels covered by each part of a split polygon: no pixel twice, and
/// every pixel whose centre lies clearly inside the polygon once.
fn assert_watertight(cam: &Camera, f: &FrameGeometry, inside: impl Fn(f64, f64) -> Option<bool>) {
    let viewport = Viewport::new(cam, f).unwrap();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut count = vec![0u32; w * h];
    for object in &f.objects {
        for (t, tri) in object.triangles().iter().enumerate() {
            for s in viewport.setup(0, t as u32, tri.map(|v| object.positions()[v as usize])) {
                rasterize(&s, 0..h as i64, |x, y, _, _| {
                    count[y as usize * w + x as usize] += 1
                });
            }
        }
    }
    for y in 0..h {
        for x in 0..w {
            let c = count[y * w + x];
            assert!(c <= 1, "pixel ({x}, {y}) written {c} times");
            if let Some(expected) = inside(x as f64 + 0.5, y as f64 + 0.5) {
                assert_eq!(c == 1, expected, "pixel ({x}, {y})");
            }
        }
    }
}

#[test]
fn shared_edges_are_covered_exactly_once() {
    // Orthogonal view of the plane z = -1 through a 90° field of view:
    // pixel (x, y) of an N×N image is world (2(x)/N − 1, 1 − 2y/N) at its
    // corner, so vertices land exactly on pixel centres and edges run
    // through rows and columns of centres: the ties the fill rule decides.
    let n = 16u32;
    let cam = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90f32.to_radians(), n, n).unwrap();
    let world =
        |px: f32, py: f32| Vec3::new(2.0 * px / n as f32 - 1.0, 1.0 - 2.0 * py / n as f32, -1.0);
    // An axis-aligned quad with corners on pixel centres, split on its diagonal.
    let (a, b) = (2.5, 12.5);
    let square = quad([world(a, b), world(b, b), world(b, a), world(a, a)]);
    let f = frame(vec![square]);
    // Top-left rule: centres on the top and left edges are in, those on
    // the bottom and right edges out.
    let (a64, b64) = (f64::from(a), f64::from(b));
    assert_watertight(&cam, &f, |x, y| {
        Some((a64..b64).contains(&x) && (a64..b64).contains(&y))
    });
    // A fan of eight triangles around a vertex on a pixel centre, with
    // spokes through centres at 0°, 45°, 90°, ...: no centre is lost or
    // counted twice.
    let centre = world(8.5, 8.5);
    let mut positions = vec![centre];
    for k in 0..8 {
        let angle = k as f32 * std::f32::consts::FRAC_PI_4;
        let r = if k % 2 == 0 {
            6.0
        } else {
            6.0 * std::f32::consts::SQRT_2
        };
        positions.push(world(8.5 + r * angle.cos(), 8.5 - r * angle.sin()));
    }
    let triangles = (0..8).map(|k| [0, 1 + k, 1 + (k + 1) % 8]).collect();
    let f = frame(vec![(positions, triangles)]);
    assert_watertight(&cam, &f, |x, y| {
        let (dx, dy) = ((x - 8.5).abs(), (y - 8.5).abs());
        if dx < 5.9 && dy < 5.9 {
            Some(true)
        } else if dx > 6.1 || dy > 6.1 {
            Some(false)
        } else {
            None
        }
    });
    // A rotated, perspective quad split the other way.
    let tilted = quad([
        Vec3::new(-0.7, -0.3, -1.5),
        Vec3::new(0.4, -0.8, -2.5),
        Vec3::new(0.8, 0.6, -2.0),
        Vec3::new(-0.3, 0.7, -1.2),
    ]);
    let f = frame(vec![tilted]);
    assert_watertight(&cam, &f, |_, _| None);
}

#[test]
fn coverage_matches_projected_area_from_both_sides() {
    let p = [
        Vec3::new(-0.9, -0.6, -3.0),
        Vec3::new(1.1, -0.2, -4.0),
        Vec3::new(0.1, 0.9, -2.5),
    ];
    let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 64, 48);
    let view = clip_from_world(&cam, 0.1);
    let pixel = |q: Vec3| {
        let c = view * q.extend(1.0);
        glam::DVec2::new(
            ((c.x / c.w) as f64 * 0.5 + 0.5) * 64.0,
            (0.5 - (c.y / c.w) as f64 * 0.5) * 48.0,
        )
    };
    let s = p.map(pixel);
    let area = ((s[1] - s[0]).perp_dot(s[2] - s[0]) * 0.5).abs();
    let perimeter = (s[1] - s[0]).length() + (s[2] - s[1]).length() + (s[0] - s[2]).length();
    for triangle in [[0, 1, 2], [0, 2, 1]] {
        let f = frame(vec![(p.to_vec(), vec![triangle])]);
        let covered = visible_surface(&cam, &f).unwrap().iter().flatten().count() as f64;
        // Only pixels along the edges can differ from the area, each by
        // less than one.
        assert!(
            (covered - area).abs() < perimeter * 0.75,
            "{covered} pixels for area {area}"
        );
        assert!(covered > 100.0);
    }
}

#[test]
fn pixel_rays_hit_the_rasterized_triangle() {
    // Overlapping triangles at several depths and slants.
    let f = frame(vec![
        (
            vec![
                Vec3::new(-1.5, -1.0, -3.0),
                Vec3::new(1.0, -1.2, -5.0),
                Vec3::new(0.2, 1.4, -2.0),
            ],
            vec![[0, 1, 2]],
        ),
        quad([
            Vec3::new(-2.0, -0.5, -6.0),
            Vec3::new(2.0, -0.5, -2.5),
            Vec3::new(2.0, 0.5, -2.5),
            Vec3::new(-2.0, 0.5, -6.0),
        ]),
    ]);
    let cam = camera(Vec3::new(0.1, 0.2, 0.5), Vec3::new(0.0, 0.0, -3.0), 48, 36);
    let hits = visible_surface(&cam, &f).unwrap();
    let mut checked = 0;
    for y in 0..cam.height {
        for x in 0..cam.width {
            let dir = cam.ray_direction(x, y);
            let nearest = f
                .objects
                .iter()
                .enumerate()
                .flat_map(|(o, mesh)| {
                    mesh.triangles()
                        .iter()
                        .enumerate()
                        .map(move |(t, tri)| (o, t, tri.map(|v| mesh.positions()[v as usize])))
                })
                .filter_map(|(o, t, tri)| intersect(cam.eye, dir, tri).map(|(d, b)| (o, t, d, b)))
                .filter(|&(_, _, d, b)| d > 0.0 && b.min_element() >= 0.0)
                .min_by(|a, b| a.2.total_cmp(&b.2));
            let hit = hits[(y * cam.width + x) as usize];
            match (hit, nearest) {
                (Some(hit), Some((o, t, _, b))) => {
                    // The ray meets the reported triangle where the
                    // rasterizer says (same weights, same point).
                    let (d, weights) = intersect(cam.eye, dir, corners(&f, &hit)).unwrap();
                    assert!(
                        (weights - hit.barycentric).abs().max_element() < 1e-3,
                        "({x}, {y})"
                    );
                    assert!((cam.eye + dir * d - hit.position).length() < 1e-3);
                    // Away from edges, it is also the nearest triangle.
                    if b.min_element() > 1e-3 && weights.min_element() > 1e-3 {
                        assert_eq!(
                            (hit.object, hit.triangle),
                            (o as u32, t as u32),
                            "({x}, {y})"
                        );
                        checked += 1;
                    }
                }
                (None, None) => {}
                (hit, nearest) => {
                    // Only pixels whose ray grazes an edge may disagree.
                    let margin = nearest.map_or(0.0, |n| n.3.min_element());
                    assert!(margin < 1e-3, "({x}, {y}): raster {hit:?}, ray {nearest:?}");
                }
            }
        }
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn triangles_behind_the_camera_are_clipped_not_wrapped() {
    // A floor reaching behind the eye: the lower half of the image sees
    // it, the upper half sees nothing, and the floor point under each
    // covered pixel is where its ray meets the floor.
    let f = frame(vec![quad([
        Vec3::new(-50.0, 0.0, 50.0),
        Vec3::new(50.0, 0.0, 50.0),
        Vec3::new(50.0, 0.0, -50.0),
        Vec3::new(-50.0, 0.0, -50.0),
    ])]);
    let cam = camera(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.9, -1.0), 32, 32);
    let hits = visible_surface(&cam, &f).unwrap();
    for y in 0..cam.height {
        for x in 0..cam.width {
            let dir = cam.ray_direction(x, y);
            let t = -cam.eye.y / dir.y;
            let on_floor = dir.y < 0.0 && (cam.eye + dir * t).abs().max_element() < 50.0;
            let hit = hits[(y * cam.width + x) as usize];
            assert_eq!(hit.is_some(), on_floor, "({x}, {y})");
            if let Some(hit) = hit {
                assert!(
                    (hit.position - (cam.eye + dir * t)).length() < 1e-4 * t,
                    "({x}, {y}): {hit:?}"
                );
                assert!((hit.normal - Vec3::Y).length() < 1e-5);
            }
        }
    }
    // A triangle entirely behind the eye draws nothing.
    let behind = frame(vec![(
        vec![
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ],
        vec![[0, 1, 2]],
    )]);
    let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 8, 8);
    assert!(
        visible_surface(&cam, &behind)
            .unwrap()
            .iter()
            .all(Option::is_none)
    );
}

#[test]
fn bad_inputs_are_errors() {
    let f = frame(vec![(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])]);
    let cam = camera(Vec3::Z, Vec3::ZERO, 8, 8);
    assert!(render_vertex_colors(&cam, &f, &[]).is_err());
    let message = render_vertex_colors(&cam, &f, &[vec![Vec3::ONE; 2]])
        .unwrap_err()
        .to_string();
    assert!(message.contains("3 vertices but 2 colours"), "{message}");
    let huge = camera(Vec3::Z, Vec3::ZERO, MAX_IMAGE_SIZE + 1, 1);
    assert!(visible_surface(&huge, &f).is_err());
}
