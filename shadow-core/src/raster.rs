//! A CPU rasterizer for the `render` stage of per-vertex methods: which
//! triangle is visible through each pixel, and images that interpolate
//! per-vertex radiance over those triangles (DESIGN.md, stage 5).
//!
//! It agrees with [`Camera::ray_direction`]: pixels are sampled at their
//! centres through the same perspective projection ([`clip_from_world`]), so
//! the ray through a covered pixel hits the triangle the rasterizer reports
//! there. The rules are those of a GPU rasterizer, so that images do not
//! depend on how a mesh is split into triangles:
//!
//! * triangles are clipped in homogeneous space against the near plane (and a
//!   guard band far outside the image, which keeps screen coordinates bounded);
//! * vertices are snapped to 1/256 pixel and edge functions are evaluated in
//!   exact integer arithmetic with the top-left fill rule, so a pixel centre on
//!   an edge shared by two triangles belongs to exactly one of them: no cracks,
//!   no double coverage;
//! * the surface point at a pixel centre is computed exactly, in homogeneous
//!   coordinates from the unclipped triangle (perspective-correct, untouched by
//!   clipping and snapping), and the depth test keeps the largest 1/w, the
//!   nearest surface; on exact ties the triangle drawn first (lower object,
//!   then lower triangle index) wins;
//! * both faces are drawn (no back-face culling: scenes have open meshes).
//!
//! Rows are rasterized in bands in parallel with rayon.

use glam::{DMat3, DMat4, DVec3, DVec4, Mat4, Vec3, Vec4Swizzles};
use rayon::prelude::*;

use crate::{Camera, Error, FrameGeometry, Image, Result};

/// The largest image width or height the rasterizer accepts: with 8 bits of
/// sub-pixel precision and the guard band, edge functions of larger images
/// would overflow 64-bit integers.
pub const MAX_IMAGE_SIZE: u32 = 1 << 16;

/// Sub-pixel precision: vertices snap to 1/256 pixel.
const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;

/// Triangles are clipped to |x|, |y| ≤ `GUARD_BAND` · w in clip space, eight
/// times the view in normalized device coordinates; beyond it nothing is
/// visible and screen coordinates stay within i32 after snapping.
const GUARD_BAND: f64 = 8.0;

/// Rows per parallel band.
const BAND_ROWS: usize = 16;

/// The surface seen through one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Index of the object in the frame.
    pub object: u32,
    /// Index of the triangle in the object's mesh ([`crate::Mesh::triangles`]).
    pub triangle: u32,
    /// Weights of the triangle's three vertices at the point the pixel
    /// centre's ray meets it (perspective-correct); they sum to one and are
    /// clamped to [0, 1], since a centre within 1/512 pixel of an edge may be
    /// covered by the snapped triangle without lying on the exact one.
    pub barycentric: Vec3,
    /// World-space position of the surface point.
    pub position: Vec3,
    /// Interpolated vertex normal, unit length, not flipped toward the camera
    /// (back faces keep the normal of their front).
    pub normal: Vec3,
}

/// The world-to-clip matrix of `camera` in wgpu's conventions (directx NDC:
/// x, y in [−1, 1] with +y up, depth 0 at `near` rising toward 1 at infinity),
/// consistent with [`Camera::ray_direction`]: pixel (x, y) covers NDC
/// x ∈ [2x/W − 1, 2(x+1)/W − 1] and y ∈ [1 − 2(y+1)/H, 1 − 2y/H].
/// `near` must be positive. GPU renderers use it so that their images line up
/// with the rasterizer's and the reference's.
pub fn clip_from_world(camera: &Camera, near: f32) -> Mat4 {
    glam::camera::rh::proj::directx::perspective_infinite(camera.fov_y, camera.aspect(), near)
        * camera.view()
}

