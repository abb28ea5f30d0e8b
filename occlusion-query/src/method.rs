//! [`OcclusionQuery`]: the method driven through the [`ShadowMethod`] stages,
//! and recorded into a host's encoder through [`GpuStages`].

use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Mat4, Vec3, Vec4};
use shadow_core::gpu::{GpuContext, GpuStages};
use shadow_core::{
    Brdf, Camera, Capabilities, Capability, DirectionalVisibility, Environment, Error, Export,
    FrameGeometry, Image, Mesh, Pose, Profile, Result, Scene, ShadowMethod, Stage, VertexRadiance,
};

use crate::config::{Config, DepthOffset, Normalization, Occluder};
use crate::filter::{CameraFilter, vertices_of};
use crate::lightsphere::{Level, Lightsphere};
use crate::name::NAME;
use crate::occluder;
use crate::shading::Shading;
use crate::views::{self, GpuDirection};
use crate::visibility::{Counts, Geometry, TestOffset, Visibility};

/// Sattler, Sarlette, Zachmann and Klein 2004 on wgpu: per vertex, binary
/// visibility toward the k directions of a lightsphere, from depth maps of
/// the scene rendered along each direction (every object occludes, Fig. 8),
/// kept on the GPU as one bit per vertex and direction; shading sums the
/// visible directions' radiance from the prefiltered environment, weighted
/// by solid angle, cosine and BRDF (§3.3, §5).
///
/// # Geometry over frames (§6, §4)
///
/// A scene of one object whose every pose is a rotation, uniform scale and
/// translation of its mesh keeps the visibility of its first update in model
/// space: later frames only turn the light directions' look-ups. Any other
/// scene recomputes the visibility whenever the geometry changes. When it
/// does not change between updates, `idle_level` refines the lightsphere a
/// level per update, reusing the coarser levels' bits (§4.2). With
/// `filtering`, only vertices of triangles the camera has seen are
/// evaluated (§4.1); `shade` marks the others as not evaluated.
pub struct OcclusionQuery {
    name: String,
    config: Config,
    ctx: Arc<GpuContext>,
    /// Every level up to the finest: each level's directions are a prefix of
    /// the finest's, but its weights are its own.
    spheres: Vec<Lightsphere>,
    scene: Option<Prepared>,
    state: Option<State>,
    environment: Option<Environment>,
    /// Environments prefiltered for a level, kept while the lighting holds.
    prefiltered: Vec<(Level, Environment)>,
    profile: Profile,
}

/// What `prepare` found out about the scene, and its GPU resources.
struct Prepared {
    vertex_counts: Vec<usize>,
    /// Every triangle, as indices into all objects' vertices.
    triangles: Vec<u32>,
    /// The vertices of no triangle: the camera never sees them, so vertex
    /// filtering evaluates them with the first update of a geometry.
    loose: Vec<u32>,
    /// The model-space mesh of a scene of one object moving rigidly (§6):
    /// uploaded once, its visibility turned with it.
    model: Option<Arc<Mesh>>,
    /// How far the simplified occluders' surfaces may lie from the meshes'
    /// (0 for full occluders): tested vertices move that much further along
    /// their normals, out of the coarse surface.
    simplification: f32,
    gpu: Gpu,
}

struct Gpu {
    geometry: Geometry,
    visibility: Visibility,
    shading: Shading,
    filter: Option<CameraFilter>,
}

/// The frame the visibility belongs to.
struct State {
    /// The frame in world space (for `render` and `export`).
    frame: FrameGeometry,
    /// Model to world for the rigid case, identity otherwise.
    transform: Affine3A,
    /// What was uploaded, to tell a changed frame from the same one.
    positions: Vec<Vec4>,
    /// Every direction's map view, and the tested vertices' offset.
    views: Vec<GpuDirection>,
    offset: TestOffset,
    normals: Vec<Vec4>,
    /// The level every evaluated vertex has its visibility at.
    level: Level,
    evaluated: Vec<bool>,
    /// The level and rotation the incoming radiance was looked up for.
    lit: Option<(Level, Mat3)>,
}

