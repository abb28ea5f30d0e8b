//! The method's settings: plain values, validated by [`Config::check`].

use shadow_core::{Error, Result};

use crate::{
    lightsphere::{Level, Orientation, Weights},
    name::NAME,
};

/// How each vertex is tested against a direction's depth map (§3.1–3.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VertexTest {
    /// A compute pass reads every vertex's depth-map texel and compares
    /// (the paper's future work, §8.1): results stay on the GPU.
    #[default]
    DepthCompare,
    /// The paper's test: every vertex drawn as a point with its own
    /// occlusion query, 4096 queries per render pass; the sample counts are
    /// resolved into a GPU buffer and turned into visibility bits there.
    OcclusionQuery,
}

/// Whether each vertex's sum over directions is divided by its own
/// quadrature of the cosine.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Normalization {
    /// c_i is scaled by π / Σ_j w_j max(0, n_i·l_j), the quadrature's
    /// integral of the clamped cosine: an unoccluded vertex under uniform
    /// light gets exactly ρ at every level. At k = 6 a normal along an axis
    /// sees one direction (the quadrature gives 4π/6 ≈ 2.09 for π), at k = 258
    /// the quadrature is within about 1% everywhere; the scaling removes that
    /// error, which would otherwise depend on the normal.
    #[default]
    PerVertex,
    /// The raw quadrature Σ_j w_j M_ij I_j, as the paper sums it.
    Off,
}

/// The depth offset between an occluder's depth map and the vertices tested
/// against it (§3.2: the paper used `glPolygonOffset(1, 1)`).
///
/// Without one, a vertex is hidden by its own surface (acne): a map texel
/// holds the depth at its centre, up to half a diagonal from the vertex
/// along the surface, which is 0.71 texel × tan θ deeper or shallower along
/// the light (θ between the surface normal and the light). The offset has
/// the polygon offset's terms on the occluders' side, as WebGPU's depth bias
/// gives them, and moves of the tested vertices, which WebGPU has no bias
/// for (point lists get none):
///
/// * `occluder_slope`, the polygon offset's *factor*: the occluders' depth
///   moves away from the light by this many times their depth slope (depth
///   per texel of the map), at most `occluder_clamp` texels of depth (0:
///   unbounded, as in OpenGL). An occluder seen edge-on gets a large bias,
///   so without a bound a vertex close under it sees through it.
/// * `occluder_units`, the polygon offset's *units*: the occluders' depth
///   moves by this many steps of the depth buffer's resolution. The maps are
///   32-bit float, whose step is 2^(e − 23) for a triangle whose largest
///   depth has exponent e (Vulkan's rule): 6·10⁻⁸ to 1.2·10⁻⁷ of the depth
///   range over its far half, about the step of the paper's 24-bit buffer
///   (6·10⁻⁸). A unit is 10⁻⁵ to 10⁻⁴ of a texel: it matters only where the
///   slope term is zero.
/// * `receiver_slope`: the tested vertex moves toward the light by this many
///   texels times its own tan θ (tan θ at most [`DepthOffset::MAX_TAN`]):
///   the factor, from the receiver's side, which is the surface that causes
///   the acne.
/// * `toward_light`: a constant move of the tested vertex toward the light,
///   in texels.
/// * `along_normal`: a move off the vertex's own surface along its normal,
///   in texels, which keeps it out of that surface at 0.71 texel whatever
///   the angle, but lifts it through any surface closer than that (a
///   contact).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthOffset {
    pub occluder_slope: f32,
    pub occluder_units: u32,
    pub occluder_clamp: f32,
    pub receiver_slope: f32,
    pub toward_light: f32,
    pub along_normal: f32,
}

impl DepthOffset {
    /// The paper's `glPolygonOffset(1, 1)`: one depth slope and one step of
    /// the depth buffer, on the occluders.
    pub const PAPER: DepthOffset = DepthOffset {
        occluder_slope: 1.0,
        occluder_units: 1,
        ..DepthOffset::NONE
    };

    /// No offset at all.
    pub const NONE: DepthOffset = DepthOffset {
        occluder_slope: 0.0,
        occluder_units: 0,
        occluder_clamp: 0.0,
        receiver_slope: 0.0,
        toward_light: 0.0,
        along_normal: 0.0,
    };

    /// Half a texel along the vertex normal: the least error of a sweep of
    /// offsets and map sizes on a ball resting on a floor under a thin slab.
    pub const DEFAULT: DepthOffset = DepthOffset {
        along_normal: 0.5,
        ..DepthOffset::NONE
    };

    /// The largest tan θ `receiver_slope` is multiplied by (θ ≈ 83°).
    pub const MAX_TAN: f32 = 8.0;
}

impl Default for DepthOffset {
    fn default() -> DepthOffset {
        DepthOffset::DEFAULT
    }
}

/// Vertex filtering by temporal coherence (§4.1): only vertices of
/// triangles the camera has seen get their visibility computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filtering {
    /// Once fewer than this fraction of the triangles remain unseen, every
    /// remaining one is evaluated and filtering stops (the paper's
    /// threshold below which it no longer pays).
    pub threshold: f32,
}

