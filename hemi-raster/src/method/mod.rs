//! [`HemiRaster`]: the method driven through the [`ShadowMethod`] stages.

use std::time::{Duration, Instant};

use glam::Vec3;
use shadow_core::sh;
use shadow_core::shading::{lambert_radiance, lambert_transfer_radiance};
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, Export, FrameGeometry, Image, Profile, Result,
    Scene, ShTransfer, ShadowMethod, Stage, TransferSpace, VertexRadiance,
};

use crate::blockers::Blockers;
use crate::config::{BackfaceCulling, Config, Hierarchy, Integration, MaskResolution, Pvs};
use crate::engine::{Engine, Lighting, UpdateProfile, with_pipeline};
use crate::hierarchy::TwoLevel;
use crate::pvs::VisibleSets;
use crate::transfer::pixel_angle;

use crate::name::NAME;

/// Per vertex of `frame`, all objects one after another, whether it is
/// pressed on another object or buried in another one whose back faces are
/// culled (`cull`): such a receiver sees nothing, whatever its mask would
/// say. The paper rasterizes every receiver alike; this is the reference's
/// rule ([`shadow_core::contact`]), which a frame without another object
/// near each vertex skips.
fn enclosed(frame: &FrameGeometry, cull: &[bool]) -> Result<Vec<bool>> {
    Ok(shadow_core::contact::Contacts::new(frame, cull)?.enclosed_vertices())
}

/// Kautz, Lehtinen and Aila 2004: per vertex, the blocker triangles of the
/// frame (all objects: shadows between objects come for free) are
/// rasterized into a hemispherical visibility mask, which `update`
/// integrates to a world-space SH transfer vector; `relight` projects the
/// environment to SH and `shade` dots the two (eq. 2).
///
/// # Glossy materials
/// For a [`Brdf::Phong`] object the transfer depends on the view (the
/// paper's eq. 3 with the BRDF inside), so it cannot be integrated in
/// `update`: `update` keeps every vertex's mask, and `shade` integrates,
/// per vertex of a Phong object and in parallel, the specular lobe of its
/// own view direction against the SH basis over the mask's visible pixels
/// ([`glossy_transfer`](crate::glossy_transfer)), and dots that glossy
/// transfer vector with the lighting: ρ_d/π · L·T + ρ_s · L·T_glossy(ω_o).
/// With [`Integration::Direct`] the lobe weighs the prefiltered
/// environment directly. Each `shade` of a glossy scene redoes this for
/// every glossy vertex; `update` and `relight` cost what they do for
/// Lambert.
///
/// The lobe is evaluated at pixel centres, so its accuracy depends on the
/// lobe's width against the pixel (the table of
/// [`glossy_transfer`](crate::glossy_transfer)); and the SH
/// path reflects the lighting only as far as the SH order keeps it, which
/// a lobe of exponent 20 exceeds at order 5: for glossy materials under
/// real maps, prefer `Direct`.
pub struct HemiRaster {
    config: Config,
    /// What [`ShadowMethod::name`] returns ([`Config::name`]).
    name: String,
    /// Built by the first `prepare` and kept: it depends on the config only.
    engine: Option<Engine>,
    scene: Option<Prepared>,
    blockers: Option<Blockers>,
    frame: Option<FrameGeometry>,
    /// World-space transfer vectors, `coeff_count` per vertex, all objects
    /// one after another (SH integrations only).
    transfer: Vec<f32>,
    lighting: Option<Lighting>,
    /// Per vertex, Direct integration only: the shadowed irradiance.
    irradiance: Option<Vec<Vec3>>,
    /// What the last calls of the stages measured.
    profile: Profile,
}

struct Prepared {
    materials: Vec<Brdf>,
    /// Per object: whether its back faces are culled.
    cull: Vec<bool>,
    vertex_counts: Vec<usize>,
    /// The coarse meshes and per-vertex blocker lists, unless flat.
    hierarchy: Option<TwoLevel>,
    /// Per-vertex potentially visible sets, with [`Pvs::Animation`].
    visible: Option<VisibleSets>,
}

