//! # deferred-shadow
//!
//! Tamura, Johan and Nishita, "Deferred shadowing for real-time rendering of
//! dynamic scenes under environment illumination": per-vertex PRT for
//! self-shadowing plus per-pixel shadows from other objects through occlusion
//! maps, on wgpu.
//!
//! Not implemented yet: this crate exists so the workspace has its final shape.
//! It exports nothing until the method lands, so that nothing here pretends to work.