/// Vertices to test against a range of directions.
struct Job {
    list: Vec<u32>,
    directions: Range<usize>,
}

impl OcclusionQuery {
    /// The method on `ctx`'s device (shared with other methods, or a host
    /// renderer's), with `config`; fails with [`Error::InvalidConfig`] for
    /// settings out of range.
    pub fn new(ctx: Arc<GpuContext>, config: Config) -> Result<OcclusionQuery> {
        config.check()?;
        let name = config.name();
        Ok(OcclusionQuery {
            name,
            spheres: (0..=config.finest().get())
                .filter_map(Level::new)
                .map(|level| Lightsphere::new(level, config.weights, config.orientation))
                .collect(),
            config,
            ctx,
            scene: None,
            state: None,
            environment: None,
            prefiltered: Vec::new(),
            profile: Profile::default(),
        })
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The lightsphere of `level` (at most the configuration's finest).
    fn sphere(&self, level: Level) -> &Lightsphere {
        &self.spheres[level.get() as usize]
    }

    fn finest(&self) -> &Lightsphere {
        self.sphere(self.config.finest())
    }

    /// Where direction `j`'s depth map looks from in the current frame:
    /// model space (world space unless the scene is one rigid object) to the
    /// map's clip space, and how far each tested vertex moves before it is
    /// compared. `None` before `update` or beyond the finest level.
    pub fn map_view(&self, j: usize) -> Option<(Mat4, TestOffset)> {
        let state = self.state.as_ref()?;
        let view = state.views.get(j)?;
        Some((view.clip_from_world, state.offset))
    }

    /// The lightsphere level the current visibility is at.
    pub fn level(&self) -> Option<Level> {
        self.state.as_ref().map(|s| s.level)
    }

    fn prepared(&self) -> Result<&Prepared> {
        self.scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "update before prepare"))
    }

    /// The positions and normals to upload for `frame` (model space when
    /// rigid), and its model-to-world transform.
    fn geometry_of(
        frame: &FrameGeometry,
        scene: &Prepared,
    ) -> Result<(Vec<Vec4>, Vec<Vec4>, Affine3A)> {
        let counts: Vec<usize> = frame.objects.iter().map(|o| o.vertex_count()).collect();
        if counts != scene.vertex_counts {
            return Err(Error::InvalidScene(format!(
                "{NAME}: frame {} has vertex counts {counts:?} per object, the prepared scene {:?}",
                frame.frame, scene.vertex_counts
            )));
        }
        let meshes: Vec<&Mesh> = match &scene.model {
            Some(model) => vec![model],
            None => frame.objects.iter().map(|o| &*o.mesh).collect(),
        };
        let positions = meshes
            .iter()
            .flat_map(|m| m.positions())
            .map(|p| p.extend(1.0));
        let normals = meshes
            .iter()
            .flat_map(|m| m.normals())
            .map(|n| n.extend(0.0));
        let transform = match &scene.model {
            Some(_) => frame.objects[0].transform.unwrap_or(Affine3A::IDENTITY),
            None => Affine3A::IDENTITY,
        };
        Ok((positions.collect(), normals.collect(), transform))
    }

