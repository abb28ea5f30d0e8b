//! What the runs show: each family's sweep as a curve of error against
//! time, per scene and domain.

use super::Report;
use super::render::setting_label;
use crate::{
    chart::{Axes, Curve},
    run::RunResult,
    suite::RAY_TRACER,
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

    /// (error in percent, milliseconds per frame) of a run in this domain.
    pub(super) fn point(self, r: &RunResult) -> Option<(f64, f64)> {
        match self {
            Domain::Vertex => Some((f64::from(r.mean_error()) * 100.0, r.frame_seconds() * 1e3)),
            Domain::Image => Some((
                f64::from(r.mean_image_error()?) * 100.0,
                r.image_frame_seconds()? * 1e3,
            )),
        }
    }
}

impl Report {
    /// Each family's sweep on `scene` in one domain, cheapest setting first.
    pub(super) fn curves(&self, scene: &str, domain: Domain) -> Vec<Curve> {
        self.families
            .iter()
            .filter_map(|f| {
                let mut points: Vec<(String, f64, f64)> = self
                    .runs_of(scene)
                    .filter(|r| r.family == f.family)
                    .filter_map(|r| {
                        let (e, t) = domain.point(&r.result)?;
                        Some((setting_label(&r.setting), e, t))
                    })
                    .collect();
                points.sort_by(|a, b| a.2.total_cmp(&b.2));
                (!points.is_empty()).then(|| Curve {
                    family: f.family.to_string(),
                    points,
                    baseline: f.family == RAY_TRACER,
                })
            })
            .collect()
    }
}
