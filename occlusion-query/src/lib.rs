//! # occlusion-query
//!
//! Sattler, Sarlette, Zachmann and Klein 2004, "Hardware-accelerated ambient
//! occlusion computation": per-vertex visibility from k light directions by
//! GPU depth tests (occlusion queries), on wgpu.
//!
//! Not implemented yet: this crate exists so the workspace has its final shape.
//! It exports nothing until the method lands, so that nothing here pretends to work.
