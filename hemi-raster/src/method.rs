//! [`HemiRaster`]: the method driven through the [`ShadowMethod`] stages.

use std::f32::consts::FRAC_1_PI;
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use shadow_core::sh::{self, ShRgb, Zonal};
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, FrameGeometry, Image, Result, Scene,
    ShadowMethod, VertexRadiance,
};

use crate::config::{BackfaceCulling, Config, Hierarchy, MaskResolution};
use crate::hierarchy::TwoLevel;
use crate::kernel::{Candidates, Corners, Scratch, Simd, receiver_mask};
use crate::mask::{Mask, MaskRow};
use crate::rasterize::{Blockers, Rasterizer};
use crate::transfer::{Integration, direct_irradiance, pixel_angle, sh_transfer};

const NAME: &str = "hemi-raster";

/// Kautz, Lehtinen and Aila 2004: per vertex, every triangle of the frame
/// (all objects: shadows between objects come for free) is rasterized into a
/// hemispherical visibility mask, which is integrated to a world-space SH
/// transfer vector in `update`; `relight` projects the environment to SH and
/// `shade` dots the two (eq. 2).
///
/// Lambert materials only for now: a scene with a glossy material is
/// rejected by `prepare` with [`Error::Unsupported`].
pub struct HemiRaster {
    config: Config,
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
}

struct Prepared {
    materials: Vec<Brdf>,
    /// Per object: whether its back faces are culled.
    cull: Vec<bool>,
    vertex_counts: Vec<usize>,
    /// The coarse meshes and per-vertex blocker lists, unless flat.
    hierarchy: Option<TwoLevel>,
}

/// Where one [`HemiRaster::profile_update`] spent its time, on one thread:
/// the split of Kautz et al.'s Table 2 ("transform includes backface culling
/// and view transformation of blockers") and the counts behind its Table 1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateProfile {
    /// Receivers (vertices, all objects).
    pub receivers: usize,
    /// Blocker triangles considered, summed over receivers: divided by
    /// `receivers`, Table 1's "Avg. #Tris".
    pub candidates: u64,
    /// Of those, the ones that survived culling and were rasterized.
    pub survivors: u64,
    /// Gathering the frame's blockers into the loop's arrays, and the rest
    /// of the visibility stage outside the per-receiver loop ("Other").
    pub gather: Duration,
    /// Per receiver: blockers into its tangent frame, culling (horizon,
    /// receiver, back faces, boxes below the horizon), plane cells.
    pub transform: Duration,
    /// Per receiver: plane-mask look-ups, ANDs and ORs.
    pub rasterization: Duration,
    /// Masks to transfer vectors (or, for direct integration, to irradiance).
    pub integration: Duration,
}

impl UpdateProfile {
    /// The whole update.
    pub fn total(&self) -> Duration {
        self.gather + self.transform + self.rasterization + self.integration
    }
}

enum Lighting {
    Sh(ShRgb),
    /// Prefiltered to the mask's pixel size.
    Direct(Environment),
}

enum Engine {
    R16(Box<Pipeline<u16>>),
    R32(Box<Pipeline<u32>>),
    R64(Box<Pipeline<u64>>),
}

/// Runs `$body` with `$p` bound to the engine's pipeline, whatever its
/// resolution.
macro_rules! with_pipeline {
    ($engine:expr, $p:ident => $body:expr) => {
        match $engine {
            Engine::R16($p) => $body,
            Engine::R32($p) => $body,
            Engine::R64($p) => $body,
        }
    };
}

struct Pipeline<W: MaskRow> {
    raster: Rasterizer<W>,
    /// The compilation of the per-receiver loop this CPU runs.
    simd: Simd,
    /// The current frame's masks, one per vertex, all objects together.
    masks: Vec<Mask<W>>,
}

impl<W: MaskRow> Pipeline<W> {
    fn new(config: &Config) -> Result<Pipeline<W>> {
        Ok(Pipeline {
            raster: Rasterizer::new(config.lut_resolution)?,
            simd: config.simd.resolve()?,
            masks: Vec::new(),
        })
    }

