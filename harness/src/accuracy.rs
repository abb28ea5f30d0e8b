//! What each option of hemispherical rasterization costs in accuracy.
//!
//! Kautz, Lehtinen and Aila 2004 (§4, Table 1) score their method by the
//! "average L2 error in V*": the relative L2 error of the SH transfer
//! vectors, "average relative L2 error over all vertices and many animation
//! frames", 2.5–7.9% on their four models. This module measures the same
//! quantity against a ray-traced transfer reference
//! ([`crate::reference::transfer`]) for the paper's configuration and for
//! each option changed alone (mesh hierarchy, plane-table and mask
//! resolution, integration), beside the exit-radiance error against the
//! converged radiance reference and the time per frame. Two rows bound the
//! table: the unshadowed transfer (clamped cosine only, no visibility) and
//! the reference transfer itself shaded with the environment's SH of the same
//! order, whose radiance error is the floor that SH truncation sets under
//! that environment: no order-5 transfer method can do better.

use std::{f32::consts::FRAC_1_PI, fmt::Write, path::Path, time::Instant};

use glam::Vec3;
use hemi_raster::{Config, HemiRaster, Hierarchy, Integration, MaskResolution};
use indicatif::ProgressBar;
use serde::Serialize;
use shadow_core::{
    Environment, Error, Result, Scene, ShadowMethod,
    sh::{self, ShOrder, ShRgb, Zonal},
};

use crate::{
    io::{write_atomic, write_json_atomic},
    reference::{
        VertexReference,
        transfer::{TransferReference, TransferSettings, scene_transfer_references},
    },
    report::{MachineInfo, ReferenceInfo},
    run::median,
    score::{ErrorStats, against},
};

/// The scenes of the paper's Table 1 that have a built-in counterpart:
/// Fight (`human`), Cloth and Chess.
pub const DEFAULT_SCENES: &[&str] = &["human", "cloth", "chess"];

/// One hemi-raster configuration of the table.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    pub name: &'static str,
    pub what: &'static str,
    pub config: Config,
}

/// The paper's configuration, then each option changed alone.
pub fn variants() -> Vec<Variant> {
    let paper = Config::default();
    let with = |name, what, config| Variant { name, what, config };

    vec![
        with(
            "default",
            "the paper's: 32×32 mask, 128² plane table, order 5 from 4×4 blocks, two-level hierarchy",
            paper,
        ),
        with(
            "flat",
            "no hierarchy: every triangle at full resolution",
            Config {
                hierarchy: Hierarchy::Flat,
                ..paper
            },
        ),
        with(
            "rings-only",
            "two-level, but full resolution over the two-ring only (near_reach 0)",
            Config {
                hierarchy: paper.hierarchy.with_near_reach(0),
                ..paper
            },
        ),
        with(
            "coarse-40",
            "two-level, small objects simplified too (at least 40 coarse triangles, not 300)",
            Config {
                hierarchy: paper.hierarchy.with_min_coarse_triangles(40),
                ..paper
            },
        ),
        with(
            "lut-32",
            "32² plane table",
            Config {
                lut_resolution: 32,
                ..paper
            },
        ),
        with(
            "lut-64",
            "64² plane table",
            Config {
                lut_resolution: 64,
                ..paper
            },
        ),
        with(
            "lut-256",
            "256² plane table",
            Config {
                lut_resolution: 256,
                ..paper
            },
        ),
        with(
            "mask-16",
            "16×16 mask",
            Config {
                mask_resolution: MaskResolution::R16,
                ..paper
            },
        ),
        with(
            "mask-64",
            "64×64 mask",
            Config {
                mask_resolution: MaskResolution::R64,
                ..paper
            },
        ),
        with(
            "sh-pixels",
            "SH from every blocked pixel instead of 4×4 blocks",
            Config {
                integration: Integration::ShPixels,
                ..paper
            },
        ),
        with(
            "direct",
            "no SH: the prefiltered environment summed over visible pixels (no transfer vector)",
            Config {
                integration: Integration::Direct,
                ..paper
            },
        ),
    ]
}

/// Vertices whose reference transfer vector is shorter than this fraction of
/// an unoccluded vertex's are left out of the per-vertex mean (see
/// [`TransferScore`]).
pub const DARK: f32 = 0.05;

