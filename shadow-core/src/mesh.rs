//! Triangle meshes: validated positions, normals and counter-clockwise triangles.

use std::sync::Arc;

use glam::Vec3;

use crate::frame::vertex_lifts;
use crate::{Error, Result};

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (grows from nothing).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The smallest box holding every point.
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |b, p| b.grow(p))
    }

    /// This box grown to hold `p`.
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f32 {
        self.extent().length()
    }
}

/// What validation changed while building a [`Mesh`], for reports and logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MeshReport {
    /// Triangles dropped because they repeat a vertex or have zero area.
    pub degenerate_triangles: usize,
    /// True when the input had no normals and area-weighted normals were computed.
    pub normals_computed: bool,
    /// Vertices whose normal was zero-length (in the input, or because they touch
    /// only degenerate triangles or none): given the area-weighted normal where one
    /// exists, else +Y.
    pub normals_repaired: usize,
    /// Vertices no kept triangle uses.
    pub unreferenced_vertices: usize,
}

/// A validated triangle mesh, right-handed, +Y up, metres, counter-clockwise
/// front faces (glTF's conventions).
///
/// The fields are private so that every `Mesh` in the program has passed
/// validation: finite positions and unit normals, indices in range, at least one
/// non-degenerate triangle.
#[derive(Clone, Debug)]
pub struct Mesh {
    name: String,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// Shared between the poses of one mesh: topology never changes.
    triangles: Arc<[[u32; 3]]>,
    /// Per vertex, how far its rays start off the surface
    /// ([`vertex_lifts`](crate::frame::vertex_lifts)), of this pose.
    lifts: Vec<f32>,
    report: MeshReport,
}

impl Mesh {
    /// Validates and builds a mesh.
    ///
    /// * positions must be finite;
    /// * every index must be below `positions.len()`;
    /// * triangles repeating a vertex or of zero area are dropped and counted;
    /// * without `normals`, per-vertex normals are the area-weighted sum of the
    ///   face normals of the kept triangles (the cross product's length is twice
    ///   the area, so summing raw cross products weights by area);
    /// * given normals must be finite, one per position; they are normalized.
    ///
    /// Errors name the mesh and the first offending element.
    pub fn new(
        name: impl Into<String>,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        triangles: Vec<[u32; 3]>,
    ) -> Result<Mesh> {
        let name = name.into();
        let bad = |what: String| Error::InvalidMesh {
            name: name.clone(),
            what,
        };
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(bad(format!(
                "vertex {i} has a non-finite position {:?}",
                positions[i]
            )));
        }
        check_extent(&positions).map_err(bad)?;
        let n = positions.len();
        if let Some((t, tri)) = triangles
            .iter()
            .enumerate()
            .find(|(_, tri)| tri.iter().any(|&i| i as usize >= n))
        {
            return Err(bad(format!(
                "triangle {t} has index {tri:?} out of range for {n} vertices"
            )));
        }
        if let Some(normals) = &normals {
            if normals.len() != n {
                return Err(bad(format!("{} normals for {n} positions", normals.len())));
            }
            if let Some(i) = normals.iter().position(|p| !p.is_finite()) {
                return Err(bad(format!(
                    "vertex {i} has a non-finite normal {:?}",
                    normals[i]
                )));
            }
        }

