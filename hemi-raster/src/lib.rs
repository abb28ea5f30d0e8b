#![doc = include_str!("../README.md")]
#![deny(unsafe_code)]

mod blockers;
mod config;
mod csr;
mod engine;
mod hierarchy;
mod mask;
mod method;
pub mod name;
mod pvs;
mod raster;
mod transfer;

#[cfg(test)]
mod properties;
#[cfg(test)]
mod test_util;

pub use config::{
    BackfaceCulling, Config, Hierarchy, Integration, MaskResolution, NearRings, Pvs, Simd,
};
pub use mask::{BLOCK, DiskGrid, Mask, Mask16, Mask32, Mask64, MaskRow};
pub use method::HemiRaster;
pub use raster::{PlaneLut, Rasterizer, TangentFrame};
pub use transfer::{
    LOBE_CUTOFF, LobeGrid, PhongLobe, TangentBasis, direct_glossy, direct_irradiance,
    glossy_transfer, pixel_angle,
};
