//! The lightsphere (Sattler et al. 2004, §3.4): light directions from midpoint
//! subdivision of an octahedron, nested so that every level keeps the
//! directions of the coarser ones, each standing for a solid angle.

use std::collections::HashMap;
use std::f32::consts::PI;

use glam::{DQuat, DVec3, Vec3};

/// A subdivision level s = 0..=5 of the lightsphere: 2 + 4^(s+1) directions
/// (6, 18, 66, 258, 1026, 4098).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Level(u8);

impl Level {
    /// The finest level: 4098 directions.
    pub const MAX: Level = Level(5);

    /// Level `s`, if at most [`Level::MAX`].
    pub const fn new(s: u8) -> Option<Level> {
        if s <= Level::MAX.0 {
            Some(Level(s))
        } else {
            None
        }
    }

    /// The level with exactly `k` directions.
    pub fn with_directions(k: usize) -> Option<Level> {
        (0..=Level::MAX.0).map(Level).find(|l| l.directions() == k)
    }

    pub const fn get(self) -> u8 {
        self.0
    }

    /// Directions at this level: 2 + 4^(s+1).
    pub const fn directions(self) -> usize {
        2 + (4usize << (2 * self.0))
    }

    /// The next finer level, if any.
    pub fn finer(self) -> Option<Level> {
        Level::new(self.0 + 1)
    }
}

/// How much of the sphere each direction stands for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Weights {
    /// The solid angle of each direction's spherical Voronoi cell: the
    /// directions crowd near the octahedron's vertices and thin out near
    /// its face centres, and the cells say by how much.
    #[default]
    Voronoi,
    /// 4π/k each, as the paper's sum c_i = Σ_j M_ij I_j implies.
    Equal,
}

/// How the lightsphere sits in world space.
///
/// The paper's octahedron has its vertices on the coordinate axes (§3.4), so
/// midpoint subdivision puts whole great circles of directions in the
/// planes x = 0, y = 0 and z = 0: a floor or wall aligned with the axes is
/// seen exactly edge-on by every direction of those circles, and its depth
/// maps show it as a line that covers some texels and misses others.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Orientation {
    /// The octahedron's vertices on ±x, ±y, ±z, as in the paper.
    Axes,
    /// The octahedron turned by [`Orientation::TURN`], which keeps every
    /// direction of levels 0 to 4 at least 0.25° (level 3: 0.56°) off the
    /// three coordinate planes.
    #[default]
    Turned,
}

impl Orientation {
    /// The turn of [`Orientation::Turned`]: of 20,000 random rotations and a
    /// local search from the best, the one whose directions at levels 1–4
    /// keep the largest least angle from the coordinate planes, measured in
    /// each level's spacing √(4π/k) (a test checks the angles).
    pub const TURN: DQuat = DQuat::from_xyzw(-0.2678, -0.9477, -0.1139, 0.1314);

    fn rotation(self) -> DQuat {
        match self {
            Orientation::Axes => DQuat::IDENTITY,
            Orientation::Turned => Orientation::TURN.normalize(),
        }
    }
}

/// The directions of one level, with their weights.
#[derive(Clone, Debug, PartialEq)]
pub struct Lightsphere {
    level: Level,
    directions: Vec<Vec3>,
    weights: Vec<f32>,
}

impl Lightsphere {
    /// The directions of `level` (unit vectors toward the light; those of
    /// every coarser level first, in the same order), turned by
    /// `orientation`, and their `weights` (steradians, summing to 4π; each
    /// level has its own, since a coarser level's cells are larger).
    pub fn new(level: Level, weights: Weights, orientation: Orientation) -> Lightsphere {
        let (points, triangles) = subdivided_octahedron(level);
        let weights = match weights {
            Weights::Voronoi => voronoi_areas(&points, &triangles),
            Weights::Equal => vec![4.0 * std::f64::consts::PI / points.len() as f64; points.len()],
        };
        let turn = orientation.rotation();
        Lightsphere {
            level,
            directions: points.iter().map(|&p| (turn * p).as_vec3()).collect(),
            weights: weights.iter().map(|&w| w as f32).collect(),
        }
    }

    pub fn level(&self) -> Level {
        self.level
    }

