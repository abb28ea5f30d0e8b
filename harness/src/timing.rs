//! Wall-clock samples of a stage and what the report says of them: the
//! median, and the spread from the fastest to the slowest sample.

use serde::{Deserialize, Deserializer, Serialize, Serializer, ser::SerializeStruct};

/// Seconds of repeated runs of one stage (or of a frame's stages summed per
/// repeat). Reports give the median with the range; a single sample is
/// shown as such, never as a figure with a spread.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timing {
    samples: Vec<f64>,
}

impl Timing {
    /// The samples in seconds, in the order they were taken.
    pub fn new(samples: Vec<f64>) -> Timing {
        Timing { samples }
    }

    /// Every sample of every timing of `timings`, pooled.
    pub fn pooled<'a>(timings: impl IntoIterator<Item = &'a Timing>) -> Timing {
        Timing::new(
            timings
                .into_iter()
                .flat_map(|t| t.samples.iter().copied())
                .collect(),
        )
    }

    /// Sample by sample sums of `self` and `other` (repeats paired in
    /// order); the shorter one decides how many.
    pub fn plus(&self, other: &Timing) -> Timing {
        Timing::new(
            self.samples
                .iter()
                .zip(&other.samples)
                .map(|(a, b)| a + b)
                .collect(),
        )
    }

    pub fn samples(&self) -> &[f64] {
        &self.samples
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The median (the upper one for an even count); 0 without samples.
    pub fn median(&self) -> f64 {
        crate::run::median(self.samples.clone())
    }

    /// The fastest sample; 0 without samples.
    pub fn min(&self) -> f64 {
        self.samples.iter().copied().reduce(f64::min).unwrap_or(0.0)
    }

    /// The slowest sample; 0 without samples.
    pub fn max(&self) -> f64 {
        self.samples.iter().copied().reduce(f64::max).unwrap_or(0.0)
    }

    /// "12.30 ms (11.90–13.00, 3 samples)", or "12.30 ms (1 sample)".
    pub fn describe_ms(&self) -> String {
        match self.len() {
            0 => "–".into(),
            1 => format!("{:.2} ms (1 sample)", self.median() * 1e3),
            n => format!(
                "{:.2} ms ({:.2}–{:.2}, {n} samples)",
                self.median() * 1e3,
                self.min() * 1e3,
                self.max() * 1e3
            ),
        }
    }
}

/// As `{median, min, max, samples}` in seconds: the summary beside the
/// samples it was computed from.
impl Serialize for Timing {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut s = serializer.serialize_struct("Timing", 4)?;
        s.serialize_field("median", &self.median())?;
        s.serialize_field("min", &self.min())?;
        s.serialize_field("max", &self.max())?;
        s.serialize_field("samples", &self.samples)?;
        s.end()
    }
}

/// Reads back what [`Serialize`] wrote: the samples (the summary is
/// recomputed from them).
impl<'de> Deserialize<'de> for Timing {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Timing, D::Error> {
        #[derive(Deserialize)]
        struct Samples {
            samples: Vec<f64>,
        }
        Samples::deserialize(deserializer).map(|s| Timing::new(s.samples))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_range_of_samples() {
        let t = Timing::new(vec![0.003, 0.001, 0.002]);
        assert_eq!((t.median(), t.min(), t.max()), (0.002, 0.001, 0.003));
        assert_eq!(t.describe_ms(), "2.00 ms (1.00–3.00, 3 samples)");
        assert_eq!(Timing::new(vec![0.5]).describe_ms(), "500.00 ms (1 sample)");
        assert_eq!(Timing::default().median(), 0.0);
    }

    #[test]
    fn sums_pair_repeats_and_pooling_keeps_every_sample() {
        let a = Timing::new(vec![1.0, 2.0, 3.0]);
        let b = Timing::new(vec![10.0, 20.0]);
        assert_eq!(a.plus(&b).samples(), &[11.0, 22.0]);
        assert_eq!(Timing::pooled([&a, &b]).len(), 5);
        let json = serde_json::to_value(&a).unwrap();
        assert_eq!(json["median"], 2.0);
        assert_eq!(json["samples"].as_array().unwrap().len(), 3);
        assert_eq!(serde_json::from_value::<Timing>(json).unwrap(), a);
    }
}
