//! The two tests a ray does against eight things at once, the boxes of a
//! node's children and the triangles of a leaf, in two forms: AVX2 + FMA
//! intrinsics (x86-64 CPUs that have them, detected at run time) and plain
//! loops over arrays for every other CPU. Both compute the same
//! operations in the same order, so they agree bit for bit.
//!
//! The triangle test is Möller and Trumbore's in the form Embree's
//! intersectors use: the two barycentrics and the distance are kept scaled
//! by the determinant, made positive by its sign, and compared with its
//! magnitude, so that no lane divides until one hits.

use std::mem::MaybeUninit;

use glam::Vec3A;

use super::wide::{Block, Node};

/// Lanes per node and per leaf block.
pub const LANES: usize = 8;

/// Eight floats, one per lane.
pub type Row = [f32; LANES];

/// Tfar is widened by this factor (three ulps) before it is compared with
/// tnear, so that rounding in the slab distances never drops a box that the
/// ray grazes (Ize 2013, "Robust BVH ray traversal", §3).
const WIDEN: f32 = 1.0 + 3.0 * f32::EPSILON;

/// The sign bit of an f32.
const SIGN: u32 = 1 << 31;

/// A ray as the tests read it.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    origin: [f32; 3],
    dir: [f32; 3],
    /// 1 / direction, a zero component taken as 10⁻³⁰ (a slab the ray runs
    /// along is then entered and left at ∓10³⁰-ish distances, or never).
    inv: [f32; 3],
    /// Per axis, whether the near plane of a box is its upper one (the ray
    /// runs toward −axis).
    flip: [bool; 3],
}

impl Ray {
    pub fn new(origin: Vec3A, dir: Vec3A) -> Ray {
        let dir = dir.to_array();
        let inv = dir.map(|d| 1.0 / if d == 0.0 { 1e-30 } else { d });
        Ray {
            origin: origin.to_array(),
            dir,
            inv,
            flip: inv.map(|i| i < 0.0),
        }
    }
}

/// The CPU can run [`Avx2`].
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Work written once over [`Lanes`] and compiled per path: `run` must be
/// `#[inline(always)]`, so that it is compiled inside the path's
/// `#[target_feature]` function.
pub trait Kernel {
    type Output;
    fn run<L: Lanes>(self) -> Self::Output;
}

