//! What the harness writes for other tools: exports that relight to the
//! method's own radiance, images whose scores can be recomputed from the
//! files, and clear refusals of bad requests that leave nothing behind.

use std::{
    collections::HashMap,
    io::{Cursor, Read},
    path::Path,
    process::Command,
};

use glam::Vec3;
use harness::{
    export::{self, Provenance},
    images,
    methods::SharedGpu,
    scenes,
};
use shadow_core::{
    DirectionalVisibility, Environment, Export, Scene, ShadowMethod,
    sh::{self, ShOrder},
};

/// One array of an `.npz`: its type descriptor, shape and raw data.
struct Npy {
    descr: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Npy {
    fn f32s(&self) -> Vec<f32> {
        assert_eq!(self.descr, "<f4");
        self.data
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    fn text(&self) -> String {
        assert!(self.descr.starts_with("<U"), "{}", self.descr);
        let chars = self.data.chunks_exact(4);
        chars
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .filter(|&c| c != 0)
            .map(|c| char::from_u32(c).unwrap())
            .collect()
    }
}

/// Reads an `.npz` as numpy would: every `name.npy` member, its header
/// parsed from the dictionary text.
fn read_npz(path: &Path) -> HashMap<String, Npy> {
    let bytes = std::fs::read(path).unwrap();
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
    let mut out = HashMap::new();
    for i in 0..zip.len() {
        let mut member = zip.by_index(i).unwrap();
        let name = member
            .name()
            .unwrap()
            .strip_suffix(".npy")
            .unwrap()
            .to_string();
        let mut npy = Vec::new();
        member.read_to_end(&mut npy).unwrap();
        assert_eq!(&npy[..8], b"\x93NUMPY\x01\x00");
        let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
        let header = std::str::from_utf8(&npy[10..10 + header_len]).unwrap();
        let field = |key: &str| {
            let start = header.find(key).unwrap() + key.len();
            header[start..].trim_start_matches([':', ' ', '\''])
        };
        let descr = field("'descr'").split('\'').next().unwrap().to_string();
        let shape_text = field("'shape'");
        let shape = shape_text[1..shape_text.find(')').unwrap()]
            .split(',')
            .filter_map(|d| d.trim().parse().ok())
            .collect();
        assert!(field("'fortran_order'").starts_with("False"));
        out.insert(
            name,
            Npy {
                descr,
                shape,
                data: npy[10 + header_len..].to_vec(),
            },
        );
    }
    out
}

/// A lat-long map with a bright patch: light that differs by direction.
fn patchy_sky() -> Environment {
    let (w, h) = (32, 16);
    let texels = (0..w * h)
        .map(|i| {
            let (row, col) = (i / w, i % w);
            let base = Vec3::new(0.3, 0.4, 0.6) * (1.0 - row as f32 / h as f32);
            if (3..6).contains(&row) && (20..24).contains(&col) {
                base + Vec3::new(20.0, 16.0, 9.0)
            } else {
                base
            }
        })
        .collect();
    Environment::new("patchy", w, h, texels).unwrap()
}

/// `name` run on the built-in `scene` under a uniform sky, its export
/// written to an `.npz` and read back: the method (to relight and shade
/// next), the scene, and the file's arrays and metadata.
fn exported(
    scene: &str,
    name: &str,
    gpu: &SharedGpu,
) -> (
    Box<dyn ShadowMethod>,
    Scene,
    HashMap<String, Npy>,
    serde_json::Value,
) {
    let scene = scenes::builtin(scene).unwrap();
    let frame = scene.frame_geometry(0).unwrap();
    let mut method = harness::methods::by_name(name, gpu).unwrap();
    method.prepare(&scene).unwrap();
    method.relight(&Environment::uniform(Vec3::ONE)).unwrap();
    method.update(&frame, scene.camera()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("exported.npz");
    let from = Provenance {
        method: method.name(),
        scene: &scene,
        frame: &frame,
    };
    export::write_npz(&path, &method.export().unwrap(), from).unwrap();
    let arrays = read_npz(&path);
    let meta = serde_json::from_str(&arrays["meta"].text()).unwrap();
    (method, scene, arrays, meta)
}

#[test]
fn exported_transfer_relights_to_the_methods_own_radiance() {
    relit_transfer_matches(exported("wall", "hemi-raster", &SharedGpu::new()));
}

/// deferred-shadow exports its self-transfer: on one object (nothing else
/// casts on it) that is all it shades.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn exported_self_transfer_relights_to_the_methods_own_radiance() {
    let context = shadow_core::gpu::test_context();
    relit_transfer_matches(exported(
        "teapot",
        "deferred-shadow",
        &SharedGpu::with(context),
    ));
}

/// The transfer of an export relit under a second environment from the file
/// alone is what the method shades after relighting: to rounding.
fn relit_transfer_matches(
    (mut method, scene, arrays, meta): (
        Box<dyn ShadowMethod>,
        Scene,
        HashMap<String, Npy>,
        serde_json::Value,
    ),
) {
    assert_eq!(meta["kind"], "sh_transfer");
    let order = ShOrder::new(meta["sh"]["order"].as_u64().unwrap() as u32).unwrap();
    let n = order.coeff_count();
    let transfer = &arrays["transfer"];
    assert_eq!(transfer.shape, vec![scene.vertex_count(), n]);
    let offsets = &arrays["object_offsets"];
    assert_eq!(offsets.shape, vec![scene.objects().len() + 1]);
    let sky = patchy_sky();
    let light = sh::project_environment(&sky, order);
    let albedo = |o: usize| {
        let a = &meta["materials"][o]["Lambert"]["albedo"];
        Vec3::new(
            a[0].as_f64().unwrap() as f32,
            a[1].as_f64().unwrap() as f32,
            a[2].as_f64().unwrap() as f32,
        )
    };
    let coefficients = transfer.f32s();
    let mut relit = Vec::new();
    let objects = scene.objects();
    for (o, object) in objects.iter().enumerate() {
        let first: usize = objects[..o].iter().map(|x| x.mesh.vertex_count()).sum();
        for v in first..first + object.mesh.vertex_count() {
            let e = light.dot(&coefficients[v * n..(v + 1) * n]);
            relit.push((albedo(o) * std::f32::consts::FRAC_1_PI * e).max(Vec3::ZERO));
        }
    }
    method.relight(&sky).unwrap();
    let shaded: Vec<Vec3> = method.shade(scene.camera().eye).unwrap().flat().collect();
    let scale = shaded.iter().map(|x| x.length()).fold(0.0, f32::max);
    for (a, b) in relit.iter().zip(&shaded) {
        assert!((*a - *b).length() <= 1e-5 * scale, "{a} against {b}");
    }
}

#[test]
fn exported_visibility_unpacks_as_documented() {
    let scene = scenes::builtin("wall").unwrap();
    let frame = scene.frame_geometry(0).unwrap();
    let vertices = scene.vertex_count();
    let k = 70; // two words per vertex, the last byte partly used
    let directions: Vec<Vec3> = (0..k)
        .map(|j| {
            let z = 1.0 - 2.0 * (j as f32 + 0.5) / k as f32;
            let phi = j as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * phi.cos(), z, r * phi.sin())
        })
        .collect();
    let weights = vec![4.0 * std::f32::consts::PI / k as f32; k];
    let normals: Vec<Vec3> = frame
        .objects
        .iter()
        .flat_map(|o| o.normals().to_vec())
        .collect();
    let visible: Vec<u64> = (0..vertices * 2)
        .map(|w| 0x9e37_79b9_7f4a_7c15u64.rotate_left(w as u32 % 64) ^ w as u64)
        .collect();
    let counts = frame.objects.iter().map(|o| o.vertex_count()).collect();
    let vis = DirectionalVisibility::new(directions, weights, counts, normals, visible).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vis.npz");
    let from = Provenance {
        method: "synthetic",
        scene: &scene,
        frame: &frame,
    };
    export::write_npz(&path, &Export::Visibility(vis.clone()), from).unwrap();

    let arrays = read_npz(&path);
    let packed = &arrays["visible"];
    assert_eq!(
        (packed.descr.as_str(), packed.shape.clone()),
        ("|u1", vec![vertices, 9])
    );
    let d = arrays["directions"].f32s();
    let w = arrays["weights"].f32s();
    let n = arrays["normals"].f32s();
    let radiance: Vec<Vec3> = (0..k)
        .map(|j| Vec3::new(1.0, j as f32 * 0.1, 2.0))
        .collect();
    let expected = vis.irradiance(&radiance);
    for i in 0..vertices {
        let mut e = Vec3::ZERO;
        for j in 0..k {
            // numpy.unpackbits(..., bitorder="little")
            let bit = packed.data[i * 9 + j / 8] >> (j % 8) & 1;
            let cos =
                n[3 * i] * d[3 * j] + n[3 * i + 1] * d[3 * j + 1] + n[3 * i + 2] * d[3 * j + 2];
            e += radiance[j] * f32::from(bit) * w[j] * cos.max(0.0);
        }
        assert!(
            (e - expected[i]).length() <= 1e-4 * expected[i].length().max(1.0),
            "vertex {i}"
        );
    }
}

/// occlusion-query's visibility, read back from the `.npz` alone and relit
/// under a second environment as the module docs say, is what the method
/// shades after relighting.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn exported_visibility_relights_to_the_methods_own_radiance() {
    let context = shadow_core::gpu::test_context();
    let (mut method, scene, arrays, meta) =
        exported("wall", "occlusion-query:k=66", &SharedGpu::with(context));
    assert_eq!(meta["kind"], "directional_visibility");
    let vec3s = |name: &str| -> Vec<Vec3> {
        arrays[name]
            .f32s()
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect()
    };
    let (directions, normals) = (vec3s("directions"), vec3s("normals"));
    let weights = arrays["weights"].f32s();
    let packed = &arrays["visible"];
    let bytes = packed.shape[1];
    let sky = patchy_sky().prefiltered(meta["prefilter_radians"].as_f64().unwrap() as f32);
    let incoming: Vec<Vec3> = directions.iter().map(|&l| sky.lookup(l)).collect();
    let normalized = meta["cosine_normalized"].as_bool().unwrap();
    let albedo = 0.8; // scenes::white()
    let relit: Vec<Vec3> = normals
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let (mut e, mut quadrature) = (Vec3::ZERO, 0.0);
            for (j, l) in directions.iter().enumerate() {
                let wc = weights[j] * n.dot(*l).max(0.0);
                quadrature += wc;
                if packed.data[i * bytes + j / 8] >> (j % 8) & 1 == 1 {
                    e += incoming[j] * wc;
                }
            }
            if normalized {
                e *= std::f32::consts::PI / quadrature;
            }
            e * albedo / std::f32::consts::PI
        })
        .collect();

    method.relight(&patchy_sky()).unwrap();
    let shaded: Vec<Vec3> = method.shade(scene.camera().eye).unwrap().flat().collect();
    let scale = shaded.iter().map(|x| x.length()).fold(0.0, f32::max);
    for (a, b) in relit.iter().zip(&shaded) {
        assert!((*a - *b).length() <= 1e-4 * scale, "{a} against {b}");
    }
}

