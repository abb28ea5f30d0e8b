//! The comparison report: every method on every scene, time per stage and
//! error against the reference, as JSON (for tools) and Markdown (for people).

use std::{fmt::Write, path::Path};

use serde::Serialize;
use shadow_core::Result;

use crate::{
    chart::{Axes, Point, speed_vs_error},
    io::{write_atomic, write_json_atomic},
    run::{FrameResult, RunResult},
    score::ErrorStats,
};

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

/// A scene's references: how they were made and how noisy they are.
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
    /// The per-pixel reference, when images are scored.
    pub image: Option<ImageReferenceInfo>,
}

/// A scene's per-pixel reference.
#[derive(Clone, Debug, Serialize)]
pub struct ImageReferenceInfo {
    pub width: u32,
    pub height: u32,
    /// Covered pixels, summed over frames.
    pub pixels: usize,
    /// Worst per-frame relative L2 noise over the covered pixels.
    pub noise: f32,
    pub rays: u64,
    pub seconds: f64,
    pub cached: bool,
}

/// The chart files beside the report.
const CHARTS: [&str; 2] = ["speed-vs-error.png", "speed-vs-error-image.png"];

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub machine: MachineInfo,
    pub references: Vec<ReferenceInfo>,
    pub runs: Vec<RunResult>,
    /// Method × scene pairs that could not run, and why.
    pub skipped: Vec<(String, String, String)>,
    /// The scene whose images the report shows side by side
    /// ([`STRIP_SCENE`]), when its images were written (under
    /// `strip/{scene}/`).
    pub strip: Option<String>,
}

/// The scene of the image strip: the bunny's contact shadow on a
/// two-triangle floor, which per-vertex methods cannot draw.
pub const STRIP_SCENE: &str = "bunny";

/// The methods of the strip, in order.
const STRIP_METHODS: [&str; 4] = [
    "deferred-shadow",
    "hemi-raster",
    "occlusion-query-k258",
    "raytrace-64-vertex",
];

