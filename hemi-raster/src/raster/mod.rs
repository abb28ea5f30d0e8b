//! Hemispherical rasterization of blocker triangles (Kautz et al. 2004,
//! §3.1.1) into a vertex's visibility mask: the plane look-up table
//! ([`PlaneLut`]), the receiver's tangent frame ([`TangentFrame`]), the
//! edge planes of a triangle and the culling they decide, and the scalar
//! rasterizer built from them ([`Rasterizer`]), which the throughput engine
//! reproduces bit for bit.
//!
//! # Why three edge planes are enough
//! In the receiver's tangent frame (origin at the receiver, z along its
//! normal) let a triangle have vertices a, b, c with det = a·(b×c) ≠ 0, so
//! that a, b, c are a basis. Any direction is d = αa + βb + γc, and
//! (b×c)·d = α det, (c×a)·d = β det, (a×b)·d = γ det. With the edge normals
//! multiplied by sign(det), d is on the positive side of all three planes iff
//! α, β, γ > 0: iff the ray t·d, t > 0, hits the triangle. That is a single
//! cone, not a double one (−d has all three coordinates negative), so the AND
//! of the three plane masks is exactly the set of disk pixels whose direction
//! hits the triangle; and since disk pixels are upper-hemisphere directions,
//! a triangle straddling the horizon covers exactly the directions toward its
//! part above the tangent plane, without clipping. Tests check both claims.
//!
//! Triangles with |det| ≤ 10⁻⁶·|a||b||c| (seen exactly edge-on, or through
//! the receiver) subtend no solid angle and are skipped.
//!
//! # Back-face culling
//! det > 0 means the receiver is behind the triangle's plane (the
//! counter-clockwise normal (b−a)×(c−a) has (b−a)×(c−a)·a = det). A ray that
//! leaves a point outside a closed mesh and hits one of its back faces has
//! crossed a front face first, so for closed meshes back faces can be dropped
//! without changing the mask (the paper's Table 2 counts back-face culling in
//! its blocker transform). For open meshes (a sheet of cloth, a floor) it would
//! let light through from behind, so it is per object (see
//! [`crate::BackfaceCulling`]).

use glam::Vec3;
use shadow_core::Result;

use crate::mask::{DiskGrid, Mask, MaskRow};

mod edges;
mod frame;
mod plane_table;

pub(crate) use edges::edge_planes;
pub use frame::TangentFrame;
pub use plane_table::PlaneLut;
pub(crate) use plane_table::{plane_code, row_code};

/// The disk grid and the plane table of one mask resolution: everything
/// needed to rasterize triangles into masks.
#[derive(Clone, Debug)]
pub struct Rasterizer<W: MaskRow> {
    grid: DiskGrid<W>,
    lut: PlaneLut<W>,
}

impl<W: MaskRow> Rasterizer<W> {
    /// Builds the plane table with `lut_resolution`² cells per cube face.
    pub fn new(lut_resolution: usize) -> Result<Rasterizer<W>> {
        let grid = DiskGrid::new();
        let lut = PlaneLut::new(&grid, lut_resolution)?;
        Ok(Rasterizer { grid, lut })
    }

    pub fn grid(&self) -> &DiskGrid<W> {
        &self.grid
    }

    pub fn lut(&self) -> &PlaneLut<W> {
        &self.lut
    }

    /// ORs triangle (a, b, c), given in tangent coordinates, into `mask`.
    /// Returns false when the triangle was culled: entirely below the horizon
    /// (all z ≤ 0), through the receiver (module docs), or back-facing while
    /// `cull_back_faces`. The reference the fast per-receiver loop is tested
    /// against.
    pub fn draw(&self, triangle: [Vec3; 3], cull_back_faces: bool, mask: &mut Mask<W>) -> bool {
        let planes = edge_planes(triangle, cull_back_faces);
        if !planes.kept {
            return false;
        }
        let [a, b, c] = planes.normals.map(|m| self.lut.lookup(m));
        *mask = mask.or(&a.and(&b).and(&c));
        true
    }

