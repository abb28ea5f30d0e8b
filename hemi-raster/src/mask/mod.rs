//! The visibility mask (Kautz et al. 2004, §3.1): a square grid over the
//! unit disk onto which a vertex's upper hemisphere projects
//! ([`DiskGrid`]), bit-packed one machine word per row ([`Mask`]), so that
//! rasterizing a triangle is three row-wise ANDs and an OR (§3.1.1), with
//! no per-pixel work.

use std::fmt::Debug;
use std::ops::{BitAnd, BitOr, BitXor, Not, Shr};

mod disk;

pub use disk::{BLOCK, DiskGrid};

/// A row of a mask: an unsigned word whose bit `c` is column `c`. Its width is
/// the mask's resolution, so a mask is `RESOLUTION` words.
pub trait MaskRow:
    Copy
    + Eq
    + Debug
    + Send
    + Sync
    + 'static
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + BitXor<Output = Self>
    + Not<Output = Self>
    + Shr<u32, Output = Self>
{
    /// Pixels per row and rows per mask.
    const RESOLUTION: usize;
    /// No bit set.
    const ZERO: Self;
    /// The rows of one mask: `[Self; RESOLUTION]`.
    type Rows: Copy + Eq + Debug + Send + Sync + AsRef<[Self]> + AsMut<[Self]>;
    /// Every row zero.
    const EMPTY_ROWS: Self::Rows;

    /// The word with only bit `col` set.
    fn bit(col: usize) -> Self;
    /// Number of set bits.
    fn ones(self) -> u32;
    /// Index of the lowest set bit (the word must not be zero).
    fn lowest(self) -> u32;
    /// The word with its lowest set bit cleared.
    fn clear_lowest(self) -> Self;
    /// The word, zero-extended.
    fn widen(self) -> u64;
}

macro_rules! mask_row {
    ($t:ty) => {
        impl MaskRow for $t {
            const RESOLUTION: usize = <$t>::BITS as usize;
            const ZERO: Self = 0;
            type Rows = [$t; <$t>::BITS as usize];
            const EMPTY_ROWS: Self::Rows = [0; <$t>::BITS as usize];

            fn bit(col: usize) -> Self {
                1 << col
            }
            fn ones(self) -> u32 {
                self.count_ones()
            }
            fn lowest(self) -> u32 {
                self.trailing_zeros()
            }
            fn clear_lowest(self) -> Self {
                self & self.wrapping_sub(1)
            }
            fn widen(self) -> u64 {
                self as u64
            }
        }
    };
}

mask_row!(u16);
mask_row!(u32);
mask_row!(u64);

/// A binary image of `W::RESOLUTION`² pixels over the square [−1, 1]² that
/// holds the unit disk: row `r`, column `c` is the pixel centred on
/// x = −1 + (2c+1)/R, y = −1 + (2r+1)/R (see [`DiskGrid`]). A set bit
/// means "blocked" in a visibility mask, "above the plane" in a LUT entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mask<W: MaskRow> {
    rows: W::Rows,
}

/// The paper's 32×32 mask.
pub type Mask32 = Mask<u32>;
/// A coarser 16×16 mask.
pub type Mask16 = Mask<u16>;
/// A finer 64×64 mask.
pub type Mask64 = Mask<u64>;

impl<W: MaskRow> Default for Mask<W> {
    fn default() -> Self {
        Mask::EMPTY
    }
}

impl<W: MaskRow> Mask<W> {
    /// No pixel set.
    pub const EMPTY: Mask<W> = Mask {
        rows: W::EMPTY_ROWS,
    };

    /// Pixels per side.
    pub const RESOLUTION: usize = W::RESOLUTION;

    /// The rows in storage order: rows 0 to R/2 − 1, then R − 1 down to R/2
    /// (see [`Mask::storage_row`]).
    pub fn rows(&self) -> &[W] {
        self.rows.as_ref()
    }