impl HemiRaster {
    /// A method with `config`; the plane table is built by the first
    /// [`ShadowMethod::prepare`].
    pub fn new(config: Config) -> HemiRaster {
        HemiRaster {
            name: config.name(),
            config,
            engine: None,
            scene: None,
            blockers: None,
            frame: None,
            transfer: Vec::new(),
            lighting: None,
            irradiance: None,
            profile: Profile::default(),
        }
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// How long the plane table took to build, once `prepare` has run.
    pub fn lut_build_time(&self) -> Option<Duration> {
        Some(with_pipeline!(self.engine.as_ref()?, p => p.raster().lut().build_time()))
    }

    /// The world-space transfer vector of `vertex` of `object` in the current
    /// frame (without ρ/π): its dot product with the lighting's SH is the
    /// irradiance. `None` before `update`, out of range, or with
    /// [`Integration::Direct`].
    pub fn transfer(&self, object: usize, vertex: usize) -> Option<&[f32]> {
        let v = self.global_vertex(object, vertex)?;
        let n = self.config.order.coeff_count();
        self.transfer.get(v * n..(v + 1) * n)
    }

    /// The cosine-weighted fraction of the hemisphere of `vertex` of `object`
    /// that its mask marks as blocked (ambient occlusion), in [0, 1]. `None`
    /// before `update` or out of range.
    pub fn blocked_fraction(&self, object: usize, vertex: usize) -> Option<f32> {
        let v = self.global_vertex(object, vertex)?;
        self.frame.as_ref()?;
        Some(with_pipeline!(self.engine.as_ref()?, p => p.blocked_fraction(v)))
    }

    /// How many coarse triangles stand for `object` with
    /// [`Hierarchy::TwoLevel`] (its full count when it was too small to
    /// simplify); `None` in flat mode, before `prepare` or out of range.
    pub fn coarse_triangle_count(&self, object: usize) -> Option<usize> {
        self.scene
            .as_ref()?
            .hierarchy
            .as_ref()?
            .coarse_triangle_count(object)
    }

    fn global_vertex(&self, object: usize, vertex: usize) -> Option<usize> {
        let counts = &self.scene.as_ref()?.vertex_counts;
        (vertex < *counts.get(object)?).then(|| counts[..object].iter().sum::<usize>() + vertex)
    }

    /// Runs [`ShadowMethod::update`] on one thread with its stages timed,
    /// and returns the profile: the update's split of the paper's Table 2
    /// (seconds of "gather", "transform", "rasterization", "integration")
    /// and the blocker counts of its Table 1 ("receivers", "candidates",
    /// "survivors"). The masks and transfer vectors are those `update`
    /// computes; only the time differs (one thread, plus two clock reads per
    /// receiver). A plain `update` records "visibility" and "integration"
    /// only.
    pub fn profile_update(&mut self, frame: &FrameGeometry) -> Result<Profile> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| Error::stage(NAME, format!("no thread pool for profiling: {e}")))?;
        let mut split = UpdateProfile::default();
        pool.install(|| self.update_frame(frame, Some(&mut split)))?;
        split.record(&mut self.profile);
        Ok(self.profile.clone())
    }

    /// `update`, optionally profiled.
    fn update_frame(
        &mut self,
        frame: &FrameGeometry,
        mut profile: Option<&mut UpdateProfile>,
    ) -> Result<()> {
        let prepared = self
            .scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "update before prepare"))?;
        let counts: Vec<usize> = frame.objects.iter().map(|o| o.vertex_count()).collect();
        if counts != prepared.vertex_counts {
            return Err(Error::InvalidScene(format!(
                "{NAME}: frame {} has vertex counts {counts:?} per object, the prepared scene {:?}",
                frame.frame, prepared.vertex_counts
            )));
        }
        let engine = self
            .engine
            .as_mut()
            .ok_or_else(|| Error::stage(NAME, "update before prepare"))?;
        let start = Instant::now();
        let blockers = Blockers::new(frame, &prepared.cull)?;
        let enclosed = enclosed(frame, &prepared.cull)?;
        let (hierarchy, visible) = (prepared.hierarchy.as_ref(), prepared.visible.as_ref());
        let candidates = with_pipeline!(engine, p => p.rasterize(&blockers, &enclosed, hierarchy, visible, profile.as_deref_mut()));
        let visibility = start.elapsed();
        match self.config.integration {
            Integration::ShBlocks | Integration::ShPixels => {
                let blocks = self.config.integration == Integration::ShBlocks;
                with_pipeline!(engine, p => p.transfer(&blockers, blocks, &mut self.transfer));
            }
            Integration::Direct => self.transfer.clear(),
        }
        self.blockers = Some(blockers);
        self.frame = Some(frame.clone());
        self.integrate_direct();
        let integration = start.elapsed() - visibility;
        self.profile.begin(Stage::Update);
        self.profile
            .seconds(Stage::Update, "visibility", visibility.as_secs_f64());
        self.profile
            .seconds(Stage::Update, "integration", integration.as_secs_f64());
        self.profile.count(
            Stage::Update,
            "blockers per receiver",
            candidates.round() as u64,
        );
        if let Some(p) = profile {
            p.integration = integration;
            // Gathering the frame's blockers and corner arrays, the rest.
            p.gather = visibility.saturating_sub(p.transform + p.rasterization);
        }
        Ok(())
    }

    /// Direct integration: the per-vertex irradiance, once both the masks and
    /// the environment are there.
    fn integrate_direct(&mut self) {
        self.irradiance = match (&self.engine, &self.blockers, &self.lighting) {
            (Some(engine), Some(blockers), Some(Lighting::Direct(env))) if self.frame.is_some() => {
                Some(with_pipeline!(engine, p => p.direct(blockers, env)))
            }
            _ => None,
        };
    }
}

