//! The two-level mesh hierarchy of Kautz et al. 2004, §3.2: near a receiver
//! the full-resolution mesh, elsewhere a coarse version of every object.
//!
//! # The coarse mesh
//! Built once per object by `prepare` with meshoptimizer's edge-collapse
//! simplifier. Its index buffer refers to the original vertices, so each
//! frame's coarse triangles are made of that frame's posed positions: the
//! coarse mesh follows rigid motion, skinning and morphs for free. Vertices
//! at the same position (UV or normal seams) are welded to their first copy
//! before simplifying, otherwise the simplifier would keep every seam; the
//! copies move together under any pose that gives equal inputs equal outputs.
//! An object whose target is not below its triangle count is used whole, and
//! a receiver then sees exactly the triangles of [`crate::Hierarchy::Flat`].
//!
//! # Near and far
//! A receiver rasterizes, at full resolution, the triangles of its one- or
//! two-ring (found on the welded mesh, so that they continue across seams)
//! and the triangles of its object that come within `near_reach` × the mean
//! coarse-triangle radius of it in the rest pose (close in space but maybe
//! far along the surface: the paper's §4.1 "Accuracy of Local Geometry");
//! and the coarse triangles of every object, its own included. Near and
//! coarse triangles over the same region overlap, which the OR of the mask
//! absorbs (§3.2).
//!
//! Coarse triangles through the receiver subtend no solid angle and are
//! skipped, and so are the receiver's own object's coarse triangles that it
//! sees from behind with their centroid closer than twice their radius
//! ([`crate::rasterize`]'s `is_near_chord`, tested per frame in the
//! per-receiver loop, so that it follows deformation): a coarse triangle is
//! a chord of the fine surface, and over a concave receiver it passes just
//! above it, back side down, blocking half its hemisphere. Closed meshes
//! cull those as back faces anyway; on the open wavy cloth of the
//! `frame_timing` example (rings only), keeping them darkened the mean
//! radiance from 0.651 (flat) to 0.405, skipping them gave 0.654. A fold of
//! the same object seen from behind farther away than the coarse triangle's
//! size is kept. (The rule was first tested once in the rest pose; on the
//! harness's deforming `cloth`, whose folds form after the rest pose, that
//! left chords over the new folds and 18% transfer error against 3.8%
//! flat.)
//!
//! On the skinned human of the harness (three open parts, 5,126 → 931
//! coarse triangles, two-ring), the rings alone gave a much larger error
//! than `near_reach` 2 (`harness accuracy`, row `rings-only`, and the
//! crate README): vertices that flat mode finds fully occluded, in cavities
//! and under close folds, were lit once the coarse surface cut past them.
//!
//! Skipping more was tried and is worse, because a skipped coarse triangle
//! takes its far part away too, leaving a hole. On the test's bumpy sphere
//! (5,120 → 512 triangles, two-ring only, blocked fraction 0.070 on average
//! in flat mode) the mean per-vertex difference from flat mode was 0.0047
//! with the rule above, 0.026 when also skipping the coarse triangles that
//! touch the near rings, and 0.038 when also skipping those facing the
//! receiver closer than the near rings reach.
//!
//! The near lists are computed once, in the rest pose, and kept under
//! deformation: rings are topological; spatial neighbours that a
//! deformation brings close are seen through the coarse mesh.

use std::collections::HashMap;
use std::ops::Range;

use glam::Vec3;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use rayon::prelude::*;
use shadow_core::{Adjacency, Error, Mesh, Result, Scene};

use crate::config::NearRings;
use crate::kernel::{Candidates, Corners, Entry};
use crate::rasterize::Blockers;

/// The static part of the hierarchy of a scene: coarse meshes and, per
/// receiver, its near triangles. Vertex and
/// triangle indices are global (all objects one after another, as in
/// [`Blockers`]).
#[derive(Clone, Debug)]
pub(crate) struct TwoLevel {
    /// All objects' coarse triangles, over global vertex indices, so that
    /// each frame's posed positions make them.
    coarse_triangles: Vec<[u32; 3]>,
    /// Per object: the range of its coarse triangles.
    coarse_objects: Vec<Range<usize>>,
    /// Per global vertex: its object.
    vertex_object: Vec<u32>,
    /// Per global vertex (CSR): its near full-resolution triangles, as
    /// entries of the frame's fine [`Corners`].
    near_offsets: Vec<u32>,
    near: Vec<Entry>,
}

