//! Where a vertex touches another object, as the Monte-Carlo reference sees
//! it, for methods that do not trace its shadow rays: whether the vertex is
//! *enclosed* (pressed on another object's surface, or buried inside
//! another closed object: it receives no light), and the *contact planes*
//! through it (another object's triangle through the lifted vertex, the
//! floor under a box's side: it blocks the half of the hemisphere that sees
//! its front, or the part of that half across the triangle's edges where the
//! vertex stands on one, [`ContactCone`]).
//!
//! - **Pressed** is the reference's own test
//!   ([`SceneBvh::pressed`](crate::bvh::SceneBvh::pressed)): each of the
//!   four [`press_probes`] crosses another object's triangle.
//! - **Buried**: inside another object that the method draws with its back
//!   faces culled (`buries`), which would hide every face the vertex sees.
//!   The parity of the crossings of three rays from the lifted vertex with
//!   that object's triangles decides, the majority of the three (a ray
//!   through an edge counts twice, which one of three may do).
//! - **Contact planes**: a triangle of another object whose plane passes
//!   through the lifted vertex or just in front of it (the vertex on the
//!   plane or behind it by at most a quarter of its lift), over it (its
//!   foot on the plane within that reach of the triangle), and above its
//!   horizon: the reference's shadow rays back up half a lift along
//!   themselves and count a hit nearer than the lift only on a front face,
//!   so that such a plane blocks the directions that see its front
//!   ([`contact_plane`]).
//!
//! Every test looks only at objects whose box holds the vertex, and inside
//! them only at runs of [`RUN`] consecutive triangles whose box does. The
//! positions are held centred on the frame's bounds and scaled by a power
//! of two to about unit size, so that nothing overflows or is lost in the
//! rounding of coordinates far from the world's origin.

use std::ops::Range;

use glam::Vec3;

use crate::frame::{PRESS_REACH, lift_at, press_probes};
use crate::triangle::ray_crossing;
use crate::{Aabb, Error, FrameGeometry, Result};

/// Triangles per run: consecutive in their object's index buffer, which for
/// scanned and authored meshes keeps them close in space.
pub const RUN: usize = 16;

/// How far behind a plane a lifted vertex may be and still touch it, in
/// lifts ([`contact_plane`]).
pub const CONTACT_REACH: f32 = 0.25;

/// The directions of the parity rays: off the axes and off each other's
/// planes, so that no two run along the same mesh edges.
const RAYS: [Vec3; 3] = [
    Vec3::new(0.5377, 0.7063, 0.4604),
    Vec3::new(-0.6312, 0.2297, 0.7408),
    Vec3::new(0.1953, -0.8640, 0.4640),
];

/// A frame's surfaces, searched per vertex for contacts (module docs).
pub struct Contacts {
    objects: Vec<Surface>,
    /// World to the centred space: `(p − centre) · scale`.
    scale: f32,
}

struct Surface {
    /// Positions in the centred space, and each vertex's lift and normal.
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    lifts: Vec<f32>,
    triangles: Vec<[u32; 3]>,
    bounds: Aabb,
    /// Whether it can bury a vertex (its back faces culled by the method).
    buries: bool,
    /// Consecutive runs of its triangles, each with its box.
    runs: Vec<(Range<usize>, Aabb)>,
}

/// What [`Contacts::at`] found at a vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Contact {
    /// Pressed on another object's surface or buried inside another closed
    /// object: the vertex receives no light.
    pub enclosed: bool,
    /// What the contact planes block: each the directions that see its
    /// front, across the edges the vertex's foot lies on ([`ContactCone`]).
    pub planes: Vec<ContactCone>,
}

