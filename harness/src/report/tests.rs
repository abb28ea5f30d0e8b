use shadow_core::{Capabilities, Profile};

use super::*;
use crate::reference::ImageReferenceInfo;
use crate::report::{Overtakes, equal_error_ms, overtakes};
use crate::run::{FrameResult, StageTimes};
use crate::score::{ErrorStats, Temporal};
use crate::suite::RAY_TRACER;
use crate::timing::Timing;

fn stats(error: f32) -> ErrorStats {
    ErrorStats {
        relative_l2: error,
        p50: 0.8 * error,
        p90: 1.5 * error,
        p99: 2.0 * error,
        max: 3.0 * error,
        reference_noise: 0.005,
        count: 100,
    }
}

fn run(scene: &str, family: &str, setting: &str, error: f32, ms: f64) -> ReportRun {
    let frames = (0..2)
        .map(|frame| FrameResult {
            frame,
            vertex: stats(error),
            vertices: 100,
            image: Some(stats(error * 1.5)),
            temporal: (frame > 0).then_some(Temporal {
                error_change: error / 4.0,
                reference_change: 0.1,
                noise_floor: 0.007,
            }),
            times: StageTimes {
                prepare: 0.1,
                relight: Timing::new(vec![0.01]),
                update: Timing::new(vec![ms / 2e3]),
                shade: Timing::new(vec![ms / 2e3; 3]),
                render: Some(Timing::new(vec![ms / 1e3; 3])),
            },
            profile: Profile::default(),
        })
        .collect();
    ReportRun {
        family: family.into(),
        setting: setting.into(),
        result: RunResult {
            method: setting.replace([':', '='], "-"),
            scene: scene.into(),
            environment: "forest".into(),
            capabilities: Capabilities::ALL,
            image_size: Some((16, 12)),
            frames,
            last_shading: None,
            last_image: None,
        },
    }
}

fn report() -> Report {
    let suite = Suite::Quick;
    let reference = |scene: &str| ReferenceInfo {
        scene: scene.into(),
        environment: "forest".into(),
        frames: 2,
        vertices: 100,
        noise: 0.004,
        rays: 1000,
        seconds: 1.0,
        cached: false,
        image: Some(ImageReferenceInfo {
            width: 16,
            height: 12,
            pixels: 150,
            noise: 0.009,
            rays: 1000,
            seconds: 1.0,
            cached: true,
        }),
    };
    let settings = Settings {
        suite,
        target_noise: 0.005,
        image_target_noise: 0.01,
        image_width: 16,
        picture_width: 64,
        repeats: 1,
        seed: 7,
        scenes: vec!["bunny".into(), "human".into()],
        atlas_scenes: vec!["thin-sheets".into()],
        part: Part::WHOLE,
    };
    Report {
        references: vec![reference("bunny"), reference("human")],
        runs: vec![
            run("bunny", RAY_TRACER, "raytrace:4", 0.2, 3.0),
            run("bunny", RAY_TRACER, "raytrace:16", 0.1, 12.0),
            run("bunny", "hemi-raster", "hemi-raster", 0.049, 2.0),
            run("bunny", "hemi-raster", "hemi-raster:pvs", 0.049, 1.0),
            run("human", "occlusion-query", "occlusion-query:k=18", 0.3, 5.0),
        ],
        skipped: vec![Skipped {
            method: "hemi-raster".into(),
            scene: "human".into(),
            why: "does not support deforming meshes".into(),
        }],
        failed: vec![Skipped {
            method: "occlusion-query:k=66".into(),
            scene: "human".into(),
            why: "GPU: device lost".into(),
        }],
        ..Report::new(
            MachineInfo::detect(Some("llvmpipe (LLVM 15.0.7, 256 bits)".into())),
            settings,
            suite.families().iter().map(Into::into).collect(),
        )
    }
}

