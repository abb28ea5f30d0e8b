//! The viewer's timings: each measured quantity's last samples, shown as
//! their median and range.

use std::collections::VecDeque;
use std::time::Duration;

/// Samples kept per quantity.
const WINDOW: usize = 31;

/// The last [`WINDOW`] samples of named quantities, in first-seen order.
#[derive(Debug, Default)]
pub struct Clock {
    rows: Vec<(String, VecDeque<f64>)>,
}

/// A quantity's median and range over its samples, in milliseconds.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    pub name: String,
    pub median_ms: f64,
    pub min_ms: f64,
    pub max_ms: f64,
    pub samples: usize,
}

impl Clock {
    pub fn add(&mut self, name: &str, time: Duration) {
        let index = match self.rows.iter().position(|(n, _)| n == name) {
            Some(i) => i,
            None => {
                self.rows.push((name.to_string(), VecDeque::new()));
                self.rows.len() - 1
            }
        };
        let samples = &mut self.rows[index].1;
        if samples.len() == WINDOW {
            samples.pop_front();
        }
        samples.push_back(time.as_secs_f64() * 1e3);
    }

    pub fn summaries(&self) -> Vec<Summary> {
        self.rows
            .iter()
            .filter(|(_, s)| !s.is_empty())
            .map(|(name, samples)| {
                let mut sorted: Vec<f64> = samples.iter().copied().collect();
                sorted.sort_by(f64::total_cmp);
                let n = sorted.len();
                let median = if n % 2 == 1 {
                    sorted[n / 2]
                } else {
                    0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
                };
                Summary {
                    name: name.clone(),
                    median_ms: median,
                    min_ms: sorted[0],
                    max_ms: sorted[n - 1],
                    samples: n,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_are_medians_and_ranges_of_the_last_window() {
        let mut clock = Clock::default();
        for ms in [5, 1, 3] {
            clock.add("frame", Duration::from_millis(ms));
        }
        clock.add("shade", Duration::from_millis(2));
        let s = clock.summaries();
        assert_eq!(s[0].name, "frame");
        assert_eq!((s[0].median_ms, s[0].min_ms, s[0].max_ms), (3.0, 1.0, 5.0));
        assert_eq!(s[1].samples, 1);
        for _ in 0..100 {
            clock.add("frame", Duration::from_millis(7));
        }
        let s = clock.summaries();
        assert_eq!(s[0].samples, WINDOW);
        assert_eq!((s[0].min_ms, s[0].max_ms), (7.0, 7.0));
    }
}
