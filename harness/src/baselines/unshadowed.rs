//! Unshadowed SH lighting: the environment projected to spherical harmonics and
//! convolved with the BRDF's zonal lobe, with no visibility at all. It is the
//! upper bound every shadowing method sits below, and the shading term the
//! PRT-style methods share.

use glam::Vec3;
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, FrameGeometry, Image, Result, Scene,
    ShadowMethod, VertexRadiance, reflect,
    sh::{self, ShOrder, ShRgb, Zonal},
    shading::lambert_radiance,
};

/// SH lighting without shadows.
pub struct Unshadowed {
    /// `unshadowed`, with `:order=N` where the order is not
    /// [`Unshadowed::ORDER`].
    name: String,
    order: ShOrder,
    materials: Vec<Brdf>,
    frame: Option<FrameGeometry>,
    /// The environment convolved with the clamped cosine: irradiance E(n).
    irradiance: Option<ShRgb>,
    /// Per material, the environment convolved with its Phong lobe.
    glossy: Vec<Option<ShRgb>>,
}

impl Unshadowed {
    /// The order the harness's `unshadowed` uses.
    pub const ORDER: u32 = 9;

    /// SH of `order` (bands 0..order−1). The clamped-cosine kernel falls off as
    /// l⁻²·⁵, so order 3 already holds 99% of irradiance and order 9 is exact to
    /// well below a percent; glossy lobes need more (about √exponent bands).
    pub fn new(order: ShOrder) -> Unshadowed {
        let name = match order.get() {
            Unshadowed::ORDER => "unshadowed".to_string(),
            n => format!("unshadowed:order={n}"),
        };
        Unshadowed {
            name,
            order,
            materials: Vec::new(),
            frame: None,
            irradiance: None,
            glossy: Vec::new(),
        }
    }
}

impl ShadowMethod for Unshadowed {
    fn name(&self) -> &str {
        &self.name
    }

    /// Everything: ignoring visibility costs nothing for any kind of scene.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            per_pixel: false,
            export: false,
            ..Capabilities::ALL
        }
    }

    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.materials = scene.objects().iter().map(|o| o.material).collect();
        self.frame = None;
        Ok(())
    }

    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        self.frame = Some(frame.clone());
        Ok(())
    }

    fn relight(&mut self, environment: &Environment) -> Result<()> {
        let light = sh::project_environment(environment, self.order);
        self.irradiance = Some(light.convolve(&Zonal::lambert(self.order)));
        self.glossy = self
            .materials
            .iter()
            .map(|m| match *m {
                Brdf::Phong {
                    exponent, specular, ..
                } if specular != Vec3::ZERO => {
                    Zonal::phong(self.order, exponent).map(|lobe| light.convolve(&lobe))
                }
                _ => None,
            })
            .collect();
        Ok(())
    }

    /// Lambert: ρ/π · E(n). Phong adds ρ_s times the lobe-convolved lighting at
    /// the mirror direction r, times max(0, n·r): the cosine of the lobe's axis
    /// stands in for the cosine under the lobe (exact as the exponent grows).
    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        let frame = self
            .frame
            .as_ref()
            .ok_or_else(|| Error::stage("unshadowed", "shade before update"))?;
        let irradiance = self
            .irradiance
            .as_ref()
            .ok_or_else(|| Error::stage("unshadowed", "shade before relight"))?;
        let radiance = frame
            .objects
            .iter()
            .zip(self.materials.iter().zip(&self.glossy))
            .map(|(object, (material, glossy))| {
                object
                    .positions()
                    .iter()
                    .zip(object.normals())
                    .map(|(&p, &n)| {
                        let diffuse = lambert_radiance(material.diffuse(), irradiance.eval(n));
                        match (material, glossy) {
                            (Brdf::Phong { specular, .. }, Some(lobe)) => {
                                let r = reflect((eye - p).normalize_or(n), n);
                                diffuse + *specular * lobe.eval(r) * n.dot(r).max(0.0)
                            }
                            _ => diffuse,
                        }
                        .max(Vec3::ZERO)
                    })
                    .collect()
            })
            .collect();
        Ok(VertexRadiance::new(radiance))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        shadow_core::raster::render_shading("unshadowed", camera, self.frame.as_ref(), &shading)
    }
}
