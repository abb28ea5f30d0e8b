//! # hemi-raster
//!
//! Kautz, Lehtinen and Aila 2004, "Hemispherical rasterization for
//! self-shadowing of dynamic objects": per-vertex visibility masks rasterized on
//! the CPU, projected to spherical-harmonic transfer.
//!
//! Not implemented yet: this crate exists so the workspace has its final shape.
//! It exports nothing until the method lands, so that nothing here pretends to work.
