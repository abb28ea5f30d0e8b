//! [`DeferredShadow`]: the stages of [`ShadowMethod`] over the parts of the
//! paper.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Mat4, Vec3, Vec4};
use shadow_core::{
    Aabb, Brdf, Camera, Capabilities, Capability, Environment, Error, Export, FrameGeometry, Image,
    Mesh, Pose, Profile, Result, Scene, ShadowMethod, Stage, VertexRadiance,
    gpu::{GpuContext, GpuStages},
    reflect,
    sh::Zonal,
};

use crate::config::Config;
use crate::gpu::{Geometry, Gpu, GpuObject};
use crate::groups::{Groups, posed_bounds};
use crate::lights::{AreaLight, decompose};
use crate::maps::{GpuLight, Plan};
use crate::transfer::{
    DIFFUSE_ORDER, GLOSSY_ORDER, GlossyVertex, Lighting, Transfer, diffuse, export, glossy,
};

use crate::name::NAME;

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
/// Deforming meshes are refused ([`Capability::DeformingMeshes`]): the
/// transfer is precomputed per rigid shape.
pub struct DeferredShadow {
    ctx: Arc<GpuContext>,
    config: Config,
    name: String,
    scene: Option<Prepared>,
    lit: Option<Lit>,
    posed: Option<Posed>,
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

    /// The occluder groups: the group of each object.
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

