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
mod tests {
    use super::*;

    /// `estimates.json` as criterion 0.8.2 wrote it for
    /// `fig7/dragon-5k-diffuse/q32/64` (medians 491.857 ms [459.383, 519.470]).
    const ESTIMATES_Q32_64: &str = r#"{"mean":{"confidence_interval":{"confidence_level":0.95,"lower_bound":472099145.09250003,"upper_bound":524125301.84499997},"point_estimate":496113119.0,"standard_error":13370700.151912533},"median":{"confidence_interval":{"confidence_level":0.95,"lower_bound":459383327.5,"upper_bound":519469507.0},"point_estimate":491857008.0,"standard_error":17456079.304006223},"median_abs_dev":{"confidence_interval":{"confidence_level":0.95,"lower_bound":9317408.430182934,"upper_bound":73558705.47087193},"point_estimate":41534589.03481364,"standard_error":15724711.491725104},"slope":null,"std_dev":{"confidence_interval":{"confidence_level":0.95,"lower_bound":21623581.89448252,"upper_bound":60282697.66839189},"point_estimate":44437141.53382118,"standard_error":11164390.228858985}}"#;

    /// `benchmark.json` and `estimates.json` as criterion 0.8.2 wrote them for
    /// `frame/bunny/hemi-raster` in a `--quick` run (slope present, median
    /// 22.298 ms [21.337, 23.258]).
    const BENCHMARK_HEMI_RASTER: &str = r#"{"group_id":"frame/bunny","function_id":null,"value_str":"hemi-raster","throughput":null,"full_id":"frame/bunny/hemi-raster","directory_name":"frame_bunny/hemi-raster","title":"frame/bunny/hemi-raster"}"#;
    const ESTIMATES_HEMI_RASTER: &str = r#"{"mean":{"confidence_interval":{"confidence_level":0.95,"lower_bound":21336769.5546875,"upper_bound":23258310.953125},"point_estimate":22297540.25390625,"standard_error":679933.7109637128},"median":{"confidence_interval":{"confidence_level":0.95,"lower_bound":21336769.5546875,"upper_bound":23258310.953125},"point_estimate":22297540.25390625,"standard_error":679933.7109637128},"median_abs_dev":{"confidence_interval":{"confidence_level":0.95,"lower_bound":0.0,"upper_bound":1424438.6133728782},"point_estimate":1424438.6133728782,"standard_error":712221.886508059},"slope":{"confidence_interval":{"confidence_level":0.95,"lower_bound":21336769.5546875,"upper_bound":23258310.953125},"point_estimate":21721077.834375,"standard_error":736927.2631407407},"std_dev":{"confidence_interval":{"confidence_level":0.95,"lower_bound":0.0,"upper_bound":1358734.9531658378},"point_estimate":1358734.9531658378,"standard_error":679369.9374078903}}"#;

    /// Criterion's `estimates.json` with the given median, in its layout.
    fn estimates(point: f64, lower: f64, upper: f64) -> String {
        format!(
            r#"{{"mean":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":{lower},"upper_bound":{upper}}},"point_estimate":{point},"standard_error":1.0}},"median":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":{lower},"upper_bound":{upper}}},"point_estimate":{point},"standard_error":1.0}},"median_abs_dev":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":1.0,"upper_bound":2.0}},"point_estimate":1.5,"standard_error":0.2}},"slope":null,"std_dev":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":1.0,"upper_bound":2.0}},"point_estimate":1.5,"standard_error":0.2}}}}"#
        )
    }

    /// Criterion's `benchmark.json` for a group, function and value.
    fn benchmark(group: &str, function: Option<&str>, value: Option<&str>) -> String {
        let full_id = [Some(group), function, value]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join("/");
        let directory = [Some(group), function, value]
            .into_iter()
            .flatten()
            .map(group_directory)
            .collect::<Vec<_>>()
            .join("/");
        let json = |v: Option<&str>| v.map_or("null".to_string(), |v| format!("{v:?}"));
        format!(
            r#"{{"group_id":{group:?},"function_id":{},"value_str":{},"throughput":null,"full_id":{full_id:?},"directory_name":{directory:?},"title":{full_id:?}}}"#,
            json(function),
            json(value),
        )
    }

    /// Writes one benchmark's `new/` (and a stale `base/`) where criterion would.
    fn save(
        root: &Path,
        group: &str,
        function: Option<&str>,
        value: Option<&str>,
        estimates: &str,
    ) -> PathBuf {
        let mut dir = root.join(group_directory(group));
        for part in [function, value].into_iter().flatten() {
            dir = dir.join(group_directory(part));
        }
        for (sub, text) in [("new", estimates), ("base", ESTIMATES_Q32_64)] {
            fs::create_dir_all(dir.join(sub)).unwrap();
            fs::write(
                dir.join(sub).join("benchmark.json"),
                benchmark(group, function, value),
            )
            .unwrap();
            fs::write(dir.join(sub).join("estimates.json"), text).unwrap();
            fs::write(dir.join(sub).join("tukey.json"), "[1.0,2.0,3.0,4.0]").unwrap();
        }
        fs::create_dir_all(dir.join("change")).unwrap();
        fs::write(dir.join("change/estimates.json"), "{}").unwrap();
        dir.join("new")
    }

