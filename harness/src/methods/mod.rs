//! The methods the harness runs, by name: one vocabulary for the command
//! line, the suites, the report, the benches and the tests.
//!
//! A name is a family and its options, each after a `:`
//! (`occlusion-query:k=66:queries`; [`shadow_core::name`]). [`parse`] reads
//! one without a device into a [`MethodSpec`], whose [`MethodSpec::name`] is
//! the name every report prints (the settings in the family's own order,
//! those equal to the preset left out) and builds the method when asked.
//! [`Methods`] holds the families; a host adds its own beside the built-in
//! ones with [`Methods::with`].

mod shared_gpu;

use std::{fmt, sync::Arc};

use occlusion_query::OcclusionQuery;
use shadow_core::{
    Error, Result, ShadowMethod,
    gpu::{GpuContext, GpuStages},
    name::{MethodName, closest},
    sh::ShOrder,
};

use crate::baselines::{RayTrace, Unshadowed};
pub use shared_gpu::SharedGpu;

/// Makes a CPU method.
type MakeCpu = dyn Fn() -> Box<dyn ShadowMethod> + Send + Sync;

/// Makes a GPU method on a device.
type MakeGpu = dyn Fn(Arc<GpuContext>) -> Result<Box<dyn GpuStages>> + Send + Sync;

/// How a [`MethodSpec`] builds its method.
#[derive(Clone)]
pub enum Build {
    /// A CPU method.
    Cpu(Arc<MakeCpu>),
    /// A GPU method, on the run's shared device.
    Gpu(Arc<MakeGpu>),
}

impl Build {
    /// A CPU method made by `make`.
    pub fn cpu(make: impl Fn() -> Box<dyn ShadowMethod> + Send + Sync + 'static) -> Build {
        Build::Cpu(Arc::new(make))
    }

    /// A GPU method made by `make` on the run's device; its stages can
    /// also be recorded into a host's encoder ([`Built::Gpu`]).
    pub fn gpu(
        make: impl Fn(Arc<GpuContext>) -> Result<Box<dyn GpuStages>> + Send + Sync + 'static,
    ) -> Build {
        Build::Gpu(Arc::new(make))
    }
}

/// A built method, with what a host can do with it: a CPU method's stages
/// are calls, a GPU method's stages can also be recorded into the host's
/// own command encoder ([`GpuStages`]).
pub enum Built {
    Cpu(Box<dyn ShadowMethod>),
    Gpu(Box<dyn GpuStages>),
}

impl Built {
    pub fn method(&self) -> &dyn ShadowMethod {
        match self {
            Built::Cpu(m) => m.as_ref(),
            Built::Gpu(m) => m.as_ref(),
        }
    }

    pub fn method_mut(&mut self) -> &mut dyn ShadowMethod {
        match self {
            Built::Cpu(m) => m.as_mut(),
            Built::Gpu(m) => m.as_mut(),
        }
    }

    pub fn into_method(self) -> Box<dyn ShadowMethod> {
        match self {
            Built::Cpu(m) => m,
            Built::Gpu(m) => m,
        }
    }
}

/// What a family's reader returns for a name: the name the method prints
/// (its [`ShadowMethod::name`]) and how to build it.
pub type Read = Result<(String, Build)>;

/// A method family: the first word of a name, what it is, its options and
/// how it reads a name of its own.
#[derive(Clone)]
pub struct Family {
    pub name: &'static str,
    pub about: &'static str,
    /// Its options as `harness list` shows them (`k=N`, `queries`).
    pub options: &'static [&'static str],
    read: Arc<dyn Fn(&str) -> Read + Send + Sync>,
}

impl Family {
    /// A family named `name` whose `read` takes a whole name of the family
    /// (`name` alone or followed by `:` and options) and fails with
    /// [`Error::InvalidConfig`] on a bad one.
    pub fn new(
        name: &'static str,
        about: &'static str,
        options: &'static [&'static str],
        read: impl Fn(&str) -> Read + Send + Sync + 'static,
    ) -> Family {
        Family {
            name,
            about,
            options,
            read: Arc::new(read),
        }
    }
}