        let before = triangles.len();
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| !is_degenerate(&positions, *t))
            .collect();
        if triangles.is_empty() {
            return Err(bad(if before == 0 {
                "no triangles".to_string()
            } else {
                format!("all {before} triangles are degenerate")
            }));
        }
        let mut report = MeshReport {
            degenerate_triangles: before - triangles.len(),
            normals_computed: normals.is_none(),
            ..MeshReport::default()
        };

        let area_normals = area_weighted_normals(&positions, &triangles);
        let mut referenced = vec![false; n];
        for t in &triangles {
            for &i in t {
                referenced[i as usize] = true;
            }
        }
        report.unreferenced_vertices = referenced.iter().filter(|r| !**r).count();

        let mut normals = normals.unwrap_or_else(|| area_normals.clone());
        for (normal, fallback) in normals.iter_mut().zip(&area_normals) {
            match normal.try_normalize() {
                Some(unit) => *normal = unit,
                None => {
                    report.normals_repaired += 1;
                    *normal = fallback.try_normalize().unwrap_or(Vec3::Y);
                }
            }
        }
        Ok(Mesh {
            name,
            lifts: vertex_lifts(&positions, &triangles),
            positions,
            normals,
            triangles: triangles.into(),
            report,
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Per vertex, the first vertex at the same position (equal bit for
    /// bit): the copies a UV or normal seam makes map to one, so that
    /// simplification and adjacency see the surface continue across it.
    pub fn welded_vertices(&self) -> Vec<u32> {
        let mut first = std::collections::HashMap::new();
        (self.positions.iter().enumerate())
            .map(|(i, p)| {
                *first
                    .entry(p.to_array().map(f32::to_bits))
                    .or_insert(i as u32)
            })
            .collect()
    }

    /// Unit normals, one per position.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Per vertex, how far its rays start off the surface: [`LIFT`](crate::frame::LIFT)
    /// times the longest edge of its triangles
    /// ([`vertex_lifts`](crate::frame::vertex_lifts)).
    pub fn lifts(&self) -> &[f32] {
        &self.lifts
    }

    /// Counter-clockwise triangles, none degenerate.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// What validation changed.
    pub fn report(&self) -> MeshReport {
        self.report
    }

    /// The volume a closed mesh encloses (divergence theorem: the sum of
    /// the tetrahedra from the origin to each face), positive when its faces
    /// wind outward. Meaningless for an open mesh.
    pub fn signed_volume(&self) -> f32 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.positions.iter().copied())
    }

    /// The vertex and triangle neighbourhoods of every vertex.
    pub fn adjacency(&self) -> Adjacency {
        Adjacency::new(self.positions.len(), &self.triangles)
    }

    /// Number of edges used by exactly one triangle (holes, open borders).
    /// Edges used by three or more triangles (non-manifold) are not counted.
    pub fn boundary_edge_count(&self) -> usize {
        let mut edges: Vec<(u32, u32)> = self
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        edges
            .chunk_by(|a, b| a == b)
            .filter(|run| run.len() == 1)
            .count()
    }

    /// A closed mesh has no boundary edges: back-facing blockers are then always
    /// hidden behind front-facing ones, which some methods exploit.
    pub fn is_closed(&self) -> bool {
        self.boundary_edge_count() == 0
    }

    /// A copy with positions and normals replaced: a deformed or moved pose of
    /// the same topology. The triangles are kept as they are (a triangle that
    /// collapses in one pose stays, with zero area) so that triangle and vertex
    /// indices mean the same thing in every pose. Without normals, area-weighted
    /// normals of the pose are computed.
    pub fn with_pose(&self, positions: Vec<Vec3>, normals: Option<Vec<Vec3>>) -> Result<Mesh> {
        let bad = |what: String| Error::InvalidMesh {
            name: self.name.clone(),
            what,
        };
        let n = self.positions.len();
        if positions.len() != n || normals.as_ref().is_some_and(|nn| nn.len() != n) {
            return Err(bad(format!(
                "pose has {} positions and {:?} normals, mesh has {n} vertices",
                positions.len(),
                normals.as_ref().map(Vec::len)
            )));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(bad(format!("pose vertex {i} has a non-finite position")));
        }
        check_extent(&positions).map_err(|what| bad(format!("pose: {what}")))?;
        let fallback = self.normals.iter().copied();
        let normals = match normals {
            Some(given) => given
                .into_iter()
                .zip(fallback)
                .map(|(g, f)| g.try_normalize().unwrap_or(f))
                .collect(),
            None => area_weighted_normals(&positions, &self.triangles)
                .into_iter()
                .zip(fallback)
                .map(|(g, f)| g.try_normalize().unwrap_or(f))
                .collect(),
        };
        Ok(Mesh {
            name: self.name.clone(),
            lifts: vertex_lifts(&positions, &self.triangles),
            positions,
            normals,
            triangles: Arc::clone(&self.triangles),
            report: self.report,
        })
    }
}

