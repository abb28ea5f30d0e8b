//! What the runs show: each family's sweep as a curve of error against
//! time, per scene and domain.

use super::Report;
use super::render::setting_label;
use crate::{
    chart::{Axes, Curve, CurvePoint},
    run::RunResult,
    suite::RAY_TRACER,
    timing::Timing,
};

/// The two domains a run is scored in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Domain {
    Vertex,
    Image,
}

impl Domain {
    pub(super) fn key(self) -> &'static str {
        match self {
            Domain::Vertex => "vertex",
            Domain::Image => "image",
        }
    }

    pub(super) fn axes(self) -> Axes<'static> {
        match self {
            Domain::Vertex => Axes::RADIANCE,
            Domain::Image => Axes::IMAGE,
        }
    }

    /// (error in percent, time per frame) of a run in this domain.
    pub(super) fn point(self, r: &RunResult) -> Option<(f64, Timing)> {
        match self {
            Domain::Vertex => Some((f64::from(r.mean_error()) * 100.0, r.frame_time())),
            Domain::Image => Some((
                f64::from(r.mean_image_error()?) * 100.0,
                r.image_frame_time()?,
            )),
        }
    }
}

impl Report {
    /// Each family's sweep on `scene` in one domain, cheapest setting first.
    pub(super) fn curves(&self, scene: &str, domain: Domain) -> Vec<Curve> {
        self.families
            .iter()
            .enumerate()
            .filter_map(|(colour, f)| {
                let mut points: Vec<CurvePoint> = self
                    .runs_of(scene)
                    .filter(|r| r.family == f.family)
                    .filter_map(|r| {
                        let (error_percent, time) = domain.point(&r.result)?;
                        Some(CurvePoint {
                            label: setting_label(&r.setting),
                            error_percent,
                            ms: time.median() * 1e3,
                            ms_range: (time.min() * 1e3, time.max() * 1e3),
                        })
                    })
                    .collect();
                points.sort_by(|a, b| a.ms.total_cmp(&b.ms));
                (!points.is_empty()).then(|| Curve {
                    family: f.family.to_string(),
                    points,
                    baseline: f.family == RAY_TRACER,
                    colour,
                })
            })
            .collect()
    }
}
