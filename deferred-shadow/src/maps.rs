//! Which occlusion maps a frame needs, where each lies and how far its
//! occluder stands from its receiver, planned on the CPU; the GPU renders
//! and filters them (`gpu/map_pass.rs`).
//!
//! For light i, occluder group A and receiver B, A's shadow is projected
//! along ω_i onto a plane perpendicular to it, and a point p of B reads it
//! at (p·u_i, p·v_i): the orthogonal projection of §6.2.2, in the light's
//! frame (u_i, v_i, ω_i). Receivers are groups too (§4.2.3): the two
//! colours of a board share their maps.
//!
//! Where this departs from §4.2.2: the paper blurs a whole map by one box
//! of side s = √Ω_i · D, D = (c_A − c_B)·ω_i the distance between the planes
//! through the groups' centres. That is wrong wherever the shadow does not
//! fall at the receiver's centre plane: a piece's foot on the board (D from
//! the piece's middle), a piece at the corner of a large board under a
//! slanted light (D off by the corner's offset along ω_i). Here each texel
//! keeps its occluder's height along ω_i, and the receiver's height on
//! that texel's line is the light-facing side of B's bounding box; the map
//! is then filtered as percentage-closer soft shadows prefiltered on a
//! summed-area table: per texel, the mean height of the occluders within
//! the widest penumbra gives the distance d and the box's side
//! s = √Ω_i · d (a blend of the two odd integer boxes around s, half the
//! table loads of a box with fractional corners; texels whose widest box
//! is empty or all covered skip it). The paper's fixed D is the case of a
//! flat occluder over a receiver plane through B's centre. Occluder texels
//! behind the receiver's surface (the board under a piece, as seen from a
//! low light above) cast nothing.
//!
//! The height kept is that of the occluder's surface farthest from the
//! light, not the nearest as a shadow map keeps: over a receiver under an
//! overhang (the floor under the bunny's belly) the nearest surface is the
//! occluder's top, and the blocker search would blur the shadow as if cast
//! from there; on a convex occluder both meet at the silhouette, where the
//! penumbra is.
//!
//! The paper sizes a map to its receiver. Here a map covers the smaller of
//! two squares: the receiver's projected bounding sphere widened by half
//! the widest box, or the occluder's, outside which the filtered shadow is
//! zero. A small piece over a large board then gets its texels where its
//! shadow falls instead of spreading them over the whole board; points
//! outside the window read zero.
//!
//! A pair gets a map only where the occluder stands in front of the
//! receiver (toward the light): judged on the line along ω_i through the
//! occluder's centre where it meets B's box, else on the line through B's
//! centre where it meets A's, else by the centres as the paper's planes
//! (D > 0). A floor under an object, lit from above, casts nothing on it,
//! and a sheet at the side of a floor shades the floor also where the
//! floor's centre lies nearer a slanted light than the sheet's (the
//! paper's planes drop that shadow). Pairs whose filtered shadow cannot
//! reach the receiver are skipped.

use glam::{Vec2, Vec3, Vec4};
use shadow_core::Aabb;

use crate::groups::Groups;
use crate::lights::AreaLight;

shadow_core::wgsl_struct! {
    /// An area light W_i (§4.2.1) as the shaders read it: direction ω_i (w:
    /// the extent its light comes from, [`AreaLight::extent`], which sets
    /// the blur), radiosity B_i, and the axes (u, v) of planes
    /// perpendicular to ω_i.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct GpuLight {
        pub direction: Vec4,
        pub radiosity: Vec4,
        pub u: Vec4,
        pub v: Vec4,
    }
}

impl GpuLight {
    pub fn new(light: &AreaLight) -> GpuLight {
        let (u, v) = light.direction.any_orthonormal_pair();
        GpuLight {
            direction: light.direction.extend(light.extent),
            radiosity: light.radiosity.extend(0.0),
            u: u.extend(0.0),
            v: v.extend(0.0),
        }
    }

