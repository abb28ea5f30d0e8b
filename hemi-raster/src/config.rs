//! What a user can tune: plain settings, with named presets.
//!
//! Nothing here depends on the rest of the crate; the modules that use a
//! setting say what it does.

use std::num::NonZeroU32;

use shadow_core::sh::{ShOrder, Window};
use shadow_core::{Error, Result};

/// Pixels per side of the visibility mask (one machine word per row).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MaskResolution {
    /// 16×16, `u16` rows.
    R16,
    /// 32×32, `u32` rows: the paper's.
    #[default]
    R32,
    /// 64×64, `u64` rows.
    R64,
}

impl MaskResolution {
    pub fn pixels_per_side(self) -> usize {
        match self {
            MaskResolution::R16 => 16,
            MaskResolution::R32 => 32,
            MaskResolution::R64 => 64,
        }
    }
}

/// How a mask becomes shading (§3, eq. 3; the `transfer` module).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integration {
    /// SH transfer from every blocked pixel.
    #[default]
    ShPixels,
    /// SH transfer from the 4×4-block grey downsample (§3.2).
    ShBlocks,
    /// No SH: the environment integrated over the visible pixels directly.
    Direct,
}

/// Which blocker triangles are dropped when they face away from the receiver
/// (see the [`Rasterizer`](crate::Rasterizer) docs for why this is exact for
/// closed meshes only).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BackfaceCulling {
    /// Cull the back faces of objects whose mesh is closed
    /// ([`shadow_core::Mesh::is_closed`]), keep those of open ones.
    #[default]
    Auto,
    /// Cull every object's back faces (wrong for open meshes).
    On,
    /// Rasterize every triangle.
    Off,
}

/// How far from a receiver the full-resolution mesh is used (§3.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NearRings {
    /// The triangles around the vertex.
    One,
    /// The triangles around the vertex and around its one-ring neighbours.
    #[default]
    Two,
}

/// Which blocker triangles a receiver rasterizes (§3.2, "Mesh Hierarchy").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hierarchy {
    /// Every triangle of the frame, at full resolution: cost vertices ×
    /// triangles.
    Flat,
    /// The paper's two-level hierarchy: a receiver rasterizes the
    /// full-resolution triangles of its `near` rings and a coarse version of
    /// every object (its own and the others) built once by `prepare` with
    /// meshoptimizer. The coarse mesh indexes the original vertices, so it
    /// follows every pose, skinned ones included. An object is simplified to
    /// max(triangles / `coarse_divisor`, `min_coarse_triangles`) triangles;
    /// objects that would not shrink are used whole, exactly as in
    /// [`Hierarchy::Flat`]. Near and coarse triangles overlap, which the OR
    /// of the mask absorbs. Coarse triangles of the receiver's body (its
    /// object and the parts touching it) that pass too close to it are
    /// dropped per frame and replaced by the fine triangles they stand for
    /// (see the `hierarchy` module docs).
    TwoLevel {
        coarse_divisor: NonZeroU32,
        min_coarse_triangles: u32,
        near: NearRings,
        /// Also near: the fine triangles of the receiver's body that come
        /// within `near_reach` × their object's mean coarse-triangle radius
        /// of it in the scene's first frame, wherever they are on the
        /// surface (the paper's §4.1 "Accuracy of Local Geometry": eyes in
        /// their sockets, arms against the body); objects touching within
        /// that reach form one body. 0 keeps the rings only (coarse
        /// triangles too close to the receiver are still replaced by their
        /// fine triangles, per frame).
        near_reach: u8,
        /// Whether coarse triangles of the receiver's body that pass too
        /// close to it are dropped and replaced by the fine triangles they
        /// stand for, per frame, and those whose region the near list
        /// covers skipped (the `hierarchy` module docs): §3.2's "in the
        /// vicinity of a vertex we use triangles from the high-resolution
        /// mesh. For the remaining parts of the model we use a coarser
        /// mesh". False keeps every coarse triangle, however close; a
        /// chord passing just above a receiver then covers most of its
        /// hemisphere (the cloth's transfer error 52.6%, unshadowed's
        /// 16.6%, docs/measurements.md).
        replace_near_chords: bool,
    },
}