/// One object's share of the hierarchy, in its own indices.
struct ObjectLevels {
    /// Coarse triangles over the object's (welded) vertices.
    coarse: Vec<[u32; 3]>,
    /// Per vertex: its near triangles.
    near: Vec<Vec<u32>>,
}

impl TwoLevel {
    /// Simplifies every object to max(triangles / `divisor`,
    /// `min_triangles`) triangles and gathers the per-vertex lists; `cull`
    /// says per object whether its back faces are culled.
    pub(crate) fn new(
        scene: &Scene,
        cull: &[bool],
        divisor: u32,
        min_triangles: u32,
        rings: NearRings,
        reach: u8,
    ) -> Result<TwoLevel> {
        let mut h = TwoLevel {
            coarse_triangles: Vec::new(),
            coarse_objects: Vec::new(),
            vertex_object: Vec::new(),
            near_offsets: vec![0],
            near: Vec::new(),
        };
        let slot_bases =
            Corners::slot_bases(scene.objects().iter().map(|o| o.mesh.triangle_count()));
        let mut vertex_base = 0u32;
        for (o, object) in scene.objects().iter().enumerate() {
            let mesh = &object.mesh;
            let levels = ObjectLevels::new(mesh, divisor, min_triangles, rings, reach)?;
            let coarse_base = h.coarse_triangles.len();
            h.coarse_triangles
                .extend(levels.coarse.iter().map(|t| t.map(|i| i + vertex_base)));
            h.coarse_objects.push(coarse_base..h.coarse_triangles.len());
            for near in levels.near {
                h.near.extend(
                    near.iter()
                        .map(|t| Entry::new(t + slot_bases[o], cull[o], false)),
                );
                h.near_offsets.push(h.near.len() as u32);
                h.vertex_object.push(o as u32);
            }
            vertex_base += mesh.vertex_count() as u32;
        }
        Ok(h)
    }

    /// Number of coarse triangles of `object`.
    pub(crate) fn coarse_triangle_count(&self, object: usize) -> Option<usize> {
        self.coarse_objects.get(object).map(|r| r.len())
    }

    /// This frame's coarse triangles, laid out for the per-receiver loop.
    pub(crate) fn corners(&self, blockers: &Blockers) -> Corners {
        let groups = self
            .coarse_objects
            .iter()
            .zip(&blockers.objects)
            .map(|(range, (_, cull))| (range.clone(), *cull));
        Corners::new(blockers, &self.coarse_triangles, groups)
    }

    /// What global vertex `v` rasterizes: its near triangles at full
    /// resolution (from `fine`, every triangle of the frame) and every coarse
    /// triangle (`coarse`, from [`TwoLevel::corners`]) but its own object's
    /// near chords. Triangles through `v` itself subtend no solid angle and
    /// are culled by the loop.
    pub(crate) fn candidates<'a>(
        &'a self,
        coarse: &'a Corners,
        fine: &'a Corners,
        v: usize,
    ) -> Candidates<'a> {
        let near = self.near_offsets[v] as usize..self.near_offsets[v + 1] as usize;
        Candidates::TwoLevel {
            coarse,
            fine,
            own: self.vertex_object[v] as usize,
            near: &self.near[near],
        }
    }
}