fn harness_command(args: &[&str], cache: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_harness"))
        .args(args)
        .arg("--cache")
        .arg(cache)
        .output()
        .unwrap()
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn image_scores_agree_with_the_written_images() {
    let dir = tempfile::tempdir().unwrap();
    let (report, pictures, cache) = (
        dir.path().join("report"),
        dir.path().join("img"),
        dir.path().join("cache"),
    );
    let out = harness_command(
        &[
            "report",
            "--scenes",
            "wall",
            "--repeats",
            "1",
            "--target",
            "0.05",
            "--image-width",
            "40",
            "--image-target",
            "0.05",
            "--out-dir",
            report.to_str().unwrap(),
            "--images-dir",
            pictures.to_str().unwrap(),
        ],
        &cache,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(report.join("report.json")).unwrap()).unwrap();
    let reference = images::read_exr(&pictures.join("wall/reference.exr")).unwrap();
    assert_eq!((reference.width, reference.height), (40, 30));
    let runs = json["runs"].as_array().unwrap();
    assert!(runs.len() >= 5);
    for run in runs {
        let method = run["method"].as_str().unwrap();
        let stem = images::file_stem(method);
        let image = images::read_exr(&pictures.join(format!("wall/{stem}.exr"))).unwrap();
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for i in 0..reference.pixels.len() {
            if reference.covered[i] {
                let x = if image.covered[i] {
                    image.pixels[i]
                } else {
                    Vec3::ZERO
                };
                num += (x - reference.pixels[i]).length_squared() as f64;
                den += reference.pixels[i].length_squared() as f64;
            }
        }
        let recomputed = (num / den).sqrt();
        let reported = run["frames"][0]["image"]["relative_l2"].as_f64().unwrap();
        assert!(
            (recomputed - reported).abs() <= 1e-5 * reported.max(1e-3),
            "{method}: {recomputed} recomputed, {reported} reported"
        );
        assert!(pictures.join(format!("wall/{stem}-error.png")).is_file());
        assert!(image::open(pictures.join(format!("wall/{stem}.png"))).is_ok());
    }
    let markdown = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        markdown.contains("image error") && markdown.contains("40×30"),
        "{markdown}"
    );
    for chart in ["scenes-image.png", "wall-image.png", "wall-image.svg"] {
        assert!(report.join("charts").join(chart).is_file(), "{chart}");
    }
}