    /// Every receiver's mask, in parallel; or, with `profile`, on the
    /// calling thread with the loop's phases timed.
    fn rasterize(
        &mut self,
        blockers: &Blockers,
        hierarchy: Option<&TwoLevel>,
        profile: Option<&mut UpdateProfile>,
    ) {
        let fine = Corners::new(blockers, &blockers.triangles, blockers.objects.clone());
        let levels = hierarchy.map(|h| (h, h.corners(blockers)));
        let (lut, simd) = (self.raster.lut(), self.simd);
        let candidates = |v: usize| match &levels {
            Some((h, coarse)) => h.candidates(coarse, &fine, v),
            None => Candidates::All(&fine),
        };
        let mask = |scratch: &mut Scratch, v: usize| {
            receiver_mask(
                simd,
                lut,
                blockers,
                &blockers.frame(v),
                &candidates(v),
                scratch,
            )
        };
        let receivers = 0..blockers.vertex_count();
        self.masks = match profile {
            None => receivers
                .into_par_iter()
                .map_init(Scratch::default, mask)
                .collect(),
            Some(profile) => {
                let mut scratch = Scratch::profiling();
                let masks = receivers
                    .clone()
                    .map(|v| {
                        profile.candidates += candidates(v).count() as u64;
                        mask(&mut scratch, v)
                    })
                    .collect();
                let phases = scratch.profile().unwrap_or_default();
                profile.transform = phases.transform;
                profile.rasterization = phases.rasterization;
                profile.survivors = phases.survivors;
                profile.receivers = receivers.len();
                masks
            }
        };
    }

    fn transfer(&self, blockers: &Blockers, lambert: &Zonal, blocks: bool, out: &mut Vec<f32>) {
        let n = lambert.order().coeff_count();
        out.resize(self.masks.len() * n, 0.0);
        let grid = self.raster.grid();
        out.par_chunks_mut(n)
            .zip(self.masks.par_iter())
            .enumerate()
            .for_each(|(v, (out, mask))| {
                sh_transfer(grid, mask, &blockers.frame(v), lambert, blocks, out)
            });
    }

    fn direct(&self, blockers: &Blockers, environment: &Environment) -> Vec<Vec3> {
        let grid = self.raster.grid();
        self.masks
            .par_iter()
            .enumerate()
            .map(|(v, mask)| direct_irradiance(grid, mask, &blockers.frame(v), environment))
            .collect()
    }

    fn blocked_fraction(&self, v: usize) -> f32 {
        self.raster.grid().coverage(&self.masks[v]) * FRAC_1_PI
    }
}

impl Engine {
    fn new(config: &Config) -> Result<Engine> {
        Ok(match config.mask_resolution {
            MaskResolution::R16 => Engine::R16(Box::new(Pipeline::new(config)?)),
            MaskResolution::R32 => Engine::R32(Box::new(Pipeline::new(config)?)),
            MaskResolution::R64 => Engine::R64(Box::new(Pipeline::new(config)?)),
        })
    }
}

impl HemiRaster {
    /// A method with `config`; the plane table is built by the first
    /// [`ShadowMethod::prepare`].
    pub fn new(config: Config) -> HemiRaster {
        HemiRaster {
            config,
            engine: None,
            scene: None,
            blockers: None,
            frame: None,
            transfer: Vec::new(),
            lighting: None,
            irradiance: None,
        }
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// How long the plane table took to build, once `prepare` has run.
    pub fn lut_build_time(&self) -> Option<Duration> {
        Some(with_pipeline!(self.engine.as_ref()?, p => p.raster.lut().build_time()))
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

    /// Runs [`ShadowMethod::update`] on one thread with its stages timed:
    /// the split of the paper's Table 2 and the blocker counts of its Table 1.
    /// The masks and transfer vectors are those `update` computes; only the
    /// time differs (one thread, plus two clock reads per receiver).
    pub fn profile_update(&mut self, frame: &FrameGeometry) -> Result<UpdateProfile> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| Error::stage(NAME, format!("no thread pool for profiling: {e}")))?;
        let mut profile = UpdateProfile::default();
        pool.install(|| self.update_frame(frame, Some(&mut profile)))?;
        Ok(profile)
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
        let blockers = Blockers::new(frame, &prepared.cull);
        let hierarchy = prepared.hierarchy.as_ref();
        with_pipeline!(engine, p => p.rasterize(&blockers, hierarchy, profile.as_deref_mut()));
        let visibility = start.elapsed();
        let order = self.config.order;
        match self.config.integration {
            Integration::ShBlocks | Integration::ShPixels => {
                let blocks = self.config.integration == Integration::ShBlocks;
                let lambert = Zonal::lambert(order);
                with_pipeline!(engine, p => p.transfer(&blockers, &lambert, blocks, &mut self.transfer));
            }
            Integration::Direct => self.transfer.clear(),
        }
        self.blockers = Some(blockers);
        self.frame = Some(frame.clone());
        self.integrate_direct();
        if let Some(p) = profile {
            p.integration = start.elapsed() - visibility;
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
    /// `hemi-raster`, or `hemi-raster-flat` without the mesh hierarchy, so
    /// that reports tell the two apart.
    fn name(&self) -> &str {
        match self.config.hierarchy {
            Hierarchy::Flat => "hemi-raster-flat",
            Hierarchy::TwoLevel { .. } => NAME,
        }
    }

    /// Any geometry, any number of objects; Lambert only, per vertex.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            deforming_meshes: true,
            rigid_motion: true,
            multiple_objects: true,
            glossy_brdf: false,
            per_pixel: false,
        }
    }

