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

mod bounds;
mod document;
mod score;

pub use document::{AccuracyReport, CHART, Row, SceneAccuracy, TransferReferenceInfo};
pub use score::{
    BreakdownBuilder, CUT_OFFS, DARK, ErrorBreakdown, MeshError, RadianceError, TransferError,
    TransferScore, WORST_FRACTION,
};

use indicatif::ProgressBar;
use shadow_core::{Environment, Error, Export, Result, Scene, TransferSpace};

use crate::{
    methods::{MethodSpec, SharedGpu},
    reference::{
        ReferenceInfo, VertexReference,
        transfer::{TransferReference, TransferSettings, scene_transfer_references},
    },
    run::{self, References},
    score::ErrorStats,
};
use bounds::Bounds;

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
        "hemi-raster:min=0",
        "two-level, every object simplified to a tenth however few triangles that leaves (the paper's Table 1)",
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
        "hemi-raster:blocks",
        "SH from the paper's 4×4-block downsample instead of every blocked pixel",
    ),
    (
        "hemi-raster:paper",
        "the paper as published (Config::paper): 4×4 blocks, a tenth of the triangles however few, the one-ring",
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
    let mut blockers = Vec::new();
    let result = run::run_inspecting(
        method.as_mut(),
        scene,
        environment,
        References::vertices(radiance),
        repeats,
        |index, method| {
            let profile = method.profile();
            blockers.extend(profile.count_in(shadow_core::Stage::Update, BLOCKERS));
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
        frame_ms: Some(result.frame_time().median() * 1e3),
        blockers: (!blockers.is_empty())
            .then(|| blockers.iter().sum::<u64>() as f64 / blockers.len() as f64),
    })
}

/// The profile entry of hemi-raster's update that counts the blockers a
/// receiver rasterizes (Table 1's "Avg. #Tris").
const BLOCKERS: &str = "blockers per receiver";

#[cfg(test)]
mod tests;
