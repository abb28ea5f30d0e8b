//! The two rows that bound the table: the unshadowed transfer above, the
//! reference transfer shaded with order-n lighting below.

use glam::Vec3;
use shadow_core::{
    Environment, Result, Scene,
    sh::{self, ShRgb, Zonal},
    shading::lambert_transfer_radiance,
};

use super::{RadianceError, Row, TransferScore};
use crate::{
    reference::{
        VertexReference,
        transfer::{TransferReference, TransferSettings},
    },
    score::{ErrorStats, against},
};

/// What shading a transfer vector needs: the lighting's SH and every
/// vertex's albedo.
pub(super) struct Bounds {
    light: ShRgb,
    lambert: Zonal,
    /// Per flat vertex.
    albedo: Vec<Vec3>,
}

impl Bounds {
    pub(super) fn new(
        scene: &Scene,
        environment: &Environment,
        settings: &TransferSettings,
    ) -> Bounds {
        let albedo = scene
            .objects()
            .iter()
            .flat_map(|o| std::iter::repeat_n(o.material.diffuse(), o.mesh.vertex_count()))
            .collect();
        Bounds {
            light: sh::project_environment(environment, settings.order),
            lambert: Zonal::lambert(settings.order),
            albedo,
        }
    }

    /// Exit radiance ρ/π · max(0, L·T) (Kautz et al. eq. 2, clamped as
    /// hemi-raster's `shade` does).
    fn shade(&self, transfer: &[f32]) -> Vec<Vec3> {
        let n = self.lambert.order().coeff_count();
        transfer
            .chunks_exact(n)
            .zip(&self.albedo)
            .map(|(t, &rho)| lambert_transfer_radiance(rho, &self.light, t).max(Vec3::ZERO))
            .collect()
    }

    /// The upper bound: the clamped cosine about each vertex normal, no
    /// visibility.
    pub(super) fn unshadowed(
        &self,
        scene: &Scene,
        radiance: &[VertexReference],
        references: &[TransferReference],
    ) -> Result<Row> {
        let n = self.lambert.order().coeff_count();
        let mut score = TransferScore::default();
        let mut errors = Vec::new();
        for (index, (rad, reference)) in radiance.iter().zip(references).enumerate() {
            let frame = scene.frame_geometry(index)?;
            let normals = frame.objects.iter().flat_map(|o| o.normals().iter());
            let mut transfer = vec![0.0; reference.mean().len()];
            for (t, &normal) in transfer.chunks_exact_mut(n).zip(normals) {
                self.lambert.project_along(normal, t);
            }
            score.add(&transfer, reference.mean(), Some(reference.std_error()), n)?;
            errors.push(against(&self.shade(&transfer), rad));
        }
        Ok(Row {
            name: "unshadowed".into(),
            what: "clamped cosine only, no visibility: the upper bound".into(),
            transfer: Some(score.summary()),
            breakdown: None,
            radiance: RadianceError::over_frames(&errors),
            frame_ms: None,
            blockers: None,
        })
    }

    /// The floor: the reference transfer shaded with the order-n lighting.
    pub(super) fn floor(
        &self,
        radiance: &[VertexReference],
        references: &[TransferReference],
    ) -> Row {
        let errors: Vec<ErrorStats> = radiance
            .iter()
            .zip(references)
            .map(|(rad, reference)| against(&self.shade(reference.mean()), rad))
            .collect();
        Row {
            name: "reference transfer".into(),
            what: format!(
                "the ray-traced transfer with the environment's SH of {}: the floor SH truncation sets",
                self.lambert.order()
            ),
            transfer: None,
            breakdown: None,
            radiance: RadianceError::over_frames(&errors),
            frame_ms: None,
            blockers: None,
        }
    }
}