/// Running sums of the transfer error over vertices and frames.
///
/// The paper's measure divides each vertex's error by |T_ref|, which is
/// undefined where the reference sees no sky at all: real meshes hide
/// vertices inside other parts (on the human, a tenth of the vertices, the neck
/// inside the torso and the like, have T_ref = 0 exactly), and a floor under
/// |T_ref| only trades the infinity for whatever the floor makes of it. So
/// the per-vertex mean covers the vertices whose |T_ref| is at least [`DARK`]
/// times that of an unoccluded vertex (the clamped cosine, whose length is
/// the same for every normal), and counts the others; the global measure
/// covers every vertex. The threshold matters little: on one frame of the
/// human, the paper's configuration scores 7.7% with a 2% threshold, 7.3%
/// with 5% or 10%, 6.9% with 20%.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TransferScore {
    vertices: usize,
    dark: usize,
    relative_sum: f64,
    noise_relative_sum: f64,
    diff_sq: f64,
    reference_sq: f64,
    noise_sq: f64,
}

/// The transfer error over all vertices and frames scored.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TransferError {
    /// The paper's measure: the mean over vertices and frames of the
    /// per-vertex relative L2 error |T − T_ref| / |T_ref|, over the vertices
    /// that are not dark (0 when every vertex is).
    pub per_vertex: f32,
    /// `sqrt(ΣΣ|T − T_ref|² / ΣΣ|T_ref|²)` over every vertex and frame.
    pub global: f32,
    /// The reference's own noise in the paper's measure: the mean per-vertex
    /// |SE| / |T_ref| over the same vertices.
    pub noise_per_vertex: f32,
    /// The reference's own noise in the global measure, `sqrt(ΣΣ SE² / ΣΣ T_ref²)`.
    pub noise_global: f32,
    /// Vertices × frames compared.
    pub count: usize,
    /// Of those, how many are dark and left out of the per-vertex mean.
    pub dark: usize,
}

/// |Λ_l Y_lm(n)| of [`Zonal::lambert`]: by the addition theorem,
/// Σ_m Y_lm(n)² = (2l+1)/4π for every n.
fn unoccluded_norm(order: ShOrder) -> f64 {
    Zonal::lambert(order)
        .eigenvalues()
        .iter()
        .enumerate()
        .map(|(l, &lambda)| (lambda as f64).powi(2) * (2 * l + 1) as f64)
        .sum::<f64>()
        .sqrt()
        / (4.0 * std::f64::consts::PI).sqrt()
}

impl TransferScore {
    /// Adds one frame: `values` and `reference` hold `coeffs` coefficients
    /// (a whole SH order) per vertex, `std_error` (if known) the reference's
    /// standard errors in the same layout.
    pub fn add(
        &mut self,
        values: &[f32],
        reference: &[f32],
        std_error: Option<&[f32]>,
        coeffs: usize,
    ) -> Result<()> {
        let order = ShOrder::from_coeff_count(coeffs).filter(|_| {
            values.len() == reference.len()
                && reference.len().is_multiple_of(coeffs)
                && std_error.is_none_or(|se| se.len() == reference.len())
        });
        let Some(order) = order else {
            return Err(Error::InvalidScene(format!(
                "transfer score: {} values, {} reference coefficients, {:?} standard errors \
                 do not make vertices of one SH order's {coeffs} coefficients",
                values.len(),
                reference.len(),
                std_error.map(<[f32]>::len)
            )));
        };
        let norm_sq = |x: &[f32]| x.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
        let dark = DARK as f64 * unoccluded_norm(order);
        for (v, (x, r)) in values
            .chunks_exact(coeffs)
            .zip(reference.chunks_exact(coeffs))
            .enumerate()
        {
            let d_sq: f64 = x
                .iter()
                .zip(r)
                .map(|(&a, &b)| (a as f64 - b as f64).powi(2))
                .sum();
            let r_sq = norm_sq(r);
            let s_sq = std_error.map_or(0.0, |se| norm_sq(&se[v * coeffs..(v + 1) * coeffs]));
            self.diff_sq += d_sq;
            self.reference_sq += r_sq;
            self.noise_sq += s_sq;
            self.vertices += 1;
            let length = r_sq.sqrt();
            if length < dark {
                self.dark += 1;
            } else {
                self.relative_sum += d_sq.sqrt() / length;
                self.noise_relative_sum += s_sq.sqrt() / length;
            }
        }
        Ok(())
    }