impl Hierarchy {
    /// The near reach of [`Config::fast`], in mean coarse-triangle radii:
    /// far enough that the cracks where the near list meets the coarse
    /// mesh (about the simplification error wide) subtend about a mask
    /// pixel (the `hierarchy` module docs, "Cracks between the levels").
    pub const WIDE_NEAR_REACH: u8 = 6;

    /// The same hierarchy with `near_reach` (no change to [`Hierarchy::Flat`]).
    pub fn with_near_reach(mut self, near_reach: u8) -> Hierarchy {
        if let Hierarchy::TwoLevel { near_reach: r, .. } = &mut self {
            *r = near_reach;
        }
        self
    }

    /// The same hierarchy with `min_coarse_triangles` (no change to
    /// [`Hierarchy::Flat`]).
    pub fn with_min_coarse_triangles(mut self, min_coarse_triangles: u32) -> Hierarchy {
        if let Hierarchy::TwoLevel {
            min_coarse_triangles: m,
            ..
        } = &mut self
        {
            *m = min_coarse_triangles;
        }
        self
    }
}

impl Default for Hierarchy {
    /// One tenth of every object's triangles (the paper's Table 1), at
    /// least 300, or more where a tenth would lose a tenth of the object's
    /// area (the `hierarchy` module docs), with the two-ring, plus the fine
    /// triangles within twice the mean coarse triangle radius. The floor
    /// keeps small objects nearly whole, so that their coarse mesh does
    /// not hang on rounding: the simplifier breaks the ties of a
    /// symmetric mesh by it, and without the floor an icosphere of 320
    /// triangles resting on a box took a different coarse shape at each
    /// scale, changing a blocked fraction by up to 24 of 812 pixels
    /// between scales of the scene (and 12 between places). Without it,
    /// `min_coarse_triangles: 0`, the transfer error of the human, cloth
    /// and chess moves by at most 0.03 points and the chess's blockers per
    /// receiver fall from 2,581 to 1,148 (docs/measurements.md).
    fn default() -> Self {
        Hierarchy::TwoLevel {
            coarse_divisor: NonZeroU32::new(10).expect("10 is not zero"),
            min_coarse_triangles: 300,
            near: NearRings::Two,
            near_reach: 2,
            replace_near_chords: true,
        }
    }
}

impl Hierarchy {
    /// The paper's (§3.2, Table 1): every object simplified to a tenth of
    /// its triangles however few that leaves (Table 1's low-resolution
    /// meshes hold a tenth to a sixteenth), the one-ring of the
    /// full-resolution mesh (Fight's 448.8 blockers per vertex against its
    /// 444 low-resolution triangles leave room for little more), no other
    /// near triangles, and the coarse mesh only for "the remaining parts of
    /// the model": coarse triangles over the receiver's vicinity replaced.
    pub const PAPER: Hierarchy = Hierarchy::TwoLevel {
        coarse_divisor: NonZeroU32::new(10).expect("10 is not zero"),
        min_coarse_triangles: 0,
        near: NearRings::One,
        near_reach: 0,
        replace_near_chords: true,
    };
}

/// Potentially visible sets (§3.2, "PVS"): per vertex, the blocker
/// triangles that showed in frames known beforehand.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pvs {
    /// Every candidate of the hierarchy, every frame.
    #[default]
    Off,
    /// A static set per vertex, built by `prepare` from frames 0, `stride`,
    /// 2·`stride`, … of the scene's animation (the paper's offline
    /// preprocess). On those frames the masks are exactly those without
    /// sets; on other poses a blocker hidden in all of them is missed
    /// (`pvs` module docs), so the frames should be as dense as the poses
    /// the sets will serve.
    Animation { stride: NonZeroU32 },
}

