//! Receivers that see nothing at all, whatever the mask would say: those
//! pressed on another object's surface, and those buried inside another
//! closed object. The paper rasterizes blockers from every vertex alike;
//! both cases depart from it to give what the Monte-Carlo reference gives.
//!
//! - **Pressed**: a box's bottom face on the floor, the floor under it. The
//!   lifted receiver sits just behind the other surface, which then lies
//!   below its horizon or shows its back face, and the mask would see the
//!   sky. The test is the reference's own
//!   ([`SceneBvh::pressed`](shadow_core::bvh::SceneBvh::pressed)): each of
//!   the four [`press_probes`] crosses another object's triangle.
//! - **Buried**: a receiver inside another object whose back faces are
//!   culled (a closed mesh, [`crate::BackfaceCulling`]). Culling drops every
//!   face it sees, all of them back faces, and the receiver would be lit;
//!   every ray from it hits that object. The test is the parity of the
//!   crossings of three rays from the lifted receiver with that object's
//!   triangles, the majority of the three deciding (a ray through an edge
//!   counts twice, which one of three may do). Objects whose back faces are
//!   drawn need no test: the mask already sees all their faces.
//!
//! Both look only at objects whose box holds the receiver, and inside them
//! only at clusters of [`CLUSTER`] consecutive triangles whose box does.

use std::ops::Range;

use glam::Vec3;
use shadow_core::Aabb;
use shadow_core::frame::{PRESS_REACH, press_probes};
use shadow_core::triangle::ray_crossing;

use super::{Blockers, CLUSTER};

/// Per object of a frame, its box and its clusters' boxes, in the frame's
/// centred space: what the two tests search.
pub(crate) struct Enclosure {
    objects: Vec<Surface>,
}

struct Surface {
    bounds: Aabb,
    /// Whether its back faces are culled: only then can it bury a receiver.
    culled: bool,
    /// Consecutive runs of its triangles, each with its box.
    clusters: Vec<(Range<usize>, Aabb)>,
}

/// The directions of the parity rays: off the axes and off each other's
/// planes, so that no two run along the same mesh edges.
const RAYS: [Vec3; 3] = [
    Vec3::new(0.5377, 0.7063, 0.4604),
    Vec3::new(-0.6312, 0.2297, 0.7408),
    Vec3::new(0.1953, -0.8640, 0.4640),
];

impl Enclosure {
    pub(crate) fn new(blockers: &Blockers) -> Enclosure {
        let objects = (blockers.objects.iter())
            .map(|(range, culled)| {
                let clusters: Vec<(Range<usize>, Aabb)> = (range.clone())
                    .step_by(CLUSTER)
                    .map(|start| {
                        let run = start..(start + CLUSTER).min(range.end);
                        let corners = blockers.triangles[run.clone()].iter().flatten();
                        let bounds =
                            Aabb::from_points(corners.map(|&i| blockers.position(i as usize)));
                        (run, bounds)
                    })
                    .collect();
                let bounds = (clusters.iter()).fold(Aabb::EMPTY, |b, (_, c)| b.union(*c));
                Surface {
                    bounds,
                    culled: *culled,
                    clusters,
                }
            })
            .collect();
        Enclosure { objects }
    }

    /// Whether global vertex `v`'s receiver sees nothing: pressed on
    /// another object's surface, or buried in another closed object
    /// (module docs).
    pub(crate) fn encloses(&self, blockers: &Blockers, v: usize) -> bool {
        let own = blockers.object_of(v);
        let p = blockers.position(v);
        let (normal, lift) = blockers.surface(v);
        let reach = PRESS_REACH * lift;
        // The probes reach at most 2 lifts from the point.
        let near = |b: &Aabb| holds(b, p, 2.0 * lift);
        let others = || {
            (self.objects.iter().enumerate())
                .filter(move |&(o, s)| o != own && near(&s.bounds))
                .map(|(_, s)| s)
        };
        let probes = press_probes(p, normal, lift);
        let pressed = probes.iter().all(|&probe| {
            others().any(|s| {
                s.triangles(blockers, |b| holds(b, probe, reach))
                    .any(|t| ray_crossing(probe, normal, t).is_some_and(|d| d <= reach))
            })
        });
        if pressed {
            return true;
        }
        let origin = p + normal * lift;
        others()
            .filter(|s| s.culled && holds(&s.bounds, origin, 0.0))
            .any(|s| {
                let odd = RAYS.iter().filter(|&&dir| {
                    let crossings = s
                        .triangles(blockers, |b| reaches(b, origin, dir))
                        .filter(|&t| ray_crossing(origin, dir, t).is_some())
                        .count();
                    crossings % 2 == 1
                });
                odd.count() >= 2
            })
    }
}

