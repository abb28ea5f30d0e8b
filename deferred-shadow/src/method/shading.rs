//! The per-vertex data of the deferred pass: L_s toward the eye and the
//! light weights.

use glam::{Mat3, Vec3};
use shadow_core::{Error, Result, reflect};

use super::{DeferredShadow, SelfRadiance};
use crate::name::NAME;

impl DeferredShadow {
    /// L_s toward `eye` at every vertex (eq. 2, 13) and the light weights,
    /// uploaded unless the GPU has them already.
    pub(super) fn upload_shading(&mut self, eye: Vec3) -> Result<()> {
        if self.posed.is_some() && self.lit.is_some() && !self.current {
            return Err(Error::stage(
                NAME,
                "shade or render after a failed update or relight (the GPU holds maps of \
                 neither frame); a successful update makes it current",
            ));
        }
        let q = self.config.lights;
        let (Some(scene), Some(posed), Some(_)) = (&mut self.scene, &mut self.posed, &self.lit)
        else {
            return Err(Error::stage(
                NAME,
                "shade or render before prepare, relight and update",
            ));
        };
        let glossy = posed
            .radiance
            .iter()
            .any(|r| matches!(r, Some(SelfRadiance::Glossy { .. })));
        if posed.uploaded.is_some_and(|e| !glossy || e == eye) {
            return Ok(());
        }
        let mut out = Vec::with_capacity(scene.gpu.vertex_count());
        for ((part, terms), t) in scene
            .parts
            .iter()
            .zip(&posed.radiance)
            .zip(&posed.transforms)
        {
            let terms = terms
                .as_ref()
                .ok_or_else(|| Error::stage(NAME, "shade or render before relight"))?;
            match terms {
                SelfRadiance::Diffuse(values) => out.extend_from_slice(values),
                SelfRadiance::Glossy { vertices, specular } => {
                    let normal_matrix = Mat3::from(t.matrix3).inverse().transpose();
                    let mesh = &part.mesh;
                    out.extend(
                        vertices
                            .iter()
                            .zip(mesh.positions().iter().zip(mesh.normals()))
                            .map(|(g, (&p, &n))| {
                                let n = (normal_matrix * n).normalize();
                                let wo = (eye - t.transform_point3(p)).normalize_or_zero();
                                g.radiance(reflect(wo, n).normalize_or(n), *specular)
                            }),
                    );
                }
            }
        }
        let stride = 4 + q;
        let mut shading = vec![0.0f32; out.len() * stride];
        for (v, ((dst, ls), w)) in shading
            .chunks_exact_mut(stride)
            .zip(&out)
            .zip(posed.weights.chunks_exact(q))
            .enumerate()
        {
            dst[..3].copy_from_slice(&ls.to_array());
            // Enclosed: the vertex pass gives it 0 (deferred.wgsl).
            dst[3] = f32::from(u8::from(posed.enclosed.get(v).copied().unwrap_or(false)));
            dst[4..].copy_from_slice(w);
        }
        scene.gpu.set_shading(&shading)?;
        posed.uploaded = Some(eye);
        Ok(())
    }
}
