//! Self-shadowing (§4.1, §5.1): each object's precomputed transfer, and the
//! radiance it gives under a lighting.
//!
//! The transfer of vertex x is the SH projection, in the object's model
//! space, of its cosine-weighted self-visibility
//! t(ω) = v_s(x, ω) max(0, n·ω), traced against the object alone. This is
//! π times the paper's T of eq. 1 (the [`ShTransfer`] convention: the
//! irradiance is L·t), so that one vector serves both cases:
//!
//! - diffuse (eq. 2): L_s = ρ/π · L·t, with 36 terms (`ShOrder` 6, the
//!   paper's "5th order");
//! - glossy (eq. 9–13): the first 16 terms (`ShOrder` 4, its "3rd order")
//!   are the visibility vector of eq. 11 *with* the cosine of DESIGN.md's
//!   L_o, which eq. 9 leaves out. The lighting is the matrix of eq. 10,
//!   L_ij = ∫ L y_i y_j dω, so that P = L t is the projection of the lit,
//!   self-shadowed, cosine-weighted radiance L·v_s·cos; the Phong lobe is
//!   then a zonal convolution of P evaluated at the mirror direction (eq.
//!   12–13), and the diffuse part is ρ_d/π ∫ P dω.
//!
//! The same vector, evaluated at a light's direction, is the per-vertex
//! weight v_s(x, ω_i) max(0, n·ω_i) of the deferred pass (eq. 8, §6.2.3).

use std::f32::consts::PI;
use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Vec3};
use rayon::prelude::*;
use shadow_core::{
    Environment, FrameGeometry, Mesh, PosedObject, Result, ShTransfer, SurfacePoint, TangentSpace,
    TransferSpace,
    bvh::SceneBvh,
    qmc::{cosine_hemisphere, sobol2},
    sh::{ShOrder, ShRgb, ShRotation, Window, Zonal, eval_basis, project_environment},
};

use crate::lights::Samples;

/// The diffuse transfer's order: 36 terms.
pub const DIFFUSE_ORDER: ShOrder = match ShOrder::new(6) {
    Some(order) => order,
    None => panic!("order 6"),
};

/// The glossy transfer's order: 16 terms.
pub const GLOSSY_ORDER: ShOrder = match ShOrder::new(4) {
    Some(order) => order,
    None => panic!("order 4"),
};

/// One object's precomputed transfer, in model space.
#[derive(Clone, Debug)]
pub struct Transfer {
    pub order: ShOrder,
    /// `order.coeff_count()` coefficients per vertex.
    pub coefficients: Vec<f32>,
    /// Wall-clock seconds the precomputation took.
    pub seconds: f64,
}

