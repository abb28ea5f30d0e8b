//! The methods the harness can run, by name, and the one GPU device the GPU
//! methods of a run share.

use std::num::NonZeroU32;
use std::sync::{Arc, OnceLock};

use occlusion_query::{Filtering, Level, Occluder, OcclusionQuery, VertexTest};
use shadow_core::{Error, Result, ShadowMethod, gpu::GpuContext, sh::ShOrder};

use crate::baselines::{RayTrace, Unshadowed};

/// The GPU context every GPU method of a run shares, opened when the first
/// one is built (so that a run of CPU methods needs no adapter).
#[derive(Debug, Default)]
pub struct SharedGpu {
    context: OnceLock<std::result::Result<Arc<GpuContext>, String>>,
}

impl SharedGpu {
    /// A device opened on first use ([`GpuContext::new`]).
    pub fn new() -> SharedGpu {
        SharedGpu::default()
    }

    /// `context` for every GPU method (a test's, or a host's device).
    pub fn with(context: Arc<GpuContext>) -> SharedGpu {
        let shared = SharedGpu::default();
        let _ = shared.context.set(Ok(context));
        shared
    }

    /// The shared context, opening it on first use; a failure to open is
    /// the same error for every later call.
    pub fn get(&self) -> Result<Arc<GpuContext>> {
        let opened = self.context.get_or_init(|| {
            GpuContext::new().map(Arc::new).map_err(|e| match e {
                Error::Gpu(message) => message,
                other => other.to_string(),
            })
        });
        opened.clone().map_err(Error::Gpu)
    }

    /// The adapter the shared device runs on, once a method opened it.
    pub fn adapter(&self) -> Option<String> {
        match self.context.get()? {
            Ok(context) => Some(context.adapter.to_string()),
            Err(_) => None,
        }
    }
}

/// Names accepted by [`by_name`], with what each is.
pub const METHODS: &[(&str, &str)] = &[
    (
        "unshadowed",
        "SH lighting (order 9) with no visibility: the upper bound",
    ),
    (
        "hemi-raster",
        "Kautz et al. 2004: CPU hemispherical rasterization to SH transfer (32×32 masks, order 5, two-level mesh hierarchy)",
    ),
    (
        "hemi-raster:flat",
        "the same without the hierarchy: every triangle blocks every vertex (what the hierarchy costs in error; hemi_raster::Config::accurate())",
    ),
    (
        "hemi-raster:pvs",
        "hemi-raster with per-vertex potentially visible sets built from the scene's own frames (§3.2) and a near field of 6 coarse-triangle radii: the flat mesh's accuracy from far fewer blockers (hemi_raster::Config::fast())",
    ),
    (
        "hemi-raster:mask=N",
        "hemi-raster with N×N masks (16, 32 or 64); more options: table=N (plane-table cells per cube-face side, even), order=N (SH order), reach=N (the hierarchy's near reach, in mean coarse-triangle radii), min=N (its least coarse triangle count), pvs=N (sets from every Nth frame), paper (SH from 4×4 blocks, as published), direct (no SH), window=none|hanning|lanczos (σ-factors on the lighting's SH bands), combined with flat or pvs (e.g. hemi-raster:pvs:mask=16:order=3)",
    ),
    (
        "occlusion-query",
        "Sattler et al. 2004: GPU visibility of every vertex toward 258 lightsphere directions, by depth compare in a compute pass; options after ':' (e.g. occlusion-query:queries:k=66)",
    ),
    (
        "occlusion-query:queries",
        "the same with the paper's per-vertex occlusion queries (slow on a software rasterizer)",
    ),
    (
        "occlusion-query:paper",
        "the paper as published: queries, equal weights, the raw quadrature, glPolygonOffset(1, 1), the lightsphere on the axes; other options change it (occlusion-query:paper:k=66)",
    ),
    (
        "occlusion-query:k=N",
        "N lightsphere directions (6, 18, 66, 258, 1026 or 4098); more options: map=N (depth map side), filter (vertex filtering, §4.1), axes (the octahedron on the coordinate axes, as in the paper), blur=F (the environment's prefilter width in lightsphere spacings), simplified (occluders simplified while their surface moves by at most a texel of the depth maps; simplified=TEXELS for another bound)",
    ),
    (
        "deferred-shadow",
        "Tamura et al.: per-vertex precomputed self-shadowing plus per-pixel shadows from other objects through occlusion maps (32 area lights, 64² maps) on the GPU; options after ':' (e.g. deferred-shadow:q=64:map=128)",
    ),
    (
        "deferred-shadow:q=N",
        "N area lights (1..=256); more options: map=N (occlusion map side), rays=N (precomputation rays per vertex), uncorrected (no self-visibility correction of the occlusion, eq. 4 instead of eq. 8), window=none|hanning|lanczos (σ-factors on the SH bands of the self-shadowed lighting)",
    ),
    (
        "raytrace:N",
        "Monte-Carlo ray tracing, N MIS iterations per vertex and per pixel (e.g. raytrace:16)",
    ),
    (
        "raytrace:N:vertex",
        "the same per vertex, its images interpolated from the vertices as a per-vertex method's",
    ),
];

