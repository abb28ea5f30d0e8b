//! [`DeferredShadow`]: the stages of [`ShadowMethod`] over the parts of the
//! paper.

mod inputs;
mod prepare;
mod refresh;
mod shading;

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Vec3, Vec4};
use shadow_core::{
    Aabb, Brdf, Camera, Capabilities, Environment, Error, Export, FrameGeometry, Image, Mesh,
    Profile, Result, Scene, ShadowMethod, Stage, VertexRadiance,
    gpu::{GpuContext, GpuStages},
    sh::Zonal,
};

use crate::config::Config;
use crate::gpu::Gpu;
use crate::groups::Groups;
use crate::lights::AreaLight;
use crate::maps::{GpuLight, Plan};
use crate::name::NAME;
use crate::transfer::{GlossyVertex, Lighting, Transfer, export};
use refresh::world_bounds;

/// Tamura, Johan and Nishita's deferred shadowing on wgpu.
///
/// Per rigid object, a precomputed per-vertex transfer gives the radiance
/// with self-shadowing only, L_s (§4.1, §5.1); per pixel, occlusion maps of
/// the other objects, one per area light, take away what they block, L_o
/// (§4.2, §5.2); the image is max(L_s − L_o, 0) (eq. 3). Stages:
///
/// - `prepare`: the transfer of every object (ray-traced, model space);
/// - `relight`: the area lights, the lighting's SH and matrix, the light
///   weights and the maps;
/// - `update`: the objects' poses; the maps are rebuilt when an object
///   moved, the self-shadowed radiance and light weights of an object when
///   it turned;
/// - `shade` / `render`: the deferred pass at the vertices or the pixels.
///
/// Deforming meshes are refused ([`Capability::DeformingMeshes`](shadow_core::Capability::DeformingMeshes)): the
/// transfer is precomputed per rigid shape.
pub struct DeferredShadow {
    ctx: Arc<GpuContext>,
    config: Config,
    name: String,
    scene: Option<Prepared>,
    lit: Option<Lit>,
    posed: Option<Posed>,
    /// The last `update` and `relight` succeeded: the GPU holds their
    /// objects and maps. A failed one leaves them partly the old frame's
    /// and partly the new one's, and shading is refused until one
    /// succeeds.
    current: bool,
    profile: Profile,
}

/// What `prepare` builds.
struct Prepared {
    parts: Vec<Part>,
    /// Every triangle's global vertex indices and object.
    triangles: Vec<[u32; 4]>,
    groups: Groups,
    gpu: Gpu,
}

/// One object: its model-space mesh, transfer and material.
struct Part {
    mesh: Arc<Mesh>,
    transfer: Transfer,
    material: Brdf,
    /// How the material shades the self-shadowed radiance.
    shading: Shading,
    /// First global vertex.
    first_vertex: usize,
    /// Model-space bounds of the mesh.
    bounds: Aabb,
}

/// A material as the self-shadowing uses it (§5.1).
enum Shading {
    /// ρ/π, with the 36-term transfer (eq. 2).
    Diffuse { albedo: Vec3 },
    /// ρ_d/π plus ρ_s times the Phong lobe over [`GLOSSY_ORDER`], with the
    /// 16-term transfer (eq. 12–13).
    Glossy {
        diffuse: Vec3,
        specular: Vec3,
        lobe: Zonal,
    },
}

/// What `relight` builds.
struct Lit {
    lights: Vec<AreaLight>,
    gpu: Vec<GpuLight>,
    lighting: Lighting,
}

/// The current frame's poses and what depends on them and the lights.
struct Posed {
    transforms: Vec<Affine3A>,
    rotations: Vec<Mat3>,
    /// Per object under the current lights: the diffuse radiance, or the
    /// glossy vertices' view-independent part; `None` until lit.
    radiance: Vec<Option<SelfRadiance>>,
    /// Per vertex and light, v_s max(0, n·ω_i); stale objects are redone.
    weights: Vec<f32>,
    weights_stale: Vec<bool>,
    /// Per vertex, pressed on another object or buried in a closed one: it
    /// receives nothing (the vertex pass gives it 0).
    enclosed: Vec<bool>,
    /// The eye the GPU's per-vertex shading data was last written for;
    /// `None` when it is stale.
    uploaded: Option<Vec3>,
    /// The maps match the poses and lights.
    maps_ready: bool,
    /// The plan of the maps on the GPU and the poses it was made for; `None`
    /// when the lights changed since.
    planned: Option<(Plan, Vec<Affine3A>)>,
}

