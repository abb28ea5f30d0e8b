//! The scenes modelled on Kautz, Lehtinen and Aila 2004, Table 1: `cloth` and
//! `chess` have the paper's size, move over their frames, and stay valid and
//! physically plausible (outward faces, nothing through the floor or board).

use approx::{assert_relative_eq, relative_eq};
use glam::Vec3;
use harness::scenes::{self, ENVIRONMENTS, SCENES};
use shadow_core::{FrameGeometry, Mesh, Scene};

fn scene(name: &str) -> Scene {
    scenes::builtin(name).unwrap()
}

fn frames(scene: &Scene) -> Vec<FrameGeometry> {
    (0..scene.frames().len())
        .map(|i| scene.frame_geometry(i).unwrap())
        .collect()
}

/// Every triangle of the pose has area, and its counter-clockwise face normal
/// agrees with its vertices' normals (so the winding is consistent).
fn assert_faces_valid(mesh: &Mesh, what: &str) {
    for (t, tri) in mesh.triangles().iter().enumerate() {
        let [a, b, c] = tri.map(|i| mesh.positions()[i as usize]);
        let face = (b - a).cross(c - a);
        let longest = (b - a)
            .length_squared()
            .max((c - b).length_squared())
            .max((a - c).length_squared());
        assert!(
            face.length() > 1e-4 * longest,
            "{what}: triangle {t} is (nearly) degenerate"
        );
        let normal = tri
            .iter()
            .map(|&i| mesh.normals()[i as usize])
            .sum::<Vec3>();
        assert!(
            face.dot(normal) > 0.0,
            "{what}: triangle {t} winds against its normals"
        );
    }
}

#[test]
fn both_scenes_are_listed_and_have_the_papers_size() {
    for (name, vertices, triangles) in [("cloth", 1378.0, 2560.0), ("chess", 1897.0, 3704.0)] {
        let spec = SCENES.iter().find(|s| s.name == name).unwrap();
        assert!(ENVIRONMENTS.contains(&spec.environment));
        assert!(!spec.shows.is_empty() && !spec.shows.contains('\n'));
        let s = scene(name);
        let (v, t) = (s.vertex_count() as f32, s.triangle_count() as f32);
        assert!(
            relative_eq!(v, vertices, max_relative = 0.15),
            "{name}: {v} vertices"
        );
        assert!(
            relative_eq!(t, triangles, max_relative = 0.15),
            "{name}: {t} triangles"
        );
        assert_eq!(s.frames().len(), 6, "{name}");
        assert!(s.moves());
    }
}

#[test]
fn every_frame_of_both_scenes_is_valid_geometry() {
    for name in ["cloth", "chess"] {
        let s = scene(name);
        for g in frames(&s) {
            for o in &g.objects {
                assert_faces_valid(o, &format!("{name} frame {} {}", g.frame, o.name()));
            }
        }
    }
}

#[test]
fn cloth_is_an_open_deforming_sheet_above_its_floor() {
    let s = scene("cloth");
    assert!(s.deforms());
    let [cloth, floor] = s.objects() else {
        panic!("cloth scene has {} objects", s.objects().len());
    };
    assert!(!cloth.mesh.is_closed());
    assert!(!floor.mesh.is_closed());
    assert!(floor.mesh.triangle_count() <= 8, "the floor is coarse");
    let rest = cloth.mesh.positions();
    let geometry = frames(&s);
    for g in &geometry {
        let (sheet, floor) = (&g.objects[0], &g.objects[1]);
        let (sheet_bounds, floor_bounds) = (sheet.bounds(), floor.bounds());
        // Well clear of the floor, and over it, so its shadow lands on it.
        assert!(
            sheet_bounds.min.y > floor_bounds.max.y + 0.1,
            "{sheet_bounds:?}"
        );
        assert!(sheet_bounds.min.x > floor_bounds.min.x && sheet_bounds.max.x < floor_bounds.max.x);
        assert!(sheet_bounds.min.z > floor_bounds.min.z && sheet_bounds.max.z < floor_bounds.max.z);
        // A height field over the rest grid: each vertex moves only vertically,
        // so the sheet cannot pass through itself.
        for (p, r) in sheet.positions().iter().zip(rest) {
            assert_relative_eq!(p.x, r.x);
            assert_relative_eq!(p.z, r.z);
        }
        assert!(sheet.normals().iter().all(|n| n.y > 0.0));
        // Real folds: the surface tilts well away from flat somewhere.
        let steepest = sheet.normals().iter().map(|n| n.y).fold(1.0, f32::min);
        assert!(steepest < 0.8, "steepest normal has y = {steepest}");
    }
    for pair in geometry.windows(2) {
        let moved = pair[0].objects[0]
            .positions()
            .iter()
            .zip(pair[1].objects[0].positions())
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f32::max);
        assert!(
            moved > 0.01,
            "frame {}: sheet moved {moved} m",
            pair[1].frame
        );
    }
}

