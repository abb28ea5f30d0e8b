//! Surface reflectance: Lambert, and a normalized Phong lobe plus a diffuse term.

use std::f32::consts::{FRAC_1_PI, TAU};

use glam::Vec3;

use crate::{Error, Result};

/// A BRDF f_r(ω_i, ω_o) (DESIGN.md, "The quantity every method returns").
///
/// Built through [`Brdf::lambert`] and [`Brdf::phong`], which reject albedos
/// that would create energy (a channel outside [0, 1], or diffuse + specular
/// above 1) so that every material in the program is physically plausible.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum Brdf {
    /// f_r = ρ/π.
    Lambert { albedo: Vec3 },
    /// f_r = ρ_d/π + ρ_s (n+2)/(2π) max(0, r·ω_i)ⁿ, with r the mirror of ω_o
    /// about the normal. The (n+2)/(2π) factor normalizes the lobe so that at
    /// normal incidence its cosine-weighted integral is exactly ρ_s
    /// (Lafortune and Willems' modified Phong).
    Phong {
        diffuse: Vec3,
        specular: Vec3,
        exponent: f32,
    },
}

impl Brdf {
    pub fn lambert(albedo: Vec3) -> Result<Brdf> {
        check_albedo("albedo", albedo)?;
        Ok(Brdf::Lambert { albedo })
    }

    pub fn phong(diffuse: Vec3, specular: Vec3, exponent: f32) -> Result<Brdf> {
        check_albedo("diffuse", diffuse)?;
        check_albedo("specular", specular)?;
        check_albedo("diffuse + specular", diffuse + specular)?;
        if !(exponent.is_finite() && exponent >= 0.0) {
            return Err(Error::InvalidScene(format!(
                "Phong exponent {exponent} must be finite and non-negative"
            )));
        }
        Ok(Brdf::Phong {
            diffuse,
            specular,
            exponent,
        })
    }

    /// Fails as [`Brdf::lambert`] or [`Brdf::phong`] would have for these
    /// values: the variants' fields are public, so a `Brdf` can be built
    /// without them, and a NaN exponent would shade silently to NaN.
    pub fn check(&self) -> Result<()> {
        match *self {
            Brdf::Lambert { albedo } => Brdf::lambert(albedo),
            Brdf::Phong {
                diffuse,
                specular,
                exponent,
            } => Brdf::phong(diffuse, specular, exponent),
        }
        .map(drop)
    }

    /// The diffuse albedo ρ (ρ_d for Phong).
    pub fn diffuse(&self) -> Vec3 {
        match *self {
            Brdf::Lambert { albedo } => albedo,
            Brdf::Phong { diffuse, .. } => diffuse,
        }
    }

    /// True when the BRDF depends on the view direction.
    pub fn is_glossy(&self) -> bool {
        matches!(self, Brdf::Phong { specular, .. } if *specular != Vec3::ZERO)
    }

    /// f_r(ω_i, ω_o) at a surface with unit normal `n`; `wi` points to the light,
    /// `wo` to the viewer, both unit. The cosine factor is not included.
    pub fn eval(&self, n: Vec3, wi: Vec3, wo: Vec3) -> Vec3 {
        match *self {
            Brdf::Lambert { albedo } => albedo * FRAC_1_PI,
            Brdf::Phong {
                diffuse,
                specular,
                exponent,
            } => {
                let r = reflect(wo, n);
                let lobe = r.dot(wi).max(0.0).powf(exponent) * (exponent + 2.0) / TAU;
                diffuse * FRAC_1_PI + specular * lobe
            }
        }
    }
}

/// The mirror direction of `wo` about `n`: 2(n·ω_o)n − ω_o.
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * n.dot(wo) * n - wo
}

fn check_albedo(what: &str, rho: Vec3) -> Result<()> {
    if rho.is_finite() && rho.min_element() >= 0.0 && rho.max_element() <= 1.0 {
        Ok(())
    } else {
        Err(Error::InvalidScene(format!(
            "{what} {rho} must lie in [0, 1] per channel"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f32::consts::PI;

    /// ∫ f_r(ω_i, ω_o) cos θ_i dω_i over the hemisphere, by midpoint quadrature.
    fn albedo(brdf: &Brdf, wo: Vec3) -> Vec3 {
        let (nt, np) = (400, 800);
        let mut sum = Vec3::ZERO;
        for i in 0..nt {
            let theta = (i as f32 + 0.5) / nt as f32 * PI / 2.0;
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * TAU;
                let wi = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                let d_omega = theta.sin() * (PI / 2.0 / nt as f32) * (TAU / np as f32);
                sum += brdf.eval(Vec3::Y, wi, wo) * wi.y * d_omega;
            }
        }
        sum
    }

    #[test]
    fn lambert_reflects_its_albedo() {
        let b = Brdf::lambert(Vec3::new(0.2, 0.5, 0.9)).unwrap();
        assert_relative_eq!(
            albedo(&b, Vec3::Y),
            Vec3::new(0.2, 0.5, 0.9),
            max_relative = 1e-3
        );
    }

    #[test]
    fn phong_lobe_is_normalized_at_normal_incidence() {
        for n in [1.0, 10.0, 100.0] {
            let b = Brdf::phong(Vec3::ZERO, Vec3::ONE, n).unwrap();
            assert_relative_eq!(albedo(&b, Vec3::Y).x, 1.0, max_relative = 5e-3);
        }
    }

    #[test]
    fn energy_creating_materials_are_rejected() {
        assert!(Brdf::lambert(Vec3::splat(1.1)).is_err());
        assert!(Brdf::phong(Vec3::splat(0.6), Vec3::splat(0.6), 10.0).is_err());
        assert!(Brdf::phong(Vec3::splat(0.5), Vec3::splat(0.5), f32::NAN).is_err());
    }
}
