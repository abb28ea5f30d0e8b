//! A report split into parts that run apart (a Slurm array's tasks, a CI
//! matrix's jobs) and merged into one.
//!
//! A part is a whole number of the plan's scenes, dealt round-robin: the
//! built-in scenes then the stress scenes, the `u`-th (from 0) to part
//! `(u mod N) + 1`.
//! Each part writes its `report.json` and its images; [`merge`] puts the
//! runs back in the plan's order and judges the atlas again over every
//! standard scene ([`super::atlas::judge`]), so the merged page's tables are
//! those of one run of the whole plan. A part runs the remedies of every
//! stress run that may fail ([`super::AtlasRun::may_fail`]), since whether it
//! does depends on scenes other parts run.

use std::{fmt, fs, path::Path, str::FromStr};

use serde::{Deserialize, Serialize};
use shadow_core::{Error, Result};

use super::{Report, Settings};

/// The `index`-th (from 1) of `count` disjoint parts of a report's plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Part {
    index: usize,
    count: usize,
}

impl Part {
    /// The whole plan, as one part.
    pub const WHOLE: Part = Part { index: 1, count: 1 };

    /// Part `index` of `count`; fails unless `1 <= index <= count`.
    pub fn new(index: usize, count: usize) -> Result<Part> {
        if index == 0 || index > count {
            return Err(Error::config(
                "--shard",
                format!("part {index}/{count}: expected I/N with 1 <= I <= N"),
            ));
        }
        Ok(Part { index, count })
    }

    pub fn index(self) -> usize {
        self.index
    }

    pub fn count(self) -> usize {
        self.count
    }

    pub fn is_whole(self) -> bool {
        self.count == 1
    }

