#![doc = include_str!("../README.md")]

mod config;
mod csr;
mod disk;
mod hierarchy;
mod kernel;
mod lut;
mod mask;
mod method;
mod pvs;
mod rasterize;
mod transfer;

#[cfg(test)]
mod properties;
#[cfg(test)]
mod test_util;

pub use config::{BackfaceCulling, Config, Hierarchy, MaskResolution, NearRings, Pvs};
pub use disk::{BLOCK, DiskGrid};
pub use kernel::Simd;
pub use lut::PlaneLut;
pub use mask::{Mask, Mask16, Mask32, Mask64, MaskRow};
pub use method::HemiRaster;
pub use rasterize::{Rasterizer, TangentFrame};
pub use transfer::{
    Integration, LOBE_CUTOFF, LobeGrid, PhongLobe, TangentBasis, direct_glossy, direct_irradiance,
    glossy_transfer, pixel_angle,
};