impl Report {
    /// Writes `report.json`, `report.md` and the speed-versus-error charts
    /// (per vertex, and per pixel when images were scored) into `dir`, each
    /// atomically.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_json_atomic(&dir.join("report.json"), self)?;
        let vertex: Vec<Point> = (self.runs.iter())
            .map(|r| Point {
                series: r.method.clone(),
                label: r.scene.clone(),
                error_percent: r.mean_error() as f64 * 100.0,
                frame_ms: r.frame_seconds() * 1e3,
            })
            .collect();
        speed_vs_error(&vertex, Axes::RADIANCE, &dir.join(CHARTS[0]))?;
        let image: Vec<Point> = (self.runs.iter())
            .filter_map(|r| {
                Some(Point {
                    series: r.method.clone(),
                    label: r.scene.clone(),
                    error_percent: r.mean_image_error()? as f64 * 100.0,
                    frame_ms: r.image_frame_seconds()? * 1e3,
                })
            })
            .collect();
        if !image.is_empty() {
            speed_vs_error(&image, Axes::IMAGE, &dir.join(CHARTS[1]))?;
        }
        write_atomic(&dir.join("report.md"), self.markdown().as_bytes())
    }

    pub fn markdown(&self) -> String {
        let m = &self.machine;
        let images = self.runs.iter().any(|r| r.image_size.is_some());
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
            "Errors are relative L2 errors against the Monte-Carlo reference, averaged over frames: \
             per vertex over the vertices a method evaluated, per pixel over the pixels the reference \
             covers (a pixel the method leaves uncovered counts as zero). p99 and max are per-element \
             relative errors (floor 1% of the RMS radiance), the worst over frames; \"noise\" is the \
             reference's own relative L2 noise, below which errors cannot be told apart. Time per \
             frame is update + shade per vertex, update + render per image; relighting is timed \
             apart. Times are wall clock: update on its first call for each frame (a repeat with the \
             same geometry may reuse the work), the other stages medians of repeated runs (a frame \
             is not repeated once its stages took 2 s).\n"
        );
        let _ = writeln!(s, "## References\n");
        let _ = writeln!(
            s,
            "| scene | environment | frames | vertices | noise | rays | seconds | image | image noise | image seconds |"
        );
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
        let secs = |cached: bool, seconds: f64| {
            if cached {
                "cached".to_string()
            } else {
                format!("{seconds:.1}")
            }
        };
        for r in &self.references {
            let (size, noise, seconds) = match &r.image {
                Some(i) => (
                    format!("{}×{}", i.width, i.height),
                    format!("{:.3}%", i.noise * 100.0),
                    secs(i.cached, i.seconds),
                ),
                None => ("–".into(), "–".into(), "–".into()),
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.3}% | {} | {} | {size} | {noise} | {seconds} |",
                r.scene,
                r.environment,
                r.frames,
                r.vertices,
                r.noise * 100.0,
                r.rays,
                secs(r.cached, r.seconds),
            );
        }
        let _ = writeln!(s, "\n## Methods\n");
        let _ = writeln!(
            s,
            "![time per frame against error, per vertex]({})\n",
            CHARTS[0]
        );
        if images {
            let _ = writeln!(
                s,
                "![time per image against error, per pixel]({})\n",
                CHARTS[1]
            );
        }
        let _ = writeln!(
            s,
            "| scene | method | vertex error | p99 | max | frame ms | image error | p99 | max | image ms | relight ms | prepare ms |"
        );
        let _ = writeln!(
            s,
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        for r in &self.runs {
            let worst = |f: fn(&ErrorStats) -> f32,
                         domain: fn(&FrameResult) -> Option<ErrorStats>| {
                let values: Option<Vec<f32>> = r
                    .frames
                    .iter()
                    .map(|fr| domain(fr).map(|e| f(&e)))
                    .collect();
                values.map(|v| v.into_iter().fold(0.0, f32::max))
            };
            let vertex = |fr: &FrameResult| Some(fr.vertex);
            let image = |fr: &FrameResult| fr.image;
            let percent = |v: Option<f32>, digits: usize| {
                v.map_or("–".to_string(), |v| format!("{:.*}%", digits, v * 100.0))
            };
            let ms = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{:.2}", v * 1e3));
            let evaluated = r.evaluated_fraction();
            let vertex_error = if evaluated < 1.0 {
                format!(
                    "{:.2}% ({:.0}% of vertices)",
                    r.mean_error() * 100.0,
                    evaluated * 100.0
                )
            } else {
                format!("{:.2}%", r.mean_error() * 100.0)
            };
            let first = r.frames.first().map(|f| f.times);
            let _ = writeln!(
                s,
                "| {} | {} | {vertex_error} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                r.scene,
                r.method,
                percent(worst(|e| e.p99, vertex), 1),
                percent(worst(|e| e.max, vertex), 1),
                ms(Some(r.frame_seconds())),
                percent(r.mean_image_error(), 2),
                percent(worst(|e| e.p99, image), 1),
                percent(worst(|e| e.max, image), 1),
                ms(r.image_frame_seconds()),
                ms(first.map(|t| t.relight)),
                ms(first.map(|t| t.prepare)),
            );
        }
        let profiled: Vec<&RunResult> = (self.runs.iter())
            .filter(|r| r.frames.iter().any(|f| !f.profile.is_empty()))
            .collect();
        if !profiled.is_empty() {
            let _ = writeln!(s, "\n## Where the time goes\n");
            let _ = writeln!(
                s,
                "Each method's own breakdown of its stages, on the middle frame (medians over repeats).\n"
            );
            for r in profiled {
                let frame = &r.frames[r.frames.len() / 2];
                let text = frame.profile.to_string().replace('\n', "; ");
                let _ = writeln!(
                    s,
                    "- {} on {} (frame {}): {text}",
                    r.method, r.scene, frame.frame
                );
            }
        }
        if let Some(scene) = &self.strip {
            self.strip_markdown(&mut s, scene);
        }
        if !self.skipped.is_empty() {
            let _ = writeln!(s, "\n## Not run\n");
            for (method, scene, why) in &self.skipped {
                let _ = writeln!(s, "- {method} on {scene}: {why}");
            }
        }
        s
    }

    /// The strip: the reference, then each strip method's image and its
    /// error map, with its error per pixel.
    fn strip_markdown(&self, s: &mut String, scene: &str) {
        let runs: Vec<&RunResult> = STRIP_METHODS
            .iter()
            .filter_map(|m| {
                self.runs
                    .iter()
                    .find(|r| r.scene == scene && r.method == *m && r.last_image.is_some())
            })
            .collect();
        let _ = writeln!(s, "\n## Per pixel against per vertex: {scene}\n");
        let _ = writeln!(
            s,
            "The contact shadow on a floor of two triangles: per-vertex methods interpolate \
             between the floor's four corners, deferred shadowing draws it per pixel. Top: the \
             images (the reference's exposure); bottom: relative error per pixel (0.1% to 100%, \
             logarithmic).\n"
        );
        let header: Vec<String> = std::iter::once("reference".to_string())
            .chain(runs.iter().map(|r| {
                format!(
                    "{} ({:.1}%)",
                    r.method,
                    100.0 * r.mean_image_error().unwrap_or(f32::NAN)
                )
            }))
            .collect();
        let _ = writeln!(s, "| {} |", header.join(" | "));
        let _ = writeln!(s, "|{}", "---|".repeat(header.len()));
        let images: Vec<String> =
            std::iter::once(format!("![reference](strip/{scene}/reference.png)"))
                .chain(
                    runs.iter()
                        .map(|r| format!("![{0}](strip/{scene}/{0}.png)", r.method)),
                )
                .collect();
        let _ = writeln!(s, "| {} |", images.join(" | "));
        let errors: Vec<String> = std::iter::once(String::new())
            .chain(
                runs.iter()
                    .map(|r| format!("![{0} error](strip/{scene}/{0}-error.png)", r.method)),
            )
            .collect();
        let _ = writeln!(s, "| {} |", errors.join(" | "));
    }
}
