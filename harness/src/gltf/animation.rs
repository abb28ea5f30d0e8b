//! Animation clips: keyframe channels driving node translation, rotation,
//! scale and morph weights, sampled with STEP, LINEAR (slerp for rotations)
//! or CUBICSPLINE interpolation (glTF 2.0 §3.11 and Appendix C).

use std::collections::HashSet;
use std::path::Path;

use ::gltf::accessor::Dimensions;
use ::gltf::animation::{Interpolation, Property};
use glam::{Quat, Vec3};
use shadow_core::{Error, Result};

use super::accessor::Buffers;
use super::hierarchy::{Local, unit_rotation};

/// One clip: its channels and its duration, the last key time of any channel.
pub(super) struct Clip {
    pub name: String,
    pub duration: f32,
    channels: Vec<Channel>,
}

struct Channel {
    node: usize,
    property: Property,
    sampler: Sampler,
}

/// Key times and values. `width` floats per value (3 for translation and
/// scale, 4 for rotation quaternions as x, y, z, w, the morph-target count for
/// weights); CUBICSPLINE stores in-tangent, value, out-tangent per key.
struct Sampler {
    interpolation: Interpolation,
    times: Vec<f32>,
    values: Vec<f32>,
    width: usize,
}

impl Clip {
    /// Reads and checks one animation: key times finite and strictly
    /// increasing, one value (three for CUBICSPLINE) per key, no channel on a
    /// node given by a matrix (§3.11.1), weights only on nodes with morph
    /// targets, one channel per node and property. `target_counts[n]` is the
    /// number of morph targets of node n's mesh.
    pub fn new(
        path: &Path,
        animation: &::gltf::Animation,
        buffers: &Buffers,
        rest: &[Local],
        target_counts: &[usize],
    ) -> Result<Clip> {
        let name = animation.name().map_or_else(
            || format!("animation {}", animation.index()),
            str::to_string,
        );
        let mut channels = Vec::new();
        let mut seen = HashSet::new();
        for channel in animation.channels() {
            let node = channel.target().node().index();
            let property = channel.target().property();
            let bad = |what: String| {
                Error::format(
                    path,
                    format!(
                        "{}, channel {} ({property:?} of node {node}): {what}",
                        super::named("animation", animation.index(), animation.name()),
                        channel.index()
                    ),
                )
            };
            if !seen.insert((node, property as u32)) {
                return Err(bad("a second channel for the same node and property".into()));
            }
            if matches!(rest[node], Local::Matrix(_)) && property != Property::MorphTargetWeights {
                return Err(bad("animates a node whose transform is a matrix".into()));
            }
            let (width, dims) = match property {
                Property::Translation | Property::Scale => (3, Dimensions::Vec3),
                Property::Rotation => (4, Dimensions::Vec4),
                Property::MorphTargetWeights => (target_counts[node], Dimensions::Scalar),
            };
            if width == 0 {
                return Err(bad(
                    "animates morph weights of a node without morph targets".into(),
                ));
            }
            let sampler = channel.sampler();
            let what = format!(
                "{}, sampler {}",
                super::named("animation", animation.index(), animation.name()),
                sampler.index()
            );
            let times = buffers.floats(
                &sampler.input(),
                &format!("{what} input"),
                Dimensions::Scalar,
            )?;
            if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
                return Err(bad(format!(
                    "key times {} and {} are not increasing",
                    times[k],
                    times[k + 1]
                )));
            }
            let mut values = buffers.floats(&sampler.output(), &format!("{what} output"), dims)?;
            let interpolation = sampler.interpolation();
            let per_key = width
                * if interpolation == Interpolation::CubicSpline {
                    3
                } else {
                    1
                };
            if values.len() != times.len() * per_key {
                return Err(bad(format!(
                    "{} output values for {} keys of {per_key} values ({interpolation:?})",
                    values.len(),
                    times.len()
                )));
            }
            if property == Property::Rotation && interpolation != Interpolation::CubicSpline {
                for (k, q) in values.chunks_exact_mut(4).enumerate() {
                    let unit = unit_rotation(Quat::from_slice(q))
                        .ok_or_else(|| bad(format!("key {k} is a zero quaternion")))?;
                    q.copy_from_slice(&unit.to_array());
                }
            }
            channels.push(Channel {
                node,
                property,
                sampler: Sampler {
                    interpolation,
                    times,
                    values,
                    width,
                },
            });
        }
        let duration = channels
            .iter()
            .filter_map(|c| c.sampler.times.last())
            .fold(0.0f32, |a, &b| a.max(b));
        Ok(Clip {
            name,
            duration,
            channels,
        })
    }

    /// True when some channel drives node `node`'s morph weights.
    pub fn animates_weights(&self, node: usize) -> bool {
        self.channels
            .iter()
            .any(|c| c.node == node && c.property == Property::MorphTargetWeights)
    }

    /// Overwrites the animated properties of `locals` and `weights` (per node)
    /// with their values at `time`, which is clamped to [0, duration]: before a
    /// channel's first key it holds the first value, after its last the last.
    pub fn apply(&self, time: f32, locals: &mut [Local], weights: &mut [Vec<f32>]) {
        let time = time.clamp(0.0, self.duration);
        let mut value = Vec::new();
        for channel in &self.channels {
            channel
                .sampler
                .sample(time, channel.property == Property::Rotation, &mut value);
            match (channel.property, &mut locals[channel.node]) {
                (Property::MorphTargetWeights, _) => weights[channel.node].clone_from(&value),
                (Property::Translation, Local::Trs(trs)) => {
                    trs.translation = Vec3::from_slice(&value)
                }
                (Property::Scale, Local::Trs(trs)) => trs.scale = Vec3::from_slice(&value),
                (Property::Rotation, Local::Trs(trs)) => trs.rotation = Quat::from_slice(&value),
                // Rejected in `Clip::new`.
                (_, Local::Matrix(_)) => {}
            }
        }
    }
}

