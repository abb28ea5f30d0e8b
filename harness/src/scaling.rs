//! Time per image against image width: what a method's image costs at the
//! resolutions a renderer draws, not only at the width the report scores.
//!
//! A method's time per image is update + render of a fresh frame (the
//! report's per-pixel time, [`crate::run::StageTimes::image_frame`]). Work
//! per frame (visibility, maps) does not grow with the width; work per
//! pixel (a ray tracer's rays, deferred shadowing's lookups) grows with its
//! square. The report fits the power of the width each setting's time
//! grows with, and compares each with the per-pixel ray tracer at equal
//! error ([`crate::report`]'s resolution section).

use serde::{Deserialize, Serialize};
use shadow_core::{Environment, Result, Scene, ShadowMethod};

use crate::run::{BATCH_SECONDS, MIN_SAMPLES, nudged, sample, timed};
use crate::timing::Timing;

/// A setting's time per image at one width.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WidthTime {
    pub width: u32,
    pub height: u32,
    pub time: Timing,
}

/// One setting's times per image on a scene, over widths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalingRun {
    pub scene: String,
    pub family: String,
    pub setting: String,
    /// Whether the method draws per pixel (else it interpolates its
    /// per-vertex results).
    pub per_pixel: bool,
    pub widths: Vec<WidthTime>,
}

/// Times `method`'s image of the first frame of `scene` under
/// `environment`, seen by the scene's camera at each of `widths` (the
/// camera's aspect kept).
///
/// Each width gets one untimed image first (what the size allocates), then
/// `samples` samples (at least one) of update + render, each update made
/// fresh by first updating, untimed, to a nudged twin of the frame; a
/// sample under [`BATCH_SECONDS`] is a batch of such calls and their mean,
/// as the report's still scenes are timed.
pub fn time_images(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    environment: &Environment,
    widths: &[u32],
    samples: usize,
) -> Result<Vec<WidthTime>> {
    method.prepare(scene)?;
    method.relight(environment)?;
    let frame = scene.frame_geometry(0)?;
    let twin = nudged(&frame)?;
    widths
        .iter()
        .map(|&width| {
            let camera = scene.camera().with_width(width)?;
            method.update(&frame, &camera)?;
            method.render(&camera)?;
            let times = (0..samples.max(1))
                .map(|_| {
                    sample(BATCH_SECONDS, || {
                        method.update(&twin, &camera)?;
                        let update = timed(|| method.update(&frame, &camera))?;
                        let render = timed(|| method.render(&camera).map(drop))?;
                        Ok(update + render)
                    })
                    .map(|d| d.as_secs_f64())
                })
                .collect::<Result<Vec<f64>>>()?;
            Ok(WidthTime {
                width: camera.width,
                height: camera.height,
                time: Timing::new(times),
            })
        })
        .collect()
}

/// Samples per width the report takes: [`MIN_SAMPLES`], or `repeats` when
/// fewer are asked for.
pub fn samples(repeats: usize) -> usize {
    MIN_SAMPLES.min(repeats).max(1)
}

/// The least-squares slope of log time against log width: the power of
/// the width the time grows with (0 for none of the widths' times
/// positive or fewer than two widths).
pub fn slope(widths: &[WidthTime]) -> f64 {
    let points: Vec<(f64, f64)> = widths
        .iter()
        .filter(|w| w.time.median() > 0.0)
        .map(|w| (f64::from(w.width).ln(), w.time.median().ln()))
        .collect();
    let n = points.len() as f64;
    if points.len() < 2 {
        return 0.0;
    }
    let (mx, my) = (
        points.iter().map(|p| p.0).sum::<f64>() / n,
        points.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn widths(f: impl Fn(f64) -> f64) -> Vec<WidthTime> {
        [160, 320, 640, 1280]
            .map(|w| WidthTime {
                width: w,
                height: w * 3 / 4,
                time: Timing::new(vec![f(f64::from(w))]),
            })
            .to_vec()
    }

    #[test]
    fn the_slope_is_the_power_of_the_width() {
        approx::assert_relative_eq!(slope(&widths(|w| 3e-9 * w * w)), 2.0, epsilon = 1e-9);
        approx::assert_relative_eq!(slope(&widths(|_| 0.01)), 0.0, epsilon = 1e-9);
        approx::assert_relative_eq!(slope(&widths(|w| 1e-5 * w)), 1.0, epsilon = 1e-9);
        assert_eq!(slope(&widths(|w| w)[..1]), 0.0);
    }
}
