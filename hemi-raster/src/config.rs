//! What a user can tune, with the paper's choices as defaults.

use shadow_core::sh::ShOrder;

use crate::transfer::Integration;

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

/// Which blocker triangles are dropped when they face away from the receiver
/// (see the [`rasterize`](crate::Rasterizer) docs for why this is exact for
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

/// Settings of [`crate::HemiRaster`].
///
/// The default is the paper's setup (§3.1.1, §3.2): a 32×32 mask, a
/// 6×128×128 plane table, 25-term SH (order 5: bands 0–4) integrated from the
/// 4×4-block downsample, back faces culled on closed meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    pub mask_resolution: MaskResolution,
    /// Cells per side of each cube face of the plane table. It should grow
    /// with the mask: the plane quantization, about 1/N in disk units, should
    /// stay below the pixel size 2/R.
    pub lut_resolution: usize,
    /// SH order of the transfer vectors and lighting.
    pub order: ShOrder,
    pub integration: Integration,
    pub backface_culling: BackfaceCulling,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            mask_resolution: MaskResolution::R32,
            lut_resolution: 128,
            order: ShOrder::new(5).expect("5 is a valid order"),
            integration: Integration::ShBlocks,
            backface_culling: BackfaceCulling::Auto,
        }
    }
}
