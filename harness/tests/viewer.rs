//! The viewer shows what the report scores: its offscreen screenshot equals
//! the image `harness run --images-dir` writes for the same camera, frame and
//! method, and its heat map's error is the run's image error. Under Xvfb its
//! real window answers keys that switch the method and turn the environment.

#![cfg(feature = "viewer")]

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use harness::images::{linear_from_srgb, read_exr};

/// The scene of the single-scene tests, and the noise target of the cheap
/// references (the viewer reads the same cached image reference as the run,
/// so both take the same settings).
const SCENE: &str = "bunny";
const TARGET: &str = "0.05";

fn harness() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_harness"));
    // lavapipe prints an error line per run without a runtime directory.
    let runtime = std::env::temp_dir().join("soft-shadows-xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    command.env("XDG_RUNTIME_DIR", runtime);
    command
}

fn run_ok(command: &mut Command) -> String {
    let out = command.output().expect("run the harness");
    assert!(
        out.status.success(),
        "{command:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `harness run --images-dir DIR` of `method` on `scene`: the run's
/// printout.
fn run_images(scene: &str, method: &str, dir: &Path, cache: &Path) -> String {
    run_ok(
        harness()
            .args(["run", "--scene", scene, "--method", method])
            .args([
                "--target",
                TARGET,
                "--image-target",
                TARGET,
                "--repeats",
                "1",
                "--images-dir",
                dir.to_str().unwrap(),
                "--cache",
                cache.to_str().unwrap(),
            ]),
    )
}

/// `harness view --screenshot` of `method` on `scene` at `size` after
/// `frames` frames, with `extra` arguments.
fn screenshot(
    (scene, method): (&str, &str),
    size: (u32, u32),
    frames: usize,
    out: &Path,
    cache: &Path,
    extra: &[&str],
) -> String {
    run_ok(
        harness()
            .args(["view", "--scene", scene, "--method", method])
            .args([
                "--width",
                &size.0.to_string(),
                "--height",
                &size.1.to_string(),
            ])
            .args(["--screenshot", out.to_str().unwrap()])
            .args(["--frames", &frames.to_string()])
            .args(["--image-target", TARGET, "--cache", cache.to_str().unwrap()])
            .args(extra),
    )
}

/// Linear values of an 8-bit sRGB PNG.
fn read_png(path: &Path) -> (u32, u32, Vec<[f32; 3]>) {
    let image = image::open(path).unwrap().to_rgb8();
    let pixels = image.pixels().map(|p| p.0.map(linear_from_srgb)).collect();
    (image.width(), image.height(), pixels)
}

/// `sqrt(Σ|a − b|² / Σ|b|²)` over the pixels `mask` keeps.
fn relative_l2(a: &[[f32; 3]], b: &[[f32; 3]], mask: impl Fn(usize) -> bool) -> f64 {
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for i in (0..b.len()).filter(|&i| mask(i)) {
        for c in 0..3 {
            diff += ((a[i][c] - b[i][c]) as f64).powi(2);
            norm += (b[i][c] as f64).powi(2);
        }
    }
    (diff / norm).sqrt()
}

/// The image error of the last frame the run printed (the fifth column of
/// its frame table's last row), as a fraction.
fn image_error(printout: &str) -> f64 {
    let row = printout
        .lines()
        .rev()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .find(|words| {
            words.len() > 4 && words[0].parse::<usize>().is_ok() && words[1].ends_with('%')
        })
        .unwrap_or_else(|| panic!("no frame table:\n{printout}"));
    row[4].trim_end_matches('%').parse::<f64>().unwrap() / 100.0
}

/// The error line `harness view --heat-map` printed, as a fraction.
fn heat_error(printout: &str) -> f64 {
    let line = printout
        .lines()
        .find(|l| l.contains("error against the cached image reference"))
        .unwrap_or_else(|| panic!("no heat-map error printed:\n{printout}"));
    let figure = line.rsplit(' ').next().unwrap();
    figure.trim_end_matches('%').parse::<f64>().unwrap() / 100.0
}

/// Per scene and method: the screenshot against the run's PNG of the
/// scene's last frame, over the pixels the run's image covers (the
/// background differs: the viewer draws the environment there), and the
/// heat map's error against the run's. Each screenshot draws the frames
/// given: one frame relights, updates and renders in one submission; more
/// frames reuse the lighting; the chess's six frames end on its last.
///
/// Measured on lavapipe at 160 pixels wide: hemi-raster on the bunny (per
/// vertex, interpolated by the GPU here and by the CPU rasterizer in the
/// run) 0.27%, deferred-shadow (per pixel, recorded into the viewer's
/// encoder here, its own blocking stages in the run) 0.29%, unshadowed on
/// the chess 0.07%: the two PNGs' 8-bit rounding and the GPU's sRGB
/// encoding. The allowance is 1%; half an EV of exposure is more than 5%
/// (checked), and before the depth buffer was reversed, surfaces fighting
/// at the chess pieces' bases gave 7%.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn screenshots_equal_the_images_the_run_scores() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    for (scene, method, frames) in [
        (SCENE, "hemi-raster", &[2][..]),
        (SCENE, "deferred-shadow", &[1, 2][..]),
        ("chess", "unshadowed", &[6][..]),
    ] {
        let images = dir.path().join(format!("{scene}-{method}"));
        let printout = run_images(scene, method, &images, &cache);
        let stem = harness::images::file_stem(method);
        let scored = read_exr(&images.join(scene).join(format!("{stem}.exr"))).unwrap();
        let (_, _, expected) = read_png(&images.join(scene).join(format!("{stem}.png")));
        let size = (scored.width, scored.height);

        for &n in frames {
            let shot = dir.path().join(format!("{scene}-{stem}-{n}.png"));
            screenshot((scene, method), size, n, &shot, &cache, &[]);
            let (w, h, seen) = read_png(&shot);
            assert_eq!((w, h), size);
            let difference = relative_l2(&seen, &expected, |i| scored.covered[i]);
            eprintln!(
                "{method} on {scene}, {n} frames: screenshot against the scored image {:.3}%",
                difference * 100.0
            );
            assert!(
                difference < 0.01,
                "{method} on {scene}, {n} frames: the viewer's picture differs from the \
                 scored image by {:.3}%",
                difference * 100.0
            );
        }

        // Half an EV is a different picture.
        let brighter = dir.path().join(format!("{scene}-{stem}-brighter.png"));
        let ev = ["--display-ev", "0.5"];
        screenshot((scene, method), size, frames[0], &brighter, &cache, &ev);
        let (_, _, bright) = read_png(&brighter);
        assert!(relative_l2(&bright, &expected, |i| scored.covered[i]) > 0.05);

        // The heat map scores what the run scored: measured equal to the
        // run's printed digits (25.47%, 4.93%, 10.61%); the allowance is
        // the printout's rounding (0.005%) and 1% of the figure.
        let heat = dir.path().join(format!("{scene}-{stem}-heat.png"));
        let on = ["--heat-map"];
        let said = screenshot((scene, method), size, frames[0], &heat, &cache, &on);
        let (viewer, run) = (heat_error(&said), image_error(&printout));
        eprintln!("{method} on {scene}: heat map error {viewer}, the run's {run}");
        assert!(
            (viewer - run).abs() <= 0.0001 + 0.01 * run,
            "{method} on {scene}: heat map {viewer} against the run's {run}"
        );
    }
}

