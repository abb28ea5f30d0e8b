//! The study's tables and chart: rows, scenes, the report written to disk.

use std::{fmt::Write, path::Path};

use serde::Serialize;
use shadow_core::Result;

use super::{CUT_OFFS, ErrorBreakdown, RadianceError, TransferError, WORST_FRACTION};
use crate::{
    chart::{Axes, Point, speed_vs_error},
    io::{write_atomic, write_json_atomic},
    reference::{ReferenceInfo, transfer::TransferSettings},
    report::MachineInfo,
};

/// The chart's file name beside the table.
pub const CHART: &str = "accuracy.png";

const AXES: Axes = Axes {
    title: "time per frame against transfer error",
    error: "transfer error per vertex, Table 1's measure (%)",
    time: "update + shade per frame (ms)",
};

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub name: String,
    pub what: String,
    /// `None` where there is no transfer vector to score (direct integration,
    /// the reference itself).
    pub transfer: Option<TransferError>,
    /// Where the transfer error sits, for the configurations that have one.
    pub breakdown: Option<ErrorBreakdown>,
    pub radiance: RadianceError,
    /// Median over frames of the update + shade time, milliseconds; `None`
    /// for the bounds, which are not methods.
    pub frame_ms: Option<f64>,
    /// The mean number of blockers a receiver rasterizes (Table 1's "Avg.
    /// #Tris"), where the method counts them.
    pub blockers: Option<f64>,
}

/// How the transfer reference of a scene was made.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct TransferReferenceInfo {
    pub settings: TransferSettings,
    pub rays: u64,
    pub seconds: f64,
}

/// Every row of one scene.
#[derive(Clone, Debug, Serialize)]
pub struct SceneAccuracy {
    pub scene: String,
    pub environment: String,
    pub frames: usize,
    pub vertices: usize,
    pub triangles: usize,
    pub transfer_reference: TransferReferenceInfo,
    pub radiance_reference: ReferenceInfo,
    pub rows: Vec<Row>,
    /// Variants that could not run on this scene, and why.
    pub skipped: Vec<(String, String)>,
}

/// Every scene's table, and where it was measured.
#[derive(Clone, Debug, Serialize)]
pub struct AccuracyReport {
    pub machine: MachineInfo,
    pub repeats: usize,
    pub scenes: Vec<SceneAccuracy>,
}

impl AccuracyReport {
    /// Writes `accuracy.json`, `accuracy.md` and the chart of time against
    /// transfer error [`CHART`] (and its SVG beside it) into `dir`, each
    /// atomically.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_json_atomic(&dir.join("accuracy.json"), self)?;
        let png = dir.join(CHART);
        speed_vs_error(&self.points(), AXES, &png, &png.with_extension("svg"))?;
        write_atomic(&dir.join("accuracy.md"), self.markdown().as_bytes())
    }

    /// Every configuration with a transfer vector and a time, per scene.
    fn points(&self) -> Vec<Point> {
        let mut points = Vec::new();
        for scene in &self.scenes {
            for row in &scene.rows {
                if let (Some(transfer), Some(frame_ms)) = (row.transfer, row.frame_ms) {
                    points.push(Point {
                        series: row.name.clone(),
                        label: scene.scene.clone(),
                        error_percent: transfer.per_vertex as f64 * 100.0,
                        frame_ms,
                    });
                }
            }
        }
        points
    }

    pub fn markdown(&self) -> String {
        let m = &self.machine;
        let mut s = String::new();
        let _ = writeln!(s, "# What hemispherical rasterization costs in accuracy\n");
        let _ = writeln!(
            s,
            "Machine: {}, {} threads, {} build; update and shade timed {} time(s) per frame.\n",
            m.cpu, m.threads, m.profile, self.repeats
        );
        let _ = writeln!(
            s,
            "**Transfer error** is Kautz et al. 2004's Table 1 measure, the error in the SH \
             transfer vectors T_k = ∫ V(ω) max(0, n·ω) Y_k(ω) dω (order 5, 25 terms) against a \
             ray-traced reference: *per vertex* is the relative L2 error |T − T_ref| / |T_ref| \
             averaged over all vertices and frames (the paper's), leaving out the dark \
             vertices, whose |T_ref| is below 5% of an unoccluded vertex's and whose relative \
             error is undefined (they are counted under each scene), *global* is sqrt(ΣΣ|T − T_ref|² / ΣΣ|T_ref|²). The paper reports 2.47% \
             (Cloth), 7.93% (Fight), 2.89% (Chess), 3.82% (Hand). **Radiance error** is the \
             relative L2 error of exit radiance against the converged radiance reference, \
             averaged over frames, as in report.md; p99 is the worst frame's 99th-percentile \
             per-vertex relative error. **ms/frame** is the median over frames and repeats of update + \
             shade. *unshadowed* ignores visibility (the upper bound); *reference transfer* \
             shades the ray-traced transfer with the environment's order-5 SH: its radiance \
             error is what SH truncation alone costs under that environment, the floor of every \
             SH row. `{CHART}` plots each configuration's time against its transfer error.\n"
        );
        for scene in &self.scenes {
            scene.markdown(&mut s);
        }
        s
    }
}

