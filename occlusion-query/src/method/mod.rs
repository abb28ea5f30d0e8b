//! [`OcclusionQuery`]: the method driven through the [`ShadowMethod`] stages,
//! and recorded into a host's encoder through [`GpuStages`].

mod prepare;
mod relight;
mod update;

use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat3, Mat4, Vec3, Vec4};
use shadow_core::gpu::{GpuContext, GpuStages};
use shadow_core::{
    Camera, Capabilities, Capability, DirectionalVisibility, Environment, Error, Export,
    FrameGeometry, Image, Mesh, Profile, Result, Scene, ShadowMethod, Stage, VertexRadiance,
};

use crate::config::{Config, Normalization};
use crate::filter::CameraFilter;
use crate::lightsphere::{Level, Lightsphere};
use crate::name::NAME;
use crate::shading::Shading;
use crate::views::GpuDirection;
use crate::visibility::{Geometry, TestOffset, Visibility};
use relight::rotation_of;

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
    /// Every region's map view of every direction, the tested vertices'
    /// offset, and each vertex's region.
    views: Vec<GpuDirection>,
    offset: TestOffset,
    vertex_regions: Vec<u32>,
    /// Each vertex's contact push ([`Visibility::set_contacts`]).
    push: Vec<Vec4>,
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

    /// Where the depth map that vertex `vertex` (all objects one after
    /// another) is tested against for direction `j` looks from in the
    /// current frame: model space (world space unless the scene is one rigid
    /// object) to the map's clip space, and the point the vertex is
    /// compared at, moved by the offsets. `None` before `update`, beyond the
    /// finest level or the vertex count.
    pub fn map_view(&self, vertex: usize, j: usize) -> Option<(Mat4, Vec3)> {
        let state = self.state.as_ref()?;
        let region = *state.vertex_regions.get(vertex)? as usize;
        if j >= state.offset.stride as usize {
            return None;
        }
        let view = state.views.get(region * state.offset.stride as usize + j)?;
        let (p, n) = (state.positions[vertex], state.normals[vertex]);
        let (light, texel) = (view.light.truncate(), view.light.w);
        let push = state.push[vertex];
        let moved = (state.offset).moved(p.truncate(), n.truncate(), light, texel, push);
        Some((view.clip_from_world, moved))
    }

    /// How many regions the current frame's maps are fitted to
    /// ([`crate::views::Regions`]); `None` before `update`.
    pub fn regions(&self) -> Option<usize> {
        let state = self.state.as_ref()?;
        Some(state.views.len() / (state.offset.stride as usize).max(1))
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
        let frame = self.state.as_ref().map(|state| &state.frame);
        shadow_core::raster::render_shading(NAME, camera, frame, &shading)
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
