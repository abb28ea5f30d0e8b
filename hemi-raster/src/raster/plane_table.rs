//! The plane look-up table of Kautz et al. 2004, §3.1.1: for a discrete set of
//! planes through the origin of the tangent frame, the mask of the disk pixels
//! whose hemisphere direction lies on the positive side. Rasterizing a
//! triangle is then three look-ups and a bitwise AND.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use shadow_core::Result;

use crate::config::check_plane_table;
use crate::mask::{DiskGrid, Mask, MaskRow};

/// Plane masks indexed by a cube-map parameterization of the plane normal
/// m (§3.1.1): the face is the axis a of m's largest component, and the cell
/// is (⌊(u+1)/2·N⌋, ⌊(v+1)/2·N⌋) for u = m_{a+1}/|m_a|, v = m_{a+2}/|m_a|
/// (axes cyclic). Each entry is the mask of its cell's centre normal.
///
/// # A quarter of the paper's table
/// The paper stores all 6×N² cells (12 MB for 32×32 masks at N = 128). Two
/// symmetries of the disk grid, both exact on its pixel centres, cut that to
/// a quarter, so that at N = 128 the table is 3 MB rather than 12 and more of
/// it stays in cache, where the look-ups spend most of the loop's time:
/// - the opposite normal −m gives the complement within the disk, so
///   normals with m_x < 0 are looked up as −m;
/// - mirroring y (m_y → −m_y) mirrors the mask top to bottom, so normals with
///   m_y < 0 are looked up mirrored. Masks store their rows folded (see
///   [`Mask`]) so that this mirror is a swap of the two halves of storage:
///   free in the per-receiver loop.
///
/// What is stored is thus every cell that a normal with m_x ≥ 0, m_y ≥ 0
/// reaches: half of the +x face, half of the +y face, and two quadrants of
/// the +z face (the −z face being the complement of the mirrored +z cell, as
/// before). Every cell keeps its centre normal, so the answers are those of
/// the full table up to which side of a cell boundary a normal lands on.
///
/// The three positive faces are laid out whole, cell (face, i, j) at
/// (face·N + j)·N + i, so that finding a cell is two multiply-adds in the
/// per-receiver loop; the unreached half of that range is allocated zeroed
/// and never written, so the operating system never maps it: the table
/// occupies 3 MB of memory at N = 128, as [`PlaneLut::bytes`] reports.
#[derive(Clone, Debug)]
pub struct PlaneLut<W: MaskRow> {
    resolution: usize,
    disk: Mask<W>,
    /// The stored masks' rows, one mask after another, each in the folded
    /// order of [`Mask::storage_row`].
    rows: Vec<W>,
    build_time: Duration,
}

impl<W: MaskRow> PlaneLut<W> {
    /// Builds the table with `resolution`² cells per cube face (an even
    /// number), in parallel. Fails if `resolution` is zero or odd, or the
    /// table would exceed 1 GiB.
    pub fn new(grid: &DiskGrid<W>, resolution: usize) -> Result<PlaneLut<W>> {
        check_plane_table(W::RESOLUTION, resolution)?;
        let start = Instant::now();
        let pixels: Vec<(usize, usize, Vec3)> = grid
            .disk()
            .pixels()
            .map(|(r, c)| (r, c, grid.direction(r, c)))
            .collect();
        let n = resolution as u32;
        // Zeroed, so the unreached cells are never touched (struct docs).
        let mut rows = vec![W::ZERO; 3 * resolution * resolution * W::RESOLUTION];
        rows.par_chunks_exact_mut(W::RESOLUTION)
            .enumerate()
            .filter_map(|(index, rows)| {
                let index = index as u32;
                let (face, j, i) = (index / (n * n), index / n % n, index % n);
                reached(face, i, j, n).then_some((face, i, j, rows))
            })
            .for_each(|(face, i, j, rows)| {
                let m = cell_normal(face as usize, i as usize, j as usize, resolution);
                let mut mask = Mask::<W>::EMPTY;
                for &(r, c, d) in &pixels {
                    if m.dot(d) > 0.0 {
                        mask.set(r, c);
                    }
                }
                rows.copy_from_slice(mask.rows());
            });
        Ok(PlaneLut {
            resolution,
            disk: *grid.disk(),
            rows,
            build_time: start.elapsed(),
        })
    }

    /// Cells per side of a cube face.
    pub fn resolution(&self) -> usize {
        self.resolution
    }