    fn prepared(&self) -> Result<&Prepared> {
        self.scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "a stage before prepare"))
    }

    /// The pose of every object of `frame`: refused unless rigid with a
    /// uniform scale (the precomputed self-visibility holds for nothing
    /// else).
    fn poses_of(frame: &FrameGeometry) -> Result<Vec<(Affine3A, Mat3)>> {
        frame
            .objects
            .iter()
            .map(|o| match o.transform {
                Some(t) => rigid(o.name(), t),
                None => Err(Error::Unsupported {
                    method: NAME.to_string(),
                    capability: Capability::DeformingMeshes,
                }),
            })
            .collect()
    }

    /// Brings everything that depends on the poses and the lights up to
    /// date on the CPU and in GPU buffers; true when the maps must be
    /// (re)drawn.
    fn refresh(&mut self, stage: Stage) -> Result<bool> {
        let (Some(scene), Some(lit), Some(posed)) = (&mut self.scene, &self.lit, &mut self.posed)
        else {
            return Ok(false);
        };
        let q = lit.gpu.len();
        let start = Instant::now();
        for (o, part) in scene.parts.iter().enumerate() {
            if posed.radiance[o].is_none() {
                posed.radiance[o] = Some(self_terms(part, &lit.lighting, posed.rotations[o]));
                posed.uploaded = None;
            }
        }
        let self_seconds = start.elapsed().as_secs_f64();
        let start = Instant::now();
        for (o, part) in scene.parts.iter().enumerate() {
            if posed.weights_stale[o] {
                let to_model = posed.rotations[o].transpose();
                let directions: Vec<Vec3> = lit
                    .lights
                    .iter()
                    .map(|l| (to_model * l.direction).normalize())
                    .collect();
                let range =
                    part.first_vertex * q..(part.first_vertex + part.mesh.vertex_count()) * q;
                part.transfer.expand(&directions, &mut posed.weights[range]);
                posed.weights_stale[o] = false;
                posed.uploaded = None;
            }
        }
        let weight_seconds = start.elapsed().as_secs_f64();
        self.profile
            .seconds(stage, "self-shadowed radiance (CPU)", self_seconds);
        self.profile
            .seconds(stage, "light weights (CPU)", weight_seconds);
        if posed.maps_ready {
            return Ok(false);
        }
        let start = Instant::now();
        let bounds = world_bounds(&scene.parts, &posed.transforms);
        let plan = Plan::new(&lit.gpu, &bounds, &scene.groups, self.config.map_resolution);
        // Refused before the masks are made, as before anything is allocated.
        scene.gpu.check_plan(&plan)?;
        // Maps between groups that did not move since they were drawn are
        // kept.
        let reuse = match &posed.planned {
            Some((previous, transforms)) => {
                let mut moved = vec![false; scene.groups.len()];
                for (o, (now, then)) in posed.transforms.iter().zip(transforms).enumerate() {
                    if now != then {
                        moved[scene.groups.of_object[o] as usize] = true;
                    }
                }
                plan.reuse(previous, &moved)
            }
            None => vec![None; plan.maps.len()],
        };
        let positions: Vec<Vec3> = scene
            .parts
            .iter()
            .zip(&posed.transforms)
            .flat_map(|(part, t)| part.mesh.positions().iter().map(|p| t.transform_point3(*p)))
            .collect();
        let masks = plan.masks(
            &lit.gpu,
            &positions,
            &scene.triangles,
            &scene.groups.of_object,
        );
        if let Err(e) = scene
            .gpu
            .set_plan(&plan, &masks, &scene.groups.of_object, &reuse)
        {
            // The maps on the GPU may be partly this plan's: keep none.
            posed.planned = None;
            return Err(e);
        }
        self.profile
            .seconds(stage, "map planning (CPU)", start.elapsed().as_secs_f64());
        self.profile
            .count(stage, "occlusion maps", plan.maps.len() as u64);
        self.profile.count(
            stage,
            "occlusion maps drawn",
            reuse.iter().filter(|r| r.is_none()).count() as u64,
        );
        posed.planned = Some((plan, posed.transforms.clone()));
        posed.maps_ready = true;
        Ok(true)
    }

    /// [`Self::refresh`], then the maps recorded into `encoder` if needed.
    fn record_refresh(&mut self, stage: Stage, encoder: &mut wgpu::CommandEncoder) -> Result<()> {
        if self.refresh(stage)? {
            self.prepared()?.gpu.record_maps(encoder)?;
        }
        Ok(())
    }

    /// [`Self::refresh`] and the maps drawn, waiting for the GPU.
    fn run_refresh(&mut self, stage: Stage) -> Result<()> {
        if self.refresh(stage)? {
            let start = Instant::now();
            let ctx = Arc::clone(&self.ctx);
            let gpu = &self.prepared()?.gpu;
            ctx.run("deferred-shadow: occlusion maps", |encoder| {
                gpu.record_maps(encoder)
            })?;
            self.profile
                .seconds(stage, "occlusion maps (GPU)", start.elapsed().as_secs_f64());
        }
        Ok(())
    }

    /// The area lights and the lighting of `environment`; what depended on
    /// the previous lights is marked stale.
    fn light(&mut self, environment: &Environment) -> Result<()> {
        let start = Instant::now();
        let lights = decompose(environment, self.config.lights)?;
        let gpu: Vec<GpuLight> = lights.iter().map(GpuLight::new).collect();
        self.profile
            .seconds(Stage::Relight, "area lights", start.elapsed().as_secs_f64());
        let start = Instant::now();
        let lighting = Lighting::new(environment, self.config.window);
        self.profile.seconds(
            Stage::Relight,
            "SH lighting and matrix",
            start.elapsed().as_secs_f64(),
        );
        if let Some(scene) = &mut self.scene {
            scene.gpu.set_lights(&gpu)?;
        }
        self.lit = Some(Lit {
            lights,
            gpu,
            lighting,
        });
        if let Some(posed) = &mut self.posed {
            posed.radiance.iter_mut().for_each(|r| *r = None);
            posed.weights_stale.iter_mut().for_each(|s| *s = true);
            posed.maps_ready = false;
            posed.planned = None;
        }
        Ok(())
    }

    /// Takes the poses of `frame`.
    fn pose(&mut self, frame: &FrameGeometry) -> Result<()> {
        let scene = self
            .scene
            .as_mut()
            .ok_or_else(|| Error::stage(NAME, "update before prepare"))?;
        if frame.objects.len() != scene.parts.len() {
            return Err(Error::stage(
                NAME,
                format!(
                    "a frame of {} objects for a scene of {}",
                    frame.objects.len(),
                    scene.parts.len()
                ),
            ));
        }
        let poses = Self::poses_of(frame)?;
        let q = self.config.lights;
        let vertices = scene.gpu.vertex_count();
        let posed = self.posed.get_or_insert_with(|| Posed {
            transforms: Vec::new(),
            rotations: Vec::new(),
            radiance: Vec::new(),
            weights: vec![0.0; vertices * q],
            weights_stale: Vec::new(),
            uploaded: None,
            maps_ready: false,
            planned: None,
        });
        let fresh = posed.transforms.len() != poses.len();
        if fresh {
            posed.radiance = (0..poses.len()).map(|_| None).collect();
            posed.weights_stale = vec![true; poses.len()];
        }
        for (o, &(t, r)) in poses.iter().enumerate() {
            if fresh || posed.transforms[o] != t {
                posed.maps_ready = false;
            }
            if fresh || posed.rotations[o] != r {
                posed.radiance[o] = None;
                posed.weights_stale[o] = true;
            }
        }
        posed.transforms = poses.iter().map(|p| p.0).collect();
        posed.rotations = poses.iter().map(|p| p.1).collect();
        let objects: Vec<GpuObject> = scene
            .parts
            .iter()
            .zip(&posed.transforms)
            .zip(&scene.groups.of_object)
            .map(|((part, t), &g)| GpuObject::new(Mat4::from(*t), &part.material, g))
            .collect();
        scene.gpu.set_objects(&objects)
    }

    /// L_s toward `eye` at every vertex (eq. 2, 13) and the light weights,
    /// uploaded unless the GPU has them already.
    fn upload_shading(&mut self, eye: Vec3) -> Result<()> {
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
            match terms.as_ref().expect("refreshed with the lights") {
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
        for ((dst, ls), w) in shading
            .chunks_exact_mut(stride)
            .zip(&out)
            .zip(posed.weights.chunks_exact(q))
        {
            dst[..3].copy_from_slice(&ls.to_array());
            dst[4..].copy_from_slice(w);
        }
        scene.gpu.set_shading(&shading)?;
        posed.uploaded = Some(eye);
        Ok(())
    }

    /// The near plane for `camera`: just short of the scene's bounds.
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

/// A rigid transform's rotation, refused unless it scales evenly.
fn rigid(name: &str, t: Affine3A) -> Result<(Affine3A, Mat3)> {
    let (scale, rotation, _) = t.to_scale_rotation_translation();
    if scale.max_element() > scale.min_element() * (1.0 + 1e-3) {
        return Err(Error::InvalidScene(format!(
            "{NAME}: object {name} is scaled unevenly ({scale}), which changes its self-shadowing"
        )));
    }
    Ok((t, Mat3::from_quat(rotation)))
}

/// How object `name` shades: a glossy material with its Phong lobe's
/// zonal expansion (eq. 12), which every exponent a scene accepts has.
fn shading_of(name: &str, material: Brdf) -> Result<Shading> {
    let refused = |what: String| Error::InvalidScene(format!("{NAME}: object {name}: {what}"));
    match material {
        Brdf::Phong {
            diffuse,
            specular,
            exponent,
        } if material.is_glossy() => Ok(Shading::Glossy {
            diffuse,
            specular,
            lobe: Zonal::phong(GLOSSY_ORDER, exponent)
                .ok_or_else(|| refused(format!("Phong exponent {exponent} has no lobe")))?,
        }),
        material => Ok(Shading::Diffuse {
            albedo: material.diffuse(),
        }),
    }
}

/// The self-shadowed radiance of `part` turned by `rotation`, the
/// view-dependent part left for later.
fn self_terms(part: &Part, lighting: &Lighting, rotation: Mat3) -> SelfRadiance {
    match &part.shading {
        Shading::Glossy {
            diffuse,
            specular,
            lobe,
        } => SelfRadiance::Glossy {
            vertices: glossy(lighting, &part.transfer.rotated(rotation), *diffuse, lobe),
            specular: *specular,
        },
        Shading::Diffuse { albedo } => {
            SelfRadiance::Diffuse(diffuse(lighting, &part.transfer, rotation, *albedo))
        }
    }
}

/// World-space bounds of every part under `transforms`.
fn world_bounds(parts: &[Part], transforms: &[Affine3A]) -> Vec<Aabb> {
    parts
        .iter()
        .zip(transforms)
        .map(|(part, t)| posed_bounds(part.bounds, t))
        .collect()
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
        self.profile = Profile::default();
        self.capabilities().check(&self.name, scene)?;
        for frame in scene.frames() {
            for (pose, object) in frame.poses.iter().zip(scene.objects()) {
                match pose {
                    Pose::Rigid(t) => {
                        rigid(object.mesh.name(), *t)?;
                    }
                    Pose::Deformed { .. } => {
                        return Err(Error::Unsupported {
                            method: self.name.clone(),
                            capability: Capability::DeformingMeshes,
                        });
                    }
                }
            }
        }
        let shadings = scene
            .objects()
            .iter()
            .map(|o| shading_of(o.mesh.name(), o.material))
            .collect::<Result<Vec<_>>>()?;
        let start = Instant::now();
        let mut parts = Vec::new();
        let mut first_vertex = 0;
        for (object, shading) in scene.objects().iter().zip(shadings) {
            let order = match shading {
                Shading::Diffuse { .. } => DIFFUSE_ORDER,
                Shading::Glossy { .. } => GLOSSY_ORDER,
            };
            parts.push(Part {
                mesh: Arc::clone(&object.mesh),
                transfer: Transfer::precompute(&object.mesh, order, self.config.rays)?,
                material: object.material,
                shading,
                first_vertex,
                bounds: object.mesh.bounds(),
            });
            first_vertex += object.mesh.vertex_count();
        }
        self.profile.seconds(
            Stage::Prepare,
            "self transfer (ray-traced)",
            start.elapsed().as_secs_f64(),
        );
        self.profile.count(
            Stage::Prepare,
            "transfer bytes",
            parts.iter().map(|p| p.transfer.bytes() as u64).sum(),
        );
        let start = Instant::now();
        let frame = scene.frame_geometry(0)?;
        let transforms: Vec<Affine3A> = Self::poses_of(&frame)?.into_iter().map(|p| p.0).collect();
        let groups = Groups::of_scene(&self.config.grouping, scene)?;
        let geometry = Geometry::new(parts.iter().map(|p| &*p.mesh));
        let objects: Vec<GpuObject> = parts
            .iter()
            .zip(&transforms)
            .zip(&groups.of_object)
            .map(|((part, t), &g)| GpuObject::new(Mat4::from(*t), &part.material, g))
            .collect();
        let mut gpu = Gpu::new(
            Arc::clone(&self.ctx),
            &geometry,
            &objects,
            self.config.map_resolution,
            self.config.self_visibility,
        )?;
        self.profile.seconds(
            Stage::Prepare,
            "pipelines and buffers",
            start.elapsed().as_secs_f64(),
        );
        gpu.warm_up()?;
        if let Some(lit) = &self.lit {
            gpu.set_lights(&lit.gpu)?;
        }
        self.scene = Some(Prepared {
            parts,
            triangles: geometry.triangles,
            groups,
            gpu,
        });
        Ok(())
    }

    /// Splits the environment into area lights and projects it; redoes the
    /// self-shadowed radiance, light weights and maps of the current poses.
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.profile.begin(Stage::Relight);
        self.light(environment)?;
        self.run_refresh(Stage::Relight)
    }

    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        self.profile.begin(Stage::Update);
        self.pose(frame)?;
        self.run_refresh(Stage::Update)
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
        self.light(environment)?;
        self.record_refresh(Stage::Relight, encoder)
    }

    fn record_update(
        &mut self,
        frame: &FrameGeometry,
        _camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        self.profile.begin(Stage::Update);
        self.pose(frame)?;
        self.record_refresh(Stage::Update, encoder)
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