impl fmt::Debug for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// A method as named, read without a device: its family, the name it
/// prints, and how to build it.
#[derive(Clone)]
pub struct MethodSpec {
    family: &'static str,
    name: String,
    build: Build,
}

impl MethodSpec {
    /// The name the method prints, which [`parse`] reads back to the same
    /// settings.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The family's name (`hemi-raster`).
    pub fn family(&self) -> &'static str {
        self.family
    }

    /// Whether it runs on the GPU.
    pub fn needs_gpu(&self) -> bool {
        matches!(self.build, Build::Gpu(_))
    }

    /// Builds the method, GPU methods on `gpu`'s device. Fails where the
    /// method calls itself by another name than the spec's: a family's
    /// method prints the name it was read from.
    pub fn build(&self, gpu: &SharedGpu) -> Result<Box<dyn ShadowMethod>> {
        self.build_stages(gpu).map(Built::into_method)
    }

    /// Builds the method as [`MethodSpec::build`] does, keeping a GPU
    /// method's recordable stages.
    pub fn build_stages(&self, gpu: &SharedGpu) -> Result<Built> {
        let built = match &self.build {
            Build::Cpu(make) => Built::Cpu(make()),
            Build::Gpu(make) => Built::Gpu(make(gpu.get()?)?),
        };
        let method = built.method();
        if method.name() != self.name {
            return Err(Error::config(
                &self.name,
                format!(
                    "the {} family built a method that calls itself {:?}",
                    self.family,
                    method.name()
                ),
            ));
        }
        Ok(built)
    }
}

impl fmt::Debug for MethodSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

impl fmt::Display for MethodSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

/// The families a run knows.
#[derive(Clone, Debug)]
pub struct Methods {
    families: Vec<Family>,
}

impl Default for Methods {
    fn default() -> Methods {
        Methods::builtin()
    }
}

impl Methods {
    /// The built-in families: `unshadowed`, `hemi-raster`, `occlusion-query`,
    /// `deferred-shadow` and `raytrace`.
    pub fn builtin() -> Methods {
        Methods {
            families: vec![
                Family::new(
                    "unshadowed",
                    "SH lighting (order 9) with no visibility: the upper bound",
                    &["order=N"],
                    unshadowed,
                ),
                Family::new(
                    "hemi-raster",
                    "Kautz et al. 2004: CPU hemispherical rasterization to SH transfer (32×32 masks, order 5, two-level mesh hierarchy); pvs: per-vertex visible sets from the scene's own frames (§3.2), flat: no hierarchy, paper: as published (SH from 4×4 blocks, a tenth of the triangles, the one-ring)",
                    hemi_raster::name::OPTIONS,
                    |text| {
                        let config = hemi_raster::Config::from_name(text)?;
                        let build =
                            Build::cpu(move || Box::new(hemi_raster::HemiRaster::new(config)));
                        Ok((config.name(), build))
                    },
                ),
                Family::new(
                    "occlusion-query",
                    "Sattler et al. 2004: GPU visibility of every vertex toward 258 lightsphere directions by depth compare in a compute pass; queries: the paper's per-vertex occlusion queries, paper: the method as published",
                    occlusion_query::name::OPTIONS,
                    |text| {
                        let config = occlusion_query::Config::from_name(text)?;
                        let build = Build::gpu(move |gpu| {
                            Ok(Box::new(OcclusionQuery::new(gpu, config)?) as Box<dyn GpuStages>)
                        });
                        Ok((config.name(), build))
                    },
                ),
                Family::new(
                    "deferred-shadow",
                    "Tamura et al.: per-vertex precomputed self-shadowing plus per-pixel shadows from other objects through occlusion maps (32 area lights, 64² maps) on the GPU",
                    deferred_shadow::name::OPTIONS,
                    |text| {
                        let config = deferred_shadow::Config::from_name(text)?;
                        let name = config.name();
                        let build = Build::gpu(move |gpu| {
                            let method = deferred_shadow::DeferredShadow::new(gpu, config.clone())?;
                            Ok(Box::new(method) as Box<dyn GpuStages>)
                        });
                        Ok((name, build))
                    },
                ),
                Family::new(
                    "raytrace",
                    "Monte-Carlo ray tracing, N MIS iterations per vertex and per pixel (raytrace:16); vertex: images interpolated from the vertices as a per-vertex method's",
                    &["N", "vertex"],
                    raytrace,
                ),
            ],
        }
    }

