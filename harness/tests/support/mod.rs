//! The npm glTF tools the tests run (`tools/gltf`): glTF Transform's command
//! line, to make the variants a user's pipeline would, and the Khronos glTF
//! validator. Without them (`npm ci --prefix tools/gltf` installs them) a
//! test fails, naming the install; `SOFT_SHADOWS_SKIP=gltf-tools` marks
//! those tests as ignored instead.

#![allow(dead_code)] // each test binary uses part of this module

pub mod wall;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The installed tools.
pub struct GltfTools {
    dir: PathBuf,
}

impl GltfTools {
    /// The tools; panics, naming the install and the opt-out, when they
    /// are not installed.
    pub fn find() -> GltfTools {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/gltf");
        let installed = dir.join("node_modules/.bin/gltf-transform").exists()
            && dir.join("node_modules/gltf-validator").exists();
        assert!(
            installed,
            "this test needs the glTF tools, which are not installed in {}: \
             run `npm ci --prefix tools/gltf` (Node.js 20), or set \
             SOFT_SHADOWS_SKIP=gltf-tools to skip the tests that need them",
            dir.display()
        );
        GltfTools { dir }
    }

    /// Runs `gltf-transform ARGS…`, panicking with its output on failure.
    pub fn transform(&self, args: &[&str]) {
        let out = Command::new(self.dir.join("node_modules/.bin/gltf-transform"))
            .args(args)
            .output()
            .expect("run gltf-transform");
        assert!(
            out.status.success(),
            "gltf-transform {args:?} failed:\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// The Khronos validator's report of `file` (its JSON).
    pub fn validate(&self, file: &Path) -> serde_json::Value {
        let out = Command::new("node")
            .arg(self.dir.join("validate.mjs"))
            .arg(file)
            .output()
            .expect("run node");
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
            panic!(
                "the validator printed no report for {} ({e}):\n{}",
                file.display(),
                String::from_utf8_lossy(&out.stderr)
            )
        })
    }

    /// Panics with the validator's messages unless `file` has no errors.
    pub fn assert_valid(&self, file: &Path) {
        let report = self.validate(file);
        let errors = report["issues"]["numErrors"].as_u64().unwrap();
        assert_eq!(
            errors,
            0,
            "{} has validation errors: {:#}",
            file.display(),
            report["issues"]["messages"]
        );
    }
}

/// The top-level JSON of a GLB or `.gltf` file.
pub fn gltf_json(file: &Path) -> serde_json::Value {
    let bytes = std::fs::read(file).unwrap();
    let json = if bytes.starts_with(b"glTF") {
        let length = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        &bytes[20..20 + length]
    } else {
        &bytes[..]
    };
    serde_json::from_slice(json).unwrap()
}

/// The shipped asset `name` (in assets/meshes).
pub fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/meshes")
        .join(name)
}

/// Writes `meshes` (each placed by a translation) as `NAME.gltf` with its
/// data in `NAME.bin` in `dir`: one node and one mesh each, or one mesh
/// shared by every node when `shared` (then only the first mesh is written).
pub fn write_gltf(
    dir: &Path,
    name: &str,
    meshes: &[(&shadow_core::Mesh, glam::Vec3)],
    shared: bool,
) -> PathBuf {
    use serde_json::json;
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut gltf_meshes, mut nodes) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, (mesh, at)) in meshes.iter().enumerate() {
        nodes.push(json!({"mesh": if shared { 0 } else { i }, "translation": at.to_array()}));
        if shared && i > 0 {
            continue;
        }
        let positions: Vec<f32> = mesh.positions().iter().flat_map(|p| p.to_array()).collect();
        let (min, max) = (mesh.bounds().min, mesh.bounds().max);
        let indices: Vec<u32> = mesh.triangles().iter().flatten().copied().collect();
        let first = accessors.len();
        for (bytes, count, kind, component, target) in [
            (
                f32_bytes(&positions),
                mesh.vertex_count(),
                "VEC3",
                5126,
                34962,
            ),
            (u32_bytes(&indices), indices.len(), "SCALAR", 5125, 34963),
        ] {
            views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len(), "target": target}));
            let mut accessor = json!({"bufferView": views.len() - 1, "componentType": component, "count": count, "type": kind});
            if kind == "VEC3" {
                accessor["min"] = json!(min.to_array());
                accessor["max"] = json!(max.to_array());
            }
            accessors.push(accessor);
            bin.extend(bytes);
        }
        gltf_meshes.push(json!({"name": mesh.name(), "primitives": [{"attributes": {"POSITION": first}, "indices": first + 1}]}));
    }
    let json = json!({
        "asset": {"version": "2.0", "generator": "harness tests"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": gltf_meshes,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"uri": format!("{name}.bin"), "byteLength": bin.len()}],
    });
    std::fs::write(dir.join(format!("{name}.bin")), &bin).unwrap();
    let path = dir.join(format!("{name}.gltf"));
    std::fs::write(&path, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    path
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn u32_bytes(values: &[u32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Runs the `harness` binary with `args`; its stdout, or its stderr as the
/// error when it fails.
pub fn harness(args: &[&str]) -> Result<String, String> {
    let out = Command::new(env!("CARGO_BIN_EXE_harness"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("run harness");
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    }
}
