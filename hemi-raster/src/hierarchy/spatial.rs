//! Triangles found by distance: the near lists and the regions of the
//! hierarchy are built from these queries, once per scene.

use glam::Vec3;
use shadow_core::triangle::bounding_sphere;

/// Triangles sorted by the x of their centroid, so that those within some
/// distance of a point lie in a window found by bisection.
#[derive(Default)]
pub(super) struct Sorted {
    items: Vec<Item>,
    max_radius: f32,
}

struct Item {
    index: u32,
    corners: [Vec3; 3],
    centre: Vec3,
    radius: f32,
}

impl Sorted {
    pub(super) fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Sorted {
        let mut items: Vec<Item> = triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let corners = tri.map(|i| positions[i as usize]);
                let (centre, radius) = bounding_sphere(corners);
                Item {
                    index: t as u32,
                    corners,
                    centre,
                    radius,
                }
            })
            .collect();
        items.sort_unstable_by(|x, y| x.centre.x.total_cmp(&y.centre.x));
        let max_radius = items.iter().map(|i| i.radius).fold(0.0, f32::max);
        Sorted { items, max_radius }
    }

    pub(super) fn mean_radius(&self) -> f32 {
        self.items.iter().map(|i| i.radius).sum::<f32>() / self.items.len() as f32
    }

    /// The triangles whose centroid's x is within `reach` + the largest
    /// radius of `p`'s: among them, all those within `reach` of `p`.
    fn window(&self, p: Vec3, reach: f32) -> &[Item] {
        let margin = reach + self.max_radius;
        let from = self.items.partition_point(|i| i.centre.x < p.x - margin);
        let to = self.items.partition_point(|i| i.centre.x <= p.x + margin);
        &self.items[from..to]
    }

    /// The triangles within `reach` of `p`.
    pub(super) fn within(&self, p: Vec3, reach: f32) -> impl Iterator<Item = u32> + '_ {
        self.window(p, reach)
            .iter()
            .filter(move |i| {
                let [a, b, c] = i.corners;
                p.distance(i.centre) - i.radius < reach
                    && closest_point(p, a, b, c).distance(p) < reach
            })
            .map(|i| i.index)
    }

    /// The triangle closest to `p`, searched within `reach`, then twice as
    /// far, and so on.
    pub(super) fn nearest(&self, p: Vec3, reach: f32) -> u32 {
        let mut reach = reach.max(f32::MIN_POSITIVE);
        loop {
            let (distance, index) = self
                .window(p, reach)
                .iter()
                .map(|i| {
                    let [a, b, c] = i.corners;
                    (closest_point(p, a, b, c).distance(p), i.index)
                })
                .fold(
                    (f32::INFINITY, 0),
                    |best, x| if x.0 < best.0 { x } else { best },
                );
            // The window holds every triangle within `reach`; the whole list
            // once `reach` exceeds its span.
            if distance <= reach || self.window(p, reach).len() == self.items.len() {
                return index;
            }
            reach *= 2.0;
        }
    }
}

/// The point of triangle (a, b, c) closest to `p` (Ericson, "Real-Time
/// Collision Detection", §5.1.5).
fn closest_point(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}