    /// Wall-clock time the table took to build.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Memory the stored masks occupy, in bytes (the cells a normal can
    /// reach; struct docs).
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.rows.as_slice()) / 2
    }

    /// The disk pixels on the positive side of the plane through the origin
    /// with normal `m` (any length, non-zero and finite), quantized to the
    /// table's cell. A zero or non-finite `m` gives the empty mask.
    pub fn lookup(&self, m: Vec3) -> Mask<W> {
        if !m.is_finite() || m == Vec3::ZERO {
            return Mask::EMPTY;
        }
        let code = plane_code(m, self.resolution as u32);
        let mut stored = Mask::EMPTY;
        let index = (code >> 2) as usize * W::RESOLUTION;
        stored
            .rows_mut()
            .copy_from_slice(&self.rows[index..index + W::RESOLUTION]);
        let mirrored = if code & 2 != 0 {
            stored.mirrored()
        } else {
            stored
        };
        if code & 1 != 0 {
            self.disk.and_not(&mirrored)
        } else {
            mirrored
        }
    }

    /// The rows of every stored mask, one after another: mask `index` (a
    /// [`plane_code`] shifted right by two) is at `index · RESOLUTION`.
    #[inline(always)]
    pub(crate) fn rows(&self) -> &[W] {
        &self.rows
    }

    /// The disk pixels.
    pub(crate) fn disk(&self) -> &Mask<W> {
        &self.disk
    }
}

/// Where the mask of plane normal `m` (non-zero and finite; anything else
/// gives an arbitrary code) is in a table of `resolution`² cells per face:
/// `index << 2 | mirror << 1 | complement`. The mask is the stored mask
/// `index`, mirrored top to bottom if `mirror`, complemented within the disk
/// if `complement` ([`PlaneLut`] docs).
///
/// Written without branches or indexing by a variable axis, so that the
/// per-receiver loop computes 16 codes at once; [`PlaneLut::lookup`] uses it
/// too, so both pick the same cells bit for bit.
#[inline(always)]
#[allow(unsafe_code)]
pub(crate) fn plane_code(m: Vec3, resolution: u32) -> u32 {
    // Into the stored quarter: m_x ≥ 0 by negation, then m_y ≥ 0 by mirror.
    let negated = m.x < 0.0;
    let q = if negated { -m } else { m };
    let mirror = q.y < 0.0;
    let p = Vec3::new(q.x, q.y.abs(), q.z);
    let abs = p.abs();
    let x_major = (abs.x >= abs.y) & (abs.x >= abs.z);
    let y_major = !x_major & (abs.y >= abs.z);
    let (face, major, u, v) = if x_major {
        (0, p.x, p.y, p.z)
    } else if y_major {
        (1, p.y, p.z, p.x)
    } else {
        (2, p.z, p.x, p.y)
    };
    let inv = 1.0 / major.abs();
    let (n, last) = (resolution as f32, (resolution - 1) as f32);
    // Clamped in float (`max` maps NaN to 0), then truncated: the plain
    // conversion vectorizes where Rust's saturating `as` does not.
    let cell = |t: f32| {
        let x = ((t * inv + 1.0) * 0.5 * n).max(0.0).min(last);
        // SAFETY: `max` maps NaN and −∞ to 0 and `min` maps +∞ to `last`,
        // so x is finite and in [0, resolution − 1], which u32 holds.
        unsafe { x.to_int_unchecked::<u32>() }
    };
    let (i, j) = (cell(u), cell(v));
    // A normal on the −z face (the only negative face left) is the
    // complement of the mirrored +z cell; its centre is the negated centre.
    let below = major < 0.0;
    let last = resolution - 1;
    let (i, j) = if below { (last - i, last - j) } else { (i, j) };
    let index = (face * resolution + j) * resolution + i;
    (index << 2) | (u32::from(mirror) << 1) | u32::from(negated ^ below)
}

/// A [`plane_code`] as the per-receiver loop looks it up:
/// `top << 1 | complement`, `top` being where in [`PlaneLut::rows`] the
/// `R/2` stored rows of the mask's top half start. Its bottom half starts at
/// `top ^ R/2`: a mask's rows start at a multiple of R, and the mirror swaps
/// its two halves of storage ([`Mask::storage_row`]).
#[inline(always)]
pub(crate) fn row_code<W: MaskRow>(code: u32) -> u32 {
    let rows = W::RESOLUTION as u32;
    let top = (code >> 2) * rows + ((code >> 1) & 1) * (rows / 2);
    (top << 1) | (code & 1)
}

