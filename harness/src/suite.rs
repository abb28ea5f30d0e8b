//! What `harness report` runs: which scenes, and each method family swept
//! over its own parameters, so that the report can chart a curve of time
//! against error per family instead of one point per method.
//!
//! Three suites trade coverage for time:
//!
//! * [`Suite::Quick`]: four small scenes, two or three settings a family
//!   (a first look, and what CI runs);
//! * [`Suite::Default`]: every built-in scene, the sweeps below;
//! * [`Suite::Full`]: the default plus the slow settings (1026 lightsphere
//!   directions, the paper's per-vertex occlusion queries, 256 area lights,
//!   256 rays a vertex), which take minutes per frame on the larger scenes.

use serde::Serialize;

/// A method family and its sweep: the method names in order of cost.
#[derive(Clone, Debug, Serialize)]
pub struct Family {
    /// What the chart's legend calls it.
    pub name: &'static str,
    /// What varies along the sweep, for the chart's labels.
    pub parameter: &'static str,
    /// The method names (see [`crate::methods::by_name`]).
    pub methods: Vec<&'static str>,
}

/// The ray tracer's family: the line the other methods have to beat.
pub const RAY_TRACER: &str = "ray tracing";

/// How much the report runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, clap::ValueEnum)]
pub enum Suite {
    Quick,
    #[default]
    Default,
    Full,
}

impl Suite {
    /// The built-in scenes it runs.
    pub fn scenes(self) -> Vec<&'static str> {
        match self {
            Suite::Quick => vec!["furnace", "wall", "bunny", "human"],
            Suite::Default | Suite::Full => crate::scenes::SCENES.iter().map(|s| s.name).collect(),
        }
    }

    /// The stress scenes of the stability atlas
    /// ([`crate::scenes::stress::STRESS_SCENES`]).
    pub fn atlas_scenes(self) -> Vec<&'static str> {
        let all = crate::scenes::stress::STRESS_SCENES.iter().map(|s| s.0);
        match self {
            Suite::Quick => all
                .filter(|s| ["thin-sheets", "near-contact", "sun-only"].contains(s))
                .collect(),
            Suite::Default | Suite::Full => all.collect(),
        }
    }

    /// One setting per family that the atlas runs on every stress scene,
    /// with the family it belongs to.
    pub fn atlas_settings(self) -> Vec<(&'static str, &'static str)> {
        let quick = self == Suite::Quick;
        vec![
            ("unshadowed", "unshadowed"),
            ("hemi-raster", "hemi-raster"),
            (
                "occlusion-query",
                if quick {
                    "occlusion-query:k=66"
                } else {
                    "occlusion-query"
                },
            ),
            (
                "deferred-shadow",
                if quick {
                    "deferred-shadow:q=8"
                } else {
                    "deferred-shadow"
                },
            ),
            (
                RAY_TRACER,
                if quick { "raytrace:16" } else { "raytrace:64" },
            ),
        ]
    }

    /// The families and their sweeps.
    pub fn families(self) -> Vec<Family> {
        let quick = self == Suite::Quick;
        let full = self == Suite::Full;
        let pick = |always: &[&'static str], default: &[&'static str], slow: &[&'static str]| {
            let mut m = always.to_vec();
            if !quick {
                m.extend(default);
            }
            if full {
                m.extend(slow);
            }
            m
        };
        vec![
            Family {
                name: "unshadowed",
                parameter: "SH order 9, no visibility",
                methods: vec!["unshadowed"],
            },
            Family {
                name: "hemi-raster",
                parameter: "visible sets, mask side, plane table, SH order, integration, near reach, hierarchy",
                methods: pick(
                    &["hemi-raster:pvs", "hemi-raster"],
                    &[
                        "hemi-raster:pvs:mask=16",
                        "hemi-raster:pvs:table=64",
                        "hemi-raster:pvs:order=3",
                        "hemi-raster:paper",
                        "hemi-raster:reach=6",
                        "hemi-raster:flat",
                    ],
                    &["hemi-raster:pvs:mask=64", "hemi-raster:pvs:order=7"],
                ),
            },
            Family {
                name: "occlusion-query",
                parameter: "lightsphere directions k, depth map side",
                methods: pick(
                    &["occlusion-query:k=18", "occlusion-query:k=66"],
                    &[
                        "occlusion-query",
                        "occlusion-query:map=256",
                        "occlusion-query:simplified",
                    ],
                    &[
                        "occlusion-query:k=1026",
                        "occlusion-query:map=1024",
                        "occlusion-query:queries",
                    ],
                ),
            },
            Family {
                name: "deferred-shadow",
                parameter: "area lights q, map side",
                methods: pick(
                    &["deferred-shadow:q=8", "deferred-shadow"],
                    &["deferred-shadow:q=128", "deferred-shadow:map=128"],
                    &["deferred-shadow:q=256"],
                ),
            },
            Family {
                name: RAY_TRACER,
                parameter: "MIS iterations per vertex and pixel",
                methods: pick(
                    &["raytrace:4", "raytrace:16"],
                    &["raytrace:64", "raytrace:64:vertex"],
                    &["raytrace:256"],
                ),
            },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::{SharedGpu, by_name, check};

    /// Every name of every suite parses, without a device.
    #[test]
    fn every_method_of_every_suite_is_a_valid_name() {
        for family in Suite::Full.families() {
            for method in &family.methods {
                assert!(check(method).is_ok(), "{method}: {:?}", check(method));
            }
        }
    }

    #[test]
    #[cfg_attr(
        skip_gpu_tests,
        ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
    )]
    fn every_method_of_every_suite_builds_by_name() {
        let context = shadow_core::gpu::test_context();
        let gpu = SharedGpu::with(context);
        for family in Suite::Full.families() {
            for method in &family.methods {
                let built = by_name(method, &gpu);
                assert!(built.is_ok(), "{method}: {:?}", built.err());
            }
        }
    }

    #[test]
    fn suites_grow_from_quick_to_full() {
        let methods =
            |s: Suite| -> Vec<&str> { s.families().into_iter().flat_map(|f| f.methods).collect() };
        let (quick, default, full) = (
            methods(Suite::Quick),
            methods(Suite::Default),
            methods(Suite::Full),
        );
        assert!(quick.iter().all(|m| default.contains(m)));
        assert!(default.iter().all(|m| full.contains(m)));
        assert!(quick.len() < default.len() && default.len() < full.len());
        assert!(Suite::Quick.scenes().len() < Suite::Default.scenes().len());
    }
}