enum SelfRadiance {
    Diffuse(Vec<Vec3>),
    Glossy {
        vertices: Vec<GlossyVertex>,
        specular: Vec3,
    },
}

impl DeferredShadow {
    /// The method on `ctx`'s device; fails on a configuration out of range.
    pub fn new(ctx: Arc<GpuContext>, config: Config) -> Result<DeferredShadow> {
        config.check()?;
        let name = config.name();
        Ok(DeferredShadow {
            ctx,
            config,
            name,
            scene: None,
            lit: None,
            posed: None,
            current: false,
            profile: Profile::default(),
        })
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The area lights of the current environment.
    pub fn area_lights(&self) -> Option<&[AreaLight]> {
        self.lit.as_ref().map(|l| l.lights.as_slice())
    }

    /// The occlusion maps of the current frame.
    pub fn map_count(&self) -> Option<u32> {
        self.scene.as_ref().map(|s| s.gpu.map_count())
    }

    /// The occluder groups of the current frame: the group of each object.
    pub fn groups(&self) -> Option<&[u32]> {
        self.scene.as_ref().map(|s| s.groups.of_object.as_slice())
    }

    /// Seconds and bytes of the precomputed transfer, over all objects.
    pub fn precomputation(&self) -> Option<(f64, usize)> {
        let scene = self.scene.as_ref()?;
        Some((
            scene.parts.iter().map(|p| p.transfer.seconds).sum(),
            scene.parts.iter().map(|p| p.transfer.bytes()).sum(),
        ))
    }

    /// Runs `change`, an `update` or `relight`: until one succeeds after it
    /// fails, shading is refused ([`DeferredShadow::current`]).
    fn changing(&mut self, change: impl FnOnce(&mut Self) -> Result<()>) -> Result<()> {
        self.current = false;
        change(self)?;
        self.current = true;
        Ok(())
    }

    fn prepared(&self) -> Result<&Prepared> {
        self.scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "a stage before prepare"))
    }

    /// The near plane for `camera`: just short of the scene's bounds, or
    /// 10⁻⁵ of the far distance from inside them, where the reversed depth
    /// of the visible-surface pass keeps the far surfaces apart.
    fn near(&self, camera: &Camera) -> Result<f32> {
        let scene = self.prepared()?;
        let posed = self
            .posed
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "render before update"))?;
        let bounds = world_bounds(&scene.parts, &posed.transforms)
            .into_iter()
            .fold(Aabb::EMPTY, Aabb::union);
        let far = (bounds.center() - camera.eye).length() + 0.5 * bounds.diagonal();
        let outside = (camera.eye.clamp(bounds.min, bounds.max) - camera.eye).length();
        Ok((0.9 * outside).max(1e-5 * far).max(f32::MIN_POSITIVE))
    }
}

