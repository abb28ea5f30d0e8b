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
    Environment, FrameGeometry, Mesh, PosedObject, Result, ShTransfer, TangentSpace, TransferSpace,
    bvh::SceneBvh,
    qmc::{cosine_hemisphere, sobol2},
    ray_origin,
    sh::{ShOrder, ShRgb, ShRotation, Zonal, eval_basis, project_environment},
};

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
        let offset = bvh.ray_offset();
        let n = order.coeff_count();
        let mut coefficients = vec![0.0f32; mesh.vertex_count() * n];
        let scale = PI / rays as f32;
        coefficients
            .par_chunks_mut(n)
            .enumerate()
            .for_each(|(v, out)| {
                let p = mesh.positions()[v];
                let normal = mesh.normals()[v];
                let tangents = TangentSpace::new(normal);
                let origin = ray_origin(p, normal, offset);
                let shift = vertex_shift(v as u32);
                let mut basis = [0.0f32; 64];
                for k in 0..rays {
                    let local = cosine_hemisphere(sobol2(k, shift));
                    let dir = tangents.to_world(local).normalize();
                    if bvh.unoccluded(origin, dir, f32::INFINITY) {
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
    /// The environment's projection, [`DIFFUSE_ORDER`].
    pub sh: ShRgb,
    /// Eq. 10's matrix L_ij = ∫ L y_i y_j dω over [`GLOSSY_ORDER`]'s
    /// basis, row-major, 16 × 16.
    pub matrix: Vec<Vec3>,
}

/// The matrix is integrated over the map at most this many texels wide.
const MATRIX_WIDTH: usize = 256;

impl Lighting {
    pub fn new(environment: &Environment) -> Lighting {
        let sh = project_environment(environment, DIFFUSE_ORDER);
        let env = if environment.width() > MATRIX_WIDTH {
            environment.downsampled(MATRIX_WIDTH, MATRIX_WIDTH / 2)
        } else {
            environment.clone()
        };
        let n = GLOSSY_ORDER.coeff_count();
        let matrix = (0..env.height())
            .into_par_iter()
            .map(|row| {
                let mut m = vec![Vec3::ZERO; n * n];
                let mut y = [0.0f32; 16];
                let omega = env.solid_angle(row);
                for col in 0..env.width() {
                    let l = env.texel(row, col) * omega;
                    eval_basis(GLOSSY_ORDER, env.direction(row, col), &mut y);
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
        Lighting { sh, matrix }
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
        .map(|i| lobe.eigenvalues()[(i as f32).sqrt() as usize])
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