    fn omega(&self) -> Vec3 {
        self.direction.truncate()
    }
}

shadow_core::wgsl_struct! {
    /// One occlusion map as the shaders read it: its window in the light's
    /// plane, how the light's size turns distance into blur, which light,
    /// occluder group and receiver it is for, and the heights (x·ω_i) the
    /// filter compares.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct MapWindow {
        /// The window's centre in the light's plane, (p·u, p·v).
        pub centre: Vec2,
        /// 1 / the window's side, world units.
        pub inverse_side: f32,
        /// The box's side per unit of occluder distance, texels: √Ω_i times
        /// the texels per world unit.
        pub spread: f32,
        pub light: u32,
        /// The occluder group.
        pub occluder: u32,
        /// The receiving group.
        pub receiver: u32,
        /// Where the map is drawn: its tile in its batch of the atlas (set by
        /// the GPU side for the maps it draws).
        pub tile: u32,
        /// The receiving group's bounding box: its light-facing side is the
        /// receiver's height on each texel's line ([`receiver_height`]).
        pub receiver_min: Vec4,
        pub receiver_max: Vec4,
        /// The occluder group's heights lie in [near, far] (its bounding
        /// sphere's, padded): the range the map's depth is rendered over.
        pub near: f32,
        pub far: f32,
        /// Texels per side ([`resolution`]).
        pub resolution: u32,
        /// Its first texel in the array of maps, which lie one after
        /// another, row by row.
        pub offset: u32,
    }
}

impl MapWindow {
    pub fn texels(&self) -> u32 {
        self.resolution * self.resolution
    }

    /// A texel's side, world units.
    pub fn texel(&self) -> f32 {
        1.0 / (self.inverse_side * self.resolution as f32)
    }
}

/// Where the line {o + t ω} last leaves the box [min, max] toward the
/// light: the least over the axes of the larger slab bound (an axis along
/// which the line does not move bounds nothing). Concave in o and
/// continuous, also past the box's silhouette, where it extends the
/// box's light-facing side; maps.wgsl's `receiver_height` is the same.
pub fn receiver_height(o: Vec3, omega: Vec3, min: Vec3, max: Vec3) -> f32 {
    crossing(o, omega, min, max).1
}

/// The heights (t) where the line {o + t ω} enters and leaves the box
/// [min, max]: it meets the box where entry ≤ exit.
fn crossing(o: Vec3, omega: Vec3, min: Vec3, max: Vec3) -> (f32, f32) {
    let (mut entry, mut exit) = (f32::NEG_INFINITY, f32::INFINITY);
    for k in 0..3 {
        if omega[k].abs() > AXIS_EPSILON {
            let (a, b) = ((min[k] - o[k]) / omega[k], (max[k] - o[k]) / omega[k]);
            entry = entry.max(a.min(b));
            exit = exit.min(a.max(b));
        } else if o[k] < min[k] || o[k] > max[k] {
            entry = f32::INFINITY;
        }
    }
    (entry, exit)
}

/// How far `point` stands in front of (toward the light from) the
/// light-facing side of `other` on the line through it along ω, where
/// that line meets `other`.
fn in_front(point: Vec3, other: &Aabb, omega: Vec3) -> Option<f32> {
    let height = point.dot(omega);
    let (entry, exit) = crossing(point - height * omega, omega, other.min, other.max);
    (entry <= exit).then_some(height - exit)
}

/// The least height x·ω over the box's corners.
fn lowest_corner(b: &Aabb, omega: Vec3) -> f32 {
    (b.min * omega).min(b.max * omega).element_sum()
}

/// Heights closer than this fraction of a map's depth range [near, far]
/// are in contact, whatever their rounding, and contact occludes: in the
/// plan's choice of pairs as in maps.wgsl's per-texel test.
pub const TIE: f32 = 1e-4;

/// Light direction components below this count as zero in
/// [`receiver_height`].
pub const AXIS_EPSILON: f32 = 1e-6;

