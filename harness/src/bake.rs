//! Baking a per-vertex result into a user's glTF file: ambient occlusion,
//! irradiance or outgoing radiance of one frame, computed by the reference
//! or by a method, written as a vertex attribute (see [`crate::gltf::patch`]
//! for what the written file keeps).
//!
//! Which attribute suits what: viewers multiply `COLOR_0` into the base
//! colour, so ambient occlusion in `COLOR_0` darkens the model in any viewer
//! (and replaces the vertex colours a file may have); irradiance and radiance
//! are not colours (they exceed 1 and carry units), so they go into
//! application-specific attributes, which viewers ignore and engines read by
//! name.

use glam::Vec3;
use indicatif::ProgressBar;
use serde::Serialize;
use shadow_core::{Brdf, Environment, Error, Result, Scene, ShadowMethod, VertexRadiance};

use crate::gltf::VertexAttribute;
use crate::reference::{self, ReferenceSettings};

/// What is baked per vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
pub enum Quantity {
    /// Ambient occlusion: the cosine-weighted fraction of the hemisphere that
    /// sees the sky, in [0, 1] (outgoing radiance of a white Lambert surface
    /// under a uniform white sky). One value per vertex.
    #[value(name = "ao")]
    AmbientOcclusion,
    /// Irradiance E (W·m⁻², RGB): the light arriving at the vertex, shadows
    /// included, independent of any material.
    Irradiance,
    /// Outgoing radiance (W·sr⁻¹·m⁻², RGB) of the white Lambert material of
    /// the given albedo, as the methods compute it.
    Radiance,
}

impl Quantity {
    /// The attribute written unless another is asked for.
    pub fn default_attribute(self) -> &'static str {
        match self {
            Quantity::AmbientOcclusion => "_AO",
            Quantity::Irradiance => "_IRRADIANCE",
            Quantity::Radiance => "_RADIANCE",
        }
    }

    /// Checks that the lighting asked for defines this quantity (ambient
    /// occlusion needs the uniform white sky) and that it fits the attribute
    /// (only ambient occlusion is a colour for `COLOR_0`).
    pub fn check(self, env: &Environment, attribute: &str) -> Result<()> {
        let refuse = |what: String| Err(Error::InvalidScene(what));
        let uniform_white = env.texels().iter().all(|t| *t == Vec3::ONE);
        match self {
            Quantity::AmbientOcclusion if !uniform_white => refuse(format!(
                "ambient occlusion is defined under the uniform white sky, not {}: \
                 bake irradiance or radiance under it instead",
                env.name()
            )),
            Quantity::Irradiance | Quantity::Radiance if attribute == "COLOR_0" => refuse(format!(
                "{self:?} is not a colour (it exceeds 1 and has units): write it to an \
                 application-specific attribute such as {}",
                self.default_attribute()
            )),
            _ => Ok(()),
        }
    }

    /// The per-object attribute values from each vertex's outgoing radiance
    /// L of a white Lambert material of `albedo`: L / albedo for ambient
    /// occlusion (clamped to [0, 1], which noise or an approximation may
    /// leave slightly), π L / albedo for irradiance, L for radiance.
    pub fn values(self, radiance: &VertexRadiance, albedo: f32) -> Vec<VertexAttribute> {
        radiance
            .radiance
            .iter()
            .map(|object| match self {
                Quantity::AmbientOcclusion => VertexAttribute {
                    components: 1,
                    values: object
                        .iter()
                        .map(|l| (l.element_sum() / (3.0 * albedo)).clamp(0.0, 1.0))
                        .collect(),
                },
                Quantity::Irradiance | Quantity::Radiance => {
                    let scale = if self == Quantity::Irradiance {
                        std::f32::consts::PI / albedo
                    } else {
                        1.0
                    };
                    VertexAttribute {
                        components: 3,
                        values: object
                            .iter()
                            .flat_map(|l| (*l * scale).to_array())
                            .collect(),
                    }
                }
            })
            .collect()
    }
}

/// The white Lambert albedo `scene`'s objects share (bakes use one material).
pub fn albedo_of(scene: &Scene) -> Result<f32> {
    match scene.objects().first().map(|o| o.material) {
        Some(Brdf::Lambert { albedo }) if albedo == Vec3::splat(albedo.x) => Ok(albedo.x),
        other => Err(Error::InvalidScene(format!(
            "a bake needs one white Lambert material, the scene has {other:?}"
        ))),
    }
}

/// Frame `frame`'s per-vertex outgoing radiance by the Monte-Carlo reference,
/// to `settings`' noise.
pub fn reference_frame(
    scene: &Scene,
    env: &Environment,
    frame: usize,
    settings: &ReferenceSettings,
    progress: &ProgressBar,
) -> Result<reference::VertexReference> {
    let geometry = scene.frame_geometry(frame)?;
    reference::vertex_reference(
        scene,
        &geometry,
        env,
        scene.camera().eye,
        settings,
        progress,
    )
}

/// Frame `frame`'s per-vertex outgoing radiance by `method`, run as a
/// renderer would: prepare, relight, then the frame's update and shade.
pub fn method_frame(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    env: &Environment,
    frame: usize,
) -> Result<VertexRadiance> {
    let geometry = scene.frame_geometry(frame)?;
    method.prepare(scene)?;
    method.relight(env)?;
    method.update(&geometry, scene.camera())?;
    method.shade(scene.camera().eye)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantities_follow_from_lambert_radiance() {
        let radiance = VertexRadiance::new(vec![vec![Vec3::splat(0.25), Vec3::new(0.5, 1.0, 1.5)]]);
        let ao = Quantity::AmbientOcclusion.values(&radiance, 0.5);
        assert_eq!(ao[0].components, 1);
        assert_eq!(ao[0].values, vec![0.5, 1.0]);
        let e = Quantity::Irradiance.values(&radiance, 0.5);
        approx::assert_relative_eq!(e[0].values[3], 0.5 * std::f32::consts::PI / 0.5);
        let l = Quantity::Radiance.values(&radiance, 0.5);
        assert_eq!(l[0].values, vec![0.25, 0.25, 0.25, 0.5, 1.0, 1.5]);
    }

    #[test]
    fn quantities_refuse_what_does_not_define_them() {
        let sky = Environment::uniform(Vec3::ONE);
        let grey = Environment::uniform(Vec3::splat(2.0));
        assert!(Quantity::AmbientOcclusion.check(&sky, "COLOR_0").is_ok());
        assert!(Quantity::AmbientOcclusion.check(&grey, "_AO").is_err());
        assert!(Quantity::Irradiance.check(&grey, "COLOR_0").is_err());
        assert!(Quantity::Radiance.check(&grey, "_RADIANCE").is_ok());
    }
}
