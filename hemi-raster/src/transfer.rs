//! From a visibility mask to shading (Kautz et al. 2004, §3, eq. 3, and §3.2).
//!
//! For a Lambert surface the transfer vector is
//! T_k = ∫ V(ω) max(0, n·ω) Y_k(ω) dω, and the exit radiance ρ/π Σ_k L_k T_k
//! (eq. 2). Writing V = 1 − B (B the blocked directions),
//!
//! ```text
//! T_k = Λ_l Y_k(n)  −  ∫ B(ω) max(0, n·ω) Y_k(ω) dω,
//! ```
//!
//! the first term being the clamped cosine turned to the normal, exact by the
//! Funk–Hecke theorem ([`Zonal::project_along`]). Only the blocked part is
//! integrated over the mask: a vertex with nothing above it gets the exact
//! unshadowed transfer (the white furnace holds to rounding), and the
//! quadrature error is confined to the blocked directions. In the disk
//! parameterization the cosine is already in the pixel weights (Nusselt),
//! so the blocked integral is Σ_{blocked pixels} w · Y_k(ω_pixel).
//!
//! - [`Integration::ShPixels`] (the default): every blocked pixel counts at
//!   its own direction.
//! - [`Integration::ShBlocks`] (the paper's §3.2 optimization): the mask is
//!   downsampled in 4×4 blocks to a grey occlusion level (the block's count
//!   of blocked pixels), and each block counts at the mean direction of its
//!   disk pixels. With the tables below it saves a fifth of the
//!   integration (on the harness's human with potentially visible sets,
//!   0.96 against 1.22 ms an update on one thread) and costs 2 points of
//!   transfer error (README), most near the horizon, where the disk
//!   (ρ = sin θ) squeezes elevation: a 4×4 block of the 32×32 mask spans
//!   14° of elevation at the zenith, an outermost one 49° to 90°. It is
//!   kept to reproduce the paper and measure what it cost (README).
//!
//! # Tangent-frame tables
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
//! 0, which rotations leave alone, is exact: the white furnace holds. It
//! replaced evaluating the basis at world-space directions eight at a time,
//! per block centroid and per pixel near the horizon, which took 40% of an
//! update with potentially visible sets on the human.
//! - [`Integration::Direct`] (§3, "integrate the lighting directly"): no SH;
//!   the environment's radiance summed over the visible pixels.
//!
//! # Glossy transfer
//!
//! For the normalized Phong lobe of [`Brdf::Phong`](shadow_core::Brdf), the
//! BRDF goes inside eq. 3 and the transfer vector depends on the view
//! direction ω_o (the paper's V*_p(v), eq. 1–3):
//!
//! ```text
//! T_k(ω_o) = ∫ V(ω) lobe(ω; r) max(0, n·ω) Y_k(ω) dω,
//! lobe(ω; r) = (s+2)/(2π) max(0, r·ω)^s,   r = reflect(ω_o, n),
//! ```
//!
//! which [`glossy_transfer`] integrates by quadrature over the **visible**
//! pixels, Σ_visible w_p · lobe(ω_p) · Y_k(ω_p) (the disk weights carry the
//! cosine). There is no exact unshadowed term to subtract from, as there is
//! for Lambert: the lobe clipped by the horizon is not zonal about any axis.
//! The paper computes this for the current view (§3 eq. 3, the BRDF inside
//! the integral; §4, the hand "with a slightly glossy Phong BRDF"), noting
//! that "evaluation of the SH functions dominates BRDF evaluation in the
//! integration".
//!
//! The weights w_p are those of [`LobeGrid`], not the uniform π/count of
//! [`DiskGrid`]: a lobe inside the disk then gets its pixels' exact areas
//! instead of the boundary's bias (−0.95% at 32×32).
//!
//! With the 4×4 blocks the lobe is still evaluated at every visible pixel
//! (a dot product and a power, a fraction of a basis evaluation), and the
//! basis once per block at the lobe-weighted mean direction of the block's
//! visible pixels. Evaluating the lobe at the block's mean direction too, as
//! the blocked Lambert integral does, is a quadrature with a step of four
//! pixels (0.25 rad at the zenith at 32×32); measured on the unshadowed
//! lobe at 32×32 while choosing, it missed by up to 3.5% for exponent 5,
//! 17% for 20 and 19% (normal view) to 99% (grazing) for 100, against the
//! figures below.
//!
//! The pixel quadrature is accurate while the lobe, about 1/√s rad wide,
//! spans a few pixels. A pixel spans 2/R rad at the zenith, and toward the
//! horizon the disk compresses θ by cos θ, so sharp lobes at grazing views
//! fail first. Worst relative error of the unshadowed lobe integral
//! (`lobe_quadrature_error` in the tests; 12 azimuths per view angle θ_o):
//!
//! | R | s | θ_o ≤ 30° | 60° | 75° | 85° |
//! |---|---|---|---|---|---|
//! | 16 | 5 | 0.4% | 0.8% | 0.5% | 1.6% |
//! | 16 | 20 | 0.02% | 2.7% | 1.1% | 13% |
//! | 16 | 100 | 0.01% | 15% | 26% | 90% |
//! | 32 | 5 | 0.04% | 0.1% | 0.06% | 0.2% |
//! | 32 | 20 | 0.00% | 0.4% | 0.5% | 1.5% |
//! | 32 | 100 | 0.00% | 0.06% | 7.9% | 27% |
//! | 32 | 500 | 0.1% | 11% | 83% | 210% |
//! | 64 | 20 | 0.00% | 0.1% | 0.6% | 1.3% |
//! | 64 | 100 | 0.00% | 0.00% | 1.5% | 7.7% |
//! | 64 | 500 | 0.00% | 0.02% | 17% | 47% |
//!
//! So the paper's 32×32 mask serves the "slightly glossy" exponents up to a
//! few tens at every view and up to about 100 away from grazing; sharper
//! lobes need the 64×64 mask or another method (the lobe falls between
//! pixels and the sum is noise).
//!
//! Blocker edges that cross a lobe are quantized to pixels like any other,
//! but a lobe concentrates its weight on few pixels: a lobe of exponent 20
//! two-thirds blocked was 2.3% off the exact integral (median over 600
//! turns of the setup), 5.8% at p90 and 12% at worst, the same with every
//! pixel classified exactly by ray casting (the property tests).