    pub fn directions(&self) -> &[Vec3] {
        &self.directions
    }

    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    pub fn len(&self) -> usize {
        self.directions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// The mean angular spacing of the directions, √(4π/k) radians: the
    /// scale the environment is prefiltered at (§5).
    pub fn spacing(&self) -> f32 {
        (4.0 * PI / self.len() as f32).sqrt()
    }
}

/// The unit-sphere points of `level` (coarser levels' first) and the
/// triangles of its subdivided octahedron, counter-clockwise seen from
/// outside.
fn subdivided_octahedron(level: Level) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mut points = vec![
        DVec3::X,
        DVec3::NEG_X,
        DVec3::Y,
        DVec3::NEG_Y,
        DVec3::Z,
        DVec3::NEG_Z,
    ];
    let (x, nx, y, ny, z, nz) = (0, 1, 2, 3, 4, 5);
    let mut triangles: Vec<[u32; 3]> = vec![
        [y, z, x],
        [y, x, nz],
        [y, nz, nx],
        [y, nx, z],
        [ny, x, z],
        [ny, nz, x],
        [ny, nx, nz],
        [ny, z, nx],
    ];
    for _ in 0..level.get() {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, points: &mut Vec<DVec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                points.push((points[a as usize] + points[b as usize]).normalize());
                (points.len() - 1) as u32
            })
        };
        let mut finer = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let ab = midpoint(a, b, &mut points);
            let bc = midpoint(b, c, &mut points);
            let ca = midpoint(c, a, &mut points);
            finer.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        triangles = finer;
    }
    (points, triangles)
}

/// The solid angle of each point's spherical Voronoi cell, given the
/// Delaunay triangulation of the points (the convex hull's faces, which the
/// subdivided octahedron's triangles are: a test checks it). Each triangle
/// gives each of its corners the part of its cell between the two edge
/// midpoints and the triangle's circumcentre, as two signed spherical
/// triangles, so obtuse triangles (circumcentre outside) count right.
fn voronoi_areas(points: &[DVec3], triangles: &[[u32; 3]]) -> Vec<f64> {
    let mut areas = vec![0.0; points.len()];
    for &[a, b, c] in triangles {
        let [pa, pb, pc] = [a, b, c].map(|i| points[i as usize]);
        let centre = (pb - pa).cross(pc - pa).normalize();
        for (corner, p, next, prev) in [(a, pa, pb, pc), (b, pb, pc, pa), (c, pc, pa, pb)] {
            let to_next = (p + next).normalize();
            let to_prev = (p + prev).normalize();
            areas[corner as usize] +=
                signed_solid_angle(p, to_next, centre) + signed_solid_angle(p, centre, to_prev);
        }
    }
    areas
}