impl ObjectLevels {
    fn new(
        mesh: &Mesh,
        divisor: u32,
        min_triangles: u32,
        rings: NearRings,
        reach: u8,
    ) -> Result<Self> {
        let triangles = mesh.triangles();
        let target = (triangles.len() / divisor as usize).max(min_triangles as usize);
        let whole = || ObjectLevels {
            coarse: triangles.to_vec(),
            near: vec![Vec::new(); mesh.vertex_count()],
        };
        if target >= triangles.len() {
            return Ok(whole());
        }
        let positions = mesh.positions();
        // Weld copies of a position to the first one.
        let mut first = HashMap::new();
        let weld: Vec<u32> = positions
            .iter()
            .enumerate()
            .map(|(i, p)| {
                *first
                    .entry(p.to_array().map(f32::to_bits))
                    .or_insert(i as u32)
            })
            .collect();
        let welded: Vec<[u32; 3]> = triangles
            .iter()
            .map(|t| t.map(|i| weld[i as usize]))
            .collect();
        let floats: Vec<f32> = positions.iter().flat_map(|p| p.to_array()).collect();
        let adapter =
            VertexDataAdapter::new(meshopt::typed_to_bytes(&floats), 12, 0).map_err(|e| {
                Error::InvalidMesh {
                    name: mesh.name().into(),
                    what: format!("meshopt refused the positions: {e}"),
                }
            })?;
        let indices = meshopt::simplify(
            welded.as_flattened(),
            &adapter,
            3 * target,
            // Relative to the mesh's extent: let the triangle target decide.
            1.0,
            SimplifyOptions::None,
            None,
        );
        let coarse: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if coarse.is_empty() || coarse.len() >= triangles.len() {
            return Ok(whole());
        }
        let adjacency = Adjacency::new(mesh.vertex_count(), &welded);
        let mean_radius = coarse
            .iter()
            .map(|t| bounding_sphere(t.map(|i| positions[i as usize])).1)
            .sum::<f32>()
            / coarse.len() as f32;
        let spatial = f32::from(reach) * mean_radius;
        // Fine triangles sorted by the x of their centre, so that those
        // within `spatial` of a vertex lie in a window found by bisection.
        let mut fine: Vec<(u32, [Vec3; 3], Vec3, f32)> = triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let corners = tri.map(|i| positions[i as usize]);
                let (centre, radius) = bounding_sphere(corners);
                (t as u32, corners, centre, radius)
            })
            .collect();
        fine.sort_unstable_by(|x, y| x.2.x.total_cmp(&y.2.x));
        let max_radius = fine.iter().map(|f| f.3).fold(0.0, f32::max);
        let near = (0..mesh.vertex_count())
            .into_par_iter()
            .map(|v| {
                let r = weld[v] as usize;
                let mut near: Vec<u32> = adjacency.triangles_of(r).to_vec();
                if rings == NearRings::Two {
                    for &u in adjacency.one_ring(r) {
                        near.extend_from_slice(adjacency.triangles_of(u as usize));
                    }
                }
                let p = positions[v];
                if spatial > 0.0 {
                    let margin = spatial + max_radius;
                    let from = fine.partition_point(|f| f.2.x < p.x - margin);
                    let to = fine.partition_point(|f| f.2.x <= p.x + margin);
                    for (t, [a, b, c], centre, radius) in &fine[from..to] {
                        if p.distance(*centre) - radius < spatial
                            && closest_point(p, *a, *b, *c).distance(p) < spatial
                        {
                            near.push(*t);
                        }
                    }
                }
                near.sort_unstable();
                near.dedup();
                near
            })
            .collect();
        Ok(ObjectLevels { coarse, near })
    }
}
/// A sphere around a triangle: its centroid and the distance to the farthest
/// corner.
fn bounding_sphere(corners: [Vec3; 3]) -> (Vec3, f32) {
    let centre = (corners[0] + corners[1] + corners[2]) / 3.0;
    let radius = corners
        .iter()
        .map(|p| p.distance(centre))
        .fold(0.0, f32::max);
    (centre, radius)
}