/// What a method's name sets, read without building it: the GPU methods'
/// configurations (built later on a device), or a CPU method already built.
enum Parsed {
    OcclusionQuery(occlusion_query::Config),
    DeferredShadow(deferred_shadow::Config),
    Cpu(Box<dyn ShadowMethod>),
}

/// Checks that `name` names a method with valid settings without building
/// it: no GPU device is opened.
pub fn check(name: &str) -> Result<()> {
    parse(name).map(drop)
}

/// Builds a method from its name; GPU methods run on `gpu`'s device.
pub fn by_name(name: &str, gpu: &SharedGpu) -> Result<Box<dyn ShadowMethod>> {
    Ok(match parse(name)? {
        Parsed::OcclusionQuery(config) => Box::new(OcclusionQuery::new(gpu.get()?, config)?),
        Parsed::DeferredShadow(config) => {
            Box::new(deferred_shadow::DeferredShadow::new(gpu.get()?, config)?)
        }
        Parsed::Cpu(method) => method,
    })
}

/// The family and settings `name` gives.
fn parse(name: &str) -> Result<Parsed> {
    if name.starts_with("occlusion-query") {
        return occlusion_query_config(name).map(Parsed::OcclusionQuery);
    }
    if name.starts_with("deferred-shadow") {
        return deferred_shadow_config(name).map(Parsed::DeferredShadow);
    }
    cpu_method(name).map(Parsed::Cpu)
}

/// A method that runs on the CPU, from its name.
fn cpu_method(name: &str) -> Result<Box<dyn ShadowMethod>> {
    if name == "unshadowed" {
        let order = ShOrder::new(9).expect("9 is a valid SH order");
        return Ok(Box::new(Unshadowed::new(order)));
    }
    if name.starts_with("hemi-raster") {
        return Ok(Box::new(hemi_raster::HemiRaster::new(hemi_raster_config(
            name,
        )?)));
    }
    if let Some(n) = name.strip_prefix("raytrace:") {
        let (count, vertex) = match n.strip_suffix(":vertex") {
            Some(count) => (count, true),
            None => (n, false),
        };
        let iterations: u32 = count.parse().ok().filter(|&i| i >= 2).ok_or_else(|| {
            Error::config(
                name,
                "the iteration count must be an integer ≥ 2 (raytrace:N or raytrace:N:vertex)",
            )
        })?;
        return Ok(Box::new(if vertex {
            RayTrace::per_vertex(iterations, 0xba5e)
        } else {
            RayTrace::new(iterations, 0xba5e)
        }));
    }
    Err(Error::config(
        name,
        format!(
            "no such method; methods are {}",
            METHODS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
        ),
    ))
}