impl Default for HemiRaster {
    fn default() -> Self {
        HemiRaster::new(Config::default())
    }
}

impl ShadowMethod for HemiRaster {
    /// [`Config::name`]: `hemi-raster` and each setting that differs from
    /// the preset it starts from (`hemi-raster:pvs:mask=16`), the name
    /// [`Config::from_name`] builds the same settings from.
    fn name(&self) -> &str {
        &self.name
    }

    /// Any geometry, any number of objects; Lambert and Phong, per vertex;
    /// export of the transfer vectors with the SH integrations.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            deforming_meshes: true,
            rigid_motion: true,
            multiple_objects: true,
            glossy_brdf: true,
            per_pixel: false,
            export: self.config.integration != Integration::Direct,
        }
    }

    /// Checks the scene's needs and materials, builds the plane table (first
    /// call only), decides back-face culling per object and, with
    /// [`Hierarchy::TwoLevel`], builds the coarse meshes and every vertex's
    /// blocker lists.
    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.capabilities().check(NAME, scene)?;
        if self.engine.is_none() {
            self.engine = Some(Engine::new(&self.config)?);
        }
        let cull: Vec<bool> = scene
            .objects()
            .iter()
            .map(|o| match self.config.backface_culling {
                BackfaceCulling::Auto => o.mesh.is_closed(),
                BackfaceCulling::On => true,
                BackfaceCulling::Off => false,
            })
            .collect();
        let hierarchy = match self.config.hierarchy {
            Hierarchy::Flat => None,
            Hierarchy::TwoLevel {
                coarse_divisor,
                min_coarse_triangles,
                near,
                near_reach,
                replace_near_chords,
            } => Some(TwoLevel::new(
                scene,
                &cull,
                coarse_divisor.get(),
                min_coarse_triangles,
                near,
                near_reach,
                replace_near_chords,
            )?),
        };
        let visible = match self.config.pvs {
            Pvs::Off => None,
            Pvs::Animation { stride } => {
                let frames = (0..scene.frames().len())
                    .step_by(stride.get() as usize)
                    .map(|i| scene.frame_geometry(i));
                let engine = self
                    .engine
                    .as_ref()
                    .ok_or_else(|| Error::stage(NAME, "no plane table"))?;
                Some(with_pipeline!(engine, p => {
                    VisibleSets::build(p.raster(), frames, &cull, hierarchy.as_ref())
                })?)
            }
        };
        self.scene = Some(Prepared {
            materials: scene.objects().iter().map(|o| o.material).collect(),
            cull,
            vertex_counts: scene
                .objects()
                .iter()
                .map(|o| o.mesh.vertex_count())
                .collect(),
            hierarchy,
            visible,
        });
        self.frame = None;
        self.blockers = None;
        self.transfer.clear();
        self.irradiance = None;
        Ok(())
    }

    /// Rasterizes every triangle of the frame into every vertex's mask (in
    /// parallel over vertices), then integrates the transfer vectors.
    fn update(&mut self, frame: &FrameGeometry, _camera: &Camera) -> Result<()> {
        self.update_frame(frame, None)
    }

    /// Projects the environment to SH (or, for direct integration,
    /// prefilters it to the mask's pixel size and sums it over the stored
    /// masks); visibility is not recomputed.
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.lighting = Some(match self.config.integration {
            Integration::ShBlocks | Integration::ShPixels => {
                let light = sh::project_environment(environment, self.config.order);
                Lighting::Sh(self.config.window.apply(&light))
            }
            Integration::Direct => {
                let sigma = match self.config.mask_resolution {
                    MaskResolution::R16 => pixel_angle::<u16>(),
                    MaskResolution::R32 => pixel_angle::<u32>(),
                    MaskResolution::R64 => pixel_angle::<u64>(),
                };
                Lighting::Direct(environment.prefiltered(sigma))
            }
        });
        self.integrate_direct();
        Ok(())
    }

    /// Lambert: ρ/π · L·T (eq. 2). Phong adds ρ_s · L·T_glossy(ω_o), the
    /// glossy transfer of each vertex's stored mask for its own view
    /// direction ω_o = normalize(eye − position), computed here (in
    /// parallel) because it depends on the eye (see [`HemiRaster`]); with
    /// direct integration, the lobe-weighted sum of the environment instead.
    /// Clamped at zero (SH ringing can dip below it behind strong blockers).
    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        if !eye.is_finite() {
            return Err(Error::InvalidScene(format!(
                "{NAME}: eye position {eye} is not finite"
            )));
        }
        let frame = self
            .frame
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before update"))?;
        let prepared = self
            .scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before prepare"))?;
        let lighting = self
            .lighting
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before relight"))?;
        let n = self.config.order.coeff_count();
        // The diffuse radiance of vertex v of albedo ρ, from SH transfer or
        // from direct sums.
        let transfer = &self.transfer;
        let diffuse: Box<dyn Fn(Vec3, usize) -> Vec3 + '_> = match lighting {
            Lighting::Sh(light) => Box::new(move |rho, v| {
                lambert_transfer_radiance(rho, light, &transfer[v * n..(v + 1) * n])
            }),
            Lighting::Direct(_) => {
                let e = self
                    .irradiance
                    .as_deref()
                    .ok_or_else(|| Error::stage(NAME, "shade before relight"))?;
                Box::new(move |rho, v| lambert_radiance(rho, e[v]))
            }
        };
        let (engine, blockers) = self
            .engine
            .as_ref()
            .zip(self.blockers.as_ref())
            .ok_or_else(|| Error::stage(NAME, "shade before update"))?;
        let blocks = self.config.integration == Integration::ShBlocks;
        let mut first = 0;
        let radiance = frame
            .objects
            .iter()
            .zip(&prepared.materials)
            .map(|(object, material)| {
                let rho = material.diffuse();
                let range = first..first + object.vertex_count();
                first = range.end;
                let glossy = match *material {
                    Brdf::Phong {
                        specular, exponent, ..
                    } if specular != Vec3::ZERO => {
                        let vertices = range.clone();
                        let g = with_pipeline!(engine, p => {
                            p.glossy(blockers, vertices, eye, exponent, lighting, blocks)
                        });
                        Some((specular, g))
                    }
                    _ => None,
                };
                range
                    .enumerate()
                    .map(|(i, v)| {
                        let mut l = diffuse(rho, v);
                        if let Some((specular, g)) = &glossy {
                            l += *specular * g[i];
                        }
                        l.max(Vec3::ZERO)
                    })
                    .collect()
            })
            .collect();
        Ok(VertexRadiance::new(radiance))
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        shadow_core::raster::render_shading(NAME, camera, self.frame.as_ref(), &shading)
    }

    fn profile(&self) -> Profile {
        self.profile.clone()
    }

    /// The current frame's world-space transfer vectors (without ρ/π) of
    /// the configured order: the diffuse part of every vertex's shading. A
    /// Phong object's glossy term depends on the view and is computed in
    /// `shade`, not exported. With [`Integration::Direct`] there is no
    /// transfer vector: an [`Error::InvalidConfig`].
    fn export(&self) -> Result<Export> {
        if self.config.integration == Integration::Direct {
            return Err(Error::config(
                NAME,
                "direct integration computes no SH transfer to export; use an SH integration",
            ));
        }
        let prepared = self
            .scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "export before prepare"))?;
        if self.frame.is_none() {
            return Err(Error::stage(NAME, "export before update"));
        }
        Ok(Export::Transfer(ShTransfer::new(
            self.config.order,
            TransferSpace::World,
            prepared.vertex_counts.clone(),
            self.transfer.clone(),
        )?))
    }
}

#[cfg(test)]
mod tests;
