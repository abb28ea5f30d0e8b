//! `harness report --quick`, as CI runs it: every method has a row per scene
//! it supports (or says why not), every number is finite and agrees with a
//! recomputation from the JSON, the charts decode, and the page opens in
//! headless Chromium without errors and shows its charts.

mod support;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use harness::chart::TIME_TIE;

/// The pictures' width the quick report of these tests asks for (the
/// default, 512, costs minutes in a debug build).
const PICTURE_WIDTH: u32 = 128;
use harness::suite::Suite;
use serde_json::Value;
use support::harness;

/// Runs the quick suite into `out` with references cached under `cache`
/// (to looser noise than the default, so that a debug build finishes in
/// minutes), `extra` arguments added.
fn quick(out: &Path, cache: &Path, extra: &[&str]) {
    let picture_width = PICTURE_WIDTH.to_string();
    let mut args = vec![
        "report",
        "--quick",
        "--out-dir",
        out.to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
        "--target",
        "0.02",
        "--image-target",
        "0.03",
        "--image-width",
        "64",
        "--repeats",
        "1",
        "--picture-width",
        &picture_width,
    ];
    args.extend(extra);
    harness(&args).unwrap();
}

/// Runs the quick suite once into a temporary folder.
fn quick_report() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("reports");
    quick(&out, &dir.path().join("cache"), &[]);
    (dir, out)
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
#[cfg_attr(
    skip_browser_tests,
    ignore = "needs Chromium and playwright-core (SOFT_SHADOWS_SKIP lists browser)"
)]
fn the_quick_report_holds_every_run_and_opens_in_a_browser() {
    let (_keep, out) = quick_report();
    let json: Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let runs = json["runs"].as_array().unwrap();
    let skipped = json["skipped"].as_array().unwrap();
    assert_eq!(
        json["failed"].as_array().unwrap().len(),
        0,
        "{:#}",
        json["failed"]
    );

    // A row per scene and setting, or a reason naming what is missing.
    let mut seen = BTreeSet::new();
    for scene in Suite::Quick.scenes() {
        for family in Suite::Quick.families() {
            for spec in family.methods {
                let setting = spec.name().to_string();
                let ran = runs
                    .iter()
                    .any(|r| r["scene"] == scene && r["setting"] == setting);
                let refused = skipped
                    .iter()
                    .find(|s| s["scene"] == scene && s["method"] == setting);
                assert!(
                    ran || refused.is_some(),
                    "{setting} on {scene}: neither run nor refused"
                );
                if let Some(s) = refused {
                    let why = s["why"].as_str().unwrap();
                    assert!(why.contains("support"), "{setting} on {scene}: {why}");
                }
                seen.insert((scene, setting));
            }
        }
    }
    assert_eq!(runs.len() + skipped.len(), seen.len());

    // Every error is finite and the table's figure is the JSON's frames'.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let csv = std::fs::read_to_string(out.join("report.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert_eq!(rows.len(), runs.len());
    for (run, row) in runs.iter().zip(&rows) {
        let frames = run["frames"].as_array().unwrap();
        let errors = frames
            .iter()
            .map(|f| f["vertex"]["relative_l2"].as_f64().unwrap());
        assert!(errors.clone().all(f64::is_finite), "{run:#}");
        let recomputed = 100.0 * mean(errors);
        let written: f64 = row[column("vertex error")]
            .split('%')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(
            (written - recomputed).abs() <= 0.006,
            "{} on {}: table {written}%, frames {recomputed}%",
            run["setting"],
            run["scene"]
        );
        for f in frames {
            if let Some(image) = f["image"].as_object() {
                assert!(image["relative_l2"].as_f64().unwrap().is_finite());
            }
            for stage in ["update", "shade"] {
                let t = &f["times"][stage];
                let samples = t["samples"].as_array().unwrap();
                assert!(!samples.is_empty(), "{stage}: {t}");
                assert!(samples.iter().all(|s| s.as_f64().unwrap() >= 0.0));
                let (min, median, max) = (
                    t["min"].as_f64().unwrap(),
                    t["median"].as_f64().unwrap(),
                    t["max"].as_f64().unwrap(),
                );
                assert!(min <= median && median <= max, "{stage}: {t}");
            }
        }
    }

    check_recommendations(&json, &md);

    // The atlas: every stress scene of the suite with every atlas setting,
    // a sentence each; a refusal names the capability.
    let atlas = json["atlas"].as_array().unwrap();
    for scene in Suite::Quick.atlas_scenes() {
        for spec in Suite::Quick.atlas_settings() {
            let setting = spec.name();
            let entry = atlas
                .iter()
                .find(|a| a["scene"] == scene && a["setting"] == setting)
                .unwrap_or_else(|| panic!("{setting} on {scene}: not in the atlas"));
            let diagnosis = entry["diagnosis"].as_str().unwrap();
            assert!(
                diagnosis.starts_with(setting) && diagnosis.ends_with('.'),
                "{diagnosis}"
            );
            if let Some(why) = entry["outcome"].get("Refused") {
                assert!(why.as_str().unwrap().contains("support"), "{why}");
            } else {
                let frames = entry["outcome"]["Ran"]["frames"].as_array().unwrap();
                for f in frames {
                    for p in ["p50", "p90", "p99", "max"] {
                        assert!(
                            f["vertex"][p].as_f64().unwrap().is_finite(),
                            "{setting} on {scene}"
                        );
                    }
                }
            }
        }
    }
    // A remedy stands beside a setting of its family on its scene, which
    // scored above 5%, and is scored itself.
    for remedy in atlas.iter().filter(|a| !a["remedy_for"].is_null()) {
        let failing = atlas
            .iter()
            .find(|a| {
                a["scene"] == remedy["scene"]
                    && a["setting"] == remedy["remedy_for"]
                    && a["family"] == remedy["family"]
            })
            .unwrap_or_else(|| panic!("{remedy:#}: stands for nothing"));
        let mean = |entry: &Value| {
            let frames = entry["outcome"]["Ran"]["frames"].as_array().unwrap();
            mean(
                frames
                    .iter()
                    .map(|f| f["vertex"]["relative_l2"].as_f64().unwrap()),
            )
        };
        assert!(mean(failing) > 0.05, "{failing:#}");
        assert!(mean(remedy).is_finite());
        let setting = remedy["setting"].as_str().unwrap();
        assert!(md.contains(&format!("{setting} (instead of ")), "{setting}");
        // Pictures of both, each beside its error map, framed on the
        // failure, as wide as asked.
        let scene = remedy["scene"].as_str().unwrap();
        let pictures = json["pictures"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["scene"] == scene)
            .unwrap_or_else(|| panic!("{scene}: no pictures"));
        assert_eq!(pictures["width"], PICTURE_WIDTH);
        for shown in [remedy, failing] {
            let picture = pictures["shown"]
                .as_array()
                .unwrap()
                .iter()
                .find(|p| p["setting"] == shown["setting"])
                .unwrap_or_else(|| panic!("{scene}: no picture of {}", shown["setting"]));
            let stem = picture["stem"].as_str().unwrap();
            let (image, map) = (
                format!("pictures/{scene}/{stem}.png"),
                format!("pictures/{scene}/{stem}-error.png"),
            );
            let row = md
                .lines()
                .find(|l| l.contains(&format!("]({image})")))
                .unwrap_or_else(|| panic!("{image}: not on the page"));
            assert!(row.contains(&format!("]({map})")), "{row}");
        }
    }
    // The strip: the bunny's pictures, each beside its error map.
    assert!(md.contains("](pictures/bunny/reference.png)"));
    assert!(md.contains("](pictures/bunny/deferred-shadow-error.png)"));

    // Time per image across widths, on both scenes, from 160 to 1024
    // pixels at least; the table's slope is the log-log fit of the JSON's
    // medians.
    let scaling = json["scaling"].as_array().unwrap();
    for scene in harness::suite::SCALING_SCENES {
        let runs: Vec<&Value> = scaling.iter().filter(|s| s["scene"] == scene).collect();
        assert!(
            runs.len() >= 4,
            "{scene}: {} settings timed across widths",
            runs.len()
        );
        for run in runs {
            let widths = run["widths"].as_array().unwrap();
            let (w, t): (Vec<f64>, Vec<f64>) = widths
                .iter()
                .map(|w| {
                    let median = w["time"]["median"].as_f64().unwrap();
                    (w["width"].as_f64().unwrap().ln(), median.ln())
                })
                .unzip();
            assert!(
                w[0] <= 160f64.ln() && w[w.len() - 1] >= 1024f64.ln(),
                "{run}"
            );
            let n = w.len() as f64;
            let (mw, mt) = (w.iter().sum::<f64>() / n, t.iter().sum::<f64>() / n);
            let slope = w
                .iter()
                .zip(&t)
                .map(|(a, b)| (a - mw) * (b - mt))
                .sum::<f64>()
                / w.iter().map(|a| (a - mw).powi(2)).sum::<f64>();
            let setting = run["setting"].as_str().unwrap();
            let section = &md[md.find(&format!("### Resolution: {scene}")).unwrap()..];
            let row = section
                .lines()
                .find(|l| l.starts_with(&format!("| {setting} |")))
                .unwrap_or_else(|| panic!("{setting} on {scene}: no row"));
            assert!(
                row.contains(&format!("| {slope:.2} |")),
                "{row}: slope {slope:.2}"
            );
        }
    }

    // The figures decode, and the page embeds them all.
    let mut charts = 0;
    for entry in std::fs::read_dir(out.join("charts")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "png") {
            image::load_from_memory(&std::fs::read(&path).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            charts += 1;
        }
    }
    assert!(charts >= 2 * Suite::Quick.scenes().len());
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(!html.contains("[missing"));
    for scene in Suite::Quick.scenes() {
        assert!(md.contains(&format!("## Scene: {scene}")), "{scene}");
    }

    browser_check(&out.join("index.html"));
}

