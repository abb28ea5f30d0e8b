//! What a method computed, in a form a user can keep and relight without the
//! method: per-vertex SH transfer vectors (precomputed radiance transfer), or
//! per-vertex visibility over a weighted set of directions.

use glam::Vec3;

use crate::sh::{ShOrder, ShRgb};
use crate::{Error, Result};

/// A method's raw per-vertex result, by kind ([`ShadowMethod::export`](crate::ShadowMethod::export)).
/// Every kind lists the vertices of all objects one after another, object 0
/// first, in the order of each object's mesh.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Export {
    Transfer(ShTransfer),
    Visibility(DirectionalVisibility),
}

impl Export {
    /// Vertices per object.
    pub fn vertex_counts(&self) -> &[usize] {
        match self {
            Export::Transfer(t) => &t.vertex_counts,
            Export::Visibility(v) => &v.vertex_counts,
        }
    }
}

/// The space transfer vectors are expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TransferSpace {
    /// World space: dot with the SH projection of the environment as it is.
    World,
}

/// Per-vertex SH transfer vectors of the cosine-weighted visibility
/// (Kautz et al. 2004, eq. 2): for lighting with SH coefficients `L` (the
/// convention of [`crate::sh`]), a vertex's irradiance is `E = L·T` and its
/// Lambert radiance `ρ/π · E`. View-dependent (glossy) terms are not part of
/// a transfer vector.
#[derive(Clone, Debug, PartialEq)]
pub struct ShTransfer {
    pub order: ShOrder,
    pub space: TransferSpace,
    /// Vertices per object.
    pub vertex_counts: Vec<usize>,
    /// `order.coeff_count()` coefficients per vertex, vertex after vertex.
    pub coefficients: Vec<f32>,
}

impl ShTransfer {
    /// Validates the coefficient count against the vertex counts.
    pub fn new(
        order: ShOrder,
        space: TransferSpace,
        vertex_counts: Vec<usize>,
        coefficients: Vec<f32>,
    ) -> Result<ShTransfer> {
        let vertices: usize = vertex_counts.iter().sum();
        if coefficients.len() != vertices * order.coeff_count() {
            return Err(Error::InvalidScene(format!(
                "SH transfer: {} coefficients for {vertices} vertices of order {}",
                coefficients.len(),
                order.get()
            )));
        }
        Ok(ShTransfer {
            order,
            space,
            vertex_counts,
            coefficients,
        })
    }

    /// The transfer vector of global vertex `v`.
    pub fn vector(&self, v: usize) -> &[f32] {
        let n = self.order.coeff_count();
        &self.coefficients[v * n..(v + 1) * n]
    }

    /// Irradiance at every vertex under `light` (its bands beyond the
    /// transfer's order are ignored; missing ones count as zero).
    pub fn irradiance(&self, light: &ShRgb) -> Vec<Vec3> {
        let n = self.order.coeff_count().min(light.order().coeff_count());
        self.coefficients
            .chunks_exact(self.order.coeff_count())
            .map(|t| light.dot(&t[..n]))
            .collect()
    }
}

/// Per-vertex binary visibility over `k` directions, each standing for a
/// solid angle (Sattler et al. 2004's visibility matrix with its cosines kept
/// apart): `M_ij = n_i·l_j` where direction `j` is visible from vertex `i`,
/// else 0, and a vertex's irradiance under radiance `I_j` arriving from
/// direction `j` is `E_i = Σ_j w_j max(0, M_ij) I_j`, times
/// `π / Σ_j w_j max(0, n_i·l_j)` when `cosine_normalized` (then an
/// unoccluded vertex under uniform light gets exactly π). `I_j` is the
/// environment blurred with a Gaussian of `prefilter` radians (0: none),
/// looked up at `l_j`, as the method that made it shades.
#[derive(Clone, Debug, PartialEq)]
pub struct DirectionalVisibility {
    /// Unit world-space directions toward the light.
    pub directions: Vec<Vec3>,
    /// Solid angle of each direction in steradians; they sum to 4π.
    pub weights: Vec<f32>,
    /// Vertices per object.
    pub vertex_counts: Vec<usize>,
    /// The unit normal `n_i` of every vertex.
    pub normals: Vec<Vec3>,
    /// Bit `j % 64` of word `i · words + j / 64` is set when direction `j` is
    /// visible from vertex `i`, with `words = ceil(k / 64)`.
    pub visible: Vec<u64>,
    /// Whether each vertex's sum is divided by its quadrature of the cosine.
    pub cosine_normalized: bool,
    /// The width (radians) of the Gaussian the environment is blurred with
    /// before it is looked up along each direction.
    pub prefilter: f32,
}

