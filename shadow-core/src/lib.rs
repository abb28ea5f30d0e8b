#![doc = include_str!("../README.md")]
//!
//! Conventions (DESIGN.md): right-handed, +Y up, metres, counter-clockwise
//! front faces; environments are equirectangular maps of linear radiance with
//! row 0 at the top; every method returns the outgoing radiance of direct
//! distant lighting with visibility from every object,
//! `L_o(x, v) = ∫ L_env(ω) V(x, ω) f_r(ω, v) max(0, n·ω) dω`.
#![deny(unsafe_code)]

mod brdf;
mod camera;
pub mod contact;
pub mod environment;
mod error;
mod export;
pub mod frame;
mod mesh;
mod method;
pub mod name;
mod profile;
pub mod qmc;
pub mod raster;
mod scene;
pub mod sh;
pub mod shading;
pub mod shapes;
pub mod triangle;

#[cfg(feature = "bvh")]
pub mod bvh;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(feature = "simplify")]
pub mod simplify;

pub use brdf::{Brdf, reflect};
pub use camera::Camera;
pub use environment::{Environment, EnvironmentReport};
pub use error::{Error, Result};
pub use export::{DirectionalVisibility, Export, ShTransfer, TransferSpace};
pub use frame::{SurfacePoint, TangentSpace, ray_origin};
pub use mesh::{Aabb, Adjacency, Mesh, MeshReport};
pub use method::{Capabilities, Capability, Image, ShadowMethod, VertexRadiance};
pub use profile::{Profile, ProfileEntry, ProfileValue, Stage};
pub use scene::{Frame, FrameGeometry, Object, Pose, PosedObject, Scene};