/// Runs `kernel` with [`Avx2`] where `avx2` (which must come from
/// [`avx2()`]) says the CPU has it, else with [`Portable`].
#[inline]
pub fn run<K: Kernel>(avx2: bool, kernel: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` comes from the run-time detection.
        return unsafe { run_avx2(kernel) };
    }
    let _ = avx2;
    kernel.run::<Portable>()
}

/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn run_avx2<K: Kernel>(kernel: K) -> K::Output {
    kernel.run::<Avx2>()
}

/// The traversal's stack of node indices, left uninitialized (a walk
/// starts thousands of times a millisecond, and zeroing a stack for the
/// deepest tree took 4% of a bake). Pushing past `N` panics.
pub struct Stack<const N: usize> {
    items: [MaybeUninit<u32>; N],
    len: usize,
}

impl<const N: usize> Stack<N> {
    #[inline(always)]
    pub fn new(first: u32) -> Self {
        let mut items = [const { MaybeUninit::uninit() }; N];
        items[0].write(first);
        Stack { items, len: 1 }
    }

    #[inline(always)]
    pub fn push(&mut self, item: u32) {
        self.items[self.len].write(item);
        self.len += 1;
    }

    #[inline(always)]
    pub fn pop(&mut self) -> Option<u32> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: every slot below the old length was written by `new` or
        // `push`.
        Some(unsafe { self.items[self.len].assume_init() })
    }
}

/// A way to run the two eight-lane tests.
pub trait Lanes {
    /// The mask of `node`'s children whose boxes `ray` meets at a distance
    /// in [0, `t_max`].
    fn boxes(node: &Node, ray: &Ray, t_max: f32) -> u32;
    /// The mask of `block`'s triangles that `ray` hits at a distance in
    /// [0, `t_max`], and the distances (meaningful in the mask's lanes
    /// only).
    fn triangles(block: &Block, ray: &Ray, t_max: f32) -> (u32, Row);
}

/// Loops over arrays, for any CPU.
pub struct Portable;

impl Lanes for Portable {
    #[inline(always)]
    fn boxes(node: &Node, ray: &Ray, t_max: f32) -> u32 {
        let mut near = [0.0f32; LANES];
        let mut far = [t_max; LANES];
        for a in 0..3 {
            let (lo, hi) = if ray.flip[a] {
                (&node.hi[a], &node.lo[a])
            } else {
                (&node.lo[a], &node.hi[a])
            };
            for i in 0..LANES {
                near[i] = max(near[i], (lo[i] - ray.origin[a]) * ray.inv[a]);
                far[i] = min(far[i], (hi[i] - ray.origin[a]) * ray.inv[a]);
            }
        }
        let mut mask = 0;
        for i in 0..LANES {
            mask |= u32::from(near[i] <= far[i] * WIDEN) << i;
        }
        mask
    }

    #[inline(always)]
    fn triangles(block: &Block, ray: &Ray, t_max: f32) -> (u32, Row) {
        let [dx, dy, dz] = ray.dir;
        let mut t = [0.0f32; LANES];
        let mut mask = 0;
        for i in 0..LANES {
            let c = [0, 1, 2].map(|a| block.v0[a][i] - ray.origin[a]);
            let r = [
                dy * c[2] - dz * c[1],
                dz * c[0] - dx * c[2],
                dx * c[1] - dy * c[0],
            ];
            let dot = |v: &[Row; 3], w: [f32; 3]| v[0][i] * w[0] + v[1][i] * w[1] + v[2][i] * w[2];
            let det = dot(&block.ng, ray.dir);
            let sign = det.to_bits() & SIGN;
            let signed = |x: f32| f32::from_bits(x.to_bits() ^ sign);
            let scale = f32::from_bits(det.to_bits() & !SIGN);
            let u = signed(dot(&block.e2, r));
            let v = signed(dot(&block.e1, r));
            let along = signed(dot(&block.ng, c));
            let inside = u >= 0.0 && v >= 0.0 && u + v <= scale;
            let ahead = along >= 0.0 && along <= scale * t_max;
            let hit = det != 0.0 && inside && ahead;
            mask |= u32::from(hit) << i;
            t[i] = along / scale;
        }
        (mask, t)
    }
}

/// `a` if it is the larger, else `b`, as `maxps` computes it.
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `a` if it is the smaller, else `b`, as `minps` computes it.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// AVX2 + FMA intrinsics: only to be used where [`avx2`] is true.
#[cfg(target_arch = "x86_64")]
pub struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    #[inline(always)]
    fn boxes(node: &Node, ray: &Ray, t_max: f32) -> u32 {
        // SAFETY: `Avx2` runs only where the CPU has AVX2 and FMA.
        unsafe { x86::boxes(node, ray, t_max) }
    }

    #[inline(always)]
    fn triangles(block: &Block, ray: &Ray, t_max: f32) -> (u32, Row) {
        // SAFETY: as above.
        unsafe { x86::triangles(block, ray, t_max) }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::{Block, LANES, Node, Ray, Row, SIGN, WIDEN};

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn load(row: &Row) -> __m256 {
        // SAFETY: a row is eight floats, read unaligned.
        unsafe { _mm256_loadu_ps(row.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub fn boxes(node: &Node, ray: &Ray, t_max: f32) -> u32 {
        let mut near = _mm256_setzero_ps();
        let mut far = _mm256_set1_ps(t_max);
        for a in 0..3 {
            let (lo, hi) = if ray.flip[a] {
                (&node.hi[a], &node.lo[a])
            } else {
                (&node.lo[a], &node.hi[a])
            };
            let origin = _mm256_set1_ps(ray.origin[a]);
            let inv = _mm256_set1_ps(ray.inv[a]);
            near = _mm256_max_ps(near, _mm256_mul_ps(_mm256_sub_ps(load(lo), origin), inv));
            far = _mm256_min_ps(far, _mm256_mul_ps(_mm256_sub_ps(load(hi), origin), inv));
        }
        let far = _mm256_mul_ps(far, _mm256_set1_ps(WIDEN));
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub fn triangles(block: &Block, ray: &Ray, t_max: f32) -> (u32, Row) {
        let d = ray.dir.map(|x| _mm256_set1_ps(x));
        let c: [__m256; 3] =
            [0, 1, 2].map(|a| _mm256_sub_ps(load(&block.v0[a]), _mm256_set1_ps(ray.origin[a])));
        let cross = |p: __m256, q: __m256, s: __m256, t: __m256| {
            _mm256_sub_ps(_mm256_mul_ps(p, q), _mm256_mul_ps(s, t))
        };
        let r = [
            cross(d[1], c[2], d[2], c[1]),
            cross(d[2], c[0], d[0], c[2]),
            cross(d[0], c[1], d[1], c[0]),
        ];
        let dot = |v: &[Row; 3], w: &[__m256; 3]| {
            let xy = _mm256_add_ps(
                _mm256_mul_ps(load(&v[0]), w[0]),
                _mm256_mul_ps(load(&v[1]), w[1]),
            );
            _mm256_add_ps(xy, _mm256_mul_ps(load(&v[2]), w[2]))
        };
        let det = dot(&block.ng, &d);
        let sign_bit = _mm256_set1_ps(f32::from_bits(SIGN));
        let sign = _mm256_and_ps(det, sign_bit);
        let scale = _mm256_andnot_ps(sign_bit, det);
        let u = _mm256_xor_ps(dot(&block.e2, &r), sign);
        let v = _mm256_xor_ps(dot(&block.e1, &r), sign);
        let along = _mm256_xor_ps(dot(&block.ng, &c), sign);
        let zero = _mm256_setzero_ps();
        let ge = |x: __m256| _mm256_cmp_ps::<_CMP_GE_OQ>(x, zero);
        let inside = _mm256_and_ps(
            _mm256_and_ps(ge(u), ge(v)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_add_ps(u, v), scale),
        );
        let ahead = _mm256_and_ps(
            ge(along),
            _mm256_cmp_ps::<_CMP_LE_OQ>(along, _mm256_mul_ps(scale, _mm256_set1_ps(t_max))),
        );
        let valid = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_NEQ_OQ>(det, zero),
            _mm256_and_ps(inside, ahead),
        );
        let mask = _mm256_movemask_ps(valid) as u32;
        if mask == 0 {
            return (0, [0.0; LANES]);
        }
        let t = _mm256_div_ps(along, scale);
        let mut out = [0.0f32; LANES];
        // SAFETY: `out` is eight floats, written unaligned.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), t) };
        (mask, out)
    }
}