    /// Brings the state to `frame` (uploads, lists) and says which vertices
    /// to test against which directions. With filtering, runs the camera
    /// pass, which reads query results back.
    fn plan(&mut self, frame: &FrameGeometry, camera: &Camera) -> Result<Vec<Job>> {
        let scene = self.prepared()?;
        let (positions, normals, transform) = Self::geometry_of(frame, scene)?;
        let vertices = positions.len();
        let changed = match &self.state {
            None => true,
            // The rigid object's model-space mesh never changes.
            Some(_) if scene.model.is_some() => false,
            Some(state) => state.positions != positions || state.normals != normals,
        };
        let ctx = Arc::clone(&self.ctx);
        let scene = self.scene.as_mut().expect("checked above");
        let mut jobs = Vec::new();
        if changed {
            let (centre, radius) = bounding_sphere(&positions);
            let finest = &self.spheres[self.config.finest().get() as usize];
            let (directions, offset) =
                fitted(finest, centre, radius, &self.config, scene.simplification);
            scene.gpu.geometry.write(&ctx, &positions, &normals);
            scene.gpu.visibility.set_view(&ctx, &directions, offset);
            if let Some(filter) = &mut scene.gpu.filter {
                filter.reset();
            }
            let level = self.config.level;
            self.state = Some(State {
                frame: frame.clone(),
                transform,
                positions,
                normals,
                views: directions,
                offset,
                level,
                evaluated: vec![scene.gpu.filter.is_none(); vertices],
                lit: None,
            });
            let state = self.state.as_mut().expect("set above");
            let list = match scene.gpu.filter {
                None => (0..vertices as u32).collect(),
                Some(_) => scene.loose.clone(),
            };
            for &v in &list {
                state.evaluated[v as usize] = true;
            }
            if !list.is_empty() {
                jobs.push(Job {
                    list,
                    directions: 0..level.directions(),
                });
            }
        } else {
            let state = self.state.as_mut().expect("not changed, so present");
            state.frame = frame.clone();
            state.transform = transform;
            let idle = self.config.idle_level.filter(|&idle| idle > state.level);
            if let Some(finer) = idle.and_then(|_| state.level.finer()) {
                let list: Vec<u32> = (0..vertices as u32)
                    .filter(|&v| state.evaluated[v as usize])
                    .collect();
                jobs.push(Job {
                    list,
                    directions: state.level.directions()..finer.directions(),
                });
                state.level = finer;
            }
        }
        let state = self.state.as_mut().expect("set above");
        if let (Some(filter), Some(filtering)) = (&mut scene.gpu.filter, self.config.filtering) {
            let model = Mat4::from(state.transform);
            let start = Instant::now();
            let seen = filter.newly_seen(
                &ctx,
                &scene.gpu.geometry,
                camera,
                model,
                filtering.threshold,
            )?;
            let touched = vertices_of(&seen, &scene.triangles, vertices);
            let list: Vec<u32> = (0..vertices as u32)
                .filter(|&v| touched[v as usize] && !state.evaluated[v as usize])
                .collect();
            for &v in &list {
                state.evaluated[v as usize] = true;
            }
            self.profile.seconds(
                Stage::Update,
                "camera queries",
                start.elapsed().as_secs_f64(),
            );
            self.profile
                .count(Stage::Update, "triangles unseen", filter.remaining() as u64);
            if !list.is_empty() {
                jobs.push(Job {
                    list,
                    directions: 0..state.level.directions(),
                });
            }
        }
        scene.gpu.shading.set_evaluated(&ctx, &state.evaluated);
        Ok(jobs)
    }

    /// The width of the Gaussian the environment is blurred with for
    /// `level` (§5): `prefilter` times the level's spacing √(4π/k).
    fn sigma(&self, level: Level) -> f32 {
        let k = level.directions() as f32;
        self.config.prefilter * (4.0 * std::f32::consts::PI / k).sqrt()
    }

    /// Looks up the radiance arriving from each direction of the current
    /// level, turned by the rigid object's rotation, when either changed.
    fn light(&mut self) -> Result<()> {
        let (Some(state), Some(env), Some(scene)) = (&self.state, &self.environment, &self.scene)
        else {
            return Ok(());
        };
        let rotation = rotation_of(state.transform);
        let wanted = (state.level, rotation);
        if state.lit == Some(wanted) {
            return Ok(());
        }
        let level = state.level;
        let start = Instant::now();
        let sigma = self.sigma(level);
        if !self.prefiltered.iter().any(|(l, _)| *l == level) {
            self.prefiltered.push((level, env.prefiltered(sigma)));
        }
        let map = &self
            .prefiltered
            .iter()
            .find(|(l, _)| *l == level)
            .expect("added above")
            .1;
        let sphere = self.sphere(level);
        let incoming: Vec<Vec3> = sphere
            .directions()
            .iter()
            .map(|&l| map.lookup(rotation * l))
            .collect();
        scene
            .gpu
            .shading
            .set_incoming(&self.ctx, &incoming, sphere.weights());
        self.profile
            .seconds(Stage::Relight, "look-ups", start.elapsed().as_secs_f64());
        self.state.as_mut().expect("present").lit = Some(wanted);
        Ok(())
    }