/// The options after `family` in method `name`, each after a ':'.
fn options<'a>(name: &'a str, family: &str) -> Result<std::str::Split<'a, char>> {
    let mut options = name
        .strip_prefix(family)
        .ok_or_else(|| Error::config(name, format!("not a {family} method")))?
        .split(':');
    if options.next() != Some("") {
        return Err(Error::config(name, "options follow the name after ':'"));
    }
    Ok(options)
}

/// The SH window `value` of option `window=` of method `name`.
fn window(name: &str, value: &str) -> Result<shadow_core::sh::Window> {
    shadow_core::sh::Window::from_name(value).ok_or_else(|| {
        Error::config(
            name,
            format!("window={value}: windows are none, hanning, lanczos"),
        )
    })
}

/// The value of `option` of method `name` as a whole number.
fn whole(name: &str, option: &str, value: &str) -> Result<u32> {
    value
        .parse()
        .map_err(|_| Error::config(name, format!("{option}: not a whole number")))
}

/// The configuration the options of `occlusion-query` in `name` give. The
/// preset `paper` ([`occlusion_query::Config::paper`]) is the base the other
/// options change, wherever it stands among them; `axes` puts the
/// lightsphere on the coordinate axes (the paper's orientation), `blur=F`
/// sets the environment's prefilter width in lightsphere spacings.
fn occlusion_query_config(name: &str) -> Result<occlusion_query::Config> {
    use occlusion_query::{Config, Orientation};
    let bad = |what: String| Err(Error::config(name, what));
    let paper = options(name, "occlusion-query")?.any(|option| option == "paper");
    let mut config = if paper {
        Config::paper()
    } else {
        Config::default()
    };
    for option in options(name, "occlusion-query")? {
        match option.split_once('=') {
            None if option == "paper" => {}
            None if option == "queries" => config.test = VertexTest::OcclusionQuery,
            None if option == "filter" => config.filtering = Some(Filtering::default()),
            None if option == "simplified" => config.occluder = Config::fast().occluder,
            None if option == "axes" => config.orientation = Orientation::Axes,
            Some(("k", k)) => match k.parse().ok().and_then(Level::with_directions) {
                Some(level) => config.level = level,
                None => {
                    return bad(format!(
                        "k={k}: the lightsphere has 6, 18, 66, 258, 1026 or 4098 directions"
                    ));
                }
            },
            Some(("simplified", t)) => match t.parse() {
                Ok(texels) => config.occluder = Occluder::Simplified { texels },
                Err(_) => return bad(format!("simplified={t}: not a number")),
            },
            Some(("blur", b)) => match b.parse() {
                Ok(width) => config.prefilter = width,
                Err(_) => return bad(format!("blur={b}: not a number")),
            },
            Some(("map", n)) => config.map_resolution = whole(name, option, n)?,
            _ => {
                return bad(format!(
                    "unknown option {option:?}; options are queries, paper, filter, axes, simplified, simplified=TEXELS, k=N, map=N, blur=F"
                ));
            }
        }
    }
    config.check()?;
    Ok(config)
}

