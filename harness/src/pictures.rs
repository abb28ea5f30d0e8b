//! Pictures for people: a scene rendered [`PICTURE_WIDTH`] pixels wide (or
//! as asked) by each setting shown, framed on where their errors concentrate (the
//! bunny's contact shadow, a stress scene's failing region), each beside
//! its error map at the same size and on the same colour scale, against a
//! reference of the same view.
//!
//! The frame comes from the scored images: the error of the settings shown,
//! summed per pixel ([`window`]), picks a window of the scored view, and
//! the camera turns and zooms onto it ([`Camera::zoomed`]). The pictures'
//! reference is its own (cached like every reference), to a looser noise
//! than the scored one: it is for the eye and for the error maps, whose
//! scale starts at 0.1%; each picture's error against it is given with the
//! reference's noise.

use std::path::Path;

use serde::{Deserialize, Serialize};
use shadow_core::{Camera, Environment, Error, Image, Result, Scene};

use crate::{
    images::{self, Exposure},
    methods::{MethodSpec, SharedGpu},
    progress::Progress,
    reference::{self, ReferenceCache, ReferenceSettings},
    score,
};

/// The pictures' width in pixels (the scene camera's aspect kept).
pub const PICTURE_WIDTH: u32 = 512;

/// The closest zoom a picture frames: its window is at least 1 / `MAX_ZOOM`
/// of the scored view's height (a closer one would show fewer triangles
/// than pixels).
pub const MAX_ZOOM: f32 = 3.0;

/// One setting's picture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Picture {
    pub setting: String,
    /// The file stem of its picture (`{stem}.png`) and error map
    /// (`{stem}-error.png`) in the set's folder.
    pub stem: String,
    /// Its relative L2 error against the pictures' reference.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub error: f32,
}

/// A scene's pictures: one view, one reference, the settings shown.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pictures {
    pub scene: String,
    /// The folder under the report's holding `reference.png` and the
    /// pictures.
    pub folder: String,
    /// The frame shown (the scene's last, as the scored images).
    pub frame: usize,
    pub width: u32,
    pub height: u32,
    /// The fraction of the scored view's height the pictures show (1: all
    /// of it).
    pub zoom: f32,
    /// The pictures' reference's relative noise, and the seconds it took
    /// (0 from the cache).
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub reference_noise: f32,
    pub reference_seconds: f64,
    pub shown: Vec<Picture>,
    /// The settings whose picture failed to render, and why (the page says
    /// so where it would show them).
    pub failed: Vec<Unrendered>,
}

/// A setting whose picture failed to render.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unrendered {
    pub setting: String,
    pub why: String,
}

impl Pictures {
    /// The picture of `setting`, if it was taken.
    pub fn of(&self, setting: &str) -> Option<&Picture> {
        self.shown.iter().find(|p| p.setting == setting)
    }
}

/// Where the per-pixel `errors` of a `width` × `height` image concentrate:
/// the window's centre (pixels from the top left) and its height as a
/// fraction of the image's. The window is centred on the errors' centroid
/// and holds two standard deviations of them either way (at least 1 /
/// [`MAX_ZOOM`] of the image, at most all of it), shifted to lie inside the
/// image; no errors, the whole image.
pub fn window(width: u32, height: u32, errors: &[f32]) -> ((f32, f32), f32) {
    let (w, h) = (width as f32, height as f32);
    let whole = ((w / 2.0, h / 2.0), 1.0);
    let total: f32 = errors.iter().sum();
    if total.is_nan() || total <= 0.0 || errors.len() != (width * height) as usize {
        return whole;
    }
    let at = |i: usize| {
        (
            (i % width as usize) as f32 + 0.5,
            (i / width as usize) as f32 + 0.5,
        )
    };
    let (mut cx, mut cy) = (0.0, 0.0);
    for (i, e) in errors.iter().enumerate() {
        let (x, y) = at(i);
        cx += e * x;
        cy += e * y;
    }
    let (cx, cy) = (cx / total, cy / total);
    let (mut vx, mut vy) = (0.0, 0.0);
    for (i, e) in errors.iter().enumerate() {
        let (x, y) = at(i);
        vx += e * (x - cx).powi(2);
        vy += e * (y - cy).powi(2);
    }
    let (sx, sy) = ((vx / total).sqrt(), (vy / total).sqrt());
    // The window's height: ±2σ vertically, or horizontally at the aspect.
    let fraction = (4.0 * sy.max(sx * h / w) / h).clamp(1.0 / MAX_ZOOM, 1.0);
    let (half_w, half_h) = (fraction * w / 2.0, fraction * h / 2.0);
    (
        (cx.clamp(half_w, w - half_w), cy.clamp(half_h, h - half_h)),
        fraction,
    )
}

