//! The unoccluded diffuse integral `E(n) = ∫ L_env(ω) max(0, n·ω) dω` of a
//! lat-long environment taken as stored (piecewise constant per texel, the
//! function [`shadow_core::environment::EnvironmentSampler`] draws from),
//! per normal: the known part of the reference's control variate.
//!
//! A texel's cell is θ ∈ [θ₀, θ₁] × φ ∈ [φ₀, φ₁]. Where n·ω > 0 on the
//! whole cell, its part is exactly `L · (n · m)` with the cell's first
//! moment `m = ∫ ω dω` in closed form, so the cells wholly above the
//! horizon of a row, a contiguous arc of φ, are summed from per-row prefix
//! sums of `L ⊗ m`. On one latitude, n·ω = n_y cos θ + ρ sin θ cos(φ − φ_n)
//! with ρ = |(n_x, n_z)|, positive on an arc about φ_n; over a row's band
//! of θ, cells inside the narrower of the arcs at its two edges are wholly
//! above the horizon, and cells between the narrower and the wider arc
//! straddle it: those are integrated exactly in θ and by two-point
//! Gauss–Legendre in φ. The error is that of the straddling cells alone
//! (below 10⁻⁵ of E on the shipped maps; see the tests). A constant map's
//! `E(n)` is `π L` for every normal, taken as is.
//!
//! The control variate takes `E` at the centre of the normal's cell on an
//! octahedral grid of normals ([`Unoccluded::control`]), computed once per
//! cell and kept: any normal's exact `E` serves, so the estimate stays
//! unbiased, and a picture's hundred thousand pixels need a few thousand
//! integrals instead of one each.
//!
//! The cost of an integral is one `acos` per row edge and one `atan2` per quadrature node
//! of a straddling cell: the sines and cosines of cell edges and of the
//! nodes of whole cells are tabulated per column, those of the arc ends
//! follow from the arc's `acos` by angle addition, and those of the nodes
//! of clipped cells from their cell edge by a short Taylor series.

use std::f64::consts::{PI, TAU};
use std::sync::OnceLock;

use glam::{DVec3, Vec2, Vec3};
use shadow_core::Environment;

/// Cells per side of the octahedral grid of normals whose `E` the control
/// variate uses: 64 × 64 cells, a normal at most 3.7° from its cell's
/// centre (see the tests).
const NORMAL_GRID: usize = 64;

/// Two-point Gauss–Legendre nodes on [−1, 1], each of weight 1.
const GAUSS: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];

/// Per-row prefix sums of `L ⊗ m` over an environment's texels.
pub struct Unoccluded {
    width: usize,
    /// Row-major texel radiance.
    texels: Vec<DVec3>,
    /// Each row's band of θ.
    bands: Vec<Band>,
    /// The width of a column, `2π / width`.
    dphi: f64,
    /// `(sin, cos)` of the column edges `k · Δφ`, `k = 0..width`.
    columns: Vec<(f64, f64)>,
    /// `(sin, cos)` at the two quadrature nodes of each whole column.
    nodes: Vec<[(f64, f64); 2]>,
    /// Per row, `width + 1` prefix sums of the 3 × 3 `L ⊗ m` (channel-major:
    /// `[r·m, g·m, b·m]`).
    prefix: Vec<[DVec3; 3]>,
    /// `π L` where every texel holds the same `L`.
    constant: Option<Vec3>,
    /// `E` at the centre of each cell of the octahedral grid of normals,
    /// computed when first asked for.
    grid: Vec<OnceLock<Vec3>>,
}

