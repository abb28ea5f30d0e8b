//! Error against the reference (DESIGN.md, "Scoring").

use glam::Vec3;
use serde::{Deserialize, Serialize};
use shadow_core::{Error, Image, Result, VertexRadiance};

use crate::reference::{ImageReference, VertexReference};

/// How far a method's values are from the reference's, over a domain (all
/// vertices of a frame, or all covered pixels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// `sqrt(Σ|x − r|² / Σ|r|²)` over the domain, on linear RGB.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub relative_l2: f32,
    /// Median of the per-element relative error.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub p50: f32,
    /// 90th percentile of the per-element relative error.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub p90: f32,
    /// 99th percentile of the per-element relative error.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub p99: f32,
    /// Largest per-element relative error.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub max: f32,
    /// The reference's own relative L2 noise, `sqrt(Σ|SE|² / Σ|r|²)`: errors
    /// near this are indistinguishable from zero.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub reference_noise: f32,
    /// Elements compared.
    pub count: usize,
}

/// Per-element relative errors divide by `max(|r|, FLOOR · rms(|r|))`, so that
/// elements in near-total shadow (|r| → 0) do not turn a tiny absolute error
/// into an enormous relative one; 1% of the domain's RMS radiance.
pub const FLOOR: f32 = 0.01;

/// Scores per-vertex radiance `values` (all objects, flattened) against a
/// vertex reference, its standard errors included.
pub fn against(values: &[Vec3], reference: &VertexReference) -> ErrorStats {
    let expected: Vec<Vec3> = reference.radiance.flat().collect();
    let se: Option<Vec<Vec3>> = reference
        .radiance
        .std_error
        .as_ref()
        .map(|s| s.iter().flatten().copied().collect());
    compare(values, &expected, se.as_deref())
}

/// Scores the vertices `shading` evaluated against a vertex reference: a
/// method that skips vertices is scored over the ones it evaluated, and
/// [`ErrorStats::count`] says how many those were.
pub fn vertices(shading: &VertexRadiance, reference: &VertexReference) -> ErrorStats {
    if shading.evaluated.is_none() {
        return against(&shading.flat().collect::<Vec<_>>(), reference);
    }
    let se = reference.radiance.std_error.as_ref();
    let se: Vec<Vec3> = se
        .map(|s| s.iter().flatten().copied().collect())
        .unwrap_or_default();
    let (mut values, mut expected, mut errors) = (Vec::new(), Vec::new(), Vec::new());
    let rows = shading.flat().zip(shading.flat_evaluated());
    for (i, ((x, evaluated), r)) in rows.zip(reference.radiance.flat()).enumerate() {
        if evaluated {
            values.push(x);
            expected.push(r);
            errors.extend(se.get(i));
        }
    }
    compare(
        &values,
        &expected,
        (!se.is_empty()).then_some(errors.as_slice()),
    )
}

/// Scores `image` over the pixels `reference` covers: a pixel the method
/// leaves uncovered counts as zero radiance, one it covers outside the
/// reference's surfaces is background and not scored. Fails if the sizes
/// differ.
pub fn image(image: &Image, reference: &ImageReference) -> Result<ErrorStats> {
    let r = &reference.image;
    if (image.width, image.height) != (r.width, r.height) {
        return Err(Error::InvalidScene(format!(
            "image {}×{} scored against a {}×{} reference",
            image.width, image.height, r.width, r.height
        )));
    }
    let scored = || (0..r.pixels.len()).filter(|&i| r.covered[i]);
    let values: Vec<Vec3> = scored()
        .map(|i| {
            if image.covered[i] {
                image.pixels[i]
            } else {
                Vec3::ZERO
            }
        })
        .collect();
    let expected: Vec<Vec3> = scored().map(|i| r.pixels[i]).collect();
    let se: Option<Vec<Vec3>> = r
        .std_error
        .as_ref()
        .map(|se| scored().map(|i| se[i]).collect());
    Ok(compare(&values, &expected, se.as_deref()))
}

/// How much a method's per-vertex error changes from one frame to the next:
/// what the eye sees as flicker or popping (lightsphere levels switching,
/// visible sets changing, map aliasing), which a low mean error can hide.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Temporal {
    /// `sqrt(Σ|e_t − e_{t−1}|² / Σ|r_t|²)` with `e = x − r` per vertex, over
    /// the vertices evaluated in both frames.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub error_change: f32,
    /// The same of the reference itself, `sqrt(Σ|r_t − r_{t−1}|² / Σ|r_t|²)`:
    /// how much the true shading moves between the two frames.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub reference_change: f32,
    /// The part of `error_change` the references' noise explains:
    /// `sqrt(n_t² + n_{t−1}²)`, their relative L2 noises combined.
    #[serde(deserialize_with = "crate::io::f32_or_null")]
    pub noise_floor: f32,
}