/// The point of triangle (a, b, c) closest to `p` (Ericson, "Real-Time
/// Collision Detection", §5.1.5).
fn closest_point(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, Hierarchy};
    use crate::method::HemiRaster;
    use crate::test_util::{grid, icosphere, projected_solid_angle};
    use glam::Affine3A;
    use shadow_core::{Brdf, Camera, Frame, Object, Pose, ShadowMethod};
    use std::f32::consts::PI;
    use std::num::NonZeroU32;
    use std::sync::Arc;

    fn object(mesh: Mesh) -> Object {
        Object {
            mesh: Arc::new(mesh),
            material: Brdf::lambert(Vec3::splat(0.5)).unwrap(),
        }
    }

    fn camera() -> Camera {
        Camera::new(Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 32, 24).unwrap()
    }

    fn flat() -> Config {
        Config {
            hierarchy: Hierarchy::Flat,
            ..Config::default()
        }
    }

    fn two_level(near: NearRings, near_reach: u8) -> Config {
        Config {
            hierarchy: Hierarchy::TwoLevel {
                coarse_divisor: NonZeroU32::new(10).unwrap(),
                min_coarse_triangles: 100,
                near,
                near_reach,
            },
            ..Config::default()
        }
    }

    /// Blocked fractions of every vertex of frame `f`.
    fn blocked(config: Config, scene: &Scene, f: usize) -> (HemiRaster, Vec<f32>) {
        let mut method = HemiRaster::new(config);
        method.prepare(scene).unwrap();
        method.update(&scene.frame_geometry(f).unwrap()).unwrap();
        let mut out = Vec::new();
        for (o, object) in scene.objects().iter().enumerate() {
            for v in 0..object.mesh.vertex_count() {
                out.push(method.blocked_fraction(o, v).unwrap());
            }
        }
        (method, out)
    }

    /// A unit sphere with radial bumps, `subdivisions` times subdivided:
    /// closed, with concave and convex regions.
    fn bumpy_sphere(subdivisions: u32) -> Mesh {
        let sphere = icosphere(Vec3::ZERO, 1.0, subdivisions);
        let positions = sphere
            .positions()
            .iter()
            .map(|p| {
                let n = p.normalize();
                n * (1.0 + 0.3 * (6.0 * n.x).sin() * (5.0 * n.y).cos() * (4.0 * n.z + 1.0).sin())
            })
            .collect();
        Mesh::new("bumpy", positions, None, sphere.triangles().to_vec()).unwrap()
    }

    /// Objects below the coarse target are used whole: the masks, hence the
    /// transfer vectors, are those of flat mode bit for bit.
    #[test]
    fn small_meshes_match_flat_mode_exactly() {
        let scene = Scene::still(
            "sphere over floor",
            vec![
                object(icosphere(Vec3::new(0.0, 0.6, 0.0), 0.4, 1)),
                object(grid(0.0, 1.0, 6)),
            ],
            camera(),
        )
        .unwrap();
        let whole = Config {
            hierarchy: Hierarchy::default().with_min_coarse_triangles(100),
            ..Config::default()
        };
        let (h, hb) = blocked(whole, &scene, 0);
        let (f, fb) = blocked(flat(), &scene, 0);
        assert_eq!(h.coarse_triangle_count(0), Some(80));
        assert_eq!(h.coarse_triangle_count(1), Some(72));
        assert_eq!(f.coarse_triangle_count(0), None);
        assert_eq!(hb, fb);
        assert!(hb.iter().any(|&b| b > 0.1));
        for v in 0..scene.objects()[1].mesh.vertex_count() {
            assert_eq!(h.transfer(1, v), f.transfer(1, v));
        }
    }

    /// On a closed bumpy sphere of 5,120 triangles simplified to 512, the
    /// self-shadowing stays close to flat mode's, with one ring or two, with
    /// or without spatial neighbours. Measured: mean |difference| of the
    /// blocked fraction 0.0076 (one ring), 0.0047 (two), 0.0034 (two and
    /// `near_reach` 2), worst vertex 0.22, 0.11, 0.11, against a flat-mode
    /// mean of 0.070.
    #[test]
    fn bumpy_sphere_stays_close_to_flat_mode() {
        let scene = Scene::still("bumpy", vec![object(bumpy_sphere(4))], camera()).unwrap();
        let (_, fb) = blocked(flat(), &scene, 0);
        let n = fb.len() as f32;
        let flat_mean = fb.iter().sum::<f32>() / n;
        for (near, reach) in [
            (NearRings::One, 0),
            (NearRings::Two, 0),
            (NearRings::Two, 2),
        ] {
            let (h, hb) = blocked(two_level(near, reach), &scene, 0);
            assert_eq!(h.coarse_triangle_count(0), Some(512));
            let mean = hb.iter().sum::<f32>() / n;
            let mean_abs = fb.iter().zip(&hb).map(|(a, b)| (a - b).abs()).sum::<f32>() / n;
            let max_abs = fb
                .iter()
                .zip(&hb)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            eprintln!(
                "{near:?} reach {reach}: mean blocked {mean:.4} vs flat {flat_mean:.4}, mean |diff| {mean_abs:.4}, max {max_abs:.4}"
            );
            assert!(flat_mean > 0.02, "the bumps must shadow: {flat_mean}");
            assert!((mean - flat_mean).abs() < 0.01, "{mean} vs {flat_mean}");
            assert!(mean_abs < 0.01, "{mean_abs}");
            assert!(max_abs < 0.25, "{max_abs}");
        }
    }

    /// An open wavy sheet: no back-face culling hides the coarse chords over
    /// its valleys, the skip rule must. Measured: mean blocked 0.1774 against
    /// 0.1700 flat, mean |difference| 0.0084 (with `near_reach` 0: 0.1697 and
    /// 0.0080; without the skip rule 0.48 and 0.31).
    #[test]
    fn open_wavy_sheet_stays_close_to_flat_mode() {
        let flat_sheet = grid(0.0, 0.5, 28);
        let positions = flat_sheet
            .positions()
            .iter()
            .map(|p| {
                let y = 0.06 * (p.x * 19.0).sin() * (p.z * 7.0).cos() + 0.04 * (p.z * 23.0).sin();
                Vec3::new(p.x, y, p.z)
            })
            .collect();
        let sheet = Mesh::new("wavy", positions, None, flat_sheet.triangles().to_vec()).unwrap();
        let scene = Scene::still("wavy", vec![object(sheet)], camera()).unwrap();
        let (_, fb) = blocked(flat(), &scene, 0);
        let (h, hb) = blocked(two_level(NearRings::Two, 2), &scene, 0);
        assert_eq!(h.coarse_triangle_count(0), Some(156));
        let n = fb.len() as f32;
        let (flat_mean, mean) = (fb.iter().sum::<f32>() / n, hb.iter().sum::<f32>() / n);
        let mean_abs = fb.iter().zip(&hb).map(|(a, b)| (a - b).abs()).sum::<f32>() / n;
        eprintln!(
            "wavy sheet: mean blocked {mean:.4} vs flat {flat_mean:.4}, mean |diff| {mean_abs:.4}"
        );
        assert!(flat_mean > 0.05, "the waves must shadow: {flat_mean}");
        assert!((mean - flat_mean).abs() < 0.02, "{mean} vs {flat_mean}");
        assert!(mean_abs < 0.02, "{mean_abs}");
    }

    /// The coarse mesh indexes the original vertices, so it follows a
    /// deformation: a dense sheet over a small floor, shrunk by a
    /// `Pose::Deformed`, shadows the floor's centre by its form factor in
    /// both frames.
    #[test]
    fn coarse_mesh_follows_deformed_poses() {
        let sheet = grid(0.4, 0.6, 24);
        let shrunk: Arc<[Vec3]> = sheet
            .positions()
            .iter()
            .map(|p| Vec3::new(0.2 * p.x, p.y, 0.2 * p.z))
            .collect();
        let frames = vec![
            Frame {
                time: 0.0,
                poses: vec![Pose::Rigid(Affine3A::IDENTITY); 2],
            },
            Frame {
                time: 1.0,
                poses: vec![
                    Pose::Rigid(Affine3A::IDENTITY),
                    Pose::Deformed {
                        positions: shrunk,
                        normals: None,
                    },
                ],
            },
        ];
        let scene = Scene::new(
            "sheet over floor",
            vec![object(grid(0.0, 1.0, 4)), object(sheet)],
            frames,
            camera(),
        )
        .unwrap();
        for (f, half) in [(0, 0.6), (1, 0.12)] {
            let (h, hb) = blocked(two_level(NearRings::Two, 2), &scene, f);
            // 1,152 triangles to about 115.
            let coarse = h.coarse_triangle_count(1).unwrap();
            assert!((100..=115).contains(&coarse), "{coarse}");
            // The sheet in the tangent frame of the floor's centre (vertex 12).
            let square = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .map(|(x, y)| Vec3::new(half * x, half * y, 0.4));
            let form_factor = projected_solid_angle(&square) / PI;
            assert!(
                (hb[12] - form_factor).abs() < 0.02,
                "frame {f}: {} vs {form_factor}",
                hb[12]
            );
        }
    }
}