impl Unoccluded {
    pub fn new(environment: &Environment) -> Unoccluded {
        let (width, height) = (environment.width(), environment.height());
        let dphi = TAU / width as f64;
        let texels: Vec<DVec3> = environment.texels().iter().map(|t| t.as_dvec3()).collect();
        let bands: Vec<Band> = (0..height).map(|row| Band::new(row, height)).collect();
        let columns = (0..width).map(|k| (k as f64 * dphi).sin_cos()).collect();
        let nodes = (0..width)
            .map(|k| {
                let mid = (k as f64 + 0.5) * dphi;
                GAUSS.map(|x| (mid + 0.5 * dphi * x).sin_cos())
            })
            .collect();
        let mut table = Unoccluded {
            width,
            texels,
            bands,
            dphi,
            columns,
            nodes,
            prefix: Vec::with_capacity(height * (width + 1)),
            constant: None,
            grid: (0..NORMAL_GRID * NORMAL_GRID)
                .map(|_| OnceLock::new())
                .collect(),
        };
        for row in 0..height {
            let mut sum = [DVec3::ZERO; 3];
            table.prefix.push(sum);
            for col in 0..width {
                let cell = (table.column(col as i64), table.column(col as i64 + 1));
                let m = table.bands[row].moment(cell);
                let l = table.texels[row * width + col];
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += l[c] * m;
                }
                table.prefix.push(sum);
            }
        }
        let first = environment.texels()[0];
        let constant = environment.texels().iter().all(|t| *t == first);
        table.constant = constant.then_some(first * PI as f32);
        table
    }

    /// The edge between columns `k − 1` and `k` (any integer: φ wraps).
    #[inline]
    fn column(&self, k: i64) -> Angle {
        let (sin, cos) = self.columns[k.rem_euclid(self.width as i64) as usize];
        Angle {
            at: k as f64 * self.dphi,
            sin,
            cos,
        }
    }

    /// The control variate of a point of unit normal `n`: a unit normal
    /// `m` near `n` and its exact `E(m)`. `m` is the centre of `n`'s cell
    /// on a 64 × 64 octahedral grid, its `E` computed once; under a
    /// constant map, `n` itself (`E` is the same for every normal).
    pub fn control(&self, n: Vec3) -> (Vec3, Vec3) {
        if let Some(e) = self.constant {
            return (n, e);
        }
        let (cell, centre) = grid_cell(n);
        (
            centre,
            *self.grid[cell].get_or_init(|| self.irradiance(centre)),
        )
    }

    /// `E(n)` for a unit normal `n`: radiance times clamped cosine over the
    /// sphere, per channel.
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        if let Some(e) = self.constant {
            return e;
        }
        let n = n.as_dvec3();
        let rho = (n.x * n.x + n.z * n.z).sqrt();
        let phi_n = Angle::new(n.z.atan2(n.x));
        let dphi = self.dphi;
        let count = self.width as i64;
        let texel =
            |row: usize, k: i64| self.texels[row * self.width + k.rem_euclid(count) as usize];
        let mut total = DVec3::ZERO;
        // A row's bottom edge is the next row's top: one `acos` per edge.
        let mut top = self.bands[0].half_width(n.y, rho, 0);
        for (row, band) in self.bands.iter().enumerate() {
            let bottom = band.half_width(n.y, rho, 1);
            let (inner, outer) = if top.at <= bottom.at {
                (top, bottom)
            } else {
                (bottom, top)
            };
            top = bottom;
            if outer.at <= 0.0 {
                continue;
            }
            if inner.at >= PI {
                let sum = self.row_sum(row, 0, count);
                total += DVec3::new(sum[0].dot(n), sum[1].dot(n), sum[2].dot(n));
                continue;
            }
            // Wholly above the horizon: φ within `inner` of φ_n. Whole cells
            // from the prefix sums, the two cells at its ends clipped.
            if inner.at > 0.0 {
                let (lo, hi) = (phi_n.minus(inner), phi_n.plus(inner));
                let first = (lo.at / dphi).floor() as i64;
                let last = (hi.at / dphi).ceil() as i64 - 1;
                if last > first + 1 {
                    let sum = self.row_sum(row, first + 1, last);
                    total += DVec3::new(sum[0].dot(n), sum[1].dot(n), sum[2].dot(n));
                }
                let ends = if last > first { 2 } else { 1 };
                for k in [first, last].into_iter().take(ends) {
                    let piece = (self.column(k).max(lo), self.column(k + 1).min(hi));
                    total += texel(row, k) * n.dot(band.moment(piece));
                }
            }
            // Where the horizon crosses the band: between `inner` and
            // `outer` of φ_n, on either side.
            for (lo, hi) in [
                (phi_n.plus(inner), phi_n.plus(outer)),
                (phi_n.minus(outer), phi_n.minus(inner)),
            ] {
                if hi.at <= lo.at {
                    continue;
                }
                for k in (lo.at / dphi).floor() as i64..(hi.at / dphi).ceil() as i64 {
                    let (p0, p1) = (self.column(k), self.column(k + 1));
                    let crossed = if lo.at <= p0.at && p1.at <= hi.at {
                        band.crossed(n, self.nodes[k.rem_euclid(count) as usize], 0.5 * dphi)
                    } else {
                        let (p0, p1) = (p0.max(lo), p1.min(hi));
                        let half = 0.5 * (p1.at - p0.at);
                        let nodes = GAUSS.map(|x| {
                            let node = p0.turned(half * (1.0 + x));
                            (node.sin, node.cos)
                        });
                        band.crossed(n, nodes, half)
                    };
                    total += texel(row, k) * crossed;
                }
            }
        }
        total.as_vec3()
    }

    /// Σ `L ⊗ m` over the cells `first..end` of `row`, wrapping in φ.
    fn row_sum(&self, row: usize, first: i64, end: i64) -> [DVec3; 3] {
        let w = self.width as i64;
        let base = row * (self.width + 1);
        let at = |k: i64| self.prefix[base + k as usize];
        let span = |a: i64, b: i64| {
            let (x, y) = (at(b), at(a));
            [x[0] - y[0], x[1] - y[1], x[2] - y[2]]
        };
        let add = |x: [DVec3; 3], y: [DVec3; 3]| [x[0] + y[0], x[1] + y[1], x[2] + y[2]];
        let (a, b) = (
            first.rem_euclid(w),
            first.rem_euclid(w) + (end - first).min(w),
        );
        if b <= w {
            span(a, b)
        } else {
            add(span(a, w), span(0, b - w))
        }
    }
}

