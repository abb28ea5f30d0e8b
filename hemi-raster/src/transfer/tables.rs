//! The SH basis over the disk, tabled in the tangent frame, and the
//! Lambert transfer summed from it (module docs of [`crate::transfer`]).
//!
//! The paper evaluates the basis per block at run time, which dominated its
//! integration. The blocked sum is linear in the mask, and in the vertex's
//! tangent frame the pixel directions are fixed, so the sums are tabled
//! once ([`TangentBasis`]): per mask row, per group of four columns and per
//! 4-bit pattern of them, −w Σ Y_k(ω_p) over the pattern's pixels (512 KB
//! at 32×32 and order 5, padded to 32 floats an entry). A vertex starts
//! from the unshadowed term in the tangent frame (zonal about ẑ: constant),
//! adds one entry per non-empty nibble of its mask (at most 204 at 32×32,
//! two AVX-512 adds each) and turns the sum to world space with one SH
//! rotation, applied through Euler angles without building its matrix
//! ([`shadow_core::sh::EulerShRotation`]: at order 5, three turns about
//! the polar axis and two fixed products of 25 sixteen-lane multiply-adds
//! each). Projection onto bands below n commutes with rotation, so this is
//! the per-pixel quadrature in world space to rounding (tested), and band
//! 0, which rotations leave alone, is exact: the white furnace holds.

use std::marker::PhantomData;

use glam::Vec3;
use shadow_core::sh::{CHUNK, Chunk, EulerShRotation, ShOrder, Zonal, eval_basis};

use super::MAX_BLOCKS;
use crate::mask::{BLOCK, DiskGrid, Mask, MaskRow};
use crate::raster::TangentFrame;

/// The SH basis over the disk in the tangent frame, summed ahead of time
/// for every way a mask can block it (module docs, "Tangent-frame
/// tables"), and the per-vertex turn of a sum to world space.
#[derive(Clone, Debug)]
pub struct TangentBasis<W: MaskRow> {
    disk: Mask<W>,
    order: ShOrder,
    pub(super) rotation: EulerShRotation,
    /// [`CHUNK`]s per table entry: the order's coefficient count rounded up
    /// to a power of two of chunks (order 5: 25 → 2 chunks, 32 floats), so
    /// that a sum is held in registers by one of a few compilations.
    pub(super) chunks: usize,
    /// Per storage row of the mask ([`Mask::storage_row`]), per group of
    /// four columns and per 4-bit pattern of them, entry
    /// `(storage_row · R/4 + group) · 16 + pattern`: −w Σ Y_k(ω_p) over the
    /// disk pixels ω_p that the pattern selects.
    patterns: Vec<Chunk>,
    /// Per 4×4 block (row-major): −w Y_k at the mean direction of the
    /// block's disk pixels, the paper's downsample (§3.2).
    blocks: Vec<Chunk>,
    /// Per pixel (row-major): Y_k(ω_p), zero outside the disk.
    pub(super) pixels: Vec<Chunk>,
    /// One entry: the unshadowed Lambert transfer in the tangent frame,
    /// Λ_l Y_k(ẑ) (zonal about the normal), where every sum starts, so
    /// that the one rotation to world space turns it to the normal too.
    unshadowed: Vec<Chunk>,
    _row: PhantomData<W>,
}

/// A sum of table entries of `K` chunks, small enough for registers.
pub(super) struct TableSum<const K: usize>([Chunk; K]);

impl<const K: usize> TableSum<K> {
    #[inline(always)]
    pub(super) fn new() -> Self {
        TableSum([[0.0; CHUNK]; K])
    }

    /// Entry `entry` of `table`: its `K` chunks.
    #[inline(always)]
    fn entry(table: &[Chunk], entry: usize) -> &[Chunk; K] {
        table[entry * K..(entry + 1) * K]
            .try_into()
            .expect("whole entries")
    }

    /// The sum holding entry `entry` of `table`.
    #[inline(always)]
    fn of(table: &[Chunk], entry: usize) -> Self {
        TableSum(*Self::entry(table, entry))
    }

    /// Adds entry `entry` of `table` (a product by one, which compiles to
    /// none).
    #[inline(always)]
    fn add(&mut self, table: &[Chunk], entry: usize) {
        self.add_scaled(table, entry, 1.0);
    }

    /// Adds `weight` times entry `entry` of `table`.
    #[inline(always)]
    pub(super) fn add_scaled(&mut self, table: &[Chunk], entry: usize, weight: f32) {
        for (s, e) in self.0.iter_mut().zip(Self::entry(table, entry)) {
            for (s, e) in s.iter_mut().zip(e) {
                *s += weight * e;
            }
        }
    }

    /// The sum turned from the tangent frame `frame` to world space, its
    /// first `out.len()` coefficients written to `out`.
    #[inline(always)]
    pub(super) fn rotate_into(
        mut self,
        rotation: &EulerShRotation,
        frame: &TangentFrame,
        out: &mut [f32],
    ) {
        rotation.apply_chunks(frame.to_world(), &mut self.0);
        out.copy_from_slice(&self.0.as_flattened()[..out.len()]);
    }
}