use std::f32::consts::{PI, TAU};
use std::marker::PhantomData;

use glam::{Vec3, Vec4};
use shadow_core::sh::{
    CHUNK, Chunk, EulerShRotation, ShOrder, Zonal, eval_basis, eval_basis_lanes,
};
use shadow_core::{Environment, reflect};

use crate::disk::{BLOCK, DiskGrid};
use crate::kernel::Simd;
use crate::mask::{Mask, MaskRow};
use crate::rasterize::TangentFrame;

/// How a mask becomes shading (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integration {
    /// SH transfer from every pixel.
    #[default]
    ShPixels,
    /// SH transfer from the 4×4-block grey downsample (§3.2).
    ShBlocks,
    /// No SH: the environment integrated over the visible pixels directly.
    Direct,
}

/// Stack room for the per-block sums of the finest mask.
const MAX_BLOCKS: usize = (<u64 as MaskRow>::RESOLUTION / BLOCK).pow(2);

/// Directions per basis evaluation ([`eval_basis_lanes`]).
const LANES: usize = 8;

/// Adds Σ weight · Y_k(direction) over `terms` (world-space unit directions
/// and their weights) to `out[k]` for every k < `out.len()`, evaluating the
/// basis eight directions at a time. The stack room is sized to the order
/// (the buffers of order 16 are 16 KB, too much to clear for every vertex
/// of an order-5 frame). Allocation-free.
#[inline(always)]
fn add_weighted_basis(order: ShOrder, terms: impl Iterator<Item = (Vec3, f32)>, out: &mut [f32]) {
    match order.coeff_count() {
        n if n <= 25 => BasisSum::<25>::new(order).add_all(terms, out),
        n if n <= 81 => BasisSum::<81>::new(order).add_all(terms, out),
        _ => BasisSum::<{ ShOrder::MAX.coeff_count() }>::new(order).add_all(terms, out),
    }
}

/// The running sum of [`add_weighted_basis`], with room for `C`
/// coefficients: a batch of directions, and per coefficient and lane the
/// sum so far (reduced across lanes once, at the end).
struct BasisSum<const C: usize> {
    order: ShOrder,
    directions: [[f32; LANES]; 3],
    weights: [f32; LANES],
    len: usize,
    basis: [[f32; LANES]; C],
    sums: [[f32; LANES]; C],
}

impl<const C: usize> BasisSum<C> {
    #[inline(always)]
    fn new(order: ShOrder) -> Self {
        debug_assert!(order.coeff_count() <= C);
        BasisSum {
            order,
            directions: [[0.0; LANES]; 3],
            weights: [0.0; LANES],
            len: 0,
            basis: [[0.0; LANES]; C],
            sums: [[0.0; LANES]; C],
        }
    }