/// The cell of the octahedral grid of normals that holds the unit vector
/// `n` (Meyer et al. 2010's octahedral map, +Y up), and the unit normal
/// at the cell's centre.
fn grid_cell(n: Vec3) -> (usize, Vec3) {
    let p = Vec2::new(n.x, n.z) / (n.x.abs() + n.y.abs() + n.z.abs());
    let p = if n.y < 0.0 { folded(p) } else { p };
    let side = NORMAL_GRID as f32;
    let index = |x: f32| (((x + 1.0) * 0.5 * side) as usize).min(NORMAL_GRID - 1);
    let (i, j) = (index(p.x), index(p.y));
    let centre = |k: usize| (k as f32 + 0.5) / side * 2.0 - 1.0;
    let q = Vec2::new(centre(i), centre(j));
    let y = 1.0 - q.x.abs() - q.y.abs();
    let q = if y < 0.0 { folded(q) } else { q };
    (j * NORMAL_GRID + i, Vec3::new(q.x, y, q.y).normalize())
}

/// The octahedral map's fold of the lower hemisphere onto the square's
/// corners, its own inverse.
fn folded(p: Vec2) -> Vec2 {
    let sign = |x: f32| if x < 0.0 { -1.0 } else { 1.0 };
    (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * Vec2::new(sign(p.x), sign(p.y))
}

/// An angle with its sine and cosine.
#[derive(Clone, Copy, Debug)]
struct Angle {
    at: f64,
    sin: f64,
    cos: f64,
}

impl Angle {
    const ZERO: Angle = Angle {
        at: 0.0,
        sin: 0.0,
        cos: 1.0,
    };
    const HALF_TURN: Angle = Angle {
        at: PI,
        sin: 0.0,
        cos: -1.0,
    };

    fn new(at: f64) -> Angle {
        let (sin, cos) = at.sin_cos();
        Angle { at, sin, cos }
    }

    /// `self + other`, by angle addition.
    #[inline]
    fn plus(self, other: Angle) -> Angle {
        Angle {
            at: self.at + other.at,
            sin: self.sin * other.cos + self.cos * other.sin,
            cos: self.cos * other.cos - self.sin * other.sin,
        }
    }

    /// `self − other`, by angle addition.
    #[inline]
    fn minus(self, other: Angle) -> Angle {
        Angle {
            at: self.at - other.at,
            sin: self.sin * other.cos - self.cos * other.sin,
            cos: self.cos * other.cos + self.sin * other.sin,
        }
    }

    /// `self + δ`: for |δ| ≤ 0.1 (a cell of a map 63 or more texels wide)
    /// δ's sine and cosine from their Taylor series to δ⁹ and δ¹⁰, whose
    /// next terms are below 10⁻¹⁸; beyond, directly.
    #[inline]
    fn turned(self, delta: f64) -> Angle {
        if delta.abs() > 0.1 {
            return Angle::new(self.at + delta);
        }
        let d2 = delta * delta;
        let sin =
            delta * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0))));
        let cos = 1.0
            - d2 / 2.0
                * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0 * (1.0 - d2 / 90.0))));
        self.plus(Angle {
            at: delta,
            sin,
            cos,
        })
    }

    /// The later of two angles.
    #[inline]
    fn max(self, other: Angle) -> Angle {
        if other.at > self.at { other } else { self }
    }

    /// The earlier of two angles.
    #[inline]
    fn min(self, other: Angle) -> Angle {
        if other.at < self.at { other } else { self }
    }
}

