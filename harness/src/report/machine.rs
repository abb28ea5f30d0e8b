//! Where the numbers were measured: the CPU, its SIMD extensions, the GPU
//! adapter, the build.

use serde::{Deserialize, Serialize};

/// Where and how the numbers were measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MachineInfo {
    pub cpu: String,
    /// The SIMD extensions the CPU reports that the methods' code paths use.
    pub cpu_features: Vec<String>,
    pub threads: usize,
    /// The wgpu adapter the GPU methods ran on; `None` when no GPU method ran.
    pub adapter: Option<String>,
    pub profile: String,
    /// `git describe` of the source tree the binary was built from (with
    /// `-dirty` for local changes), when it was a git checkout.
    pub revision: Option<String>,
}

impl MachineInfo {
    pub fn detect(adapter: Option<String>) -> MachineInfo {
        MachineInfo {
            cpu: cpu_name(cpuinfo().as_deref()),
            cpu_features: cpu_features().into_iter().map(String::from).collect(),
            threads: rayon::current_num_threads(),
            adapter,
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
            .to_string(),
            revision: revision(),
        }
    }

    /// Whether the adapter is a software rasterizer (Mesa's llvmpipe or
    /// lavapipe, or one that says so): its GPU timings are CPU timings.
    pub fn software_adapter(&self) -> bool {
        self.adapter.as_deref().is_some_and(|a| {
            let a = a.to_lowercase();
            a.contains("llvmpipe") || a.contains("lavapipe") || a.contains("software")
        })
    }

    /// The CPU's model name with its family and model numbers, which tell
    /// generations apart where the name does not (a virtual machine's "AMD
    /// EPYC" may be a Zen 3 or a Zen 4, whose timings differ twofold): for
    /// benchmark printouts. Without them, as [`MachineInfo::detect`] names it.
    pub fn cpu_generation() -> String {
        let info = cpuinfo();
        let info = info.as_deref();
        let name = cpu_name(info);
        let field = |key| info.and_then(|i| cpuinfo_field(i, key));
        match (field("cpu family"), field("model")) {
            (Some(family), Some(model)) => format!("{name} (family {family}, model {model})"),
            _ => name,
        }
    }
}

/// The SIMD extensions detected at run time that matter to the methods.
fn cpu_features() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        let mut found = Vec::new();
        macro_rules! check {
            ($($f:tt),*) => {$(
                if std::arch::is_x86_feature_detected!($f) {
                    found.push($f);
                }
            )*};
        }
        check!(
            "sse4.2", "avx", "avx2", "fma", "bmi1", "bmi2", "popcnt", "avx512f", "avx512bw",
            "avx512dq", "avx512vl"
        );
        found
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec::new()
}

/// `git describe --always --dirty` of the source tree the binary was built
/// from (captured by the build script), if it was a git checkout.
fn revision() -> Option<String> {
    option_env!("HARNESS_REVISION")
        .filter(|r| !r.is_empty())
        .map(str::to_owned)
}

/// The text of /proc/cpuinfo (Linux only).
fn cpuinfo() -> Option<String> {
    std::fs::read_to_string("/proc/cpuinfo").ok()
}

/// The first value of `key` in /proc/cpuinfo's text `info`.
fn cpuinfo_field<'a>(info: &'a str, key: &str) -> Option<&'a str> {
    info.lines()
        .filter_map(|l| l.split_once(':'))
        .find(|(k, _)| k.trim() == key)
        .map(|(_, value)| value.trim())
}

/// The CPU's model name from /proc/cpuinfo's text, or the architecture
/// where it is not known.
fn cpu_name(info: Option<&str>) -> String {
    info.and_then(|i| cpuinfo_field(i, "model name"))
        .map_or_else(|| std::env::consts::ARCH.to_owned(), str::to_owned)
}