#[test]
fn the_report_writes_every_file_with_a_row_per_run() {
    let dir = tempfile::tempdir().unwrap();
    let report = report();
    report.write(dir.path()).unwrap();
    for file in ["report.json", "report.md", "report.csv", "index.html"] {
        assert!(dir.path().join(file).is_file(), "{file}");
    }
    for chart in ["bunny-vertex", "bunny-image", "human-vertex"] {
        let png = std::fs::read(dir.path().join(format!("charts/{chart}.png"))).unwrap();
        assert!(image::load_from_memory(&png).is_ok(), "{chart}");
        let svg = std::fs::read_to_string(dir.path().join(format!("charts/{chart}.svg"))).unwrap();
        assert!(svg.starts_with("<svg"), "{chart}");
    }
    let csv = std::fs::read_to_string(dir.path().join("report.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + report.runs.len());
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(json["runs"].as_array().unwrap().len(), report.runs.len());
    assert_eq!(json["runs"][0]["family"], RAY_TRACER);
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("software-rasterized"));
    assert!(md.contains("hemi-raster on human: does not support deforming meshes"));
    assert!(md.contains("## Failed") && md.contains("occlusion-query:k=66 on human: GPU"));
    assert!(md.contains("![bunny: time against error](charts/bunny-vertex.png)"));
    let html = std::fs::read_to_string(dir.path().join("index.html")).unwrap();
    assert!(html.contains("data:image/png;base64,") && !html.contains("[missing"));
}

#[test]
fn frontiers_and_summary_name_the_best_settings() {
    let report = report();
    let table = report.table_of(report.runs_of("bunny"), false);
    let frontier = table.header.iter().position(|h| h == "frontier").unwrap();
    let setting = table.header.iter().position(|h| h == "setting").unwrap();
    let on: Vec<&str> = table
        .rows
        .iter()
        .filter(|r| r[frontier].contains("vertex"))
        .map(|r| r[setting].as_str())
        .collect();
    // hemi-raster: the visible sets give the same error faster.
    assert_eq!(on, vec!["raytrace:4", "raytrace:16", "hemi-raster:pvs"]);
    let summary = report.summary().unwrap();
    let bunny = &summary.rows[0];
    let hemi = summary
        .header
        .iter()
        .position(|h| h == "hemi-raster")
        .unwrap();
    assert!(
        bunny[hemi].starts_with("4.90% at 1.0 ms (pvs)"),
        "{}",
        bunny[hemi]
    );
    assert_eq!(summary.rows[1][hemi], "–");
}

/// Each budget picks the fastest setting meeting it (ties: the more
/// accurate, then the name) or the most accurate within it, and "none"
/// where nothing does; the page and the sentences name the same.
#[test]
fn recommendations_pick_per_budget_and_the_page_names_them() {
    let report = report();
    let recs = report.recommendations();
    let find = |scene: &str, domain: &str, budget: Budget| {
        recs.iter()
            .find(|r| r.scene == scene && r.domain == domain && r.budget == budget)
            .unwrap()
            .setting
            .clone()
    };
    let error = |percent| Budget::Error { percent };
    let time = |ms| Budget::Time { ms };
    assert_eq!(find("bunny", "vertex", error(2.0)), None);
    assert_eq!(
        find("bunny", "vertex", error(5.0)).unwrap(),
        "hemi-raster:pvs"
    );
    assert_eq!(
        find("bunny", "vertex", time(1.0)).unwrap(),
        "hemi-raster:pvs"
    );
    // hemi-raster and its visible sets tie on error: the faster wins.
    assert_eq!(
        find("bunny", "vertex", time(16.0)).unwrap(),
        "hemi-raster:pvs"
    );
    // Per pixel the images cost 1.5 ms: nothing within 1 ms.
    assert_eq!(find("bunny", "image", time(1.0)), None);
    assert_eq!(find("human", "vertex", error(10.0)), None);
    assert_eq!(
        find("human", "vertex", time(100.0)).unwrap(),
        "occlusion-query:k=18"
    );
    assert_eq!(recs.len(), 2 * 2 * Budget::all().count());

    let dir = tempfile::tempdir().unwrap();
    report.write(dir.path()).unwrap();
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("## Recommendations") && md.contains("## Which method when"));
    assert!(md.contains("hemi-raster:pvs (4.90%, 1.0 ms)"), "{md}");
    assert!(
        md.contains("hemi-raster: the fastest per vertex to 5% and 10% on bunny"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(
        json["recommendations"].as_array().unwrap().len(),
        recs.len()
    );
}

/// A stress run of `setting` on thin-sheets with mean error `error`.
fn atlas(setting: &str, error: f32) -> AtlasRun {
    let spec = crate::methods::parse(setting).unwrap();
    let result = run("thin-sheets", spec.family(), setting, error, 1.0).result;
    AtlasRun::new("thin-sheets", &spec, Outcome::Ran(Box::new(result)))
}

/// A stress run fails above 5% and twice its setting's median error on the
/// standard scenes; the best remedy is the lowest error among those that
/// ran, standing in for the failing setting.
#[test]
fn failing_atlas_settings_get_their_best_remedy() {
    let report = report();
    // hemi-raster's median on the standard scenes is 4.9%.
    assert!(atlas("hemi-raster", 0.2).fails(&report.runs));
    assert!(!atlas("hemi-raster", 0.08).fails(&report.runs));
    assert!(atlas("hemi-raster", 0.08).may_fail());
    assert!(!atlas("hemi-raster", 0.04).may_fail());
    // A setting the standard scenes never ran fails above 10%.
    assert!(atlas("hemi-raster:direct", 0.12).fails(&report.runs));
    assert!(!atlas("hemi-raster:direct", 0.08).fails(&report.runs));

    let failing = atlas("hemi-raster", 0.2);
    let spec = |name: &str| crate::methods::parse(name).unwrap();
    let remedy = |name: &str, outcome| AtlasRun::remedy(&failing, &spec(name), outcome);
    let ran = |error| atlas("hemi-raster", error).outcome;
    let tried = vec![
        remedy("hemi-raster:flat", ran(0.12)),
        remedy("hemi-raster:direct", ran(0.06)),
        remedy("hemi-raster:pvs", Outcome::Refused("no".into())),
    ];
    let best = AtlasRun::best_remedy(&failing, &tried).unwrap();
    assert_eq!(best.setting, "hemi-raster:direct");
    assert_eq!(best.remedy_for.as_deref(), Some("hemi-raster"));
    assert!(
        best.diagnosis
            .contains("6.0% error against hemi-raster's 20.0%"),
        "{}",
        best.diagnosis
    );
    let no_help = vec![remedy("hemi-raster:flat", ran(0.195))];
    let best = AtlasRun::best_remedy(&failing, &no_help).unwrap();
    assert!(
        best.diagnosis
            .contains("nothing better among hemi-raster:flat"),
        "{}",
        best.diagnosis
    );
    let refused = vec![remedy("hemi-raster:flat", Outcome::Refused("no".into()))];
    assert!(AtlasRun::best_remedy(&failing, &refused).is_none());
    // Remedies tried for another setting or scene do not count.
    let elsewhere = AtlasRun {
        scene: "sun-only".into(),
        ..remedy("hemi-raster:direct", ran(0.01))
    };
    assert!(AtlasRun::best_remedy(&failing, &[elsewhere]).is_none());
}

/// [`report`] with thin-sheets in its atlas: `hemi-raster` failing (20%)
/// with `hemi-raster:direct` (6%) tried as its remedy, and `raytrace:4`;
/// judged.
fn with_failing_atlas() -> Report {
    let mut report = report();
    let failing = atlas("hemi-raster", 0.2);
    let spec = crate::methods::parse("hemi-raster:direct").unwrap();
    let direct = atlas("hemi-raster:direct", 0.06).outcome;
    report.atlas = vec![failing.clone(), atlas("raytrace:4", 0.3)];
    report.remedies = vec![AtlasRun::remedy(&failing, &spec, direct)];
    report.judge_atlas();
    report
}

/// Judging diagnoses every standard setting, puts the best remedy after
/// each failing one only, and gives the same atlas when judged again.
#[test]
fn judging_the_atlas_places_remedies_after_failing_settings_only() {
    let mut report = with_failing_atlas();
    let settings: Vec<(&str, Option<&str>)> = report
        .atlas
        .iter()
        .map(|r| (r.setting.as_str(), r.remedy_for.as_deref()))
        .collect();
    assert_eq!(
        settings,
        [
            ("hemi-raster", None),
            ("hemi-raster:direct", Some("hemi-raster")),
            ("raytrace:4", None),
        ]
    );
    assert!(report.atlas.iter().all(|r| !r.diagnosis.is_empty()));
    let judged = serde_json::to_value(&report.atlas).unwrap();
    report.judge_atlas();
    assert_eq!(serde_json::to_value(&report.atlas).unwrap(), judged);
}

#[test]
fn parts_read_as_i_of_n_and_deal_scenes_round_robin() {
    let part: Part = "2/3".parse().unwrap();
    assert_eq!((part.index(), part.count()), (2, 3));
    assert_eq!(part.to_string(), "2/3");
    assert_eq!(
        (0..7).filter(|&u| part.holds(u)).collect::<Vec<_>>(),
        [1, 4]
    );
    for bad in ["0/2", "3/2", "2", "a/b", "1/0"] {
        assert!(bad.parse::<Part>().is_err(), "{bad}");
    }
    assert!((0..5).all(|u| Part::WHOLE.holds(u)));
}

/// `report`'s data as part `index` of 2: the scenes part `index` holds,
/// its atlas not yet judged.
fn part_of(report: &Report, index: usize) -> Report {
    let part = Part::new(index, 2).unwrap();
    let s = &report.settings;
    let order: Vec<&String> = s.scenes.iter().chain(&s.atlas_scenes).collect();
    let holds = |scene: &str| part.holds(order.iter().position(|s| *s == scene).unwrap());
    let mut r = report.clone();
    r.settings.part = part;
    r.references.retain(|x| holds(&x.scene));
    r.runs.retain(|x| holds(&x.result.scene));
    r.skipped.retain(|x| holds(&x.scene));
    r.failed.retain(|x| holds(&x.scene));
    r.atlas
        .retain(|x| holds(&x.scene) && x.remedy_for.is_none());
    r.remedies.retain(|x| holds(&x.scene));
    r
}

/// Two parts merge into the report they were cut from, through the files
/// a part writes; a missing, doubled or foreign part is refused by name.
#[test]
fn parts_merge_into_the_whole_report() {
    // thin-sheets (the third unit, part 1's) fails against the standard
    // scenes of part 2 (human) and part 1 (bunny) alike.
    let whole = with_failing_atlas();
    assert_eq!(whole.atlas.len(), 3);
    let dir = tempfile::tempdir().unwrap();
    let mut parts = Vec::new();
    for index in [2, 1] {
        let folder = dir.path().join(format!("part{index}"));
        part_of(&whole, index).write_part(&folder).unwrap();
        parts.push((format!("part{index}"), Report::read(&folder).unwrap()));
    }
    let merged = merge(parts.clone()).unwrap();
    let json = |r: &Report| {
        let mut v = serde_json::to_value(r).unwrap();
        v.as_object_mut().unwrap().remove("merged_from");
        v
    };
    assert_eq!(json(&merged), json(&whole));
    assert_eq!(merged.merged_from.len(), 2);

    let error = |parts: Vec<(String, Report)>| merge(parts).unwrap_err().to_string();
    assert!(error(parts[..1].to_vec()).contains("part 1/2 missing"));
    let mut of_three = parts.clone();
    of_three[1].1.settings.part = Part::new(3, 3).unwrap();
    assert!(error(of_three).contains("part1 is part 3/3, part2 part 2 of 2"));
    let doubled = vec![parts[0].clone(), parts[0].clone()];
    assert!(error(doubled).contains("both part 2/2"));
    let mut foreign = parts.clone();
    foreign[1].1.settings.seed += 1;
    assert!(error(foreign).contains("part1 is a part of another plan than part2"));
    assert!(Report::read(dir.path()).is_err());
}

/// Equal error: log-log between the ray tracer's settings, time ∝ error⁻²
/// beyond them.
#[test]
fn the_ray_tracer_at_equal_error_is_read_off_its_settings() {
    let at = [(0.4, 10.0), (0.1, 160.0)];
    let (ms, beyond) = equal_error_ms(&at, 0.2).unwrap();
    approx::assert_relative_eq!(ms, 40.0, max_relative = 1e-5);
    assert!(!beyond);
    let (ms, beyond) = equal_error_ms(&at, 0.05).unwrap();
    approx::assert_relative_eq!(ms, 640.0, max_relative = 1e-5);
    assert!(beyond);
    let (ms, _) = equal_error_ms(&at, 0.8).unwrap();
    approx::assert_relative_eq!(ms, 2.5, max_relative = 1e-5);
    assert_eq!(equal_error_ms(&[], 0.1), None);
}

#[test]
fn a_setting_overtakes_from_where_it_stays_faster() {
    assert_eq!(
        overtakes(&[(160.0, 0.5), (1024.0, 0.1)]),
        Overtakes::Everywhere
    );
    assert_eq!(overtakes(&[(160.0, 0.5), (1024.0, 1.5)]), Overtakes::Never);
    // Behind by 2× at 160, ahead by 2× at 640: even in log-log at 320.
    let Overtakes::From(w) = overtakes(&[(160.0, 2.0), (640.0, 0.5), (1024.0, 0.2)]) else {
        panic!("expected a crossing");
    };
    approx::assert_relative_eq!(w, 320.0, max_relative = 1e-9);
    // Ahead, behind, ahead: from the last crossing.
    let Overtakes::From(w) = overtakes(&[(160.0, 0.5), (320.0, 1.5), (640.0, 0.5)]) else {
        panic!("expected a crossing");
    };
    assert!(w > 320.0 && w < 640.0, "{w}");
}

/// A per-frame method (flat in width) against a per-pixel ray tracer
/// (time ∝ width²): the table names where it overtakes, the sentence says
/// so with the figures, the chart is written.
#[test]
fn the_resolution_section_compares_with_the_ray_tracer_at_equal_error() {
    use crate::scaling::{ScalingRun, WidthTime};
    let mut report = report();
    let scaled = |family: &str, setting: &str, ms: &dyn Fn(f64) -> f64| ScalingRun {
        scene: "bunny".into(),
        family: family.into(),
        setting: setting.into(),
        per_pixel: true,
        widths: [160u32, 320, 640, 1024]
            .map(|w| WidthTime {
                width: w,
                height: w * 3 / 4,
                time: Timing::new(vec![ms(f64::from(w)) / 1e3]),
            })
            .to_vec(),
    };
    // raytrace:4 and :16 score 30% and 15% per pixel on bunny (1.5× their
    // vertex errors, see `run`); hemi-raster scores 7.35%, beyond them.
    report
        .runs
        .retain(|r| r.setting != "raytrace:16" || r.result.scene != "bunny");
    report
        .runs
        .push(run("bunny", RAY_TRACER, "raytrace:16", 0.1, 12.0));
    report.scaling = vec![
        scaled("hemi-raster", "hemi-raster", &|_| 40.0),
        scaled(RAY_TRACER, "raytrace:4", &|w| (w / 160.0).powi(2)),
        scaled(RAY_TRACER, "raytrace:16", &|w| 4.0 * (w / 160.0).powi(2)),
    ];
    let comparisons = report.width_comparisons("bunny");
    assert_eq!(comparisons.len(), 1);
    let c = &comparisons[0];
    approx::assert_relative_eq!(c.slope, 0.0, epsilon = 1e-9);
    // The ray tracer at 7.35%: (15 / 7.35)² × raytrace:16's time, beyond
    // its settings.
    let factor = (0.15f64 / 0.0735).powi(2);
    for (w, (ms, beyond)) in [160.0f64, 320.0, 640.0, 1024.0]
        .iter()
        .zip(&c.ray_tracer_ms)
    {
        approx::assert_relative_eq!(*ms, factor * 4.0 * (w / 160.0).powi(2), max_relative = 1e-4);
        assert!(beyond);
    }
    // 40 ms = factor × 4 ms × (w / 160)²: both times are powers of the
    // width, so the log-log interpolation between 160 and 320 pixels finds
    // the crossing exactly, up to the f32 rounding of the errors.
    let crossing = 160.0 * (10.0 / factor).sqrt();
    match c.overtakes {
        Overtakes::From(w) => approx::assert_relative_eq!(w, crossing, max_relative = 1e-4),
        other => panic!("{other:?}"),
    }
    let dir = tempfile::tempdir().unwrap();
    report.write(dir.path()).unwrap();
    assert!(dir.path().join("charts/resolution.png").is_file());
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("### Resolution: bunny"), "{md}");
    assert!(md.contains("| hemi-raster | 7.35% |"), "{md}");
    assert!(
        md.contains("On bunny, hemi-raster (7.35% per pixel) overtakes the ray tracer"),
        "{md}"
    );
}

/// JSON has no NaN: a non-finite error is written as null and read back
/// as NaN, so a part whose method returned non-finite radiance merges.
#[test]
fn non_finite_errors_survive_a_part_file() {
    let mut r = report();
    r.runs[0].result.frames[0].vertex.relative_l2 = f32::NAN;
    r.runs[0].result.frames[0].vertex.max = f32::INFINITY;
    let dir = tempfile::tempdir().unwrap();
    r.write_part(dir.path()).unwrap();
    let read = Report::read(dir.path()).unwrap();
    let vertex = read.runs[0].result.frames[0].vertex;
    assert!(vertex.relative_l2.is_nan() && !vertex.max.is_finite());
    assert_eq!(vertex.p50, r.runs[0].result.frames[0].vertex.p50);
}

#[test]
fn one_ray_tracer_setting_reads_off_its_own_time() {
    let (ms, beyond) = equal_error_ms(&[(0.1, 50.0)], 0.1).unwrap();
    approx::assert_relative_eq!(ms, 50.0, max_relative = 1e-9);
    assert!(!beyond);
    let (ms, beyond) = equal_error_ms(&[(0.1, 50.0)], 0.05).unwrap();
    approx::assert_relative_eq!(ms, 200.0, max_relative = 1e-5);
    assert!(beyond);
}