    /// Records `jobs` into `encoder`, or, with `timed`, runs each batch's
    /// maps and tests as their own blocking submissions and profiles them.
    fn run_jobs(
        &mut self,
        jobs: Vec<Job>,
        mut encoder: Option<&mut wgpu::CommandEncoder>,
    ) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        let gpu = &mut self.scene.as_mut().expect("planned").gpu;
        let (mut maps_seconds, mut tests_seconds, mut counts) = (0.0, 0.0, Counts::default());
        for job in jobs {
            gpu.visibility.set_list(&ctx, &job.list);
            for (index, batch) in gpu
                .visibility
                .batches(job.directions)
                .into_iter()
                .enumerate()
            {
                let (visibility, geometry) = (&gpu.visibility, &gpu.geometry);
                let (maps, tests) = match encoder.as_deref_mut() {
                    Some(encoder) => (
                        visibility.record_maps(encoder, geometry, batch.clone()),
                        visibility.record_tests(&ctx, encoder, geometry, batch, index)?,
                    ),
                    None => {
                        let start = Instant::now();
                        let maps = ctx.run("occlusion-query: depth maps", |encoder| {
                            Ok(visibility.record_maps(encoder, geometry, batch.clone()))
                        })?;
                        let middle = Instant::now();
                        let tests = ctx.run("occlusion-query: vertex tests", |encoder| {
                            visibility.record_tests(&ctx, encoder, geometry, batch, index)
                        })?;
                        maps_seconds += (middle - start).as_secs_f64();
                        tests_seconds += middle.elapsed().as_secs_f64();
                        (maps, tests)
                    }
                };
                counts.maps += maps.maps;
                counts.tests += tests.tests;
            }
        }
        if encoder.is_none() {
            self.profile
                .seconds(Stage::Update, "depth maps", maps_seconds);
            self.profile
                .seconds(Stage::Update, "vertex tests", tests_seconds);
        }
        self.profile
            .count(Stage::Update, "maps rendered", counts.maps);
        self.profile
            .count(Stage::Update, "vertex-direction tests", counts.tests);
        Ok(())
    }

    /// The eye in the space of the uploaded positions.
    fn model_eye(&self, eye: Vec3) -> Result<Vec3> {
        if !eye.is_finite() {
            return Err(Error::InvalidScene(format!(
                "{NAME}: eye position {eye} is not finite"
            )));
        }
        let state = self
            .state
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before update"))?;
        Ok(state.transform.inverse().transform_point3(eye))
    }

    fn record_shading(&self, encoder: &mut wgpu::CommandEncoder, eye: Vec3) -> Result<()> {
        let scene = self.prepared()?;
        let state = self
            .state
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before update"))?;
        if state.lit.is_none() {
            return Err(Error::stage(NAME, "shade before relight"));
        }
        let gpu = &scene.gpu;
        gpu.shading.record(
            &self.ctx,
            encoder,
            state.level.directions(),
            gpu.visibility.words(),
            self.config.normalization == Normalization::PerVertex,
            eye,
        );
        Ok(())
    }

    /// Checks the scene and builds the GPU resources for it.
    fn prepare_scene(&mut self, scene: &Scene) -> Result<Prepared> {
        self.capabilities().check(NAME, scene)?;
        let model = is_rigid(scene).then(|| Arc::clone(&scene.objects()[0].mesh));
        let mut triangles = Vec::new();
        let mut occluders = Vec::new();
        let mut objects = Vec::new();
        // The depth maps' texel at the first frame, for how far simplified
        // occluders may deviate.
        let first_frame = scene.frame_geometry(0)?;
        let meshes: Vec<&Mesh> = match &model {
            Some(model) => vec![model],
            None => first_frame.objects.iter().map(|o| &*o.mesh).collect(),
        };
        let points: Vec<Vec4> = meshes
            .iter()
            .flat_map(|m| m.positions())
            .map(|p| p.extend(1.0))
            .collect();
        let texel = 2.0 * 1.01 * bounding_sphere(&points).1 / self.config.map_resolution as f32;
        let mut first = 0u32;
        let mut simplification = 0.0f32;
        for (o, object) in scene.objects().iter().enumerate() {
            let mesh = &object.mesh;
            triangles.extend(mesh.triangles().iter().flatten().map(|&v| v + first));
            let drawn = match self.config.occluder {
                Occluder::Full => mesh.triangles().to_vec(),
                Occluder::Simplified { texels } => {
                    let simplified = occluder::simplified(mesh, texels * texel)?;
                    simplification = simplification.max(simplified.error);
                    simplified.triangles
                }
            };
            let drawn = meshopt::optimize_vertex_cache(drawn.as_flattened(), mesh.vertex_count());
            occluders.extend(drawn.iter().map(|&v| v + first));
            objects.extend(std::iter::repeat_n(o as u32, mesh.vertex_count()));
            first += mesh.vertex_count() as u32;
        }
        let vertices = first as usize;
        let every_triangle: Vec<u32> = (0..(triangles.len() / 3) as u32).collect();
        let in_triangle = vertices_of(&every_triangle, &triangles, vertices);
        let zeros = vec![Vec4::ZERO; vertices];
        let ctx = &self.ctx;
        let k = self.finest().len();
        let config = &self.config;
        let materials: Vec<Brdf> = scene.objects().iter().map(|o| o.material).collect();
        let gpu = ctx.capture("occlusion-query: prepare", || {
            let geometry = Geometry::new(ctx, &zeros, &zeros, &occluders);
            let visibility = Visibility::new(ctx, config, &geometry, k)?;
            let shading = Shading::new(
                ctx,
                &geometry,
                &visibility,
                visibility.directions(),
                &materials,
                objects,
                k,
            );
            let filter = config.filtering.map(|_| CameraFilter::new(ctx, &triangles));
            Ok(Gpu {
                geometry,
                visibility,
                shading,
                filter,
            })
        })?;
        self.profile.count(
            Stage::Prepare,
            "occluder triangles",
            (occluders.len() / 3) as u64,
        );
        Ok(Prepared {
            vertex_counts: scene
                .objects()
                .iter()
                .map(|o| o.mesh.vertex_count())
                .collect(),
            triangles,
            loose: (0..vertices as u32)
                .filter(|&v| !in_triangle[v as usize])
                .collect(),
            model,
            simplification,
            gpu,
        })
    }
}

