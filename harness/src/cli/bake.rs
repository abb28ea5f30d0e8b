//! `harness bake`: a per-vertex result of one frame of the user's glTF
//! file, written into a copy of it as a vertex attribute.

use std::{path::PathBuf, time::Instant};

use anyhow::{Result, bail};
use clap::Args;

use super::args::{EnvArgs, check_output};
use crate::{
    bake, export,
    gltf::{GltfAsset, patch},
    methods::{Methods, SharedGpu},
    progress::Progress,
    reference::ReferenceSettings,
    scenes,
};

#[derive(Args, Debug)]
pub struct BakeArgs {
    /// Your glTF (.gltf or .glb) file.
    #[arg(long)]
    mesh: PathBuf,
    /// The file to write (.glb, or .gltf with its data in a .bin beside it).
    #[arg(long)]
    out: PathBuf,
    /// What to bake: ambient occlusion (needs `--env uniform`, the
    /// default), irradiance or outgoing radiance.
    #[arg(long, value_enum, default_value_t = bake::Quantity::AmbientOcclusion)]
    quantity: bake::Quantity,
    /// `reference` (the converged Monte-Carlo estimate) or a method name
    /// (see `harness list`).
    #[arg(long, default_value = "reference")]
    method: String,
    /// The vertex attribute: `COLOR_0` (ambient occlusion only; viewers
    /// multiply it into the base colour) or an application-specific
    /// `_NAME`; default `_AO`, `_IRRADIANCE` or `_RADIANCE`.
    #[arg(long)]
    attribute: Option<String>,
    /// Overwrite the attribute where the file already has it.
    #[arg(long)]
    replace: bool,
    /// Frames to sample from the file's first animation.
    #[arg(long, default_value_t = 1)]
    frames: usize,
    /// The frame to bake, of those sampled.
    #[arg(long, default_value_t = 0)]
    frame: usize,
    /// Albedo of the white Lambert material (matters for radiance only).
    #[arg(long, default_value_t = 1.0)]
    albedo: f32,
    #[command(flatten)]
    env: EnvArgs,
    /// Target relative L2 error of the reference (with `--method
    /// reference`): its standard error over all vertices, measured from
    /// independent replicates and printed when done. 0.01 is about
    /// MeshLab's 256-ray ambient occlusion (0.98% on the 35k bunny);
    /// halving it costs about four times the rays.
    #[arg(long, default_value_t = 0.01)]
    target: f32,
    /// Also write what the method computed (its SH transfer, say) to this
    /// .npz file.
    #[arg(long)]
    export: Option<PathBuf>,
}

pub fn bake(args: BakeArgs, methods: &Methods, progress: &Progress) -> Result<()> {
    for path in std::iter::once(&args.out).chain(&args.export) {
        check_output(path)?;
    }
    let spec = match args.method.as_str() {
        "reference" if args.export.is_some() => {
            bail!("the reference has nothing to export: name a method")
        }
        "reference" => None,
        name => Some(methods.parse(name)?),
    };
    let quantity = args.quantity;
    let attribute = args
        .attribute
        .unwrap_or_else(|| quantity.default_attribute().into());
    let attribute_spec = patch::AttributeSpec::new(&attribute, args.replace)?;
    let environment = args.env.load("uniform")?;
    quantity.check(&environment, &attribute)?;
    let mesh = &args.mesh;
    let asset = GltfAsset::load(mesh)?;
    let name = mesh
        .file_stem()
        .map_or("mesh".into(), |s| s.to_string_lossy().into_owned());
    let material = scenes::lambert(args.albedo)?;
    let scene = scenes::scene_of_asset(&name, &asset, args.frames, material)?;
    let frame = args.frame;
    if frame >= scene.frames().len() {
        bail!(
            "--frame {frame}: {} has {} frames (sample more with --frames)",
            mesh.display(),
            scene.frames().len()
        );
    }
    let start = Instant::now();
    let (radiance, exported, by) = match &spec {
        None => {
            let settings = ReferenceSettings {
                target_noise: Some(args.target),
                ..ReferenceSettings::BAKE
            };
            let bar = progress.task(&format!("reference {name}"));
            let r = bake::reference_frame(&scene, &environment, frame, &settings, &bar)?;
            bar.finish_and_clear();
            println!(
                "reference: error bound {:.3}% (relative L2 standard error, from \
                 independent replicates), {:.1} M shadow rays",
                r.noise * 100.0,
                r.rays as f64 * 1e-6
            );
            (r.radiance, None, "reference".to_string())
        }
        Some(spec) => {
            let mut method = spec.build(&SharedGpu::new())?;
            let radiance = bake::method_frame(method.as_mut(), &scene, &environment, frame)?;
            let exported = args.export.as_ref().map(|_| method.export()).transpose()?;
            (radiance, exported, spec.name().to_string())
        }
    };
    let values = quantity.values(&radiance, args.albedo);
    let sources: Vec<_> = asset.sources().cloned().collect();
    let summary = patch::write_with_attribute(mesh, &args.out, &sources, &values, &attribute_spec)?;
    let all: Vec<f32> = values
        .iter()
        .flat_map(|v| v.values.iter().copied())
        .collect();
    let mean = all.iter().map(|&v| f64::from(v)).sum::<f64>() / all.len().max(1) as f64;
    println!(
        "{quantity:?} of {} under {}, frame {frame}, by {by} in {:.1} s: \
         mean {mean:.4}, min {:.4}, max {:.4}",
        mesh.display(),
        environment.name(),
        start.elapsed().as_secs_f64(),
        all.iter().copied().fold(f32::INFINITY, f32::min),
        all.iter().copied().fold(f32::NEG_INFINITY, f32::max),
    );
    println!(
        "wrote {} with {attribute} on {} primitives ({} meshes copied for their \
         instances, {} attributes replaced)",
        args.out.display(),
        summary.primitives,
        summary.copied_meshes,
        summary.replaced
    );
    if let (Some(path), Some(exported)) = (&args.export, exported) {
        let geometry = scene.frame_geometry(frame)?;
        let from = export::Provenance {
            method: &by,
            scene: &scene,
            frame: &geometry,
        };
        export::write_npz(path, &exported, from)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
