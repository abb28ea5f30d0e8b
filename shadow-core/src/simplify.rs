//! A mesh simplified within a distance, for drawing it as an occluder:
//! model no more than visibility needs (DESIGN.md). The triangles keep the
//! mesh's own vertices, so that a method can draw them over the same vertex
//! data and keep every vertex as a receiver.

use glam::Vec3;
use meshopt::{SimplifyOptions, VertexDataAdapter};

use crate::{Error, Mesh, Result};

/// Objects with fewer triangles than this are drawn whole.
pub const MIN_TRIANGLES: usize = 64;

/// A simplified occluder: its triangles, and how far its surface may lie
/// from the mesh's.
pub struct Simplified {
    /// Triangles over the mesh's own vertices.
    pub triangles: Vec<[u32; 3]>,
    /// meshopt's estimate of the distance between the two surfaces (from
    /// its quadrics), in the mesh's units.
    pub error: f32,
}

/// `mesh` simplified as far as its surface moves by at most `max_error`
/// (in the mesh's units), to no fewer than [`MIN_TRIANGLES`] triangles, as
/// triangles over the mesh's own vertices: meshopt's edge-collapse
/// simplification of the mesh welded by position (so that seams where
/// vertices are split for normals can collapse too), mapped back to the
/// first vertex at each position.
pub fn simplified(mesh: &Mesh, max_error: f32) -> Result<Simplified> {
    let triangles = mesh.triangles();
    if triangles.len() <= MIN_TRIANGLES {
        return Ok(Simplified {
            triangles: triangles.to_vec(),
            error: 0.0,
        });
    }
    let positions = mesh.positions();
    let weld = mesh.welded_vertices();
    let welded: Vec<u32> = triangles
        .iter()
        .flat_map(|t| t.map(|i| weld[i as usize]))
        .collect();
    let floats: Vec<f32> = positions.iter().flat_map(|p: &Vec3| p.to_array()).collect();
    let adapter = VertexDataAdapter::new(meshopt::typed_to_bytes(&floats), 12, 0).map_err(|e| {
        Error::InvalidMesh {
            name: mesh.name().into(),
            what: format!("meshopt refused the positions: {e}"),
        }
    })?;
    // meshopt's errors are relative to the mesh's extent.
    let scale = meshopt::simplify_scale(&adapter);
    let mut error = 0.0;
    let indices = meshopt::simplify(
        &welded,
        &adapter,
        3 * MIN_TRIANGLES,
        max_error / scale,
        SimplifyOptions::None,
        Some(&mut error),
    );
    let coarse: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok(if coarse.is_empty() {
        Simplified {
            triangles: triangles.to_vec(),
            error: 0.0,
        }
    } else {
        Simplified {
            triangles: coarse,
            error: error * scale,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 32×32 grid of quads, split along a seam (the vertices of column 16
    /// repeated) as meshes with hard edges are.
    fn seamed_grid() -> Mesh {
        let n = 32;
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for half in 0..2u32 {
            let base = positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n / 2 {
                    let x = (half * n / 2 + i) as f32 / n as f32;
                    let z = j as f32 / n as f32;
                    positions.push(Vec3::new(x, 0.1 * (6.0 * x).sin() * z, z));
                }
            }
            let row = n / 2 + 1;
            for j in 0..n {
                for i in 0..n / 2 {
                    let a = base + j * row + i;
                    triangles.push([a, a + row, a + 1]);
                    triangles.push([a + 1, a + row, a + row + 1]);
                }
            }
        }
        Mesh::new("seamed", positions, None, triangles).unwrap()
    }

    #[test]
    fn simplification_keeps_the_mesh_vertices_and_crosses_seams() {
        let mesh = seamed_grid();
        let simplified_mesh = simplified(&mesh, 0.01).unwrap();
        let coarse = simplified_mesh.triangles;
        assert!(simplified_mesh.error > 0.0 && simplified_mesh.error <= 0.01);
        let n = mesh.triangle_count();
        assert!(
            coarse.len() < n / 5 && coarse.len() >= MIN_TRIANGLES,
            "{} of {n}",
            coarse.len()
        );
        assert!(
            coarse
                .iter()
                .flatten()
                .all(|&v| (v as usize) < mesh.vertex_count())
        );
        // The covered area stays close to the original's.
        let area = |tris: &[[u32; 3]]| -> f32 {
            let p = mesh.positions();
            tris.iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| p[i as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum()
        };
        let (full, reduced) = (area(mesh.triangles()), area(&coarse));
        assert!((reduced - full).abs() < 0.05 * full, "{reduced} of {full}");
        // With no error allowed, only collapses that move nothing happen.
        let exact = simplified(&mesh, 0.0).unwrap();
        assert!((area(&exact.triangles) - full).abs() < 1e-4 * full);
        assert_eq!(exact.error, 0.0);
    }
}
