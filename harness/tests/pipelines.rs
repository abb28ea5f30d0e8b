//! Files from the common glTF pipelines load: the shipped assets run through
//! glTF Transform (quantized, meshopt-compressed, optimized with zero-filled
//! accessors, sparse) give the ambient occlusion of the originals, and what
//! cannot be read (Draco, unknown required extensions) is refused by name.

mod support;

use std::path::Path;

use glam::Vec3;
use harness::{
    gltf::GltfAsset,
    reference::{self, ReferenceSettings},
    scenes,
};
use indicatif::ProgressBar;
use shadow_core::{Brdf, Environment, Scene};
use support::{GltfTools, asset, gltf_json};

/// The surface-weighted mean ambient occlusion of every frame: each vertex
/// weighted by a third of the area of its triangles, so that files whose
/// pipelines weld or split vertices compare on the same surface.
fn mean_ao(path: &Path, frames: usize) -> Vec<f64> {
    let scene: Scene =
        scenes::asset_scene("variant", path, frames, Brdf::Lambert { albedo: Vec3::ONE }).unwrap();
    let env = Environment::uniform(Vec3::ONE);
    (0..scene.frames().len())
        .map(|k| {
            let frame = scene.frame_geometry(k).unwrap();
            let r = reference::vertex_reference(
                &scene,
                &frame,
                &env,
                scene.camera().eye,
                &ReferenceSettings::replicated(64, 2, 11),
                &ProgressBar::hidden(),
            )
            .unwrap();
            let (mut sum, mut area) = (0.0, 0.0);
            for (o, object) in frame.objects.iter().enumerate() {
                let p = object.positions();
                for t in object.triangles() {
                    let [a, b, c] = t.map(|i| i as usize);
                    let w = f64::from((p[b] - p[a]).cross(p[c] - p[a]).length()) / 6.0;
                    for v in [a, b, c] {
                        sum += w * f64::from(r.radiance.radiance[o][v].x);
                        area += w;
                    }
                }
            }
            sum / area
        })
        .collect()
}

fn assert_same_ao(original: &Path, variant: &Path, frames: usize) {
    let (a, b) = (mean_ao(original, frames), mean_ao(variant, frames));
    assert_eq!(a.len(), b.len(), "frame counts differ");
    for (k, (a, b)) in a.iter().zip(&b).enumerate() {
        assert!(
            (a - b).abs() <= 0.005 * a,
            "{}, frame {k}: mean AO {b:.5} against the original's {a:.5}",
            variant.display()
        );
    }
}

fn required(file: &Path) -> Vec<String> {
    gltf_json(file)["extensionsRequired"]
        .as_array()
        .map(|a| a.iter().map(|e| e.as_str().unwrap().to_string()).collect())
        .unwrap_or_default()
}

fn count_accessors(file: &Path, pred: impl Fn(&serde_json::Value) -> bool) -> usize {
    gltf_json(file)["accessors"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| pred(a))
        .count()
}

#[test]
#[cfg_attr(
    skip_gltf_tools_tests,
    ignore = "needs the npm glTF tools (SOFT_SHADOWS_SKIP lists gltf-tools)"
)]
fn quantized_and_meshopt_compressed_bunnies_keep_their_occlusion() {
    let tools = GltfTools::find();
    let dir = tempfile::tempdir().unwrap();
    let original = asset("bunny_npm_1839v.glb");
    let quantized = dir.path().join("quantized.glb");
    let compressed = dir.path().join("meshopt.glb");
    let input = original.to_str().unwrap();
    tools.transform(&["quantize", input, quantized.to_str().unwrap()]);
    tools.transform(&["meshopt", input, compressed.to_str().unwrap()]);
    for (file, extensions) in [
        (&quantized, &["KHR_mesh_quantization"][..]),
        (
            &compressed,
            &["EXT_meshopt_compression", "KHR_mesh_quantization"][..],
        ),
    ] {
        tools.assert_valid(file);
        let required = required(file);
        for e in extensions {
            assert!(required.iter().any(|r| r == e), "{required:?}");
        }
        assert_same_ao(&original, file, 1);
    }
}

