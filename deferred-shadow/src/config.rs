//! The method's settings.

use shadow_core::{Error, Result, sh::Window};

/// How occluders are gathered into groups, each casting through one
/// occlusion map per light and receiver (§4.2.3). Shadows cast within a
/// group are lost: its members do not shadow each other except through
/// their own self-shadowing.
#[derive(Clone, Debug, PartialEq)]
pub enum Grouping {
    /// Objects whose bounding boxes (padded by a thousandth of the smaller
    /// one's diagonal, so that flat objects have a volume) overlap by more than
    /// `overlap` of the smaller box's volume form one group: the two colours
    /// of a chess board, or parts of one figure, but not a piece standing
    /// on the board. The groups follow the objects: each frame whose poses
    /// moved regroups them, and maps are kept only while the groups stay.
    Overlapping { overlap: f32 },
    /// The given groups of object indices; each object in exactly one.
    Explicit(Vec<Vec<usize>>),
}

/// The method's settings. [`Config::default`] is the paper's real-time
/// choice (§7.2): 32 area lights and 64² occlusion maps.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// q, the number of area lights the environment is split into (§4.2.1).
    pub lights: usize,
    /// The largest side of a square occlusion map, texels (§4.2.2; the
    /// paper gives every map this side: 32, 64, 128); each map has the
    /// fewest its penumbra needs up to it (`maps::resolution`).
    pub map_resolution: u32,
    /// Shadow rays per vertex for the self-transfer precomputation
    /// (cosine-distributed, stratified).
    pub rays: u32,
    pub grouping: Grouping,
    /// Multiply the occlusion ratio by the point's own visibility toward
    /// each light (eq. 7–8, §4.2.4), so that a direction both self- and
    /// other-occluded is not subtracted twice. Off gives eq. 4.
    pub self_visibility: bool,
    /// σ-factors applied to the SH bands of the self-shadowed lighting, the
    /// diffuse lighting's and the glossy lit transfer's, against the
    /// ringing of a small bright source (shadow-core's [`Window`]).
    pub window: Window,
    /// The outgoing light's loss L_o evaluated at one pixel of each 2×2
    /// block and shared with the pixels around it that lie on the same
    /// surface where at least two blocks agree (within 5% of the pixel's
    /// L_s), evaluated at the pixel elsewhere: shadow edges, silhouettes
    /// and creases stay per pixel. At 512×384 (AVX2 host, lavapipe, runs
    /// alternated) the render takes about 148 ms instead of 205 on `chess`
    /// at 3.92–4.20% image error instead of 3.88–4.09%, 102 instead of 136
    /// on `bunny` at 4.11% instead of 4.06%: off by default, since it does
    /// not keep the error. A shadow narrower than a block (at a contact)
    /// can be missed.
    pub blocks: bool,
}

impl Default for Config {
    fn default() -> Config {
        Config {
            lights: 32,
            map_resolution: 64,
            rays: 512,
            grouping: Grouping::Overlapping { overlap: 0.5 },
            self_visibility: true,
            window: Window::None,
            blocks: false,
        }
    }
}

/// The most area lights: the deferred pass keeps one weight per light and
/// vertex.
pub const MAX_LIGHTS: usize = 256;

/// The largest occlusion map side (the blur keeps a row in registers).
pub const MAX_MAP_RESOLUTION: u32 = 256;

impl Config {
    /// Fails with [`shadow_core::Error::InvalidConfig`] naming the first
    /// setting out of range.
    pub fn check(&self) -> Result<()> {
        let bad = |what: String| Err(Error::config("deferred-shadow", what));
        if !(1..=MAX_LIGHTS).contains(&self.lights) {
            return bad(format!(
                "{} area lights is outside 1..={MAX_LIGHTS}",
                self.lights
            ));
        }
        if !(4..=MAX_MAP_RESOLUTION).contains(&self.map_resolution) {
            return bad(format!(
                "occlusion map resolution {} is outside 4..={MAX_MAP_RESOLUTION}",
                self.map_resolution
            ));
        }
        if !(16..=65536).contains(&self.rays) {
            return bad(format!(
                "{} rays per vertex is outside 16..=65536",
                self.rays
            ));
        }
        if let Grouping::Overlapping { overlap } = self.grouping
            && !(overlap > 0.0 && overlap <= 1.0)
        {
            return bad(format!("group overlap {overlap} is outside (0, 1]"));
        }
        Ok(())
    }
}
