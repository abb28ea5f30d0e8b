#![cfg_attr(not(skip_gpu_tests), doc = include_str!("../README.md"))]
#![cfg_attr(
    skip_gpu_tests,
    doc = "The README, whose example needs a GPU adapter, is left out: `SOFT_SHADOWS_SKIP` lists gpu."
)]
#![forbid(unsafe_code)]

mod config;
mod filter;
mod lightsphere;
mod method;
pub mod name;
mod occluder;
mod shading;
mod views;
mod visibility;

pub use config::{Config, DepthOffset, Filtering, Normalization, Occluder, VertexTest};
pub use lightsphere::{Level, Lightsphere, Orientation, Weights};
pub use method::OcclusionQuery;
pub use views::{Atlas, orthographic, texel};
pub use visibility::TestOffset;
