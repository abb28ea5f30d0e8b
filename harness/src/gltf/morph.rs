//! Morph targets (glTF 2.0 §3.7.2.2): the deformed attribute is the base
//! attribute plus the weighted sum of the targets' deltas, applied before
//! skinning.

use glam::Vec3;

/// One target's per-vertex deltas (zero where the file gives none).
pub(super) struct MorphTarget {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

/// Applies the morph targets of one mesh instance.
pub(super) struct Morph {
    pub targets: Vec<MorphTarget>,
}

impl Morph {
    /// `base + Σ_k w_k Δ_k` for positions, and for normals when the mesh has
    /// them (left unnormalized: the caller transforms and normalizes them).
    pub fn apply(
        &self,
        weights: &[f32],
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
    ) -> (Vec<Vec3>, Option<Vec<Vec3>>) {
        let mut positions = positions.to_vec();
        let mut normals = normals.map(<[Vec3]>::to_vec);
        for (target, &w) in self.targets.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            for (p, d) in positions.iter_mut().zip(&target.positions) {
                *p += w * *d;
            }
            if let Some(normals) = &mut normals {
                for (n, d) in normals.iter_mut().zip(&target.normals) {
                    *n += w * *d;
                }
            }
        }
        (positions, normals)
    }
}
