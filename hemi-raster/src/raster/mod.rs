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
//! # A triangle through the receiver
//! A triangle whose plane passes through the receiver subtends no solid
//! angle, and the three planes no longer bound a cone. The paper draws
//! nothing for it; but where two surfaces meet, the floor under a box's
//! side or the floor at the foot of a wall, that triangle is what blocks
//! the lower half of the receiver's hemisphere: in the limit from the
//! surface beside the vertex, any point of the face sees the floor below
//! it. So a triangle whose plane passes through the receiver or just in
//! front of it (the receiver on the plane or behind it by at most its
//! *contact reach*, a quarter of its lift, [`TangentFrame::contact`]),
//! whose extent covers the receiver's foot on that plane (within the same
//! reach of its edges), and which shows above the horizon, blocks the
//! half-space of directions that see its front face, d·n < 0 with
//! n = (b − a) × (c − a): one plane mask, drawn as the AND of that plane
//! three times. Where the foot lies on an edge (within the reach), only the
//! directions whose trace on the plane, leaving the foot, enters the
//! triangle across it: the edge's plane is replaced by the one through n
//! and the edge, so that the end of a wall on the floor blocks the quarter
//! toward the wall and a box's corner the quadrant of the box, not a half
//! for each face (shadow-core's `ContactCone`). That is the limit the Monte-Carlo reference takes, whose
//! shadow rays back up half a lift ε along themselves and count a hit
//! nearer than ε only on a front face
//! ([`SceneBvh::unoccluded_from`](shadow_core::bvh::SceneBvh::unoccluded_from)):
//! from a plane |h| behind the receiver its back face counts only for the
//! directions within asin(2|h|/ε) of the plane, none at h = 0, the half of
//! its back that a cone covers at |h| = ε/2. The reach splits that
//! transition at its middle, |h| = ε/4: nearer, the front half alone;
//! farther, the cone alone (a face folded back under the vertex, whose
//! back the reference sees).
//!
//! Anywhere else off the plane, however close, the receiver is given the
//! cone: as it nears the plane the three edge planes tend to the
//! triangle's own, and the cone to the half-space over the triangle's
//! extent (at a concave crease the faces meeting at the vertex cover only
//! their wedges; a face folded back under the vertex, its foot just beside
//! it, still covers most of the half behind it). A triangle exactly through
//! the receiver that does not cover its foot (seen exactly edge-on)
//! subtends no solid angle and is skipped, and one wholly below the horizon
//! is culled as any other (a coarse chord under the receiver's own
//! surface). No triangle is culled for being small or far: a far, dense
//! mesh of tiny triangles covers its pixels as one of large ones does.
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

    /// ORs triangle (a, b, c), given in tangent coordinates, into `mask`,
    /// for a receiver of contact reach `contact`
    /// ([`TangentFrame::contact`]). Returns false when the triangle was
    /// culled: entirely below the horizon (all z ≤ 0), through the receiver
    /// beside it (module docs), or back-facing while `cull_back_faces`. The
    /// reference the fast per-receiver loop is tested against.
    pub fn draw(
        &self,
        triangle: [Vec3; 3],
        cull_back_faces: bool,
        contact: f32,
        mask: &mut Mask<W>,
    ) -> bool {
        let planes = edge_planes(triangle, cull_back_faces, contact);
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
            let local = t.map(|p| frame.to_local(p));
            self.draw(local, cull_back_faces, frame.contact(), &mut mask);
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
                assert!(raster.draw(t, false, 0.0, &mut mask));
                let diff = mask.and_not(&truth).count() + truth.and_not(&mask).count();
                assert!(diff <= 12, "{diff} of {} pixels differ", truth.count());
            }
            // The mirrored triangle (below the horizon) covers nothing.
            let mut below = Mask::EMPTY;
            assert!(!raster.draw(tri.map(|p| -p), false, 0.0, &mut below));
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
        assert!(raster.draw(tri, false, 0.0, &mut mask));
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
    fn triangles_through_the_receiver_beside_it_and_back_faces_are_culled() {
        let raster = Rasterizer::<u32>::new(32).unwrap();
        let mut mask = Mask::EMPTY;
        // In a plane through the origin, beside it.
        assert!(!raster.draw(
            [
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(2.0, 0.0, 2.0),
                Vec3::new(0.0, 0.0, 1.0)
            ],
            false,
            0.0,
            &mut mask
        ));
        // Exactly through the origin, beside it, within any reach.
        assert!(!raster.draw(
            [
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(2.0, 0.0, 2.0)
            ],
            false,
            1e-3,
            &mut mask
        ));
        assert!(mask.is_empty());
        // Seen from below, counter-clockwise from above: a back face.
        let back = [
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        assert!(!raster.draw(back, true, 0.0, &mut mask));
        assert!(raster.draw([back[0], back[2], back[1]], true, 0.0, &mut mask));
        assert!(raster.draw(back, false, 0.0, &mut mask));
    }

    /// A floor triangle through the receiver, under it (a box's side
    /// standing on the floor, z along the side's outward normal, y up):
    /// it blocks exactly the directions that see its front, those below
    /// the floor, from within the contact reach either side of its plane,
    /// whichever way the triangle winds; beyond the reach it is drawn as
    /// the cone it subtends.
    #[test]
    fn a_triangle_through_the_receiver_blocks_the_half_that_sees_its_front() {
        let raster = Rasterizer::<u64>::new(256).unwrap();
        let grid = raster.grid();
        // The floor's front faces +y: counter-clockwise seen from above.
        let floor = |y: f32| {
            [
                Vec3::new(-3.0, y, -1.0),
                Vec3::new(0.0, y, 3.0),
                Vec3::new(3.0, y, -1.0),
            ]
        };
        let below = |mask: &Mask<u64>| {
            let mut exact = Mask::EMPTY;
            for (r, c) in grid.disk().pixels() {
                if grid.direction(r, c).y < 0.0 {
                    exact.set(r, c);
                }
            }
            mask.and_not(&exact).count() + exact.and_not(mask).count()
        };
        let reach = 1e-3;
        for y in [0.0, 0.5e-3, -0.9e-3] {
            let mut mask = Mask::EMPTY;
            assert!(raster.draw(floor(y), true, reach, &mut mask), "{y}");
            // Only the pixels the plane's offset tilts: none at this size.
            assert!(below(&mask) <= 2 * 64, "{y}: {} pixels off", below(&mask));
            assert!((grid.coverage(&mask) / PI - 0.5).abs() < 0.02, "{y}");
        }
        // Wound the other way, the floor's front faces down: it blocks what
        // sees that front, the upper half, none of the lower.
        let [a, b, c] = floor(0.0);
        let mut up = Mask::EMPTY;
        assert!(raster.draw([a, c, b], false, reach, &mut up));
        assert!(
            up.and(&{
                let mut m = Mask::EMPTY;
                raster.draw(floor(0.0), false, reach, &mut m);
                m
            })
            .is_empty()
        );
        // Beyond the reach, below the floor's plane: the cone from below,
        // the floor's back face, culled with back faces.
        let mut far = Mask::EMPTY;
        assert!(!raster.draw(floor(2e-3), true, reach, &mut far));
        assert!(raster.draw(floor(2e-3), false, reach, &mut far));
        assert!(grid.coverage(&far) / PI > 0.45);
        // The receiver's foot twice the reach outside an edge: nothing.
        let beside = [
            Vec3::new(-3.0, 0.0, 2e-3),
            Vec3::new(0.0, 0.0, 3.0),
            Vec3::new(3.0, 0.0, 2e-3),
        ];
        let mut outside = Mask::EMPTY;
        assert!(!raster.draw(beside, false, reach, &mut outside));
    }

    /// Mean and worst |coverage − exact| / π over `tris` at one resolution.
    fn coverage_errors<W: MaskRow>(lut_resolution: usize, tris: &[[Vec3; 3]]) -> (f32, f32) {
        let raster = Rasterizer::<W>::new(lut_resolution).unwrap();
        let errors: Vec<f32> = tris
            .iter()
            .map(|&tri| {
                let mut mask = Mask::EMPTY;
                raster.draw(tri, false, 0.0, &mut mask);
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

    /// A far strip of triangles each smaller than a millionth of their
    /// squared distance (which a culling threshold on |det| / (|a||b||c|)
    /// dropped, letting the sky through the whole strip) covers what the
    /// strip as two triangles covers.
    #[test]
    fn dense_meshes_of_tiny_triangles_block_as_coarse_ones_do() {
        let raster = Rasterizer::<u32>::new(128).unwrap();
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::Z);
        let (x0, y0, width, length, height) = (-0.1f32, -1.2f32, 0.2f32, 2.4f32, 2.0f32);
        let cell = 2e-3f32;
        let (nx, ny) = ((width / cell) as usize, (length / cell) as usize);
        let at = |i: usize, j: usize| Vec3::new(x0 + i as f32 * cell, y0 + j as f32 * cell, height);
        let mut dense = Vec::with_capacity(2 * nx * ny);
        for i in 0..nx {
            for j in 0..ny {
                dense.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                dense.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        // Every triangle under the old threshold: |det| / (|a||b||c|).
        let [a, b, c] = dense[0];
        assert!(a.cross(b).dot(c).abs() / (a.length() * b.length() * c.length()) < 1e-6);
        let two = [
            [at(0, 0), at(nx, 0), at(nx, ny)],
            [at(0, 0), at(nx, ny), at(0, ny)],
        ];
        let (fine, coarse) = (
            raster.mask(&frame, &dense, false),
            raster.mask(&frame, &two, false),
        );
        let differ = fine.and_not(&coarse).count() + coarse.and_not(&fine).count();
        assert!(coarse.count() > 20, "{}", coarse.count());
        // Measured: none of 32 pixels (a pixel centre on a shared edge may
        // fall to either side).
        assert!(differ <= 2, "{differ} of {} pixels differ", coarse.count());
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
        raster.draw(t1, false, 0.0, &mut m1);
        raster.draw(t2, false, 0.0, &mut m2);
        raster.draw(t1, false, 0.0, &mut both);
        raster.draw(t2, false, 0.0, &mut both);
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
        raster.draw([quad[0], quad[1], quad[2]], false, 0.0, &mut halves);
        raster.draw([quad[0], quad[2], quad[3]], false, 0.0, &mut halves);
        let exact = projected_solid_angle(&quad);
        assert!((g.coverage(&halves) - exact).abs() < 0.004 * PI);
    }
}
