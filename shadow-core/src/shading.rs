//! What a Lambert surface reflects: ρ/π times its irradiance, and the
//! irradiance from SH lighting and a transfer vector (Kautz et al. 2004,
//! eq. 2: the exit radiance is ρ/π · L·T).
//!
//! Not clamped: SH ringing can dip below zero behind strong blockers, and
//! a caller that adds a glossy term clamps the sum, not its parts.

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use crate::sh::ShRgb;

/// ρ/π · E: the radiance a Lambert surface of `albedo` ρ reflects under
/// `irradiance` E.
#[inline]
pub fn lambert_radiance(albedo: Vec3, irradiance: Vec3) -> Vec3 {
    albedo * FRAC_1_PI * irradiance
}

/// ρ/π · L·T: the radiance a Lambert surface of `albedo` reflects under
/// `lighting` L through its `transfer` vector T (without ρ/π, as every SH
/// transfer of the workspace is; [`ShRgb::dot`] over the shorter of the
/// two).
#[inline]
pub fn lambert_transfer_radiance(albedo: Vec3, lighting: &ShRgb, transfer: &[f32]) -> Vec3 {
    lambert_radiance(albedo, lighting.dot(transfer))
}

#[cfg(test)]
mod tests {
    use std::f32::consts::PI;

    use super::*;
    use crate::sh::{ShOrder, Zonal, project_fn_rgb};

    /// The white furnace: under unit radiance, an unoccluded vertex's
    /// transfer (the clamped cosine about its normal) reflects its albedo.
    #[test]
    fn an_unoccluded_vertex_reflects_its_albedo_under_unit_light() {
        let order = ShOrder::new(3).unwrap();
        let light = project_fn_rgb(order, 16, |_| Vec3::ONE);
        let mut transfer = vec![0.0; order.coeff_count()];
        Zonal::lambert(order).project_along(Vec3::new(0.6, 0.0, 0.8), &mut transfer);
        let albedo = Vec3::new(0.2, 0.5, 0.9);
        let l = lambert_transfer_radiance(albedo, &light, &transfer);
        assert!((l - albedo).abs().max_element() < 1e-4, "{l}");
        assert_eq!(l, lambert_radiance(albedo, light.dot(&transfer)));
        let one = lambert_radiance(Vec3::ONE, Vec3::splat(PI));
        assert!((one - Vec3::ONE).abs().max_element() < 1e-6, "{one}");
    }
}