impl Contacts {
    /// The surfaces of `frame`; `buries[o]` says whether object o can bury
    /// a vertex (module docs). Fails on a frame whose extent f32 cannot
    /// hold.
    pub fn new(frame: &FrameGeometry, buries: &[bool]) -> Result<Contacts> {
        let bounds = frame.bounds();
        let diagonal = bounds.diagonal();
        let scale = if diagonal > 0.0 {
            (1.0 / diagonal).log2().round().exp2()
        } else {
            1.0
        };
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::InvalidScene(format!(
                "a frame {diagonal} across cannot be searched for contacts in f32"
            )));
        }
        let centre = bounds.center();
        let objects = (frame.objects.iter().zip(buries))
            .map(|(object, &buries)| {
                let positions: Vec<Vec3> = (object.positions().iter())
                    .map(|&p| (p - centre) * scale)
                    .collect();
                let lifts = (object.lifts().iter().zip(&positions))
                    .map(|(&lift, &p)| lift_at(lift * scale, p))
                    .collect();
                let triangles = object.triangles().to_vec();
                let runs: Vec<(Range<usize>, Aabb)> = (0..triangles.len())
                    .step_by(RUN)
                    .map(|start| {
                        let run = start..(start + RUN).min(triangles.len());
                        let corners = triangles[run.clone()].iter().flatten();
                        let b = Aabb::from_points(corners.map(|&i| positions[i as usize]));
                        (run, b)
                    })
                    .collect();
                let bounds = runs.iter().fold(Aabb::EMPTY, |b, (_, r)| b.union(*r));
                Surface {
                    normals: object.normals().to_vec(),
                    positions,
                    lifts,
                    triangles,
                    bounds,
                    buries,
                    runs,
                }
            })
            .collect();
        Ok(Contacts { objects, scale })
    }

    /// What vertex `vertex` of object `object` touches (module docs).
    pub fn at(&self, object: usize, vertex: usize) -> Contact {
        if self.enclosed(object, vertex) {
            return Contact {
                enclosed: true,
                planes: Vec::new(),
            };
        }
        let (origin, normal, lift) = self.lifted(object, vertex);
        let contact = CONTACT_REACH * lift;
        let planes = self
            .others(object, origin, lift)
            .flat_map(|s| {
                s.triangles(|b| holds(b, origin, contact))
                    .filter_map(|t| contact_plane(t.map(|c| c - origin), normal, contact))
            })
            .collect();
        Contact {
            enclosed: false,
            planes,
        }
    }

    /// Whether vertex `vertex` of object `object` is pressed on another
    /// object's surface or buried inside another closed object (module
    /// docs): it receives no light.
    pub fn enclosed(&self, object: usize, vertex: usize) -> bool {
        let own = &self.objects[object];
        let (p, normal, lift) = (
            own.positions[vertex],
            own.normals[vertex],
            own.lifts[vertex],
        );
        let reach = PRESS_REACH * lift;
        let probes = press_probes(p, normal, lift);
        let pressed = probes.iter().all(|&probe| {
            self.others(object, p, lift).any(|s| {
                s.triangles(|b| holds(b, probe, reach))
                    .any(|t| ray_crossing(probe, normal, t).is_some_and(|d| d <= reach))
            })
        });
        let origin = p + normal * lift;
        pressed
            || self
                .others(object, p, lift)
                .filter(|s| s.buries && holds(&s.bounds, origin, 0.0))
                .any(|s| {
                    let odd = RAYS.iter().filter(|&&dir| {
                        let crossings = s
                            .triangles(|b| reaches(b, origin, dir))
                            .filter(|&t| ray_crossing(origin, dir, t).is_some())
                            .count();
                        crossings % 2 == 1
                    });
                    odd.count() >= 2
                })
    }

    /// Per vertex of the frame, objects one after another, whether it is
    /// enclosed ([`Contacts::enclosed`]): the rule a method that does not
    /// trace the reference's rays takes for the receivers that see nothing.
    pub fn enclosed_vertices(&self) -> Vec<bool> {
        use rayon::prelude::*;
        let vertices: Vec<(usize, usize)> = (self.objects.iter().enumerate())
            .flat_map(|(o, s)| (0..s.positions.len()).map(move |v| (o, v)))
            .collect();
        vertices
            .par_iter()
            .map(|&(o, v)| self.enclosed(o, v))
            .collect()
    }

    /// How far vertex `vertex` of object `object` can move along its normal
    /// before it meets another object's surface (either side), up to
    /// `reach` (world units): a method that moves tested vertices off their
    /// surface (a depth-map bias) must not move them through another.
    /// Measured from the vertex lifted by its lift, so that the surfaces
    /// through the vertex (a neighbouring part sharing its place) do not
    /// count.
    pub fn clearance(&self, object: usize, vertex: usize, reach: f32) -> f32 {
        let (p, normal, lift) = self.lifted(object, vertex);
        let reach = (reach * self.scale - lift).max(0.0);
        let end = p + normal * reach;
        let within = Aabb::from_points([p, end]);
        let near = |b: &Aabb| b.min.cmple(within.max).all() && b.max.cmpge(within.min).all();
        let nearest = (self.objects.iter().enumerate())
            .filter(|&(o, s)| o != object && near(&s.bounds))
            .flat_map(|(_, s)| {
                s.triangles(near)
                    .filter_map(move |t| ray_crossing(p, normal, t))
            })
            .fold(reach, f32::min);
        (nearest + lift) / self.scale
    }

    /// Vertex `vertex` of object `object` lifted along its normal, its
    /// normal and its lift, in the centred space.
    fn lifted(&self, object: usize, vertex: usize) -> (Vec3, Vec3, f32) {
        let own = &self.objects[object];
        let (normal, lift) = (own.normals[vertex], own.lifts[vertex]);
        (own.positions[vertex] + normal * lift, normal, lift)
    }

    /// The objects but `object` whose box comes within 2 lifts of `p`
    /// (as far as the probes and the contact reach go).
    fn others(&self, object: usize, p: Vec3, lift: f32) -> impl Iterator<Item = &Surface> {
        (self.objects.iter().enumerate())
            .filter(move |&(o, s)| o != object && holds(&s.bounds, p, 2.0 * lift))
            .map(|(_, s)| s)
    }
}

