//! Where each light direction's depth map looks from (§3.2: orthographic,
//! fitted to the scene's bounding sphere; here to each [`Regions`]'s
//! sphere) and where it sits in the atlas the maps of a batch of directions
//! share.

use glam::{Mat4, Vec3, Vec4};
use shadow_core::Aabb;

use crate::lightsphere::Lightsphere;
use crate::visibility::TestOffset;

shadow_core::wgsl_struct! {
    /// One direction as the shaders read it.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct GpuDirection {
        /// World (or model) space to the clip space of the direction's map.
        pub clip_from_world: Mat4,
        /// Toward the light (xyz), and the side of one texel of the map in
        /// world units (w), which the tests' offsets are measured in (a
        /// direction's weight depends on the level shaded, and travels with
        /// the incoming radiance).
        pub light: Vec4,
    }
}

/// The orthographic view of a sphere (`centre`, `radius`) from direction
/// `light` (toward the light): x and y span the sphere's disc, depth runs
/// from 0 at `reach` toward the light from the centre to 1 on the sphere's
/// far side, so every point within `radius` of the centre, and every
/// occluder between it and the light within `reach`, is inside the view
/// volume (`reach` ≥ `radius`).
pub fn orthographic(light: Vec3, centre: Vec3, radius: f32, reach: f32) -> Mat4 {
    // Whether the map is mirrored does not matter: occluders are drawn
    // without culling, and every test maps points the same way.
    let (u, v) = light.any_orthonormal_pair();
    let inv = 1.0 / radius;
    let depth = 1.0 / (radius + reach);
    Mat4::from_cols(
        Vec4::new(u.x * inv, v.x * inv, -light.x * depth, 0.0),
        Vec4::new(u.y * inv, v.y * inv, -light.y * depth, 0.0),
        Vec4::new(u.z * inv, v.z * inv, -light.z * depth, 0.0),
        Vec4::new(
            -u.dot(centre) * inv,
            -v.dot(centre) * inv,
            (reach + light.dot(centre)) * depth,
            1.0,
        ),
    )
}

/// How many times the diameter of its smallest object a region's sphere
/// may span: at the default 512² maps every object keeps at least 32
/// texels across, wherever it stands and whatever else the scene holds.
pub const REGION_SPAN: f32 = 16.0;

/// At most this many regions: past it the two whose union is smallest are
/// merged (a scene of many small objects spread far apart).
pub const MAX_REGIONS: usize = 16;

/// The regions a frame's maps are fitted to: groups of objects whose
/// vertices are tested against one map per direction. The paper fits one
/// map to the whole scene (§3.2); then a small object on a large floor has
/// a few texels and loses its self-shadowing and its contact. Objects share
/// a region while its bounds span at most [`REGION_SPAN`] times the
/// diagonal of the smallest of them, so that the texel follows the size of
/// what is tested, never the scene's.
#[derive(Clone, Debug, PartialEq)]
pub struct Regions {
    /// Per object, its region.
    pub of_object: Vec<u32>,
    /// Per region, the sphere holding its objects' vertices.
    pub spheres: Vec<(Vec3, f32)>,
    /// The sphere holding every vertex: what the maps' depth must reach.
    pub scene: (Vec3, f32),
}

impl Regions {
    /// The regions of objects whose vertices are `objects` (world space).
    pub fn new(objects: &[&[Vec4]]) -> Regions {
        let bounds: Vec<Aabb> = objects
            .iter()
            .map(|p| Aabb::from_points(p.iter().map(|p| p.truncate())))
            .collect();
        // Largest first, so that small objects join the region of the large
        // one they stand on when it is small enough.
        let mut order: Vec<usize> = (0..objects.len()).collect();
        order.sort_by(|&a, &b| bounds[b].diagonal().total_cmp(&bounds[a].diagonal()));
        // (bounds, smallest member diagonal, members)
        let mut groups: Vec<(Aabb, f32, Vec<usize>)> = Vec::new();
        for o in order {
            let size = bounds[o].diagonal();
            let joins = groups.iter_mut().find(|(b, smallest, _)| {
                b.union(bounds[o]).diagonal() <= REGION_SPAN * smallest.min(size)
            });
            match joins {
                Some((b, smallest, members)) => {
                    *b = b.union(bounds[o]);
                    *smallest = smallest.min(size);
                    members.push(o);
                }
                None => groups.push((bounds[o], size, vec![o])),
            }
        }
        while groups.len() > MAX_REGIONS {
            let mut best = (0, 1, f32::INFINITY);
            for i in 0..groups.len() {
                for j in i + 1..groups.len() {
                    let d = groups[i].0.union(groups[j].0).diagonal();
                    if d < best.2 {
                        best = (i, j, d);
                    }
                }
            }
            let (b, smallest, members) = groups.swap_remove(best.1);
            let g = &mut groups[best.0];
            g.0 = g.0.union(b);
            g.1 = g.1.min(smallest);
            g.2.extend(members);
        }
        let mut of_object = vec![0; objects.len()];
        let spheres = (groups.iter().enumerate())
            .map(|(r, (_, _, members))| {
                for &o in members {
                    of_object[o] = r as u32;
                }
                let points: Vec<Vec4> = members.iter().flat_map(|&o| objects[o].to_vec()).collect();
                bounding_sphere(&points)
            })
            .collect();
        let all: Vec<Vec4> = objects.iter().flat_map(|p| p.to_vec()).collect();
        Regions {
            of_object,
            spheres,
            scene: bounding_sphere(&all),
        }
    }