    /// These families and `family`; fails where one has its name.
    pub fn with(mut self, family: Family) -> Result<Methods> {
        if self.families.iter().any(|f| f.name == family.name) {
            return Err(Error::config(
                family.name,
                "a method family of that name exists",
            ));
        }
        self.families.push(family);
        Ok(self)
    }

    pub fn families(&self) -> &[Family] {
        &self.families
    }

    /// Reads `name` (no device is opened): its family is the text before
    /// the first `:`. A typo in the family or an option is an
    /// [`Error::InvalidConfig`] naming the closest valid word.
    pub fn parse(&self, name: &str) -> Result<MethodSpec> {
        let word = name.split(':').next().unwrap_or(name);
        let Some(family) = self.families.iter().find(|f| f.name == word) else {
            let names = self.families.iter().map(|f| f.name);
            let hint = closest(word, names.clone())
                .map_or(String::new(), |c| format!(" (did you mean {c}?)"));
            return Err(Error::config(
                name,
                format!(
                    "no method family {word:?}{hint}; families are {}",
                    names.collect::<Vec<_>>().join(", ")
                ),
            ));
        };
        let (canonical, build) = (family.read)(name)?;
        Ok(MethodSpec {
            family: family.name,
            name: canonical,
            build,
        })
    }

    /// Every name of `names` read, or the first error.
    pub fn parse_all<S: AsRef<str>>(&self, names: &[S]) -> Result<Vec<MethodSpec>> {
        names.iter().map(|n| self.parse(n.as_ref())).collect()
    }
}

/// `name` read by the built-in families ([`Methods::parse`]).
pub fn parse(name: &str) -> Result<MethodSpec> {
    Methods::builtin().parse(name)
}

/// The method `name` gives, built by the built-in families; GPU methods run
/// on `gpu`'s device.
pub fn by_name(name: &str, gpu: &SharedGpu) -> Result<Box<dyn ShadowMethod>> {
    parse(name)?.build(gpu)
}

/// `unshadowed`, or `unshadowed:order=N`.
fn unshadowed(text: &str) -> Read {
    let name = MethodName::parse(text, "unshadowed")?;
    let mut order = Unshadowed::ORDER;
    for option in name.options() {
        match (option.key, option.value) {
            ("order", Some(n)) => order = name.value(option, n)?,
            _ => return Err(name.unknown(option, &["order=N"])),
        }
    }
    let order = ShOrder::new(order).ok_or_else(|| {
        name.error(format!(
            "order={order}: SH orders are 1 to {}",
            ShOrder::MAX.get()
        ))
    })?;
    let method = Unshadowed::new(order);
    let printed = method.name().to_string();
    Ok((
        printed,
        Build::cpu(move || Box::new(Unshadowed::new(order))),
    ))
}

