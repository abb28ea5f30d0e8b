//! Rotation of SH coefficient vectors (see [`ShRotation`]).

use std::ops::{Add, Mul, Range};

use glam::{DMat3, Mat3, Quat};

use super::ShOrder;

/// The SH rotation matrix of a 3D rotation R, up to an order.
///
/// Semantics: if g(ω) = f(R⁻¹ω), i.e. g is f carried along by R (an
/// environment turned by R), then coeffs(g) = `rotation.apply(coeffs(f))`.
///
/// A rotation mixes coefficients only within a band, so the matrix is
/// block-diagonal with one (2l+1)×(2l+1) block per band. Band 1 is R itself
/// with rows and columns permuted to the basis order: (y, z, x) in the
/// textbook z-up frame, (z, y, x) in ours, whose polar axis is +Y
/// ([module docs](super)). Each further band follows from band 1 and the band
/// below by the recurrence of Ivanic and Ruedenberg (J. Phys. Chem. 1996,
/// with the corrections of their 1998 erratum), written for the real basis
/// without the Condon–Shortley phase, which ours is up to that relabelling of
/// axes. Building is O(n³) work (about 35 µs for order 9); applying is one
/// small matrix-vector product per band.
#[derive(Clone, Debug, PartialEq)]
pub struct ShRotation {
    order: ShOrder,
    /// The blocks of bands 0..n, each (2l+1)² row-major, concatenated.
    blocks: Vec<f32>,
}

/// Largest |RᵀR − I| entry accepted as a rotation by [`ShRotation::from_mat3`].
const ORTHONORMAL_TOLERANCE: f32 = 1e-4;

impl ShRotation {
    /// The rotation of a unit quaternion (normalized here); `None` if `q` is
    /// not finite or has (nearly) zero length.
    pub fn from_quat(order: ShOrder, q: Quat) -> Option<ShRotation> {
        if !q.is_finite() || q.length_squared() < 1e-12 {
            return None;
        }
        Some(ShRotation::build(
            order,
            Mat3::from_quat(q.normalize()).as_dmat3(),
        ))
    }

    /// The rotation of a 3×3 rotation matrix (column vectors: ω ↦ Rω);
    /// `None` unless `r` is finite, orthonormal to within 1e-4 per entry of
    /// RᵀR − I, and proper (det > 0: no reflection, which no SH rotation can
    /// represent as the same kind of map).
    pub fn from_mat3(order: ShOrder, r: Mat3) -> Option<ShRotation> {
        if !r.is_finite() || r.determinant() <= 0.0 {
            return None;
        }
        let gram = r.transpose() * r - Mat3::IDENTITY;
        if gram
            .to_cols_array()
            .iter()
            .any(|e| e.abs() > ORTHONORMAL_TOLERANCE)
        {
            return None;
        }
        Some(ShRotation::build(order, r.as_dmat3()))
    }

    /// The identity.
    pub fn identity(order: ShOrder) -> ShRotation {
        ShRotation::build(order, DMat3::IDENTITY)
    }

    pub fn order(&self) -> ShOrder {
        self.order
    }

    /// dst = rotation · src, band by band. `src` and `dst` hold the same
    /// number of coefficients, that of an order no higher than this
    /// rotation's. Works on scalar (f32) and RGB (Vec3) coefficients alike.
    ///
    /// # Panics
    /// If the lengths differ, are not a square n², or exceed the rotation's
    /// order (a caller's bug: no rotation exists to return).
    pub fn apply<T>(&self, src: &[T], dst: &mut [T])
    where
        T: Copy + Default + Add<Output = T> + Mul<f32, Output = T>,
    {
        assert_eq!(
            src.len(),
            dst.len(),
            "SH rotation: source and destination lengths differ"
        );
        let order = ShOrder::from_coeff_count(src.len())
            .filter(|o| *o <= self.order)
            .unwrap_or_else(|| {
                panic!(
                    "SH rotation of {} cannot rotate {} coefficients",
                    self.order,
                    src.len()
                )
            });
        let mut block_start = 0;
        for l in 0..order.bands() {
            let size = 2 * l + 1;
            let band = l * l..l * l + size;
            let block = &self.blocks[block_start..block_start + size * size];
            for (row, out) in block.chunks_exact(size).zip(&mut dst[band.clone()]) {
                *out = row
                    .iter()
                    .zip(&src[band.clone()])
                    .fold(T::default(), |acc, (&r, &c)| acc + c * r);
            }
            block_start += size * size;
        }
    }

