//! Baselines beside the three papers (DESIGN.md, "Scoring"): unshadowed SH
//! lighting (no visibility, the upper bound) and Monte-Carlo ray tracing at a
//! low sample count (what a user would pick today).

mod raytrace;
mod unshadowed;

pub use raytrace::RayTrace;
pub use unshadowed::Unshadowed;