    /// Checks the scene's needs, builds the plane table (first call only),
    /// decides back-face culling per object and, with
    /// [`Hierarchy::TwoLevel`], builds the coarse meshes and every vertex's
    /// blocker lists.
    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.capabilities().check(NAME, scene)?;
        if self.engine.is_none() {
            self.engine = Some(Engine::new(&self.config)?);
        }
        let cull = scene
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
            } => Some(TwoLevel::new(
                scene,
                coarse_divisor.get(),
                min_coarse_triangles,
                near,
                near_reach,
            )?),
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
        });
        self.frame = None;
        self.blockers = None;
        self.transfer.clear();
        self.irradiance = None;
        Ok(())
    }

    /// Rasterizes every triangle of the frame into every vertex's mask (in
    /// parallel over vertices), then integrates the transfer vectors.
    fn update(&mut self, frame: &FrameGeometry) -> Result<()> {
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
        self.update_frame(frame, None)
    }

    /// Projects the environment to SH (or, for direct integration,
    /// prefilters it to the mask's pixel size and sums it over the stored
    /// masks); visibility is not recomputed.
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.lighting = Some(match self.config.integration {
            Integration::ShBlocks | Integration::ShPixels => {
                Lighting::Sh(sh::project_environment(environment, self.config.order))
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

    /// Lambert: ρ/π · L·T (eq. 2), clamped at zero (SH ringing can dip below
    /// it behind strong blockers).
    fn shade(&mut self, _eye: Vec3) -> Result<VertexRadiance> {
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
        // The irradiance of vertex v, from SH transfer or from direct sums.
        let transfer = &self.transfer;
        let irradiance: Box<dyn Fn(usize) -> Vec3 + '_> = match lighting {
            Lighting::Sh(light) => Box::new(move |v| light.dot(&transfer[v * n..(v + 1) * n])),
            Lighting::Direct(_) => {
                let e = self
                    .irradiance
                    .as_deref()
                    .ok_or_else(|| Error::stage(NAME, "shade before relight"))?;
                Box::new(move |v| e[v])
            }
        };
        let mut first = 0;
        let radiance = frame
            .objects
            .iter()
            .zip(&prepared.materials)
            .map(|(object, material)| {
                let rho = material.diffuse() * FRAC_1_PI;
                let range = first..first + object.vertex_count();
                first = range.end;
                range
                    .map(|v| (rho * irradiance(v)).max(Vec3::ZERO))
                    .collect()
            })
            .collect();
        Ok(VertexRadiance {
            radiance,
            std_error: None,
        })
    }

    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        let frame = self
            .frame
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "render before update"))?;
        shadow_core::raster::render_vertex_colors(camera, frame, &shading.radiance)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{grid, icosphere, projected_solid_angle};
    use glam::Affine3A;
    use shadow_core::{Frame, Mesh, Object, Pose};
    use std::f32::consts::PI;
    use std::sync::Arc;

    fn lambert(rho: f32) -> Brdf {
        Brdf::lambert(Vec3::splat(rho)).unwrap()
    }

    fn camera() -> Camera {
        Camera::new(Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 32, 24).unwrap()
    }

    /// A 0.6 m square at height 0.3 over the centre of a 2 m floor.
    fn floor_and_square(frames: Vec<Frame>) -> Scene {
        let square = Mesh::new(
            "square",
            vec![
                Vec3::new(-0.3, 0.3, -0.3),
                Vec3::new(-0.3, 0.3, 0.3),
                Vec3::new(0.3, 0.3, 0.3),
                Vec3::new(0.3, 0.3, -0.3),
            ],
            None,
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap();
        let objects = vec![
            Object {
                mesh: Arc::new(grid(0.0, 1.0, 8)),
                material: lambert(0.8),
            },
            Object {
                mesh: Arc::new(square),
                material: lambert(0.5),
            },
        ];
        Scene::new("floor and square", objects, frames, camera()).unwrap()
    }

    fn still() -> Vec<Frame> {
        vec![Frame {
            time: 0.0,
            poses: vec![Pose::Rigid(Affine3A::IDENTITY); 2],
        }]
    }

    fn run(method: &mut HemiRaster, scene: &Scene, env: &Environment) -> VertexRadiance {
        method.prepare(scene).unwrap();
        method.update(&scene.frame_geometry(0).unwrap()).unwrap();
        method.relight(env).unwrap();
        method.shade(scene.camera().eye).unwrap()
    }

    /// The white furnace on a closed convex mesh: nothing blocks any vertex's
    /// upper hemisphere, so every vertex reflects its albedo, for every
    /// resolution, integration and culling mode.
    #[test]
    fn white_furnace_on_a_sphere() {
        let scene = Scene::still(
            "sphere",
            vec![Object {
                mesh: Arc::new(icosphere(Vec3::new(0.0, 1.0, 0.0), 0.5, 2)),
                material: lambert(0.7),
            }],
            camera(),
        )
        .unwrap();
        let furnace = Environment::uniform(Vec3::ONE);
        for (mask_resolution, integration, backface_culling) in [
            (
                MaskResolution::R32,
                Integration::ShBlocks,
                BackfaceCulling::Auto,
            ),
            (
                MaskResolution::R16,
                Integration::ShPixels,
                BackfaceCulling::Off,
            ),
            (
                MaskResolution::R64,
                Integration::Direct,
                BackfaceCulling::On,
            ),
        ] {
            let mut method = HemiRaster::new(Config {
                mask_resolution,
                lut_resolution: 32,
                integration,
                backface_culling,
                ..Config::default()
            });
            let shaded = run(&mut method, &scene, &furnace);
            for (v, l) in shaded.flat().enumerate() {
                assert!(
                    (l - Vec3::splat(0.7)).abs().max_element() < 1e-4,
                    "{mask_resolution:?} {integration:?}: vertex {v} reflects {l}"
                );
                assert_eq!(method.blocked_fraction(0, v), Some(0.0));
            }
        }
    }

    #[test]
    fn the_square_shadows_the_floor() {
        let scene = floor_and_square(still());
        let mut method = HemiRaster::default();
        let sky = Environment::uniform(Vec3::ONE);
        let shaded = run(&mut method, &scene, &sky);
        let floor = &shaded.radiance[0];
        // Vertex 40 is the floor's centre (row 4 of 9, column 4), 0 a corner.
        let (centre, corner) = (floor[40], floor[0]);
        assert!(centre.x < 0.6 * corner.x, "{centre} vs {corner}");
        // The corner sees the square low on its horizon: nearly unshadowed.
        assert!((corner.x - 0.8).abs() < 0.01, "{corner}");
        // Under the centre the blocked fraction is the square's form factor.
        let square = [
            Vec3::new(-0.3, -0.3, 0.3),
            Vec3::new(0.3, -0.3, 0.3),
            Vec3::new(0.3, 0.3, 0.3),
            Vec3::new(-0.3, 0.3, 0.3),
        ];
        let form_factor = projected_solid_angle(&square) / PI;
        let blocked = method.blocked_fraction(0, 40).unwrap();
        assert!(
            (blocked - form_factor).abs() < 0.01,
            "{blocked} vs {form_factor}"
        );
        // Uniform sky: the SH shading is ρ(1 − blocked) up to the transfer's
        // quadrature of the blocked part.
        assert!(
            (centre.x - 0.8 * (1.0 - form_factor)).abs() < 0.01,
            "{centre}"
        );
        // The square's top sees the open sky; its underside normal is up too
        // (computed from the winding), so it is unshadowed.
        assert!(shaded.radiance[1].iter().all(|l| (l.x - 0.5).abs() < 0.01));
        // The direct integration agrees.
        let mut direct = HemiRaster::new(Config {
            integration: Integration::Direct,
            ..Config::default()
        });
        let d = run(&mut direct, &scene, &sky);
        assert!((d.radiance[0][40].x - centre.x).abs() < 0.01);
        let image = method.render(&camera()).unwrap();
        assert!(image.covered.iter().any(|&c| c));
    }

    /// `update` recomputes visibility when the square moves away; `relight`
    /// changes lighting without touching visibility.
    #[test]
    fn update_follows_motion_and_relight_keeps_visibility() {
        let away = Affine3A::from_translation(Vec3::new(0.0, 5.0, 0.0));
        let frames = vec![
            still().remove(0),
            Frame {
                time: 1.0,
                poses: vec![Pose::Rigid(Affine3A::IDENTITY), Pose::Rigid(away)],
            },
        ];
        let scene = floor_and_square(frames);
        let mut method = HemiRaster::default();
        let shaded = run(&mut method, &scene, &Environment::uniform(Vec3::ONE));
        let before = shaded.radiance[0][40].x;
        let transfer = method.transfer(0, 40).unwrap().to_vec();
        method
            .relight(&Environment::uniform(Vec3::splat(2.0)))
            .unwrap();
        assert_eq!(method.transfer(0, 40).unwrap(), &transfer[..]);
        let brighter = method.shade(Vec3::ZERO).unwrap().radiance[0][40].x;
        assert!((brighter - 2.0 * before).abs() < 1e-5);
        method.update(&scene.frame_geometry(1).unwrap()).unwrap();
        let after = method.shade(Vec3::ZERO).unwrap().radiance[0][40].x;
        assert!(after > 1.5 * before && after > 1.55, "{before} → {after}");
    }

    #[test]
    fn stages_out_of_order_and_bad_input_are_errors() {
        let scene = floor_and_square(still());
        let frame = scene.frame_geometry(0).unwrap();
        let mut method = HemiRaster::default();
        let stage = |e: Error| matches!(e, Error::Stage { .. });
        assert!(stage(method.update(&frame).unwrap_err()));
        assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
        method.prepare(&scene).unwrap();
        assert!(method.lut_build_time().is_some());
        assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
        assert!(stage(method.render(&camera()).unwrap_err()));
        method.update(&frame).unwrap();
        assert!(stage(method.shade(Vec3::ZERO).unwrap_err()));
        method.relight(&Environment::uniform(Vec3::ONE)).unwrap();
        assert!(method.shade(Vec3::ZERO).is_ok());
        assert!(method.transfer(2, 0).is_none() && method.transfer(1, 4).is_none());
        // A frame of another scene.
        let other = Scene::still(
            "sphere",
            vec![Object {
                mesh: Arc::new(icosphere(Vec3::ZERO, 1.0, 1)),
                material: lambert(0.5),
            }],
            camera(),
        )
        .unwrap();
        let msg = method
            .update(&other.frame_geometry(0).unwrap())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("vertex counts"), "{msg}");
        // Glossy materials are not supported yet.
        let glossy = Scene::still(
            "glossy",
            vec![Object {
                mesh: Arc::new(icosphere(Vec3::ZERO, 1.0, 1)),
                material: Brdf::phong(Vec3::splat(0.3), Vec3::splat(0.3), 20.0).unwrap(),
            }],
            camera(),
        )
        .unwrap();
        assert!(matches!(
            method.prepare(&glossy).unwrap_err(),
            Error::Unsupported { .. }
        ));
        // A table too large to build.
        let mut huge = HemiRaster::new(Config {
            lut_resolution: 100_000,
            ..Config::default()
        });
        assert!(huge.prepare(&scene).is_err());
    }
}