/// The visible surface at every pixel centre of `camera`'s image, row 0 at
/// the top, `None` where no triangle is seen.
///
/// The near plane sits at 10⁻⁵ of the distance from the eye to the farthest
/// corner of the frame's bounds; surfaces closer to the eye are clipped.
/// Fails if the image is larger than [`MAX_IMAGE_SIZE`] in either direction.
pub fn visible_surface(camera: &Camera, frame: &FrameGeometry) -> Result<Vec<Option<SurfaceHit>>> {
    let viewport = Viewport::new(camera, frame)?;
    let triangles: Vec<ScreenTriangle> = frame
        .objects
        .par_iter()
        .enumerate()
        .flat_map_iter(|(o, object)| {
            let positions = object.positions();
            object
                .triangles()
                .iter()
                .enumerate()
                .flat_map(move |(t, tri)| {
                    let corners = tri.map(|v| positions[v as usize]);
                    viewport.setup(o as u32, t as u32, corners)
                })
        })
        .collect();

    let width = camera.width as usize;
    let mut hits = vec![None; width * camera.height as usize];
    hits.par_chunks_mut(width * BAND_ROWS)
        .enumerate()
        .for_each(|(band, out)| {
            let first_row = (band * BAND_ROWS) as i64;
            let rows = first_row..first_row + (out.len() / width) as i64;
            let mut depth = vec![0.0f64; out.len()];
            let mut nearest: Vec<Option<(usize, Vec3)>> = vec![None; out.len()];
            for (index, triangle) in triangles.iter().enumerate() {
                rasterize(triangle, rows.clone(), |x, y, inverse_w, barycentric| {
                    let pixel = (y - first_row) as usize * width + x as usize;
                    if inverse_w > depth[pixel] {
                        depth[pixel] = inverse_w;
                        nearest[pixel] = Some((index, barycentric));
                    }
                });
            }
            for (hit, fragment) in out.iter_mut().zip(nearest) {
                *hit = fragment.map(|(index, barycentric)| {
                    let triangle = &triangles[index];
                    surface_hit(frame, triangle.object, triangle.triangle, barycentric)
                });
            }
        });
    Ok(hits)
}

/// An image of per-vertex colours (`colors[object][vertex]`, e.g. a method's
/// per-vertex outgoing radiance) interpolated over the visible triangles;
/// uncovered pixels are black and not `covered`.
///
/// Fails if `colors` does not have one colour per vertex of every object of
/// `frame`, or if the image is too large ([`visible_surface`]).
pub fn render_vertex_colors(
    camera: &Camera,
    frame: &FrameGeometry,
    colors: &[Vec<Vec3>],
) -> Result<Image> {
    if colors.len() != frame.objects.len() {
        return Err(Error::InvalidScene(format!(
            "render_vertex_colors: {} colour lists for {} objects",
            colors.len(),
            frame.objects.len()
        )));
    }
    for (o, (object, object_colors)) in frame.objects.iter().zip(colors).enumerate() {
        if object_colors.len() != object.vertex_count() {
            return Err(Error::InvalidScene(format!(
                "render_vertex_colors: object {o} ({}) has {} vertices but {} colours",
                object.name(),
                object.vertex_count(),
                object_colors.len()
            )));
        }
    }
    let hits = visible_surface(camera, frame)?;
    let pixels = hits
        .iter()
        .map(|hit| match hit {
            None => Vec3::ZERO,
            Some(hit) => {
                let object = hit.object as usize;
                let tri = frame.objects[object].triangles()[hit.triangle as usize];
                let c = tri.map(|v| colors[object][v as usize]);
                c[0] * hit.barycentric.x + c[1] * hit.barycentric.y + c[2] * hit.barycentric.z
            }
        })
        .collect();
    Ok(Image {
        width: camera.width,
        height: camera.height,
        pixels,
        covered: hits.iter().map(Option::is_some).collect(),
        std_error: None,
    })
}

/// Position and normal of the surface point at `barycentric` on a triangle.
fn surface_hit(frame: &FrameGeometry, object: u32, triangle: u32, barycentric: Vec3) -> SurfaceHit {
    let mesh = &frame.objects[object as usize];
    let tri = mesh.triangles()[triangle as usize];
    let p = tri.map(|v| mesh.positions()[v as usize]);
    let n = tri.map(|v| mesh.normals()[v as usize]);
    let b = barycentric;
    let position = p[0] * b.x + p[1] * b.y + p[2] * b.z;
    // Opposite vertex normals can cancel; fall back to the face normal.
    let normal = (n[0] * b.x + n[1] * b.y + n[2] * b.z)
        .try_normalize()
        .or_else(|| (p[1] - p[0]).cross(p[2] - p[0]).try_normalize())
        .unwrap_or(Vec3::Y);
    SurfaceHit {
        object,
        triangle,
        barycentric,
        position,
        normal,
    }
}

/// Signed distances of a clip-space point to the clip planes, non-negative
/// inside: the near plane (directx depth ≥ 0) and the four guard-band planes.
fn plane_distances(c: DVec4) -> [f64; 5] {
    let g = GUARD_BAND * c.w;
    [c.z, g - c.x, g + c.x, g - c.y, g + c.y]
}