/// A scene of one object whose every pose is rigid without shear or
/// non-uniform scale: its visibility turns with it (§6).
fn is_rigid(scene: &Scene) -> bool {
    scene.objects().len() == 1
        && scene.frames().iter().all(|f| match &f.poses[0] {
            Pose::Rigid(t) => is_similarity(t.matrix3.into()),
            Pose::Deformed { .. } => false,
        })
}

/// Whether `m` is a rotation times a positive uniform scale.
fn is_similarity(m: Mat3) -> bool {
    let scale = m.x_axis.length();
    let mtm = m.transpose() * m;
    scale > 0.0
        && m.determinant() > 0.0
        && mtm.abs_diff_eq(
            Mat3::from_diagonal(Vec3::splat(scale * scale)),
            1e-4 * scale * scale,
        )
}

/// The rotation part of a similarity transform.
fn rotation_of(transform: Affine3A) -> Mat3 {
    let m: Mat3 = transform.matrix3.into();
    let scale = m.x_axis.length();
    if scale > 0.0 {
        m * (1.0 / scale)
    } else {
        Mat3::IDENTITY
    }
}

/// A sphere holding every point: the centre of their bounds, and the largest
/// distance from it.
fn bounding_sphere(positions: &[Vec4]) -> (Vec3, f32) {
    let points = positions.iter().map(|p| p.truncate());
    let bounds = shadow_core::Aabb::from_points(points.clone());
    let centre = bounds.center();
    let radius = points.map(|p| p.distance(centre)).fold(0.0f32, f32::max);
    (centre, radius.max(1e-6))
}