impl Pvs {
    /// Sets built from every frame of the animation.
    pub const EVERY_FRAME: Pvs = Pvs::Animation {
        stride: NonZeroU32::MIN,
    };
}

/// Which compilation of the per-receiver loop and of the SH integration
/// runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Simd {
    /// The widest path the running CPU supports (detected at run time).
    #[default]
    Auto,
    /// The build target's baseline instructions (SSE2 on x86-64): what any
    /// CPU runs.
    Portable,
    /// AVX2 and FMA, with BMI1, BMI2 and POPCNT (x86-64 only).
    Avx2,
    /// AVX-512 F/BW/DQ/VL, with everything of [`Simd::Avx2`] (x86-64 only).
    Avx512,
}

/// Settings of [`crate::HemiRaster`].
///
/// [`Config::default`] is the paper's setup (§3.1.1, §3.2) but for
/// integrating every blocked pixel: a 32×32 mask, a 6×128×128 plane table,
/// 25-term SH (order 5: bands 0–4), back faces culled on closed meshes, the
/// two-level mesh hierarchy without PVS, and the widest SIMD path the
/// running CPU has. The presets:
///
/// - [`Config::paper`]: as published, SH from the 4×4-block downsample and
///   the paper's hierarchy (a tenth of the triangles, the one-ring).
/// - [`Config::fast`]: potentially visible sets from every frame of the
///   scene and a wider near field: 2–6× faster frames, the flat mesh's
///   accuracy, but `prepare` must see the animation (seconds on the
///   benchmark scenes).
/// - [`Config::accurate`]: no hierarchy, every triangle for every receiver:
///   0.2 points less transfer error on deforming meshes, 1–2.5× the time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    pub mask_resolution: MaskResolution,
    /// Cells per side of each cube face of the plane table: even, at least
    /// 2. It should grow with the mask: the plane quantization, about 1/N in
    /// disk units, should stay below the pixel size 2/R.
    pub lut_resolution: usize,
    /// SH order of the transfer vectors and lighting.
    pub order: ShOrder,
    /// σ-factors applied to the lighting's bands against the ringing of a
    /// small bright source (shadow-core's [`Window`]); direct integration,
    /// which has no SH, ignores it.
    pub window: Window,
    pub integration: Integration,
    pub backface_culling: BackfaceCulling,
    pub hierarchy: Hierarchy,
    pub pvs: Pvs,
    /// Which compilation of the per-receiver loop runs; `Auto` detects the
    /// CPU's widest.
    pub simd: Simd,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            mask_resolution: MaskResolution::R32,
            lut_resolution: 128,
            order: ShOrder::new(5).expect("5 is a valid order"),
            window: Window::None,
            integration: Integration::ShPixels,
            backface_culling: BackfaceCulling::Auto,
            hierarchy: Hierarchy::default(),
            pvs: Pvs::Off,
            simd: Simd::Auto,
        }
    }
}

impl Config {
    /// The paper as published: the SH integrated from the 4×4-block
    /// downsample of the mask ([`Integration::ShBlocks`], §3.2) and the
    /// paper's mesh hierarchy ([`Hierarchy::PAPER`]).
    pub fn paper() -> Config {
        Config {
            integration: Integration::ShBlocks,
            hierarchy: Hierarchy::PAPER,
            ..Config::default()
        }
    }

    /// Potentially visible sets built by `prepare` from every frame of the
    /// scene ([`Pvs::EVERY_FRAME`], §3.2), and the hierarchy's near reach
    /// widened to [`Hierarchy::WIDE_NEAR_REACH`]: on those frames the masks
    /// of that hierarchy, from a small fraction of its blockers. The sets
    /// drop the hidden part of the wider near field, so it costs little
    /// here, and it narrows the cracks between the two levels that light
    /// receivers enclosed by their own body (the `hierarchy` module docs,
    /// "Cracks between the levels"). For animations known in advance: on
    /// poses between the known frames a set may miss a blocker.
    pub fn fast() -> Config {
        Config {
            pvs: Pvs::EVERY_FRAME,
            hierarchy: Hierarchy::default().with_near_reach(Hierarchy::WIDE_NEAR_REACH),
            ..Config::default()
        }
    }