/// Without a cached reference the heat map says so and the picture is the
/// method's.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn the_heat_map_needs_a_cached_reference() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("view.png");
    let said = screenshot(
        (SCENE, "unshadowed"),
        (64, 48),
        1,
        &out,
        &dir.path().join("empty"),
        &["--heat-map"],
    );
    assert!(said.contains("no cached image reference"), "{said}");
    assert!(out.exists());
}

/// Bad requests are refused before any window or device, naming the fault.
#[test]
fn bad_requests_are_refused() {
    for (args, says) in [
        (&["--method", "hemi-rastr"][..], "did you mean hemi-raster?"),
        (
            &["--screenshot", "/nonexistent/dir/x.png"][..],
            "does not exist",
        ),
    ] {
        let out = harness()
            .args(["view", "--scene", SCENE])
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
}

/// Without an adapter the viewer says so, naming what to install, and
/// exits with an error rather than a panic (OpenGL, the only backend
/// `WGPU_BACKEND=gl` leaves, is never used).
#[test]
fn no_adapter_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = harness()
        .env("WGPU_BACKEND", "gl")
        .args(["view", "--scene", SCENE, "--screenshot"])
        .arg(dir.path().join("x.png"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no GPU adapter"), "{stderr}");
    assert!(stderr.contains("mesa-vulkan-drivers"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.path().join("x.png").exists());
}

/// An X server of its own for one test, killed when dropped.
struct Xvfb {
    server: Child,
    display: String,
}

impl Xvfb {
    /// A server on a display number it picks itself (`-displayfd`: free
    /// of races with other servers), once it accepts connections.
    fn start() -> Xvfb {
        let mut server = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "this test needs Xvfb ({e}): apt-get install xvfb xdotool x11-apps, \
                     or set SOFT_SHADOWS_SKIP=display to skip it"
                )
            });
        // Xvfb writes the display number once it is ready.
        let mut number = String::new();
        let stdout = server.stdout.take().expect("piped");
        std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut number).unwrap();
        let number = number.trim();
        assert!(!number.is_empty(), "Xvfb exited without a display");
        Xvfb {
            server,
            display: format!(":{number}"),
        }
    }

    fn tool(&self, program: &str) -> Command {
        let mut command = Command::new(program);
        command.env("DISPLAY", &self.display);
        command
    }

    /// Runs `program args` on this display; its standard output.
    fn run(&self, program: &str, args: &[&str]) -> Vec<u8> {
        let out = self.tool(program).args(args).output().unwrap_or_else(|e| {
            panic!(
                "this test needs {program} ({e}): apt-get install xvfb xdotool x11-apps, \
                 or set SOFT_SHADOWS_SKIP=display to skip it"
            )
        });
        assert!(
            out.status.success(),
            "{program} {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    }

    /// The id of `program`'s window titled `title`, once it is open (at
    /// most two minutes); fails with the program's output if it exits
    /// first.
    fn window_of(&self, program: &mut Child, title: &str) -> String {
        let start = Instant::now();
        loop {
            let found = self
                .tool("xdotool")
                .args(["search", "--name", title])
                .output()
                .expect("run xdotool");
            if let Some(id) = String::from_utf8_lossy(&found.stdout).lines().next() {
                return id.trim().to_string();
            }
            if let Some(status) = program.try_wait().unwrap() {
                panic!("the viewer exited ({status}) before opening its window");
            }
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "no window titled {title:?}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// The window's pixels as `xwd` dumps them, RGB.
    fn capture(&self, window: &str) -> (u32, u32, Vec<[u8; 3]>) {
        parse_xwd(&self.run("xwd", &["-id", window, "-silent"]))
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

/// An XWD dump (Z pixmap, 24 or 32 bits per pixel, true colour) as RGB.
fn parse_xwd(bytes: &[u8]) -> (u32, u32, Vec<[u8; 3]>) {
    let field = |i: usize| u32::from_be_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let (header, width, height) = (field(0) as usize, field(4), field(5));
    let (byte_order, bits, line) = (field(7), field(11) as usize, field(12) as usize);
    let masks = [field(14), field(15), field(16)];
    let colours = field(19) as usize;
    assert!(bits == 32 || bits == 24, "{bits} bits per pixel");
    let data = &bytes[header + 12 * colours..];
    let step = bits / 8;
    let mut pixels = Vec::with_capacity((width * height) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let at = y * line + x * step;
            let mut word = [0u8; 4];
            word[..step].copy_from_slice(&data[at..at + step]);
            let value = if byte_order == 0 {
                u32::from_le_bytes(word)
            } else {
                u32::from_be_bytes(word) >> (32 - bits)
            };
            pixels.push(masks.map(|m| ((value & m) >> m.trailing_zeros()) as u8));
        }
    }
    (width, height, pixels)
}

/// Pixels at the right of the window the panel may cover.
const PANEL_WIDTH: usize = 340;

/// The mean absolute difference of two captures left of the panel (which
/// sits at the top right, and whose timings change every frame), in 8-bit
/// levels.
fn scene_change(a: &(u32, u32, Vec<[u8; 3]>), b: &(u32, u32, Vec<[u8; 3]>)) -> f64 {
    let (width, height) = (a.0 as usize, a.1 as usize);
    let left = width - PANEL_WIDTH;
    let mut sum = 0u64;
    for y in 0..height {
        for x in 0..left {
            let (p, q) = (a.2[y * width + x], b.2[y * width + x]);
            sum += (0..3).map(|c| p[c].abs_diff(q[c]) as u64).sum::<u64>();
        }
    }
    sum as f64 / (3 * height * left) as f64
}

/// Opens the real window under Xvfb, presses keys that switch the method
/// (4: deferred-shadow, per pixel) and turn the environment (→), drags the
/// mouse to orbit, and checks that each changed the picture, that Q closes
/// the window, and that nothing was reported as an error.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
#[cfg_attr(
    skip_display_tests,
    ignore = "needs Xvfb and xdotool (SOFT_SHADOWS_SKIP lists display)"
)]
fn the_window_answers_keys() {
    let x = Xvfb::start();
    let dir = tempfile::tempdir().unwrap();
    let mut viewer = harness()
        .env("DISPLAY", &x.display)
        .args(["view", "--scene", SCENE, "--method", "hemi-raster"])
        .args(["--width", "960", "--height", "600"])
        .args(["--cache", dir.path().to_str().unwrap()])
        .stdout(std::fs::File::create(dir.path().join("stdout")).unwrap())
        .stderr(std::fs::File::create(dir.path().join("stderr")).unwrap())
        .spawn()
        .unwrap();
    let window = x.window_of(&mut viewer, "harness view");
    x.run("xdotool", &["windowfocus", "--sync", &window]);

    // A picture has changed when it differs from the previous one left of
    // the panel, and settled when two captures 300 ms apart are equal there
    // (an idle viewer draws nothing new).
    let settled = |previous: &(u32, u32, Vec<[u8; 3]>)| {
        let start = Instant::now();
        let mut last = x.capture(&window);
        loop {
            std::thread::sleep(Duration::from_millis(300));
            let next = x.capture(&window);
            let changed = scene_change(previous, &next) > 0.05;
            if changed && scene_change(&last, &next) == 0.0 {
                return next;
            }
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "the picture did not change and settle within 2 minutes"
            );
            last = next;
        }
    };
    // Before its first frame the window is black.
    let (width, height, _) = x.capture(&window);
    let black = (width, height, vec![[0u8; 3]; (width * height) as usize]);
    let first = settled(&black);
    x.run("xdotool", &["key", "4"]);
    let switched = settled(&first);
    x.run("xdotool", &["key", "Right"]);
    let turned = settled(&switched);
    // A left drag orbits the camera.
    x.run(
        "xdotool",
        &[
            "mousemove",
            "--window",
            &window,
            "200",
            "300",
            "mousedown",
            "1",
        ],
    );
    x.run(
        "xdotool",
        &[
            "mousemove",
            "--window",
            &window,
            "320",
            "260",
            "mouseup",
            "1",
        ],
    );
    let orbited = settled(&turned);
    for (name, shot) in [
        ("first", &first),
        ("switched", &switched),
        ("turned", &turned),
        ("orbited", &orbited),
    ] {
        let rgb: Vec<u8> = shot.2.iter().flatten().copied().collect();
        image::save_buffer(
            dir.path().join(format!("{name}.png")),
            &rgb,
            shot.0,
            shot.1,
            image::ColorType::Rgb8,
        )
        .unwrap();
    }
    if let Ok(keep) = std::env::var("VIEWER_SCREENSHOTS") {
        for name in ["first", "switched", "turned", "orbited"] {
            std::fs::copy(
                dir.path().join(format!("{name}.png")),
                Path::new(&keep).join(format!("viewer-{name}.png")),
            )
            .unwrap();
        }
    }
    x.run("xdotool", &["key", "q"]);
    let success = exited(viewer);
    let read = |name| std::fs::read_to_string(dir.path().join(name)).unwrap();
    let (stdout, stderr) = (read("stdout"), read("stderr"));
    assert!(success, "the viewer failed:\n{stdout}\n{stderr}");
    // What the viewer itself reports as a failure starts so.
    let failures = stderr
        .lines()
        .filter(|l| l.starts_with("error") || l.starts_with("GPU error"));
    assert_eq!(
        failures.count(),
        0,
        "the viewer reported an error:\n{stderr}"
    );
    assert!(stdout.contains("deferred-shadow on bunny"), "{stdout}");
    // Switching relit once, the turn once more.
    let relights = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("relight"))
        .unwrap_or_else(|| panic!("no relight timed:\n{stdout}"));
    assert!(relights.contains("last 2 frames"), "{relights}");
}

/// Waits (at most a minute) for the viewer to exit; whether it succeeded.
fn exited(mut viewer: Child) -> bool {
    let start = Instant::now();
    loop {
        if let Some(status) = viewer.try_wait().unwrap() {
            return status.success();
        }
        if start.elapsed() > Duration::from_secs(60) {
            let _ = viewer.kill();
            panic!("the viewer did not close on Q within a minute");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}