/// Every direction's view of the sphere (`centre`, `radius`), grown so that
/// the tested vertices, once moved by their offsets, stay inside the view
/// volume (where the paper's queries are reliable), and those offsets in
/// world units; `simplification` adds to the move along the normal.
fn fitted(
    sphere: &Lightsphere,
    centre: Vec3,
    radius: f32,
    config: &Config,
    simplification: f32,
) -> (Vec<GpuDirection>, TestOffset) {
    let inner = radius * 1.01;
    let texel = 2.0 * inner / config.map_resolution as f32;
    let offset = TestOffset {
        toward_light: config.offset.toward_light * texel,
        along_normal: config.offset.along_normal * texel + simplification,
        slope: config.offset.receiver_slope * texel,
        max_tan: DepthOffset::MAX_TAN,
    };
    let outer = inner + offset.toward_light + offset.slope * offset.max_tan + offset.along_normal;
    (views::directions(sphere, centre, outer), offset)
}

impl ShadowMethod for OcclusionQuery {
    fn name(&self) -> &str {
        &self.name
    }

    /// Any geometry and any number of objects, Lambert and Phong, per
    /// vertex; its export is the visibility over the lightsphere.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            per_pixel: false,
            ..Capabilities::ALL
        }
    }

    /// Checks the scene, simplifies the occluders if asked, and builds the
    /// pipelines and buffers (the lightsphere is built by [`OcclusionQuery::new`]).
    fn prepare(&mut self, scene: &Scene) -> Result<()> {
        self.scene = None;
        self.state = None;
        self.profile = Profile::default();
        let start = Instant::now();
        let prepared = self.prepare_scene(scene)?;
        self.profile.seconds(
            Stage::Prepare,
            "pipelines and buffers",
            start.elapsed().as_secs_f64(),
        );
        self.scene = Some(prepared);
        Ok(())
    }

    /// Keeps the environment; the look-ups along the directions are redone
    /// (visibility is not).
    fn relight(&mut self, environment: &Environment) -> Result<()> {
        self.profile.begin(Stage::Relight);
        self.environment = Some(environment.clone());
        self.prefiltered.clear();
        if let Some(state) = &mut self.state {
            state.lit = None;
        }
        self.light()
    }

    fn update(&mut self, frame: &FrameGeometry, camera: &Camera) -> Result<()> {
        self.profile.begin(Stage::Update);
        let start = Instant::now();
        let jobs = self.plan(frame, camera)?;
        let camera_queries = self
            .profile
            .seconds_in(Stage::Update, "camera queries")
            .unwrap_or(0.0);
        self.profile.seconds(
            Stage::Update,
            "planning and uploads",
            start.elapsed().as_secs_f64() - camera_queries,
        );
        self.run_jobs(jobs, None)?;
        self.light()
    }

    /// Radiance toward `eye` at every evaluated vertex; others are zero and
    /// marked as not evaluated.
    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance> {
        self.profile.begin(Stage::Shade);
        let model_eye = self.model_eye(eye)?;
        let start = Instant::now();
        let ctx = Arc::clone(&self.ctx);
        ctx.run("occlusion-query: shade", |encoder| {
            self.record_shading(encoder, model_eye)
        })?;
        let middle = Instant::now();
        let scene = self
            .scene
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "shade before prepare"))?;
        let vertices = scene.gpu.geometry.vertices;
        let values: Vec<[f32; 4]> = ctx.read_buffer(scene.gpu.shading.radiance(), 0, vertices)?;
        self.profile
            .seconds(Stage::Shade, "shading", (middle - start).as_secs_f64());
        self.profile
            .seconds(Stage::Shade, "read-back", middle.elapsed().as_secs_f64());
        let mut values = values.into_iter();
        let (mut radiance, mut evaluated) = (Vec::new(), Vec::new());
        for &n in &scene.vertex_counts {
            let part: Vec<[f32; 4]> = values.by_ref().take(n).collect();
            radiance.push(part.iter().map(|v| Vec3::new(v[0], v[1], v[2])).collect());
            evaluated.push(part.iter().map(|v| v[3] > 0.5).collect::<Vec<bool>>());
        }
        let all = evaluated.iter().flatten().all(|e| *e);
        Ok(VertexRadiance {
            radiance,
            std_error: None,
            evaluated: (!all).then_some(evaluated),
        })
    }

    /// The shaded vertices interpolated over the visible triangles
    /// (shadow-core's rasterizer).
    fn render(&mut self, camera: &Camera) -> Result<Image> {
        let shading = self.shade(camera.eye)?;
        let state = self
            .state
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "render before update"))?;
        shadow_core::raster::render_vertex_colors(camera, &state.frame, &shading.radiance)
    }

    fn profile(&self) -> Profile {
        self.profile.clone()
    }

    /// The visibility of the current level in world space: directions,
    /// weights, normals and one bit per vertex and direction (set where the
    /// vertex sees the light and faces it). Vertices not evaluated have no
    /// bit set.
    fn export(&self) -> Result<Export> {
        let scene = self.prepared()?;
        let state = self
            .state
            .as_ref()
            .ok_or_else(|| Error::stage(NAME, "export before update"))?;
        let k = state.level.directions();
        let words = scene.gpu.visibility.words() as usize;
        let vertices = scene.gpu.geometry.vertices;
        let bits: Vec<u32> =
            self.ctx
                .read_buffer(scene.gpu.visibility.bits(), 0, vertices * words)?;
        let per_vertex = k.div_ceil(64);
        let mut visible = vec![0u64; vertices * per_vertex];
        for v in 0..vertices {
            if !state.evaluated[v] {
                continue;
            }
            for j in 0..k {
                if bits[v * words + j / 32] >> (j % 32) & 1 == 1 {
                    visible[v * per_vertex + j / 64] |= 1 << (j % 64);
                }
            }
        }
        let rotation = rotation_of(state.transform);
        let sphere = self.sphere(state.level);
        let directions = sphere.directions().iter().map(|&l| rotation * l).collect();
        let normals = state
            .frame
            .objects
            .iter()
            .flat_map(|o| o.normals().to_vec())
            .collect();
        let mut exported = DirectionalVisibility::new(
            directions,
            sphere.weights().to_vec(),
            scene.vertex_counts.clone(),
            normals,
            visible,
        )?;
        exported.cosine_normalized = self.config.normalization == Normalization::PerVertex;
        exported.prefilter = self.sigma(state.level);
        Ok(Export::Visibility(exported))
    }
}