/// The solid angle of the spherical triangle (a, b, c), positive when
/// counter-clockwise seen from outside (Van Oosterom and Strackee 1983).
fn signed_solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let det = a.dot(b.cross(c));
    2.0 * det.atan2(1.0 + a.dot(b) + b.dot(c) + c.dot(a))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn levels() -> impl Iterator<Item = Level> {
        (0..=5).map(|s| Level::new(s).unwrap())
    }

    #[test]
    fn levels_have_the_papers_direction_counts_and_nest() {
        let counts: Vec<usize> = levels().map(Level::directions).collect();
        assert_eq!(counts, [6, 18, 66, 258, 1026, 4098]);
        let finest = Lightsphere::new(Level::MAX, Weights::Equal, Orientation::Axes);
        for level in levels() {
            let sphere = Lightsphere::new(level, Weights::Equal, Orientation::Axes);
            assert_eq!(sphere.len(), level.directions());
            assert_eq!(sphere.directions(), &finest.directions()[..sphere.len()]);
            for d in sphere.directions() {
                assert_relative_eq!(d.length(), 1.0, epsilon = 1e-6);
            }
        }
        assert_eq!(Level::with_directions(258), Level::new(3));
        assert!(Level::with_directions(100).is_none() && Level::new(6).is_none());
    }

    #[test]
    fn weights_sum_to_the_sphere() {
        for level in levels() {
            for weights in [Weights::Voronoi, Weights::Equal] {
                let sphere = Lightsphere::new(level, weights, Orientation::Turned);
                let total: f64 = sphere.weights().iter().map(|&w| w as f64).sum();
                assert_relative_eq!(total, 4.0 * std::f64::consts::PI, max_relative = 1e-5);
                assert!(sphere.weights().iter().all(|&w| w > 0.0));
            }
        }
    }

    /// The triangles are the convex hull's faces (every point on or behind
    /// each face's plane), hence the Delaunay triangulation on the sphere,
    /// and the circumcentre cells are the Voronoi cells.
    #[test]
    fn the_subdivision_is_the_convex_hull() {
        for level in levels() {
            let (points, triangles) = subdivided_octahedron(level);
            for &[a, b, c] in &triangles {
                let [pa, pb, pc] = [a, b, c].map(|i| points[i as usize]);
                let n = (pb - pa).cross(pc - pa).normalize();
                assert!(n.dot(pa) > 0.0, "face {a} {b} {c} faces inward");
                let behind = points.iter().all(|p| (*p - pa).dot(n) <= 1e-12);
                assert!(
                    behind,
                    "level {}: face {a} {b} {c} is not a hull face",
                    level.get()
                );
            }
        }
    }

    /// A cell's solid angle agrees with counting which direction is nearest
    /// over a fine grid of the sphere.
    #[test]
    fn voronoi_weights_match_nearest_direction_counts() {
        let sphere = Lightsphere::new(
            Level::new(2).unwrap(),
            Weights::Voronoi,
            Orientation::Turned,
        );
        let (rows, cols) = (400, 800);
        let mut counted = vec![0.0f64; sphere.len()];
        for r in 0..rows {
            let theta = PI as f64 * (r as f64 + 0.5) / rows as f64;
            let solid = (PI as f64 / rows as f64) * (2.0 * PI as f64 / cols as f64) * theta.sin();
            for c in 0..cols {
                let phi = 2.0 * PI as f64 * (c as f64 + 0.5) / cols as f64;
                let d = DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                let nearest = (0..sphere.len())
                    .max_by(|&i, &j| {
                        let (a, b) = (sphere.directions()[i], sphere.directions()[j]);
                        d.dot(a.as_dvec3()).total_cmp(&d.dot(b.as_dvec3()))
                    })
                    .unwrap();
                counted[nearest] += solid;
            }
        }
        for (w, c) in sphere.weights().iter().zip(&counted) {
            assert_relative_eq!(*w as f64, *c, max_relative = 0.02);
        }
        // Cells differ: the octahedron's vertices get more than face centres.
        let (lo, hi) = sphere
            .weights()
            .iter()
            .fold((f32::MAX, 0.0f32), |(lo, hi), &w| (lo.min(w), hi.max(w)));
        assert!(hi / lo > 1.2, "{lo} .. {hi}");
    }

    /// The paper's orientation puts directions in the coordinate planes; the
    /// turned one keeps every direction of levels 0–4 off them (least
    /// angles measured: 8.4°, 6.7°, 0.90°, 0.56°, 0.25°), and turning
    /// changes neither the nesting nor the weights.
    #[test]
    fn the_turned_lightsphere_keeps_off_the_coordinate_planes() {
        let least_angle = |sphere: &Lightsphere| {
            sphere
                .directions()
                .iter()
                .map(|d| d.abs().min_element().asin().to_degrees())
                .fold(f32::INFINITY, f32::min)
        };
        let measured = [8.3, 6.6, 0.9, 0.55, 0.25];
        for (level, least) in levels().zip(measured) {
            let axes = Lightsphere::new(level, Weights::Voronoi, Orientation::Axes);
            let turned = Lightsphere::new(level, Weights::Voronoi, Orientation::Turned);
            assert_eq!(least_angle(&axes), 0.0);
            let angle = least_angle(&turned);
            assert!(angle >= least, "level {}: {angle}°", level.get());
            assert_eq!(axes.weights(), turned.weights());
            for (a, t) in axes.directions().iter().zip(turned.directions()) {
                let turn = Orientation::TURN.normalize().as_quat();
                assert_relative_eq!(turn * *a, *t, epsilon = 1e-6);
            }
        }
    }
}