    #[inline(always)]
    fn add_all(mut self, terms: impl Iterator<Item = (Vec3, f32)>, out: &mut [f32]) {
        for (direction, weight) in terms {
            for (axis, lanes) in self.directions.iter_mut().enumerate() {
                lanes[self.len] = direction[axis];
            }
            self.weights[self.len] = weight;
            self.len += 1;
            if self.len == LANES {
                self.flush();
            }
        }
        if self.len > 0 {
            // Unused lanes: any unit direction, weight zero.
            for lane in self.len..LANES {
                self.directions[0][lane] = 0.0;
                self.directions[1][lane] = 1.0;
                self.directions[2][lane] = 0.0;
                self.weights[lane] = 0.0;
            }
            self.flush();
        }
        let n = self.order.coeff_count();
        for (o, sum) in out[..n].iter_mut().zip(&self.sums) {
            *o += sum.iter().sum::<f32>();
        }
    }

    #[inline(always)]
    fn flush(&mut self) {
        let n = self.order.coeff_count();
        let [x, y, z] = &self.directions;
        eval_basis_lanes(self.order, [x, y, z], &mut self.basis);
        for (sum, basis) in self.sums[..n].iter_mut().zip(&self.basis) {
            for lane in 0..LANES {
                sum[lane] += self.weights[lane] * basis[lane];
            }
        }
        self.len = 0;
    }
}

/// The SH basis over the disk in the tangent frame, summed ahead of time
/// for every way a mask can block it (module docs, "Tangent-frame
/// tables"), and the per-vertex turn of a sum to world space.
#[derive(Clone, Debug)]
pub struct TangentBasis<W: MaskRow> {
    disk: Mask<W>,
    order: ShOrder,
    rotation: EulerShRotation,
    /// [`CHUNK`]s per table entry: the order's coefficient count rounded up
    /// to a power of two of chunks (order 5: 25 → 2 chunks, 32 floats), so
    /// that a sum is held in registers by one of a few compilations.
    chunks: usize,
    /// Per storage row of the mask ([`Mask::storage_row`]), per group of
    /// four columns and per 4-bit pattern of them, entry
    /// `(storage_row · R/4 + group) · 16 + pattern`: −w Σ Y_k(ω_p) over the
    /// disk pixels ω_p that the pattern selects.
    patterns: Vec<Chunk>,
    /// Per 4×4 block (row-major): −w Y_k at the mean direction of the
    /// block's disk pixels, the paper's downsample (§3.2).
    blocks: Vec<Chunk>,
    /// Per pixel (row-major): Y_k(ω_p), zero outside the disk.
    pixels: Vec<Chunk>,
    /// One entry: the unshadowed Lambert transfer in the tangent frame,
    /// Λ_l Y_k(ẑ) (zonal about the normal), where every sum starts, so
    /// that the one rotation to world space turns it to the normal too.
    unshadowed: Vec<Chunk>,
    _row: PhantomData<W>,
}

/// Runs `$body` with the const `$k` equal to `$chunks` (a power of two up
/// to 16, the chunks of order 16's 256 coefficients).
macro_rules! with_chunks {
    ($chunks:expr, $k:ident => $body:expr) => {
        match $chunks {
            1 => {
                const $k: usize = 1;
                $body
            }
            2 => {
                const $k: usize = 2;
                $body
            }
            4 => {
                const $k: usize = 4;
                $body
            }
            8 => {
                const $k: usize = 8;
                $body
            }
            _ => {
                const $k: usize = 16;
                $body
            }
        }
    };
}

/// A sum of table entries of `K` chunks, small enough for registers.
struct TableSum<const K: usize>([Chunk; K]);

