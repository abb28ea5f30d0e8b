//! The transfer error of Kautz et al. (§4, Table 1) summed over vertices and
//! frames, where it sits, and the radiance error over frames.

use serde::Serialize;
use shadow_core::{
    Error, Result, Scene,
    sh::{ShOrder, Zonal},
};

use crate::score::ErrorStats;

/// Vertices whose reference transfer vector is shorter than this fraction of
/// an unoccluded vertex's are left out of the per-vertex mean (see
/// [`TransferScore`]).
pub const DARK: f32 = 0.05;

/// The cut-offs the per-vertex mean is also measured at
/// ([`TransferError::by_cut_off`]), [`DARK`] among them.
pub const CUT_OFFS: [f32; 4] = [0.02, 0.05, 0.1, 0.2];

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
/// covers every vertex. What the cut-off does is measured, not argued: the
/// mean is also kept at each of [`CUT_OFFS`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TransferScore {
    vertices: usize,
    dark: usize,
    relative_sum: f64,
    /// Per cut-off of [`CUT_OFFS`]: vertices kept and their relative sum.
    by_cut_off: [(usize, f64); CUT_OFFS.len()],
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
    /// The paper's measure with each cut-off of [`CUT_OFFS`] in place of
    /// [`DARK`].
    pub by_cut_off: [f32; CUT_OFFS.len()],
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
            let unoccluded = unoccluded_norm(order);
            for (cut, (kept, sum)) in CUT_OFFS.iter().zip(&mut self.by_cut_off) {
                if length >= f64::from(*cut) * unoccluded {
                    *kept += 1;
                    *sum += d_sq.sqrt() / length;
                }
            }
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
            by_cut_off: self
                .by_cut_off
                .map(|(kept, sum)| (sum / kept.max(1) as f64) as f32),
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
    pub(super) fn over_frames(frames: &[ErrorStats]) -> RadianceError {
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