/// The θ band of a row.
fn band(row: usize, height: usize) -> (f64, f64) {
    let h = height as f64;
    (PI * row as f64 / h, PI * (row + 1) as f64 / h)
}

/// The φ range of a column.
#[cfg(test)]
fn arc(col: usize, width: usize) -> (f64, f64) {
    let w = width as f64;
    (TAU * col as f64 / w, TAU * (col + 1) as f64 / w)
}

/// A row's band of θ, with what the integrals need at its edges.
struct Band {
    t0: f64,
    t1: f64,
    /// (cos, sin) at each edge.
    edges: [(f64, f64); 2],
    /// The antiderivatives of sin θ cos θ and sin² θ at each edge.
    primitives: [(f64, f64); 2],
}

impl Band {
    fn new(row: usize, height: usize) -> Band {
        let (t0, t1) = band(row, height);
        let at = |t: f64| (t.sin().powi(2) / 2.0, t / 2.0 - (2.0 * t).sin() / 4.0);
        Band {
            t0,
            t1,
            edges: [(t0.cos(), t0.sin()), (t1.cos(), t1.sin())],
            primitives: [at(t0), at(t1)],
        }
    }

    /// Half the width of the arc of φ about φ_n where n·ω > 0 on the band's
    /// edge `edge` (0: top, 1: bottom): 0 for none, π for the whole circle.
    #[inline]
    fn half_width(&self, ny: f64, rho: f64, edge: usize) -> Angle {
        let (cos, sin) = self.edges[edge];
        let (a, b) = (ny * cos, rho * sin);
        if b <= 1e-12 {
            return if a > 0.0 {
                Angle::HALF_TURN
            } else {
                Angle::ZERO
            };
        }
        let x = (-a / b).clamp(-1.0, 1.0);
        Angle {
            at: x.acos(),
            sin: (1.0 - x * x).sqrt(),
            cos: x,
        }
    }

    /// `∫ ω dω` over the band and φ from `p0` to `p1`.
    #[inline]
    fn moment(&self, (p0, p1): (Angle, Angle)) -> DVec3 {
        let sincos = self.primitives[1].0 - self.primitives[0].0;
        let sin2 = self.primitives[1].1 - self.primitives[0].1;
        DVec3::new(
            sin2 * (p1.sin - p0.sin),
            sincos * (p1.at - p0.at),
            sin2 * (p0.cos - p1.cos),
        )
    }

    /// `∫ max(0, n·ω) dω` over the band and a piece of φ of half-width
    /// `half` whose quadrature nodes have the `(sin, cos)` given, where the
    /// horizon crosses the band's edges at no φ inside: exact in θ,
    /// two-point Gauss–Legendre in φ (the θ integral is smooth there).
    #[inline]
    fn crossed(&self, n: DVec3, nodes: [(f64, f64); 2], half: f64) -> f64 {
        nodes
            .iter()
            .map(|&(sin, cos)| half * self.positive_part(n.y, n.x * cos + n.z * sin))
            .sum()
    }

