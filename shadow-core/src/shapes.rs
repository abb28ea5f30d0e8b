//! Procedural meshes: a few lines each, for scenes that need no asset.

use std::f32::consts::{PI, TAU};

use crate::{Error, Mesh, Result};
use glam::{Vec2, Vec3};

/// A closed sphere: a lathed semicircle of `rings` rings and `segments`
/// segments, one vertex per pole and the seam shared, so that it has no
/// boundary edge ([`Mesh::is_closed`]; a [`uv_sphere`] repeats its seam and
/// poles). Area-weighted normals.
pub fn closed_sphere(
    name: &str,
    center: Vec3,
    radius: f32,
    rings: u32,
    segments: u32,
) -> Result<Mesh> {
    let profile: Vec<Vec2> = (0..=rings)
        .map(|k| {
            let theta = PI * k as f32 / rings as f32;
            let x = if k == 0 || k == rings {
                0.0
            } else {
                theta.sin()
            };
            Vec2::new(x, -theta.cos()) * radius
        })
        .collect();
    let mesh = lathe(name, &profile, segments)?;
    let positions = mesh.positions().iter().map(|p| *p + center).collect();
    mesh.with_pose(positions, Some(mesh.normals().to_vec()))
}

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

/// A closed surface of revolution about +Y: the profile polyline, given as
/// (radius, height) points from the axis back to the axis, swept through
/// `segments` equal steps of a full turn.
///
/// The first and last points must lie on the axis (radius 0): each becomes a
/// single pole vertex, so the ends are capped (a flat foot when the first ring
/// is at the pole's height) and, with the seam shared rather than duplicated,
/// the mesh has no boundary edge and reports [`Mesh::is_closed`]. Every point
/// in between must be off the axis, and the profile should not cross itself.
/// Triangles wind counter-clockwise seen from the right of the profile as it
/// is walked from the bottom pole to the top pole (radius to the right, height
/// up): outward for a profile that goes out, up and back in. Normals are area-weighted, so creases of the
/// profile are smoothed over (per-vertex shading cannot hold a crease on a
/// shared vertex anyway).
pub fn lathe(name: &str, profile: &[Vec2], segments: u32) -> Result<Mesh> {
    let bad = |what: String| Error::InvalidMesh {
        name: name.to_string(),
        what,
    };
    let (Some(first), Some(last)) = (profile.first(), profile.last()) else {
        return Err(bad("empty lathe profile".into()));
    };
    if profile.len() < 3 || segments < 3 {
        return Err(bad(format!(
            "a lathe needs at least 3 profile points and 3 segments, got {} and {segments}",
            profile.len()
        )));
    }
    if first.x != 0.0 || last.x != 0.0 {
        return Err(bad(format!(
            "lathe profile must start and end on the axis (radius 0), got {first} and {last}"
        )));
    }
    let rings = &profile[1..profile.len() - 1];
    if let Some(i) = rings.iter().position(|p| p.x.is_nan() || p.x <= 0.0) {
        return Err(bad(format!(
            "lathe profile point {} has radius {}: only the ends may lie on the axis",
            i + 1,
            rings[i].x
        )));
    }
    // Vertex order: bottom pole, each ring's `segments` vertices, top pole.
    let mut positions = vec![Vec3::new(0.0, first.y, 0.0)];
    for p in rings {
        positions.extend((0..segments).map(|j| {
            // A turn by φ about +Y maps +X to (cos φ, 0, −sin φ).
            let phi = TAU * j as f32 / segments as f32;
            Vec3::new(p.x * phi.cos(), p.y, -p.x * phi.sin())
        }));
    }
    let top = positions.len() as u32;
    positions.push(Vec3::new(0.0, last.y, 0.0));

    // Index of vertex j (mod `segments`) on profile point i.
    let at = |i: usize, j: u32| -> u32 {
        match i {
            0 => 0,
            i if i == profile.len() - 1 => top,
            i => 1 + (i as u32 - 1) * segments + j % segments,
        }
    };
    let mut triangles = Vec::with_capacity(2 * segments as usize * rings.len());
    for i in 0..profile.len() - 1 {
        for j in 0..segments {
            let (a0, a1, b0, b1) = (at(i, j), at(i, j + 1), at(i + 1, j), at(i + 1, j + 1));
            // Each band is a ring of quads; next to a pole one triangle of
            // each quad collapses and is not emitted.
            if i > 0 {
                triangles.push([a0, a1, b0]);
            }
            if i + 1 < profile.len() - 1 {
                triangles.push([a1, b1, b0]);
            }
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
    fn lathe_of_a_rectangle_is_a_closed_outward_prism() {
        let profile = [
            Vec2::new(0.0, 1.0),
            Vec2::new(0.5, 1.0),
            Vec2::new(0.5, 3.0),
            Vec2::new(0.0, 3.0),
        ];
        let m = lathe("cylinder", &profile, 12).unwrap();
        assert!(m.is_closed());
        assert_eq!(m.vertex_count(), 2 + 2 * 12);
        assert_eq!(m.triangle_count(), 4 * 12);
        assert_eq!(m.report().degenerate_triangles, 0);
        // A regular 12-gon prism: area (n/2) r² sin(2π/n), height 2.
        let area = 6.0 * 0.25 * (TAU / 12.0).sin();
        assert_relative_eq!(m.signed_volume(), area * 2.0, epsilon = 1e-5);
        let b = m.bounds();
        assert_relative_eq!(b.min.y, 1.0);
        assert_relative_eq!(b.max.y, 3.0);
    }

    #[test]
    fn lathe_winds_a_hollow_top_outward_too() {
        // A cup: out, up, in across the rim, down into the bowl, to the axis.
        let profile = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.5, 1.0),
            Vec2::new(0.5, 0.5),
            Vec2::new(0.0, 0.5),
        ];
        let m = lathe("cup", &profile, 64).unwrap();
        assert!(m.is_closed());
        // Outer cylinder minus the bowl, to within the polygon's area loss.
        let expected = std::f32::consts::PI * (1.0 - 0.25 * 0.5);
        assert_relative_eq!(m.signed_volume(), expected, max_relative = 0.01);
        // The bowl's floor faces up.
        let floor_normal = m.normals()[m.vertex_count() - 1];
        assert_relative_eq!(floor_normal, Vec3::Y, epsilon = 1e-5);
    }

    #[test]
    fn bad_lathe_profiles_are_errors() {
        let open = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
        ];
        let msg = lathe("p", &open, 8).unwrap_err().to_string();
        assert!(msg.contains("on the axis"), "{msg}");
        let pinched = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 0.5),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ];
        let msg = lathe("p", &pinched, 8).unwrap_err().to_string();
        assert!(msg.contains("point 2"), "{msg}");
        assert!(lathe("p", &[], 8).is_err());
        let tiny = [Vec2::ZERO, Vec2::X, Vec2::Y];
        assert!(lathe("p", &tiny, 2).is_err());
        assert!(lathe("p", &tiny, 3).unwrap().is_closed());
    }

    #[test]
    fn floor_faces_up() {
        let m = floor("f", Vec3::ZERO, 1.0, 3).unwrap();
        assert!(m.normals().iter().all(|n| n.abs_diff_eq(Vec3::Y, 1e-6)));
        assert_eq!(m.triangle_count(), 18);
    }
}
