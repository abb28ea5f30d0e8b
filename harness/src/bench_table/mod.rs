//! Criterion's saved measurements as one table: each benchmark's median time
//! with criterion's confidence interval of the median, and, where the bench
//! recorded it, the method's error against the reference beside it.
//!
//! Criterion 0.8 saves each benchmark's last run under
//! `<criterion dir>/<group>/<function>/<value>/new/` (fewer levels when the
//! id has no function or no value): `benchmark.json` names it (`group_id`,
//! `function_id`, `value_str`, `full_id`) and `estimates.json` holds the
//! statistics, in nanoseconds for wall-clock time. Benches that score what
//! they time (`benches/benches/methods.rs`) write [`ERRORS_FILE`] into the
//! group's directory, through [`GroupErrors::write`].
//!
//! # Layout
//!
//! Each benchmark id becomes a row and a column of a section (a table of
//! its own in Markdown):
//!
//! - `group/function/value` (`BenchmarkId::new(function, value)`): section
//!   `group`, row `function`, column `value`; e.g. `fig7/bunny-35k-diffuse`,
//!   rows `q16`, `q32`, `q64` (lights), columns `32`, `64`, `128` (maps).
//! - `prefix/scene/method` (`BenchmarkId::from_parameter(method)` in a group
//!   named `prefix/scene`): section `prefix`, row `method`, column `scene`:
//!   method × scene, e.g. `frame/bunny/hemi-raster`.
//! - `group/function` (a named function, no value): section `group`, row
//!   `function`, one column.
//! - `prefix/name` (`Criterion::bench_function`): section `prefix`, row
//!   `name`, one column; without a `/`, section `""`.
//!
//! Sections, rows and columns are in natural order (`q16` before `q128`).

use std::{
    cmp::Ordering,
    collections::BTreeMap,
    fmt::Write,
    fs,
    path::{Path, PathBuf},
};

use serde::{Deserialize, Serialize};
use shadow_core::{Error, Result};

use crate::{io::write_json_atomic, report::Table};

/// The file, in a group's directory, that holds its benchmarks' errors.
pub const ERRORS_FILE: &str = "errors.json";

/// An estimate with criterion's confidence interval, in the measurement's
/// unit (nanoseconds for wall-clock time).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub point: f64,
    pub lower: f64,
    pub upper: f64,
    /// 0.95 by default.
    pub confidence_level: f64,
}

/// One benchmark's last run.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// Criterion's full id, `group/function/value`.
    pub id: String,
    /// The median time per iteration, nanoseconds.
    pub median: Interval,
    /// The error the bench recorded for it, as a fraction (see
    /// [`Section::error_measure`]).
    pub error: Option<f64>,
}

/// One row of a section: a cell per column, `None` where nothing was measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub name: String,
    pub cells: Vec<Option<Measurement>>,
}

/// A grid of benchmarks sharing a section name (see the module's "Layout").
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    pub name: String,
    /// Column names; `""` is the one column of ids without a value.
    pub columns: Vec<String>,
    pub rows: Vec<Row>,
    /// What the errors in this section measure, from the first
    /// [`ERRORS_FILE`] that applied.
    pub error_measure: Option<String>,
}

/// Every benchmark saved in a criterion directory, laid out in sections.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchTable {
    pub sections: Vec<Section>,
}

/// Errors of the benchmarks of one group, saved as [`ERRORS_FILE`] in the
/// group's directory and read by [`collect`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupErrors {
    /// Criterion's group id, e.g. `frame/bunny`.
    pub group_id: String,
    /// What the numbers are, in words (fractions, not percent).
    pub measure: String,
    /// By the benchmark's id within the group (`full_id` without
    /// `group_id/`); `None` (JSON `null`) for a non-finite error.
    pub errors: BTreeMap<String, Option<f64>>,
}

impl GroupErrors {
    pub fn new(group_id: impl Into<String>, measure: impl Into<String>) -> GroupErrors {
        GroupErrors {
            group_id: group_id.into(),
            measure: measure.into(),
            errors: BTreeMap::new(),
        }
    }

