use super::*;
use crate::config::Grouping;
use crate::groups::Groups;
use crate::lights::AreaLight;
use glam::Mat4;
use shadow_core::{Aabb, Brdf, Mesh, gpu::test_context, shapes};

/// Where a continuous profile sampled at `values[k]` (k = 0, 1, ...)
/// falling from 1 to 0 crosses `level`, by linear interpolation.
fn crossing(values: &[f32], level: f32) -> f32 {
    let k = values
        .windows(2)
        .position(|w| w[0] >= level && w[1] < level)
        .expect("the profile crosses the level");
    k as f32 + (values[k] - level) / (values[k] - values[k + 1])
}

/// A half-plane's occlusion map (§4.2.2): a 2 × 2 sheet at height D = 1
/// over a 4 × 4 floor, under a light straight above of Ω = 0.25 sr, its
/// edges along the light's plane axes (u, v). Across an edge the blurred
/// map falls from 1 to 0 linearly over the box's side s = √Ω · D = 0.5
/// (eq. 5–6, D between the planes through the sheet's and the floor's
/// centres), in the row pass (across u) as in the column pass (across
/// v), centred on the edge.
#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn the_blur_ramp_across_a_sheet_edge_is_s_wide() {
    let ctx = test_context();
    let (omega, height, n) = (0.25f32, 1.0f32, 64);
    let light = GpuLight::new(&AreaLight {
        direction: Vec3::Y,
        radiosity: Vec3::ONE,
        solid_angle: omega,
    });
    let (u, v) = (light.u.truncate(), light.v.truncate());
    // The sheet covers u ∈ [−2, 0], v ∈ [−1, 1].
    let sheet = shapes::grid(
        "sheet",
        height * Vec3::Y - 2.0 * u - v,
        2.0 * u,
        2.0 * v,
        1,
        1,
    )
    .unwrap();
    let floor = shapes::floor("floor", Vec3::ZERO, 2.0, 1).unwrap();
    let meshes = [floor, sheet];
    let bounds: Vec<Aabb> = meshes.iter().map(Mesh::bounds).collect();
    let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &bounds).unwrap();
    let plan = Plan::new(&[light], &bounds, &groups, n);
    assert_eq!(plan.maps.len(), 1, "the sheet onto the floor");
    let map = plan.maps[0];
    let s = omega.sqrt() * height;

    let geometry = Geometry::new(&meshes);
    let white = Brdf::lambert(Vec3::ONE).unwrap();
    let objects: Vec<GpuObject> = groups
        .of_object
        .iter()
        .map(|&g| GpuObject::new(Mat4::IDENTITY, &white, g))
        .collect();
    let mut gpu = Gpu::new(Arc::clone(&ctx), &geometry, &objects, n, true).unwrap();
    gpu.set_lights(&[light]).unwrap();
    let positions: Vec<Vec3> = meshes
        .iter()
        .flat_map(|m| m.positions().iter().copied())
        .collect();
    let masks = plan.masks(&[light], &positions, &geometry.triangles, &groups.of_object);
    gpu.set_plan(&plan, &masks, &groups.of_object, &[None])
        .unwrap();
    ctx.run("test: occlusion map", |encoder| gpu.record_maps(encoder))
        .unwrap();
    let blurred: Vec<f32> = ctx
        .read_buffer(gpu.maps.blurred.buffer(), 0, (n * n) as usize)
        .unwrap();

    // Texel k's centre along either axis, in the light's plane.
    let texel = 1.0 / (map.inverse_side * n as f32);
    let at = |k: f32, centre: f32| centre + (k + 0.5 - 0.5 * n as f32) * texel;
    let middle = |centre: f32| ((0.5 * n as f32 - 0.5) - centre / texel).round() as usize;
    // Across u along the row through v = 0, then across v along the
    // column through u = −1 (rows go along +v).
    let row = middle(map.centre.y);
    let across_u: Vec<f32> = blurred[row * n as usize..(row + 1) * n as usize].to_vec();
    let column = middle(map.centre.x + 1.0);
    let across_v: Vec<f32> = (0..n as usize)
        .map(|r| blurred[r * n as usize + column])
        .collect();
    for (profile, centre, edge) in [
        (&across_u, map.centre.x, 0.0),
        (&across_v, map.centre.y, 1.0),
    ] {
        // From the inside (1) out: past the ramp's ends, then the ramp.
        let start = profile.iter().position(|&o| o > 0.999).unwrap();
        let falling = &profile[start..];
        let (high, low) = (crossing(falling, 0.75), crossing(falling, 0.25));
        let width = (low - high) / 0.5 * texel;
        let half_way = at(start as f32 + crossing(falling, 0.5), centre);
        println!(
            "ramp {width} wide (s = {s}, off by {:e}), half-way at {half_way} (edge {edge}, texel {texel})",
            width - s
        );
        // Measured: the width is s to f32 rounding (off by 0) on both
        // axes (the box blur integrates the texels exactly); half-way at
        // −0.012 and 0.988, 0.23 texel from the edges (the coverage's
        // step lies on a texel boundary).
        assert!((width - s).abs() < 1e-3 * s, "ramp {width}, s = {s}");
        assert!(
            (half_way - edge).abs() <= 0.5 * texel,
            "half-way at {half_way}"
        );
    }
}

/// 4,800 maps of 256² at q = 256, 1.26 GB: more than the 128 MiB a
/// storage binding of lavapipe (and of WebGPU's defaults) holds.
/// Refused naming the settings, the bytes and the limit; 597 maps of
/// 64² at q = 32 fit. So do masks until q × triangles words pass the
/// limit.
#[test]
fn plans_beyond_a_storage_binding_are_refused_by_name() {
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 128 << 20,
        max_buffer_size: (1 << 31) - 1,
        ..wgpu::Limits::default()
    };
    let refused = check_storage(256, 256, 4800, 2 * 256 * 3, 20_000, &limits);
    let Err(Error::InvalidConfig { what, .. }) = refused else {
        panic!("{refused:?}")
    };
    for named in [
        "q = 256",
        "256×256",
        "4800 maps",
        "1258291200 bytes",
        "134217728 bytes",
    ] {
        assert!(what.contains(named), "{named:?} not in {what:?}");
    }
    check_storage(32, 64, 597, 2 * 32 * 3, 20_000, &limits).unwrap();
    let masks = check_storage(256, 32, 10, 0, 150_000, &limits);
    let Err(Error::InvalidConfig { what, .. }) = masks else {
        panic!("{masks:?}")
    };
    assert!(
        what.contains("q = 256") && what.contains("150000 triangles"),
        "{what}"
    );
}