    fn build(order: ShOrder, r: DMat3) -> ShRotation {
        let bands = order.bands();
        let mut blocks = vec![1.0f32];
        if bands > 1 {
            // Band 1 in basis order (z, y, x): entry (i, j), i, j ∈ {−1, 0, 1},
            // is R[axis(i)][axis(j)]. Derivation: band-1 functions are
            // k·(z, y, x); f(R⁻¹ω) = f(Rᵀω) turns coefficient vector c into
            // c'_i = Σ_j R[axis(i)][axis(j)] c_j.
            const AXIS: [usize; 3] = [2, 1, 0];
            let mut band1 = [[0.0f64; 3]; 3];
            for (i, row) in band1.iter_mut().enumerate() {
                for (j, e) in row.iter_mut().enumerate() {
                    *e = r.col(AXIS[j])[AXIS[i]];
                }
            }
            let mut previous: Vec<f64> = band1.iter().flatten().copied().collect();
            blocks.extend(previous.iter().map(|&e| e as f32));
            for l in 2..bands as i32 {
                let current = next_band(&band1, &previous, l);
                blocks.extend(current.iter().map(|&e| e as f32));
                previous = current;
            }
        }
        ShRotation { order, blocks }
    }
}

/// Coefficients per chunk of [`EulerShRotation::apply_chunks`]: one
/// AVX-512 register, two AVX ones.
pub const CHUNK: usize = 16;

/// Sixteen coefficients, the unit of [`EulerShRotation::apply_chunks`].
pub type Chunk = [f32; CHUNK];

/// The SH rotation of any rotation applied in place without building its
/// matrix: for rotations that change with every use, such as a vertex's
/// tangent frame, where [`ShRotation`]'s O(n³) build would cost far more
/// than applying it.
///
/// The rotation is split into Euler angles about our polar axis +Y and +X,
/// R = R_y(α) · R_x(β) · R_y(γ), and the tilt about +X into a turn about
/// +Y between two fixed quarter turns, R_x(β) = T · R_y(β) · T⁻¹ with
/// T = R_z(−90°) (T ŷ = x̂). A turn about the polar axis only mixes each
/// band's pair of coefficients (l, ±m), by the angle m·θ (the basis of
/// order m is cos mφ and sin mφ), so the SH rotation of R is three such
/// turns and two products with the fixed blocks of T and T⁻¹ (the
/// decomposition of Kautz, Sloan and Snyder 2002, "Fast, arbitrary BRDF
/// shading for low-frequency lighting using spherical harmonics"). No
/// trigonometric function is called: the angles' cosines and sines come
/// from R's entries, their multiples by the angle-addition recurrence.
///
/// Laid out for SIMD ([`EulerShRotation::apply_chunks`]): coefficients in
/// zero-padded chunks of [`CHUNK`], the fixed products as one
/// chunk-wide multiply-add per coefficient and chunk its band touches
/// (order 5: 25, in place of 2 Σ (2l+1)² = 328 scalar ones), the polar
/// turns as chunk-wide arithmetic on each coefficient and its (l, −m)
/// partner.
#[derive(Clone, Debug, PartialEq)]
pub struct EulerShRotation {
    order: ShOrder,
    /// T = R_z(−90°) and its inverse, by columns.
    quarter: BandColumns,
    quarter_inverse: BandColumns,
    /// Per coefficient k = l² + l + m, by chunk: |m| (padding: 0).
    abs_m: Vec<Chunk>,
    /// Per coefficient: the sign of m (padding: 0).
    sign_m: Vec<Chunk>,
    /// Per coefficient: the index of its partner l² + l − m.
    partner: Vec<u16>,
}

