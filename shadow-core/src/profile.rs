//! Where a method's stages spend their time, as the method itself measures it:
//! the breakdown behind a stage's wall-clock time (render depth maps, read
//! back, integrate), and counts that explain it (blockers per vertex).

use std::{borrow::Cow, fmt};

/// The stages of [`ShadowMethod`](crate::ShadowMethod), in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
#[non_exhaustive]
pub enum Stage {
    Prepare,
    Relight,
    Update,
    Shade,
    Render,
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stage::Prepare => "prepare",
            Stage::Update => "update",
            Stage::Relight => "relight",
            Stage::Shade => "shade",
            Stage::Render => "render",
        })
    }
}

/// A named measurement within one stage.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ProfileEntry {
    pub stage: Stage,
    /// What the entry measures, e.g. "rasterization" or "depth maps":
    /// a method's own constant, or a name read back from a saved report.
    pub name: Cow<'static, str>,
    pub value: ProfileValue,
}

/// Seconds of wall clock, or a count.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum ProfileValue {
    Seconds(f64),
    Count(u64),
}

impl fmt::Display for ProfileValue {
    /// Seconds in milliseconds ("12.34 ms"), counts as integers.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ProfileValue::Seconds(s) => write!(f, "{:.2} ms", s * 1e3),
            ProfileValue::Count(n) => write!(f, "{n}"),
        }
    }
}

/// The breakdown of the most recent call of each stage. A stage that measures
/// itself starts with [`Profile::begin`] (dropping what its previous call
/// recorded) and adds entries with [`Profile::seconds`] and [`Profile::count`].
#[derive(Clone, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Profile {
    entries: Vec<ProfileEntry>,
}

impl Profile {
    /// Forgets what the previous call of `stage` recorded.
    pub fn begin(&mut self, stage: Stage) {
        self.entries.retain(|e| e.stage != stage);
    }

    /// Records that part `name` of `stage` took `seconds`.
    pub fn seconds(&mut self, stage: Stage, name: impl Into<Cow<'static, str>>, seconds: f64) {
        self.set(stage, name, ProfileValue::Seconds(seconds));
    }

    /// Records a count within `stage`.
    pub fn count(&mut self, stage: Stage, name: impl Into<Cow<'static, str>>, count: u64) {
        self.set(stage, name, ProfileValue::Count(count));
    }

    fn set(&mut self, stage: Stage, name: impl Into<Cow<'static, str>>, value: ProfileValue) {
        let name = name.into();
        match self
            .entries
            .iter_mut()
            .find(|e| e.stage == stage && e.name == name)
        {
            Some(entry) => entry.value = value,
            None => self.entries.push(ProfileEntry { stage, name, value }),
        }
    }

    /// Every entry, in the order first recorded.
    pub fn entries(&self) -> &[ProfileEntry] {
        &self.entries
    }

    /// The value of part `name` of `stage`, if recorded.
    pub fn get(&self, stage: Stage, name: &str) -> Option<ProfileValue> {
        self.entries
            .iter()
            .find(|e| e.stage == stage && e.name == name)
            .map(|e| e.value)
    }

    /// The seconds part `name` of `stage` took, if recorded as seconds.
    pub fn seconds_in(&self, stage: Stage, name: &str) -> Option<f64> {
        match self.get(stage, name)? {
            ProfileValue::Seconds(s) => Some(s),
            ProfileValue::Count(_) => None,
        }
    }

    /// The count `name` of `stage`, if recorded as a count.
    pub fn count_in(&self, stage: Stage, name: &str) -> Option<u64> {
        match self.get(stage, name)? {
            ProfileValue::Count(n) => Some(n),
            ProfileValue::Seconds(_) => None,
        }
    }

    /// The entries of the stages `keep` accepts.
    pub fn of_stages(&self, keep: impl Fn(Stage) -> bool) -> Profile {
        Profile {
            entries: self
                .entries
                .iter()
                .filter(|e| keep(e.stage))
                .cloned()
                .collect(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl fmt::Display for Profile {
    /// One stage per line: "update: gather 1.20 ms, rasterization 8.00 ms".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut stages: Vec<Stage> = self.entries.iter().map(|e| e.stage).collect();
        stages.sort();
        stages.dedup();
        for (i, stage) in stages.into_iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{stage}:")?;
            let parts = self.entries.iter().filter(|e| e.stage == stage);
            for (j, e) in parts.enumerate() {
                write!(
                    f,
                    "{} {} {}",
                    if j == 0 { "" } else { "," },
                    e.name,
                    e.value
                )?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_replaces_only_its_own_entries() {
        let mut p = Profile::default();
        p.begin(Stage::Update);
        p.seconds(Stage::Update, "rasterize", 0.002);
        p.count(Stage::Update, "blockers", 7);
        p.seconds(Stage::Relight, "project", 0.001);
        p.begin(Stage::Update);
        p.seconds(Stage::Update, "rasterize", 0.003);
        assert_eq!(
            p.get(Stage::Update, "rasterize"),
            Some(ProfileValue::Seconds(0.003))
        );
        assert_eq!(p.get(Stage::Update, "blockers"), None);
        assert_eq!(
            p.get(Stage::Relight, "project"),
            Some(ProfileValue::Seconds(0.001))
        );
        assert_eq!(
            p.to_string(),
            "relight: project 1.00 ms\nupdate: rasterize 3.00 ms"
        );
    }
}
