//! Which occlusion maps a frame needs, where each lies and how much it is
//! blurred (§4.2.2, eq. 5–6), planned on the CPU; the GPU renders and blurs
//! them (`gpu/map_pass.rs`).
//!
//! For light i, occluder group A and receiver B, A's shadow is projected
//! along ω_i onto the plane H_B through B's centre, and a point p of B reads
//! it at (p·u_i, p·v_i): the orthogonal projection of §6.2.2, in the
//! light's frame (u_i, v_i, ω_i). The coverage is convolved with a box of
//! side s = √Ω_i · D, D = (c_A − c_B)·ω_i the distance from H_B to A's plane
//! H_A. Receivers are groups too (§4.2.3): the two colours of a board share
//! their maps.
//!
//! The paper sizes a map to its receiver. Here a map covers the smaller of
//! two squares: the receiver's projected bounding sphere widened by s/2, or
//! the occluder's widened by s/2, outside which the blurred shadow is zero.
//! A small piece over a large board then gets its texels where its shadow
//! falls instead of spreading them over the whole board; points outside the
//! window read zero.
//!
//! A pair whose occluder plane is not nearer the light than the receiver's
//! (D ≤ 0: the occluder lies behind the receiver, as seen from the light)
//! casts nothing: the plane approximation cannot say which part of B it
//! shades, and the common case is a floor under an object, which must not
//! darken the object for lights above. Pairs whose blurred shadow cannot
//! reach the receiver are skipped.

use glam::{Vec2, Vec3, Vec4};
use shadow_core::Aabb;

use crate::groups::Groups;
use crate::lights::AreaLight;

shadow_core::wgsl_struct! {
    /// An area light W_i (§4.2.1) as the shaders read it: direction ω_i (w:
    /// solid angle Ω_i), radiosity B_i, and the axes (u, v) of planes
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
            direction: light.direction.extend(light.solid_angle),
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
    /// plane, its blur, and which light, occluder group and receiver it is for.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct MapWindow {
        /// The window's centre in the light's plane, (p·u, p·v).
        pub centre: Vec2,
        /// 1 / the window's side, world units.
        pub inverse_side: f32,
        /// The box's side s, in texels.
        pub blur: f32,
        pub light: u32,
        /// The occluder group.
        pub occluder: u32,
        /// The receiving group.
        pub receiver: u32,
        /// Where the map is drawn: its tile in its batch of the atlas (set by
        /// the GPU side for the maps it draws).
        pub tile: u32,
    }
}

/// Every map of a frame, sorted by receiving group and then light, with the
/// range of maps each (receiver, light) reads.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    pub maps: Vec<MapWindow>,
    /// `[first, count]` of receiving group b and light i at `b * q + i`.
    pub ranges: Vec<[u32; 2]>,
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

    /// For each map, the index of the same map in `previous` when it can be
    /// kept: same receiver, light and occluder, neither group moved
    /// (`moved[g]`) and the lights did not change since `previous`.
    pub fn reuse(&self, previous: &Plan, moved: &[bool]) -> Vec<Option<u32>> {
        let key = |m: &MapWindow| (m.receiver, m.light, m.occluder);
        let old: std::collections::HashMap<_, u32> = previous
            .maps
            .iter()
            .enumerate()
            .map(|(k, m)| (key(m), k as u32))
            .collect();
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

impl Plan {
    /// The maps between the groups of objects with bounds `objects` under
    /// `lights`, at `resolution` texels a side.
    pub fn new(lights: &[GpuLight], objects: &[Aabb], groups: &Groups, resolution: u32) -> Plan {
        let q = lights.len();
        let spheres: Vec<(Vec3, f32)> = groups
            .members
            .iter()
            .map(|m| sphere(&m.iter().map(|&o| objects[o]).fold(Aabb::EMPTY, Aabb::union)))
            .collect();
        let mut plan = Plan {
            maps: Vec::new(),
            ranges: vec![[0, 0]; groups.len() * q],
        };
        for (b, &(centre, radius)) in spheres.iter().enumerate() {
            for (i, light) in lights.iter().enumerate() {
                let first = plan.maps.len() as u32;
                let omega = light.omega();
                let (u, v) = (light.u.truncate(), light.v.truncate());
                for (a, &(occluder, occluder_radius)) in spheres.iter().enumerate() {
                    if a == b {
                        continue;
                    }
                    let offset = occluder - centre;
                    let distance = offset.dot(omega);
                    if distance <= 0.0 {
                        continue;
                    }
                    let side = light.direction.w.sqrt() * distance;
                    let apart = (offset - distance * omega).length();
                    if apart > occluder_radius + radius + side {
                        continue;
                    }
                    let (middle, half) = if occluder_radius < radius {
                        (occluder, occluder_radius + 0.5 * side)
                    } else {
                        (centre, radius + 0.5 * side)
                    };
                    plan.maps.push(MapWindow {
                        centre: Vec2::new(middle.dot(u), middle.dot(v)),
                        inverse_side: 1.0 / (2.0 * half),
                        blur: side / (2.0 * half) * resolution as f32,
                        light: i as u32,
                        occluder: a as u32,
                        receiver: b as u32,
                        tile: 0,
                    });
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
        // s = √Ω · D with D = 0.5; the window is the ball's sphere (smaller
        // than the floor's) widened by s/2 each side, around the ball.
        let s = 0.1f32.sqrt() * 0.5;
        let side = 2.0 * 0.2 * 3.0f32.sqrt() + s;
        approx::assert_relative_eq!(map.inverse_side, 1.0 / side, max_relative = 1e-5);
        approx::assert_relative_eq!(map.blur, s / side * 64.0, max_relative = 1e-5);
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
}