impl ShadowMethod for DeferredShadow {
    fn name(&self) -> &str {
        &self.name
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            deforming_meshes: false,
            rigid_motion: true,
            multiple_objects: true,
            glossy_brdf: true,
            per_pixel: true,
            export: true,
        }
    }

    /// Checks that every pose of the scene is rigid, precomputes each
    /// object's transfer and uploads the geometry.
    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.scene = None;
        self.posed = None;
        self.current = false;
        self.profile = Profile::default();
        self.scene = Some(self.prepare_scene(scene)?);
        Ok(())
    }

    /// Splits the environment into area lights and projects it; redoes the
    /// self-shadowed radiance, light weights and maps of the current poses.
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.profile.begin(Stage::Relight);
        self.changing(|m| {
            m.light(environment)?;
            m.run_refresh(Stage::Relight)
        })
    }

    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        self.profile.begin(Stage::Update);
        self.changing(|m| {
            m.pose(frame)?;
            m.run_refresh(Stage::Update)
        })
    }

    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        self.profile.begin(Stage::Shade);
        let start = Instant::now();
        self.upload_shading(eye)?;
        self.profile.seconds(
            Stage::Shade,
            "self-shadowed radiance (CPU)",
            start.elapsed().as_secs_f64(),
        );
        let start = Instant::now();
        let ctx = Arc::clone(&self.ctx);
        let gpu = &self.prepared()?.gpu;
        ctx.run("deferred-shadow: shade", |encoder| {
            gpu.record_vertices(encoder, eye)
        })?;
        let middle = Instant::now();
        let values: Vec<Vec4> = ctx.read_buffer(gpu.vertex_radiance(), 0, gpu.vertex_count())?;
        self.profile.seconds(
            Stage::Shade,
            "deferred pass (GPU)",
            (middle - start).as_secs_f64(),
        );
        self.profile
            .seconds(Stage::Shade, "read-back", middle.elapsed().as_secs_f64());
        let scene = self.prepared()?;
        let radiance = scene
            .parts
            .iter()
            .map(|p| {
                values[p.first_vertex..p.first_vertex + p.mesh.vertex_count()]
                    .iter()
                    .map(|v| v.truncate())
                    .collect()
            })
            .collect();
        Ok(VertexRadiance::new(radiance))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        self.profile.begin(Stage::Render);
        let start = Instant::now();
        self.upload_shading(camera.eye)?;
        let near = self.near(camera)?;
        self.profile.seconds(
            Stage::Render,
            "self-shadowed radiance (CPU)",
            start.elapsed().as_secs_f64(),
        );
        let start = Instant::now();
        let ctx = Arc::clone(&self.ctx);
        let scene = self
            .scene
            .as_mut()
            .ok_or_else(|| Error::stage(NAME, "render before prepare"))?;
        ctx.run("deferred-shadow: render", |encoder| {
            scene.gpu.record_image(encoder, camera, near)
        })?;
        let middle = Instant::now();
        let texture = scene.gpu.image();
        let texels: Vec<[f32; 4]> = ctx.read_texture(texture)?;
        self.profile.seconds(
            Stage::Render,
            "visible surface and deferred pass (GPU)",
            (middle - start).as_secs_f64(),
        );
        self.profile
            .seconds(Stage::Render, "read-back", middle.elapsed().as_secs_f64());
        Ok(Image {
            width: camera.width,
            height: camera.height,
            pixels: texels.iter().map(|t| Vec3::new(t[0], t[1], t[2])).collect(),
            covered: texels.iter().map(|t| t[3] > 0.5).collect(),
            std_error: None,
        })
    }

    fn profile(&self) -> Profile {
        self.profile.clone()
    }

    /// The self-transfer of every vertex in world space for the current
    /// poses ([`shadow_core::ShTransfer`]'s convention: irradiance = L·t):
    /// 36 terms, or 16 when the scene has a glossy object.
    fn export(&self) -> Result<Export> {
        let scene = self.prepared()?;
        let posed = self
            .posed
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "export before update"))?;
        let transfers: Vec<&Transfer> = scene.parts.iter().map(|p| &p.transfer).collect();
        Ok(Export::Transfer(export(&transfers, &posed.rotations)?))
    }
}

impl GpuStages for DeferredShadow {
    fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The area lights and lighting on the CPU; the maps of the current
    /// poses into `encoder`.
    fn record_relight(
        &mut self,
        environment: &Environment,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        self.profile.begin(Stage::Relight);
        self.changing(|m| {
            m.light(environment)?;
            m.record_refresh(Stage::Relight, encoder)
        })
    }

    fn record_update(
        &mut self,
        frame: &FrameGeometry,
        _camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        self.profile.begin(Stage::Update);
        self.changing(|m| {
            m.pose(frame)?;
            m.record_refresh(Stage::Update, encoder)
        })
    }

    /// The deferred pass at the vertices, into `encoder`. Each recording
    /// reads its own eye and self-shadowed radiance, so several eyes can be
    /// recorded into one encoder; the returned buffer is the same for all,
    /// so copy it out before recording the next.
    fn record_shade(
        &mut self,
        eye: Vec3,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Buffer> {
        self.upload_shading(eye)?;
        let gpu = &self.prepared()?.gpu;
        gpu.record_vertices(encoder, eye)?;
        Ok(gpu.vertex_radiance())
    }

    /// The visible surface and the deferred pass per pixel, into
    /// `encoder`. Each recording reads its own camera, eye and
    /// self-shadowed radiance, so several cameras can be recorded into one
    /// encoder; cameras of one image size share the returned texture, so
    /// sample or copy it before recording the next.
    fn record_render(
        &mut self,
        camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Texture> {
        self.upload_shading(camera.eye)?;
        let near = self.near(camera)?;
        let scene = self
            .scene
            .as_mut()
            .ok_or_else(|| Error::stage(NAME, "render before prepare"))?;
        scene.gpu.record_image(encoder, camera, near)?;
        Ok(scene.gpu.image())
    }
}
