//! The plane look-up table of Kautz et al. 2004, §3.1.1: for a discrete set of
//! planes through the origin of the tangent frame, the mask of the disk pixels
//! whose hemisphere direction lies on the positive side. Rasterizing a
//! triangle is then three look-ups and a bitwise AND.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use shadow_core::{Error, Result};

use crate::disk::DiskGrid;
use crate::mask::{Mask, MaskRow};

/// The largest table accepted (bytes); bigger ones are configuration
/// mistakes rather than useful accuracy.
const MAX_BYTES: usize = 1 << 30;

/// Plane masks indexed by a cube-map parameterization of the plane normal
/// m: the face is the axis a of m's largest component, and the cell is
/// (⌊(u+1)/2·N⌋, ⌊(v+1)/2·N⌋) for u = m_{a+1}/|m_a|, v = m_{a+2}/|m_a|
/// (axes cyclic). Each entry is the mask of the cell's centre normal.
///
/// Only the three positive faces are stored: the opposite normal −m falls in
/// the mirrored cell of the negative face, whose centre is exactly the
/// negated centre, so its mask is the complement within the disk. The paper's
/// 6×128×128 table of 32×32 masks (12 MB) is thus 6 MB here.
#[derive(Clone, Debug)]
pub struct PlaneLut<W: MaskRow> {
    resolution: usize,
    disk: Mask<W>,
    /// The empty mask, to flip nothing by reference.
    empty: Mask<W>,
    masks: Vec<Mask<W>>,
    build_time: Duration,
}

impl<W: MaskRow> PlaneLut<W> {
    /// Builds the table with `resolution`² cells per cube face, in parallel.
    /// Fails if `resolution` is zero or the table would exceed 1 GiB.
    pub fn new(grid: &DiskGrid<W>, resolution: usize) -> Result<PlaneLut<W>> {
        let bytes = 3usize
            .checked_mul(resolution)
            .and_then(|n| n.checked_mul(resolution))
            .and_then(|n| n.checked_mul(std::mem::size_of::<Mask<W>>()));
        if resolution == 0 || bytes.is_none_or(|b| b > MAX_BYTES) {
            return Err(Error::Stage {
                method: "hemi-raster".into(),
                what: format!(
                    "plane LUT resolution {resolution} per cube face must be at least 1 and \
                     give a table of at most 1 GiB for {0}×{0} masks",
                    W::RESOLUTION
                ),
            });
        }
        let start = Instant::now();
        let pixels: Vec<(usize, usize, Vec3)> = grid
            .disk()
            .pixels()
            .map(|(r, c)| (r, c, grid.direction(r, c)))
            .collect();
        let mut masks = vec![Mask::EMPTY; 3 * resolution * resolution];
        masks
            .par_chunks_mut(resolution)
            .enumerate()
            .for_each(|(face_row, row)| {
                let (face, j) = (face_row / resolution, face_row % resolution);
                for (i, mask) in row.iter_mut().enumerate() {
                    let m = cell_normal(face, i, j, resolution);
                    for &(r, c, d) in &pixels {
                        if m.dot(d) > 0.0 {
                            mask.set(r, c);
                        }
                    }
                }
            });
        Ok(PlaneLut {
            resolution,
            disk: *grid.disk(),
            empty: Mask::EMPTY,
            masks,
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

    /// Memory held by the masks, in bytes.
    pub fn bytes(&self) -> usize {
        self.masks.len() * std::mem::size_of::<Mask<W>>()
    }

    /// The disk pixels on the positive side of the plane through the origin
    /// with normal `m` (any length, non-zero and finite), quantized to the
    /// table's cell. A zero or non-finite `m` gives the empty mask.
    pub fn lookup(&self, m: Vec3) -> Mask<W> {
        match self.entry(m) {
            None => Mask::EMPTY,
            Some((mask, flip)) => {
                let mut out = Mask::EMPTY;
                out.or_and3_xor(
                    [mask, &self.disk, &self.disk],
                    [flip, &self.empty, &self.empty],
                );
                out
            }
        }
    }

    /// [`PlaneLut::lookup`] without copying: the stored mask `e` and a mask
    /// `f` such that the answer is `e XOR f` (f is the disk for normals on
    /// the negative faces, whose masks are complements, and empty
    /// otherwise). `None` for a zero or non-finite `m`.
    pub fn entry(&self, m: Vec3) -> Option<(&Mask<W>, &Mask<W>)> {
        if !m.is_finite() || m == Vec3::ZERO {
            return None;
        }
        let code = cell_code(m, self.resolution as u32);
        let flip = if code & 1 == 1 {
            &self.disk
        } else {
            &self.empty
        };
        Some((self.mask((code >> 1) as usize), flip))
    }

    /// Stored mask `index` (the code of [`cell_code`] shifted right by one).
    #[inline(always)]
    pub(crate) fn mask(&self, index: usize) -> &Mask<W> {
        &self.masks[index]
    }

    /// The disk pixels: the complement of a stored mask is taken within it.
    pub(crate) fn disk(&self) -> &Mask<W> {
        &self.disk
    }
}

/// The cell of plane normal `m` (non-zero and finite; anything else gives
/// an arbitrary code) in a table of `resolution`² cells per face, encoded as
/// `index << 1 | complement`: `index` is the stored mask of the cell (on a
/// positive face) and `complement` says whether `m` lies on the negative face,
/// whose mask is the complement of the mirrored positive cell's.
///
/// The face is the axis a of m's largest component, the cell
/// (⌊(u+1)/2·N⌋, ⌊(v+1)/2·N⌋) for u = m_{a+1}/|m_a|, v = m_{a+2}/|m_a| (axes
/// cyclic). Written without branches or indexing by a variable axis, so that
/// the per-receiver loop computes 16 codes at once; [`PlaneLut::entry`] uses
/// it too, so both paths pick the same cells bit for bit.
#[inline(always)]
pub(crate) fn cell_code(m: Vec3, resolution: u32) -> u32 {
    let abs = m.abs();
    let x_major = (abs.x >= abs.y) & (abs.x >= abs.z);
    let y_major = !x_major & (abs.y >= abs.z);
    let (face, major, u, v) = if x_major {
        (0, m.x, m.y, m.z)
    } else if y_major {
        (1, m.y, m.z, m.x)
    } else {
        (2, m.z, m.x, m.y)
    };
    let inv = 1.0 / major.abs();
    let (n, last) = (resolution as f32, resolution as i32 - 1);
    // Saturating casts: NaN and out-of-range lanes land in a valid cell.
    let cell = |t: f32| ((((t * inv + 1.0) * 0.5 * n) as i32).clamp(0, last)) as u32;
    let (i, j) = (cell(u), cell(v));
    let negative = major < 0.0;
    // −m is in cell (N−1−i, N−1−j) of the positive face.
    let last = resolution - 1;
    let (i, j) = if negative {
        (last - i, last - j)
    } else {
        (i, j)
    };
    (((face * resolution + j) * resolution + i) << 1) | u32::from(negative)
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
        assert_eq!(lut.bytes(), 3 * 128 * 128 * 128);
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

    #[test]
    fn bad_resolutions_are_errors() {
        let grid = DiskGrid::<u64>::new();
        assert!(PlaneLut::new(&grid, 0).is_err());
        assert!(PlaneLut::new(&grid, 1 << 20).is_err());
    }
}