/// Every map of a frame, sorted by receiving group and then light, with the
/// range of maps each (receiver, light) reads.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    pub maps: Vec<MapWindow>,
    /// `[first, count]` of receiving group b and light i at `b * q + i`.
    pub ranges: Vec<[u32; 2]>,
}

impl Plan {
    /// Texels of all its maps.
    pub fn texels(&self) -> u64 {
        self.maps.iter().map(|m| u64::from(m.texels())).sum()
    }
}

impl Plan {
    /// Per triangle and light, which maps of its receiving group's range
    /// its projection along the light touches: bit j for the range's j-th
    /// map, bit 31 for the 32nd and later. `positions` are world-space
    /// vertices, `triangles` their corners and object, `groups[o]` the group
    /// of object o. The deferred pass reads only the maps a pixel's
    /// triangle touches.
    pub fn masks(
        &self,
        lights: &[GpuLight],
        positions: &[Vec3],
        triangles: &[[u32; 4]],
        groups: &[u32],
    ) -> Vec<u32> {
        use rayon::prelude::*;
        let q = lights.len();
        let mut masks = vec![0u32; triangles.len() * q];
        masks.par_chunks_mut(q).zip(triangles).for_each(|(out, t)| {
            let corners = [t[0], t[1], t[2]].map(|v| positions[v as usize]);
            let receiver = groups[t[3] as usize] as usize;
            for (i, (mask, light)) in out.iter_mut().zip(lights).enumerate() {
                let [first, count] = self.ranges[receiver * q + i];
                if count == 0 {
                    continue;
                }
                let (u, v) = (light.u.truncate(), light.v.truncate());
                let projected = corners.map(|c| Vec2::new(c.dot(u), c.dot(v)));
                let lo = projected[0].min(projected[1]).min(projected[2]);
                let hi = projected[0].max(projected[1]).max(projected[2]);
                for j in 0..count {
                    let m = &self.maps[(first + j) as usize];
                    let half = 0.5 / m.inverse_side;
                    if lo.cmple(m.centre + half).all() && hi.cmpge(m.centre - half).all() {
                        *mask |= 1 << j.min(31);
                    }
                }
            }
        });
        masks
    }

    /// For each map, where the same map lies in `previous`'s array of maps
    /// (its first texel) when it can be kept: same receiver, light,
    /// occluder and resolution, neither group moved (`moved[g]`) and the
    /// lights did not change since `previous`.
    pub fn reuse(&self, previous: &Plan, moved: &[bool]) -> Vec<Option<u32>> {
        let key = |m: &MapWindow| (m.receiver, m.light, m.occluder, m.resolution);
        let old: std::collections::HashMap<_, u32> =
            previous.maps.iter().map(|m| (key(m), m.offset)).collect();
        self.maps
            .iter()
            .map(|m| {
                let still = !moved[m.receiver as usize] && !moved[m.occluder as usize];
                old.get(&key(m)).copied().filter(|_| still)
            })
            .collect()
    }
}

/// A bounding sphere from a box: its centre and half its diagonal.
fn sphere(b: &Aabb) -> (Vec3, f32) {
    (b.center(), 0.5 * b.diagonal())
}

/// Texels across the penumbra an occluder casts at its own radius from
/// where it stands: the least a map gets (see [`resolution`]). Measured
/// per pixel (`bunny` 128 wide, q = 16 / 32 / 64 at 64² at most; `chess`
/// 512 wide, six frames): 8 gave 4.31 / 3.74 / 3.43% and 3.88–4.09%
/// against 4.53 / 3.76 / 3.46% and 3.88–4.09% with every map at 64², 4
/// gave 5.07 / 3.97 / 3.49% and 3.91–4.14%.
pub const PENUMBRA_TEXELS: f32 = 8.0;