impl Default for Filtering {
    /// Filtering stops once fewer than 5% of the triangles remain unseen.
    fn default() -> Filtering {
        Filtering { threshold: 0.05 }
    }
}

/// What is drawn into the depth maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Occluder {
    /// Every triangle of the frame.
    Full,
    /// Each object simplified by meshopt as far as its surface moves at
    /// most `texels` texels of the depth maps (detail the maps cannot hold
    /// anyway), to no fewer than 64 triangles: the tested vertices stay at
    /// full resolution, only the blockers are coarser.
    Simplified { texels: f32 },
}

/// The method's settings. Build from a preset ([`Config::default`],
/// [`Config::paper`], [`Config::fast`]) and change fields.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The lightsphere level while the geometry changes: 258 directions by
    /// default, the paper's "reasonable" level 3 (§4.2).
    pub level: Level,
    /// How the lightsphere's directions sit in world space.
    pub orientation: Orientation,
    /// While the geometry stays, refine one level per update up to this one,
    /// reusing every coarser direction's result (§4.2); `None` keeps `level`.
    pub idle_level: Option<Level>,
    pub weights: Weights,
    pub normalization: Normalization,
    pub test: VertexTest,
    /// Side of each direction's square depth map, in texels.
    pub map_resolution: u32,
    pub offset: DepthOffset,
    pub filtering: Option<Filtering>,
    pub occluder: Occluder,
    /// The environment is blurred with a Gaussian of this many times the
    /// lightsphere's spacing √(4π/k) before it is looked up in each
    /// direction (§5). The default, 1/√(2π) ≈ 0.4, gives the Gaussian the
    /// second moment of a disc the size of a direction's cell (4π/k).
    pub prefilter: f32,
}

impl Default for Config {
    /// Depth compare on the GPU at 258 directions, turned off the
    /// coordinate planes, with Voronoi weights and per-vertex normalization,
    /// full occluders, 512² maps offset by half a texel along the normal, no
    /// filtering.
    fn default() -> Config {
        Config {
            level: Level::new(3).expect("level 3"),
            orientation: Orientation::default(),
            idle_level: None,
            weights: Weights::Voronoi,
            normalization: Normalization::PerVertex,
            test: VertexTest::DepthCompare,
            map_resolution: 512,
            offset: DepthOffset::DEFAULT,
            filtering: None,
            occluder: Occluder::Full,
            // 1/√(2π)
            prefilter: 0.398_942_3,
        }
    }
}

impl Config {
    /// The paper's method as published: occlusion queries, equal weights,
    /// the raw quadrature, offset (1, 1) ([`DepthOffset::PAPER`]), 258
    /// directions from an octahedron on the axes.
    pub fn paper() -> Config {
        Config {
            orientation: Orientation::Axes,
            weights: Weights::Equal,
            normalization: Normalization::Off,
            test: VertexTest::OcclusionQuery,
            offset: DepthOffset::PAPER,
            ..Config::default()
        }
    }

    /// The default with occluders simplified as far as their surface moves
    /// by at most half a texel of the depth maps: it pays on dense meshes
    /// (the 35k-vertex bunny's 69k triangles become 9k), and costs accuracy
    /// on coarse or deforming ones.
    pub fn fast() -> Config {
        Config {
            occluder: Occluder::Simplified { texels: 0.5 },
            ..Config::default()
        }
    }

    /// The finest level the method can reach.
    pub fn finest(&self) -> Level {
        self.idle_level
            .map_or(self.level, |idle| idle.max(self.level))
    }

    /// Fails with [`Error::InvalidConfig`] naming the first setting out of
    /// range.
    pub fn check(&self) -> Result<()> {
        let bad = |what: String| Err(Error::config(NAME, what));
        if !(8..=4096).contains(&self.map_resolution) {
            return bad(format!(
                "depth map resolution {} is outside 8..=4096",
                self.map_resolution
            ));
        }
        let offset = self.offset;
        let non_negative = |x: f32| x.is_finite() && x >= 0.0;
        let terms = [
            offset.occluder_slope,
            offset.occluder_clamp,
            offset.receiver_slope,
            offset.toward_light,
            offset.along_normal,
        ];
        if !terms.into_iter().all(non_negative) || offset.occluder_units > i32::MAX as u32 {
            return bad(format!(
                "depth offset {offset:?} must be finite and non-negative (units at most 2^31 - 1)"
            ));
        }
        if let Some(f) = self.filtering
            && !(0.0..=1.0).contains(&f.threshold)
        {
            return bad(format!(
                "filtering threshold {} is outside [0, 1]",
                f.threshold
            ));
        }
        if let Occluder::Simplified { texels } = self.occluder
            && !(texels.is_finite() && texels > 0.0)
        {
            return bad(format!(
                "occluder simplification by {texels} texels must be positive"
            ));
        }
        if !non_negative(self.prefilter) {
            return bad(format!(
                "prefilter width {} must be finite and non-negative",
                self.prefilter
            ));
        }
        Ok(())
    }
}