#[test]
fn bad_requests_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            "--scene",
            "wall",
            "--target",
            "0.2",
            "--image-width",
            "8",
        ];
        args.extend_from_slice(extra);
        harness_command(&args, &cache)
    };
    let refused = |out: &std::process::Output, needle: &str| {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "accepted: {err}");
        assert!(err.contains(needle) && !err.contains("panicked"), "{err}");
    };

    let out = run(&["--method", "unshadowed", "--image-width", "0"]);
    refused(&out, "--image-width");

    let missing = dir.path().join("no/such/folder/out.csv");
    let out = run(&["--method", "unshadowed", "--out", missing.to_str().unwrap()]);
    refused(&out, "does not exist");
    assert!(!dir.path().join("no").exists());

    let export = dir.path().join("unshadowed.npz");
    let out = run(&[
        "--method",
        "unshadowed",
        "--export",
        export.to_str().unwrap(),
    ]);
    refused(&out, "nothing to export");
    assert!(!export.exists());
    // Refused before any reference was computed.
    assert!(!cache.exists());

    let out = run(&["--method", "raytrace:1"]);
    refused(&out, "invalid configuration");

    // A typo in a method or a scene names the closest valid one.
    refused(
        &run(&["--method", "hemi-raster:msak=16"]),
        "did you mean mask=",
    );
    let out = harness_command(
        &["run", "--scene", "tepot", "--method", "unshadowed"],
        &cache,
    );
    refused(&out, "did you mean teapot?");
    let report = |scenes: &str| {
        let out_dir = dir.path().join("report");
        let args = [
            "report",
            "--scenes",
            scenes,
            "--out-dir",
            out_dir.to_str().unwrap(),
        ];
        harness_command(&args, &cache)
    };
    refused(&report("bunny,tepot"), "did you mean teapot?");
    assert!(!dir.path().join("report").exists());

    // A GPU method where wgpu finds no adapter (only Metal allowed, on a
    // machine without it), or only OpenGL is asked for, whose shading
    // language cannot read depth textures as the methods do: a clear error
    // before any reference is computed.
    if cfg!(not(target_os = "macos")) {
        let with_backend = |backend: &str| {
            Command::new(env!("CARGO_BIN_EXE_harness"))
                .args([
                    "run",
                    "--scene",
                    "wall",
                    "--method",
                    "occlusion-query",
                    "--cache",
                ])
                .arg(&cache)
                .env("WGPU_BACKEND", backend)
                .output()
                .unwrap()
        };
        refused(&with_backend("metal"), "no GPU adapter found");
        refused(&with_backend("gl"), "OpenGL is never used");
        assert!(!cache.exists());
    }
}