impl<W: MaskRow> TangentBasis<W> {
    /// The tables of `grid`'s pixels up to `order`: 512 KB at 32×32 and
    /// order 5 for the patterns, 128 KB for the pixels.
    pub fn new(grid: &DiskGrid<W>, order: ShOrder) -> TangentBasis<W> {
        let r = W::RESOLUTION;
        let n = order.coeff_count();
        let chunks = n.div_ceil(CHUNK).next_power_of_two();
        let entries = |count: usize| vec![[0.0f32; CHUNK]; count * chunks];
        // Adds k · Y(d) to entry `at` of `table`.
        let add_basis = |table: &mut [Chunk], at: usize, d: Vec3, k: f32| {
            let mut y = [0.0f32; ShOrder::MAX.coeff_count()];
            eval_basis(order, d, &mut y[..n]);
            let entry = table[at * chunks..(at + 1) * chunks].as_flattened_mut();
            for (e, y) in entry.iter_mut().zip(&y[..n]) {
                *e += k * y;
            }
        };
        let mut pixels = entries(r * r);
        for (row, col) in grid.disk().pixels() {
            add_basis(&mut pixels, row * r + col, grid.direction(row, col), 1.0);
        }
        let w = grid.weight();
        let groups = r / BLOCK;
        let mut patterns = entries(r * groups * 16);
        for (row, col) in grid.disk().pixels() {
            let (group, bit) = (col / BLOCK, col % BLOCK);
            let first = (Mask::<W>::storage_row(row) * groups + group) * 16;
            for pattern in (0..16).filter(|pattern| pattern >> bit & 1 == 1) {
                add_basis(&mut patterns, first + pattern, grid.direction(row, col), -w);
            }
        }
        let mut blocks = entries(groups * groups);
        for block in 0..groups * groups {
            let mean: Vec3 = grid
                .disk()
                .pixels()
                .filter(|&(r, c)| (r / BLOCK) * groups + c / BLOCK == block)
                .map(|(r, c)| grid.direction(r, c))
                .sum();
            // A corner block outside the disk is never counted.
            add_basis(&mut blocks, block, mean.normalize_or(Vec3::Z), -w);
        }
        let mut unshadowed = entries(1);
        Zonal::lambert(order).project_along(Vec3::Z, &mut unshadowed.as_flattened_mut()[..n]);
        TangentBasis {
            disk: *grid.disk(),
            order,
            rotation: EulerShRotation::new(order),
            chunks,
            patterns,
            blocks,
            pixels,
            unshadowed,
            _row: PhantomData,
        }
    }

    pub fn order(&self) -> ShOrder {
        self.order
    }

    /// Writes the world-space Lambert transfer vector of a vertex with
    /// tangent frame `frame` and visibility `mask` into
    /// `out[..order.coeff_count()]` (without ρ/π); `blocks` selects the
    /// paper's 4×4 downsample. Allocation-free; always inlined, so that the
    /// engine's per-instruction-set compilations hold the whole body.
    ///
    /// # Panics
    /// If `out` is shorter than the order's coefficient count.
    #[inline(always)]
    pub fn lambert(&self, mask: &Mask<W>, frame: &TangentFrame, blocks: bool, out: &mut [f32]) {
        let out = &mut out[..self.order().coeff_count()];
        let blocked = mask.and(&self.disk);
        with_chunks!(self.chunks, K => {
            let mut sum = TableSum::<K>::of(&self.unshadowed, 0);
            if blocks {
                let side = W::RESOLUTION / BLOCK;
                let mut counts = [0u8; MAX_BLOCKS];
                blocked.block_counts(&mut counts);
                for (b, &count) in counts[..side * side].iter().enumerate() {
                    if count > 0 {
                        sum.add_scaled(&self.blocks, b, f32::from(count));
                    }
                }
            } else {
                let groups = W::RESOLUTION / BLOCK;
                for (row, word) in blocked.rows().iter().enumerate() {
                    let mut bits = word.widen();
                    while bits != 0 {
                        let group = bits.trailing_zeros() as usize / BLOCK;
                        let pattern = (bits >> (BLOCK * group)) as usize & 0xF;
                        bits &= !(0xF << (BLOCK * group));
                        sum.add(&self.patterns, (row * groups + group) * 16 + pattern);
                    }
                }
            }
            sum.rotate_into(&self.rotation, frame, out);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order5() -> ShOrder {
        ShOrder::new(5).unwrap()
    }

    #[test]
    fn empty_and_full_masks() {
        let grid = DiskGrid::<u32>::new();
        let basis = TangentBasis::new(&grid, order5());
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::new(0.2, 0.9, -0.3).normalize());
        let mut t = [0.0; 25];
        let mut exact = [0.0; 25];
        Zonal::lambert(order5()).project_along(frame.normal(), &mut exact);
        for blocks in [false, true] {
            // Nothing blocked: the unshadowed transfer turned to the normal,
            // to rounding; band 0, which no rotation changes, exactly (the
            // white furnace).
            basis.lambert(&Mask::EMPTY, &frame, blocks, &mut t);
            assert_eq!(t[0], exact[0]);
            for (k, (a, b)) in t.iter().zip(&exact).enumerate() {
                assert!((a - b).abs() < 1e-6, "{k}: {a} vs {b}");
            }
        }
        // Fully blocked: the quadrature of the whole hemisphere cancels the
        // exact term up to the disk quadrature error (measured 0.011 every
        // pixel, 0.031 from blocks at their mean direction).
        for (blocks, bound) in [(false, 0.012), (true, 0.032)] {
            basis.lambert(grid.disk(), &frame, blocks, &mut t);
            let worst = t.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(t[0].abs() < 1e-5, "band 0 is exact: {}", t[0]);
            eprintln!("fully blocked, blocks {blocks}: worst |T_k| {worst}");
            assert!(worst < bound, "{blocks}: {worst}");
        }
    }
}