/// The configuration the options of `hemi-raster` in `name` give, applied
/// left to right: the presets' switches (`flat`:
/// [`hemi_raster::Config::accurate`]'s flat blockers; `pvs`:
/// [`hemi_raster::Config::fast`]'s visible sets and wide near reach;
/// `paper`: [`hemi_raster::Config::paper`]'s block
/// integration; `pvs=N`: sets from every Nth frame), `direct`, and
/// `mask=N`, `table=N`, `order=N`, `reach=N`, `min=N` (the hierarchy's
/// least coarse triangle count).
pub fn hemi_raster_config(name: &str) -> Result<hemi_raster::Config> {
    use hemi_raster::{Config, Hierarchy, Integration, MaskResolution, Pvs};
    let mut config = Config::default();
    let bad = |what: String| Err(Error::config(name, what));
    for option in options(name, "hemi-raster")? {
        let number = |value| whole(name, option, value);
        match option.split_once('=') {
            None if option == "flat" => config.hierarchy = Hierarchy::Flat,
            None if option == "pvs" => {
                config.pvs = Pvs::EVERY_FRAME;
                config.hierarchy = config.hierarchy.with_near_reach(Hierarchy::WIDE_NEAR_REACH);
            }
            Some(("pvs", n)) => {
                let stride = NonZeroU32::new(number(n)?)
                    .ok_or_else(|| Error::config(name, "pvs=0: the stride is at least 1"))?;
                config.pvs = Pvs::Animation { stride };
                config.hierarchy = config.hierarchy.with_near_reach(Hierarchy::WIDE_NEAR_REACH);
            }
            Some(("min", n)) => {
                config.hierarchy = config.hierarchy.with_min_coarse_triangles(number(n)?)
            }
            None if option == "paper" => config.integration = Integration::ShBlocks,
            None if option == "direct" => config.integration = Integration::Direct,
            Some(("window", w)) => config.window = window(name, w)?,
            Some(("mask", n)) => {
                config.mask_resolution = match number(n)? {
                    16 => MaskResolution::R16,
                    32 => MaskResolution::R32,
                    64 => MaskResolution::R64,
                    _ => return bad(format!("mask={n}: masks are 16, 32 or 64 pixels a side")),
                }
            }
            Some(("table", n)) => config.lut_resolution = number(n)? as usize,
            Some(("reach", n)) => {
                let reach = u8::try_from(number(n)?)
                    .map_err(|_| Error::config(name, format!("{option}: at most 255")))?;
                config.hierarchy = config.hierarchy.with_near_reach(reach);
            }
            Some(("order", n)) => match ShOrder::new(number(n)?) {
                Some(order) => config.order = order,
                _ => {
                    return bad(format!(
                        "order={n}: SH orders are 1 to {}",
                        ShOrder::MAX.get()
                    ));
                }
            },
            _ => {
                return bad(format!(
                    "unknown option {option:?}; options are flat, pvs, pvs=N, paper, direct, mask=N, table=N, order=N, reach=N, min=N, window=none|hanning|lanczos"
                ));
            }
        }
    }
    config.validate()?;
    Ok(config)
}