impl Surface {
    /// The triangles of the clusters whose box `keep` accepts, in the
    /// centred space.
    fn triangles<'a>(
        &'a self,
        blockers: &'a Blockers,
        keep: impl Fn(&Aabb) -> bool + 'a,
    ) -> impl Iterator<Item = [Vec3; 3]> + 'a {
        (self.clusters.iter())
            .filter(move |(_, b)| keep(b))
            .flat_map(move |(run, _)| {
                blockers.triangles[run.clone()]
                    .iter()
                    .map(move |t| t.map(|i| blockers.position(i as usize)))
            })
    }
}

/// Whether `b` grown by `margin` holds `p`.
fn holds(b: &Aabb, p: Vec3, margin: f32) -> bool {
    p.cmpge(b.min - margin).all() && p.cmple(b.max + margin).all()
}

/// Whether the ray from `origin` along `dir` meets box `b` (slabs).
fn reaches(b: &Aabb, origin: Vec3, dir: Vec3) -> bool {
    let inv = dir.recip();
    let (t0, t1) = ((b.min - origin) * inv, (b.max - origin) * inv);
    let near = t0.min(t1).max_element();
    let far = t0.max(t1).min_element();
    near <= far && far >= 0.0
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::Vec3;
    use shadow_core::{Brdf, Camera, Object, Scene, shapes};

    use super::*;

    fn blockers_of(meshes: Vec<shadow_core::Mesh>, cull: &[bool]) -> Blockers {
        let objects = meshes
            .into_iter()
            .map(|mesh| Object {
                mesh: Arc::new(mesh),
                material: Brdf::lambert(Vec3::ONE).unwrap(),
            })
            .collect();
        let camera = Camera::new(Vec3::new(0.0, 2.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
        let scene = Scene::still("enclosure", objects, camera).unwrap();
        Blockers::new(&scene.frame_geometry(0).unwrap(), cull).unwrap()
    }

    /// A box on a floor: its bottom face's vertices are pressed, its side
    /// and top vertices and the floor's corners are not.
    #[test]
    fn a_box_s_bottom_on_the_floor_is_pressed() {
        let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 1).unwrap();
        let cube = shapes::cuboid(
            "box",
            Vec3::new(-0.3, 0.0, -0.3),
            Vec3::new(0.3, 0.5, 0.3),
            false,
        )
        .unwrap();
        let b = blockers_of(vec![floor, cube], &[false, true]);
        let e = Enclosure::new(&b);
        let (mut pressed, mut bottom) = (0, 0);
        for v in 0..b.vertex_count() {
            let down = b.surface(v).0.y < -0.99;
            bottom += usize::from(down);
            let got = e.encloses(&b, v);
            assert_eq!(got, down, "vertex {v} at {}", b.position(v));
            pressed += usize::from(got);
        }
        assert_eq!(pressed, bottom);
        assert!(bottom >= 4);
    }

    /// Two closed balls sunk into each other: the vertices of each inside
    /// the other are buried, the others not; with back faces drawn nothing
    /// is tested.
    #[test]
    fn vertices_inside_another_closed_object_are_buried() {
        let a = shapes::uv_sphere("a", Vec3::ZERO, 1.0, 12, 24).unwrap();
        let b = shapes::uv_sphere("b", Vec3::new(1.2, 0.0, 0.0), 1.0, 12, 24).unwrap();
        let centres = [Vec3::ZERO, Vec3::new(1.2, 0.0, 0.0)];
        let blockers = blockers_of(vec![a.clone(), b.clone()], &[true, true]);
        let e = Enclosure::new(&blockers);
        let mut buried = 0;
        for v in 0..blockers.vertex_count() {
            let own = blockers.object_of(v);
            // In world units: the space is centred and scaled.
            let world = if own == 0 {
                a.positions()[v]
            } else {
                b.positions()[v - a.vertex_count()]
            };
            let inside = world.distance(centres[1 - own]) < 0.99;
            let outside = world.distance(centres[1 - own]) > 1.01;
            let got = e.encloses(&blockers, v);
            if inside {
                assert!(got, "vertex {v} at {world}");
                buried += 1;
            } else if outside {
                assert!(!got, "vertex {v} at {world}");
            }
        }
        assert!(buried > 20, "{buried}");
        let drawn = blockers_of(vec![a, b], &[false, false]);
        let e = Enclosure::new(&drawn);
        assert!((0..drawn.vertex_count()).all(|v| !e.encloses(&drawn, v)));
    }
}