/// `report.json` without what a rerun changes: times, the method's own
/// profile (seconds), references' compute time and cache state, the
/// machine, the picks by time, and the remedies tried and pictures taken (a
/// part tries and pictures every one that may be needed; the page shows
/// the same chosen ones).
fn timings_aside(mut json: Value) -> Value {
    const VARY: [&str; 10] = [
        "times",
        "time",
        "profile",
        "seconds",
        "cached",
        "machine",
        "merged_from",
        "remedies",
        "pictures",
        "recommendations",
    ];
    fn strip(v: &mut Value) {
        match v {
            Value::Object(map) => {
                map.retain(|k, _| !VARY.contains(&k.as_str()));
                map.values_mut().for_each(strip);
            }
            Value::Array(items) => items.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut json);
    json
}

/// A CSV line's fields (quoted fields may hold commas).
fn fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(String::new()),
            c => fields.last_mut().unwrap().push(c),
        }
    }
    fields
}

/// The CSV without its timing columns and the frontier (which times
/// decide).
fn csv_timings_aside(csv: &str) -> Vec<Vec<String>> {
    let rows: Vec<Vec<String>> = csv.lines().map(fields).collect();
    let keep: Vec<usize> = (0..rows[0].len())
        .filter(|&i| !["ms", "frontier"].iter().any(|t| rows[0][i].contains(t)))
        .collect();
    rows.iter()
        .map(|r| keep.iter().map(|&i| r[i].clone()).collect())
        .collect()
}