/// Sutherland–Hodgman clipping of a convex clip-space polygon against plane
/// `plane`. An intersection is always computed from the inside vertex toward
/// the outside one, so an edge shared by two triangles is cut at bit-identical
/// points in both: clipping opens no cracks.
fn clip_polygon(polygon: &[DVec4], plane: usize) -> Vec<DVec4> {
    let mut out = Vec::with_capacity(polygon.len() + 1);
    for (i, &current) in polygon.iter().enumerate() {
        let next = polygon[(i + 1) % polygon.len()];
        let d_current = plane_distances(current)[plane];
        let d_next = plane_distances(next)[plane];
        let cut = |inside: DVec4, d_in: f64, outside: DVec4, d_out: f64| {
            inside + (outside - inside) * (d_in / (d_in - d_out))
        };
        if d_current >= 0.0 {
            out.push(current);
            if d_next < 0.0 {
                out.push(cut(current, d_current, next, d_next));
            }
        } else if d_next >= 0.0 {
            out.push(cut(next, d_next, current, d_current));
        }
    }
    out
}

/// A vertex snapped to the sub-pixel grid (1/256 pixel, y down).
#[derive(Clone, Copy, Debug)]
struct ScreenVertex {
    x: i32,
    y: i32,
}

/// A triangle ready to rasterize: counter-clockwise on screen (positive area
/// in y-down coordinates), with its pixel bounds and the interpolation of
/// the original triangle it came from.
#[derive(Clone, Copy, Debug)]
struct ScreenTriangle {
    object: u32,
    triangle: u32,
    v: [ScreenVertex; 3],
    /// Inclusive bounds of the pixels whose centres it may cover.
    min: [i64; 2],
    max: [i64; 2],
    /// `q = x·dx + y·dy + origin` at pixel (x, y) is the original triangle's
    /// vertex weights divided by the depth w of the surface point there:
    /// Σq = 1/w and q/Σq are the perspective-correct weights.
    dx: DVec3,
    dy: DVec3,
    origin: DVec3,
}

/// The image plane of a camera for one frame.
#[derive(Clone, Copy, Debug)]
struct Viewport {
    clip_from_world: DMat4,
    width: f64,
    height: f64,
}

impl Viewport {
    fn new(camera: &Camera, frame: &FrameGeometry) -> Result<Viewport> {
        if camera.width > MAX_IMAGE_SIZE || camera.height > MAX_IMAGE_SIZE {
            return Err(Error::InvalidScene(format!(
                "camera image {}×{} exceeds the rasterizer's {MAX_IMAGE_SIZE}-pixel limit",
                camera.width, camera.height
            )));
        }
        let bounds = frame.bounds();
        let farthest = (camera.eye - bounds.center()).abs() + bounds.extent() * 0.5;
        let near = (farthest.length() * 1e-5).max(f32::MIN_POSITIVE);
        Ok(Viewport {
            clip_from_world: clip_from_world(camera, near).as_dmat4(),
            width: f64::from(camera.width),
            height: f64::from(camera.height),
        })
    }

    /// Clips and projects one world-space triangle; yields the screen
    /// triangles of its clipped polygon (none if it is outside the view,
    /// behind the near plane or seen edge-on).
    ///
    /// Coverage comes from the clipped, snapped polygon; the weights come from
    /// the unclipped triangle in homogeneous coordinates (Olano and Greer
    /// 1997): with M the matrix of its clip-space (x, y, w) columns,
    /// M⁻¹ (x_ndc, y_ndc, 1) = weights / w exactly, so neither clipping nor
    /// snapping moves the surface point seen through a pixel centre.
    fn setup(&self, object: u32, triangle: u32, corners: [Vec3; 3]) -> Vec<ScreenTriangle> {
        let clip = corners.map(|p| self.clip_from_world * p.as_dvec3().extend(1.0));
        let homogeneous = DMat3::from_cols(clip[0].xyw(), clip[1].xyw(), clip[2].xyw());
        let Some(inverse) = homogeneous.try_inverse() else {
            return Vec::new();
        };
        let distances = clip.map(plane_distances);
        let mut polygon = clip.to_vec();
        for plane in 0..5 {
            if distances.iter().all(|d| d[plane] < 0.0) {
                return Vec::new();
            }
            if distances.iter().any(|d| d[plane] < 0.0) {
                polygon = clip_polygon(&polygon, plane);
            }
        }
        if polygon.len() < 3 {
            return Vec::new();
        }
        // Pixel (x, y) has its centre at NDC ((2x + 1)/W − 1, 1 − (2y + 1)/H).
        let (sx, sy) = (2.0 / self.width, -2.0 / self.height);
        let centre = DVec3::new(1.0 / self.width - 1.0, 1.0 - 1.0 / self.height, 1.0);
        let (dx, dy, origin) = (inverse.x_axis * sx, inverse.y_axis * sy, inverse * centre);
        let screen: Vec<ScreenVertex> = polygon.iter().map(|&c| self.snap(c)).collect();
        (1..screen.len() - 1)
            .filter_map(|i| {
                let mut v = [screen[0], screen[i], screen[i + 1]];
                let (min, max) = self.bounds(&mut v)?;
                Some(ScreenTriangle {
                    object,
                    triangle,
                    v,
                    min,
                    max,
                    dx,
                    dy,
                    origin,
                })
            })
            .collect()
    }