impl Surface {
    /// The triangles of the runs whose box `keep` accepts.
    fn triangles<'a>(
        &'a self,
        keep: impl Fn(&Aabb) -> bool + 'a,
    ) -> impl Iterator<Item = [Vec3; 3]> + 'a {
        (self.runs.iter())
            .filter(move |(_, b)| keep(b))
            .flat_map(move |(run, _)| {
                self.triangles[run.clone()]
                    .iter()
                    .map(move |t| t.map(|i| self.positions[i as usize]))
            })
    }
}

/// The directions a contact triangle blocks ([`contact_plane`]): those on
/// the positive side of all three planes, d·p > 0 for each p in `planes`.
/// In the limit the reference takes, a direction from the receiver meets
/// the triangle's plane at the receiver's foot, just off it along the
/// direction's part in the plane: it is blocked when it sees the plane's
/// front and that part points into the triangle. With the foot inside the
/// triangle that is the front half (each plane the reversed front normal);
/// on an edge, the half of that half across the edge (one plane the edge's
/// inward normal in the triangle's plane: the end of a wall on the floor
/// blocks the quarter toward the wall); at a corner, the wedge of the
/// corner's angle (a box's side at the floor vertex under the box's corner:
/// each side the quarter toward the box, not a half each).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactCone {
    /// Unit front normal of the triangle.
    pub front: Vec3,
    /// Unit plane normals whose positive sides bound what it blocks.
    pub planes: [Vec3; 3],
}

impl ContactCone {
    /// Whether direction `d` is blocked.
    pub fn blocks(&self, d: Vec3) -> bool {
        self.planes.iter().all(|p| p.dot(d) > 0.0)
    }
}