#[test]
#[cfg_attr(
    skip_gltf_tools_tests,
    ignore = "needs the npm glTF tools (SOFT_SHADOWS_SKIP lists gltf-tools)"
)]
fn an_optimized_skinned_human_with_zero_filled_accessors_keeps_its_occlusion() {
    let tools = GltfTools::find();
    let dir = tempfile::tempdir().unwrap();
    let original = asset("BCN_Epileptic_skinned_animated.glb");
    let optimized = dir.path().join("optimized.glb");
    tools.transform(&[
        "optimize",
        original.to_str().unwrap(),
        optimized.to_str().unwrap(),
        "--simplify",
        "false",
    ]);
    tools.assert_valid(&optimized);
    assert!(count_accessors(&optimized, |a| a.get("bufferView").is_none()) > 0);
    assert!(
        required(&optimized)
            .iter()
            .any(|e| e == "EXT_meshopt_compression")
    );
    assert_same_ao(&original, &optimized, 3);
}

#[test]
#[cfg_attr(
    skip_gltf_tools_tests,
    ignore = "needs the npm glTF tools (SOFT_SHADOWS_SKIP lists gltf-tools)"
)]
fn sparse_morph_targets_pose_like_the_dense_ones() {
    let tools = GltfTools::find();
    let dir = tempfile::tempdir().unwrap();
    let original = asset("AnimatedMorphCube.gltf");
    let sparse = dir.path().join("sparse.glb");
    tools.transform(&[
        "sparse",
        original.to_str().unwrap(),
        sparse.to_str().unwrap(),
    ]);
    tools.assert_valid(&sparse);
    assert!(count_accessors(&sparse, |a| a.get("sparse").is_some()) > 0);
    let (a, b) = (
        GltfAsset::load(&original).unwrap(),
        GltfAsset::load(&sparse).unwrap(),
    );
    for time in [0.0, 0.4, 1.1, 2.0] {
        let (pa, pb) = (a.pose_at(time).unwrap(), b.pose_at(time).unwrap());
        assert_eq!(pa.len(), pb.len());
        for (pa, pb) in pa.iter().zip(&pb) {
            let (
                shadow_core::Pose::Deformed { positions: xa, .. },
                shadow_core::Pose::Deformed { positions: xb, .. },
            ) = (pa, pb)
            else {
                panic!("the morphed cube is deformed at {time} s");
            };
            for (x, y) in xa.iter().zip(xb.iter()) {
                assert!(x.abs_diff_eq(*y, 1e-6), "{x} against {y} at {time} s");
            }
        }
    }
}

#[test]
#[cfg_attr(
    skip_gltf_tools_tests,
    ignore = "needs the npm glTF tools (SOFT_SHADOWS_SKIP lists gltf-tools)"
)]
fn draco_and_unknown_required_extensions_are_refused_by_name() {
    let tools = GltfTools::find();
    let dir = tempfile::tempdir().unwrap();
    let draco = dir.path().join("draco.glb");
    tools.transform(&[
        "draco",
        asset("bunny_npm_1839v.glb").to_str().unwrap(),
        draco.to_str().unwrap(),
    ]);
    let message = GltfAsset::load(&draco).err().unwrap().to_string();
    assert!(
        message.contains("KHR_draco_mesh_compression") && message.contains("draco.glb"),
        "{message}"
    );

    let mut json = gltf_json(&asset("AnimatedMorphCube.gltf"));
    json["extensionsUsed"] = serde_json::json!(["EXT_made_up"]);
    json["extensionsRequired"] = serde_json::json!(["EXT_made_up"]);
    json["buffers"][0]["uri"] = serde_json::json!(asset("AnimatedMorphCube.bin"));
    let unknown = dir.path().join("unknown.gltf");
    std::fs::write(&unknown, serde_json::to_vec(&json).unwrap()).unwrap();
    let message = GltfAsset::load(&unknown).err().unwrap().to_string();
    assert!(
        message.contains("unsupported extension EXT_made_up"),
        "{message}"
    );
}
