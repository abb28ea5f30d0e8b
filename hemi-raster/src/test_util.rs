//! Exact references and small meshes for the tests.

use glam::Vec3;
use shadow_core::Mesh;

/// The cosine-weighted solid angle ∫ max(0, cos θ) dω of a polygon above the
/// tangent plane (z ≥ 0), seen from the origin with normal +z: π times
/// Lambert's form factor, F = (1/2π) |Σ_i Θ_i γ_i·n|, Θ_i the angle between
/// consecutive vertices and γ_i the unit normal of the plane through edge i
/// and the origin.
pub fn projected_solid_angle(polygon: &[Vec3]) -> f32 {
    let mut sum = 0.0f64;
    for (i, &a) in polygon.iter().enumerate() {
        let b = polygon[(i + 1) % polygon.len()];
        let (a, b) = (a.as_dvec3().normalize(), b.as_dvec3().normalize());
        let cross = a.cross(b);
        if cross.length() < 1e-15 {
            continue;
        }
        let theta = cross.length().atan2(a.dot(b));
        sum += theta * cross.normalize().z;
    }
    (0.5 * sum.abs()) as f32
}

/// The part of a convex polygon with z ≥ 0 (Sutherland–Hodgman).
pub fn clip_above_horizon(polygon: &[Vec3]) -> Vec<Vec3> {
    let mut out = Vec::new();
    for (i, &a) in polygon.iter().enumerate() {
        let b = polygon[(i + 1) % polygon.len()];
        if a.z >= 0.0 {
            out.push(a);
        }
        if (a.z >= 0.0) != (b.z >= 0.0) {
            out.push(a + (b - a) * (a.z / (a.z - b.z)));
        }
    }
    out
}

/// An icosphere with `subdivisions` levels and exact radial normals.
pub fn icosphere(center: Vec3, radius: f32, subdivisions: u32) -> Mesh {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let mut p: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, p: &mut Vec<Vec3>| {
            *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                (p.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let (ab, bc, ca) = (mid(a, b, &mut p), mid(b, c, &mut p), mid(c, a, &mut p));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    let normals = p.clone();
    let positions = p.iter().map(|&n| center + radius * n).collect();
    Mesh::new("icosphere", positions, Some(normals), tris).unwrap()
}

/// A `cells`×`cells` grid in the plane y = `height` spanning [−half, half]²
/// in x and z, facing +y (counter-clockwise seen from above).
pub fn grid(height: f32, half: f32, cells: u32) -> Mesh {
    let row = cells + 1;
    let mut positions = Vec::new();
    for k in 0..row {
        for i in 0..row {
            let s = |j: u32| -half + 2.0 * half * j as f32 / cells as f32;
            positions.push(Vec3::new(s(i), height, s(k)));
        }
    }
    let mut triangles = Vec::new();
    for k in 0..cells {
        for i in 0..cells {
            let a = k * row + i;
            triangles.push([a, a + row, a + 1]);
            triangles.push([a + 1, a + row, a + row + 1]);
        }
    }
    let normals = vec![Vec3::Y; positions.len()];
    Mesh::new("grid", positions, Some(normals), triangles).unwrap()
}

#[test]
fn references_are_right() {
    use std::f32::consts::PI;
    // A huge square above the receiver covers nearly the whole hemisphere.
    let big = [
        Vec3::new(-1e4, -1e4, 1.0),
        Vec3::new(1e4, -1e4, 1.0),
        Vec3::new(1e4, 1e4, 1.0),
        Vec3::new(-1e4, 1e4, 1.0),
    ];
    assert!((projected_solid_angle(&big) - PI).abs() < 1e-3);
    // A disk of angular radius α covers π sin²α: a fine polygon approximates it.
    let alpha = 0.5f32;
    let ring: Vec<Vec3> = (0..2000)
        .map(|k| {
            let phi = k as f32 * std::f32::consts::TAU / 2000.0;
            Vec3::new(alpha.tan() * phi.cos(), alpha.tan() * phi.sin(), 1.0)
        })
        .collect();
    assert!((projected_solid_angle(&ring) - PI * alpha.sin().powi(2)).abs() < 1e-4);
    let clipped = clip_above_horizon(&[
        Vec3::new(0.0, 1.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(0.0, 1.0, 1.0),
    ]);
    assert_eq!(clipped.len(), 4);
    assert!(clipped.contains(&Vec3::new(0.5, 0.5, 0.0)) && clipped.contains(&Vec3::Y));
    assert!(clipped.iter().all(|p| p.z >= 0.0));
    let sphere = icosphere(Vec3::ZERO, 1.0, 2);
    assert!(sphere.is_closed());
    assert_eq!(sphere.vertex_count(), 162);
}