    /// One region holding everything.
    pub fn whole(points: &[Vec4]) -> Regions {
        Regions::new(&[points])
    }
}

/// A sphere holding every point: the centre of their bounds, and the largest
/// distance from it.
pub fn bounding_sphere(positions: &[Vec4]) -> (Vec3, f32) {
    let points = positions.iter().map(|p| p.truncate());
    let bounds = Aabb::from_points(points.clone());
    let centre = bounds.center();
    let radius = points.map(|p| p.distance(centre)).fold(0.0f32, f32::max);
    (centre, radius.max(f32::MIN_POSITIVE))
}

/// Every region's view of every direction of `sphere`, region by region
/// (view `r · k + j` for direction j of region r, k = `sphere.len()`), for
/// `map`-sided maps: region r's sphere grown by a hundredth and by the
/// farthest that `offset` moves a tested vertex, so that moved vertices stay
/// inside the view volume (where the paper's queries are reliable), seen
/// from direction j, its depth reaching the scene's far side toward the
/// light; the texel the offsets are measured in travels with the light
/// ([`GpuDirection::light`]).
pub fn views(
    sphere: &Lightsphere,
    regions: &Regions,
    map: u32,
    offset: &TestOffset,
) -> Vec<GpuDirection> {
    let (scene_centre, scene_radius) = regions.scene;
    regions
        .spheres
        .iter()
        .flat_map(|&(centre, radius)| {
            let inner = radius * 1.01;
            let texel = 2.0 * inner / map as f32;
            let outer = inner + offset.reach(texel);
            sphere.directions().iter().map(move |&light| {
                // Occluders stand anywhere in the scene's sphere.
                let reach = (light.dot(scene_centre - centre) + scene_radius).max(outer);
                GpuDirection {
                    clip_from_world: orthographic(light, centre, outer, reach),
                    light: light.extend(texel),
                }
            })
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
            let m = orthographic(light, centre, 2.0, 2.0);
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

    fn cube(centre: Vec3, half: f32) -> Vec<Vec4> {
        [-1.0, 1.0]
            .into_iter()
            .flat_map(|x| [-1.0, 1.0].map(move |y| (x, y)))
            .flat_map(|(x, y)| [-1.0, 1.0].map(move |z| Vec3::new(x, y, z)))
            .map(|c| (centre + c * half).extend(1.0))
            .collect()
    }

    /// Objects of like size share one region (chess pieces on their board);
    /// a small object on a floor 200 times its size gets its own, and the
    /// regions do not change when the scene moves or grows.
    #[test]
    fn regions_keep_every_object_at_its_own_scale() {
        let board = cube(Vec3::ZERO, 0.2);
        let pieces: Vec<Vec<Vec4>> = (0..8)
            .map(|i| cube(Vec3::new(-0.15 + 0.04 * i as f32, 0.22, 0.1), 0.02))
            .collect();
        let mut objects: Vec<&[Vec4]> = vec![&board];
        objects.extend(pieces.iter().map(|p| p.as_slice()));
        let chess = Regions::new(&objects);
        assert_eq!(chess.spheres.len(), 1);
        assert!(chess.of_object.iter().all(|&r| r == 0));
        let floor = cube(Vec3::ZERO, 100.0);
        let model = cube(Vec3::new(0.0, 100.5, 0.0), 0.5);
        let scene = Regions::new(&[&floor, &model]);
        assert_eq!(scene.spheres.len(), 2);
        assert_ne!(scene.of_object[0], scene.of_object[1]);
        let model_sphere = scene.spheres[scene.of_object[1] as usize];
        assert!(model_sphere.1 < 1.0, "{model_sphere:?}");
        // Moved 10 km and scaled by 10⁷: the same grouping.
        let moved = |p: &[Vec4], by: Vec3, scale: f32| -> Vec<Vec4> {
            p.iter()
                .map(|v| (v.truncate() * scale + by).extend(1.0))
                .collect()
        };
        for (by, scale) in [(Vec3::new(6e3, 0.0, -8e3), 1.0), (Vec3::ZERO, 1e7)] {
            let (f, m) = (moved(&floor, by, scale), moved(&model, by, scale));
            assert_eq!(Regions::new(&[&f, &m]).of_object, scene.of_object);
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