    /// Records the error of the benchmark `id` (within the group).
    pub fn insert(&mut self, id: impl Into<String>, error: f64) {
        self.errors
            .insert(id.into(), Some(error).filter(|e| e.is_finite()));
    }

    /// Writes [`ERRORS_FILE`] into the group's directory under
    /// `criterion_dir` (see [`criterion_dir`]), atomically; returns its path.
    pub fn write(&self, criterion_dir: &Path) -> Result<PathBuf> {
        let path = criterion_dir
            .join(group_directory(&self.group_id))
            .join(ERRORS_FILE);
        write_json_atomic(&path, self)?;
        Ok(path)
    }
}

/// Where criterion 0.8 saves its measurements, found as criterion finds it:
/// `$CRITERION_HOME`, else `$CARGO_TARGET_DIR/criterion`, else the target
/// directory `cargo metadata` reports (cargo sets `$CARGO` for benches),
/// else `target/criterion`.
pub fn criterion_dir() -> PathBuf {
    #[derive(Deserialize)]
    struct Metadata {
        target_directory: PathBuf,
    }
    if let Some(home) = std::env::var_os("CRITERION_HOME") {
        return home.into();
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .or_else(|| {
            let output = std::process::Command::new(std::env::var_os("CARGO")?)
                .args(["metadata", "--format-version", "1", "--no-deps"])
                .output()
                .ok()?;
            let metadata: Metadata = serde_json::from_slice(&output.stdout).ok()?;
            Some(metadata.target_directory)
        });
    target.map_or_else(
        || PathBuf::from("target/criterion"),
        |t| t.join("criterion"),
    )
}

/// The directory criterion names after a group id: `?"/\*<>:|^` replaced by
/// `_`, at most 64 bytes (and on Windows trimmed and lower-cased).
pub fn group_directory(group_id: &str) -> String {
    let mut name = group_id.replace(['?', '"', '/', '\\', '*', '<', '>', ':', '|', '^'], "_");
    let mut end = name.len().min(64);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    name.truncate(end);
    if cfg!(windows) {
        name = name.trim_end().to_lowercase();
    }
    name
}

/// `benchmark.json`, the fields used.
#[derive(Deserialize)]
struct BenchmarkFile {
    group_id: String,
    function_id: Option<String>,
    value_str: Option<String>,
    full_id: String,
}

/// `estimates.json`, the fields used.
#[derive(Deserialize)]
struct EstimatesFile {
    median: EstimateFile,
}

#[derive(Deserialize)]
struct EstimateFile {
    confidence_interval: ConfidenceFile,
    point_estimate: f64,
}

#[derive(Deserialize)]
struct ConfidenceFile {
    confidence_level: f64,
    lower_bound: f64,
    upper_bound: f64,
}

/// A benchmark read from its `new/` directory.
struct Saved {
    ids: BenchmarkFile,
    median: Interval,
}

/// Reads every benchmark saved under `criterion_dir` (criterion's `new/`
/// results; saved baselines are ignored) and the [`ERRORS_FILE`]s of their
/// groups, and lays them out as a table.
///
/// Errors name the file at fault: unreadable, not JSON, or missing a field
/// criterion writes; a `new/` directory with one of `benchmark.json` and
/// `estimates.json` but not the other. A directory holding no benchmark at
/// all is an error too.
pub fn collect(criterion_dir: &Path) -> Result<BenchTable> {
    let mut dirs = Vec::new();
    find_new_dirs(criterion_dir, &mut dirs)?;
    if dirs.is_empty() {
        return Err(Error::Format {
            path: criterion_dir.to_path_buf(),
            what: "no criterion measurements here (no <group>/<bench id>/new/estimates.json): \
                   run `cargo bench -p benches` first, or pass the criterion directory"
                .into(),
        });
    }
    let saved = dirs
        .iter()
        .map(|dir| read_saved(dir))
        .collect::<Result<Vec<_>>>()?;
    let errors = read_errors(criterion_dir)?;
    Ok(layout(saved, &errors))
}

/// The entries of `dir`, sorted by name.
fn sorted_entries(dir: &Path) -> Result<Vec<fs::DirEntry>> {
    let mut entries = fs::read_dir(dir)
        .and_then(|entries| entries.collect::<std::io::Result<Vec<_>>>())
        .map_err(|e| Error::io(dir, e))?;
    entries.sort_by_key(|e| e.file_name());
    Ok(entries)
}

/// Every directory named `new` under `dir` holding `benchmark.json` or
/// `estimates.json` (symbolic links are not followed).
fn find_new_dirs(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for entry in sorted_entries(dir)? {
        let path = entry.path();
        let kind = entry.file_type().map_err(|e| Error::io(&path, e))?;
        if !kind.is_dir() {
            continue;
        }
        if entry.file_name() == "new"
            && (path.join("benchmark.json").is_file() || path.join("estimates.json").is_file())
        {
            out.push(path);
        } else {
            find_new_dirs(&path, out)?;
        }
    }
    Ok(())
}

/// Reads and parses the JSON file at `path` as a `T`, `what` naming what
/// it should be in the error.
fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let bytes = fs::read(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| Error::Format {
        path: path.to_path_buf(),
        what: format!("not {what}: {e}"),
    })
}