    /// The visibility mask at `frame` of world-space `triangles`: a
    /// convenience for single receivers; whole frames go through
    /// [`HemiRaster`](crate::HemiRaster).
    pub fn mask(
        &self,
        frame: &TangentFrame,
        triangles: &[[Vec3; 3]],
        cull_back_faces: bool,
    ) -> Mask<W> {
        let mut mask = Mask::EMPTY;
        for t in triangles {
            self.draw(t.map(|p| frame.to_local(p)), cull_back_faces, &mut mask);
        }
        mask
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{clip_above_horizon, projected_solid_angle};
    use std::f32::consts::PI;

    fn exact_cone<W: MaskRow>(grid: &DiskGrid<W>, tri: [Vec3; 3]) -> Mask<W> {
        // Directions whose ray hits the triangle, by ray casting per pixel.
        let [a, b, c] = tri;
        let n = (b - a).cross(c - a);
        let mut mask = Mask::EMPTY;
        for (r, col) in grid.disk().pixels() {
            let d = grid.direction(r, col);
            let denom = n.dot(d);
            if denom.abs() < 1e-12 {
                continue;
            }
            let t = n.dot(a) / denom;
            let p = t * d;
            let inside = (b - a).cross(p - a).dot(n) >= 0.0
                && (c - b).cross(p - b).dot(n) >= 0.0
                && (a - c).cross(p - c).dot(n) >= 0.0;
            if t > 0.0 && inside {
                mask.set(r, col);
            }
        }
        mask
    }

    fn triangles() -> Vec<[Vec3; 3]> {
        vec![
            [
                Vec3::new(-0.3, -0.2, 1.0),
                Vec3::new(0.4, -0.1, 0.8),
                Vec3::new(0.0, 0.5, 1.2),
            ],
            [
                Vec3::new(0.2, 0.1, 0.3),
                Vec3::new(1.5, -0.4, 0.6),
                Vec3::new(0.9, 0.8, 0.2),
            ],
            [
                Vec3::new(-2.0, 1.0, 0.4),
                Vec3::new(-1.0, -1.5, 1.5),
                Vec3::new(-0.1, 0.2, 2.0),
            ],
            [
                Vec3::new(-1.0, -1.0, 0.5),
                Vec3::new(1.0, -1.0, 0.5),
                Vec3::new(0.0, 1.0, 0.5),
            ],
        ]
    }

    /// The AND of the three plane masks is the single cone over the triangle,
    /// for both windings; only LUT quantization separates it from ray casting.
    #[test]
    fn edge_planes_give_the_cone_for_both_windings() {
        let raster = Rasterizer::<u32>::new(128).unwrap();
        for tri in triangles() {
            let truth = exact_cone(raster.grid(), tri);
            for t in [tri, [tri[0], tri[2], tri[1]]] {
                let mut mask = Mask::EMPTY;
                assert!(raster.draw(t, false, &mut mask));
                let diff = mask.and_not(&truth).count() + truth.and_not(&mask).count();
                assert!(diff <= 12, "{diff} of {} pixels differ", truth.count());
            }
            // The mirrored triangle (below the horizon) covers nothing.
            let mut below = Mask::EMPTY;
            assert!(!raster.draw(tri.map(|p| -p), false, &mut below));
            assert!(below.is_empty());
        }
    }

    /// A triangle straddling the tangent plane covers its upper part only.
    #[test]
    fn straddling_triangle_covers_its_upper_part() {
        let raster = Rasterizer::<u64>::new(256).unwrap();
        let tri = [
            Vec3::new(-0.8, 0.3, -0.4),
            Vec3::new(0.9, -0.2, 0.7),
            Vec3::new(0.1, 1.0, 0.6),
        ];
        let mut mask = Mask::EMPTY;
        assert!(raster.draw(tri, false, &mut mask));
        let upper = clip_above_horizon(&tri);
        let exact = projected_solid_angle(&upper);
        let whole_abs = projected_solid_angle(&tri);
        let got = raster.grid().coverage(&mask);
        assert!(
            (got - exact).abs() < 0.01 * PI,
            "coverage {got}, upper part {exact}, unclipped formula {whole_abs}"
        );
    }

    #[test]
    fn triangles_through_the_receiver_and_back_faces_are_culled() {
        let raster = Rasterizer::<u32>::new(32).unwrap();
        let mut mask = Mask::EMPTY;
        // Shares the origin.
        assert!(!raster.draw(
            [
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 1.0, 1.0)
            ],
            false,
            &mut mask
        ));
        // In a plane through the origin.
        assert!(!raster.draw(
            [
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(2.0, 0.0, 2.0),
                Vec3::new(0.0, 0.0, 1.0)
            ],
            false,
            &mut mask
        ));
        assert!(mask.is_empty());
        // Seen from below, counter-clockwise from above: a back face.
        let back = [
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        assert!(!raster.draw(back, true, &mut mask));
        assert!(raster.draw([back[0], back[2], back[1]], true, &mut mask));
        assert!(raster.draw(back, false, &mut mask));
    }

    /// Mean and worst |coverage − exact| / π over `tris` at one resolution.
    fn coverage_errors<W: MaskRow>(lut_resolution: usize, tris: &[[Vec3; 3]]) -> (f32, f32) {
        let raster = Rasterizer::<W>::new(lut_resolution).unwrap();
        let errors: Vec<f32> = tris
            .iter()
            .map(|&tri| {
                let mut mask = Mask::EMPTY;
                raster.draw(tri, false, &mut mask);
                (raster.grid().coverage(&mask) - projected_solid_angle(&tri)).abs() / PI
            })
            .collect();
        let mean = errors.iter().sum::<f32>() / errors.len() as f32;
        (mean, errors.iter().fold(0.0f32, |m, &e| m.max(e)))
    }

    /// Coverage (set pixels × weight) against π × Lambert's form factor, and
    /// its convergence as the mask and the table grow together.
    #[test]
    fn coverage_matches_the_form_factor_and_converges() {
        let mut tris = triangles();
        // More shapes: thin, near the horizon, large.
        for k in 0..12 {
            let t = k as f32;
            let c = Vec3::new(
                (t * 1.3).sin(),
                (t * 0.7).cos(),
                0.3 + 0.25 * (t * 0.9).sin().abs(),
            );
            tris.push([
                c + Vec3::new(0.5 * (t * 2.1).cos(), 0.4 * (t * 1.1).sin(), 0.1),
                c + Vec3::new(-0.4, 0.3 * (t * 0.5).cos(), 0.2 * (t * 1.7).sin()),
                c + Vec3::new(0.2 * (t * 3.1).sin(), -0.5, 0.4),
            ]);
        }
        let e16 = coverage_errors::<u16>(64, &tris);
        let e32 = coverage_errors::<u32>(128, &tris);
        let e64 = coverage_errors::<u64>(256, &tris);
        eprintln!("coverage error / π (mean, max): 16: {e16:?}, 32: {e32:?}, 64: {e64:?}");
        // Measured: 0.72% / 3.4%, 0.17% / 1.0%, 0.068% / 0.47%.
        assert!(e16.0 < 0.01 && e16.1 < 0.05, "{e16:?}");
        assert!(e32.0 < 0.003 && e32.1 < 0.015, "{e32:?}");
        assert!(e64.0 < 0.0012 && e64.1 < 0.007, "{e64:?}");
        assert!(e64.0 < e32.0 && e32.0 < e16.0);
        // A coarse table spoils a fine mask: the table must grow with it.
        let coarse = coverage_errors::<u64>(16, &tris);
        eprintln!("64×64 mask with a 6×16×16 table: {coarse:?}");
        assert!(coarse.0 > e64.0);
    }

    /// Occluder fusion: two overlapping triangles cover their union once, not
    /// the sum of their areas.
    #[test]
    fn overlapping_triangles_cover_their_union() {
        let raster = Rasterizer::<u64>::new(256).unwrap();
        let at = |x: f32, y: f32| Vec3::new(0.4 * (x - 1.0), 0.4 * (y - 1.0) + 0.1, 0.7);
        let t1 = [at(0.0, 0.0), at(2.0, 0.0), at(0.0, 2.0)];
        let t2 = [at(0.0, 0.0), at(2.0, 0.0), at(2.0, 2.0)];
        let union = [
            at(0.0, 0.0),
            at(2.0, 0.0),
            at(2.0, 2.0),
            at(1.0, 1.0),
            at(0.0, 2.0),
        ];
        let overlap = [at(0.0, 0.0), at(2.0, 0.0), at(1.0, 1.0)];
        let (mut m1, mut m2, mut both) = (Mask::EMPTY, Mask::EMPTY, Mask::EMPTY);
        raster.draw(t1, false, &mut m1);
        raster.draw(t2, false, &mut m2);
        raster.draw(t1, false, &mut both);
        raster.draw(t2, false, &mut both);
        assert_eq!(both, m1.or(&m2));
        let g = raster.grid();
        let got = g.coverage(&both);
        assert!(got < g.coverage(&m1) + g.coverage(&m2));
        let exact = projected_solid_angle(&union);
        assert!((got - exact).abs() < 0.004 * PI, "{got} vs {exact}");
        let shared = g.coverage(&m1.and(&m2));
        let exact_overlap = projected_solid_angle(&overlap);
        assert!(
            (shared - exact_overlap).abs() < 0.004 * PI,
            "{shared} vs {exact_overlap}"
        );
        // A quad split along its diagonal covers the quad.
        let quad = [at(0.0, 0.0), at(2.0, 0.0), at(2.0, 2.0), at(0.0, 2.0)];
        let mut halves = Mask::EMPTY;
        raster.draw([quad[0], quad[1], quad[2]], false, &mut halves);
        raster.draw([quad[0], quad[2], quad[3]], false, &mut halves);
        let exact = projected_solid_angle(&quad);
        assert!((g.coverage(&halves) - exact).abs() < 0.004 * PI);
    }
}
