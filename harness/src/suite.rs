//! What `harness report` runs: which scenes, and each method family swept
//! over its own parameters, so that the report can chart a curve of time
//! against error per family instead of one point per method.
//!
//! Three suites trade coverage for time:
//!
//! * [`Suite::Quick`]: four small scenes, two or three settings a family
//!   (a first look, and what CI runs);
//! * [`Suite::Default`]: every built-in scene but those of
//!   [`FULL_ONLY_SCENES`], the sweeps below;
//! * [`Suite::Full`]: every scene, and the slow settings (1026 lightsphere
//!   directions, the paper's per-vertex occlusion queries, 256 area lights,
//!   256 rays a vertex), which take minutes per frame on the larger scenes.

use serde::{Deserialize, Serialize};

use crate::methods::{MethodSpec, Methods};

/// A method family and its sweep: its settings in order of cost.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// The family's name ([`MethodSpec::family`]), what the chart's legend
    /// calls it.
    pub family: &'static str,
    /// What varies along the sweep, for the chart's labels.
    pub parameter: &'static str,
    pub methods: Vec<MethodSpec>,
}

/// Scenes only the full suite runs (or `--scenes` names): the 35k-vertex
/// bunny took 236 of the default suite's 384 seconds from an empty cache
/// (its references 86, its sweeps 150) on a 2-thread AMD EPYC.
pub const FULL_ONLY_SCENES: &[&str] = &["bunny-35k"];

/// The ray tracer's family: the line the other methods have to beat.
pub const RAY_TRACER: &str = "raytrace";

/// The scene of the image strip: the bunny's contact shadow on a
/// two-triangle floor, which per-vertex methods cannot draw.
pub const STRIP_SCENE: &str = "bunny";

/// The settings of the strip, in order (those the suite ran are shown).
const STRIP_SETTINGS: [&str; 4] = [
    "deferred-shadow",
    "hemi-raster",
    "occlusion-query",
    "raytrace:64:vertex",
];

/// The specs of the built-in names `names` (constants of this module, read
/// by a test).
fn specs(names: &[&str]) -> Vec<MethodSpec> {
    Methods::builtin()
        .parse_all(names)
        .expect("the suites name valid settings")
}

/// The scenes whose time per image the report measures across widths: the
/// bunny's contact shadow (one still frame) and the skinned human (its
/// first frame); the full suite adds [`FULL_SCALING_SCENES`].
pub const SCALING_SCENES: [&str; 2] = ["bunny", "human"];

/// What the full suite adds to [`SCALING_SCENES`]: the chess board, whose
/// pieces cast on each other the shadows deferred shadowing is for.
pub const FULL_SCALING_SCENES: [&str; 1] = ["chess"];

/// The ray tracer's per-pixel settings timed across widths beside the
/// families' standard settings: the curve of time against error that the
/// other methods are compared with at equal error.
const SCALING_RAY_TRACER: [&str; 3] = ["raytrace:4", "raytrace:16", "raytrace:64"];

/// What each family tries on a stress scene where its standard setting
/// fails: the settings that address what the stress scenes break (SH
/// truncation under small lights, too few directions at the horizon, too
/// coarse maps, too few rays). The family without visibility has none.
pub const REMEDIES: [(&str, &[&str]); 4] = [
    ("hemi-raster", &["hemi-raster:direct", "hemi-raster:flat"]),
    (
        "occlusion-query",
        &["occlusion-query:k=1026", "occlusion-query:map=1024"],
    ),
    (
        "deferred-shadow",
        &["deferred-shadow:q=128", "deferred-shadow:map=128"],
    ),
    (RAY_TRACER, &["raytrace:256"]),
];

/// The remedies of `family` ([`REMEDIES`]); none for a family it does not
/// list.
pub fn remedies(family: &str) -> Vec<MethodSpec> {
    REMEDIES
        .iter()
        .find(|(f, _)| *f == family)
        .map_or_else(Vec::new, |(_, names)| specs(names))
}

/// How much the report runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum Suite {
    Quick,
    #[default]
    Default,
    Full,
}

impl Suite {
    /// The built-in scenes it runs.
    pub fn scenes(self) -> Vec<&'static str> {
        let all = crate::scenes::SCENES.iter().map(|s| s.name);
        match self {
            Suite::Quick => vec!["furnace", "wall", "bunny", "human"],
            Suite::Default => all.filter(|s| !FULL_ONLY_SCENES.contains(s)).collect(),
            Suite::Full => all.collect(),
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

    /// The settings the image strip shows, on [`STRIP_SCENE`], where the
    /// suite ran them.
    pub fn strip_settings() -> Vec<MethodSpec> {
        specs(&STRIP_SETTINGS)
    }

    /// The scenes of the resolution study, where the suite runs them.
    pub fn scaling_scenes(self) -> Vec<&'static str> {
        let mut scenes = SCALING_SCENES.to_vec();
        if self == Suite::Full {
            scenes.extend(FULL_SCALING_SCENES);
        }
        scenes
    }

