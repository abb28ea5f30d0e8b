//! What each option of a method costs in accuracy, by default each option
//! of hemispherical rasterization ([`variants`]); any method that exports
//! SH transfer gets the transfer error, any other the radiance error.
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

use std::{fmt::Write, path::Path};

use glam::Vec3;
use indicatif::ProgressBar;
use serde::Serialize;
use shadow_core::{
    Environment, Error, Export, Result, Scene, TransferSpace,
    sh::{self, ShOrder, ShRgb, Zonal},
    shading::lambert_transfer_radiance,
};

use crate::{
    chart::{Axes, Point, speed_vs_error},
    io::{write_atomic, write_json_atomic},
    methods::{MethodSpec, SharedGpu},
    reference::{
        ReferenceInfo, VertexReference,
        transfer::{TransferReference, TransferSettings, scene_transfer_references},
    },
    report::MachineInfo,
    run::{self, References},
    score::{ErrorStats, against},
};

/// The chart's file name beside the table.
pub const CHART: &str = "accuracy.png";

const AXES: Axes = Axes {
    title: "time per frame against transfer error",
    error: "transfer error per vertex, Table 1's measure (%)",
    time: "update + shade per frame (ms)",
};

/// The scenes of the paper's Table 1 that have a built-in counterpart:
/// Fight (`human`), Cloth and Chess.
pub const DEFAULT_SCENES: &[&str] = &["human", "cloth", "chess"];

/// One method setting of the table.
#[derive(Clone, Debug)]
pub struct Variant {
    pub spec: MethodSpec,
    /// What the row shows; empty for a setting outside [`variants`].
    pub what: String,
}

impl Variant {
    /// `spec`, with what it shows where [`variants`] lists it.
    pub fn described(spec: MethodSpec) -> Variant {
        let what = VARIANTS
            .iter()
            .find(|(listed, _)| *listed == spec.name())
            .map_or(String::new(), |(_, what)| what.to_string());
        Variant { spec, what }
    }
}

/// The default rows: hemi-raster's default (the paper's, every blocked
/// pixel counted), then each option changed alone.
const VARIANTS: &[(&str, &str)] = &[
    (
        "hemi-raster",
        "the default, the paper's but with every blocked pixel counted: 32×32 mask, 128² plane table, order 5, two-level hierarchy",
    ),
    (
        "hemi-raster:flat",
        "no hierarchy: every triangle at full resolution (Config::accurate)",
    ),
    (
        "hemi-raster:reach=0",
        "two-level, but full resolution over the two-ring only (near_reach 0)",
    ),
    (
        "hemi-raster:reach=6",
        "two-level with a near field of 6 coarse-triangle radii (Hierarchy::WIDE_NEAR_REACH) instead of 2",
    ),
    (
        "hemi-raster:min=40",
        "two-level, small objects simplified too (at least 40 coarse triangles, not 300)",
    ),
    (
        "hemi-raster:pvs",
        "two-level with a near field of 6 coarse-triangle radii and potentially visible sets built from the scored frames (§3.2, Config::fast)",
    ),
    (
        "hemi-raster:pvs=2",
        "the same with sets built from every other frame: half the scored frames unseen by the sets",
    ),
    ("hemi-raster:table=32", "32² plane table"),
    ("hemi-raster:table=64", "64² plane table"),
    ("hemi-raster:table=256", "256² plane table"),
    ("hemi-raster:mask=16", "16×16 mask"),
    ("hemi-raster:mask=64", "64×64 mask"),
    (
        "hemi-raster:paper",
        "SH from the paper's 4×4-block downsample instead of every blocked pixel (Config::paper)",
    ),
    (
        "hemi-raster:direct",
        "no SH: the prefiltered environment summed over visible pixels (no transfer vector)",
    ),
];

/// The default rows: hemi-raster and each of its options changed alone.
pub fn variants() -> Vec<Variant> {
    VARIANTS
        .iter()
        .map(|(name, _)| {
            let spec = crate::methods::parse(name).expect("the listed names are valid");
            Variant::described(spec)
        })
        .collect()
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
        self.add_each(values, reference, std_error, coeffs, |_, _| ())
    }

    /// [`TransferScore::add`], also handing `each` every vertex's index and
    /// relative error (`None` for a dark vertex), as the per-vertex mean
    /// counts it.
    pub fn add_each(
        &mut self,
        values: &[f32],
        reference: &[f32],
        std_error: Option<&[f32]>,
        coeffs: usize,
        mut each: impl FnMut(usize, Option<f64>),
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
                each(v, None);
            } else {
                let relative = d_sq.sqrt() / length;
                self.relative_sum += relative;
                self.noise_relative_sum += s_sq.sqrt() / length;
                each(v, Some(relative));
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

/// Where a configuration's per-vertex transfer error sits: per mesh, and how
/// concentrated it is. A defect that breaks a class of vertices (a crease, a
/// contact) shows as a few vertex-frames holding much of the sum; quadrature
/// error spreads evenly.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ErrorBreakdown {
    /// Per mesh name (objects that share a mesh, such as the chess pieces of
    /// one shape, pooled), largest share first.
    pub meshes: Vec<MeshError>,
    /// The share of the sum of per-vertex errors held by the worst
    /// [`WORST_FRACTION`] of the vertex-frames that are not dark.
    pub worst_share: f32,
}