impl DirectionalVisibility {
    /// Validates the sizes of every part against each other; not
    /// normalized, no prefilter.
    pub fn new(
        directions: Vec<Vec3>,
        weights: Vec<f32>,
        vertex_counts: Vec<usize>,
        normals: Vec<Vec3>,
        visible: Vec<u64>,
    ) -> Result<DirectionalVisibility> {
        let vertices: usize = vertex_counts.iter().sum();
        let words = directions.len().div_ceil(64);
        if weights.len() != directions.len()
            || normals.len() != vertices
            || visible.len() != vertices * words
        {
            return Err(Error::InvalidScene(format!(
                "directional visibility: {} directions, {} weights, {} normals and {} words \
                 for {vertices} vertices",
                directions.len(),
                weights.len(),
                normals.len(),
                visible.len()
            )));
        }
        Ok(DirectionalVisibility {
            directions,
            weights,
            vertex_counts,
            normals,
            visible,
            cosine_normalized: false,
            prefilter: 0.0,
        })
    }

    /// 64-bit words per vertex.
    pub fn words_per_vertex(&self) -> usize {
        self.directions.len().div_ceil(64)
    }

    /// Whether direction `j` is visible from global vertex `i`.
    pub fn is_visible(&self, i: usize, j: usize) -> bool {
        let word = self.visible[i * self.words_per_vertex() + j / 64];
        word >> (j % 64) & 1 == 1
    }

    /// Irradiance at every vertex when radiance `radiance[j]` arrives from
    /// direction `j`.
    pub fn irradiance(&self, radiance: &[Vec3]) -> Vec<Vec3> {
        (0..self.normals.len())
            .map(|i| {
                let n = self.normals[i];
                let cosine = |j: usize| self.weights[j] * n.dot(self.directions[j]).max(0.0);
                let sum: Vec3 = (0..self.directions.len())
                    .filter(|&j| self.is_visible(i, j))
                    .map(|j| radiance[j] * cosine(j))
                    .sum();
                if !self.cosine_normalized {
                    return sum;
                }
                let quadrature: f32 = (0..self.directions.len()).map(cosine).sum();
                if quadrature > 0.0 {
                    sum * (std::f32::consts::PI / quadrature)
                } else {
                    Vec3::ZERO
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Environment;
    use crate::sh;
    use approx::assert_relative_eq;

    #[test]
    fn sizes_that_disagree_are_errors() {
        let order = ShOrder::new(2).unwrap();
        assert!(ShTransfer::new(order, TransferSpace::World, vec![2], vec![0.0; 7]).is_err());
        assert!(ShTransfer::new(order, TransferSpace::World, vec![2], vec![0.0; 8]).is_ok());
        let d = vec![Vec3::Y; 65];
        assert!(
            DirectionalVisibility::new(d.clone(), vec![0.1; 65], vec![1], vec![Vec3::Y], vec![0])
                .is_err()
        );
        assert!(
            DirectionalVisibility::new(d, vec![0.1; 65], vec![1], vec![Vec3::Y], vec![0, 0])
                .is_ok()
        );
    }

    /// An unblocked upward vertex under a uniform unit sky: the transfer of
    /// the clamped cosine gives E = π; visibility over the six axes with
    /// weights 4π/6 gives 4π/6 (only +Y faces the normal).
    #[test]
    fn both_kinds_relight_to_irradiance() {
        let order = ShOrder::new(3).unwrap();
        let cosine = sh::project_fn(order, 64, |w| w.y.max(0.0));
        let transfer = ShTransfer::new(order, TransferSpace::World, vec![1], cosine).unwrap();
        let light = sh::project_environment(&Environment::uniform(Vec3::ONE), order);
        assert_relative_eq!(
            transfer.irradiance(&light)[0].x,
            std::f32::consts::PI,
            epsilon = 1e-3
        );

        let axes = vec![
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ];
        let w = vec![4.0 * std::f32::consts::PI / 6.0; 6];
        let mut vis =
            DirectionalVisibility::new(axes, w, vec![1], vec![Vec3::Y], vec![0b111111]).unwrap();
        assert!(vis.is_visible(0, 2) && vis.words_per_vertex() == 1);
        let e = vis.irradiance(&[Vec3::ONE; 6]);
        assert_relative_eq!(e[0].x, 4.0 * std::f32::consts::PI / 6.0, epsilon = 1e-6);
        vis.cosine_normalized = true;
        let e = vis.irradiance(&[Vec3::ONE; 6]);
        assert_relative_eq!(e[0].x, std::f32::consts::PI, epsilon = 1e-5);
        vis.visible[0] = 0b111011; // +Y blocked
        assert_eq!(vis.irradiance(&[Vec3::ONE; 6])[0], Vec3::ZERO);
    }
}