/// Fails when the points span more than f32 can subtract: every edge and
/// every difference of positions must be finite.
fn check_extent(positions: &[Vec3]) -> std::result::Result<(), String> {
    let bounds = Aabb::from_points(positions.iter().copied());
    if positions.is_empty() || bounds.extent().is_finite() {
        Ok(())
    } else {
        Err(format!(
            "positions span {:?} to {:?}, beyond what f32 can hold as a difference",
            bounds.min, bounds.max
        ))
    }
}

/// True when the triangle repeats a vertex or its area is zero to within f32
/// precision relative to its longest edge (a sliver of angle below ~1e-7 rad).
/// Judged on the edges scaled by a power of two to their largest coordinate,
/// so that the test depends on the triangle's shape alone, never on its
/// size or units.
fn is_degenerate(positions: &[Vec3], [a, b, c]: [u32; 3]) -> bool {
    if a == b || b == c || c == a {
        return true;
    }
    let (pa, pb, pc) = (
        positions[a as usize],
        positions[b as usize],
        positions[c as usize],
    );
    let edges = [pb - pa, pc - pa];
    let scale = crate::frame::unit_scale(&edges);
    let [e1, e2] = edges.map(|e| e * scale);
    let cross = e1.cross(e2).length();
    let longest = e1
        .length_squared()
        .max(e2.length_squared())
        .max((e2 - e1).length_squared());
    cross <= f32::EPSILON * longest
}

/// Unnormalized per-vertex sums of face cross products (area-weighted normals).
/// Summed with the positions scaled by a power of two to their largest
/// coordinate (exact), so that no cross product overflows whatever the units.
fn area_weighted_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let scale = crate::frame::unit_scale(positions);
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for &[a, b, c] in triangles {
        let (pa, pb, pc) = (
            positions[a as usize] * scale,
            positions[b as usize] * scale,
            positions[c as usize] * scale,
        );
        let face = (pb - pa).cross(pc - pa);
        for i in [a, b, c] {
            normals[i as usize] += face;
        }
    }
    normals
}

/// Per-vertex neighbourhoods in compressed rows: the triangles that use each
/// vertex, and its one-ring of neighbouring vertices (sorted, no duplicates).
#[derive(Clone, Debug)]
pub struct Adjacency {
    triangle_offsets: Vec<u32>,
    triangles: Vec<u32>,
    ring_offsets: Vec<u32>,
    ring: Vec<u32>,
}

impl Adjacency {
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Adjacency {
        let mut triangle_offsets = vec![0u32; vertex_count + 1];
        for t in triangles {
            for &v in t {
                triangle_offsets[v as usize + 1] += 1;
            }
        }
        for i in 0..vertex_count {
            triangle_offsets[i + 1] += triangle_offsets[i];
        }
        let mut cursor = triangle_offsets.clone();
        let mut vertex_triangles = vec![0u32; triangles.len() * 3];
        for (ti, t) in triangles.iter().enumerate() {
            for &v in t {
                vertex_triangles[cursor[v as usize] as usize] = ti as u32;
                cursor[v as usize] += 1;
            }
        }

        let mut ring_offsets = Vec::with_capacity(vertex_count + 1);
        ring_offsets.push(0u32);
        let mut ring = Vec::with_capacity(triangles.len() * 3);
        for v in 0..vertex_count {
            let start = ring.len();
            let range = triangle_offsets[v] as usize..triangle_offsets[v + 1] as usize;
            for &ti in &vertex_triangles[range] {
                ring.extend(
                    triangles[ti as usize]
                        .iter()
                        .copied()
                        .filter(|&u| u as usize != v),
                );
            }
            ring[start..].sort_unstable();
            let mut kept = start;
            for i in start..ring.len() {
                if kept == start || ring[kept - 1] != ring[i] {
                    ring[kept] = ring[i];
                    kept += 1;
                }
            }
            ring.truncate(kept);
            ring_offsets.push(ring.len() as u32);
        }
        Adjacency {
            triangle_offsets,
            triangles: vertex_triangles,
            ring_offsets,
            ring,
        }
    }