/// One mesh's part of an [`ErrorBreakdown`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshError {
    pub name: String,
    /// Vertex-frames scored (dark ones left out).
    pub count: usize,
    /// Their mean relative error.
    pub per_vertex: f32,
    /// Their share of the sum of per-vertex errors over the scene.
    pub share: f32,
}

/// The fraction of vertex-frames whose share of the error
/// [`ErrorBreakdown::worst_share`] reports.
pub const WORST_FRACTION: f64 = 0.05;

/// Collects the per-vertex errors of [`TransferScore::add_each`] by mesh.
#[derive(Clone, Debug)]
pub struct BreakdownBuilder {
    names: Vec<String>,
    /// Per flat vertex (objects one after another): its index in `names`.
    mesh_of: Vec<usize>,
    /// Per name: vertex-frames and the sum of their errors.
    sums: Vec<(usize, f64)>,
    errors: Vec<f64>,
}

impl BreakdownBuilder {
    pub fn new(scene: &Scene) -> BreakdownBuilder {
        let mut names: Vec<String> = Vec::new();
        let mut mesh_of = Vec::with_capacity(scene.vertex_count());
        for object in scene.objects() {
            let name = object.mesh.name();
            let index = names.iter().position(|n| n == name).unwrap_or_else(|| {
                names.push(name.to_string());
                names.len() - 1
            });
            mesh_of.extend(std::iter::repeat_n(index, object.mesh.vertex_count()));
        }
        BreakdownBuilder {
            sums: vec![(0, 0.0); names.len()],
            names,
            mesh_of,
            errors: Vec::new(),
        }
    }

    /// Flat vertex `v` of a frame has relative error `error` (`None`: dark).
    pub fn add(&mut self, v: usize, error: Option<f64>) {
        if let (Some(e), Some(&mesh)) = (error, self.mesh_of.get(v)) {
            let (count, sum) = &mut self.sums[mesh];
            *count += 1;
            *sum += e;
            self.errors.push(e);
        }
    }