/// [`Temporal`] between the previous frame's shading and reference and this
/// frame's (same scene, so the same vertices).
pub fn temporal(
    previous: (&VertexRadiance, &VertexReference),
    current: (&VertexRadiance, &VertexReference),
) -> Temporal {
    let evaluated = |s: &VertexRadiance| -> Vec<bool> { s.flat_evaluated().collect() };
    let (was, is) = (evaluated(previous.0), evaluated(current.0));
    let (mut change, mut truth, mut norm) = (0.0f64, 0.0f64, 0.0f64);
    let rows = previous
        .0
        .flat()
        .zip(previous.1.radiance.flat())
        .zip(current.0.flat().zip(current.1.radiance.flat()));
    for (i, ((x0, r0), (x1, r1))) in rows.enumerate() {
        norm += f64::from(r1.length_squared());
        truth += f64::from((r1 - r0).length_squared());
        if was[i] && is[i] {
            change += f64::from(((x1 - r1) - (x0 - r0)).length_squared());
        }
    }
    let relative = |x: f64| (x / norm.max(f64::MIN_POSITIVE)).sqrt() as f32;
    Temporal {
        error_change: relative(change),
        reference_change: relative(truth),
        noise_floor: previous.1.noise.hypot(current.1.noise),
    }
}

/// Compares `values` with `reference` element by element; `std_error` is the
/// reference's standard error per element, if known.
pub fn compare(values: &[Vec3], reference: &[Vec3], std_error: Option<&[Vec3]>) -> ErrorStats {
    assert_eq!(
        values.len(),
        reference.len(),
        "compare: domains differ in size"
    );
    let sum_r2: f64 = reference.iter().map(|r| r.length_squared() as f64).sum();
    let sum_d2: f64 = values
        .iter()
        .zip(reference)
        .map(|(x, r)| (*x - *r).length_squared() as f64)
        .sum();
    let n = reference.len().max(1);
    let floor = FLOOR * (sum_r2 / n as f64).sqrt() as f32;
    let mut relative: Vec<f32> = values
        .iter()
        .zip(reference)
        .map(|(x, r)| (*x - *r).length() / r.length().max(floor).max(f32::MIN_POSITIVE))
        .collect();
    relative.sort_unstable_by(f32::total_cmp);
    let noise = std_error.map_or(0.0, |se| {
        se.iter().map(|s| s.length_squared() as f64).sum::<f64>()
    });
    let ratio = |num: f64| {
        if sum_r2 > 0.0 {
            (num / sum_r2).sqrt() as f32
        } else if num == 0.0 {
            0.0
        } else {
            f32::INFINITY
        }
    };
    ErrorStats {
        relative_l2: ratio(sum_d2),
        p50: percentile(&relative, 0.5),
        p90: percentile(&relative, 0.9),
        p99: percentile(&relative, 0.99),
        max: relative.last().copied().unwrap_or(0.0),
        reference_noise: ratio(noise),
        count: reference.len(),
    }
}

/// The `q` quantile of sorted values (nearest rank).
fn percentile(sorted: &[f32], q: f64) -> f32 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn reference(values: Vec<Vec3>, noise: f32) -> VertexReference {
        VertexReference {
            radiance: VertexRadiance::new(vec![values]),
            replicates: Vec::new(),
            rays: 0,
            noise,
            seconds: 0.0,
        }
    }

    #[test]
    fn a_steady_bias_does_not_flicker_and_a_switching_one_does() {
        let (r0, r1) = (vec![Vec3::ONE; 4], vec![Vec3::splat(1.1); 4]);
        let refs = (reference(r0.clone(), 0.003), reference(r1.clone(), 0.004));
        let shifted =
            |r: &[Vec3], by: f32| VertexRadiance::new(vec![r.iter().map(|v| *v + by).collect()]);
        let steady = temporal((&shifted(&r0, 0.2), &refs.0), (&shifted(&r1, 0.2), &refs.1));
        assert_relative_eq!(steady.error_change, 0.0, epsilon = 1e-6);
        assert_relative_eq!(steady.reference_change, 0.1 / 1.1, epsilon = 1e-5);
        assert_relative_eq!(steady.noise_floor, 0.005, epsilon = 1e-6);
        let popping = temporal(
            (&shifted(&r0, 0.2), &refs.0),
            (&shifted(&r1, -0.2), &refs.1),
        );
        assert_relative_eq!(popping.error_change, 0.4 / 1.1, epsilon = 1e-5);
    }

    #[test]
    fn identical_values_score_zero() {
        let r = vec![Vec3::ONE, Vec3::splat(2.0)];
        let s = compare(&r, &r, None);
        assert_eq!((s.relative_l2, s.p99, s.max), (0.0, 0.0, 0.0));
    }

    #[test]
    fn uniform_ten_percent_error() {
        let r: Vec<Vec3> = (1..=100).map(|i| Vec3::splat(i as f32)).collect();
        let x: Vec<Vec3> = r.iter().map(|v| *v * 1.1).collect();
        let s = compare(&x, &r, Some(&vec![Vec3::splat(0.01); 100]));
        assert_relative_eq!(s.relative_l2, 0.1, epsilon = 1e-5);
        assert_relative_eq!(s.p99, 0.1, epsilon = 1e-5);
        assert_relative_eq!(s.max, 0.1, epsilon = 1e-5);
        assert!(s.reference_noise > 0.0 && s.reference_noise < 0.01);
    }

    #[test]
    fn dark_elements_use_the_floor() {
        let mut r = vec![Vec3::ONE; 99];
        r.push(Vec3::ZERO);
        let mut x = r.clone();
        x[99] = Vec3::splat(0.001);
        let s = compare(&x, &r, None);
        // |x − r| = 0.0017, floor = 0.01 · rms ≈ 0.00995 ⇒ relative ≈ 0.17, not ∞.
        assert!(s.max > 0.1 && s.max < 0.2, "{}", s.max);
    }
}