    /// Clip space to pixel coordinates (pixel (0, 0) at the top left, its
    /// centre at (½, ½)) snapped to the sub-pixel grid. Inside the guard band
    /// and in front of the near plane, w > 0 and the result fits in i32.
    fn snap(&self, c: DVec4) -> ScreenVertex {
        let x = (c.x / c.w * 0.5 + 0.5) * self.width;
        let y = (0.5 - c.y / c.w * 0.5) * self.height;
        let snap = |p: f64| (p * SUBPIXEL as f64).round() as i32;
        ScreenVertex {
            x: snap(x),
            y: snap(y),
        }
    }

    /// Puts the vertices in counter-clockwise order and returns the inclusive
    /// pixel bounds of the centres they may cover; `None` for zero area or
    /// no pixels.
    fn bounds(&self, v: &mut [ScreenVertex; 3]) -> Option<([i64; 2], [i64; 2])> {
        let area = edge(&v[0], &v[1], i64::from(v[2].x), i64::from(v[2].y));
        if area == 0 {
            return None;
        }
        if area < 0 {
            // A back face (or a clockwise front face): both are drawn.
            v.swap(1, 2);
        }
        let xs = v.map(|p| i64::from(p.x));
        let ys = v.map(|p| i64::from(p.y));
        // Pixel centres c·SUBPIXEL + half inside [lo, hi].
        let half = SUBPIXEL / 2;
        let first = |lo: i64| -(half - lo).div_euclid(SUBPIXEL);
        let last = |hi: i64| (hi - half).div_euclid(SUBPIXEL);
        let min = [
            first(*xs.iter().min()?).max(0),
            first(*ys.iter().min()?).max(0),
        ];
        let max = [
            last(*xs.iter().max()?).min(self.width as i64 - 1),
            last(*ys.iter().max()?).min(self.height as i64 - 1),
        ];
        (min[0] <= max[0] && min[1] <= max[1]).then_some((min, max))
    }
}

/// The edge function of a → b at the point (px, py), in sub-pixel units
/// squared: twice the signed area of (a, b, p), positive when p is on the
/// inner side of a counter-clockwise (in y-down coordinates) triangle.
fn edge(a: &ScreenVertex, b: &ScreenVertex, px: i64, py: i64) -> i64 {
    let (ax, ay, bx, by) = (
        i64::from(a.x),
        i64::from(a.y),
        i64::from(b.x),
        i64::from(b.y),
    );
    (bx - ax) * (py - ay) - (by - ay) * (px - ax)
}

/// Top-left rule: a pixel centre exactly on an edge belongs to the triangle
/// if the edge is a top edge (horizontal, interior below) or a left edge.
/// Two triangles sharing an edge traverse it in opposite directions, so
/// exactly one of them owns it.
fn owns_edge(a: &ScreenVertex, b: &ScreenVertex) -> bool {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    dy < 0 || (dy == 0 && dx > 0)
}