    /// Where row `row` is stored. Rows are folded, the bottom half stored in
    /// reverse after the top half, so that mirroring a mask top to bottom
    /// swaps the two halves of its storage: the plane table's y symmetry
    /// ([`crate::PlaneLut`]) then costs the per-receiver loop nothing. The
    /// map is its own inverse.
    #[inline(always)]
    pub const fn storage_row(row: usize) -> usize {
        let r = W::RESOLUTION;
        if row < r / 2 {
            row
        } else {
            3 * r / 2 - 1 - row
        }
    }

    /// The mask mirrored top to bottom (row r ↔ row R − 1 − r).
    pub fn mirrored(&self) -> Mask<W> {
        let half = W::RESOLUTION / 2;
        let mut out = *self;
        let (top, bottom) = out.rows.as_mut().split_at_mut(half);
        top.swap_with_slice(bottom);
        out
    }

    /// The rows, mutable.
    pub(crate) fn rows_mut(&mut self) -> &mut [W] {
        self.rows.as_mut()
    }

    /// Whether pixel (`row`, `col`) is set.
    ///
    /// # Panics
    /// If `row` or `col` is not below the resolution.
    pub fn get(&self, row: usize, col: usize) -> bool {
        assert!(col < W::RESOLUTION, "column {col} out of range");
        self.rows.as_ref()[Self::storage_row(row)] & W::bit(col) != W::ZERO
    }

    /// Sets pixel (`row`, `col`).
    ///
    /// # Panics
    /// If `row` or `col` is not below the resolution.
    pub fn set(&mut self, row: usize, col: usize) {
        assert!(col < W::RESOLUTION, "column {col} out of range");
        let r = &mut self.rows.as_mut()[Self::storage_row(row)];
        *r = *r | W::bit(col);
    }

    /// Number of set pixels.
    pub fn count(&self) -> usize {
        self.rows().iter().map(|r| r.ones() as usize).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.rows().iter().all(|&r| r == W::ZERO)
    }

    /// Pixels set in both.
    pub fn and(&self, other: &Mask<W>) -> Mask<W> {
        self.zip(other, |a, b| a & b)
    }

    /// Pixels set in either: occluder fusion (§3.1.1).
    pub fn or(&self, other: &Mask<W>) -> Mask<W> {
        self.zip(other, |a, b| a | b)
    }

    /// Pixels set in `self` but not in `other`.
    pub fn and_not(&self, other: &Mask<W>) -> Mask<W> {
        self.zip(other, |a, b| a & !b)
    }

    /// True when every pixel set in `other` is set in `self`.
    pub fn contains(&self, other: &Mask<W>) -> bool {
        self.rows()
            .iter()
            .zip(other.rows())
            .all(|(&a, &b)| b & !a == W::ZERO)
    }