/// The per-pixel relative errors of `image` against `reference` as weights
/// for [`window`]: squared (so that the few large errors of a failure
/// outweigh the many small ones around it), capped at 1, background 0.
pub fn error_weights(image: &Image, reference: &Image) -> Vec<f32> {
    images::pixel_errors(image, reference)
        .into_iter()
        .map(|e| {
            e.map_or(0.0, |e| {
                if e.is_finite() {
                    e.min(1.0).powi(2)
                } else {
                    1.0
                }
            })
        })
        .collect()
}

/// What [`take`] shows and how.
pub struct Shot<'a> {
    pub scene: &'a Scene,
    pub environment: &'a Environment,
    /// The scored view, whose window (`center` in its pixels, `fraction` of
    /// its height, from [`window`]) the pictures frame.
    pub scored: &'a Camera,
    pub center: (f32, f32),
    pub fraction: f32,
    pub width: u32,
    pub reference: &'a ReferenceSettings,
}

/// Renders `specs` (each built on `gpu`) on the last frame of the shot's
/// scene, framed as it says, with the reference of that view from `cache`;
/// writes `reference.png` and each setting's picture and error map into
/// `dir/folder`. A setting that cannot run on the scene is left out; one
/// that fails is in [`Pictures::failed`] with its error.
pub fn take(
    shot: &Shot,
    specs: &[&MethodSpec],
    gpu: &SharedGpu,
    cache: &ReferenceCache,
    dir: &Path,
    folder: &str,
    progress: &Progress,
) -> Result<Pictures> {
    let scale = shot.width as f32 / shot.scored.width as f32;
    let camera = shot.scored.with_width(shot.width)?.zoomed(
        (shot.center.0 * scale, shot.center.1 * scale),
        shot.fraction,
    )?;
    let frame = shot.scene.frames().len().saturating_sub(1);
    let geometry = shot.scene.frame_geometry(frame)?;
    let bar = progress.task(&format!("picture reference {}", shot.scene.name()));
    let (reference, cached) = reference::frame_image_reference(
        shot.scene,
        &geometry,
        shot.environment,
        &camera,
        shot.reference,
        Some(cache),
        &bar,
    )?;
    bar.finish_and_clear();
    let out = dir.join(folder);
    let exposure = Exposure::of(&reference.image);
    images::write_png(&out.join("reference.png"), &reference.image, exposure)?;
    let mut shown = Vec::new();
    let mut failed = Vec::new();
    for spec in specs {
        let rendered = spec.build(gpu).and_then(|mut method| {
            method.prepare(shot.scene)?;
            method.relight(shot.environment)?;
            method.update(&geometry, &camera)?;
            method.render(&camera)
        });
        let image = match rendered {
            Ok(image) => image,
            Err(Error::Unsupported { .. }) => continue,
            Err(e) => {
                failed.push(Unrendered {
                    setting: spec.name().to_string(),
                    why: e.to_string(),
                });
                continue;
            }
        };
        let stem = images::file_stem(spec.name());
        images::write_png(&out.join(format!("{stem}.png")), &image, exposure)?;
        images::write_error_map(
            &out.join(format!("{stem}-error.png")),
            &image,
            &reference.image,
        )?;
        shown.push(Picture {
            setting: spec.name().to_string(),
            stem,
            error: score::image(&image, &reference)?.relative_l2,
        });
    }
    let pictures = Pictures {
        scene: shot.scene.name().to_string(),
        folder: folder.to_string(),
        frame,
        width: camera.width,
        height: camera.height,
        zoom: shot.fraction,
        reference_noise: reference.noise,
        reference_seconds: if cached { 0.0 } else { reference.seconds },
        shown,
        failed,
    };
    Ok(pictures)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_centres_on_the_errors_and_holds_them() {
        let (w, h) = (160, 120);
        // Errors in a 10-pixel square around (40, 90).
        let errors: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i32, (i / w) as i32);
                if (x - 40).abs() < 5 && (y - 90).abs() < 5 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let ((cx, cy), fraction) = window(w, h, &errors);
        // The tightest window, shifted inside the image.
        assert_eq!(fraction, 1.0 / MAX_ZOOM);
        // Pixels 36 to 44 either way, their centres averaging 40.5 and 90.5.
        approx::assert_relative_eq!(cx, 40.5, epsilon = 1e-3);
        approx::assert_relative_eq!(cy, 90.5, epsilon = 1e-3);
        // Near a corner, the window stays inside the image.
        let corner: Vec<f32> = (0..w * h).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
        let ((cx, cy), fraction) = window(w, h, &corner);
        assert_eq!(
            (cx, cy),
            (w as f32 * fraction / 2.0, h as f32 * fraction / 2.0)
        );
        // Errors everywhere: the whole view; none: the whole view.
        assert_eq!(
            window(w, h, &vec![1.0; (w * h) as usize]),
            ((80.0, 60.0), 1.0)
        );
        assert_eq!(
            window(w, h, &vec![0.0; (w * h) as usize]),
            ((80.0, 60.0), 1.0)
        );
    }
}