/// Calls `visit(x, y, 1/w, weights)` for every pixel of `rows` whose centre
/// the triangle covers, with the depth and perspective-correct vertex
/// weights of the surface point seen through the pixel centre. Weights are
/// clamped to the triangle (a covered centre can lie outside the exact
/// triangle by the snapping, 1/512 pixel) so that attributes are never
/// extrapolated.
fn rasterize(
    triangle: &ScreenTriangle,
    rows: std::ops::Range<i64>,
    mut visit: impl FnMut(i64, i64, f64, Vec3),
) {
    let y_start = triangle.min[1].max(rows.start);
    let y_end = (triangle.max[1] + 1).min(rows.end);
    if y_start >= y_end {
        return;
    }
    let v = &triangle.v;
    let half = SUBPIXEL / 2;
    let (px, py) = (triangle.min[0] * SUBPIXEL + half, y_start * SUBPIXEL + half);
    // Edge k runs between the two vertices other than k; a pixel is inside
    // when every edge value is positive, or zero on an owned edge (bias 0
    // instead of −1).
    let mut row_values = [0i64; 3];
    let mut step_x = [0i64; 3];
    let mut step_y = [0i64; 3];
    let mut bias = [0i64; 3];
    for (k, (a, b)) in [(1, 2), (2, 0), (0, 1)].into_iter().enumerate() {
        row_values[k] = edge(&v[a], &v[b], px, py);
        step_x[k] = -i64::from(v[b].y - v[a].y) * SUBPIXEL;
        step_y[k] = i64::from(v[b].x - v[a].x) * SUBPIXEL;
        bias[k] = if owns_edge(&v[a], &v[b]) { 0 } else { -1 };
    }
    for y in y_start..y_end {
        let mut e = row_values;
        for x in triangle.min[0]..=triangle.max[0] {
            if (0..3).all(|k| e[k] + bias[k] >= 0) {
                let q = triangle.dx * x as f64 + triangle.dy * y as f64 + triangle.origin;
                let inverse_w = q.element_sum();
                // Covered centres are in front of the near plane (1/w > 0);
                // the test only guards the division against rounding.
                if inverse_w > 0.0 {
                    let weights = (q / inverse_w).max(DVec3::ZERO);
                    visit(x, y, inverse_w, (weights / weights.element_sum()).as_vec3());
                }
            }
            for k in 0..3 {
                e[k] += step_x[k];
            }
        }
        for k in 0..3 {
            row_values[k] += step_y[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Brdf, Mesh, Object, Scene};
    use std::sync::Arc;

    fn camera(eye: Vec3, target: Vec3, width: u32, height: u32) -> Camera {
        Camera::new(eye, target, Vec3::Y, 50f32.to_radians(), width, height).unwrap()
    }

    /// A frame of meshes given as (positions, triangles), at rest.
    fn frame(meshes: Vec<(Vec<Vec3>, Vec<[u32; 3]>)>) -> FrameGeometry {
        let objects = meshes
            .into_iter()
            .enumerate()
            .map(|(i, (positions, triangles))| Object {
                mesh: Arc::new(Mesh::new(format!("m{i}"), positions, None, triangles).unwrap()),
                material: Brdf::lambert(Vec3::ONE).unwrap(),
            })
            .collect();
        let cam = camera(Vec3::Z, Vec3::ZERO, 4, 4);
        Scene::still("test", objects, cam)
            .unwrap()
            .frame_geometry(0)
            .unwrap()
    }

    fn quad(corners: [Vec3; 4]) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
    }

    /// Where the ray from `origin` along `dir` meets triangle `p`: (distance,
    /// barycentric weights), double-sided, or None.
    fn intersect(origin: Vec3, dir: Vec3, p: [Vec3; 3]) -> Option<(f32, Vec3)> {
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let h = dir.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-12 {
            return None;
        }
        let s = origin - p[0];
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let t = e2.dot(q) / det;
        Some((t, Vec3::new(1.0 - u - v, u, v)))
    }

    fn corners(frame: &FrameGeometry, hit: &SurfaceHit) -> [Vec3; 3] {
        let mesh = &frame.objects[hit.object as usize];
        mesh.triangles()[hit.triangle as usize].map(|v| mesh.positions()[v as usize])
    }

    #[test]
    fn full_screen_quad_interpolates_affine_colours_exactly() {
        // A slanted plane larger than the view: every pixel is covered, and a
        // colour that is an affine function of position must come out as that
        // function at the point the pixel's ray hits (perspective-correct).
        let corners = [
            Vec3::new(-60.0, -60.0, -5.0),
            Vec3::new(60.0, -60.0, -45.0),
            Vec3::new(60.0, 60.0, -45.0),
            Vec3::new(-60.0, 60.0, -5.0),
        ];
        let f = frame(vec![quad(corners)]);
        let colour = |p: Vec3| Vec3::new(0.1 * p.x + 3.0, 0.05 * p.y + 2.0, -0.1 * p.z);
        let colours = vec![
            f.objects[0]
                .positions()
                .iter()
                .map(|&p| colour(p))
                .collect(),
        ];
        let cam = camera(Vec3::ZERO, Vec3::new(0.2, 0.1, -1.0), 40, 30);
        let image = render_vertex_colors(&cam, &f, &colours).unwrap();
        assert!(image.covered.iter().all(|&c| c));
        for y in 0..cam.height {
            for x in 0..cam.width {
                let dir = cam.ray_direction(x, y);
                let (t, _) = [
                    [corners[0], corners[1], corners[2]],
                    [corners[0], corners[2], corners[3]],
                ]
                .iter()
                .filter_map(|&tri| intersect(cam.eye, dir, tri))
                .find(|(_, b)| b.min_element() >= -1e-4)
                .unwrap();
                let expected = colour(cam.eye + dir * t);
                let got = image.pixels[(y * cam.width + x) as usize];
                assert!(
                    (got - expected).abs().max_element() < 2e-4 * expected.abs().max_element(),
                    "({x}, {y}): {got} vs {expected}"
                );
            }
        }
        // A vertex-coloured corner trend: red toward the left, green toward the top.
        let trend = vec![vec![Vec3::X, Vec3::ZERO, Vec3::Y, Vec3::X + Vec3::Y]];
        let image = render_vertex_colors(&cam, &f, &trend).unwrap();
        let at = |x: u32, y: u32| image.pixels[(y * cam.width + x) as usize];
        assert!(at(0, 15).x > at(39, 15).x && at(20, 0).y > at(20, 29).y);
    }

    #[test]
    fn nearer_triangle_wins_in_either_order() {
        let near = (
            vec![
                Vec3::new(-1.0, -1.0, -2.0),
                Vec3::new(1.0, -1.0, -2.0),
                Vec3::new(0.0, 1.0, -2.0),
            ],
            vec![[0, 1, 2]],
        );
        let far = (
            vec![
                Vec3::new(-3.0, -3.0, -4.0),
                Vec3::new(3.0, -3.0, -4.0),
                Vec3::new(0.0, 3.0, -4.0),
            ],
            vec![[0, 1, 2]],
        );
        let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 32, 32);
        for (nearer, f) in [
            (0, frame(vec![near.clone(), far.clone()])),
            (1, frame(vec![far, near])),
        ] {
            let hits = visible_surface(&cam, &f).unwrap();
            let centre = hits[16 * 32 + 16].unwrap();
            assert_eq!(centre.object, nearer);
            assert!((centre.position.z + 2.0).abs() < 1e-5);
            // Both objects are visible somewhere: the far one around the near one.
            assert!(hits.iter().flatten().any(|h| h.object != nearer));
        }
    }

    /// Pixels covered by each part of a split polygon: no pixel twice, and
    /// every pixel whose centre lies clearly inside the polygon once.
    fn assert_watertight(
        cam: &Camera,
        f: &FrameGeometry,
        inside: impl Fn(f64, f64) -> Option<bool>,
    ) {
        let viewport = Viewport::new(cam, f).unwrap();
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut count = vec![0u32; w * h];
        for object in &f.objects {
            for (t, tri) in object.triangles().iter().enumerate() {
                for s in viewport.setup(0, t as u32, tri.map(|v| object.positions()[v as usize])) {
                    rasterize(&s, 0..h as i64, |x, y, _, _| {
                        count[y as usize * w + x as usize] += 1
                    });
                }
            }
        }
        for y in 0..h {
            for x in 0..w {
                let c = count[y * w + x];
                assert!(c <= 1, "pixel ({x}, {y}) written {c} times");
                if let Some(expected) = inside(x as f64 + 0.5, y as f64 + 0.5) {
                    assert_eq!(c == 1, expected, "pixel ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn shared_edges_are_covered_exactly_once() {
        // Orthogonal view of the plane z = -1 through a 90° field of view:
        // pixel (x, y) of an N×N image is world (2(x)/N − 1, 1 − 2y/N) at its
        // corner, so vertices land exactly on pixel centres and edges run
        // through rows and columns of centres: the ties the fill rule decides.
        let n = 16u32;
        let cam = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90f32.to_radians(), n, n).unwrap();
        let world = |px: f32, py: f32| {
            Vec3::new(2.0 * px / n as f32 - 1.0, 1.0 - 2.0 * py / n as f32, -1.0)
        };
        // An axis-aligned quad with corners on pixel centres, split on its diagonal.
        let (a, b) = (2.5, 12.5);
        let square = quad([world(a, b), world(b, b), world(b, a), world(a, a)]);
        let f = frame(vec![square]);
        // Top-left rule: centres on the top and left edges are in, those on
        // the bottom and right edges out.
        let (a64, b64) = (f64::from(a), f64::from(b));
        assert_watertight(&cam, &f, |x, y| {
            Some((a64..b64).contains(&x) && (a64..b64).contains(&y))
        });
        // A fan of eight triangles around a vertex on a pixel centre, with
        // spokes through centres at 0°, 45°, 90°, ...: no centre is lost or
        // counted twice.
        let centre = world(8.5, 8.5);
        let mut positions = vec![centre];
        for k in 0..8 {
            let angle = k as f32 * std::f32::consts::FRAC_PI_4;
            let r = if k % 2 == 0 {
                6.0
            } else {
                6.0 * std::f32::consts::SQRT_2
            };
            positions.push(world(8.5 + r * angle.cos(), 8.5 - r * angle.sin()));
        }
        let triangles = (0..8).map(|k| [0, 1 + k, 1 + (k + 1) % 8]).collect();
        let f = frame(vec![(positions, triangles)]);
        assert_watertight(&cam, &f, |x, y| {
            let (dx, dy) = ((x - 8.5).abs(), (y - 8.5).abs());
            if dx < 5.9 && dy < 5.9 {
                Some(true)
            } else if dx > 6.1 || dy > 6.1 {
                Some(false)
            } else {
                None
            }
        });
        // A rotated, perspective quad split the other way.
        let tilted = quad([
            Vec3::new(-0.7, -0.3, -1.5),
            Vec3::new(0.4, -0.8, -2.5),
            Vec3::new(0.8, 0.6, -2.0),
            Vec3::new(-0.3, 0.7, -1.2),
        ]);
        let f = frame(vec![tilted]);
        assert_watertight(&cam, &f, |_, _| None);
    }

    #[test]
    fn coverage_matches_projected_area_from_both_sides() {
        let p = [
            Vec3::new(-0.9, -0.6, -3.0),
            Vec3::new(1.1, -0.2, -4.0),
            Vec3::new(0.1, 0.9, -2.5),
        ];
        let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 64, 48);
        let view = clip_from_world(&cam, 0.1);
        let pixel = |q: Vec3| {
            let c = view * q.extend(1.0);
            glam::DVec2::new(
                ((c.x / c.w) as f64 * 0.5 + 0.5) * 64.0,
                (0.5 - (c.y / c.w) as f64 * 0.5) * 48.0,
            )
        };
        let s = p.map(pixel);
        let area = ((s[1] - s[0]).perp_dot(s[2] - s[0]) * 0.5).abs();
        let perimeter = (s[1] - s[0]).length() + (s[2] - s[1]).length() + (s[0] - s[2]).length();
        for triangle in [[0, 1, 2], [0, 2, 1]] {
            let f = frame(vec![(p.to_vec(), vec![triangle])]);
            let covered = visible_surface(&cam, &f).unwrap().iter().flatten().count() as f64;
            // Only pixels along the edges can differ from the area, each by
            // less than one.
            assert!(
                (covered - area).abs() < perimeter * 0.75,
                "{covered} pixels for area {area}"
            );
            assert!(covered > 100.0);
        }
    }

    #[test]
    fn pixel_rays_hit_the_rasterized_triangle() {
        // Overlapping triangles at several depths and slants.
        let f = frame(vec![
            (
                vec![
                    Vec3::new(-1.5, -1.0, -3.0),
                    Vec3::new(1.0, -1.2, -5.0),
                    Vec3::new(0.2, 1.4, -2.0),
                ],
                vec![[0, 1, 2]],
            ),
            quad([
                Vec3::new(-2.0, -0.5, -6.0),
                Vec3::new(2.0, -0.5, -2.5),
                Vec3::new(2.0, 0.5, -2.5),
                Vec3::new(-2.0, 0.5, -6.0),
            ]),
        ]);
        let cam = camera(Vec3::new(0.1, 0.2, 0.5), Vec3::new(0.0, 0.0, -3.0), 48, 36);
        let hits = visible_surface(&cam, &f).unwrap();
        let mut checked = 0;
        for y in 0..cam.height {
            for x in 0..cam.width {
                let dir = cam.ray_direction(x, y);
                let nearest =
                    f.objects
                        .iter()
                        .enumerate()
                        .flat_map(|(o, mesh)| {
                            mesh.triangles().iter().enumerate().map(move |(t, tri)| {
                                (o, t, tri.map(|v| mesh.positions()[v as usize]))
                            })
                        })
                        .filter_map(|(o, t, tri)| {
                            intersect(cam.eye, dir, tri).map(|(d, b)| (o, t, d, b))
                        })
                        .filter(|&(_, _, d, b)| d > 0.0 && b.min_element() >= 0.0)
                        .min_by(|a, b| a.2.total_cmp(&b.2));
                let hit = hits[(y * cam.width + x) as usize];
                match (hit, nearest) {
                    (Some(hit), Some((o, t, _, b))) => {
                        // The ray meets the reported triangle where the
                        // rasterizer says (same weights, same point).
                        let (d, weights) = intersect(cam.eye, dir, corners(&f, &hit)).unwrap();
                        assert!(
                            (weights - hit.barycentric).abs().max_element() < 1e-3,
                            "({x}, {y})"
                        );
                        assert!((cam.eye + dir * d - hit.position).length() < 1e-3);
                        // Away from edges, it is also the nearest triangle.
                        if b.min_element() > 1e-3 && weights.min_element() > 1e-3 {
                            assert_eq!(
                                (hit.object, hit.triangle),
                                (o as u32, t as u32),
                                "({x}, {y})"
                            );
                            checked += 1;
                        }
                    }
                    (None, None) => {}
                    (hit, nearest) => {
                        // Only pixels whose ray grazes an edge may disagree.
                        let margin = nearest.map_or(0.0, |n| n.3.min_element());
                        assert!(margin < 1e-3, "({x}, {y}): raster {hit:?}, ray {nearest:?}");
                    }
                }
            }
        }
        assert!(checked > 500, "{checked}");
    }

    #[test]
    fn triangles_behind_the_camera_are_clipped_not_wrapped() {
        // A floor reaching behind the eye: the lower half of the image sees
        // it, the upper half sees nothing, and the floor point under each
        // covered pixel is where its ray meets the floor.
        let f = frame(vec![quad([
            Vec3::new(-50.0, 0.0, 50.0),
            Vec3::new(50.0, 0.0, 50.0),
            Vec3::new(50.0, 0.0, -50.0),
            Vec3::new(-50.0, 0.0, -50.0),
        ])]);
        let cam = camera(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.9, -1.0), 32, 32);
        let hits = visible_surface(&cam, &f).unwrap();
        for y in 0..cam.height {
            for x in 0..cam.width {
                let dir = cam.ray_direction(x, y);
                let t = -cam.eye.y / dir.y;
                let on_floor = dir.y < 0.0 && (cam.eye + dir * t).abs().max_element() < 50.0;
                let hit = hits[(y * cam.width + x) as usize];
                assert_eq!(hit.is_some(), on_floor, "({x}, {y})");
                if let Some(hit) = hit {
                    assert!(
                        (hit.position - (cam.eye + dir * t)).length() < 1e-4 * t,
                        "({x}, {y}): {hit:?}"
                    );
                    assert!((hit.normal - Vec3::Y).length() < 1e-5);
                }
            }
        }
        // A triangle entirely behind the eye draws nothing.
        let behind = frame(vec![(
            vec![
                Vec3::new(-1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 1.0, 1.0),
            ],
            vec![[0, 1, 2]],
        )]);
        let cam = camera(Vec3::ZERO, Vec3::NEG_Z, 8, 8);
        assert!(
            visible_surface(&cam, &behind)
                .unwrap()
                .iter()
                .all(Option::is_none)
        );
    }

    #[test]
    fn bad_inputs_are_errors() {
        let f = frame(vec![(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])]);
        let cam = camera(Vec3::Z, Vec3::ZERO, 8, 8);
        assert!(render_vertex_colors(&cam, &f, &[]).is_err());
        let message = render_vertex_colors(&cam, &f, &[vec![Vec3::ONE; 2]])
            .unwrap_err()
            .to_string();
        assert!(message.contains("3 vertices but 2 colours"), "{message}");
        let huge = camera(Vec3::Z, Vec3::ZERO, MAX_IMAGE_SIZE + 1, 1);
        assert!(visible_surface(&huge, &f).is_err());
    }
}
