#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]

use glam::Vec3;
use harness::methods::{Build, Family, Read};
use rayon::prelude::*;
use shadow_core::{
    Camera, Capabilities, Environment, Error, FrameGeometry, Image, Result, Scene, ShadowMethod,
    SurfacePoint, TangentSpace, VertexRadiance,
    bvh::SceneBvh,
    name::{MethodName, NameWriter},
    qmc,
    sh::{self, ShOrder, ShRgb, Zonal},
    shading::lambert_radiance,
};

/// The family's name.
const NAME: &str = "bent-normals";

/// Per-vertex ambient occlusion with bent normals (Landis 2002): each
/// vertex traces `rays` cosine-distributed shadow rays; the fraction that
/// escape, V, scales the environment's irradiance looked up along the mean
/// escaping direction b: L = ρ/π · V · E(b). Exact where the sky is
/// uniform; elsewhere it ignores which part of the sky is blocked beyond
/// the bent normal's turn. Lambert only, per vertex only.
pub struct BentNormals {
    rays: u32,
    name: String,
    albedo: Vec<Vec3>,
    irradiance: Option<ShRgb>,
    frame: Option<FrameGeometry>,
    /// Per vertex of the frame, all objects in turn: V and b.
    occlusion: Vec<(f32, Vec3)>,
}

impl BentNormals {
    /// `rays` shadow rays per vertex (at least 1).
    pub fn new(rays: u32) -> Result<BentNormals> {
        if rays == 0 {
            return Err(Error::config(NAME, "at least one ray per vertex"));
        }
        let mut name = NameWriter::new(NAME);
        name.changed("rays", rays, DEFAULT_RAYS);
        Ok(BentNormals {
            rays,
            name: name.finish(),
            albedo: Vec::new(),
            irradiance: None,
            frame: None,
            occlusion: Vec::new(),
        })
    }
}

/// The rays per vertex of `bent-normals` without options.
const DEFAULT_RAYS: u32 = 32;

/// The family for [`harness::methods::Methods::with`]:
/// `bent-normals[:rays=N]`.
pub fn family() -> Family {
    Family::new(
        NAME,
        "per-vertex ambient occlusion with bent normals (Landis 2002), 32 rays a vertex",
        &["rays=N"],
        read,
    )
}

fn read(text: &str) -> Read {
    let name = MethodName::parse(text, NAME)?;
    let mut rays = DEFAULT_RAYS;
    for option in name.options() {
        match (option.key, option.value) {
            ("rays", Some(n)) => rays = name.value(option, n)?,
            _ => return Err(name.unknown(option, &["rays=N"])),
        }
    }
    let printed = BentNormals::new(rays).map_err(|e| name.error(e.to_string()))?;
    let printed = printed.name().to_string();
    let build = Build::cpu(move || Box::new(BentNormals::new(rays).expect("checked by read")));
    Ok((printed, build))
}

impl ShadowMethod for BentNormals {
    fn name(&self) -> &str {
        &self.name
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            deforming_meshes: true,
            rigid_motion: true,
            multiple_objects: true,
            glossy_brdf: false,
            per_pixel: false,
            export: false,
        }
    }

    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.capabilities().check(&self.name, scene)?;
        self.albedo = scene
            .objects()
            .iter()
            .map(|o| o.material.diffuse())
            .collect();
        Ok(())
    }

    fn relight(&mut self, environment: &Environment) -> Result<()> {
        let order = ShOrder::new(3).expect("3 is an SH order");
        let light = sh::project_environment(environment, order);
        self.irradiance = Some(light.convolve(&Zonal::lambert(order)));
        Ok(())
    }

    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        let bvh = SceneBvh::build(frame)?;
        let vertices: Vec<(u32, SurfacePoint)> = frame.object_vertices().collect();
        let rays = self.rays;
        self.occlusion = vertices
            .par_iter()
            .enumerate()
            .map(|(i, &(object, at))| {
                let n = at.normal;
                let tangent = TangentSpace::new(n);
                if bvh.pressed(&at, object) {
                    return (0.0, n);
                }
                // A Sobol' set per vertex, shifted by a hash of its index.
                let shift = [hash(2 * i as u32), hash(2 * i as u32 + 1)];
                let (mut open, mut bent) = (0_u32, Vec3::ZERO);
                for k in 0..rays {
                    let dir = tangent.to_world(qmc::cosine_hemisphere(qmc::sobol2(k, shift)));
                    if bvh.unoccluded_from(&at, dir, f32::INFINITY) {
                        open += 1;
                        bent += dir;
                    }
                }
                (open as f32 / rays as f32, bent.normalize_or(n))
            })
            .collect();
        self.frame = Some(frame.clone());
        Ok(())
    }

    fn shade(&mut self, _eye: Vec3) -> Result<VertexRadiance> {
        let (Some(frame), Some(irradiance)) = (&self.frame, &self.irradiance) else {
            return Err(Error::stage(&self.name, "shade before update and relight"));
        };
        let mut occlusion = self.occlusion.iter();
        let radiance = frame
            .objects
            .iter()
            .zip(&self.albedo)
            .map(|(object, &albedo)| {
                occlusion
                    .by_ref()
                    .take(object.positions().len())
                    .map(|&(v, b)| lambert_radiance(albedo, v * irradiance.eval(b)).max(Vec3::ZERO))
                    .collect()
            })
            .collect();
        Ok(VertexRadiance::new(radiance))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        shadow_core::raster::render_shading(&self.name, camera, self.frame.as_ref(), &shading)
    }
}

/// A 32-bit integer hash (lowbias32), for per-vertex sample shifts.
fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}
