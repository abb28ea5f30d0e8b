//! Linear-blend skinning (glTF 2.0 §3.7.3).
//!
//! A skinned vertex lands at `Σ_k w_k · G(j_k) · B(j_k) · p`, with `G` a
//! joint's global (world) transform and `B` its inverse bind matrix. The
//! transform of the node that instances the skinned mesh is ignored: only the
//! joints place the mesh (§3.7.3.3, "client implementations should apply only
//! the transform of the skeleton root node"). Exporters do put transforms on
//! such nodes (the BCN_Epileptic asset does, see the tests), and applying them
//! on top of the joints offsets the mesh from its skeleton.

use std::path::Path;

use ::gltf::accessor::Dimensions;
use glam::{Mat3, Mat4, Vec3};
use shadow_core::{Error, Result};

use super::accessor::Buffers;
use super::geometry::RawInfluences;

/// Weights whose sum differs from 1 by more than this are renormalized and
/// counted; below it the difference is f32 rounding of the exporter's sum.
const WEIGHT_SUM_TOLERANCE: f32 = 1e-5;

/// The joints of a skin and each vertex's non-zero influences, renormalized.
pub(super) struct Skin {
    /// Node index of each joint.
    joints: Vec<usize>,
    inverse_bind: Vec<Mat4>,
    /// Influences of vertex v: `slots[offsets[v]..offsets[v + 1]]`, same for
    /// `weights`; slots index `joints`.
    offsets: Vec<u32>,
    slots: Vec<u32>,
    weights: Vec<f32>,
    /// Vertices whose weights did not sum to 1 and were divided by their sum.
    pub renormalized: usize,
}

impl Skin {
    /// Reads the skin's joints and inverse bind matrices (identity when the
    /// file gives none) and checks every vertex's influences: joint numbers in
    /// range, weights finite and non-negative, and a positive sum.
    pub fn new(
        path: &Path,
        label: &str,
        skin: &::gltf::Skin,
        buffers: &Buffers,
        raw: &RawInfluences,
    ) -> Result<Skin> {
        let bad =
            |what: String| Error::format(path, format!("{label}, skin {}: {what}", skin.index()));
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        if joints.is_empty() {
            return Err(bad("has no joints".into()));
        }
        let inverse_bind = match skin.inverse_bind_matrices() {
            Some(accessor) => {
                let what = format!("{label}, skin {} inverseBindMatrices", skin.index());
                let values = buffers.floats(&accessor, &what, Dimensions::Mat4)?;
                if values.len() / 16 < joints.len() {
                    return Err(bad(format!(
                        "{} inverse bind matrices for {} joints",
                        values.len() / 16,
                        joints.len()
                    )));
                }
                values.chunks_exact(16).map(Mat4::from_cols_slice).collect()
            }
            None => vec![Mat4::IDENTITY; joints.len()],
        };

        let vertex_count = raw.joints.len().checked_div(raw.width).unwrap_or(0);
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut slots = Vec::new();
        let mut weights = Vec::new();
        let mut renormalized = 0;
        offsets.push(0);
        for v in 0..vertex_count {
            let start = weights.len();
            let range = v * raw.width..(v + 1) * raw.width;
            for (&slot, &w) in raw.joints[range.clone()].iter().zip(&raw.weights[range]) {
                if w < 0.0 {
                    return Err(bad(format!("vertex {v} has a negative joint weight {w}")));
                }
                if w == 0.0 {
                    continue;
                }
                if slot as usize >= joints.len() {
                    return Err(bad(format!(
                        "vertex {v} is weighted to joint {slot}, the skin has {} joints",
                        joints.len()
                    )));
                }
                slots.push(slot);
                weights.push(w);
            }
            let sum: f32 = weights[start..].iter().sum();
            // The weights are finite and non-negative: their sum is 0 only
            // when all are, and infinite only when they overflow.
            if sum == 0.0 || !sum.is_finite() {
                return Err(bad(format!(
                    "vertex {v} has no joint weight (WEIGHTS_n sum to {sum})"
                )));
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                renormalized += 1;
                for w in &mut weights[start..] {
                    *w /= sum;
                }
            }
            offsets.push(weights.len() as u32);
        }
        Ok(Skin {
            joints,
            inverse_bind,
            offsets,
            slots,
            weights,
            renormalized,
        })
    }

    /// The joint with the largest weight on vertex `v`, as a node index.
    #[cfg(test)]
    pub fn dominant_joint(&self, v: usize) -> usize {
        let range = self.offsets[v] as usize..self.offsets[v + 1] as usize;
        let best = range
            .max_by(|&a, &b| self.weights[a].total_cmp(&self.weights[b]))
            .map_or(0, |k| self.slots[k] as usize);
        self.joints[best]
    }

    /// Skinned world-space positions, and normals when given: each normal is
    /// transformed by the inverse transpose of the vertex's blended matrix
    /// (computed as its cofactor matrix, which is det · M⁻ᵀ, times the sign of
    /// det), then normalized. A normal whose blended matrix is singular comes
    /// out zero, and [`shadow_core::Mesh::with_pose`] falls back to the rest
    /// normal for it.
    pub fn deform(
        &self,
        world: &[Mat4],
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
    ) -> (Vec<Vec3>, Option<Vec<Vec3>>) {
        let joint_matrices: Vec<Mat4> = self
            .joints
            .iter()
            .zip(&self.inverse_bind)
            .map(|(&node, bind)| world[node] * *bind)
            .collect();
        let blended: Vec<Mat4> = (0..positions.len())
            .map(|v| {
                let range = self.offsets[v] as usize..self.offsets[v + 1] as usize;
                self.slots[range.clone()]
                    .iter()
                    .zip(&self.weights[range])
                    .fold(Mat4::ZERO, |m, (&slot, &w)| {
                        m + joint_matrices[slot as usize] * w
                    })
            })
            .collect();
        let skinned = positions
            .iter()
            .zip(&blended)
            .map(|(p, m)| m.transform_point3(*p))
            .collect();
        let normals = normals.map(|normals| {
            normals
                .iter()
                .zip(&blended)
                .map(|(n, m)| {
                    normal_matrix(Mat3::from_mat4(*m))
                        .mul_vec3(*n)
                        .normalize_or_zero()
                })
                .collect()
        });
        (skinned, normals)
    }
}

/// A matrix proportional, with a positive factor, to the inverse transpose of
/// `m`: its cofactor matrix times the sign of its determinant. It needs no
/// division, so it stays finite for singular matrices.
pub(super) fn normal_matrix(m: Mat3) -> Mat3 {
    let cofactor = Mat3::from_cols(
        m.y_axis.cross(m.z_axis),
        m.z_axis.cross(m.x_axis),
        m.x_axis.cross(m.y_axis),
    );
    cofactor * m.determinant().signum()
}