impl<const K: usize> TableSum<K> {
    #[inline(always)]
    fn new() -> Self {
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
    fn add_scaled(&mut self, table: &[Chunk], entry: usize, weight: f32) {
        for (s, e) in self.0.iter_mut().zip(Self::entry(table, entry)) {
            for (s, e) in s.iter_mut().zip(e) {
                *s += weight * e;
            }
        }
    }

    /// The sum turned from the tangent frame `frame` to world space, its
    /// first `out.len()` coefficients written to `out`.
    #[inline(always)]
    fn rotate_into(mut self, rotation: &EulerShRotation, frame: &TangentFrame, out: &mut [f32]) {
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
    /// method's per-instruction-set compilations hold the whole body.
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

/// [`TangentBasis::lambert`] compiled for the `simd` path (which must come
/// from [`Simd::resolve`]): the table sums in AVX registers.
pub(crate) fn lambert_transfer_on<W: MaskRow>(
    simd: Simd,
    basis: &TangentBasis<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    blocks: bool,
    out: &mut [f32],
) {
    match simd {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::resolve` only yields this path on CPUs with AVX-512F.
        Simd::Avx512 => unsafe { basis.lambert_avx512(mask, frame, blocks, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::resolve` only yields this path on CPUs with AVX2.
        Simd::Avx2 => unsafe { basis.lambert_avx2(mask, frame, blocks, out) },
        _ => basis.lambert(mask, frame, blocks, out),
    }
}

#[cfg(target_arch = "x86_64")]
impl<W: MaskRow> TangentBasis<W> {
    #[target_feature(enable = "avx512f,avx2,fma,bmi1")]
    fn lambert_avx512(&self, mask: &Mask<W>, frame: &TangentFrame, blocks: bool, out: &mut [f32]) {
        self.lambert(mask, frame, blocks, out);
    }

    #[target_feature(enable = "avx2,fma,bmi1")]
    fn lambert_avx2(&self, mask: &Mask<W>, frame: &TangentFrame, blocks: bool, out: &mut [f32]) {
        self.lambert(mask, frame, blocks, out);
    }
}

/// The specular lobe of [`shadow_core::Brdf::Phong`] at one vertex for one
/// view, (s+2)/(2π) max(0, r·ω)^s without ρ_s (the expression of
/// [`shadow_core::Brdf::eval`]), held in the vertex's tangent frame so that
/// evaluating it at a disk pixel is a dot product and a power.
///
/// Directions where the lobe is below [`LOBE_CUTOFF`] of its peak get zero
/// and skip the power (and the basis evaluation or environment look-up that
/// would follow): what is left is the cone of 60° about r for exponent 20
/// (half the directions with r·ω > 0), of 30° for 100 (13% of them). What
/// is dropped is at most π · 10⁻⁶ · (s+2)/(2π), a relative (s+2)/2 · 10⁻⁶
/// of the unshadowed lobe at normal view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhongLobe {
    /// The mirror direction r of the view about the normal, tangent
    /// coordinates.
    axis: Vec3,
    exponent: f32,
    /// (s+2)/(2π): the cosine-weighted lobe integrates to 1 at normal view.
    scale: f32,
    /// r·ω at and below which the lobe counts as zero: LOBE_CUTOFF^(1/s),
    /// or −∞ for s = 0 (a constant lobe, 0⁰ = 1 as in `Brdf::eval`).
    min_cos: f32,
}

/// The fraction of its peak below which [`PhongLobe`] counts as zero.
pub const LOBE_CUTOFF: f32 = 1e-6;

impl PhongLobe {
    /// The lobe of `exponent` s (finite, ≥ 0) at a vertex with tangent frame
    /// `frame`, seen from the unit world-space direction `view` (from the
    /// vertex toward the eye).
    pub fn new(frame: &TangentFrame, view: Vec3, exponent: f32) -> PhongLobe {
        let local_view = frame.to_world().transpose() * view;
        PhongLobe {
            axis: reflect(local_view, Vec3::Z),
            exponent,
            scale: (exponent + 2.0) / TAU,
            min_cos: if exponent > 0.0 {
                LOBE_CUTOFF.powf(exponent.recip())
            } else {
                f32::NEG_INFINITY
            },
        }
    }

    /// The lobe toward the unit tangent-frame direction `dir`.
    #[inline]
    pub fn eval(&self, dir: Vec3) -> f32 {
        let c = self.axis.dot(dir);
        if c > self.min_cos {
            c.powf(self.exponent) * self.scale
        } else {
            0.0
        }
    }
}

/// The disk grid with the pixel weights of the glossy quadrature.
///
/// [`DiskGrid`]'s uniform weight π/count spreads the disk's boundary error
/// over every pixel, which the Lambert integral wants (the cosine integral
/// is then exact) but which biases any lobe inside the disk by the whole
/// boundary excess: −3.3% at 16×16, −0.95% at 32×32, −0.34% at 64×64. Here
/// a pixel wholly inside the unit circle carries its exact area (2/R)², and
/// the pixels the circle cuts share what is left of π (0.84, 0.90 and 0.93
/// of a pixel's area at 16, 32 and 64): lobes away from the horizon are
/// integrated without that bias, and a constant lobe still integrates the
/// cosine exactly.
#[derive(Clone, Debug)]
pub struct LobeGrid<'a, W: MaskRow> {
    grid: &'a DiskGrid<W>,
    /// The disk pixels that the unit circle cuts.
    rim: Mask<W>,
    interior_weight: f32,
    rim_weight: f32,
}

impl<'a, W: MaskRow> LobeGrid<'a, W> {
    pub fn new(grid: &'a DiskGrid<W>) -> LobeGrid<'a, W> {
        let half = 1.0 / W::RESOLUTION as f32;
        let mut rim = Mask::EMPTY;
        for (r, c) in grid.disk().pixels() {
            // The pixel's corner farthest from the centre.
            let (x, y) = DiskGrid::<W>::centre(r, c);
            if (x.abs() + half).powi(2) + (y.abs() + half).powi(2) > 1.0 {
                rim.set(r, c);
            }
        }
        let interior_weight = (2.0 * half).powi(2);
        let interior = grid.disk().count() - rim.count();
        LobeGrid {
            grid,
            rim,
            interior_weight,
            rim_weight: (PI - interior as f32 * interior_weight) / rim.count() as f32,
        }
    }

    pub fn grid(&self) -> &DiskGrid<W> {
        self.grid
    }

    /// The cosine-weighted solid angle that disk pixel (`row`, `col`)
    /// stands for; the weights of the disk add up to π.
    #[inline]
    pub fn weight(&self, row: usize, col: usize) -> f32 {
        if self.rim.get(row, col) {
            self.rim_weight
        } else {
            self.interior_weight
        }
    }
}

/// Writes the world-space glossy transfer vector T_k(ω_o) of a vertex with
/// tangent frame `frame` and visibility `mask`, for the lobe of its view
/// (module docs, "Glossy transfer"), into `out[..order.coeff_count()]`
/// (without ρ_s), `order` being `basis`'s: Σ_visible w_p · lobe(ω_p) ·
/// Y_k(ω_p), summed in the tangent frame from the per-pixel table and
/// turned to world space. With `blocks`, the lobe is summed per pixel and
/// the basis evaluated once per 4×4 block, at the lobe-weighted mean
/// direction of its visible pixels. Allocation-free.
///
/// # Panics
/// If `out` is shorter than the order's coefficient count, or `lobes` is
/// not of the grid `basis` was built on.
pub fn glossy_transfer<W: MaskRow>(
    basis: &TangentBasis<W>,
    lobes: &LobeGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    lobe: &PhongLobe,
    blocks: bool,
    out: &mut [f32],
) {
    let order = basis.order();
    let n = order.coeff_count();
    let out = &mut out[..n];
    let grid = lobes.grid();
    let to_world = frame.to_world();
    let visible = grid.visible(mask);
    // The visible pixels the lobe reaches: position, direction, w_p · lobe.
    let lit = visible.pixels().filter_map(|(r, c)| {
        let d = grid.direction(r, c);
        let f = lobe.eval(d) * lobes.weight(r, c);
        (f > 0.0).then_some((r, c, d, f))
    });
    if blocks {
        out.fill(0.0);
        let side = grid.blocks();
        // Per block: (Σ w_p lobe · ω, Σ w_p lobe) over its visible pixels.
        let mut sums = [Vec4::ZERO; MAX_BLOCKS];
        for (r, c, d, f) in lit {
            sums[(r / BLOCK) * side + c / BLOCK] += f * d.extend(1.0);
        }
        // A block whose sum is subnormal adds nothing f32 can hold and
        // would lose the precision of its mean direction: skipped.
        let terms = sums[..side * side]
            .iter()
            .filter(|sum| sum.w >= f32::MIN_POSITIVE)
            .map(|sum| (to_world * (sum.truncate() / sum.w).normalize(), sum.w));
        add_weighted_basis(order, terms, out);
    } else {
        with_chunks!(basis.chunks, K => {
            let mut sum = TableSum::<K>::new();
            for (r, c, _, f) in lit {
                sum.add_scaled(&basis.pixels, r * W::RESOLUTION + c, f);
            }
            sum.rotate_into(&basis.rotation, frame, out);
        });
    }
}

/// Σ_visible f(row, col, ω_p) · L(ω_p) over the visible pixels, L read with
/// [`Environment::lookup`] (bilinear) at world-space directions, f given
/// the pixel and its tangent-frame direction; pixels where f is zero skip
/// the look-up.
fn direct_sum<W: MaskRow>(
    grid: &DiskGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    environment: &Environment,
    f: impl Fn(usize, usize, Vec3) -> f32,
) -> Vec3 {
    let to_world = frame.to_world();
    grid.visible(mask)
        .pixels()
        .map(|(r, c)| {
            let d = grid.direction(r, c);
            let f = f(r, c, d);
            if f > 0.0 {
                f * environment.lookup(to_world * d)
            } else {
                Vec3::ZERO
            }
        })
        .sum()
}

/// The irradiance ∫ L(ω) V(ω) max(0, n·ω) dω by direct quadrature over the
/// visible pixels: Σ_visible w · L(ω_pixel), L read with
/// [`Environment::lookup`] (bilinear). Pass an environment prefiltered to
/// about the pixel size, or the point samples alias (the paper's reason to
/// prefer SH).
pub fn direct_irradiance<W: MaskRow>(
    grid: &DiskGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    environment: &Environment,
) -> Vec3 {
    direct_sum(grid, mask, frame, environment, |_, _, _| 1.0) * grid.weight()
}

/// The glossy analogue of [`direct_irradiance`]: the specular radiance
/// ∫ L(ω) V(ω) lobe(ω) max(0, n·ω) dω (without ρ_s) by the same quadrature
/// with the lobe's weights, Σ_visible w_p · lobe(ω_p) · L(ω_p), and the same
/// need for a prefiltered environment.
pub fn direct_glossy<W: MaskRow>(
    lobes: &LobeGrid<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    lobe: &PhongLobe,
    environment: &Environment,
) -> Vec3 {
    direct_sum(lobes.grid(), mask, frame, environment, |r, c, d| {
        lobe.eval(d) * lobes.weight(r, c)
    })
}

/// The angular width (radians) of a pixel at the zenith, 2/R: the blur that
/// [`Integration::Direct`] applies to the environment.
pub fn pixel_angle<W: MaskRow>() -> f32 {
    2.0 / W::RESOLUTION as f32
}

const _: () = assert!(BLOCK == 4);

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use shadow_core::sh::{ShRgb, project_fn_rgb};
    use std::f32::consts::PI;

