//! The interactive viewer (`harness view`): a scene under its environment
//! with a method's result, live. The method is switched, the camera
//! orbited, the environment turned, the animation played, and a per-pixel
//! heat map of the error against a cached image reference shown, with each
//! stage's time per frame.
//!
//! GPU methods run on the viewer's own device and record their stages into
//! the viewer's command encoder ([`host`]): the viewer is what a renderer
//! that takes one of the method crates looks like. With `--screenshot` it
//! draws offscreen and writes a PNG ([`offscreen`]).

mod clock;
mod device;
mod draw;
pub mod host;
pub mod offscreen;
mod orbit;
mod panel;
mod state;
pub mod window;

pub use state::{Heat, Setup};