/// A block-diagonal SH matrix by chunks of rows: chunk c of the result
/// is Σ_j M[c-th rows, j] · v_j over the columns j of the bands its rows
/// belong to (a contiguous range), so that the sum stays in a register.
#[derive(Clone, Debug, PartialEq)]
struct BandColumns {
    /// Per chunk of rows: its columns, and where their entries start in
    /// `entries`.
    spans: Vec<(Range<usize>, usize)>,
    /// Per chunk of rows and column of its span: that column's entries in
    /// the chunk's rows (zero in rows of other bands and past n²).
    entries: Vec<Chunk>,
}

impl BandColumns {
    fn new(rotation: &ShRotation) -> BandColumns {
        let n = rotation.order.coeff_count();
        let band = |k: usize| k.isqrt();
        let mut spans = Vec::new();
        let mut entries = Vec::new();
        for first_row in (0..n).step_by(CHUNK) {
            let last_row = (first_row + CHUNK).min(n) - 1;
            let columns = band(first_row).pow(2)..(band(last_row) + 1).pow(2);
            spans.push((columns.clone(), entries.len()));
            for j in columns {
                let l = band(j);
                let mut chunk = [0.0; CHUNK];
                for (i, e) in chunk.iter_mut().enumerate() {
                    let row = first_row + i;
                    if row < n && band(row) == l {
                        let (size, start) = (2 * l + 1, block_start(l));
                        *e = rotation.blocks[start + (row - l * l) * size + (j - l * l)];
                    }
                }
                entries.push(chunk);
            }
        }
        BandColumns { spans, entries }
    }

    /// `coeffs` ← M · `coeffs`.
    #[inline(always)]
    fn apply<const K: usize>(&self, coeffs: &mut [Chunk; K]) {
        let v = *coeffs;
        let v = v.as_flattened();
        for (c, out) in coeffs.iter_mut().enumerate() {
            let mut sum = [0.0f32; CHUNK];
            // Chunks past n² are padding, and come out zero.
            let Some((columns, at)) = self.spans.get(c) else {
                *out = sum;
                continue;
            };
            for (column, &v) in self.entries[*at..].iter().zip(&v[columns.clone()]) {
                for (s, c) in sum.iter_mut().zip(column) {
                    *s += c * v;
                }
            }
            *out = sum;
        }
    }
}

/// Where band `l`'s block starts in [`ShRotation`]'s `blocks`: Σ_{i<l}
/// (2i+1)².
fn block_start(l: usize) -> usize {
    (0..l).map(|i| (2 * i + 1).pow(2)).sum()
}

impl EulerShRotation {
    /// The fixed quarter turns, up to `order`.
    pub fn new(order: ShOrder) -> EulerShRotation {
        let t = DMat3::from_rotation_z(-std::f64::consts::FRAC_PI_2);
        let chunks = order.coeff_count().div_ceil(CHUNK);
        let mut abs_m = vec![[0.0; CHUNK]; chunks];
        let mut sign_m = vec![[0.0; CHUNK]; chunks];
        let mut partner = Vec::with_capacity(order.coeff_count());
        for l in 0..order.bands() as i32 {
            for m in -l..=l {
                let k = (l * l + l + m) as usize;
                abs_m[k / CHUNK][k % CHUNK] = m.abs() as f32;
                sign_m[k / CHUNK][k % CHUNK] = m.signum() as f32;
                partner.push((l * l + l - m) as u16);
            }
        }
        EulerShRotation {
            order,
            quarter: BandColumns::new(&ShRotation::build(order, t)),
            quarter_inverse: BandColumns::new(&ShRotation::build(order, t.transpose())),
            abs_m,
            sign_m,
            partner,
        }
    }

    pub fn order(&self) -> ShOrder {
        self.order
    }