    /// The default without the mesh hierarchy ([`Hierarchy::Flat`]): every
    /// triangle of the frame blocks every vertex, at full resolution.
    pub fn accurate() -> Config {
        Config {
            hierarchy: Hierarchy::Flat,
            ..Config::default()
        }
    }

    /// Checks what the settings alone decide: the plane table's resolution
    /// (even, at least 2, a table of at most 1 GiB). Whether the CPU runs
    /// the chosen [`Simd`] path is checked by `prepare`
    /// ([`Simd::resolve`]).
    pub fn validate(&self) -> Result<()> {
        check_plane_table(self.mask_resolution.pixels_per_side(), self.lut_resolution)
    }
}

/// The largest plane table accepted (bytes); bigger ones are configuration
/// mistakes rather than useful accuracy.
const MAX_TABLE_BYTES: usize = 1 << 30;

/// Whether a plane table of `resolution`² cells per cube face for masks of
/// `side`² pixels can be built: `resolution` even and at least 2, the
/// table at most 1 GiB (three faces of `resolution`² masks, half of them
/// reachable; see [`PlaneLut`](crate::PlaneLut)).
pub(crate) fn check_plane_table(side: usize, resolution: usize) -> Result<()> {
    let cells = 3usize
        .checked_mul(resolution)
        .and_then(|n| n.checked_mul(resolution))
        .map(|n| n / 2);
    let bytes = cells.and_then(|n| n.checked_mul(side * side / 8));
    if resolution < 2 || resolution % 2 == 1 || bytes.is_none_or(|b| b > MAX_TABLE_BYTES) {
        return Err(Error::config(
            "hemi-raster",
            format!(
                "plane LUT resolution {resolution} per cube face must be even, at least 2, \
                 and give a table of at most 1 GiB for {side}×{side} masks"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_validates() {
        Config::default().validate().unwrap();
    }

    #[test]
    fn the_paper_preset_validates_and_integrates_blocks() {
        let paper = Config::paper();
        paper.validate().unwrap();
        assert_eq!(paper.integration, Integration::ShBlocks);
        assert_eq!(paper.mask_resolution.pixels_per_side(), 32);
        assert_eq!(paper.lut_resolution, 128);
        assert_eq!(paper.order.coeff_count(), 25);
    }

    #[test]
    fn the_fast_preset_validates_and_builds_sets_from_every_frame() {
        let fast = Config::fast();
        fast.validate().unwrap();
        assert_eq!(fast.pvs, Pvs::EVERY_FRAME);
        assert_eq!(
            fast.hierarchy,
            Hierarchy::default().with_near_reach(Hierarchy::WIDE_NEAR_REACH)
        );
    }

    #[test]
    fn the_accurate_preset_validates_and_is_flat() {
        let accurate = Config::accurate();
        accurate.validate().unwrap();
        assert_eq!(accurate.hierarchy, Hierarchy::Flat);
        assert_eq!(accurate.pvs, Pvs::Off);
    }

    #[test]
    fn bad_plane_tables_do_not_validate() {
        for (mask_resolution, lut_resolution) in [
            (MaskResolution::R32, 0),
            (MaskResolution::R32, 63),
            (MaskResolution::R64, 1 << 20),
            (MaskResolution::R16, 100_000),
        ] {
            let config = Config {
                mask_resolution,
                lut_resolution,
                ..Config::default()
            };
            let e = config.validate().unwrap_err();
            assert!(matches!(e, Error::InvalidConfig { .. }), "{e}");
        }
    }
}