/// The configuration the options of `deferred-shadow` in `name` give.
fn deferred_shadow_config(name: &str) -> Result<deferred_shadow::Config> {
    let mut config = deferred_shadow::Config::default();
    let bad = |what: String| Err(Error::config(name, what));
    for option in options(name, "deferred-shadow")? {
        let number = |value| whole(name, option, value);
        match option.split_once('=') {
            None if option == "uncorrected" => config.self_visibility = false,
            Some(("window", w)) => config.window = window(name, w)?,
            Some(("q", q)) => config.lights = number(q)? as usize,
            Some(("map", n)) => config.map_resolution = number(n)?,
            Some(("rays", n)) => config.rays = number(n)?,
            _ => {
                return bad(format!(
                    "unknown option {option:?}; options are q=N, map=N, rays=N, uncorrected, window=none|hanning|lanczos"
                ));
            }
        }
    }
    config.check()?;
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hemi_raster_names_read_as_its_presets() {
        use hemi_raster::{Config, Hierarchy, Pvs};
        let read = |name| hemi_raster_config(name).unwrap();
        assert_eq!(read("hemi-raster"), Config::default());
        assert_eq!(read("hemi-raster:pvs"), Config::fast());
        assert_eq!(read("hemi-raster:flat"), Config::accurate());
        assert_eq!(read("hemi-raster:paper"), Config::paper());
        let half = read("hemi-raster:min=40:pvs=2");
        assert_eq!(
            half.pvs,
            Pvs::Animation {
                stride: NonZeroU32::new(2).unwrap()
            }
        );
        assert_eq!(
            half.hierarchy,
            Hierarchy::default()
                .with_min_coarse_triangles(40)
                .with_near_reach(Hierarchy::WIDE_NEAR_REACH)
        );
        assert!(hemi_raster_config("occlusion-query").is_err());
    }

    /// The preset `paper` is the base whatever its place among the options.
    #[test]
    fn occlusion_query_options_compose_in_any_order() {
        for name in ["occlusion-query:k=66:paper", "occlusion-query:paper:k=66"] {
            let config = occlusion_query_config(name).unwrap();
            let expected = occlusion_query::Config {
                level: Level::with_directions(66).unwrap(),
                ..occlusion_query::Config::paper()
            };
            assert_eq!(config, expected, "{name}");
        }
        let axes = occlusion_query_config("occlusion-query:blur=0.3:axes").unwrap();
        assert_eq!(axes.orientation, occlusion_query::Orientation::Axes);
        assert_eq!(axes.prefilter, 0.3);
        for bad in ["occlusion-query:blur=-1", "occlusion-query:blur=x"] {
            let err = occlusion_query_config(bad).unwrap_err();
            assert!(matches!(err, Error::InvalidConfig { .. }), "{bad}: {err}");
        }
    }

    /// Names are checked without a device: typos and settings out of range
    /// are configuration errors.
    #[test]
    fn bad_names_are_configuration_errors() {
        for bad in [
            "occlusion-query:k=100",
            "occlusion-query:map=x",
            "occlusion-query:fast",
            "occlusion-queryx",
            "deferred-shadow:q=0",
            "deferred-shadow:map=x",
            "deferred-shadow:fast",
            "hemi-raster:mask=24",
            "hemi-raster:table=63",
            "hemi-raster:order=0",
            "hemi-raster:reach=300",
            "hemi-raster:fast",
            "hemi-rasterx",
        ] {
            let err = check(bad).unwrap_err();
            assert!(matches!(err, Error::InvalidConfig { .. }), "{bad}: {err}");
        }
        assert!(check("raytrace:1").is_err() && check("raytrace:1:vertex").is_err());
        assert!(check("hemi-raster:pvs:window=lanczos").is_ok());
        assert!(check("deferred-shadow:q=8:window=hanning").is_ok());
        let unknown = check("nonesuch").err().map(|e| e.to_string());
        assert!(unknown.is_some_and(|e| e.contains("unshadowed")));
    }

    #[test]
    #[cfg_attr(
        skip_gpu_tests,
        ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
    )]
    fn every_listed_method_builds() {
        let context = shadow_core::gpu::test_context();
        let gpu = SharedGpu::with(context);
        let by_name = |name: &str| super::by_name(name, &gpu);
        for (name, _) in METHODS {
            let name = name
                .replace("mask=N", "mask=16")
                .replace("k=N", "k=66")
                .replace("q=N", "q=16")
                .replace(":N", ":8");
            assert!(by_name(&name).is_ok(), "{name}");
        }
        assert_eq!(
            by_name("occlusion-query:queries:k=66:filter")
                .unwrap()
                .name(),
            "occlusion-query-k66-queries-filtered"
        );
        for (method, name) in [
            ("hemi-raster:flat", "hemi-raster-flat"),
            ("hemi-raster:pvs", "hemi-raster-pvs"),
            (
                "hemi-raster:pvs:mask=16:table=64:order=3:paper",
                "hemi-raster-pvs-mask16-table64-order3-blocks",
            ),
            ("hemi-raster:pvs:reach=2", "hemi-raster-reach2-pvs"),
            ("hemi-raster:flat:pvs:direct", "hemi-raster-flat-pvs-direct"),
        ] {
            assert_eq!(by_name(method).unwrap().name(), name);
        }
        assert_eq!(
            by_name("raytrace:8:vertex").unwrap().name(),
            "raytrace-8-vertex"
        );
    }
}