    /// Rotates `coeffs` in place by the rotation matrix `r` (columns:
    /// ω ↦ rω), with the semantics of [`ShRotation::apply`], at any order
    /// up to this one's. `r` must be a rotation; this is not checked (it is
    /// meant for per-vertex use, where [`ShRotation::from_mat3`]'s check
    /// would be a cost). Allocation-free.
    ///
    /// # Panics
    /// If `coeffs` is not n² long for an order n no higher than this one's.
    pub fn apply(&self, r: Mat3, coeffs: &mut [f32]) {
        let n = ShOrder::from_coeff_count(coeffs.len())
            .filter(|o| *o <= self.order)
            .unwrap_or_else(|| {
                panic!(
                    "SH rotation of {} cannot rotate {} coefficients",
                    self.order,
                    coeffs.len()
                )
            })
            .coeff_count();
        // The bands above the caller's are rotated too, as zeros: bands do
        // not mix.
        let mut chunks = [[0.0f32; CHUNK]; ShOrder::MAX.coeff_count() / CHUNK];
        chunks.as_flattened_mut()[..n].copy_from_slice(coeffs);
        self.apply_chunks(r, &mut chunks);
        coeffs.copy_from_slice(&chunks.as_flattened()[..n]);
    }

    /// [`EulerShRotation::apply`] on this rotation's order's coefficients
    /// held in `K` chunks, zero-padded past n² (the padding comes out zero);
    /// `K` must hold them. Always inlined, so that a caller compiled for
    /// wider SIMD compiles it for the same.
    ///
    /// # Panics
    /// If `K` chunks cannot hold n² coefficients.
    #[inline(always)]
    pub fn apply_chunks<const K: usize>(&self, r: Mat3, coeffs: &mut [Chunk; K]) {
        assert!(
            K * CHUNK >= self.order.coeff_count(),
            "{K} chunks cannot hold the coefficients of {}",
            self.order
        );
        // R ŷ = (sin β sin α, cos β, sin β cos α).
        let y = r.y_axis;
        let (sin_a, cos_a) = unit_or_x(y.x, y.z);
        let (sin_b, cos_b) = unit_or_x((y.x * y.x + y.z * y.z).sqrt(), y.y);
        // R_y(γ) = R_x(−β) R_y(−α) R, whose x axis is (cos γ, 0, −sin γ):
        // γ takes up what rounding left in α and β, so R is met to rounding
        // even at the poles (β near 0 or π), where α is ill-conditioned.
        let x = r.x_axis;
        let z1 = sin_a * x.x + cos_a * x.z;
        let x1 = cos_a * x.x - sin_a * x.z;
        let (sin_c, cos_c) = unit_or_x(-(-sin_b * x.y + cos_b * z1), x1);
        self.polar_turn(coeffs, cos_c, sin_c);
        self.quarter_inverse.apply(coeffs);
        self.polar_turn(coeffs, cos_b, sin_b);
        self.quarter.apply(coeffs);
        self.polar_turn(coeffs, cos_a, sin_a);
    }

    /// The SH rotation of R_y(θ) (glam's sense: +X toward −Z), given cos θ
    /// and sin θ. R_y(θ) carries the function at azimuth φ + θ to φ (φ runs
    /// from +X toward +Z), so the pair (c, s) of cos mφ and sin mφ becomes
    /// (c cos mθ + s sin mθ, s cos mθ − c sin mθ): coefficient k of order
    /// m becomes c_k cos |m|θ + sign(m) c_partner sin |m|θ. The multiples
    /// of the angle come from the angle-addition recurrence, once per turn;
    /// each lane then selects its own.
    #[inline(always)]
    fn polar_turn<const K: usize>(&self, coeffs: &mut [Chunk; K], cos: f32, sin: f32) {
        let (n, bands) = (self.order.coeff_count(), self.order.bands());
        let mut multiples = [(1.0f32, 0.0f32); ShOrder::MAX.bands()];
        for m in 1..bands {
            let (c, s) = multiples[m - 1];
            multiples[m] = (c * cos - s * sin, s * cos + c * sin);
        }
        let mut partner = [[0.0f32; CHUNK]; K];
        let flat = coeffs.as_flattened();
        for (p, &k) in partner.as_flattened_mut()[..n]
            .iter_mut()
            .zip(&self.partner)
        {
            *p = flat[k as usize];
        }
        // Chunks past n² are left as they are (the products zero them).
        let lanes = self.abs_m.iter().zip(&self.sign_m);
        for ((coeffs, partner), (abs_m, sign_m)) in coeffs.iter_mut().zip(&partner).zip(lanes) {
            let mut cos_m = [1.0f32; CHUNK];
            let mut sin_m = [0.0f32; CHUNK];
            for (m, &(cos, sin)) in multiples.iter().enumerate().take(bands).skip(1) {
                let m = m as f32;
                for i in 0..CHUNK {
                    let this = abs_m[i] == m;
                    cos_m[i] = if this { cos } else { cos_m[i] };
                    sin_m[i] = if this { sin } else { sin_m[i] };
                }
            }
            for i in 0..CHUNK {
                coeffs[i] = coeffs[i] * cos_m[i] + partner[i] * (sign_m[i] * sin_m[i]);
            }
        }
    }
}