/// `--quick` as two parts and a merge gives one run's results, timings
/// aside: the same runs in the same order with the same errors, the same
/// references, the same atlas with the same remedies and sentences.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn two_parts_merge_into_one_runs_tables() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let whole = dir.path().join("whole");
    quick(&whole, &cache, &[]);
    let parts: Vec<PathBuf> = (1..=2)
        .map(|i| {
            let out = dir.path().join(format!("part{i}"));
            quick(&out, &cache, &["--shard", &format!("{i}/2")]);
            assert!(out.join("report.json").is_file());
            assert!(!out.join("index.html").exists(), "a part writes no page");
            out
        })
        .collect();
    let merged = dir.path().join("merged");
    harness(&[
        "report",
        "--merge",
        parts[1].to_str().unwrap(),
        parts[0].to_str().unwrap(),
        "--out-dir",
        merged.to_str().unwrap(),
    ])
    .unwrap();

    let read = |dir: &Path, file: &str| std::fs::read_to_string(dir.join(file)).unwrap();
    let json = |dir: &Path| -> Value { serde_json::from_str(&read(dir, "report.json")).unwrap() };
    let (one, two) = (json(&whole), json(&merged));
    assert_eq!(two["merged_from"].as_array().unwrap().len(), 2);
    assert!(!one["runs"].as_array().unwrap().is_empty());
    assert_eq!(timings_aside(one), timings_aside(two));
    assert_eq!(
        csv_timings_aside(&read(&whole, "report.csv")),
        csv_timings_aside(&read(&merged, "report.csv"))
    );
    // The strip's pictures and the atlas's tables carry no timings: the
    // same text.
    let section = |dir: &Path, from: &str, to: &str| {
        let md = read(dir, "report.md");
        let start = md.find(from).unwrap_or_else(|| panic!("no {from}"));
        let end = md[start..].find(to).unwrap() + start;
        md[start..end].to_string()
    };
    for (from, to) in [
        ("## Per pixel against per vertex", "## Stability atlas"),
        ("## Stability atlas", "## Reproducibility"),
    ] {
        assert_eq!(section(&whole, from, to), section(&merged, from, to));
    }
    // Every image the page shows was brought over from the parts.
    let md = read(&merged, "report.md");
    for path in md.split("](").skip(1).filter_map(|s| s.split(')').next()) {
        assert!(merged.join(path).is_file(), "{path}: missing");
    }
    // A missing part is refused.
    let refused = harness(&[
        "report",
        "--merge",
        parts[0].to_str().unwrap(),
        "--out-dir",
        dir.path().join("refused").to_str().unwrap(),
    ])
    .unwrap_err();
    assert!(refused.contains("part 2/2 missing"), "{refused}");
}