fn read_saved(dir: &Path) -> Result<Saved> {
    let benchmark = dir.join("benchmark.json");
    let ids: BenchmarkFile = read_json(&benchmark, "criterion's benchmark.json")?;
    let path = dir.join("estimates.json");
    let estimates: EstimatesFile = read_json(&path, "criterion's estimates.json")?;
    let m = estimates.median;
    let ci = m.confidence_interval;
    let median = Interval {
        point: m.point_estimate,
        lower: ci.lower_bound,
        upper: ci.upper_bound,
        confidence_level: ci.confidence_level,
    };
    let values = [median.point, median.lower, median.upper];
    if values.iter().any(|v| !v.is_finite() || *v < 0.0) {
        return Err(Error::Format {
            path,
            what: format!("the median or its interval is not a time: {values:?}"),
        });
    }
    Ok(Saved { ids, median })
}

/// Every group's [`ERRORS_FILE`] (one level below `criterion_dir`), by
/// group id.
fn read_errors(criterion_dir: &Path) -> Result<BTreeMap<String, GroupErrors>> {
    let mut out = BTreeMap::new();
    for entry in sorted_entries(criterion_dir)? {
        let path = entry.path().join(ERRORS_FILE);
        if path.is_file() {
            let errors: GroupErrors = read_json(&path, "a bench's errors.json")?;
            out.insert(errors.group_id.clone(), errors);
        }
    }
    Ok(out)
}

/// Where a benchmark goes: section, row, column (see the module's "Layout").
fn place(ids: &BenchmarkFile) -> (String, String, String) {
    let split = |id: &str| match id.rsplit_once('/') {
        Some((prefix, last)) => (prefix.to_string(), last.to_string()),
        None => (String::new(), id.to_string()),
    };
    let group = ids.group_id.clone();
    match (&ids.function_id, &ids.value_str) {
        (Some(function), Some(value)) => (group, function.clone(), value.clone()),
        (None, Some(value)) => match ids.group_id.rsplit_once('/') {
            Some((prefix, scene)) => (prefix.to_string(), value.clone(), scene.to_string()),
            None => (group, value.clone(), String::new()),
        },
        (Some(function), None) => (group, function.clone(), String::new()),
        (None, None) => {
            let (section, row) = split(&ids.group_id);
            (section, row, String::new())
        }
    }
}