/// `raytrace:N` or `raytrace:N:vertex`, N ≥ 2.
fn raytrace(text: &str) -> Read {
    let name = MethodName::parse(text, "raytrace")?;
    let mut iterations = None;
    let mut per_vertex = false;
    for option in name.options() {
        match (option.key, option.value) {
            ("vertex", None) => per_vertex = true,
            (n, None) if n.bytes().all(|b| b.is_ascii_digit()) => {
                iterations = Some(name.value::<u32>(option, n)?)
            }
            _ => return Err(name.unknown(option, &["N", "vertex"])),
        }
    }
    let iterations = iterations.filter(|&i| i >= 2).ok_or_else(|| {
        name.error("the iteration count must be an integer ≥ 2 (raytrace:N or raytrace:N:vertex)")
    })?;
    let make = move || {
        Box::new(if per_vertex {
            RayTrace::per_vertex(iterations, RayTrace::SEED)
        } else {
            RayTrace::new(iterations, RayTrace::SEED)
        }) as Box<dyn ShadowMethod>
    };
    Ok((make().name().to_string(), Build::cpu(make)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names are read without a device; the printed name reads back to
    /// itself.
    #[test]
    fn names_read_to_the_names_methods_print() {
        for (typed, printed) in [
            ("unshadowed", "unshadowed"),
            ("unshadowed:order=5", "unshadowed:order=5"),
            ("hemi-raster:mask=16:pvs", "hemi-raster:pvs:mask=16"),
            ("occlusion-query:k=66:paper", "occlusion-query:paper:k=66"),
            (
                "occlusion-query:filter:queries:k=66",
                "occlusion-query:k=66:queries:filter",
            ),
            ("deferred-shadow:map=128:q=8", "deferred-shadow:q=8:map=128"),
            ("raytrace:16", "raytrace:16"),
            ("raytrace:vertex:8", "raytrace:8:vertex"),
        ] {
            let spec = parse(typed).unwrap();
            assert_eq!(spec.name(), printed, "{typed}");
            assert_eq!(parse(printed).unwrap().name(), printed);
        }
        assert!(parse("occlusion-query").unwrap().needs_gpu());
        assert!(!parse("hemi-raster").unwrap().needs_gpu());
        assert_eq!(parse("raytrace:4").unwrap().family(), "raytrace");
    }

    /// Typos and settings out of range are configuration errors, and a typo
    /// names the closest valid word.
    #[test]
    fn bad_names_are_configuration_errors() {
        for (bad, says) in [
            ("occlusion-query:k=100", "4098"),
            ("occlusion-queryx", "did you mean occlusion-query?"),
            ("deferred-shadow:q=0", "area lights"),
            ("hemi-raster:mask=24", "16, 32 or 64"),
            ("hemi-rastr", "did you mean hemi-raster?"),
            ("raytrace:1", "≥ 2"),
            ("raytrace:1:vertex", "≥ 2"),
            ("raytrace", "≥ 2"),
            ("raytrace:16:vertx", "did you mean vertex?"),
            ("unshadowed:order=0", "SH orders"),
            ("nonesuch", "families are unshadowed"),
        ] {
            let err = parse(bad).unwrap_err();
            assert!(matches!(err, Error::InvalidConfig { .. }), "{bad}: {err}");
            assert!(err.to_string().contains(says), "{bad}: {err}");
        }
    }

    /// A family of a host's own is read and built beside the built-in
    /// ones; a name taken is refused.
    #[test]
    fn hosts_add_families() {
        let methods = Methods::builtin()
            .with(Family::new(
                "flat-sky",
                "unshadowed, order 3",
                &[],
                |text| {
                    MethodName::parse(text, "flat-sky")?;
                    Ok((
                        "unshadowed:order=3".into(),
                        Build::cpu(|| Box::new(Unshadowed::new(ShOrder::new(3).unwrap()))),
                    ))
                },
            ))
            .unwrap();
        let spec = methods.parse("flat-sky").unwrap();
        assert_eq!(spec.family(), "flat-sky");
        assert!(spec.build(&SharedGpu::new()).is_ok());
        let renamed = Family::new("hemi-raster", "", &[], unshadowed);
        assert!(Methods::builtin().with(renamed).is_err());
    }

    /// A family whose method prints another name than it was read to is
    /// refused when built.
    #[test]
    fn built_methods_print_their_spec_name() {
        let methods = Methods::builtin()
            .with(Family::new("liar", "", &[], |_| {
                Ok((
                    "liar".into(),
                    Build::cpu(|| Box::new(Unshadowed::new(ShOrder::new(3).unwrap()))),
                ))
            }))
            .unwrap();
        let err = methods
            .parse("liar")
            .unwrap()
            .build(&SharedGpu::new())
            .err();
        assert!(err.is_some_and(|e| e.to_string().contains("calls itself")));
    }
}
