//! From a visibility mask to shading (Kautz et al. 2004, §3, eq. 2–3, and
//! §3.2).
//!
//! For a Lambert surface the transfer vector is
//! T_k = ∫ V(ω) max(0, n·ω) Y_k(ω) dω, and the exit radiance ρ/π Σ_k L_k T_k
//! (eq. 2). Writing V = 1 − B (B the blocked directions),
//!
//! ```text
//! T_k = Λ_l Y_k(n)  −  ∫ B(ω) max(0, n·ω) Y_k(ω) dω,
//! ```
//!
//! the first term being the clamped cosine turned to the normal, exact by the
//! Funk–Hecke theorem ([`Zonal::project_along`](shadow_core::sh::Zonal::project_along)).
//! Only the blocked part is integrated over the mask: a vertex with nothing
//! above it gets the exact unshadowed transfer (the white furnace holds to
//! rounding), and the quadrature error is confined to the blocked
//! directions. In the disk parameterization the cosine is already in the
//! pixel weights (Nusselt), so the blocked integral is
//! Σ_{blocked pixels} w · Y_k(ω_pixel), summed from tables in the tangent
//! frame ([`TangentBasis`]).
//!
//! - [`Integration::ShPixels`] (the default): every blocked pixel counts at
//!   its own direction.
//! - [`Integration::ShBlocks`] (the paper's §3.2 optimization): the mask is
//!   downsampled in 4×4 blocks to a grey occlusion level (the block's count
//!   of blocked pixels), and each block counts at the mean direction of its
//!   disk pixels. It saves a fifth of the integration and costs about 2
//!   points of transfer error, most near the horizon, where the disk
//!   (ρ = sin θ) squeezes elevation: a 4×4 block of the 32×32 mask spans
//!   14° of elevation at the zenith, an outermost one 49° to 90°. It is
//!   kept to reproduce the paper.
//! - [`Integration::Direct`] (§3, "integrate the lighting directly"): no SH;
//!   the environment's radiance summed over the visible pixels
//!   ([`direct_irradiance`]).
//!
//! Glossy materials put the BRDF inside the integral ([`glossy_transfer`],
//! [`direct_glossy`]).

use crate::mask::{BLOCK, MaskRow};

#[cfg(doc)]
use crate::config::Integration;

/// Runs `$body` with the const `$k` equal to `$chunks` (a power of two up
/// to 16, the chunks of order 16's 256 coefficients).
macro_rules! with_chunks {
    ($chunks:expr, $k:ident => $body:expr) => {
        match $chunks {
            1 => {
                const $k: usize = 1;
                $body
            }
            2 => {
                const $k: usize = 2;
                $body
            }
            4 => {
                const $k: usize = 4;
                $body
            }
            8 => {
                const $k: usize = 8;
                $body
            }
            _ => {
                const $k: usize = 16;
                $body
            }
        }
    };
}

mod direct;
mod glossy;
mod tables;
#[cfg(test)]
mod tests;

pub use direct::{direct_glossy, direct_irradiance, pixel_angle};
pub use glossy::{LOBE_CUTOFF, LobeGrid, PhongLobe, glossy_transfer};
pub use tables::TangentBasis;

#[cfg(test)]
pub(crate) use glossy::tests::clipped_lobe_albedo;

/// Stack room for the per-block sums of the finest mask.
const MAX_BLOCKS: usize = (<u64 as MaskRow>::RESOLUTION / BLOCK).pow(2);

const _: () = assert!(BLOCK == 4);
