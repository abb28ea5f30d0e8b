#![cfg_attr(not(skip_gpu_tests), doc = include_str!("../README.md"))]
#![cfg_attr(
    skip_gpu_tests,
    doc = "The README, whose example needs a GPU adapter, is left out: `SOFT_SHADOWS_SKIP` lists gpu."
)]
#![forbid(unsafe_code)]

mod config;
mod gpu;
mod groups;
mod lights;
mod maps;
mod method;
pub mod name;
mod transfer;

pub use config::{Config, Grouping, MAX_LIGHTS, MAX_MAP_RESOLUTION};
pub use groups::Groups;
pub use lights::{AreaLight, decompose};
pub use maps::{MapWindow, Plan};
pub use method::DeferredShadow;
pub use transfer::{DIFFUSE_ORDER, GLOSSY_ORDER, Lighting, Transfer};
