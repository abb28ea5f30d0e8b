//! Where each light direction's depth map looks from (§3.2: orthographic,
//! fitted to the scene's bounding sphere) and where it sits in the atlas the
//! maps of a batch of directions share.

use glam::{Mat4, Vec3, Vec4};

use crate::lightsphere::Lightsphere;

shadow_core::wgsl_struct! {
    /// One direction as the shaders read it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct GpuDirection {
        /// World (or model) space to the clip space of the direction's map.
        pub clip_from_world: Mat4,
        /// Toward the light (xyz); w is padding (a direction's weight depends
        /// on the level shaded, and travels with the incoming radiance).
        pub light: Vec4,
    }
}

/// The orthographic view of a sphere (`centre`, `radius`) from direction
/// `light` (toward the light): x and y span the sphere's disc, depth runs
/// from 0 on the light's side of the sphere to 1 on the far side, so every
/// point within `radius` of the centre is inside the view volume.
pub fn orthographic(light: Vec3, centre: Vec3, radius: f32) -> Mat4 {
    // Whether the map is mirrored does not matter: occluders are drawn
    // without culling, and every test maps points the same way.
    let (u, v) = light.any_orthonormal_pair();
    let inv = 1.0 / radius;
    Mat4::from_cols(
        Vec4::new(u.x * inv, v.x * inv, -light.x * 0.5 * inv, 0.0),
        Vec4::new(u.y * inv, v.y * inv, -light.y * 0.5 * inv, 0.0),
        Vec4::new(u.z * inv, v.z * inv, -light.z * 0.5 * inv, 0.0),
        Vec4::new(
            -u.dot(centre) * inv,
            -v.dot(centre) * inv,
            0.5 + light.dot(centre) * 0.5 * inv,
            1.0,
        ),
    )
}

/// Every direction of `sphere` viewing the sphere (`centre`, `radius`).
pub fn directions(sphere: &Lightsphere, centre: Vec3, radius: f32) -> Vec<GpuDirection> {
    sphere
        .directions()
        .iter()
        .map(|&light| GpuDirection {
            clip_from_world: orthographic(light, centre, radius),
            light: light.extend(0.0),
        })
        .collect()
}

/// How the depth maps of a batch of directions tile one square atlas:
/// `grid × grid` maps of `map × map` texels, row by row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Atlas {
    pub map: u32,
    pub grid: u32,
}

impl Atlas {
    /// The atlas for `directions` maps of side `map`, at most `max_side`
    /// texels wide (and at most 8192: a bigger atlas holds more of a batch
    /// but costs memory without saving passes that matter). When one atlas
    /// cannot hold them all, the batches are made even, so that no pass
    /// clears a whole atlas for a few maps.
    pub fn new(map: u32, directions: usize, max_side: u32) -> Atlas {
        let fits = (max_side.min(8192) / map).max(1) as usize;
        let batches = directions.div_ceil(fits * fits).max(1);
        let per_batch = directions.div_ceil(batches);
        let wanted = (per_batch as f64).sqrt().ceil() as usize;
        Atlas {
            map,
            grid: wanted.clamp(1, fits) as u32,
        }
    }

    /// Maps per batch.
    pub fn batch(&self) -> usize {
        (self.grid * self.grid) as usize
    }

    /// Texels per side.
    pub fn side(&self) -> u32 {
        self.grid * self.map
    }

    /// The top-left texel of the map in slot `slot` of a batch.
    pub fn origin(&self, slot: usize) -> (u32, u32) {
        let slot = slot as u32;
        ((slot % self.grid) * self.map, (slot / self.grid) * self.map)
    }
}

/// The texel of a `map`-sided depth map a point at clip position `clip`
/// falls in: the rasterizer's pixel of a one-pixel point, row 0 at the top.
pub fn texel(clip: Vec4, map: u32) -> (u32, u32) {
    let size = map as f32;
    let x = ((clip.x * 0.5 + 0.5) * size).floor().clamp(0.0, size - 1.0);
    let y = ((0.5 - clip.y * 0.5) * size).floor().clamp(0.0, size - 1.0);
    (x as u32, y as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_sphere_fills_the_view_volume() {
        let centre = Vec3::new(1.0, -2.0, 0.5);
        for light in [
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::new(0.3, -0.4, 0.866).normalize(),
        ] {
            let m = orthographic(light, centre, 2.0);
            // Nearest to the light: depth 0; farthest: 1; centre: ½.
            assert_relative_eq!(
                (m * (centre + 2.0 * light).extend(1.0)).z,
                0.0,
                epsilon = 1e-6
            );
            assert_relative_eq!(
                (m * (centre - 2.0 * light).extend(1.0)).z,
                1.0,
                epsilon = 1e-6
            );
            let c = m * centre.extend(1.0);
            assert_relative_eq!(c.truncate(), Vec3::new(0.0, 0.0, 0.5), epsilon = 1e-6);
            // The disc's rim reaches the edge of NDC.
            let (u, v) = light.any_orthonormal_pair();
            for edge in [u, v] {
                let e = m * (centre + 2.0 * edge).extend(1.0);
                assert_relative_eq!(e.x.abs().max(e.y.abs()), 1.0, epsilon = 1e-6);
            }
        }
    }

    #[test]
    fn atlases_hold_a_batch_and_place_maps_row_by_row() {
        let a = Atlas::new(256, 258, 16384);
        assert_eq!((a.grid, a.batch(), a.side()), (17, 289, 4352));
        assert_eq!(a.origin(18), (256, 256));
        // 4098 maps in five even batches of at most 820, not 4 × 1024 + 2.
        let big = Atlas::new(256, 4098, 16384);
        assert_eq!((big.grid, big.batch()), (29, 841));
        let two = Atlas::new(512, 258, 16384);
        assert_eq!((two.grid, two.batch()), (12, 144));
        assert_eq!(Atlas::new(4096, 6, 4096).grid, 1);
        assert_eq!(texel(Vec4::new(-1.0, 1.0, 0.5, 1.0), 8), (0, 0));
        assert_eq!(texel(Vec4::new(1.0, -1.0, 0.5, 1.0), 8), (7, 7));
        assert_eq!(texel(Vec4::new(0.01, 0.01, 0.5, 1.0), 8), (4, 3));
    }
}
