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
        err.contains(&new.join("benchmark.json").display().to_string()) && err.contains("full_id"),
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