    pub fn summary(&self) -> TransferError {
        let mean = |sum: f64| (sum / (self.vertices - self.dark).max(1) as f64) as f32;
        let ratio = |num: f64| {
            if self.reference_sq > 0.0 {
                (num / self.reference_sq).sqrt() as f32
            } else if num == 0.0 {
                0.0
            } else {
                f32::INFINITY
            }
        };
        TransferError {
            per_vertex: mean(self.relative_sum),
            global: ratio(self.diff_sq),
            noise_per_vertex: mean(self.noise_relative_sum),
            noise_global: ratio(self.noise_sq),
            count: self.vertices,
            dark: self.dark,
        }
    }
}

/// The exit-radiance error over a scene's frames, aggregated as in the
/// comparison report ([`crate::report`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RadianceError {
    /// The mean over frames of the per-frame relative L2 error.
    pub relative_l2: f32,
    /// The worst frame's 99th-percentile per-vertex relative error.
    pub p99: f32,
    /// The largest per-vertex relative error of any frame.
    pub max: f32,
    /// The worst frame's reference noise.
    pub reference_noise: f32,
}

impl RadianceError {
    fn over_frames(frames: &[ErrorStats]) -> RadianceError {
        let worst = |f: fn(&ErrorStats) -> f32| frames.iter().map(f).fold(0.0, f32::max);
        RadianceError {
            relative_l2: frames.iter().map(|f| f.relative_l2).sum::<f32>()
                / frames.len().max(1) as f32,
            p99: worst(|f| f.p99),
            max: worst(|f| f.max),
            reference_noise: worst(|f| f.reference_noise),
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub name: String,
    pub what: String,
    /// `None` where there is no transfer vector to score (direct integration,
    /// the reference itself).
    pub transfer: Option<TransferError>,
    pub radiance: RadianceError,
    /// Median over frames of the update + shade time, milliseconds; `None`
    /// for the bounds, which are not methods.
    pub frame_ms: Option<f64>,
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

/// What [`evaluate`] runs.
#[derive(Clone, Debug)]
pub struct Plan {
    pub transfer: TransferSettings,
    pub variants: Vec<Variant>,
    /// Timed runs of update and shade per frame (the median is kept).
    pub repeats: usize,
}

impl Default for Plan {
    /// The converged transfer reference, every variant, one timed run.
    fn default() -> Plan {
        Plan {
            transfer: TransferSettings::CONVERGED,
            variants: variants(),
            repeats: 1,
        }
    }
}

/// Scores the unshadowed and floor rows and every variant of `plan` on every
/// frame of `scene` under `environment`; `radiance[i]` is frame i's converged
/// radiance reference, described by `radiance_info`.
pub fn evaluate(
    scene: &Scene,
    environment: &Environment,
    radiance: &[VertexReference],
    radiance_info: ReferenceInfo,
    plan: &Plan,
    progress: &ProgressBar,
) -> Result<SceneAccuracy> {
    let settings = &plan.transfer;
    let frames = scene.frames().len();
    if radiance.len() != frames {
        return Err(Error::InvalidScene(format!(
            "{}: {} radiance references for {frames} frames",
            scene.name(),
            radiance.len()
        )));
    }
    if let Some(o) = scene.objects().iter().find(|o| o.material.is_glossy()) {
        return Err(Error::InvalidScene(format!(
            "{}: object {:?} is glossy; the transfer error is defined for Lambert surfaces",
            scene.name(),
            o.mesh.name()
        )));
    }
    if let Some(v) = plan
        .variants
        .iter()
        .find(|v| v.config.order != settings.order)
    {
        return Err(Error::InvalidScene(format!(
            "variant {} has SH {}, the transfer reference {}",
            v.name, v.config.order, settings.order
        )));
    }
    progress.set_message(format!("transfer reference {}", scene.name()));
    let references = scene_transfer_references(scene, settings, progress)?;
    let bounds = Bounds::new(scene, environment, settings);

    let mut rows = vec![
        bounds.unshadowed(scene, radiance, &references)?,
        bounds.floor(radiance, &references),
    ];
    let mut skipped = Vec::new();
    for variant in &plan.variants {
        progress.set_message(format!("{} {}", scene.name(), variant.name));
        match run_variant(
            variant,
            scene,
            environment,
            radiance,
            &references,
            plan.repeats,
        ) {
            Ok(row) => rows.push(row),
            Err(e @ Error::Unsupported { .. }) => {
                skipped.push((variant.name.to_string(), e.to_string()))
            }
            Err(e) => return Err(e),
        }
    }
    Ok(SceneAccuracy {
        scene: scene.name().to_string(),
        environment: environment.name().to_string(),
        frames,
        vertices: scene.vertex_count(),
        triangles: scene.triangle_count(),
        transfer_reference: TransferReferenceInfo {
            settings: *settings,
            rays: references.iter().map(|r| r.rays).sum(),
            seconds: references.iter().map(|r| r.seconds).sum(),
        },
        radiance_reference: radiance_info,
        rows,
        skipped,
    })
}

/// What shading a transfer vector needs: the lighting's SH and every
/// vertex's albedo.
struct Bounds {
    light: ShRgb,
    lambert: Zonal,
    /// Per flat vertex.
    albedo: Vec<Vec3>,
}

impl Bounds {
    fn new(scene: &Scene, environment: &Environment, settings: &TransferSettings) -> Bounds {
        let albedo = scene
            .objects()
            .iter()
            .flat_map(|o| std::iter::repeat_n(o.material.diffuse(), o.mesh.vertex_count()))
            .collect();
        Bounds {
            light: sh::project_environment(environment, settings.order),
            lambert: Zonal::lambert(settings.order),
            albedo,
        }
    }

    /// Exit radiance ρ/π · max(0, L·T) (Kautz et al. eq. 2, clamped as
    /// hemi-raster's `shade` does).
    fn shade(&self, transfer: &[f32]) -> Vec<Vec3> {
        let n = self.lambert.order().coeff_count();
        transfer
            .chunks_exact(n)
            .zip(&self.albedo)
            .map(|(t, rho)| (*rho * FRAC_1_PI * self.light.dot(t)).max(Vec3::ZERO))
            .collect()
    }

    /// The upper bound: the clamped cosine about each vertex normal, no
    /// visibility.
    fn unshadowed(
        &self,
        scene: &Scene,
        radiance: &[VertexReference],
        references: &[TransferReference],
    ) -> Result<Row> {
        let n = self.lambert.order().coeff_count();
        let mut score = TransferScore::default();
        let mut errors = Vec::new();
        for (index, (rad, reference)) in radiance.iter().zip(references).enumerate() {
            let frame = scene.frame_geometry(index)?;
            let normals = frame.objects.iter().flat_map(|o| o.normals().iter());
            let mut transfer = vec![0.0; reference.mean().len()];
            for (t, &normal) in transfer.chunks_exact_mut(n).zip(normals) {
                self.lambert.project_along(normal, t);
            }
            score.add(&transfer, reference.mean(), Some(reference.std_error()), n)?;
            errors.push(against(&self.shade(&transfer), rad));
        }
        Ok(Row {
            name: "unshadowed".into(),
            what: "clamped cosine only, no visibility: the upper bound".into(),
            transfer: Some(score.summary()),
            radiance: RadianceError::over_frames(&errors),
            frame_ms: None,
        })
    }

    /// The floor: the reference transfer shaded with the order-n lighting.
    fn floor(&self, radiance: &[VertexReference], references: &[TransferReference]) -> Row {
        let errors: Vec<ErrorStats> = radiance
            .iter()
            .zip(references)
            .map(|(rad, reference)| against(&self.shade(reference.mean()), rad))
            .collect();
        Row {
            name: "reference transfer".into(),
            what: format!(
                "the ray-traced transfer with the environment's SH of {}: the floor SH truncation sets",
                self.lambert.order()
            ),
            transfer: None,
            radiance: RadianceError::over_frames(&errors),
            frame_ms: None,
        }
    }
}

/// Runs one configuration over every frame: radiance and (for the SH
/// integrations) transfer error, and the time of update + shade.
fn run_variant(
    variant: &Variant,
    scene: &Scene,
    environment: &Environment,
    radiance: &[VertexReference],
    references: &[TransferReference],
    repeats: usize,
) -> Result<Row> {
    let mut method = HemiRaster::new(variant.config);
    method.prepare(scene)?;
    // Lighting first, so that each update does all of a new frame's work
    // (with direct integration, the sum over the visible pixels).
    method.relight(environment)?;
    let eye = scene.camera().eye;
    let n = variant.config.order.coeff_count();
    let has_transfer = variant.config.integration != Integration::Direct;
    let mut score = TransferScore::default();
    let mut errors = Vec::new();
    let mut frame_seconds = Vec::new();
    let mut transfer = Vec::new();
    for (index, (rad, reference)) in radiance.iter().zip(references).enumerate() {
        let frame = scene.frame_geometry(index)?;
        let (mut update, mut shade) = (Vec::new(), Vec::new());
        let mut shading = None;
        for _ in 0..repeats.max(1) {
            let start = Instant::now();
            method.update(&frame)?;
            update.push(start.elapsed().as_secs_f64());
            let start = Instant::now();
            shading = Some(method.shade(eye)?);
            shade.push(start.elapsed().as_secs_f64());
        }
        frame_seconds.push(median(update) + median(shade));
        let shading = shading.expect("at least one repeat");
        let values: Vec<Vec3> = shading.flat().collect();
        errors.push(against(&values, rad));
        if has_transfer {
            transfer.clear();
            for (o, object) in frame.objects.iter().enumerate() {
                for v in 0..object.vertex_count() {
                    let t = method.transfer(o, v).ok_or_else(|| {
                        Error::stage(
                            method.name(),
                            format!("no transfer for vertex {v} of object {o}"),
                        )
                    })?;
                    transfer.extend_from_slice(t);
                }
            }
            score.add(&transfer, reference.mean(), Some(reference.std_error()), n)?;
        }
    }
    Ok(Row {
        name: variant.name.to_string(),
        what: variant.what.to_string(),
        transfer: has_transfer.then(|| score.summary()),
        radiance: RadianceError::over_frames(&errors),
        frame_ms: Some(median(frame_seconds) * 1e3),
    })
}

/// Every scene's table, and where it was measured.
#[derive(Clone, Debug, Serialize)]
pub struct AccuracyReport {
    pub machine: MachineInfo,
    pub repeats: usize,
    pub scenes: Vec<SceneAccuracy>,
}

impl AccuracyReport {
    /// Writes `accuracy.json` and `accuracy.md` into `dir`, each atomically.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_json_atomic(&dir.join("accuracy.json"), self)?;
        write_atomic(&dir.join("accuracy.md"), self.markdown().as_bytes())
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
             per-vertex relative error. **ms/frame** is the median over frames of update + \
             shade. *unshadowed* ignores visibility (the upper bound); *reference transfer* \
             shades the ray-traced transfer with the environment's order-5 SH: its radiance \
             error is what SH truncation alone costs under that environment, the floor of every \
             SH row.\n"
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
            "| configuration | transfer error (per vertex) | transfer error (global) | radiance error | p99 | ms/frame |"
        );
        let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|");
        let percent = |x: f32| format!("{:.2}%", x * 100.0);
        for row in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.1}% | {} |",
                row.name,
                row.transfer.map_or("—".into(), |e| percent(e.per_vertex)),
                row.transfer.map_or("—".into(), |e| percent(e.global)),
                percent(row.radiance.relative_l2),
                row.radiance.p99 * 100.0,
                row.frame_ms.map_or("—".into(), |ms| format!("{ms:.1}")),
            );
        }
        let _ = writeln!(s);
        for row in &self.rows {
            let _ = writeln!(s, "- {}: {}", row.name, row.what);
        }
        for (name, why) in &self.skipped {
            let _ = writeln!(s, "- {name}: not run: {why}");
        }
        let _ = writeln!(s);
    }
}