/// Whether a normal in the stored quarter (m_x ≥ 0, m_y ≥ 0, the −z face
/// folded onto +z) can land in positive-face cell (`face`, i, j): +x cells
/// with i ≥ N/2, +y cells with j ≥ N/2, +z cells with i and j on the same
/// side of N/2.
fn reached(face: u32, i: u32, j: u32, n: u32) -> bool {
    let half = n / 2;
    match face {
        0 => i >= half,
        1 => j >= half,
        _ => (i >= half) == (j >= half),
    }
}

/// The unit normal at the centre of cell (i, j) of positive face `face`.
fn cell_normal(face: usize, i: usize, j: usize, resolution: usize) -> Vec3 {
    let n = resolution as f32;
    let mut m = Vec3::ZERO;
    m[face] = 1.0;
    m[(face + 1) % 3] = -1.0 + (2 * i + 1) as f32 / n;
    m[(face + 2) % 3] = -1.0 + (2 * j + 1) as f32 / n;
    m.normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact mask of a plane, pixel by pixel.
    fn exact<W: MaskRow>(grid: &DiskGrid<W>, m: Vec3) -> Mask<W> {
        let mut mask = Mask::EMPTY;
        for (r, c) in grid.disk().pixels() {
            if m.dot(grid.direction(r, c)) > 0.0 {
                mask.set(r, c);
            }
        }
        mask
    }

    #[test]
    fn lookups_match_exact_planes_up_to_quantization() {
        let grid = DiskGrid::<u32>::new();
        let lut = PlaneLut::new(&grid, 128).unwrap();
        assert_eq!(lut.bytes(), 3 * 128 * 128 / 2 * 128);
        // Axis-aligned normals sit on cell corners or centres: the horizon
        // plane (normal +z) holds the whole disk, −z none of it.
        assert_eq!(lut.lookup(Vec3::Z), *grid.disk());
        assert!(lut.lookup(-Vec3::Z).is_empty());
        let mut worst = 0;
        for k in 0..200 {
            let t = k as f32 * 0.731;
            let m = Vec3::new(t.sin() * 1.3, (t * 1.7).cos(), (t * 0.37).sin() - 0.2);
            let looked = lut.lookup(m);
            let truth = exact(&grid, m);
            let diff = looked.and_not(&truth).count() + truth.and_not(&looked).count();
            worst = worst.max(diff);
            // Opposite normals give complementary masks (ties on the plane aside).
            let opposite = lut.lookup(-m);
            assert!(opposite.and(&looked).count() <= 1);
            assert!(opposite.or(&looked).count() + 1 >= grid.disk().count());
        }
        // A plane's trace crosses ~32 pixels; quantization moves a few.
        assert!(worst <= 8, "{worst} pixels differ");
        assert!(lut.lookup(Vec3::ZERO).is_empty());
        assert!(lut.lookup(Vec3::NAN).is_empty());
    }

    /// The reached cells are the quarter the symmetries leave, and the code
    /// of each one's centre normal (and of its mirror images) finds it.
    #[test]
    fn reached_cells_and_codes_agree() {
        for n in [2u32, 8, 128] {
            let mut reached_cells = 0;
            for face in 0..3 {
                for j in 0..n {
                    for i in 0..n {
                        if !reached(face, i, j, n) {
                            continue;
                        }
                        reached_cells += 1;
                        let index = (face * n + j) * n + i;
                        let m = cell_normal(face as usize, i as usize, j as usize, n as usize);
                        assert_eq!(plane_code(m, n), index << 2, "n {n}");
                        let mirrored = Vec3::new(m.x, -m.y, m.z);
                        if m.y != 0.0 {
                            assert_eq!(plane_code(mirrored, n), index << 2 | 2);
                        }
                        if m.x != 0.0 {
                            assert_eq!(plane_code(-m, n), index << 2 | 1);
                        }
                    }
                }
            }
            assert_eq!(reached_cells, 3 * n * n / 2);
        }
    }

    #[test]
    fn bad_resolutions_are_errors() {
        let grid = DiskGrid::<u64>::new();
        assert!(PlaneLut::new(&grid, 0).is_err());
        assert!(PlaneLut::new(&grid, 63).is_err());
        assert!(PlaneLut::new(&grid, 1 << 20).is_err());
    }
}