impl SceneAccuracy {
    fn markdown(&self, s: &mut String) {
        let t = &self.transfer_reference;
        let r = &self.radiance_reference;
        let _ = writeln!(
            s,
            "## {} under {}\n\n{} frames, {} vertices, {} triangles.\n",
            self.scene, self.environment, self.frames, self.vertices, self.triangles
        );
        let noise = self
            .rows
            .iter()
            .find_map(|row| row.transfer)
            .map_or(String::new(), |e| {
                format!(
                    ", noise {:.3}% per vertex and {:.3}% global; {} of {} vertex-frames are dark \
                     (left out of the per-vertex mean)",
                    e.noise_per_vertex * 100.0,
                    e.noise_global * 100.0,
                    e.dark,
                    e.count
                )
            });
        let _ = writeln!(
            s,
            "Transfer reference: {} replicates × {} rays per vertex, {} rays in {:.1} s{noise}. \
             Radiance reference: noise {:.3}% (worst frame), {}.\n",
            t.settings.replicates,
            t.settings.replicate_size,
            t.rays,
            t.seconds,
            r.noise * 100.0,
            if r.cached {
                "from the cache".to_string()
            } else {
                format!("{} rays in {:.1} s", r.rays, r.seconds)
            }
        );
        let _ = writeln!(
            s,
            "| configuration | transfer error (per vertex) | transfer error (global) | radiance error | p99 | ms/frame | blockers per receiver |"
        );
        let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
        let percent = |x: f32| format!("{:.2}%", x * 100.0);
        for row in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.1}% | {} | {} |",
                row.name,
                row.transfer.map_or("—".into(), |e| percent(e.per_vertex)),
                row.transfer.map_or("—".into(), |e| percent(e.global)),
                percent(row.radiance.relative_l2),
                row.radiance.p99 * 100.0,
                row.frame_ms.map_or("—".into(), |ms| format!("{ms:.1}")),
                row.blockers.map_or("—".into(), |b| format!("{b:.0}")),
            );
        }
        let _ = writeln!(
            s,
            "\nThe per-vertex transfer error with the dark vertices cut off at other \
             fractions of an unoccluded vertex's |T_ref| ({}):\n",
            CUT_OFFS.map(|c| format!("{:.0}%", c * 100.0)).join(", ")
        );
        let _ = writeln!(
            s,
            "| configuration | {} |",
            CUT_OFFS.map(|c| format!("{:.0}%", c * 100.0)).join(" | ")
        );
        let _ = writeln!(s, "|---|{}", "---:|".repeat(CUT_OFFS.len()));
        for row in &self.rows {
            if let Some(e) = row.transfer {
                let cells: Vec<String> = e.by_cut_off.iter().map(|&x| percent(x)).collect();
                let _ = writeln!(s, "| {} | {} |", row.name, cells.join(" | "));
            }
        }
        let _ = writeln!(s);
        for row in &self.rows {
            let _ = writeln!(s, "- {}: {}", row.name, row.what);
        }
        let broken_down: Vec<_> = self
            .rows
            .iter()
            .filter_map(|row| Some((&row.name, row.breakdown.as_ref()?)))
            .collect();
        if !broken_down.is_empty() {
            let _ = writeln!(
                s,
                "\nWhere the per-vertex transfer error sits: per mesh, its mean and (in \
                 parentheses) its share of the sum over vertices and frames; then the share \
                 that the worst {:.0}% of vertex-frames hold.\n",
                WORST_FRACTION * 100.0
            );
        }
        for (name, b) in broken_down {
            let meshes: Vec<String> = b
                .meshes
                .iter()
                .map(|m| {
                    format!(
                        "{} {:.2}% ({:.0}%)",
                        m.name,
                        m.per_vertex * 100.0,
                        m.share * 100.0
                    )
                })
                .collect();
            let _ = writeln!(
                s,
                "- {name}: {}; worst {:.0}%: {:.0}%",
                meshes.join(", "),
                WORST_FRACTION * 100.0,
                b.worst_share * 100.0
            );
        }
        for (name, why) in &self.skipped {
            let _ = writeln!(s, "- {name}: not run: {why}");
        }
        let _ = writeln!(s);
    }
}