    fn order5() -> ShOrder {
        ShOrder::new(5).unwrap()
    }

    /// A smooth, non-constant sky: brighter toward +y and toward +x.
    fn sky(d: Vec3) -> Vec3 {
        Vec3::new(1.0 + d.y.max(0.0), 0.5 + 0.5 * d.x, 0.8 + 0.3 * d.z * d.y)
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

    /// The tables and the turn to world space give, to rounding, the sums
    /// they stand for: Σ w_p Y_k over the blocked pixels, and over the lit
    /// ones weighted by the lobe, evaluated at world-space directions.
    #[test]
    fn tables_equal_the_per_pixel_sums_in_world_space() {
        fn check<W: MaskRow>(order: u32) {
            let order = ShOrder::new(order).unwrap();
            let n = order.coeff_count();
            let grid = DiskGrid::<W>::new();
            let basis = TangentBasis::new(&grid, order);
            let lobes = LobeGrid::new(&grid);
            let mut state = 7u64;
            for normal in [Vec3::Y, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8), Vec3::X] {
                let frame = TangentFrame::new(Vec3::ZERO, normal.normalize());
                let to_world = frame.to_world();
                let mut mask = Mask::<W>::EMPTY;
                for r in 0..W::RESOLUTION {
                    for c in 0..W::RESOLUTION {
                        state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                        if state >> 62 != 0 {
                            mask.set(r, c);
                        }
                    }
                }
                let sum = |weight: &dyn Fn(usize, usize, Vec3) -> f32, pixels: &Mask<W>| {
                    let mut out = vec![0.0; n];
                    let mut y = vec![0.0; n];
                    for (r, c) in pixels.and(grid.disk()).pixels() {
                        let d = grid.direction(r, c);
                        eval_basis(order, to_world * d, &mut y);
                        let w = weight(r, c, d);
                        for (o, y) in out.iter_mut().zip(&y) {
                            *o += w * y;
                        }
                    }
                    out
                };
                let mut want = sum(&|_, _, _| -grid.weight(), &mask);
                let mut exact = vec![0.0; n];
                Zonal::lambert(order).project_along(frame.normal(), &mut exact);
                for (w, e) in want.iter_mut().zip(&exact) {
                    *w += e;
                }
                let mut got = vec![0.0; n];
                basis.lambert(&mask, &frame, false, &mut got);
                for (k, (a, b)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (a - b).abs() < 2e-5,
                        "lambert {order} {normal}: {k}: {a} vs {b}"
                    );
                }
                let lobe = PhongLobe::new(&frame, Vec3::new(0.2, 0.9, 0.1).normalize(), 8.0);
                let want = sum(
                    &|r, c, d| lobe.eval(d) * lobes.weight(r, c),
                    &grid.visible(&mask),
                );
                glossy_transfer(&basis, &lobes, &mask, &frame, &lobe, false, &mut got);
                for (k, (a, b)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (a - b).abs() < 2e-5,
                        "glossy {order} {normal}: {k}: {a} vs {b}"
                    );
                }
            }
        }
        check::<u16>(3);
        check::<u32>(5);
        check::<u64>(9);
    }

    /// Half the hemisphere blocked (a plane through the normal): the SH paths
    /// and the direct path agree with an exact quadrature of the lighting.
    #[test]
    fn half_blocked_paths_agree() {
        let grid = DiskGrid::<u64>::new();
        let order = ShOrder::new(8).unwrap();
        let basis = TangentBasis::new(&grid, order);
        let light: ShRgb = project_fn_rgb(order, 64, sky);
        let normal = Vec3::new(0.3, 0.8, 0.2).normalize();
        let frame = TangentFrame::new(Vec3::ZERO, normal);
        // Block the tangent half-space x > 0, pixel by pixel.
        let mut blocked = Mask::EMPTY;
        for (r, c) in grid.disk().pixels() {
            if grid.direction(r, c).x > 0.0 {
                blocked.set(r, c);
            }
        }
        let mut t = vec![0.0; order.coeff_count()];
        // Reference: fine quadrature of L·cos over the visible half.
        let to_world = frame.to_world();
        let mut reference = Vec3::ZERO;
        let steps = 600;
        for i in 0..steps {
            for j in 0..steps {
                let x = -1.0 + 2.0 * (i as f32 + 0.5) / steps as f32;
                let y = -1.0 + 2.0 * (j as f32 + 0.5) / steps as f32;
                if x * x + y * y < 1.0 && x <= 0.0 {
                    let d = Vec3::new(x, y, (1.0 - x * x - y * y).sqrt());
                    reference += light.eval(to_world * d) * (2.0 / steps as f32).powi(2);
                }
            }
        }
        for blocks in [false, true] {
            basis.lambert(&blocked, &frame, blocks, &mut t);
            let e = light.dot(&t);
            let rel = (e - reference).length() / reference.length();
            eprintln!("half blocked, blocks {blocks}: relative error {rel}");
            assert!(rel < 0.002, "{blocks}: {e} vs {reference}");
        }
        let env = Environment::new(
            "sky",
            256,
            128,
            (0..128)
                .flat_map(|r| (0..256).map(move |c| (r, c)))
                .map(|(r, c)| {
                    let theta = PI * (r as f32 + 0.5) / 128.0;
                    let phi = 2.0 * PI * (c as f32 + 0.5) / 256.0;
                    light.eval(shadow_core::environment::direction_from_angles(theta, phi))
                })
                .collect(),
        )
        .unwrap();
        let e = direct_irradiance(&grid, &blocked, &frame, &env);
        let rel = (e - reference).length() / reference.length();
        eprintln!("half blocked, direct: relative error {rel}");
        assert!(rel < 0.004, "direct: {e} vs {reference}");
    }

    /// ∫ lobe(ω; r) max(0, n·ω) dω for a view at `theta_o` from the
    /// normal n = +z, the lobe of exponent `s` (`na` × `nb` points): fine
    /// midpoint quadrature in the lobe's own polar angles, so that sharp
    /// lobes are resolved.
    pub(crate) fn clipped_lobe_albedo(theta_o: f64, s: f64, na: usize, nb: usize) -> f64 {
        use std::f64::consts::{FRAC_PI_2, PI, TAU};
        let r = glam::DVec3::new(-theta_o.sin(), 0.0, theta_o.cos());
        let (u, v) = r.any_orthonormal_pair();
        // The lobe is below 1e-9 of its peak beyond this angle; with s = 0
        // it is constant (0⁰ = 1, as in `Brdf::eval`) over the whole sphere.
        let alpha_max = if s > 0.0 {
            (1e-9f64.powf(1.0 / s)).acos().min(FRAC_PI_2)
        } else {
            PI
        };
        let (da, db) = (alpha_max / na as f64, TAU / nb as f64);
        let mut sum = 0.0;
        for i in 0..na {
            let a = (i as f64 + 0.5) * da;
            let (sa, ca) = a.sin_cos();
            let lobe = ca.powf(s) * sa;
            for j in 0..nb {
                let b = (j as f64 + 0.5) * db;
                let w = ca * r + sa * (b.cos() * u + b.sin() * v);
                sum += lobe * w.z.max(0.0);
            }
        }
        sum * da * db * (s + 2.0) / TAU
    }

    /// The worst relative error of the unshadowed lobe integral
    /// Σ w_p lobe(ω_p) against [`clipped_lobe_albedo`], over 12 azimuths of
    /// the view at `theta_o` (degrees) from the normal, in both quadratures
    /// (pixels, and blocks: under uniform light only band 0 counts, whose
    /// basis function is constant, so the two must agree).
    fn lobe_quadrature_error<W: MaskRow>(exponent: f32, theta_o: f32) -> f32 {
        let grid = DiskGrid::<W>::new();
        let lobes = LobeGrid::new(&grid);
        let basis = TangentBasis::new(&grid, ShOrder::new(1).unwrap());
        let y0 = 0.5 / PI.sqrt();
        let th = theta_o.to_radians();
        let exact = clipped_lobe_albedo(th as f64, exponent as f64, 3000, 1024) as f32;
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::new(0.3, 0.8, 0.2).normalize());
        let mut worst = 0.0f32;
        for k in 0..12 {
            let az = k as f32 * 0.53;
            let view =
                frame.to_world() * Vec3::new(th.sin() * az.cos(), th.sin() * az.sin(), th.cos());
            let lobe = PhongLobe::new(&frame, view, exponent);
            let mut t = [[0.0f32; 1]; 2];
            for (blocks, t) in [false, true].into_iter().zip(&mut t) {
                glossy_transfer(&basis, &lobes, &Mask::EMPTY, &frame, &lobe, blocks, t);
            }
            assert!((t[0][0] - t[1][0]).abs() <= 1e-5 * t[0][0], "{t:?}");
            worst = worst.max((t[0][0] / y0 - exact).abs() / exact);
        }
        worst
    }

    /// The figures of the module docs' table, and bounds on the ones the
    /// docs promise.
    #[test]
    fn lobe_quadrature_accuracy() {
        let angles = [0.0, 30.0, 60.0, 75.0, 85.0];
        let table = |name: &str, error: &dyn Fn(f32, f32) -> f32| {
            for s in [1.0, 5.0, 20.0, 100.0, 500.0] {
                let row: Vec<String> = angles
                    .iter()
                    .map(|&a| format!("{:.2}%", 100.0 * error(s, a)))
                    .collect();
                eprintln!("{name} s = {s}: {}", row.join(" "));
            }
        };
        table("R16", &lobe_quadrature_error::<u16>);
        table("R32", &lobe_quadrature_error::<u32>);
        table("R64", &lobe_quadrature_error::<u64>);
        for (s, angle, bound) in [
            (0.0, 85.0, 1e-5),
            (5.0, 85.0, 0.003),
            (20.0, 75.0, 0.006),
            (20.0, 85.0, 0.02),
            (100.0, 60.0, 0.002),
        ] {
            let e = lobe_quadrature_error::<u32>(s, angle);
            assert!(e < bound, "R32, s = {s}, {angle}°: {e}");
        }
        assert!(lobe_quadrature_error::<u64>(100.0, 75.0) < 0.02);
        // Where the table says the quadrature breaks down.
        assert!(lobe_quadrature_error::<u32>(500.0, 75.0) > 0.3);
    }

    /// The lobe is the specular term of [`shadow_core::Brdf::Phong`], and
    /// the reference integral is 1 at normal view and the unclipped
    /// cos θ_o when the lobe stays above the horizon.
    #[test]
    fn lobe_and_reference_are_right() {
        let frame = TangentFrame::new(Vec3::ZERO, Vec3::new(-0.4, 0.7, 0.5).normalize());
        let view = Vec3::new(0.2, 0.9, -0.1).normalize();
        for s in [0.0, 3.0, 40.0] {
            let brdf = shadow_core::Brdf::phong(Vec3::ZERO, Vec3::ONE, s).unwrap();
            let lobe = PhongLobe::new(&frame, view, s);
            for d in [
                Vec3::Z,
                Vec3::new(0.3, -0.2, 0.9),
                Vec3::new(-0.8, 0.1, 0.2),
            ] {
                let d = d.normalize();
                let expected = brdf.eval(frame.normal(), frame.to_world() * d, view).x;
                let got = lobe.eval(d);
                let peak = (s + 2.0) / TAU;
                assert!(
                    (got - expected).abs() <= 1e-4 * expected + LOBE_CUTOFF * peak,
                    "{got} vs {expected}"
                );
            }
        }
        for s in [0.0, 1.0, 20.0, 300.0] {
            let a = clipped_lobe_albedo(0.0, s, 3000, 1024);
            assert!((a - 1.0).abs() < 1e-4, "s = {s}: {a}");
        }
        // s = 0: the cosine integral / π at every view.
        let a = clipped_lobe_albedo(1.4, 0.0, 3000, 1024);
        assert!((a - 1.0).abs() < 1e-4, "{a}");
        // s = 300 at 30°: the lobe is 1e-9 of its peak long before the
        // horizon, and ∫ lobe · n·ω over the sphere is n·r = cos θ_o.
        let theta = std::f64::consts::FRAC_PI_6;
        let a = clipped_lobe_albedo(theta, 300.0, 3000, 1024);
        assert!((a - theta.cos()).abs() < 1e-4, "{a}");
    }
}