    /// The image widths of the resolution study, in pixels.
    pub fn scaling_widths(self) -> &'static [u32] {
        match self {
            Suite::Quick => &[160, 320, 640, 1024],
            Suite::Default => &[160, 320, 640, 1024],
            Suite::Full => &[160, 256, 384, 512, 768, 1024, 1536, 2048],
        }
    }

    /// The settings the resolution study times on its scenes: each
    /// family's standard setting (the atlas's), and the ray tracer's
    /// per-pixel settings of the suite's sweep.
    pub fn scaling_settings(self) -> Vec<MethodSpec> {
        let atlas = self.atlas_names();
        let mut names: Vec<&str> = atlas
            .iter()
            .copied()
            .filter(|name| !name.starts_with(RAY_TRACER))
            .collect();
        let sweep = self.families();
        let traced = sweep.iter().filter(|s| s.family == RAY_TRACER);
        for spec in traced.flat_map(|s| &s.methods) {
            if SCALING_RAY_TRACER.contains(&spec.name()) && !names.contains(&spec.name()) {
                names.push(spec.name());
            }
        }
        specs(&names)
    }

    /// One setting per family that the atlas runs on every stress scene.
    pub fn atlas_settings(self) -> Vec<MethodSpec> {
        specs(&self.atlas_names())
    }

    fn atlas_names(self) -> [&'static str; 5] {
        match self {
            Suite::Quick => [
                "unshadowed",
                "hemi-raster",
                "occlusion-query:k=66",
                "deferred-shadow:q=8",
                "raytrace:16",
            ],
            Suite::Default | Suite::Full => [
                "unshadowed",
                "hemi-raster",
                "occlusion-query",
                "deferred-shadow",
                "raytrace:64",
            ],
        }
    }

    /// The families and their sweeps.
    pub fn families(self) -> Vec<Sweep> {
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
            specs(&m)
        };
        vec![
            Sweep {
                family: "unshadowed",
                parameter: "SH order 9, no visibility",
                methods: specs(&["unshadowed"]),
            },
            Sweep {
                family: "hemi-raster",
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
            Sweep {
                family: "occlusion-query",
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
            Sweep {
                family: "deferred-shadow",
                parameter: "area lights q, map side, L_o shared by 2×2 blocks",
                methods: pick(
                    &["deferred-shadow:q=8", "deferred-shadow"],
                    &[
                        "deferred-shadow:q=128",
                        "deferred-shadow:map=128",
                        "deferred-shadow:blocks",
                    ],
                    &["deferred-shadow:q=256"],
                ),
            },
            Sweep {
                family: RAY_TRACER,
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
    use crate::methods::SharedGpu;

    /// Every name of every suite is the name its method prints, and of the
    /// family it is listed under.
    #[test]
    fn every_name_of_every_suite_is_as_printed() {
        for suite in [Suite::Quick, Suite::Default, Suite::Full] {
            for sweep in suite.families() {
                for spec in &sweep.methods {
                    assert_eq!(spec.family(), sweep.family);
                    assert_eq!(
                        crate::methods::parse(spec.name()).unwrap().name(),
                        spec.name()
                    );
                }
            }
            for (spec, name) in suite.atlas_settings().iter().zip(suite.atlas_names()) {
                assert_eq!(spec.name(), name);
            }
        }
        for (spec, name) in Suite::strip_settings().iter().zip(STRIP_SETTINGS) {
            assert_eq!(spec.name(), name);
        }
        for (family, names) in REMEDIES {
            for (spec, name) in remedies(family).iter().zip(names) {
                assert_eq!((spec.name(), spec.family()), (*name, family));
            }
        }
    }

    #[test]
    #[cfg_attr(
        skip_gpu_tests,
        ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
    )]
    fn every_method_of_every_suite_builds() {
        let context = shadow_core::gpu::test_context();
        let gpu = SharedGpu::with(context);
        for sweep in Suite::Full.families() {
            for spec in &sweep.methods {
                let built = spec.build(&gpu);
                assert!(built.is_ok(), "{spec}: {:?}", built.err());
            }
        }
    }

    #[test]
    fn the_full_suite_times_chess_across_widths_too() {
        assert_eq!(Suite::Default.scaling_scenes(), SCALING_SCENES);
        assert!(Suite::Full.scaling_scenes().contains(&"chess"));
        let widths = Suite::Full.scaling_widths();
        assert!(widths[0] <= 160 && *widths.last().unwrap() >= 2048);
        for suite in [Suite::Quick, Suite::Default] {
            let widths = suite.scaling_widths();
            assert!(widths[0] <= 160 && *widths.last().unwrap() >= 1024);
        }
    }

    #[test]
    fn suites_grow_from_quick_to_full() {
        let methods = |s: Suite| -> Vec<String> {
            s.families()
                .into_iter()
                .flat_map(|f| f.methods)
                .map(|m| m.name().to_string())
                .collect()
        };
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