/// Where the paper gives every map of a frame one resolution (§7 compares
/// 32², 64² and 128²), here a map has the fewest texels, at most `largest`, that give the
/// penumbra its occluder casts at the occluder's radius r (√E_i · r, the
/// light's extent E_i) [`PENUMBRA_TEXELS`] texels across its window of
/// side `window`: sharper shadow within that distance of a contact is
/// resolved to `window / n`, wider ones to many texels. A sun gets the
/// largest maps, a wide cell of sky a fraction of the texels. At least 4
/// texels, and all `largest` where the light is a point.
pub fn resolution(largest: u32, window: f32, root_extent: f32, occluder_radius: f32) -> u32 {
    let penumbra = root_extent * occluder_radius;
    let needed = PENUMBRA_TEXELS * window / penumbra;
    if needed.is_finite() {
        (needed.ceil() as u32).clamp(largest.min(4), largest)
    } else {
        largest
    }
}

/// The occluder's depth range is its sphere's, widened by this fraction of
/// the radius, so that rounding never clips a vertex.
const DEPTH_PADDING: f32 = 1e-3;

/// And by this many units in the last place of the height it stands at:
/// the rounding of coordinates far from the origin. Neither term is
/// absolute, nor grows with the distance beyond the rounding, so the same
/// plan moved 10 km gives the same maps.
const DEPTH_ROUNDING: f32 = 4.0 * f32::EPSILON;

