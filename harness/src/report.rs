//! The comparison report: every method on every scene, time per stage and
//! error against the reference, as JSON (for tools) and Markdown (for people).

use std::{fmt::Write, path::Path};

use serde::Serialize;
use shadow_core::Result;

use crate::{
    chart::{Axes, Point, speed_vs_error},
    io::{write_atomic, write_json_atomic},
    run::RunResult,
};

/// The chart's file name beside the report.
const CHART: &str = "speed-vs-error.png";

/// Where and how the numbers were measured.
#[derive(Clone, Debug, Serialize)]
pub struct MachineInfo {
    pub cpu: String,
    pub threads: usize,
    /// The wgpu adapter the GPU methods ran on; `None` when no GPU method ran.
    pub adapter: Option<String>,
    pub profile: &'static str,
}

impl MachineInfo {
    pub fn detect(adapter: Option<String>) -> MachineInfo {
        MachineInfo {
            cpu: cpu_name(cpuinfo().as_deref()),
            threads: rayon::current_num_threads(),
            adapter,
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            },
        }
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

/// A scene's reference: how it was made and how noisy it is.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceInfo {
    pub scene: String,
    pub environment: String,
    pub frames: usize,
    pub vertices: usize,
    /// Worst per-frame relative L2 noise.
    pub noise: f32,
    pub rays: u64,
    /// Seconds spent computing it (0 when every frame came from the cache).
    pub seconds: f64,
    pub cached: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub machine: MachineInfo,
    pub references: Vec<ReferenceInfo>,
    pub runs: Vec<RunResult>,
    /// Method × scene pairs that could not run, and why.
    pub skipped: Vec<(String, String, String)>,
}

impl Report {
    /// Writes `report.json`, `report.md` and the speed-versus-error chart
    /// `speed-vs-error.png` into `dir`, each atomically.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_json_atomic(&dir.join("report.json"), self)?;
        let points: Vec<Point> = (self.runs.iter())
            .map(|r| Point {
                series: r.method.clone(),
                label: r.scene.clone(),
                error_percent: r.mean_error() as f64 * 100.0,
                frame_ms: r.frame_seconds() * 1e3,
            })
            .collect();
        speed_vs_error(&points, Axes::RADIANCE, &dir.join(CHART))?;
        write_atomic(&dir.join("report.md"), self.markdown().as_bytes())
    }

    pub fn markdown(&self) -> String {
        let m = &self.machine;
        let mut s = String::new();
        let _ = writeln!(s, "# Soft-shadow methods compared\n");
        let _ = writeln!(
            s,
            "Machine: {}, {} threads, {} build. GPU adapter: {}.\n",
            m.cpu,
            m.threads,
            m.profile,
            m.adapter
                .as_deref()
                .unwrap_or("none used (CPU methods only)")
        );
        let _ = writeln!(
            s,
            "Error is the relative L2 error over all vertices against the Monte-Carlo reference, \
             averaged over frames; p99 and max are per-vertex relative errors (floor 1% of the RMS \
             radiance); \"ref noise\" is the reference's own relative L2 noise, below which errors \
             cannot be told apart. Times are medians of repeated runs, wall clock (a frame is not repeated once its stages took 2 s).\n"
        );
        let _ = writeln!(s, "## References\n");
        let _ = writeln!(
            s,
            "| scene | environment | frames | vertices | noise | rays | seconds |"
        );
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|");
        for r in &self.references {
            let secs = if r.cached {
                "cached".to_string()
            } else {
                format!("{:.1}", r.seconds)
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.3}% | {} | {} |",
                r.scene,
                r.environment,
                r.frames,
                r.vertices,
                r.noise * 100.0,
                r.rays,
                secs
            );
        }
        let _ = writeln!(s, "\n## Methods\n");
        let _ = writeln!(s, "![time per frame against error]({CHART})\n");
        let _ = writeln!(
            s,
            "| scene | method | error | p99 | max | prepare ms | update ms | relight ms | shade ms | frame ms |"
        );
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
        for r in &self.runs {
            let p99 = r.frames.iter().map(|f| f.error.p99).fold(0.0, f32::max);
            let max = r.frames.iter().map(|f| f.error.max).fold(0.0, f32::max);
            let t = |f: fn(&crate::run::StageTimes) -> f64| {
                crate::run::median(r.frames.iter().map(|fr| f(&fr.times) * 1e3).collect())
            };
            let _ = writeln!(
                s,
                "| {} | {} | {:.2}% | {:.1}% | {:.1}% | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
                r.scene,
                r.method,
                r.mean_error() * 100.0,
                p99 * 100.0,
                max * 100.0,
                t(|t| t.prepare),
                t(|t| t.update),
                t(|t| t.relight),
                t(|t| t.shade),
                r.frame_seconds() * 1e3,
            );
        }
        if !self.skipped.is_empty() {
            let _ = writeln!(s, "\n## Not run\n");
            for (method, scene, why) in &self.skipped {
                let _ = writeln!(s, "- {method} on {scene}: {why}");
            }
        }
        s
    }
}