impl Sampler {
    /// The `width` components of the value at `time`; rotations come out as
    /// unit quaternions.
    fn sample(&self, time: f32, rotation: bool, out: &mut Vec<f32>) {
        out.clear();
        let cubic = self.interpolation == Interpolation::CubicSpline;
        // Element e of key k (CUBICSPLINE: 0 in-tangent, 1 value, 2 out-tangent).
        let element = |k: usize, e: usize| {
            let start = if cubic {
                (3 * k + e) * self.width
            } else {
                k * self.width
            };
            &self.values[start..start + self.width]
        };
        let last = self.times.len() - 1;
        let k = self.times.partition_point(|&t| t <= time);
        if k == 0 || k > last {
            out.extend_from_slice(element(if k == 0 { 0 } else { last }, 1));
            return;
        }
        let k = k - 1;
        let dt = self.times[k + 1] - self.times[k];
        let s = (time - self.times[k]) / dt;
        match self.interpolation {
            Interpolation::Step => out.extend_from_slice(element(k, 1)),
            Interpolation::Linear if rotation => {
                let (a, b) = (
                    Quat::from_slice(element(k, 1)),
                    Quat::from_slice(element(k + 1, 1)),
                );
                out.extend_from_slice(&a.slerp(b, s).normalize().to_array());
            }
            Interpolation::Linear => out.extend(
                element(k, 1)
                    .iter()
                    .zip(element(k + 1, 1))
                    .map(|(a, b)| a + (b - a) * s),
            ),
            Interpolation::CubicSpline => {
                // Hermite basis, Appendix C: tangents scaled by the key interval.
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = (s3 - 2.0 * s2 + s) * dt;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = (s3 - s2) * dt;
                let (v0, b0) = (element(k, 1), element(k, 2));
                let (v1, a1) = (element(k + 1, 1), element(k + 1, 0));
                out.extend(
                    (0..self.width).map(|i| h00 * v0[i] + h10 * b0[i] + h01 * v1[i] + h11 * a1[i]),
                );
                if rotation {
                    let q = unit_rotation(Quat::from_slice(out))
                        .or_else(|| unit_rotation(Quat::from_slice(v0)))
                        .unwrap_or(Quat::IDENTITY);
                    out.copy_from_slice(&q.to_array());
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn sampler(
        interpolation: Interpolation,
        times: &[f32],
        values: &[f32],
        width: usize,
    ) -> Sampler {
        Sampler {
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
            width,
        }
    }

    fn at(s: &Sampler, t: f32, rotation: bool) -> Vec<f32> {
        let mut out = Vec::new();
        s.sample(t, rotation, &mut out);
        out
    }

    #[test]
    fn linear_and_step_interpolate_and_clamp() {
        let s = sampler(
            Interpolation::Linear,
            &[1.0, 3.0],
            &[0.0, 10.0, 4.0, 30.0],
            2,
        );
        assert_eq!(at(&s, 0.0, false), [0.0, 10.0]);
        assert_eq!(at(&s, 2.0, false), [2.0, 20.0]);
        assert_eq!(at(&s, 5.0, false), [4.0, 30.0]);
        let s = sampler(Interpolation::Step, &[1.0, 3.0], &[0.0, 10.0, 4.0, 30.0], 2);
        assert_eq!(at(&s, 2.9, false), [0.0, 10.0]);
        assert_eq!(at(&s, 3.0, false), [4.0, 30.0]);
    }

    #[test]
    fn rotations_slerp_along_the_short_arc() {
        let a = Quat::IDENTITY;
        // The same 90° rotation about Y, written with the opposite sign: the
        // short arc passes through 45°, not through 225°.
        let b = -Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let values: Vec<f32> = [a.to_array(), b.to_array()].concat();
        let s = sampler(Interpolation::Linear, &[0.0, 1.0], &values, 4);
        let q = Quat::from_slice(&at(&s, 0.5, true));
        let expected = Quat::from_rotation_y(std::f32::consts::FRAC_PI_4);
        assert_relative_eq!(q.dot(expected).abs(), 1.0, epsilon = 1e-5);
    }

    #[test]
    fn cubic_spline_is_hermite_with_interval_scaled_tangents() {
        // y(t) = t³ on [0, 2]: y' = 3t², so tangents 0 at t=0 and 12 at t=2;
        // Hermite reproduces cubics exactly.
        let values = [0.0, 0.0, 0.0, 12.0, 8.0, 0.0];
        let s = sampler(Interpolation::CubicSpline, &[0.0, 2.0], &values, 1);
        for t in [0.0, 0.5, 1.0, 1.7, 2.0] {
            assert_relative_eq!(at(&s, t, false)[0], t * t * t, epsilon = 1e-5);
        }
        assert_eq!(at(&s, 3.0, false), [8.0]);
    }
}
