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

use crate::{Camera, Error, FrameGeometry, Image, Result, VertexRadiance};

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

/// [`clip_from_world`] with depth reversed: 1 at `near`, falling toward 0
/// at infinity (x and y the same, so that images line up). With a 32-bit
/// float depth buffer compared by `Greater`, depth keeps its precision far
/// from the eye, where surfaces a scene apart, seen from inside it with the
/// near plane close, would otherwise fight.
pub fn reversed_clip_from_world(camera: &Camera, near: f32) -> Mat4 {
    glam::camera::rh::proj::directx::perspective_infinite_reverse(
        camera.fov_y,
        camera.aspect(),
        near,
    ) * camera.view()
}

/// The near plane the rasterizer clips `frame` at: 10⁻⁵ of the distance
/// from the camera's eye to the farthest corner of the frame's bounds. A GPU
/// renderer drawing the same images takes it too.
pub fn near_plane(camera: &Camera, frame: &FrameGeometry) -> f32 {
    let bounds = frame.bounds();
    let farthest = (camera.eye - bounds.center()).abs() + bounds.extent() * 0.5;
    (farthest.length() * 1e-5).max(f32::MIN_POSITIVE)
}

/// The visible surface at every pixel centre of `camera`'s image, row 0 at
/// the top, `None` where no triangle is seen.
///
/// The near plane sits at [`near_plane`]; surfaces closer to the eye are
/// clipped.
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

/// The `render` stage of a per-vertex method: `shading`, what its `shade`
/// returned toward the camera's eye, interpolated over the visible
/// triangles of `frame`, the frame of its last `update`. No frame (no
/// update yet) is a stage error naming `method`.
pub fn render_shading(
    method: &str,
    camera: &Camera,
    frame: Option<&FrameGeometry>,
    shading: &VertexRadiance,
) -> Result<Image> {
    let frame = frame.ok_or_else(|| Error::stage(method, "render before update"))?;
    render_vertex_colors(camera, frame, &shading.radiance)
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
        Ok(Viewport {
            clip_from_world: clip_from_world(camera, near_plane(camera, frame)).as_dmat4(),
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
mod tests;