/// Whether triangle (a, b, c), given relative to a lifted vertex with unit
/// normal `normal`, is a contact plane of it with reach `reach`
/// ([`CONTACT_REACH`] of its lift): its plane passes through the vertex or
/// in front of it within the reach (the vertex on the plane or behind it),
/// its extent covers the vertex's foot on the plane (within the reach of
/// its edges), and some corner is above the vertex's horizon. Returns what
/// it blocks ([`ContactCone`]): the directions that see its front and,
/// across each edge the foot lies on (within the reach), enter it. A
/// triangle whose three edges all lie within the reach of the foot (smaller
/// than the reach) blocks the front half.
pub fn contact_plane([a, b, c]: [Vec3; 3], normal: Vec3, reach: f32) -> Option<ContactCone> {
    let above = a.dot(normal) > 0.0 || b.dot(normal) > 0.0 || c.dot(normal) > 0.0;
    let (ab, bc, ca) = (a.cross(b), b.cross(c), c.cross(a));
    let n = ab + bc + ca;
    let n2 = n.length_squared();
    let det = ab.dot(c);
    let reach2 = reach * reach;
    let through = det >= 0.0 && det * det <= reach2 * n2 && n2 > 0.0;
    // (a × b)·n is the foot's distance from edge ab, inside positive, times
    // |b − a| |n|.
    let edges = [(ab, a, b), (bc, b, c), (ca, c, a)].map(|(edge, from, to)| {
        let d = edge.dot(n);
        let on = d * d <= reach2 * (to - from).length_squared() * n2;
        (d >= 0.0 || on, on, to - from)
    });
    if !(above && through && edges.iter().all(|e| e.0)) {
        return None;
    }
    let front = n.normalize();
    let on_all = edges.iter().all(|e| e.1);
    // n × (b − a) points from edge ab into the triangle, toward c.
    let planes = edges.map(|(_, on, along)| {
        if on && !on_all {
            n.cross(along).normalize()
        } else {
            -front
        }
    });
    Some(ContactCone { front, planes })
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

    use super::*;
    use crate::{Brdf, Camera, Mesh, Object, Scene, shapes};

    fn frame(meshes: Vec<Mesh>) -> FrameGeometry {
        let objects = meshes
            .into_iter()
            .map(|mesh| Object {
                mesh: Arc::new(mesh),
                material: Brdf::lambert(Vec3::ONE).unwrap(),
            })
            .collect();
        let camera = Camera::new(Vec3::new(0.0, 2.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
        Scene::still("contacts", objects, camera)
            .unwrap()
            .frame_geometry(0)
            .unwrap()
    }

    fn box_on_floor() -> Vec<Mesh> {
        let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 1).unwrap();
        let cube = shapes::cuboid(
            "box",
            Vec3::new(-0.3, 0.0, -0.3),
            Vec3::new(0.3, 0.5, 0.3),
            false,
        )
        .unwrap();
        vec![floor, cube]
    }

    /// A box on a floor: its bottom face's vertices are pressed; its side
    /// vertices on the floor touch the floor's plane, whose front (up)
    /// blocks the lower half; the others and the floor's corners touch
    /// nothing.
    #[test]
    fn a_box_on_a_floor_touches_it_where_it_stands() {
        let meshes = box_on_floor();
        let cube = meshes[1].clone();
        let frame = frame(meshes);
        let contacts = Contacts::new(&frame, &[false, true]).unwrap();
        for v in 0..4 {
            assert_eq!(contacts.at(0, v), Contact::default(), "floor corner {v}");
        }
        let mut touching = 0;
        for v in 0..cube.vertex_count() {
            let (p, n) = (cube.positions()[v], cube.normals()[v]);
            let got = contacts.at(1, v);
            if n.y < -0.5 {
                assert!(
                    got.enclosed && got.planes.is_empty(),
                    "bottom {v} at {p}: {got:?}"
                );
            } else if n.y.abs() < 0.5 && p.y == 0.0 {
                assert!(!got.enclosed, "side {v} at {p}");
                assert!(!got.planes.is_empty(), "side {v} at {p}");
                for cone in &got.planes {
                    assert!(cone.front.abs_diff_eq(Vec3::Y, 1e-6), "{cone:?}");
                }
                // The floor's one cell covers the box: every direction
                // down is blocked, none up.
                let down = |d: Vec3| got.planes.iter().any(|c| c.blocks(d));
                assert!(down(Vec3::new(0.3, -0.1, 0.2)) && down(Vec3::new(-0.2, -0.9, -0.3)));
                assert!(!down(Vec3::new(0.3, 0.1, 0.2)));
                touching += 1;
            } else {
                assert_eq!(got, Contact::default(), "{v} at {p}");
            }
        }
        assert_eq!(touching, 8);
    }

    /// The clearance along the normal: a ball 1 cm over a floor, its lowest
    /// vertex facing down.
    #[test]
    fn clearance_stops_at_another_surface() {
        let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 1).unwrap();
        let ball = shapes::uv_sphere("ball", Vec3::new(0.0, 0.26, 0.0), 0.25, 8, 16).unwrap();
        let lowest = (0..ball.vertex_count())
            .min_by(|&a, &b| ball.positions()[a].y.total_cmp(&ball.positions()[b].y))
            .unwrap();
        let top = (0..ball.vertex_count())
            .max_by(|&a, &b| ball.positions()[a].y.total_cmp(&ball.positions()[b].y))
            .unwrap();
        let contacts = Contacts::new(&frame(vec![floor, ball]), &[false, false]).unwrap();
        let gap = contacts.clearance(1, lowest, 0.1);
        assert!((gap - 0.01).abs() < 1e-5, "{gap}");
        assert_eq!(contacts.clearance(1, lowest, 0.005), 0.005);
        assert_eq!(contacts.clearance(1, top, 0.1), 0.1);
    }

    /// Two closed balls sunk into each other: the vertices of each inside
    /// the other are buried when the other buries, and not otherwise.
    #[test]
    fn vertices_inside_another_closed_object_are_buried() {
        let a = shapes::uv_sphere("a", Vec3::ZERO, 1.0, 12, 24).unwrap();
        let b = shapes::uv_sphere("b", Vec3::new(1.2, 0.0, 0.0), 1.0, 12, 24).unwrap();
        let centres = [Vec3::ZERO, Vec3::new(1.2, 0.0, 0.0)];
        let frame = frame(vec![a.clone(), b.clone()]);
        let contacts = Contacts::new(&frame, &[true, true]).unwrap();
        let open = Contacts::new(&frame, &[false, false]).unwrap();
        let mut buried = 0;
        for (o, mesh) in [&a, &b].into_iter().enumerate() {
            for (v, p) in mesh.positions().iter().enumerate() {
                let d = p.distance(centres[1 - o]);
                let got = contacts.at(o, v).enclosed;
                if d < 0.99 {
                    assert!(got, "object {o} vertex {v} at {p}");
                    buried += 1;
                } else if d > 1.01 {
                    assert!(!got, "object {o} vertex {v} at {p}");
                }
                assert!(!open.at(o, v).enclosed);
            }
        }
        assert!(buried > 20, "{buried}");
    }

    /// The rule on single triangles, relative to the lifted vertex (normal
    /// +z): on the plane and behind it within the reach, over the foot and
    /// above the horizon, and nothing otherwise.
    #[test]
    fn contact_planes_pass_through_or_just_in_front() {
        // A floor-like triangle in the plane y = h, front up (+y); the
        // vertex faces +z (a box's side).
        let floor = |h: f32| {
            [
                Vec3::new(-3.0, h, -1.0),
                Vec3::new(0.0, h, 3.0),
                Vec3::new(3.0, h, -1.0),
            ]
        };
        let reach = 1e-3;
        let half = Some(ContactCone {
            front: Vec3::Y,
            planes: [Vec3::NEG_Y; 3],
        });
        assert_eq!(contact_plane(floor(0.0), Vec3::Z, reach), half);
        // The vertex behind (below) the plane within the reach.
        assert_eq!(contact_plane(floor(0.5e-3), Vec3::Z, reach), half);
        // Beyond the reach, or in front (above) of the plane: a cone.
        assert_eq!(contact_plane(floor(2e-3), Vec3::Z, reach), None);
        assert_eq!(contact_plane(floor(-0.5e-3), Vec3::Z, reach), None);
        // Its foot outside the triangle.
        let beside = floor(0.0).map(|p| p + Vec3::new(0.0, 0.0, 3.01));
        assert_eq!(contact_plane(beside, Vec3::Z, reach), None);
        // Wholly below the horizon.
        let below = floor(0.0).map(|p| p - Vec3::new(0.0, 0.0, 4.0));
        assert_eq!(contact_plane(below, Vec3::Z, reach), None);
    }

    /// A floor vertex at the end of a wall's foot, and one under a box's
    /// corner: the wall's end blocks the quarter toward the wall, each side
    /// of the box the quarter toward the box, where a half each would have
    /// blocked three quarters (the floor vertex sees the box's corner as a
    /// quadrant: of its cosine-weighted hemisphere, a quarter).
    #[test]
    fn contacts_at_an_edge_or_a_corner_block_only_what_lies_across_them() {
        let reach = 1e-3;
        // The wall x = 0, z ≤ 0, front toward −x; the vertex at its end
        // (z = 0) facing up, lifted: the wall's foot a lift (4 reaches)
        // under it.
        let wall = [
            Vec3::new(0.0, -4e-3, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, -4e-3, -1.0),
        ];
        let cone = contact_plane(wall, Vec3::Y, reach).unwrap();
        assert!(cone.front.abs_diff_eq(Vec3::NEG_X, 1e-6), "{cone:?}");
        assert!(cone.blocks(Vec3::new(0.5, 0.5, -0.5)));
        assert!(
            !cone.blocks(Vec3::new(0.5, 0.5, 0.5)),
            "beyond the wall's end"
        );
        assert!(!cone.blocks(Vec3::new(-0.5, 0.5, -0.5)), "its back");

        // The box x ≤ 0, z ≤ 0 on the floor: the vertex at its corner.
        let meshes = {
            let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 2).unwrap();
            let cube = shapes::cuboid(
                "box",
                Vec3::new(-0.5, 0.0, -0.5),
                Vec3::new(0.0, 0.5, 0.0),
                false,
            )
            .unwrap();
            vec![floor, cube]
        };
        let corner = (meshes[0].positions().iter())
            .position(|p| p.length() < 1e-6)
            .unwrap();
        let contacts = Contacts::new(&frame(meshes), &[false, true]).unwrap();
        let got = contacts.at(0, corner);
        assert!(!got.enclosed && !got.planes.is_empty(), "{got:?}");
        let blocked = |d: Vec3| got.planes.iter().any(|c| c.blocks(d));
        assert!(blocked(Vec3::new(-0.5, 0.5, -0.5)), "into the box");
        assert!(!blocked(Vec3::new(-0.5, 0.5, 0.5)), "beside its x face");
        assert!(!blocked(Vec3::new(0.5, 0.5, -0.5)), "beside its z face");
        assert!(!blocked(Vec3::new(0.5, 0.5, 0.5)), "away from it");
    }
}
