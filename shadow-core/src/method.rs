//! The `ShadowMethod` trait: the stages every method goes through, so that the
//! harness can drive and time them all the same way (DESIGN.md).

use std::fmt;

use glam::Vec3;

use crate::{Camera, Environment, Error, Export, FrameGeometry, Profile, Result, Scene};

/// Something a method may or may not support.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum Capability {
    /// Meshes that change shape between frames (skinning, morphs, cloth).
    DeformingMeshes,
    /// Objects that move rigidly relative to each other.
    RigidMotion,
    /// Shadows cast between different objects.
    MultipleObjects,
    /// View-dependent (glossy) BRDFs.
    GlossyBrdf,
    /// Shading evaluated per pixel rather than interpolated from vertices.
    PerPixel,
    /// Its raw per-vertex result, relightable without the method
    /// ([`ShadowMethod::export`]).
    Export,
}

impl fmt::Display for Capability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Capability::DeformingMeshes => "deforming meshes",
            Capability::RigidMotion => "rigid motion",
            Capability::MultipleObjects => "shadows between objects",
            Capability::GlossyBrdf => "glossy BRDFs",
            Capability::PerPixel => "per-pixel shading",
            Capability::Export => "export of what it computed",
        })
    }
}

/// The set of capabilities a method has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Capabilities {
    pub deforming_meshes: bool,
    pub rigid_motion: bool,
    pub multiple_objects: bool,
    pub glossy_brdf: bool,
    pub per_pixel: bool,
    pub export: bool,
}

impl Capabilities {
    /// Everything.
    pub const ALL: Capabilities = Capabilities {
        deforming_meshes: true,
        rigid_motion: true,
        multiple_objects: true,
        glossy_brdf: true,
        per_pixel: true,
        export: true,
    };

    pub fn has(&self, capability: Capability) -> bool {
        match capability {
            Capability::DeformingMeshes => self.deforming_meshes,
            Capability::RigidMotion => self.rigid_motion,
            Capability::MultipleObjects => self.multiple_objects,
            Capability::GlossyBrdf => self.glossy_brdf,
            Capability::PerPixel => self.per_pixel,
            Capability::Export => self.export,
        }
    }

    /// The capabilities a scene needs to be shaded per vertex.
    pub fn needed_by(scene: &Scene) -> Vec<Capability> {
        let mut needed = Vec::new();
        if scene.deforms() {
            needed.push(Capability::DeformingMeshes);
        }
        if scene.moves() && !scene.deforms() {
            needed.push(Capability::RigidMotion);
        }
        if scene.objects().len() > 1 {
            needed.push(Capability::MultipleObjects);
        }
        if scene.objects().iter().any(|o| o.material.is_glossy()) {
            needed.push(Capability::GlossyBrdf);
        }
        needed
    }

    /// An [`Error::Unsupported`] naming the first capability `scene` needs that
    /// `method` lacks.
    pub fn check(&self, method: &str, scene: &Scene) -> Result<()> {
        match Capabilities::needed_by(scene)
            .into_iter()
            .find(|c| !self.has(*c))
        {
            None => Ok(()),
            Some(capability) => Err(Error::Unsupported {
                method: method.to_string(),
                capability,
            }),
        }
    }
}

/// Outgoing radiance per vertex of every object (linear RGB), with the standard
/// error of each value when the method is a Monte-Carlo estimate, and which
/// vertices the method evaluated when it skips some (vertices it has not seen
/// yet, say).
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct VertexRadiance {
    /// `radiance[object][vertex]`; zero where not evaluated.
    pub radiance: Vec<Vec<Vec3>>,
    /// `std_error[object][vertex]`, for stochastic methods.
    pub std_error: Option<Vec<Vec<Vec3>>>,
    /// `evaluated[object][vertex]`; `None` when every vertex was.
    pub evaluated: Option<Vec<Vec<bool>>>,
}

impl VertexRadiance {
    /// Every vertex evaluated, no standard errors.
    pub fn new(radiance: Vec<Vec<Vec3>>) -> VertexRadiance {
        VertexRadiance {
            radiance,
            std_error: None,
            evaluated: None,
        }
    }

    /// Every vertex value, objects one after another.
    pub fn flat(&self) -> impl Iterator<Item = Vec3> + '_ {
        self.radiance.iter().flatten().copied()
    }

    /// Whether each vertex was evaluated, objects one after another.
    pub fn flat_evaluated(&self) -> impl Iterator<Item = bool> + '_ {
        let all = self.evaluated.is_none();
        let counts = self.radiance.iter().map(Vec::len);
        counts.enumerate().flat_map(move |(o, n)| {
            (0..n).map(move |v| all || self.evaluated.as_ref().is_some_and(|e| e[o][v]))
        })
    }
}

/// An image of outgoing radiance, row 0 at the top, with the pixels a surface
/// covers (the others are background and are not scored).
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
    pub covered: Vec<bool>,
    pub std_error: Option<Vec<Vec3>>,
}

/// A method for shading dynamic objects with soft shadows from distant
/// environment lighting, driven through the stages of DESIGN.md.
///
/// Stages are called in order: `prepare` once per scene; `relight` whenever
/// the lighting changes; for each frame `update`; then `shade` or `render` as
/// often as views change. A stage called before the ones it needs returns
/// [`Error::Stage`].
///
/// # Time
///
/// When a stage returns, its work is done: a GPU method has waited until its
/// queue is idle, so that the wall clock around a stage measures the stage.
/// Time per frame is defined per domain: update + shade for per-vertex
/// results, update + render for images; relighting is timed apart. GPU
/// methods also let a host renderer record the same work into its own command
/// encoder without waiting (`shadow_core::gpu::GpuStages`, feature `gpu`).
pub trait ShadowMethod: Send {
    /// A short stable name used in reports and on the command line.
    fn name(&self) -> &str;

    fn capabilities(&self) -> Capabilities;

    /// Once per scene: precomputation, tables, GPU pipelines. Fails with
    /// [`Error::Unsupported`] if the scene needs a capability the method lacks.
    fn prepare(&mut self, scene: &Scene) -> Result<()>;

    /// Lighting changed: redo what depends on the lighting (projections,
    /// light-dependent maps) and nothing else; visibility that does not
    /// depend on the lighting is never recomputed here.
    fn relight(&mut self, environment: &Environment) -> Result<()>;

    /// Geometry changed: recompute visibility or transfer for this frame,
    /// seen by `camera` (methods that skip what the camera does not see use
    /// it; others ignore it).
    fn update(&mut self, frame: &FrameGeometry, camera: &Camera) -> Result<()>;

    /// Outgoing radiance toward `eye` at the vertices of the current frame,
    /// saying which it evaluated if not all.
    fn shade(&mut self, eye: Vec3) -> Result<VertexRadiance>;

    /// An image of the current frame.
    fn render(&mut self, camera: &Camera) -> Result<Image>;

    /// Where the most recent call of each stage spent its time, as the method
    /// measured it; empty for methods that do not break their stages down.
    fn profile(&self) -> Profile {
        Profile::default()
    }

    /// The raw result of the current frame, relightable without the method
    /// (SH transfer vectors, or visibility over directions). Fails with
    /// [`Error::Unsupported`] ([`Capability::Export`]) for methods that have
    /// none.
    fn export(&self) -> Result<Export> {
        Err(Error::Unsupported {
            method: self.name().to_string(),
            capability: Capability::Export,
        })
    }
}