/// A run's (error in percent, median, fastest and slowest milliseconds per
/// frame) in `domain`
/// (`vertex` or `image`), recomputed from its frames: the mean error over
/// frames; each frame's update (one sample, or one per repeat) plus each
/// repeat of shade or render, every frame's samples pooled.
fn score(run: &Value, domain: &str) -> Option<(f64, f64, f64, f64)> {
    let frames = run["frames"].as_array().unwrap();
    let stage = if domain == "vertex" {
        "shade"
    } else {
        "render"
    };
    let mut errors = Vec::new();
    let mut times = Vec::new();
    for f in frames {
        errors.push(f[domain]["relative_l2"].as_f64()?);
        let samples = |t: &Value| -> Vec<f64> {
            t["samples"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        };
        let update = samples(&f["times"]["update"]);
        let other = samples(f["times"].get(stage).filter(|t| !t.is_null())?);
        match update.as_slice() {
            [once] => times.extend(other.iter().map(|o| once + o)),
            _ => times.extend(update.iter().zip(&other).map(|(u, o)| u + o)),
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let (min, max) = (times[0], times[times.len() - 1]);
    Some((
        100.0 * mean(errors.into_iter()),
        median * 1e3,
        min * 1e3,
        max * 1e3,
    ))
}

/// Every recommendation of report.json, recomputed from the runs: the
/// picked setting meets its budget and no other run beats it (beyond the
/// f32 rounding of the stored errors); "none" where no run meets it; and
/// the page names each pick with its figures.
fn check_recommendations(json: &Value, md: &str) {
    let runs = json["runs"].as_array().unwrap();
    let recommendations = json["recommendations"].as_array().unwrap();
    assert!(!recommendations.is_empty());
    const SLACK: f64 = 1e-4;
    for r in recommendations {
        let (scene, domain) = (r["scene"].as_str().unwrap(), r["domain"].as_str().unwrap());
        let reference = json["references"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["scene"] == scene)
            .unwrap();
        let noise = 100.0
            * if domain == "vertex" {
                reference["noise"].as_f64().unwrap()
            } else {
                reference["image"]["noise"].as_f64().unwrap()
            };
        let budget = &r["budget"];
        let by_error = budget["kind"] == "error";
        let limit = budget[if by_error { "percent" } else { "ms" }]
            .as_f64()
            .unwrap();
        // (setting, error, median, fastest, slowest) of the runs meeting the
        // budget.
        let meeting: Vec<(&str, f64, f64, f64, f64)> = runs
            .iter()
            .filter(|run| run["scene"] == scene)
            .filter_map(|run| {
                let (e, t, lo, hi) = score(run, domain)?;
                Some((run["setting"].as_str().unwrap(), e, t, lo, hi))
            })
            .filter(|&(_, e, t, _, _)| {
                if by_error {
                    e <= limit + SLACK
                } else {
                    t <= limit * (1.0 + SLACK)
                }
            })
            .collect();
        let lowest = meeting.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        match r["setting"].as_str() {
            // Only a run on the budget's edge may differ by rounding.
            None => assert!(
                meeting.iter().all(|&(_, e, t, _, _)| if by_error {
                    e > limit - SLACK
                } else {
                    t > limit * (1.0 - SLACK)
                }),
                "{r}: some run meets it: {meeting:?}"
            ),
            Some(setting) => {
                let picked = *meeting
                    .iter()
                    .find(|m| m.0 == setting)
                    .unwrap_or_else(|| panic!("{r}: {setting} does not meet it"));
                // Within a time budget, the pick ties the lowest error
                // (within the reference's noise).
                if !by_error {
                    assert!(
                        picked.1 <= lowest + noise + SLACK,
                        "{r}: {picked:?}, lowest {lowest}%"
                    );
                }
                // No run it had to beat is clearly faster (its slowest
                // sample TIME_TIE times below the pick's fastest).
                for other in &meeting {
                    let contender = by_error || other.1 <= lowest + noise + SLACK;
                    assert!(
                        !(contender && other.4 * TIME_TIE < picked.3 * (1.0 - SLACK)),
                        "{r}: {other:?} is clearly faster than {picked:?}"
                    );
                }
                let cell = format!(
                    "{setting} ({:.2}%, {:.1} ms)",
                    r["score"]["error_percent"].as_f64().unwrap(),
                    r["score"]["ms"].as_f64().unwrap()
                );
                assert!(md.contains(&cell), "the page does not name {cell}");
            }
        }
    }
}

/// Opens the page in headless Chromium: no console or page errors, every
/// image decoded, and a screenshot of the first chart that shows a chart.
fn browser_check(page: &Path) {
    let tools = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/browser");
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    assert!(
        tools.join("node_modules/playwright-core").exists() && Path::new(&chromium).exists(),
        "this test needs Chromium ({chromium}; apt-get install chromium) and playwright-core \
         (npm ci --prefix {}), or SOFT_SHADOWS_SKIP=browser to skip it",
        tools.display()
    );
    let shot = page.with_file_name("first-chart.png");
    let out = Command::new("node")
        .arg(tools.join("check-page.mjs"))
        .arg(page)
        .arg(&shot)
        .env("CHROMIUM", &chromium)
        .output()
        .expect("run node");
    assert!(
        out.status.success(),
        "check-page failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(seen["problems"], serde_json::json!([]), "{seen:#}");
    let images = seen["images"].as_array().unwrap();
    assert!(!images.is_empty());
    for image in images {
        assert!(image["width"].as_u64().unwrap() > 0, "not decoded: {image}");
    }
    assert!(
        seen["headings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|h| h == "Summary")
    );
    // A chart: mostly white, with axes, grid and several coloured curves.
    let shot = image::open(&shot).unwrap().to_rgb8();
    let inked = shot
        .pixels()
        .filter(|p| p.0.iter().any(|&c| c < 200))
        .count();
    let colourful: BTreeSet<[u8; 3]> = shot
        .pixels()
        .filter(|p| {
            let (lo, hi) = (p.0.iter().min().unwrap(), p.0.iter().max().unwrap());
            hi - lo > 80
        })
        .map(|p| p.0.map(|c| c / 32))
        .collect();
    let share = inked as f64 / (shot.width() * shot.height()) as f64;
    assert!(
        share > 0.01 && share < 0.5,
        "{share} of the screenshot inked"
    );
    assert!(colourful.len() >= 4, "{} colours", colourful.len());
}
