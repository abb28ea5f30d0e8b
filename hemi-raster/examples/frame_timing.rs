//! Times one frame of hemi-raster on a wrinkled cloth of about 2,000
//! vertices (the size of the paper's Table 1 models), per stage and per mask
//! resolution, with the two-level mesh hierarchy (the default) and flat
//! (every triangle for every vertex). Run with `cargo run --release -p hemi-raster --example
//! frame_timing`.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use hemi_raster::{Config, HemiRaster, Hierarchy, Integration, MaskResolution};
use shadow_core::{Brdf, Camera, Environment, Mesh, Object, Result, Scene, ShadowMethod};

/// A 1 m sheet of `n`×`n` vertices with crossing sine wrinkles.
fn cloth(n: u32) -> Result<Mesh> {
    let mut positions = Vec::new();
    for k in 0..n {
        for i in 0..n {
            let (x, z) = (
                i as f32 / (n - 1) as f32 - 0.5,
                k as f32 / (n - 1) as f32 - 0.5,
            );
            let y = 0.06 * (x * 19.0).sin() * (z * 7.0).cos() + 0.04 * (z * 23.0).sin();
            positions.push(Vec3::new(x, y, z));
        }
    }
    let mut triangles = Vec::new();
    for k in 0..n - 1 {
        for i in 0..n - 1 {
            let a = k * n + i;
            triangles.push([a, a + n, a + 1]);
            triangles.push([a + 1, a + n, a + n + 1]);
        }
    }
    Mesh::new("cloth", positions, None, triangles)
}

fn median(mut times: Vec<Duration>) -> Duration {
    times.sort();
    times[times.len() / 2]
}

fn main() -> Result<()> {
    let mesh = cloth(45)?;
    println!(
        "cloth: {} vertices, {} triangles, {} threads",
        mesh.vertex_count(),
        mesh.triangle_count(),
        rayon::current_num_threads()
    );
    let camera = Camera::new(Vec3::new(0.0, 1.0, 1.5), Vec3::ZERO, Vec3::Y, 0.8, 64, 64)?;
    let scene = Scene::still(
        "cloth",
        vec![Object {
            mesh: Arc::new(mesh),
            material: Brdf::lambert(Vec3::splat(0.8))?,
        }],
        camera,
    )?;
    let frame = scene.frame_geometry(0)?;
    let sky = Environment::uniform(Vec3::ONE);
    let two_level = Hierarchy::default();
    for (mask_resolution, lut_resolution, integration, hierarchy) in [
        (MaskResolution::R16, 64, Integration::ShBlocks, two_level),
        (MaskResolution::R32, 128, Integration::ShBlocks, two_level),
        (
            MaskResolution::R32,
            128,
            Integration::ShBlocks,
            Hierarchy::Flat,
        ),
        (MaskResolution::R32, 128, Integration::ShPixels, two_level),
        (MaskResolution::R64, 256, Integration::ShBlocks, two_level),
    ] {
        let mut method = HemiRaster::new(Config {
            mask_resolution,
            lut_resolution,
            integration,
            hierarchy,
            ..Config::default()
        });
        let start = Instant::now();
        method.prepare(&scene)?;
        let prepare = start.elapsed();
        let levels = match method.coarse_triangle_count(0) {
            Some(coarse) => format!("two-level ({coarse} coarse triangles)"),
            None => "flat".to_string(),
        };
        let updates = (0..5)
            .map(|_| {
                let start = Instant::now();
                method
                    .update(&frame, scene.camera())
                    .map(|()| start.elapsed())
            })
            .collect::<Result<Vec<_>>>()?;
        let start = Instant::now();
        method.relight(&sky)?;
        let relight = start.elapsed();
        let start = Instant::now();
        let shaded = method.shade(scene.camera().eye)?;
        let shade = start.elapsed();
        let mean = shaded.flat().map(|l| l.x).sum::<f32>() / shaded.radiance[0].len() as f32;
        println!(
            "{mask_resolution:?} LUT {lut_resolution} {integration:?} {levels}: prepare {prepare:?} (LUT build {:?}), update {:?} (median of 5), relight {relight:?}, shade {shade:?}; mean radiance {mean:.3}",
            method.lut_build_time().unwrap_or_default(),
            median(updates),
        );
    }
    Ok(())
}