    /// The set pixels as (row, col), row by row.
    pub fn pixels(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..W::RESOLUTION).flat_map(|r| {
            let mut bits = self.rows()[Self::storage_row(r)];
            std::iter::from_fn(move || {
                (bits != W::ZERO).then(|| {
                    let c = bits.lowest() as usize;
                    bits = bits.clear_lowest();
                    (r, c)
                })
            })
        })
    }

    /// Blocks of 4×4 pixels per side: `RESOLUTION / 4`.
    pub const BLOCKS: usize = W::RESOLUTION / 4;

    /// The set pixels of every 4×4 block (§3.2's downsampling to grey
    /// levels, times 16), row-major into `out[..BLOCKS²]`. Word-parallel: the
    /// nibbles of a row are counted all at once (popcount by halving), and
    /// the four rows of a block row summed in bytes, even and odd nibbles
    /// apart, with no per-block work (and no popcount instruction, which
    /// the baseline x86-64 lacks).
    ///
    /// # Panics
    /// If `out` is shorter than `BLOCKS²`.
    pub fn block_counts(&self, out: &mut [u8]) {
        const FIVES: u64 = 0x5555_5555_5555_5555;
        const THREES: u64 = 0x3333_3333_3333_3333;
        const LOW_NIBBLES: u64 = 0x0F0F_0F0F_0F0F_0F0F;
        let side = Self::BLOCKS;
        for (block_row, out) in out[..side * side].chunks_exact_mut(side).enumerate() {
            let (mut even, mut odd) = (0u64, 0u64);
            for r in 4 * block_row..4 * block_row + 4 {
                let x = self.rows()[Self::storage_row(r)].widen();
                let pairs = x - ((x >> 1) & FIVES);
                let nibbles = (pairs & THREES) + ((pairs >> 2) & THREES);
                even += nibbles & LOW_NIBBLES;
                odd += (nibbles >> 4) & LOW_NIBBLES;
            }
            let (even, odd) = (even.to_le_bytes(), odd.to_le_bytes());
            for (b, pair) in out.chunks_mut(2).enumerate() {
                pair[0] = even[b];
                if let Some(o) = pair.get_mut(1) {
                    *o = odd[b];
                }
            }
        }
    }

    fn zip(&self, other: &Mask<W>, f: impl Fn(W, W) -> W) -> Mask<W> {
        let mut out = *self;
        for (d, &o) in out.rows.as_mut().iter_mut().zip(other.rows()) {
            *d = f(*d, o);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_get_count_and_pixels_agree() {
        let mut m = Mask32::EMPTY;
        for (r, c) in [(0, 0), (3, 31), (31, 5), (17, 17)] {
            m.set(r, c);
        }
        assert_eq!(m.count(), 4);
        assert!(m.get(3, 31) && !m.get(3, 30));
        let px: Vec<_> = m.pixels().collect();
        assert_eq!(px, vec![(0, 0), (3, 31), (17, 17), (31, 5)]);
        let mut big = Mask64::EMPTY;
        big.set(63, 63);
        assert_eq!(big.pixels().collect::<Vec<_>>(), vec![(63, 63)]);
    }

    #[test]
    fn boolean_operations_and_blocks() {
        let mut a = Mask16::EMPTY;
        let mut b = Mask16::EMPTY;
        a.set(1, 1);
        a.set(5, 6);
        b.set(5, 6);
        b.set(9, 9);
        assert_eq!(a.and(&b).count(), 1);
        assert_eq!(a.or(&b).count(), 3);
        assert_eq!(a.and_not(&b).pixels().collect::<Vec<_>>(), vec![(1, 1)]);
        assert!(a.or(&b).contains(&a) && !a.contains(&b));
        let mut mirrored = Mask16::EMPTY;
        mirrored.set(14, 1);
        mirrored.set(10, 6);
        assert_eq!(a.mirrored(), mirrored);
        assert_eq!(a.mirrored().mirrored(), a);
        for r in 0..16 {
            assert_eq!(Mask16::storage_row(Mask16::storage_row(r)), r);
        }
        let mut counts = [0u8; 16];
        a.or(&b).block_counts(&mut counts);
        assert_eq!(counts, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0]);
    }

    /// Every block of random masks holds the count of its pixels.
    #[test]
    fn block_counts_count_each_block() {
        fn check<W: MaskRow>(seed: u64) {
            let mut state = seed;
            let mut mask = Mask::<W>::EMPTY;
            for r in 0..W::RESOLUTION {
                for c in 0..W::RESOLUTION {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    if state >> 62 != 0 {
                        mask.set(r, c);
                    }
                }
            }
            let side = Mask::<W>::BLOCKS;
            let mut counts = vec![0u8; side * side];
            mask.block_counts(&mut counts);
            for (b, &count) in counts.iter().enumerate() {
                let (br, bc) = (b / side, b % side);
                let expected = mask
                    .pixels()
                    .filter(|&(r, c)| r / 4 == br && c / 4 == bc)
                    .count();
                assert_eq!(count as usize, expected, "block ({br}, {bc})");
            }
        }
        check::<u16>(1);
        check::<u32>(2);
        check::<u64>(3);
    }
}