    /// Indices of the triangles that use vertex `v`.
    pub fn triangles_of(&self, v: usize) -> &[u32] {
        &self.triangles[self.triangle_offsets[v] as usize..self.triangle_offsets[v + 1] as usize]
    }

    /// The vertices sharing an edge with vertex `v`, sorted.
    pub fn one_ring(&self, v: usize) -> &[u32] {
        &self.ring[self.ring_offsets[v] as usize..self.ring_offsets[v + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn quad() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, -1.0),
                Vec3::new(0.0, 0.0, -1.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn computed_normals_face_ccw_up() {
        let (p, t) = quad();
        let mesh = Mesh::new("quad", p, None, t).unwrap();
        for n in mesh.normals() {
            assert_relative_eq!(*n, Vec3::Y, epsilon = 1e-6);
        }
        assert!(mesh.report().normals_computed);
        assert!(!mesh.is_closed());
        assert_eq!(mesh.boundary_edge_count(), 4);
    }

    #[test]
    fn area_weighting_favours_large_faces() {
        // A big triangle facing +Y and a tiny one facing +X share vertex 0.
        let p = vec![
            Vec3::ZERO,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -10.0),
            Vec3::new(0.0, 0.1, 0.0),
            Vec3::new(0.0, 0.0, -0.1),
        ];
        let mesh = Mesh::new("m", p, None, vec![[0, 1, 2], [0, 4, 3]]).unwrap();
        let n0 = mesh.normals()[0];
        assert!(n0.y > 0.99, "{n0}");
    }

    #[test]
    fn out_of_range_index_is_named() {
        let (p, _) = quad();
        let err = Mesh::new("quad", p, None, vec![[0, 1, 7]]).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("quad") && msg.contains("triangle 0") && msg.contains("out of range"),
            "{msg}"
        );
    }

    #[test]
    fn nan_position_is_an_error() {
        let (mut p, t) = quad();
        p[2].x = f32::NAN;
        let msg = Mesh::new("q", p, None, t).unwrap_err().to_string();
        assert!(
            msg.contains("vertex 2") && msg.contains("non-finite"),
            "{msg}"
        );
    }

    #[test]
    fn empty_and_all_degenerate_meshes_are_errors() {
        let (p, _) = quad();
        let msg = Mesh::new("e", p.clone(), None, vec![])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("no triangles"), "{msg}");
        let msg = Mesh::new("d", p, None, vec![[0, 0, 1], [0, 1, 1]])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("all 2 triangles are degenerate"), "{msg}");
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_counted() {
        let (mut p, mut t) = quad();
        p.push(Vec3::new(2.0, 0.0, 0.0)); // collinear with 0 and 1
        t.push([0, 1, 4]);
        t.push([2, 2, 3]);
        let mesh = Mesh::new("q", p, None, t).unwrap();
        assert_eq!(mesh.triangle_count(), 2);
        assert_eq!(mesh.report().degenerate_triangles, 2);
        assert_eq!(mesh.report().unreferenced_vertices, 1);
        assert_eq!(mesh.report().normals_repaired, 1);
    }

    #[test]
    fn tetrahedron_is_closed_with_full_rings() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let t = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let mesh = Mesh::new("tet", p, None, t).unwrap();
        assert!(mesh.is_closed());
        let adj = mesh.adjacency();
        for v in 0..4 {
            assert_eq!(adj.triangles_of(v).len(), 3);
            let ring: Vec<u32> = (0..4u32).filter(|&u| u as usize != v).collect();
            assert_eq!(adj.one_ring(v), ring.as_slice());
        }
        // Outward normals: vertex 0 at the corner points away from the others.
        assert!(mesh.normals()[0].dot(Vec3::ONE) < 0.0);
        let b = mesh.bounds();
        assert_eq!(b.min, Vec3::ZERO);
        assert_eq!(b.max, Vec3::ONE);
    }

    #[test]
    fn welding_maps_copies_of_a_position_to_the_first() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::X, Vec3::Z];
        let mesh = Mesh::new("seam", p.to_vec(), None, vec![[0, 1, 2], [3, 4, 2]]).unwrap();
        assert_eq!(mesh.welded_vertices(), vec![0, 1, 2, 1, 4]);
    }
}