impl Transfer {
    /// Traces `rays` cosine-distributed shadow rays from every vertex of
    /// `mesh` (model space) against the mesh alone, and projects what they
    /// see onto the SH basis of `order`:
    /// t_i = ∫ v_s cos y_i dω ≈ π/N Σ_k v_s(ω_k) y_i(ω_k).
    ///
    /// The directions are the 2-D Sobol' points mapped to the
    /// cosine-weighted hemisphere ([`shadow_core::qmc`], as the reference
    /// draws them) under a digital shift per vertex, so that neighbouring
    /// vertices do not share their aliasing.
    pub fn precompute(mesh: &Arc<Mesh>, order: ShOrder, rays: u32) -> Result<Transfer> {
        let start = Instant::now();
        let alone = FrameGeometry {
            frame: 0,
            objects: vec![PosedObject {
                mesh: Arc::clone(mesh),
                transform: Some(Affine3A::IDENTITY),
            }],
        };
        let bvh = SceneBvh::build(&alone)?;
        let n = order.coeff_count();
        let mut coefficients = vec![0.0f32; mesh.vertex_count() * n];
        let scale = PI / rays as f32;
        coefficients
            .par_chunks_mut(n)
            .enumerate()
            .for_each(|(v, out)| {
                let at = SurfacePoint {
                    position: mesh.positions()[v].as_dvec3(),
                    normal: mesh.normals()[v],
                    lift: mesh.lifts()[v],
                };
                let tangents = TangentSpace::new(at.normal);
                let shift = vertex_shift(v as u32);
                let mut basis = [0.0f32; 64];
                for k in 0..rays {
                    let local = cosine_hemisphere(sobol2(k, shift));
                    let dir = tangents.to_world(local).normalize();
                    if bvh.unoccluded_from(&at, dir, f32::INFINITY) {
                        eval_basis(order, dir, &mut basis);
                        for (o, b) in out.iter_mut().zip(&basis) {
                            *o += b;
                        }
                    }
                }
                for o in out {
                    *o *= scale;
                }
            });
        Ok(Transfer {
            order,
            coefficients,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    pub fn vertex(&self, v: usize) -> &[f32] {
        let n = self.order.coeff_count();
        &self.coefficients[v * n..(v + 1) * n]
    }

    pub fn vertex_count(&self) -> usize {
        self.coefficients.len() / self.order.coeff_count()
    }

    /// Bytes of precomputed data (32-bit floats, as the GPU holds them).
    pub fn bytes(&self) -> usize {
        4 * self.coefficients.len()
    }

    /// Each vertex's vector turned by `rotation` (model to world).
    pub fn rotated(&self, rotation: Mat3) -> Vec<f32> {
        let sh = ShRotation::from_mat3(self.order, rotation)
            .expect("rigid poses carry proper rotations");
        let n = self.order.coeff_count();
        let mut out = vec![0.0; self.coefficients.len()];
        out.par_chunks_mut(n)
            .zip(self.coefficients.par_chunks(n))
            .for_each(|(dst, src)| sh.apply(src, dst));
        out
    }

    /// The weight v_s(x, ω) max(0, n·ω) of every vertex toward each of
    /// `directions` (model space): the vector evaluated there, clamped to
    /// [0, 1] (a truncated expansion rings), light after light per vertex.
    pub fn expand(&self, directions: &[Vec3], out: &mut [f32]) {
        let n = self.order.coeff_count();
        let q = directions.len();
        let mut bases = vec![0.0f32; q * n];
        for (d, basis) in directions.iter().zip(bases.chunks_exact_mut(n)) {
            eval_basis(self.order, *d, basis);
        }
        out.par_chunks_mut(q)
            .zip(self.coefficients.par_chunks(n))
            .for_each(|(weights, t)| {
                for (w, basis) in weights.iter_mut().zip(bases.chunks_exact(n)) {
                    let dot: f32 = t.iter().zip(basis).map(|(a, b)| a * b).sum();
                    *w = dot.clamp(0.0, 1.0);
                }
            });
    }
}

/// The lighting in the forms the self-shadowing needs, in world space.
#[derive(Clone, Debug)]
pub struct Lighting {
    /// The environment's projection, [`DIFFUSE_ORDER`], windowed.
    pub sh: ShRgb,
    /// Eq. 10's matrix L_ij = ∫ L y_i y_j dω over [`GLOSSY_ORDER`]'s
    /// basis, row-major, 16 × 16.
    pub matrix: Vec<Vec3>,
    /// The window on the diffuse lighting's bands and on the glossy lit
    /// transfer's (P = L t, before the lobe).
    pub window: Window,
}

/// The matrix is integrated over the map at most this many texels wide.
const MATRIX_WIDTH: usize = 256;

/// Directions per task of the matrix's integration.
const MATRIX_CHUNK: usize = 1024;

impl Lighting {
    /// The SH projection (exact per texel) and eq. 10's matrix, integrated
    /// by the midpoint rule over the map's texels, split into finer ones on
    /// maps narrower than 128 texels as the area lights split them: over
    /// the 16 × 8 texels of [`Environment::uniform`] alone the rule is off
    /// the identity by 0.047, split by 6.0e-4.
    ///
    /// `window` scales the bands of the diffuse projection here, and those
    /// of each glossy vertex's lit transfer (eq. 12).
    pub fn new(environment: &Environment, window: Window) -> Lighting {
        let sh = window.apply(&project_environment(environment, DIFFUSE_ORDER));
        let env = if environment.width() > MATRIX_WIDTH {
            environment.downsampled(MATRIX_WIDTH, MATRIX_WIDTH / 2)
        } else {
            environment.clone()
        };
        let samples = Samples::of(&env);
        let n = GLOSSY_ORDER.coeff_count();
        let matrix = samples
            .directions
            .par_chunks(MATRIX_CHUNK)
            .zip(samples.radiance.par_chunks(MATRIX_CHUNK))
            .zip(samples.solid_angle.par_chunks(MATRIX_CHUNK))
            .map(|((directions, radiance), solid_angle)| {
                let mut m = vec![Vec3::ZERO; n * n];
                let mut y = [0.0f32; 16];
                for ((&direction, &radiance), &omega) in
                    directions.iter().zip(radiance).zip(solid_angle)
                {
                    let l = radiance * omega;
                    eval_basis(GLOSSY_ORDER, direction, &mut y);
                    for i in 0..n {
                        for j in 0..n {
                            m[i * n + j] += l * (y[i] * y[j]);
                        }
                    }
                }
                m
            })
            .reduce(
                || vec![Vec3::ZERO; n * n],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                    a
                },
            );
        Lighting { sh, matrix, window }
    }
}

/// A glossy vertex's view-independent part (eq. 12): the lit transfer
/// P = L t convolved with the Phong lobe, G = Λ ⊙ P, and the diffuse
/// radiance ρ_d/π ∫ P dω.
#[derive(Clone, Copy, Debug, Default)]
pub struct GlossyVertex {
    pub lobe: [Vec3; 16],
    pub diffuse: Vec3,
}

impl GlossyVertex {
    /// Eq. 13: the radiance toward the viewer, given the mirror direction of
    /// the view about the normal, with ρ_s applied.
    pub fn radiance(&self, mirror: Vec3, specular: Vec3) -> Vec3 {
        let mut y = [0.0f32; 16];
        eval_basis(GLOSSY_ORDER, mirror, &mut y);
        let lobe: Vec3 = self.lobe.iter().zip(y).map(|(g, y)| *g * y).sum();
        self.diffuse + specular * lobe
    }
}

/// The glossy vertices of one object under `lighting`: `world` holds its
/// 16-term vectors already turned to world space ([`Transfer::rotated`]),
/// `lobe` is the material's Phong lobe over [`GLOSSY_ORDER`]
/// ([`Zonal::phong`]).
pub fn glossy(
    lighting: &Lighting,
    world: &[f32],
    diffuse: Vec3,
    lobe: &Zonal,
) -> Vec<GlossyVertex> {
    let n = GLOSSY_ORDER.coeff_count();
    let lambda: Vec<f32> = (0..n)
        .map(|i| {
            let band = (i as f32).sqrt() as usize;
            lobe.eigenvalues()[band] * lighting.window.factor(band, GLOSSY_ORDER)
        })
        .collect();
    // ∫ P dω = √(4π) P_0.
    let integral = (4.0 * PI).sqrt();
    world
        .par_chunks(n)
        .map(|t| {
            let mut out = GlossyVertex::default();
            let rows = lighting.matrix.chunks_exact(n);
            for (i, ((g, row), lambda)) in out.lobe.iter_mut().zip(rows).zip(&lambda).enumerate() {
                let p: Vec3 = row.iter().zip(t).map(|(l, t)| *l * *t).sum();
                *g = p * *lambda;
                if i == 0 {
                    out.diffuse = diffuse / PI * integral * p;
                }
            }
            out
        })
        .collect()
}

/// The radiance of a Lambert object's vertices (eq. 2): ρ/π L·t, the
/// lighting turned into model space by the inverse of `rotation`.
pub fn diffuse(
    lighting: &Lighting,
    transfer: &Transfer,
    rotation: Mat3,
    albedo: Vec3,
) -> Vec<Vec3> {
    let to_model = ShRotation::from_mat3(DIFFUSE_ORDER, rotation.transpose())
        .expect("rigid poses carry proper rotations");
    let light = lighting.sh.rotated(&to_model);
    transfer
        .coefficients
        .par_chunks(transfer.order.coeff_count())
        .map(|t| albedo / PI * light.dot(t))
        .collect()
}

/// The transfer of every object in world space for `frame`, as exported.
pub fn export(transfers: &[&Transfer], rotations: &[Mat3]) -> Result<ShTransfer> {
    let order = transfers
        .iter()
        .map(|t| t.order)
        .min()
        .unwrap_or(DIFFUSE_ORDER);
    let n = order.coeff_count();
    let mut coefficients = Vec::new();
    for (t, r) in transfers.iter().zip(rotations) {
        let world = t.rotated(*r);
        for v in world.chunks_exact(t.order.coeff_count()) {
            coefficients.extend_from_slice(&v[..n]);
        }
    }
    ShTransfer::new(
        order,
        TransferSpace::World,
        transfers.iter().map(|t| t.vertex_count()).collect(),
        coefficients,
    )
}

/// A vertex's digital shift of the Sobol' points (a PCG hash of its index).
fn vertex_shift(v: u32) -> [u32; 2] {
    let pcg = |x: u32| {
        let state = x.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
        let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
        (word >> 22) ^ word
    };
    let a = pcg(v);
    [a, pcg(a)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use shadow_core::shapes;

    /// Single quads facing six directions, nothing above them: every vertex
    /// sees its whole hemisphere. Their normals, one per vertex.
    fn open_quads() -> Vec<(Arc<Mesh>, Vec3)> {
        [
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::X,
            Vec3::new(0.3, 0.8, -0.5),
            Vec3::new(-0.6, -0.2, 0.7),
            Vec3::new(0.1, -0.9, -0.4),
        ]
        .into_iter()
        .map(|normal| {
            let normal = normal.normalize();
            let (du, dv) = normal.any_orthonormal_pair();
            let mesh = shapes::grid("quad", Vec3::ZERO, du, dv, 1, 1).unwrap();
            assert!(mesh.normals().iter().all(|n| n.dot(normal) > 0.9999));
            (Arc::new(mesh), normal)
        })
        .collect()
    }

    fn most_apart(a: &[f32], b: &[f32]) -> f32 {
        a.iter()
            .zip(b)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max)
    }

    /// The 16-term transfer of an unoccluded vertex is the projection of
    /// the clamped cosine about its normal, max(0, n·ω) (the Phong lobe of
    /// exponent 1, up to the lobe's normalization 3/(2π)): Λ_l y_lm(n) with
    /// Λ the zonal eigenvalues of `Zonal::lambert`, π, 2π/3, π/4, 0.
    #[test]
    fn an_unoccluded_glossy_transfer_is_the_cosine_lobe_s_zonal_projection() {
        let cosine = Zonal::lambert(GLOSSY_ORDER);
        let phong = Zonal::phong(GLOSSY_ORDER, 1.0).unwrap();
        for (c, p) in cosine.eigenvalues().iter().zip(phong.eigenvalues()) {
            assert!((c - 2.0 * PI / 3.0 * p).abs() < 1e-6);
        }
        let mut expected = [0.0f32; 16];
        let mut worst = 0.0f32;
        for (mesh, normal) in open_quads() {
            let transfer = Transfer::precompute(&mesh, GLOSSY_ORDER, 512).unwrap();
            cosine.project_along(normal, &mut expected);
            for v in 0..transfer.vertex_count() {
                worst = worst.max(most_apart(transfer.vertex(v), &expected));
            }
        }
        println!("largest coefficient error {worst}");
        // Measured: 8.3e-3 (512 Sobol' rays per vertex; the largest
        // coefficient, Λ_0 y_00, is 0.886).
        assert!(worst < 1.5e-2, "{worst}");
    }

    /// The white furnace at 36 terms, on the CPU: an unoccluded Lambert
    /// vertex under uniform unit light reflects its albedo ρ (eq. 2:
    /// ρ/π L·t, with L·t = π), turned or not.
    #[test]
    fn the_diffuse_furnace_gives_the_albedo() {
        let lighting = Lighting::new(&Environment::uniform(Vec3::ONE), Window::None);
        let albedo = Vec3::new(0.2, 0.5, 0.9);
        let turn = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 1.1);
        let mut worst = 0.0f32;
        for (mesh, _) in open_quads() {
            let transfer = Transfer::precompute(&mesh, DIFFUSE_ORDER, 512).unwrap();
            for rotation in [Mat3::IDENTITY, turn] {
                for radiance in diffuse(&lighting, &transfer, rotation, albedo) {
                    worst = worst.max(((radiance - albedo) / albedo).abs().max_element());
                }
            }
        }
        println!("largest relative error {worst}");
        // Measured: 2.6e-7 (t_00 = π y_00 exactly: every ray is unoccluded).
        assert!(worst < 1e-5, "{worst}");
    }

    /// The white furnace at 16 terms, on the CPU: an unoccluded glossy
    /// vertex's diffuse part under uniform unit light is ρ_d (ρ_d/π ∫ P dω
    /// with P = L t, eq. 11–12), and its lobe is the Phong lobe convolved
    /// with the clamped cosine about the normal: toward the mirror direction
    /// r, Σ_l Λ_l^Phong Λ_l^cos (2l+1)/(4π) P_l(n·r) (the addition theorem,
    /// with the Legendre polynomials P_l written out here).
    #[test]
    fn the_glossy_furnace_gives_the_diffuse_albedo_and_the_zonal_lobe() {
        let lighting = Lighting::new(&Environment::uniform(Vec3::ONE), Window::None);
        let rho = Vec3::new(0.2, 0.4, 0.6);
        let exponent = 12.0;
        let phong = Zonal::phong(GLOSSY_ORDER, exponent).unwrap();
        let cosine = Zonal::lambert(GLOSSY_ORDER);
        let legendre = |t: f32| {
            [
                1.0,
                t,
                0.5 * (3.0 * t * t - 1.0),
                0.5 * (5.0 * t * t * t - 3.0 * t),
            ]
        };
        let turn = Mat3::from_axis_angle(Vec3::new(-2.0, 1.0, 0.5).normalize(), 0.7);
        let (mut diffuse_error, mut lobe_error) = (0.0f32, 0.0f32);
        for (mesh, normal) in open_quads() {
            let transfer = Transfer::precompute(&mesh, GLOSSY_ORDER, 512).unwrap();
            for rotation in [Mat3::IDENTITY, turn] {
                let normal = rotation * normal;
                let vertices = glossy(&lighting, &transfer.rotated(rotation), rho, &phong);
                for vertex in vertices {
                    diffuse_error =
                        diffuse_error.max(((vertex.diffuse - rho) / rho).abs().max_element());
                    for k in 0..8 {
                        let r = shadow_core::environment::direction_from_angles(
                            0.4 * k as f32,
                            1.3 * k as f32,
                        );
                        let expected: f32 = legendre(normal.dot(r))
                            .iter()
                            .enumerate()
                            .map(|(l, p)| {
                                phong.eigenvalues()[l]
                                    * cosine.eigenvalues()[l]
                                    * (2 * l + 1) as f32
                                    / (4.0 * PI)
                                    * p
                            })
                            .sum();
                        let lobe = vertex.radiance(r, Vec3::ONE) - vertex.diffuse;
                        lobe_error =
                            lobe_error.max((lobe - Vec3::splat(expected)).abs().max_element());
                    }
                }
            }
        }
        println!("diffuse relative error {diffuse_error}, lobe error {lobe_error}");
        // Measured: diffuse 1.3e-4, lobe 3.5e-3 (the lobe peaks at 1.05;
        // with the matrix integrated over the unsplit 16 × 8 texels, 8.4e-3
        // and 4.4e-2).
        assert!(diffuse_error < 1e-3, "{diffuse_error}");
        assert!(lobe_error < 1e-2, "{lobe_error}");
    }

    /// Eq. 10's matrix of a uniform unit environment is the identity
    /// (orthonormal basis), on a coarse map as on a fine one.
    #[test]
    fn a_uniform_environment_s_lighting_matrix_is_the_identity() {
        let (w, h) = (256, 128);
        for env in [
            Environment::uniform(Vec3::ONE),
            Environment::new("fine", w, h, vec![Vec3::ONE; w * h]).unwrap(),
        ] {
            let lighting = Lighting::new(&env, Window::None);
            let n = GLOSSY_ORDER.coeff_count();
            let mut worst = 0.0f32;
            for i in 0..n {
                for j in 0..n {
                    let identity = if i == j { 1.0 } else { 0.0 };
                    let l = lighting.matrix[i * n + j];
                    worst = worst.max((l - Vec3::splat(identity)).abs().max_element());
                }
            }
            println!("{}×{}: {worst}", env.width(), env.height());
            // Measured: 6.0e-4 on 16 × 8 texels (split to 128 × 64; 4.7e-2
            // unsplit), 1.5e-4 on 256 × 128.
            assert!(worst < 1e-3, "{}: {worst}", env.name());
        }
    }
}