/// Recording into a host's encoder: the shading's parameters (the eye) are
/// copied inside the encoder, so several shadings recorded into one encoder
/// each read their own; the uploads of an update (geometry, vertex lists,
/// map views) and of the lighting (incoming radiance, weights) are written
/// to the queue and land before the whole submission, so record at most one
/// update and one relight per submission, before the shadings.
impl GpuStages for OcclusionQuery {
    fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The look-ups along the directions are written for the next
    /// submission; nothing is recorded.
    fn record_relight(
        &mut self,
        environment: &Environment,
        _encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        ShadowMethod::relight(self, environment)
    }

    /// The depth maps and vertex tests, into `encoder`. Vertex filtering
    /// reads the camera's query results back on the CPU, so it cannot be
    /// recorded: an [`Error::InvalidConfig`].
    fn record_update(
        &mut self,
        frame: &FrameGeometry,
        camera: &Camera,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        if self.config.filtering.is_some() {
            return Err(Error::config(
                NAME,
                "vertex filtering reads query results back on the CPU: it cannot be recorded into a caller's encoder",
            ));
        }
        self.profile.begin(Stage::Update);
        let jobs = self.plan(frame, camera)?;
        self.run_jobs(jobs, Some(encoder))?;
        self.light()
    }

    fn record_shade(
        &mut self,
        eye: Vec3,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Buffer> {
        let eye = self.model_eye(eye)?;
        self.record_shading(encoder, eye)?;
        Ok(self.prepared()?.gpu.shading.radiance())
    }

    /// A per-vertex method: the host draws [`GpuStages::record_shade`]'s
    /// buffer as vertex colours.
    fn record_render(
        &mut self,
        _camera: &Camera,
        _encoder: &mut wgpu::CommandEncoder,
    ) -> Result<&wgpu::Texture> {
        Err(Error::Unsupported {
            method: self.name.clone(),
            capability: Capability::PerPixel,
        })
    }
}
