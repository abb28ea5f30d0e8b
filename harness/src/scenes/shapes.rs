//! Procedural meshes: a few lines each, for scenes that need no asset.

use std::f32::consts::{PI, TAU};

use glam::Vec3;
use shadow_core::{Mesh, Result};

/// A UV sphere with outward normals (analytic, not area-weighted).
pub fn uv_sphere(name: &str, center: Vec3, radius: f32, rings: u32, segments: u32) -> Result<Mesh> {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for r in 0..=rings {
        let theta = PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = TAU * s as f32 / segments as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            positions.push(center + n * radius);
            normals.push(n);
        }
    }
    let row = segments + 1;
    let mut triangles = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * row + s, (r + 1) * row + s);
            // Counter-clockwise seen from outside; the pole rows' degenerate
            // triangles are dropped by validation.
            triangles.push([a, a + 1, b]);
            triangles.push([a + 1, b + 1, b]);
        }
    }
    Mesh::new(name, positions, Some(normals), triangles)
}

/// An axis-aligned rectangle in the plane y = `height`, facing +Y, split into
/// `cells`×`cells` quads.
pub fn floor(name: &str, center: Vec3, half_size: f32, cells: u32) -> Result<Mesh> {
    let corner = center - Vec3::new(half_size, 0.0, half_size);
    let step = 2.0 * half_size / cells as f32;
    grid(name, corner, Vec3::Z * step, Vec3::X * step, cells, cells)
}

/// A grid of `nu`×`nv` quads spanned by `du` and `dv` from `origin`; its front
/// face is on the side of `du × dv`.
pub fn grid(name: &str, origin: Vec3, du: Vec3, dv: Vec3, nu: u32, nv: u32) -> Result<Mesh> {
    let mut positions = Vec::new();
    for i in 0..=nu {
        for j in 0..=nv {
            positions.push(origin + du * i as f32 + dv * j as f32);
        }
    }
    let row = nv + 1;
    let mut triangles = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let a = i * row + j;
            triangles.push([a, a + row, a + row + 1]);
            triangles.push([a, a + row + 1, a + 1]);
        }
    }
    Mesh::new(name, positions, None, triangles)
}

/// An axis-aligned box; `inward` chooses whether its faces point inside (a room
/// to sit in) or outside (a solid). Corners are not shared between faces, so
/// each face keeps its flat normal.
pub fn cuboid(name: &str, min: Vec3, max: Vec3, inward: bool) -> Result<Mesh> {
    let size = max - min;
    // (origin, du, dv) with du × dv pointing outward.
    let faces = [
        (min, Vec3::Z * size.z, Vec3::Y * size.y), // −X
        (
            Vec3::new(max.x, min.y, min.z),
            Vec3::Y * size.y,
            Vec3::Z * size.z,
        ), // +X
        (min, Vec3::X * size.x, Vec3::Z * size.z), // −Y
        (
            Vec3::new(min.x, max.y, min.z),
            Vec3::Z * size.z,
            Vec3::X * size.x,
        ), // +Y
        (min, Vec3::Y * size.y, Vec3::X * size.x), // −Z
        (
            Vec3::new(min.x, min.y, max.z),
            Vec3::X * size.x,
            Vec3::Y * size.y,
        ), // +Z
    ];
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for (o, du, dv) in faces {
        let base = positions.len() as u32;
        positions.extend([o, o + du, o + du + dv, o + dv]);
        let (t0, t1) = ([base, base + 1, base + 2], [base, base + 2, base + 3]);
        if inward {
            triangles.push([t0[0], t0[2], t0[1]]);
            triangles.push([t1[0], t1[2], t1[1]]);
        } else {
            triangles.extend([t0, t1]);
        }
    }
    Mesh::new(name, positions, None, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn sphere_normals_point_out_and_winding_agrees() {
        let m = uv_sphere("s", Vec3::ZERO, 2.0, 12, 24).unwrap();
        for t in m.triangles() {
            let [a, b, c] = t.map(|i| m.positions()[i as usize]);
            let face = (b - a).cross(c - a);
            assert!(face.dot(a + b + c) > 0.0, "triangle {t:?} faces inward");
        }
        for (p, n) in m.positions().iter().zip(m.normals()) {
            assert_relative_eq!(*p / 2.0, *n, epsilon = 1e-5);
        }
    }

    #[test]
    fn cuboid_faces_point_the_chosen_way() {
        for inward in [false, true] {
            let m = cuboid("b", Vec3::ZERO, Vec3::ONE, inward).unwrap();
            assert_eq!(m.triangle_count(), 12);
            for t in m.triangles() {
                let [a, b, c] = t.map(|i| m.positions()[i as usize]);
                let outward =
                    ((a + b + c) / 3.0 - Vec3::splat(0.5)).dot((b - a).cross(c - a)) > 0.0;
                assert_eq!(outward, !inward);
            }
        }
    }

    #[test]
    fn floor_faces_up() {
        let m = floor("f", Vec3::ZERO, 1.0, 3).unwrap();
        assert!(m.normals().iter().all(|n| n.abs_diff_eq(Vec3::Y, 1e-6)));
        assert_eq!(m.triangle_count(), 18);
    }
}