    /// The methods bench on two scenes, with errors for one of them; two
    /// cells of the fig7 grid; a benchmark without a value.
    fn fixture() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        save(
            root,
            "frame/bunny",
            None,
            Some("hemi-raster"),
            ESTIMATES_HEMI_RASTER,
        );
        let methods = [
            ("raytrace:16", 1.2345e8, 1.2e8, 1.3e8),
            ("raytrace:4", 3.1e7, 3.0e7, 3.2e7),
        ];
        for (method, point, lower, upper) in methods {
            save(
                root,
                "frame/bunny",
                None,
                Some(method),
                &estimates(point, lower, upper),
            );
        }
        save(
            root,
            "frame/human",
            None,
            Some("hemi-raster"),
            &estimates(850.0, 840.0, 861.0),
        );
        let mut errors = GroupErrors::new("frame/bunny", "relative L2 error per vertex");
        errors.insert("hemi-raster", 0.0123);
        errors.insert("raytrace:4", f64::NAN);
        errors.insert("no-longer-benched", 0.5);
        errors.write(root).unwrap();
        save(
            root,
            "fig7/dragon-5k-diffuse",
            Some("q32"),
            Some("64"),
            ESTIMATES_Q32_64,
        );
        save(
            root,
            "fig7/dragon-5k-diffuse",
            Some("q16"),
            Some("128"),
            &estimates(2.5e9, 2.4e9, 2.6e9),
        );
        save(
            root,
            "chess",
            Some("raytrace:32 (deferred-shadow, pieces grouped)"),
            None,
            &estimates(5.0e4, 4.9e4, 5.2e4),
        );
        dir
    }

    #[test]
    fn fixtures_are_laid_out_as_criterion_lays_them_out() {
        assert_eq!(
            benchmark("frame/bunny", None, Some("hemi-raster")),
            BENCHMARK_HEMI_RASTER
        );
        assert_eq!(
            benchmark("fig7/dragon-5k-diffuse", Some("q32"), Some("64")),
            r#"{"group_id":"fig7/dragon-5k-diffuse","function_id":"q32","value_str":"64","throughput":null,"full_id":"fig7/dragon-5k-diffuse/q32/64","directory_name":"fig7_dragon-5k-diffuse/q32/64","title":"fig7/dragon-5k-diffuse/q32/64"}"#
        );
        let dir = fixture();
        for path in [
            "frame_bunny/hemi-raster/new/estimates.json",
            "frame_bunny/errors.json",
            "fig7_dragon-5k-diffuse/q32/64/new/benchmark.json",
            "chess/raytrace_32 (deferred-shadow, pieces grouped)/new/estimates.json",
        ] {
            assert!(dir.path().join(path).is_file(), "{path}");
        }
    }

    #[test]
    fn criterion_directory_names() {
        assert_eq!(group_directory("frame/bunny"), "frame_bunny");
        assert_eq!(
            group_directory("raytrace:32 (deferred-shadow)"),
            "raytrace_32 (deferred-shadow)"
        );
    }

    #[test]
    fn sections_rows_and_columns_follow_the_ids() {
        let dir = fixture();
        let table = collect(dir.path()).unwrap();
        let names: Vec<&str> = table.sections.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["chess", "fig7/dragon-5k-diffuse", "frame"]);

        let frame = &table.sections[2];
        assert_eq!(frame.columns, ["bunny", "human"]);
        let rows: Vec<&str> = frame.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(rows, ["hemi-raster", "raytrace:4", "raytrace:16"]);
        assert!(frame.rows.iter().all(|r| r.cells.len() == 2));
        assert!(
            frame.rows[1].cells[1].is_none(),
            "raytrace:4 did not run on human"
        );
        assert_eq!(
            frame.error_measure.as_deref(),
            Some("relative L2 error per vertex")
        );

        let fig7 = &table.sections[1];
        assert_eq!(fig7.columns, ["64", "128"]);
        let rows: Vec<&str> = fig7.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(rows, ["q16", "q32"]);
        assert_eq!(fig7.error_measure, None);

        let chess = &table.sections[0];
        assert_eq!(chess.columns, [""]);
        assert_eq!(
            chess.rows[0].name,
            "raytrace:32 (deferred-shadow, pieces grouped)"
        );
        assert_eq!(table.measurements().count(), 7);
    }

    #[test]
    fn medians_intervals_and_errors_are_read() {
        let dir = fixture();
        let table = collect(dir.path()).unwrap();
        let fig7 = &table.sections[1];
        let q32_64 = fig7.rows[1].cells[0].as_ref().unwrap();
        assert_eq!(q32_64.id, "fig7/dragon-5k-diffuse/q32/64");
        assert_eq!(
            q32_64.median,
            Interval {
                point: 491857008.0,
                lower: 459383327.5,
                upper: 519469507.0,
                confidence_level: 0.95
            }
        );
        assert_eq!(q32_64.error, None);

        let frame = &table.sections[2];
        let hemi = frame.rows[0].cells[0].as_ref().unwrap();
        assert_eq!(hemi.id, "frame/bunny/hemi-raster");
        assert_eq!(
            hemi.median,
            Interval {
                point: 22297540.25390625,
                lower: 21336769.5546875,
                upper: 23258310.953125,
                confidence_level: 0.95
            }
        );
        assert_eq!(hemi.error, Some(0.0123));
        assert_eq!(
            frame.rows[0].cells[1].as_ref().unwrap().error,
            None,
            "no errors for human"
        );
        assert_eq!(
            frame.rows[1].cells[0].as_ref().unwrap().error,
            None,
            "NaN saved as null"
        );
    }

    #[test]
    fn markdown_and_csv() {
        let dir = fixture();
        let table = collect(dir.path()).unwrap();
        let md = table.markdown();
        assert!(md.contains("95% confidence interval"), "{md}");
        assert!(
            md.contains("Errors in frame: relative L2 error per vertex."),
            "{md}"
        );
        assert!(
            md.contains("| frame | bunny | human |\n|---|---:|---:|\n"),
            "{md}"
        );
        assert!(
            md.contains("| hemi-raster | 22.3 ms [21.3, 23.3] · 1.23% | 850 ns [840, 861] |"),
            "{md}"
        );
        assert!(
            md.contains("| raytrace:4 | 31.0 ms [30.0, 32.0] | – |"),
            "{md}"
        );
        assert!(md.contains("| q32 | 492 ms [459, 519] | – |"), "{md}");
        assert!(md.contains("| q16 | – | 2.50 s [2.40, 2.60] |"), "{md}");
        assert!(md.contains("| chess | time |"), "{md}");

        let csv = table.csv();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 8, "{csv}");
        assert_eq!(
            lines[0],
            "section,row,column,id,median_ns,lower_ns,upper_ns,confidence_level,error"
        );
        assert_eq!(
            lines[1],
            "chess,\"raytrace:32 (deferred-shadow, pieces grouped)\",,\"chess/raytrace:32 (deferred-shadow, pieces grouped)\",50000,49000,52000,0.95,"
        );
        assert!(csv.contains("\nframe,hemi-raster,bunny,frame/bunny/hemi-raster,22297540.25390625,21336769.5546875,23258310.953125,0.95,0.0123\n"), "{csv}");
    }

    #[test]
    fn a_malformed_file_is_an_error_naming_it() {
        let dir = fixture();
        let new = save(
            dir.path(),
            "frame/bunny",
            None,
            Some("broken"),
            "{\"median\": {",
        );
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(&new.join("estimates.json").display().to_string()),
            "{err}"
        );

        fs::write(
            new.join("estimates.json"),
            r#"{"mean":{"point_estimate":1.0}}"#,
        )
        .unwrap();
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("estimates.json") && err.contains("missing field `median`"),
            "{err}"
        );

        fs::write(new.join("estimates.json"), estimates(1.0, 1.0, 1.0)).unwrap();
        fs::write(new.join("benchmark.json"), r#"{"group_id":"frame/bunny"}"#).unwrap();
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(&new.join("benchmark.json").display().to_string())
                && err.contains("full_id"),
            "{err}"
        );

        fs::remove_file(new.join("benchmark.json")).unwrap();
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(&new.join("benchmark.json").display().to_string()),
            "{err}"
        );
    }

    #[test]
    fn a_malformed_errors_file_is_an_error_naming_it() {
        let dir = fixture();
        let path = dir.path().join("frame_bunny").join(ERRORS_FILE);
        fs::write(&path, r#"{"group_id":"frame/bunny","errors":{}}"#).unwrap();
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(&path.display().to_string()) && err.contains("measure"),
            "{err}"
        );
    }

    #[test]
    fn an_empty_or_missing_directory_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        fs::create_dir_all(dir.path().join("frame_bunny/hemi-raster/base")).unwrap();
        let err = collect(dir.path()).unwrap_err().to_string();
        assert!(err.contains(&dir.path().display().to_string()), "{err}");
        assert!(err.contains("no criterion measurements"), "{err}");
        assert!(err.contains("cargo bench"), "{err}");

        let missing = dir.path().join("absent");
        let err = collect(&missing).unwrap_err().to_string();
        assert!(err.contains(&missing.display().to_string()), "{err}");
    }

    #[test]
    fn natural_order() {
        let mut names = vec![
            "q128",
            "q16",
            "q32",
            "raytrace:64:vertex",
            "raytrace:64",
            "raytrace:4",
            "",
            "a",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "",
                "a",
                "q16",
                "q32",
                "q128",
                "raytrace:4",
                "raytrace:64",
                "raytrace:64:vertex"
            ]
        );
    }

    #[test]
    fn errors_below_one_percent_keep_three_digits() {
        assert_eq!(format_error(0.0123), "1.23%");
        assert_eq!(format_error(0.000456), "0.0456%");
        assert_eq!(format_error(0.0), "0.00%");
    }
}