fn layout(saved: Vec<Saved>, errors: &BTreeMap<String, GroupErrors>) -> BenchTable {
    // section → (row, column) → measurement, and the section's error measure.
    type Cells = BTreeMap<(String, String), Measurement>;
    let mut sections: BTreeMap<String, (Cells, Option<String>)> = BTreeMap::new();
    for Saved { ids, median } in saved {
        let group_errors = errors.get(&ids.group_id);
        let within = (ids.full_id.strip_prefix(&ids.group_id))
            .and_then(|rest| rest.strip_prefix('/'))
            .unwrap_or(&ids.full_id);
        let error = group_errors.and_then(|g| g.errors.get(within).copied().flatten());
        let (section, row, column) = place(&ids);
        let (cells, measure) = sections.entry(section).or_default();
        if error.is_some() && measure.is_none() {
            *measure = group_errors.map(|g| g.measure.clone());
        }
        cells.insert(
            (row, column),
            Measurement {
                id: ids.full_id,
                median,
                error,
            },
        );
    }
    let mut sections: Vec<Section> = sections
        .into_iter()
        .map(|(name, (mut cells, error_measure))| {
            let mut rows: Vec<String> = cells.keys().map(|(r, _)| r.clone()).collect();
            let mut columns: Vec<String> = cells.keys().map(|(_, c)| c.clone()).collect();
            for names in [&mut rows, &mut columns] {
                names.sort_by(|a, b| natural_cmp(a, b));
                names.dedup();
            }
            let rows = rows
                .into_iter()
                .map(|row| Row {
                    cells: (columns.iter())
                        .map(|column| cells.remove(&(row.clone(), column.clone())))
                        .collect(),
                    name: row,
                })
                .collect();
            Section {
                name,
                columns,
                rows,
                error_measure,
            }
        })
        .collect();
    sections.sort_by(|a, b| natural_cmp(&a.name, &b.name));
    BenchTable { sections }
}