/// (s, c) / |(s, c)|, or (0, 1) (angle zero) when both vanish.
#[inline(always)]
fn unit_or_x(s: f32, c: f32) -> (f32, f32) {
    let length = (s * s + c * c).sqrt();
    if length > 0.0 {
        (s / length, c / length)
    } else {
        (0.0, 1.0)
    }
}

/// The block of band `l` from band 1 and the block of band l − 1, by Ivanic
/// and Ruedenberg's recurrence (1996, Table 2; with the 1998 erratum's fix of
/// the V term for m = ±1). Indices are centred: −l ≤ m, n ≤ l.
fn next_band(band1: &[[f64; 3]; 3], previous: &[f64], l: i32) -> Vec<f64> {
    let prev_size = 2 * l - 1;
    let prev = |a: i32, b: i32| previous[((a + l - 1) * prev_size + (b + l - 1)) as usize];
    let r1 = |i: i32, j: i32| band1[(i + 1) as usize][(j + 1) as usize];
    // The helper function P of the paper.
    let p = |i: i32, a: i32, b: i32| -> f64 {
        if b == l {
            r1(i, 1) * prev(a, l - 1) - r1(i, -1) * prev(a, 1 - l)
        } else if b == -l {
            r1(i, 1) * prev(a, 1 - l) + r1(i, -1) * prev(a, l - 1)
        } else {
            r1(i, 0) * prev(a, b)
        }
    };
    let delta = |a: i32, b: i32| if a == b { 1.0 } else { 0.0 };
    let size = (2 * l + 1) as usize;
    let mut block = vec![0.0; size * size];
    for m in -l..=l {
        for n in -l..=l {
            let d = delta(m, 0);
            let denom = if n.abs() == l {
                (2 * l * (2 * l - 1)) as f64
            } else {
                ((l + n) * (l - n)) as f64
            };
            let ma = m.abs();
            let u = (((l + m) * (l - m)) as f64 / denom).sqrt();
            let v = 0.5
                * ((1.0 + d) * ((l + ma - 1) * (l + ma)) as f64 / denom).sqrt()
                * (1.0 - 2.0 * d);
            let w = -0.5 * (((l - ma - 1) * (l - ma)) as f64 / denom).sqrt() * (1.0 - d);
            let mut value = 0.0;
            if u != 0.0 {
                value += u * p(0, m, n);
            }
            if v != 0.0 {
                value += v * match m.signum() {
                    0 => p(1, 1, n) + p(-1, -1, n),
                    1 => {
                        p(1, m - 1, n) * (1.0 + delta(m, 1)).sqrt()
                            - p(-1, 1 - m, n) * (1.0 - delta(m, 1))
                    }
                    _ => {
                        p(1, m + 1, n) * (1.0 - delta(m, -1))
                            + p(-1, -m - 1, n) * (1.0 + delta(m, -1)).sqrt()
                    }
                };
            }
            if w != 0.0 {
                // w = 0 for m = 0, so m is ±.
                value += w * if m > 0 {
                    p(1, m + 1, n) + p(-1, -m - 1, n)
                } else {
                    p(1, m - 1, n) - p(-1, 1 - m, n)
                };
            }
            block[((m + l) as usize) * size + (n + l) as usize] = value;
        }
    }
    block
}

#[cfg(test)]
mod tests;
