use std::sync::Arc;

use approx::assert_relative_eq;
use glam::Vec3;
use shadow_core::{Camera, Object, shapes};

use super::*;
use crate::scenes::white;

/// Every default row is listed under the name its method prints, so
/// that `--methods` naming it finds its description.
#[test]
fn the_default_rows_are_named_as_their_methods_print() {
    for variant in variants() {
        assert!(!variant.what.is_empty(), "{}", variant.spec);
    }
}

/// Objects sharing a mesh are pooled under its name, dark vertices are
/// left out, and the worst 5% share is of the non-dark sum.
#[test]
fn breakdown_pools_meshes_and_measures_concentration() {
    let grid = Arc::new(shapes::floor("tile", Vec3::ZERO, 1.0, 1).unwrap());
    let other = Arc::new(shapes::floor("slab", Vec3::Y, 1.0, 1).unwrap());
    let objects = [&grid, &other, &grid]
        .map(|mesh| Object {
            mesh: Arc::clone(mesh),
            material: white(),
        })
        .to_vec();
    let camera = Camera::framing(Vec3::ZERO, 2.0, Vec3::ONE, 8, 8).unwrap();
    let scene = Scene::still("tiles", objects, camera).unwrap();
    assert_eq!(scene.vertex_count(), 12);
    let mut b = BreakdownBuilder::new(&scene);
    // Tiles (vertices 0–3 and 8–11): one dark vertex, the others 1%,
    // but for one at 37%. Slab (4–7): 10% each.
    for v in 0..12 {
        let error = match v {
            0 => None,
            4..=7 => Some(0.1),
            9 => Some(0.37),
            _ => Some(0.01),
        };
        b.add(v, error);
    }
    let e = b.finish();
    let total = 0.37 + 0.4 + 6.0 * 0.01;
    assert_eq!(e.meshes.len(), 2);
    let (tile, slab) = (&e.meshes[0], &e.meshes[1]);
    assert_eq!((tile.name.as_str(), tile.count), ("tile", 7));
    assert_eq!((slab.name.as_str(), slab.count), ("slab", 4));
    assert_relative_eq!(tile.per_vertex, (0.37 + 0.06) / 7.0, epsilon = 1e-6);
    assert_relative_eq!(tile.share, 0.43 / total, epsilon = 1e-6);
    assert_relative_eq!(slab.share, 0.4 / total, epsilon = 1e-6);
    // 5% of 11 vertex-frames, rounded up: the single worst.
    assert_relative_eq!(e.worst_share, 0.37 / total, epsilon = 1e-6);
}