/// Compares names with their runs of digits as numbers: `q16` < `q128`.
fn natural_cmp(a: &str, b: &str) -> Ordering {
    fn chunks(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let mut digits = None;
        for (i, c) in s.char_indices() {
            let d = c.is_ascii_digit();
            if digits.is_some_and(|prev| prev != d) {
                out.push((digits.unwrap_or(false), &s[start..i]));
                start = i;
            }
            digits = Some(d);
        }
        if let Some(d) = digits {
            out.push((d, &s[start..]));
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for (x, y) in ca.iter().zip(&cb) {
        let order = match (x, y) {
            ((true, x), (true, y)) => {
                let (x, y) = (x.trim_start_matches('0'), y.trim_start_matches('0'));
                x.len().cmp(&y.len()).then_with(|| x.cmp(y))
            }
            ((_, x), (_, y)) => x.cmp(y),
        };
        if order != Ordering::Equal {
            return order;
        }
    }
    ca.len().cmp(&cb.len()).then_with(|| a.cmp(b))
}

/// The unit that suits `scale` nanoseconds, for three significant digits
/// at `scale`: `(nanoseconds per unit, unit, decimals)`.
fn unit_for(scale: f64) -> (f64, &'static str, usize) {
    let (divisor, unit) = match scale {
        s if s < 1e3 => (1.0, "ns"),
        s if s < 1e6 => (1e3, "µs"),
        s if s < 1e9 => (1e6, "ms"),
        _ => (1e9, "s"),
    };
    let scaled = scale / divisor;
    let decimals = match scaled {
        s if s < 10.0 => 2,
        s if s < 100.0 => 1,
        _ => 0,
    };
    (divisor, unit, decimals)
}

/// `4.18 ms [4.11, 4.30]`: the median with its interval, in one unit.
fn format_time(median: &Interval) -> String {
    let (divisor, unit, decimals) = unit_for(median.point);
    format!(
        "{:.*} {unit} [{:.*}, {:.*}]",
        decimals,
        median.point / divisor,
        decimals,
        median.lower / divisor,
        decimals,
        median.upper / divisor,
    )
}

/// `1.23%`, or three significant digits below 1%.
fn format_error(error: f64) -> String {
    let percent = error * 100.0;
    if percent != 0.0 && percent.abs() < 1.0 {
        let decimals = (2.0 - percent.abs().log10().floor()).clamp(2.0, 6.0) as usize;
        format!("{percent:.decimals$}%")
    } else {
        format!("{percent:.2}%")
    }
}

/// A Markdown table cell's text: `|` escaped, line breaks as spaces.
fn markdown_cell(text: &str) -> String {
    text.replace('|', "\\|").replace(['\n', '\r'], " ")
}

impl BenchTable {
    /// Every measurement, section by section, row by row.
    pub fn measurements(&self) -> impl Iterator<Item = (&Section, &Row, &str, &Measurement)> {
        self.sections.iter().flat_map(|section| {
            section.rows.iter().flat_map(move |row| {
                (section.columns.iter().zip(&row.cells)).filter_map(move |(column, cell)| {
                    Some((section, row, column.as_str(), cell.as_ref()?))
                })
            })
        })
    }

    /// A short legend, then one Markdown table per section: its name in the
    /// corner, a row per row name, a column per column name, each cell the
    /// median time per iteration with its confidence interval in brackets
    /// and, after `·`, the recorded error; `–` where nothing was measured.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let mut levels: Vec<f64> = self
            .measurements()
            .map(|m| m.3.median.confidence_level)
            .collect();
        levels.sort_by(f64::total_cmp);
        levels.dedup();
        let level = match levels.as_slice() {
            [level] => format!("{}%", level * 100.0),
            _ => "per-benchmark (see the CSV)".to_string(),
        };
        let _ = writeln!(
            s,
            "Median time per iteration from criterion's last run, with criterion's {level} \
             confidence interval of the median in brackets; after `·`, the error the bench \
             recorded for it.\n"
        );
        for section in &self.sections {
            if let Some(measure) = &section.error_measure {
                let name = if section.name.is_empty() {
                    "the table"
                } else {
                    &section.name
                };
                let _ = writeln!(
                    s,
                    "Errors in {}: {}.\n",
                    markdown_cell(name),
                    markdown_cell(measure)
                );
            }
        }
        for (i, section) in self.sections.iter().enumerate() {
            if i > 0 {
                s.push('\n');
            }
            let mut table = Table {
                header: std::iter::once(section.name.clone())
                    .chain(section.columns.iter().map(|c| {
                        if c.is_empty() {
                            "time".to_string()
                        } else {
                            c.clone()
                        }
                    }))
                    .collect(),
                numeric: std::iter::once(false)
                    .chain(section.columns.iter().map(|_| true))
                    .collect(),
                rows: Vec::new(),
            };
            for row in &section.rows {
                table.row(
                    std::iter::once(row.name.clone())
                        .chain(row.cells.iter().map(|cell| match cell {
                            None => "–".to_string(),
                            Some(m) => match m.error {
                                Some(error) => {
                                    format!("{} · {}", format_time(&m.median), format_error(error))
                                }
                                None => format_time(&m.median),
                            },
                        }))
                        .collect(),
                );
            }
            s.push_str(&table.markdown());
        }
        s
    }

    /// One line per measurement, with a header: `section,row,column,id,
    /// median_ns,lower_ns,upper_ns,confidence_level,error` (`error` a
    /// fraction, empty where none was recorded).
    pub fn csv(&self) -> String {
        let mut table = Table::new(&[
            "section",
            "row",
            "column",
            "id",
            "median_ns",
            "lower_ns",
            "upper_ns",
            "confidence_level",
            "error",
        ]);
        for (section, row, column, m) in self.measurements() {
            table.row(vec![
                section.name.clone(),
                row.name.clone(),
                column.to_string(),
                m.id.clone(),
                m.median.point.to_string(),
                m.median.lower.to_string(),
                m.median.upper.to_string(),
                m.median.confidence_level.to_string(),
                m.error.map_or(String::new(), |e| e.to_string()),
            ]);
        }
        table.csv()
    }
}

#[cfg(test)]
mod tests;