    /// `∫ max(0, a cos θ + c sin θ) sin θ dθ` over the band.
    #[inline]
    fn positive_part(&self, a: f64, c: f64) -> f64 {
        let value = |(cos, sin): (f64, f64)| a * cos + c * sin;
        let primitive = |(sc, s2): (f64, f64)| a * sc + c * s2;
        let (f0, f1) = (value(self.edges[0]), value(self.edges[1]));
        if f0 >= 0.0 && f1 >= 0.0 {
            return primitive(self.primitives[1]) - primitive(self.primitives[0]);
        }
        if f0 <= 0.0 && f1 <= 0.0 {
            return 0.0;
        }
        // One zero inside: a cos θ + c sin θ vanishes at the one θ* of
        // [0, π] with (cos θ*, sin θ*) = ±(c, −a)/R, the sign that makes
        // sin θ* ≥ 0 (a and c are not both zero: f0 and f1 differ in sign).
        let r = (a * a + c * c).sqrt();
        let (cos, sin) = if a <= 0.0 {
            (c / r, -a / r)
        } else {
            (-c / r, a / r)
        };
        let zero = sin.atan2(cos);
        let at_zero = if zero <= self.t0 {
            self.primitives[0]
        } else if zero >= self.t1 {
            self.primitives[1]
        } else {
            (sin * sin / 2.0, zero / 2.0 - sin * cos / 2.0)
        };
        if f0 > 0.0 {
            primitive(at_zero) - primitive(self.primitives[0])
        } else {
            primitive(self.primitives[1]) - primitive(at_zero)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use rand_core::Rng;
    use rand_pcg::Pcg32;

    /// The sum over every cell on a fine grid of sub-cells.
    fn brute(env: &Environment, n: Vec3, k: usize) -> DVec3 {
        let n = n.as_dvec3();
        let mut total = DVec3::ZERO;
        for row in 0..env.height() {
            let (t0, t1) = band(row, env.height());
            for col in 0..env.width() {
                let (p0, p1) = arc(col, env.width());
                let mut e = 0.0;
                for i in 0..k {
                    let (a, b) = (
                        t0 + (t1 - t0) * i as f64 / k as f64,
                        t0 + (t1 - t0) * (i + 1) as f64 / k as f64,
                    );
                    let solid = (a.cos() - b.cos()) * (p1 - p0) / k as f64;
                    let theta = 0.5 * (a + b);
                    for j in 0..k {
                        let phi = p0 + (p1 - p0) * (j as f64 + 0.5) / k as f64;
                        let w = DVec3::new(
                            theta.sin() * phi.cos(),
                            theta.cos(),
                            theta.sin() * phi.sin(),
                        );
                        e += solid * n.dot(w).max(0.0);
                    }
                }
                total += env.texel(row, col).as_dvec3() * e;
            }
        }
        total
    }

    fn random_env(width: usize, height: usize, rng: &mut Pcg32) -> Environment {
        let texels = (0..width * height)
            .map(|_| {
                let u = rng.next_u32() as f32 / u32::MAX as f32;
                // A few bright texels among dim ones, as under a sun.
                Vec3::new(u, 0.5 * u, 1.0 - u) * if u > 0.98 { 200.0 } else { 1.0 }
            })
            .collect();
        Environment::new("random", width, height, texels).unwrap()
    }

    fn unit(rng: &mut Pcg32) -> Vec3 {
        loop {
            let v = Vec3::new(
                rng.next_u32() as f32 / u32::MAX as f32 * 2.0 - 1.0,
                rng.next_u32() as f32 / u32::MAX as f32 * 2.0 - 1.0,
                rng.next_u32() as f32 / u32::MAX as f32 * 2.0 - 1.0,
            );
            if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }

    /// Against a 64 × 64 sub-cell sum of every cell, for random normals
    /// (and the poles and horizon-aligned ones) on a 48 × 24 random map with
    /// bright texels: measured within 1.1·10⁻⁶ of E; allowed 10⁻⁵.
    #[test]
    fn matches_a_fine_sum_over_every_cell() {
        let mut rng = Pcg32::new(7, 11);
        let env = random_env(48, 24, &mut rng);
        let table = Unoccluded::new(&env);
        let mut normals = vec![
            Vec3::Y,
            -Vec3::Y,
            Vec3::X,
            Vec3::Z,
            Vec3::new(1.0, 1.0, 0.0).normalize(),
        ];
        normals.extend((0..40).map(|_| unit(&mut rng)));
        let mut largest = 0.0f64;
        for n in normals {
            let fast = table.irradiance(n).as_dvec3();
            let slow = brute(&env, n, 64);
            let error = (fast - slow).length() / slow.length();
            largest = largest.max(error);
            assert!(error < 1e-5, "n = {n}: {fast} against {slow} ({error:e})");
        }
        eprintln!("largest relative difference {largest:e}");
    }

    /// Every normal lies within a few degrees of its cell's centre, and the
    /// centre lies in its own cell (measured over 20000 random normals:
    /// 3.7° at most, at the folded corners of the octahedron; allowed 4.5°).
    #[test]
    fn normals_lie_near_their_cells_centre() {
        let mut rng = Pcg32::new(5, 9);
        let mut largest = 0.0f32;
        for _ in 0..20000 {
            let n = unit(&mut rng);
            let (cell, centre) = grid_cell(n);
            assert!(cell < NORMAL_GRID * NORMAL_GRID);
            assert_eq!(grid_cell(centre).0, cell, "{n}: centre {centre}");
            largest = largest.max(n.dot(centre).clamp(-1.0, 1.0).acos().to_degrees());
        }
        eprintln!("largest angle {largest}°");
        assert!(largest < 4.5, "{largest}°");
    }

    /// Angle addition and the Taylor series of small turns give the sines
    /// and cosines that `sin_cos` gives, to rounding (measured 4.4·10⁻¹⁶).
    #[test]
    fn turned_angles_keep_their_sines() {
        let mut largest = 0.0f64;
        for i in 0..=400 {
            let start = Angle::new(-7.0 + 0.035 * i as f64);
            for delta in [-0.3, -0.1, -0.07, -1e-3, 0.0, 2e-6, 0.006, 0.099, 0.1, 0.25] {
                let turned = start.turned(delta);
                let (sin, cos) = (start.at + delta).sin_cos();
                assert_eq!(turned.at, start.at + delta);
                largest = largest.max((turned.sin - sin).abs().max((turned.cos - cos).abs()));
            }
        }
        eprintln!("largest difference {largest:e}");
        assert!(largest < 1e-15, "{largest:e}");
    }

    /// A uniform sky of radiance 1 gives π for every normal: exactly, as a
    /// constant map, and through the cells. Its 16 × 8 map's cells are
    /// 22.5° wide, the coarsest a quadrature of two points per crossed
    /// piece meets: measured 2.9·10⁻⁵ of π at most over 200 normals (three
    /// points gave 1.7·10⁻⁶ at 1.4 times the cost on a 1024 × 512 map);
    /// allowed 10⁻⁴, fifty times below the reference's 0.5% noise.
    #[test]
    fn a_uniform_sky_gives_pi() {
        let env = Environment::uniform(Vec3::ONE);
        let exact = Unoccluded::new(&env);
        assert_eq!(exact.irradiance(Vec3::Y), Vec3::splat(std::f32::consts::PI));
        let table = Unoccluded {
            constant: None,
            ..exact
        };
        let mut rng = Pcg32::new(3, 5);
        let mut largest = 0.0f32;
        for _ in 0..200 {
            let e = table.irradiance(unit(&mut rng));
            let error =
                (e - Vec3::splat(std::f32::consts::PI)).abs().max_element() / std::f32::consts::PI;
            largest = largest.max(error);
        }
        eprintln!("largest relative difference {largest:e}");
        assert!(largest < 1e-4, "{largest:e}");
    }
}