#[test]
fn chess_pieces_are_closed_and_stand_on_the_board_or_hop_over_it() {
    let s = scene("chess");
    assert!(!s.deforms());
    let (board, pieces) = s.objects().split_at(2);
    assert!(board.iter().all(|o| !o.mesh.is_closed()));
    assert_ne!(
        board[0].material.diffuse(),
        board[1].material.diffuse(),
        "light and dark squares"
    );
    assert!((6..=8).contains(&pieces.len()));
    assert!(pieces.iter().all(|o| o.mesh.is_closed()));

    let geometry = frames(&s);
    let top = geometry[0].objects[0].bounds().max.y;
    let board_bounds = geometry[0].objects[0]
        .bounds()
        .union(geometry[0].objects[1].bounds());
    let last = geometry.len() - 1;
    for g in &geometry {
        assert_relative_eq!(g.objects[0].bounds().max.y, top);
        assert_relative_eq!(g.objects[1].bounds().min.y, top);
        let posed = &g.objects[2..];
        for (i, p) in posed.iter().enumerate() {
            assert!(p.signed_volume() > 0.0, "piece {i} winds inward");
            let b = p.bounds();
            assert!(
                b.min.y >= top - 1e-6,
                "frame {}: piece {i} below the board",
                g.frame
            );
            assert!(b.min.x > board_bounds.min.x && b.max.x < board_bounds.max.x);
            assert!(b.min.z > board_bounds.min.z && b.max.z < board_bounds.max.z);
            if g.frame == 0 || g.frame == last {
                assert_relative_eq!(b.min.y, top, epsilon = 1e-6);
            }
            // No two pieces overlap, in the air or on the board.
            for (j, q) in posed.iter().enumerate().skip(i + 1) {
                let c = q.bounds();
                let apart = (0..3).any(|k| b.max[k] < c.min[k] || c.max[k] < b.min[k]);
                assert!(apart, "frame {}: pieces {i} and {j} overlap", g.frame);
            }
        }
    }
    // Two or three pieces move; one of them lifts off between its squares.
    let foot = |g: &FrameGeometry, i: usize| {
        let b = g.objects[2 + i].bounds();
        Vec3::new(b.center().x, b.min.y, b.center().z)
    };
    let movers: Vec<usize> = (0..pieces.len())
        .filter(|&i| foot(&geometry[0], i).distance(foot(&geometry[last], i)) > 0.01)
        .collect();
    assert!((2..=3).contains(&movers.len()), "{movers:?}");
    for pair in geometry.windows(2) {
        for &i in &movers {
            assert!(foot(&pair[0], i).distance(foot(&pair[1], i)) > 0.005);
        }
    }
    let highest = (1..last)
        .flat_map(|f| movers.iter().map(move |&i| (f, i)))
        .map(|(f, i)| foot(&geometry[f], i).y - top)
        .fold(0.0, f32::max);
    assert!(highest > 0.02, "no piece hops: highest foot {highest} m");
}