impl Plan {
    /// The maps between the groups of objects with bounds `objects` under
    /// `lights`, at most `largest` texels a side (`resolution`).
    pub fn new(lights: &[GpuLight], objects: &[Aabb], groups: &Groups, largest: u32) -> Plan {
        let q = lights.len();
        let boxes: Vec<Aabb> = groups
            .members
            .iter()
            .map(|m| m.iter().map(|&o| objects[o]).fold(Aabb::EMPTY, Aabb::union))
            .collect();
        let spheres: Vec<(Vec3, f32)> = boxes.iter().map(sphere).collect();
        let mut plan = Plan {
            maps: Vec::new(),
            ranges: vec![[0, 0]; groups.len() * q],
        };
        let mut texels = 0u32;
        for (b, (&(centre, radius), receiver)) in spheres.iter().zip(&boxes).enumerate() {
            for (i, light) in lights.iter().enumerate() {
                let first = plan.maps.len() as u32;
                let omega = light.omega();
                let (u, v) = (light.u.truncate(), light.v.truncate());
                let root = light.direction.w.sqrt();
                for (a, &(occluder, occluder_radius)) in spheres.iter().enumerate() {
                    if a == b {
                        continue;
                    }
                    let offset = occluder - centre;
                    let height = occluder.dot(omega);
                    let pad = DEPTH_PADDING * occluder_radius + DEPTH_ROUNDING * height.abs();
                    let (near, far) = (
                        height - occluder_radius - pad,
                        height + occluder_radius + pad,
                    );
                    // The pair casts where the occluder stands in front of
                    // the receiver: judged on the line through the
                    // occluder's centre where it meets the receiver's box (a
                    // sheet at the side of a floor, wherever the floor's
                    // centre lies), else on the line through the receiver's
                    // centre (a floor under an object, lit from above: the
                    // object stands in front), else by the centres as the
                    // paper's planes do. A tie (a floor under a post's
                    // bottom face, lit from below) casts.
                    let tie = TIE * (far - near);
                    let casts = match (
                        in_front(occluder, receiver, omega),
                        in_front(centre, &boxes[a], omega),
                    ) {
                        (Some(d), _) => d >= -tie,
                        (None, Some(d)) => d <= tie,
                        (None, None) => offset.dot(omega) > 0.0,
                    };
                    if !casts {
                        continue;
                    }
                    // The widest box: from the occluder's top to the lowest
                    // receiver height under its footprint, a square in the
                    // light's plane whose corners bound the concave height;
                    // no receiver point lies below the box's lowest corner.
                    let lowest = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)]
                        .map(|(x, y)| {
                            let o = occluder + occluder_radius * (x * u + y * v);
                            receiver_height(
                                o - o.dot(omega) * omega,
                                omega,
                                receiver.min,
                                receiver.max,
                            )
                        })
                        .into_iter()
                        .fold(f32::INFINITY, f32::min)
                        .max(lowest_corner(receiver, omega));
                    let side = root * (far - lowest).max(0.0);
                    let apart = (offset - offset.dot(omega) * omega).length();
                    // A receiver point reads the occluder's footprint (a disc)
                    // through a square of half-side s/2: at most s/√2 away.
                    if apart > occluder_radius + radius + std::f32::consts::FRAC_1_SQRT_2 * side {
                        continue;
                    }
                    let (middle, half) = if occluder_radius < radius {
                        (occluder, occluder_radius + 0.5 * side)
                    } else {
                        (centre, radius + 0.5 * side)
                    };
                    let n = resolution(largest, 2.0 * half, root, occluder_radius);
                    plan.maps.push(MapWindow {
                        centre: Vec2::new(middle.dot(u), middle.dot(v)),
                        inverse_side: 1.0 / (2.0 * half),
                        spread: root * n as f32 / (2.0 * half),
                        light: i as u32,
                        occluder: a as u32,
                        receiver: b as u32,
                        tile: 0,
                        receiver_min: receiver.min.extend(0.0),
                        receiver_max: receiver.max.extend(0.0),
                        near,
                        far,
                        resolution: n,
                        offset: texels,
                    });
                    texels = texels.saturating_add(n * n);
                }
                plan.ranges[b * q + i] = [first, plan.maps.len() as u32 - first];
            }
        }
        plan
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Grouping;

    fn cube(centre: Vec3, half: f32) -> Aabb {
        Aabb {
            min: centre - half,
            max: centre + half,
        }
    }

    fn light(direction: Vec3, solid_angle: f32) -> GpuLight {
        GpuLight::new(&AreaLight {
            direction: direction.normalize(),
            radiosity: Vec3::ONE,
            solid_angle,
            extent: solid_angle,
        })
    }

    #[test]
    fn a_ball_above_a_floor_shades_it_from_above_only() {
        let floor = Aabb {
            min: Vec3::new(-1.0, 0.0, -1.0),
            max: Vec3::new(1.0, 0.0, 1.0),
        };
        let ball = cube(Vec3::new(0.0, 0.5, 0.0), 0.2);
        let objects = [floor, ball];
        let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &objects).unwrap();
        let lights = [light(Vec3::Y, 0.1), light(-Vec3::Y, 0.1)];
        let plan = Plan::new(&lights, &objects, &groups, 64);
        // The floor receives the ball's shadow from above; the ball receives
        // the floor's from below.
        assert_eq!(plan.ranges, vec![[0, 1], [1, 0], [1, 0], [1, 1]]);
        let map = plan.maps[0];
        assert_eq!((map.light, map.occluder, map.receiver), (0, 1, 0));
        // The widest box: s = √Ω · d, d from the ball's top (its sphere's,
        // radius 0.2√3, padded) down to the floor; the window is the ball's
        // sphere (smaller than the floor's) widened by s/2 each side.
        let radius = 0.2 * 3.0f32.sqrt();
        approx::assert_relative_eq!(map.far, 0.5 + radius, epsilon = 2e-3);
        approx::assert_relative_eq!(map.near, 0.5 - radius, epsilon = 2e-3);
        let s = 0.1f32.sqrt() * map.far;
        let side = 2.0 * radius + s;
        approx::assert_relative_eq!(map.inverse_side, 1.0 / side, max_relative = 1e-5);
        // Its penumbra at the ball's radius, √0.1 · r, would span 8
        // texels in 71: it gets the 64 allowed.
        let window = 1.0 / map.inverse_side;
        assert_eq!(map.resolution, 64);
        assert_eq!(resolution(128, window, 0.1f32.sqrt(), radius), 71);
        let n = map.resolution as f32;
        approx::assert_relative_eq!(map.spread, 0.1f32.sqrt() / side * n, max_relative = 1e-5);
        assert_eq!(map.receiver_min.truncate(), floor.min);
        assert_eq!(map.receiver_max.truncate(), floor.max);
        let ball = Vec3::new(0.0, 0.5, 0.0);
        let at = Vec2::new(
            ball.dot(lights[0].u.truncate()),
            ball.dot(lights[0].v.truncate()),
        );
        approx::assert_relative_eq!(map.centre, at, epsilon = 1e-6);
        // The ball's window under the floor's shadow is the ball's own.
        let below = plan.maps[1];
        assert_eq!((below.light, below.occluder, below.receiver), (1, 0, 1));
    }

    /// A map gets the fewest texels that give its occluder's penumbra (at
    /// the occluder's radius) 8 across its window: a sun or a point
    /// light all the texels allowed, a wide light few, never fewer than 4;
    /// the same at any size of the scene.
    #[test]
    fn a_map_has_the_texels_its_penumbra_needs() {
        // A 1 m ball's 1.5 m window under a light 0.1 sr wide: 38 texels.
        let n = resolution(64, 1.5, 0.1f32.sqrt(), 1.0);
        assert_eq!(n, 38);
        let penumbra_texels = |n: u32| 0.1f32.sqrt() * 1.0 / (1.5 / n as f32);
        assert!(penumbra_texels(n) >= PENUMBRA_TEXELS);
        assert!(penumbra_texels(n - 1) < PENUMBRA_TEXELS);
        assert_eq!(resolution(64, 1.5e3, 0.1f32.sqrt(), 1e3), n);
        assert_eq!(resolution(64, 1.5e-3, 0.1f32.sqrt(), 1e-3), n);
        // The sun (6.8·10⁻⁵ sr) and a point: all 64.
        assert_eq!(resolution(64, 1.5, 6.8e-5f32.sqrt(), 1.0), 64);
        assert_eq!(resolution(64, 1.5, 0.0, 1.0), 64);
        // Half the sky over a window twice the occluder's radius: 8 · 1 /
        // 3.5 would be 2 texels; 4, the least, or fewer where fewer are
        // allowed.
        assert_eq!(resolution(64, 1.0, 3.5, 1.0), 4);
        assert_eq!(resolution(2, 1.0, 3.5, 1.0), 2);
    }

    /// Which side of a pair is in front is decided where the occluder
    /// stands over the receiver, not between the groups' centres: a sheet
    /// at the floor's side, lit from the floor's centre at 45°, has its
    /// centre behind the floor's (D < 0, the paper's planes), and still
    /// shades the floor; the floor shades neither the sheet nor, from
    /// above, a box standing on it.
    #[test]
    fn a_sheet_off_the_floors_centre_shades_it_under_a_slanted_light() {
        let floor = Aabb {
            min: Vec3::new(-1.0, 0.0, -1.0),
            max: Vec3::new(1.0, 0.0, 1.0),
        };
        let sheet = Aabb {
            min: Vec3::new(0.1, 0.25, -0.4),
            max: Vec3::new(0.8, 0.252, 0.4),
        };
        let post = Aabb {
            min: Vec3::new(-0.6, 0.0, -0.1),
            max: Vec3::new(-0.4, 0.5, 0.1),
        };
        let objects = [floor, sheet, post];
        let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &objects).unwrap();
        let slanted = light(Vec3::new(-1.0, 1.0, 0.0), 0.1);
        assert!((sheet.center() - floor.center()).dot(slanted.omega()) < 0.0);
        let plan = Plan::new(&[slanted], &objects, &groups, 64);
        let pairs: Vec<(u32, u32)> = plan.maps.iter().map(|m| (m.occluder, m.receiver)).collect();
        assert!(pairs.contains(&(1, 0)), "{pairs:?}");
        assert!(
            !pairs.contains(&(0, 1)) && !pairs.contains(&(0, 2)),
            "{pairs:?}"
        );
    }

    /// The same plan moved far from the origin gives the same maps, within
    /// the rounding of f32 there (the padding's 4 units in the last place
    /// of the height and the ulp of near and far, 1.4 cm in all at 17 km of
    /// height, on windows 0.7 m deep; measured 1.35 cm): their depth windows were
    /// padded by 10⁻³ of the world height, 1.3× wider at 1 km under a 45°
    /// light and about 4× at 10 km.
    #[test]
    fn the_same_plan_translated_gives_the_same_maps() {
        let floor = Aabb {
            min: Vec3::new(-1.0, 0.0, -1.0),
            max: Vec3::new(1.0, 0.0, 1.0),
        };
        let ball = cube(Vec3::new(0.0, 0.5, 0.0), 0.2);
        let lights = [light(Vec3::new(1.0, 1.0, 0.0), 0.05), light(Vec3::Y, 0.2)];
        let plan_at = |t: Vec3| {
            let objects = [floor, ball].map(|b| Aabb {
                min: b.min + t,
                max: b.max + t,
            });
            let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &objects).unwrap();
            Plan::new(&lights, &objects, &groups, 64)
        };
        let here = plan_at(Vec3::ZERO);
        assert!(!here.maps.is_empty());
        for t in [
            Vec3::new(1e3, 1e3, 0.0),
            Vec3::new(6e3, 0.0, -8e3),
            Vec3::splat(1e4),
        ] {
            let there = plan_at(t);
            assert_eq!(here.ranges, there.ranges, "{t}");
            for (a, b) in here.maps.iter().zip(&there.maps) {
                approx::assert_relative_eq!(a.inverse_side, b.inverse_side, max_relative = 2e-2);
                approx::assert_relative_eq!(a.spread, b.spread, max_relative = 2e-2);
                approx::assert_relative_eq!(a.far - a.near, b.far - b.near, epsilon = 3e-2);
            }
        }
    }

    #[test]
    fn far_occluders_and_one_object_give_no_maps() {
        let a = cube(Vec3::ZERO, 0.1);
        let b = cube(Vec3::new(5.0, 1.0, 0.0), 0.1);
        let groups = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &[a, b]).unwrap();
        let plan = Plan::new(&[light(Vec3::Y, 0.01)], &[a, b], &groups, 64);
        assert!(plan.maps.is_empty());
        let alone = Groups::new(&Grouping::Overlapping { overlap: 0.5 }, &[a]).unwrap();
        let plan = Plan::new(&[light(Vec3::Y, 4.0)], &[a], &alone, 64);
        assert!(plan.maps.is_empty());
    }

    /// The light-facing side of a box, and its continuation past the
    /// silhouette: straight down onto a unit cube, the top; slanted, the
    /// face the line leaves by; beside the cube, the least slab exit.
    #[test]
    fn receiver_height_is_where_the_line_leaves_the_box() {
        let (min, max) = (Vec3::ZERO, Vec3::ONE);
        let up = Vec3::Y;
        assert_eq!(
            receiver_height(Vec3::new(0.5, -3.0, 0.5), up, min, max),
            4.0
        );
        // Along (1, 1, 0)/√2 from (0, 0, 0.5): leaves by x = 1 and y = 1
        // at t = √2.
        let slant = Vec3::new(1.0, 1.0, 0.0).normalize();
        let h = receiver_height(Vec3::new(0.0, 0.0, 0.5), slant, min, max);
        approx::assert_relative_eq!(h, 2f32.sqrt(), max_relative = 1e-6);
        // From (0.5, 0, 0.5) it leaves by x = 1 at t = 0.5√2 (y is 0.5).
        let h = receiver_height(Vec3::new(0.5, 0.0, 0.5), slant, min, max);
        approx::assert_relative_eq!(h, 0.5 * 2f32.sqrt(), max_relative = 1e-6);
        // z does not move along the line: z outside [0, 1] bounds nothing,
        // so the height continues the box's past its side.
        let beside = receiver_height(Vec3::new(0.5, 0.0, 2.0), slant, min, max);
        approx::assert_relative_eq!(beside, 0.5 * 2f32.sqrt(), max_relative = 1e-6);
    }
}