    /// Whether the plan's `unit`-th scene (from 0; built-in scenes first,
    /// then stress scenes) is this part's.
    pub fn holds(self, unit: usize) -> bool {
        unit % self.count == self.index - 1
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Part {
    type Err = Error;

    /// `I/N`, as `--shard` takes it.
    fn from_str(s: &str) -> Result<Part> {
        let parse = |n: &str| n.trim().parse::<usize>().ok();
        match s.split_once('/').map(|(i, n)| (parse(i), parse(n))) {
            Some((Some(index), Some(count))) => Part::new(index, count),
            _ => Err(Error::config(
                "--shard",
                format!("{s:?}: expected I/N, e.g. 2/4"),
            )),
        }
    }
}

impl Report {
    /// Writes a part's results into `dir`: its `report.json` (its pictures
    /// are already there), which [`Report::read`] reads back.
    pub fn write_part(&self, dir: &Path) -> Result<()> {
        crate::io::write_json_atomic(&dir.join("report.json"), self)
    }

    /// The report a part wrote into `dir` (its `report.json`).
    pub fn read(dir: &Path) -> Result<Report> {
        let path = dir.join("report.json");
        let bytes = fs::read(&path).map_err(|e| Error::io(&path, e))?;
        serde_json::from_slice(&bytes)
            .map_err(|e| Error::format(&path, format!("not a report's JSON: {e}")))
    }
}

/// The one report of the whole plan from its parts (each part exactly
/// once, in any order): every list in the plan's order of scenes, the atlas
/// judged over all standard scenes, the machine of the first part (each
/// part's in [`Report::merged_from`]). Each part comes with the name its
/// errors call it by (its folder).
pub fn merge(parts: Vec<(String, Report)>) -> Result<Report> {
    let Some((first_name, first)) = parts.first() else {
        return Err(Error::config("--merge", "no parts given"));
    };
    let count = first.settings.part.count;
    let plan = |r: &Report| {
        let settings = Settings {
            part: Part::WHOLE,
            ..r.settings.clone()
        };
        (settings, r.families.clone())
    };
    let mut seen = vec![None::<&str>; count];
    for (name, part) in &parts {
        if plan(part) != plan(first) {
            return Err(Error::config(
                "--merge",
                format!(
                    "{name} is a part of another plan than {first_name} (suite, scenes, \
                     settings or reference targets differ)"
                ),
            ));
        }
        let p = part.settings.part;
        if p.count != count || p.index == 0 || p.index > count {
            return Err(Error::config(
                "--merge",
                format!(
                    "{name} is part {p}, {first_name} part {} of {count}",
                    first.settings.part.index
                ),
            ));
        }
        if let Some(other) = seen[p.index - 1].replace(name) {
            return Err(Error::config(
                "--merge",
                format!("{name} and {other} are both part {p}"),
            ));
        }
    }
    let missing: Vec<String> = (1..=count)
        .filter(|i| seen[i - 1].is_none())
        .map(|i| format!("{i}/{count}"))
        .collect();
    if !missing.is_empty() {
        return Err(Error::config(
            "--merge",
            format!("part {} missing (run it with --shard)", missing.join(", ")),
        ));
    }

    let mut parts: Vec<Report> = parts.into_iter().map(|(_, r)| r).collect();
    parts.sort_by_key(|r| r.settings.part.index);
    let order: Vec<String> = parts[0]
        .settings
        .scenes
        .iter()
        .chain(&parts[0].settings.atlas_scenes)
        .cloned()
        .collect();
    let unit = |scene: &str| order.iter().position(|s| s == scene).unwrap_or(order.len());
    let mut merged = Report::new(
        parts[0].machine.clone(),
        Settings {
            part: Part::WHOLE,
            ..parts[0].settings.clone()
        },
        parts[0].families.clone(),
    );
    merged.merged_from = parts.iter().map(|r| r.machine.clone()).collect();
    if merged.machine.adapter.is_none() {
        merged.machine.adapter = parts.iter().find_map(|r| r.machine.adapter.clone());
    }
    for part in parts {
        merged.references.extend(part.references);
        merged.runs.extend(part.runs);
        merged.skipped.extend(part.skipped);
        merged.failed.extend(part.failed);
        merged.atlas_scenes.extend(part.atlas_scenes);
        merged.atlas.extend(part.atlas);
        merged.remedies.extend(part.remedies);
        merged.scaling.extend(part.scaling);
        merged.pictures.extend(part.pictures);
    }
    // Stable sorts: within a scene, the order its part ran in.
    merged.references.sort_by_key(|r| unit(&r.scene));
    merged.runs.sort_by_key(|r| unit(&r.result.scene));
    merged.skipped.sort_by_key(|s| unit(&s.scene));
    merged.failed.sort_by_key(|s| unit(&s.scene));
    merged.atlas_scenes.sort_by_key(|s| unit(&s.name));
    merged.atlas.sort_by_key(|r| unit(&r.scene));
    merged.remedies.sort_by_key(|r| unit(&r.scene));
    merged.scaling.sort_by_key(|r| unit(&r.scene));
    merged.pictures.sort_by_key(|r| unit(&r.scene));
    merged.judge_atlas();
    Ok(merged)
}

/// Copies the pictures a part wrote (`pictures/` under `part`) into the
/// merged report's folder `out_dir`, each file atomically.
pub fn copy_images(part: &Path, out_dir: &Path) -> Result<()> {
    copy_tree(&part.join("pictures"), &out_dir.join("pictures"))
}

/// Every file under `from` to the same place under `to`; nothing when
/// `from` does not exist.
fn copy_tree(from: &Path, to: &Path) -> Result<()> {
    if !from.exists() {
        return Ok(());
    }
    for entry in fs::read_dir(from).map_err(|e| Error::io(from, e))? {
        let entry = entry.map_err(|e| Error::io(from, e))?;
        let (source, target) = (entry.path(), to.join(entry.file_name()));
        if source.is_dir() {
            copy_tree(&source, &target)?;
        } else if source != target {
            let bytes = fs::read(&source).map_err(|e| Error::io(&source, e))?;
            crate::io::write_atomic(&target, &bytes)?;
        }
    }
    Ok(())
}