    pub fn finish(mut self) -> ErrorBreakdown {
        let total: f64 = self.errors.iter().sum();
        let share = |x: f64| if total > 0.0 { (x / total) as f32 } else { 0.0 };
        let mut meshes: Vec<MeshError> = self
            .names
            .into_iter()
            .zip(&self.sums)
            .filter(|(_, (count, _))| *count > 0)
            .map(|(name, &(count, sum))| MeshError {
                name,
                count,
                per_vertex: (sum / count as f64) as f32,
                share: share(sum),
            })
            .collect();
        meshes.sort_by(|a, b| b.share.total_cmp(&a.share));
        self.errors.sort_by(|a, b| b.total_cmp(a));
        let worst = (self.errors.len() as f64 * WORST_FRACTION).ceil() as usize;
        ErrorBreakdown {
            meshes,
            worst_share: share(self.errors[..worst].iter().sum()),
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
    /// Where the transfer error sits, for the configurations that have one.
    pub breakdown: Option<ErrorBreakdown>,
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
    gpu: &SharedGpu,
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
    progress.set_message(format!("transfer reference {}", scene.name()));
    let references = scene_transfer_references(scene, settings, progress)?;
    let bounds = Bounds::new(scene, environment, settings);

    let mut rows = vec![
        bounds.unshadowed(scene, radiance, &references)?,
        bounds.floor(radiance, &references),
    ];
    let mut skipped = Vec::new();
    for variant in &plan.variants {
        progress.set_message(format!("{} {}", scene.name(), variant.spec));
        match run_variant(
            variant,
            gpu,
            scene,
            environment,
            radiance,
            &references,
            plan.repeats,
        ) {
            Ok(row) => rows.push(row),
            Err(e @ Error::Unsupported { .. }) => {
                skipped.push((variant.spec.name().to_string(), e.to_string()))
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
            .map(|(t, &rho)| lambert_transfer_radiance(rho, &self.light, t).max(Vec3::ZERO))
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
            breakdown: None,
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
            breakdown: None,
            radiance: RadianceError::over_frames(&errors),
            frame_ms: None,
        }
    }
}

/// Runs one setting over every frame through [`crate::run`]: radiance
/// error, the transfer error where the method exports world-space SH
/// transfer of the reference's order, and the time per frame.
fn run_variant(
    variant: &Variant,
    gpu: &SharedGpu,
    scene: &Scene,
    environment: &Environment,
    radiance: &[VertexReference],
    references: &[TransferReference],
    repeats: usize,
) -> Result<Row> {
    let mut method = variant.spec.build(gpu)?;
    let order = references.first().map(TransferReference::order);
    let mut score = TransferScore::default();
    let mut breakdown = BreakdownBuilder::new(scene);
    let mut has_transfer = method.capabilities().export;
    let result = run::run_inspecting(
        method.as_mut(),
        scene,
        environment,
        References::vertices(radiance),
        repeats,
        |index, method| {
            if !has_transfer {
                return Ok(());
            }
            let transfer = match method.export()? {
                Export::Transfer(t)
                    if Some(t.order) == order && t.space == TransferSpace::World =>
                {
                    t
                }
                _ => {
                    has_transfer = false;
                    return Ok(());
                }
            };
            let reference = &references[index];
            score.add_each(
                &transfer.coefficients,
                reference.mean(),
                Some(reference.std_error()),
                transfer.order.coeff_count(),
                |v, error| breakdown.add(v, error),
            )
        },
    )?;
    let errors: Vec<ErrorStats> = result.frames.iter().map(|f| f.vertex).collect();
    Ok(Row {
        name: variant.spec.name().to_string(),
        what: variant.what.clone(),
        transfer: has_transfer.then(|| score.summary()),
        breakdown: has_transfer.then(|| breakdown.finish()),
        radiance: RadianceError::over_frames(&errors),
        frame_ms: Some(result.frame_seconds() * 1e3),
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
             per-vertex relative error. **ms/frame** is the median over frames of update + \
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

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use approx::assert_relative_eq;

    /// Every default row is listed under the name its method prints, so
    /// that `--methods` naming it finds its description.
    #[test]
    fn the_default_rows_are_named_as_their_methods_print() {
        for variant in variants() {
            assert!(!variant.what.is_empty(), "{}", variant.spec);
        }
    }
    use shadow_core::{Camera, Object};

    use super::*;
    use crate::scenes::white;
    use shadow_core::shapes;

    /// Objects sharing a mesh are pooled under its name, dark vertices are
    /// left out, and the worst 5% share is of the non-dark sum.
    #[test]
    fn breakdown_pools_meshes_and_measures_concentration() {
        let grid = Arc::new(shapes::floor("tile", Vec3::ZERO, 1.0, 1).unwrap());
        let other = Arc::new(shapes::floor("slab", Vec3::Y, 1.0, 1).unwrap());
        let objects = [&grid, &other, &grid]
            .map(|mesh| Object {
                mesh: Arc::clone(mesh),
                material: white(),
            })
            .to_vec();
        let camera = Camera::framing(Vec3::ZERO, 2.0, Vec3::ONE, 8, 8).unwrap();
        let scene = Scene::still("tiles", objects, camera).unwrap();
        assert_eq!(scene.vertex_count(), 12);
        let mut b = BreakdownBuilder::new(&scene);
        // Tiles (vertices 0–3 and 8–11): one dark vertex, the others 1%,
        // but for one at 37%. Slab (4–7): 10% each.
        for v in 0..12 {
            let error = match v {
                0 => None,
                4..=7 => Some(0.1),
                9 => Some(0.37),
                _ => Some(0.01),
            };
            b.add(v, error);
        }
        let e = b.finish();
        let total = 0.37 + 0.4 + 6.0 * 0.01;
        assert_eq!(e.meshes.len(), 2);
        let (tile, slab) = (&e.meshes[0], &e.meshes[1]);
        assert_eq!((tile.name.as_str(), tile.count), ("tile", 7));
        assert_eq!((slab.name.as_str(), slab.count), ("slab", 4));
        assert_relative_eq!(tile.per_vertex, (0.37 + 0.06) / 7.0, epsilon = 1e-6);
        assert_relative_eq!(tile.share, 0.43 / total, epsilon = 1e-6);
        assert_relative_eq!(slab.share, 0.4 / total, epsilon = 1e-6);
        // 5% of 11 vertex-frames, rounded up: the single worst.
        assert_relative_eq!(e.worst_share, 0.37 / total, epsilon = 1e-6);
    }
}
