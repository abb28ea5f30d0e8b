//! The stability atlas's stress scenes: small scenes, each built to break
//! something a shadow method relies on (a depth bias, a ray offset, horizon
//! clipping, back-face culling, f32 precision at extreme scales, per-vertex
//! resolution, SH truncation under a point-like light).
//!
//! Each is small (28 to about 1500 vertices) so that a converged reference
//! takes seconds, and comes with the environment it is meant to be seen
//! under. Only `interpenetrating` moves (4 frames); the others have 1.

use std::{collections::HashMap, f32::consts::TAU, sync::Arc};

use glam::{Affine3A, Vec3};
use shadow_core::{
    Camera, Environment, Frame, Mesh, Object, Pose, Result, Scene, environment::luminance, shapes,
};

use super::{framed, still, white};

/// A stress scene, what it is built to break, and its environment.
#[derive(Clone, Debug)]
pub struct StressScene {
    pub name: &'static str,
    /// One sentence: what the scene is built to break.
    pub breaks: &'static str,
    pub scene: Scene,
    pub environment: Environment,
}

/// Every stress scene's name and what it is built to break.
pub const STRESS_SCENES: &[(&str, &str)] = &[
    (
        "thin-sheets",
        "depth biases and ray offsets: a box 1 mm thick and two parallel faces 2 mm apart over a floor must shadow it without leaking light or shadowing themselves",
    ),
    (
        "horizon-blocker",
        "horizon clipping: a long wall 2 cm high at the far edge of a floor, lit mostly by a band just above the horizon, blocks light that arrives within a few degrees of the receivers' tangent plane",
    ),
    (
        "interpenetrating",
        "closed-mesh assumptions: a sphere moving through a box over 4 frames buries vertices of each inside the other, where only back faces are seen",
    ),
    (
        "near-contact",
        "contact offsets: a sphere resting 1e-3 of its radius above a floor and another touching it at a floor vertex",
    ),
    (
        "tiny-scale",
        "absolute epsilons: a sphere on a floor 1 mm across",
    ),
    (
        "huge-scale",
        "absolute epsilons and f32 precision: a sphere on a floor 10 km across",
    ),
    (
        "slivers",
        "triangle quality: a fan of needle triangles (aspect ratio above 1e3) with zero-area triangles among them hovers over a floor",
    ),
    (
        "coarse",
        "per-vertex resolution: a 12-triangle box on a 2-triangle floor, whose contact shadow falls between vertices",
    ),
    (
        "sun-only",
        "SH truncation and sampling: a sphere on a floor under a black sky with one small sun holding all the light",
    ),
    (
        "scan-on-floor",
        "nothing: the plain twin of the three scenes after it, a 1 m scan (the 1.8k-vertex bunny) resting on a floor 3 m across under a sky fading to black at the horizon",
    ),
    (
        "large-floor",
        "tolerances taken from the whole scene: the same scan resting on a floor 200 m across, which must change nothing",
    ),
    (
        "far-away",
        "tolerances taken from the world's origin: the scan on its 3 m floor 10 km from the origin",
    ),
    (
        "scaled-up",
        "absolute tolerances and f32 range: the scan on its floor scaled by 10⁷",
    ),
];

/// The stress scenes that are another one moved, scaled or given a larger
/// floor, and that one, their plain twin: each must give what its twin
/// gives.
pub const TWINS: &[(&str, &str)] = &[
    ("large-floor", "scan-on-floor"),
    ("far-away", "scan-on-floor"),
    ("scaled-up", "scan-on-floor"),
];

/// The plain twin of stress scene `name`, if it has one ([`TWINS`]).
pub fn twin_of(name: &str) -> Option<&'static str> {
    TWINS.iter().find(|(s, _)| *s == name).map(|(_, t)| *t)
}

/// Where `far-away` stands: 10 km from the origin, off the axes.
pub const FAR_AWAY: Vec3 = Vec3::new(6000.0, 0.0, -8000.0);

/// How much larger `scaled-up` is than its twin.
pub const SCALED_UP: f32 = 1e7;

/// The floor of `large-floor`, in heights of the scan.
pub const LARGE_FLOOR: f32 = 200.0;

/// The kept triangles of the `slivers` fan: needles from one apex to 500
/// points along an edge 1 m away and 0.4 m long (8e-4 m apart).
pub const SLIVER_NEEDLES: usize = 500;

/// The zero-area triangles given to the `slivers` fan, which validation drops:
/// collinear triples along its far edge, repeated indices, and one spanned by
/// two distinct vertices at the same place.
pub const SLIVER_DEGENERATE: usize = SLIVER_NEEDLES / 2 + 3 + 1;

/// Overall size (largest extent of the bounds) of `tiny-scale` and
/// `huge-scale`, metres.
pub const TINY_SIZE: f32 = 1e-3;
pub const HUGE_SIZE: f32 = 1e4;

/// Every stress scene, in [`STRESS_SCENES`] order.
pub fn stress_scenes() -> Result<Vec<StressScene>> {
    STRESS_SCENES
        .iter()
        .map(|(name, _)| stress_scene(name))
        .collect()
}

/// A stress scene by name.
pub fn stress_scene(name: &str) -> Result<StressScene> {
    let Some(&(name, breaks)) = STRESS_SCENES.iter().find(|(n, _)| *n == name) else {
        return Err(super::unknown(
            name,
            "stress scene",
            STRESS_SCENES.iter().map(|s| s.0),
        ));
    };
    let uniform = || Environment::uniform(Vec3::ONE).renamed("uniform");
    let (scene, environment) = match name {
        "thin-sheets" => (thin_sheets(name)?, uniform()),
        "horizon-blocker" => (horizon_blocker(name)?, horizon_band()?),
        "interpenetrating" => (interpenetrating(name)?, uniform()),
        "near-contact" => (near_contact(name)?, uniform()),
        "tiny-scale" => (still(name, sphere_on_floor(TINY_SIZE, 15)?)?, uniform()),
        "huge-scale" => (still(name, sphere_on_floor(HUGE_SIZE, 15)?)?, uniform()),
        "slivers" => (slivers(name)?, uniform()),
        "coarse" => (coarse(name)?, uniform()),
        "sun-only" => (still(name, sphere_on_floor(1.0, 31)?)?, sun()?),
        "scan-on-floor" => (scan_on_floor(name, 3.0, Affine3A::IDENTITY)?, sky()?),
        "large-floor" => (
            scan_on_floor(name, LARGE_FLOOR, Affine3A::IDENTITY)?,
            sky()?,
        ),
        "far-away" => (
            scan_on_floor(name, 3.0, Affine3A::from_translation(FAR_AWAY))?,
            sky()?,
        ),
        "scaled-up" => (
            scan_on_floor(name, 3.0, Affine3A::from_scale(Vec3::splat(SCALED_UP)))?,
            sky()?,
        ),
        _ => unreachable!("every listed stress scene is built"),
    };
    Ok(StressScene {
        name,
        breaks,
        scene,
        environment,
    })
}

/// A floor 2 m across (16×16 cells), a box 1 mm thick at its left and two
/// parallel faces 2 mm apart (the lower facing down, the upper up, nothing
/// between them at the edges) at its right, both 0.25 m above it.
fn thin_sheets(name: &str) -> Result<Scene> {
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 16)?;
    let slab = closed_box(
        "slab-1mm",
        Vec3::new(-0.8, 0.25, -0.4),
        Vec3::new(-0.1, 0.251, 0.4),
        [8, 1, 8],
    )?;
    let (y0, y1) = (0.25, 0.252);
    let (x0, x1, z0, z1) = (0.1f32, 0.8f32, -0.4f32, 0.4f32);
    let cells = 8;
    let (dx, dz) = ((x1 - x0) / cells as f32, (z1 - z0) / cells as f32);
    // The lower face: X × Z points down; the upper: Z × X points up.
    let lower = shapes::grid(
        "lower",
        Vec3::new(x0, y0, z0),
        Vec3::X * dx,
        Vec3::Z * dz,
        cells,
        cells,
    )?;
    let upper = shapes::grid(
        "upper",
        Vec3::new(x0, y1, z0),
        Vec3::Z * dz,
        Vec3::X * dx,
        cells,
        cells,
    )?;
    let faces = joined("faces-2mm", &[lower, upper])?;
    still(name, vec![floor, slab, faces])
}

/// A floor 2 m across (24×24 cells) and, near its far edge (x from 0.84 to
/// 0.9 m, the whole depth), a closed wall 2 cm high: its top stands 0.6°
/// above the horizon of the floor's farthest vertices, under 5° for most.
fn horizon_blocker(name: &str) -> Result<Scene> {
    // 24 cells put floor vertices at x = 0.833 and 0.917: the wall stands
    // between them, burying none.
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 24)?;
    let wall = closed_box(
        "wall",
        Vec3::new(0.84, 0.0, -1.0),
        Vec3::new(0.9, 0.02, 1.0),
        [1, 1, 24],
    )?;
    still(name, vec![floor, wall])
}

/// The light of the scan and its twins: a sky whose radiance is the sine of
/// the elevation (1 at the zenith, 0 at the horizon) over a black ground.
/// Every direction a point of the scan sees below its floor's plane is dark
/// whether the floor reaches there or not, so the scan's true radiance is
/// the same on a 3 m floor as on a 200 m one, and a twin's error moves only
/// by what the method does. Under the whole white sphere the larger floor
/// takes light the smaller lets through (unshadowed's error 1.40× its
/// twin's), and a sky cut off at the horizon puts the methods' angular
/// resolution on the line where the twins differ (the large floor's edge
/// lies 0.2° below it): hemi-raster's direct integration 0.80% on the twin
/// and 2.42% on the large floor, occlusion-query with 1026 directions 0.68%
/// and 1.95%, though the truth is the same. Fading to zero, the sky holds
/// almost no light where either floor ends.
fn sky() -> Result<Environment> {
    procedural("sky", 256, 128, |d| Vec3::splat(d.y.max(0.0)))
}

/// The light of `horizon-blocker`: a dim sky (0.05) and a band 20 times
/// brighter than a white sky from the horizon to 4.3° above it (three rows of
/// a 256×128 map).
fn horizon_band() -> Result<Environment> {
    procedural("horizon-band", 256, 128, |d| {
        let elevation = d.y.asin().to_degrees();
        if (0.0..4.3).contains(&elevation) {
            Vec3::splat(20.0)
        } else {
            Vec3::splat(0.05)
        }
    })
}

/// A box (0.5 m, 6×6 cells a face) turning about +Y and a sphere (radius
/// 0.3 m) moving through it along X over 4 frames: in every frame each is
/// pushed into the other by at least 0.1 m.
fn interpenetrating(name: &str) -> Result<Scene> {
    let cube = closed_box("box", Vec3::splat(-0.25), Vec3::splat(0.25), [6, 6, 6])?;
    let sphere = sphere("sphere", Vec3::ZERO, 0.3)?;
    let objects = vec![object(cube), object(sphere)];
    let frames = (0..4)
        .map(|i| {
            let t = i as f32 / 3.0;
            Frame {
                time: 0.1 * i as f32,
                poses: vec![
                    Pose::Rigid(Affine3A::from_rotation_y(0.3 * t)),
                    Pose::Rigid(Affine3A::from_translation(Vec3::new(
                        -0.45 + 0.9 * t,
                        0.05,
                        0.0,
                    ))),
                ],
            }
        })
        .collect();
    framed(name, objects, frames)
}

/// Radius of the `near-contact` spheres.
const CONTACT_RADIUS: f32 = 0.25;

/// A floor 2 m across (20×20 cells, a vertex every 0.1 m), a sphere whose
/// lowest point (its pole vertex) hangs 1e-3 of its radius above the floor
/// vertex at x = −0.5, and one whose pole sits on the floor vertex at x = 0.5.
fn near_contact(name: &str) -> Result<Scene> {
    let r = CONTACT_RADIUS;
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 20)?;
    let lifted = sphere("sphere-lifted", Vec3::new(-0.5, r * (1.0 + 1e-3), 0.0), r)?;
    let touching = sphere("sphere-touching", Vec3::new(0.5, r, 0.0), r)?;
    still(name, vec![floor, lifted, touching])
}

/// A floor `size` across (`cells`×`cells`, odd so that no floor vertex lies
/// under the contact) and a sphere of radius 0.2 `size` resting on its centre.
fn sphere_on_floor(size: f32, cells: u32) -> Result<Vec<Mesh>> {
    let r = 0.2 * size;
    let floor = shapes::floor("floor", Vec3::ZERO, 0.5 * size, cells)?;
    Ok(vec![floor, sphere("sphere", Vec3::new(0.0, r, 0.0), r)?])
}

/// The shipped 1.8k-vertex bunny scaled to 1 m high, resting with its
/// lowest point on the centre of a two-triangle floor `floor` m across,
/// the whole then placed by `place` (a translation or a uniform scaling,
/// applied to the positions themselves, as a file placed there would hold
/// them). Normals are the asset's, turned with it. The camera is the plain
/// twin's, placed the same way, so that its images show the same view.
fn scan_on_floor(name: &str, floor: f32, place: Affine3A) -> Result<Scene> {
    let path = super::assets_dir().join("meshes/bunny_npm_1839v.glb");
    let (objects, _) = crate::gltf::GltfAsset::load(&path)?.to_scene_parts(white(), 30.0, 1)?;
    let scan = &objects[0].mesh;
    let bounds = scan.bounds();
    let scale = 1.0 / bounds.extent().y;
    let foot = Vec3::new(bounds.center().x, bounds.min.y, bounds.center().z);
    let fit = Affine3A::from_scale(Vec3::splat(scale)) * Affine3A::from_translation(-foot);
    let moved = |mesh: &Mesh, t: Affine3A| {
        let normal = t.matrix3.inverse().transpose();
        Mesh::new(
            mesh.name(),
            mesh.positions()
                .iter()
                .map(|&p| t.transform_point3(p))
                .collect(),
            Some(mesh.normals().iter().map(|&n| normal * n).collect()),
            mesh.triangles().to_vec(),
        )
    };
    let twin = Camera::framing(
        Vec3::new(0.0, 0.5, 0.0),
        0.5 * (3.0f32 * 3.0 + 3.0 * 3.0 + 1.0).sqrt(),
        Vec3::new(0.8, 0.6, 1.0),
        160,
        120,
    )?;
    let camera = Camera::new(
        place.transform_point3(twin.eye),
        place.transform_point3(twin.target),
        twin.up,
        twin.fov_y,
        twin.width,
        twin.height,
    )?;
    let floor = shapes::floor("floor", Vec3::ZERO, 0.5 * floor, 1)?;
    let objects = [moved(scan, place * fit)?, moved(&floor, place)?].map(object);
    Scene::still(name, objects.to_vec(), camera)
}

/// A floor 2 m across (16×16 cells) and 0.3 m above it a flat fan facing up:
/// [`SLIVER_NEEDLES`] needles from an apex at x = −0.5 to points 8e-4 m
/// apart along the edge x = 0.5, z ∈ [−0.2, 0.2], and [`SLIVER_DEGENERATE`]
/// zero-area triangles that validation drops.
fn slivers(name: &str) -> Result<Scene> {
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 16)?;
    let fan = sliver_fan()?;
    debug_assert_eq!(fan.report().degenerate_triangles, SLIVER_DEGENERATE);
    still(name, vec![floor, fan])
}

fn sliver_fan() -> Result<Mesh> {
    let (height, half_width) = (0.3, 0.2);
    let n = SLIVER_NEEDLES as u32;
    let apex = Vec3::new(-0.5, height, 0.0);
    let mut positions = vec![apex];
    positions.extend((0..=n).map(|i| {
        let z = -half_width + 2.0 * half_width * i as f32 / n as f32;
        Vec3::new(0.5, height, z)
    }));
    // A second vertex at the apex's place.
    let twin = positions.len() as u32;
    positions.push(apex);
    let edge = |i: u32| 1 + i;
    // (apex, q_{i+1}, q_i) winds counter-clockwise seen from above.
    let mut triangles: Vec<[u32; 3]> = (0..n).map(|i| [0, edge(i + 1), edge(i)]).collect();
    // Zero area: three points of the straight far edge, ...
    triangles.extend((0..n / 2).map(|i| [edge(2 * i), edge(2 * i + 1), edge(2 * i + 2)]));
    // ... a vertex repeated, ...
    triangles.extend([
        [0, 0, edge(1)],
        [edge(3), edge(4), edge(4)],
        [edge(7), 0, edge(7)],
    ]);
    // ... and two distinct vertices at one place.
    triangles.push([0, twin, edge(n / 2)]);
    Mesh::new("fan", positions, None, triangles)
}

/// A two-triangle floor 2 m across and a 12-triangle box (0.6 × 0.5 × 0.6 m)
/// standing on its centre: the floor's only vertices are its corners.
fn coarse(name: &str) -> Result<Scene> {
    let floor = shapes::floor("floor", Vec3::ZERO, 1.0, 1)?;
    let cube = shapes::cuboid(
        "box",
        Vec3::new(-0.3, 0.0, -0.3),
        Vec3::new(0.3, 0.5, 0.3),
        false,
    )?;
    still(name, vec![floor, cube])
}

/// Direction toward the sun of `sun-only`: 40° above the horizon.
pub fn sun_direction() -> Vec3 {
    let elevation = 40f32.to_radians();
    let azimuth = 0.3 * TAU;
    Vec3::new(
        elevation.cos() * azimuth.cos(),
        elevation.sin(),
        elevation.cos() * azimuth.sin(),
    )
}

/// Angular radius of the sun disc, radians.
const SUN_RADIUS: f32 = 0.035;

/// Black but for a sun disc of angular radius 2° (about eight texels of a
/// 256×128 map) of radiance 1000: about 4 W·m⁻² on a surface facing it,
/// as much as a white sky of radiance 1.3 gives.
fn sun() -> Result<Environment> {
    let (w, h) = (256, 128);
    let toward = sun_direction();
    let mut env = procedural("sun", w, h, |d| {
        if d.dot(toward) >= SUN_RADIUS.cos() {
            Vec3::splat(1000.0)
        } else {
            Vec3::ZERO
        }
    })?;
    if env.texels().iter().all(|t| *t == Vec3::ZERO) {
        // Never at this size; kept so that a smaller map still has a sun.
        let (row, col) = env.texel_of(toward);
        let mut texels = env.texels().to_vec();
        texels[row * w + col] = Vec3::splat(1000.0);
        env = Environment::new("sun", w, h, texels)?;
    }
    Ok(env)
}

/// A `w`×`h` lat-long map with `radiance` evaluated at every texel's centre.
fn procedural(
    name: &str,
    w: usize,
    h: usize,
    radiance: impl Fn(Vec3) -> Vec3,
) -> Result<Environment> {
    let blank = Environment::new(name, w, h, vec![Vec3::ZERO; w * h])?;
    let texels = (0..w * h)
        .map(|i| radiance(blank.direction(i / w, i % w)))
        .collect();
    Environment::new(name, w, h, texels)
}

/// A closed axis-aligned box facing out, each face a grid of `cells` (along
/// X, Y, Z) quads, faces sharing the vertices of their common edges (so that
/// [`Mesh::is_closed`] holds; normals are area-weighted, flat inside a face).
fn closed_box(name: &str, min: Vec3, max: Vec3, cells: [u32; 3]) -> Result<Mesh> {
    // The vertex at lattice point `c`, the far side exactly at `max`.
    let at = |c: [u32; 3]| {
        Vec3::from_array(std::array::from_fn(|a| {
            if c[a] == cells[a] {
                max[a]
            } else {
                min[a] + (max[a] - min[a]) * c[a] as f32 / cells[a] as f32
            }
        }))
    };
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut vertex = |c: [u32; 3]| {
        *index.entry(c).or_insert_with(|| {
            positions.push(at(c));
            positions.len() as u32 - 1
        })
    };
    // (fixed axis, on its far side?, u axis, v axis) with e_u × e_v outward.
    let faces = [
        (0, false, 2, 1),
        (0, true, 1, 2),
        (1, false, 0, 2),
        (1, true, 2, 0),
        (2, false, 1, 0),
        (2, true, 0, 1),
    ];
    let mut triangles = Vec::new();
    for (axis, far, u, v) in faces {
        let corner = |i: u32, j: u32| {
            let mut c = [0; 3];
            c[axis] = if far { cells[axis] } else { 0 };
            c[u] = i;
            c[v] = j;
            c
        };
        for i in 0..cells[u] {
            for j in 0..cells[v] {
                let [a, b, c, d] = [
                    corner(i, j),
                    corner(i + 1, j),
                    corner(i + 1, j + 1),
                    corner(i, j + 1),
                ]
                .map(&mut vertex);
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
    }
    Mesh::new(name, positions, None, triangles)
}

/// A closed sphere of 16 rings and 32 segments, 482 vertices.
fn sphere(name: &str, center: Vec3, radius: f32) -> Result<Mesh> {
    shapes::closed_sphere(name, center, radius, 16, 32)
}

/// One mesh of several, each part keeping its vertices and normals.
fn joined(name: &str, parts: &[Mesh]) -> Result<Mesh> {
    let (mut positions, mut normals, mut triangles) = (Vec::new(), Vec::new(), Vec::new());
    for part in parts {
        let base = positions.len() as u32;
        positions.extend_from_slice(part.positions());
        normals.extend_from_slice(part.normals());
        triangles.extend(part.triangles().iter().map(|t| t.map(|i| i + base)));
    }
    Mesh::new(name, positions, Some(normals), triangles)
}

fn object(mesh: Mesh) -> Object {
    Object {
        mesh: Arc::new(mesh),
        material: white(),
    }
}

/// Longest edge over shortest altitude, `L² / 2A`: 2/√3 for an equilateral
/// triangle, infinite for a zero-area one.
pub fn aspect_ratio([a, b, c]: [Vec3; 3]) -> f32 {
    let longest = (b - a)
        .length_squared()
        .max((c - b).length_squared())
        .max((a - c).length_squared());
    longest / (b - a).cross(c - a).length()
}

/// The smallest set of texels, brightest per solid angle first, that holds
/// `fraction` of the environment's luminance integral: its solid angle, sr.
pub fn solid_angle_holding(env: &Environment, fraction: f32) -> f32 {
    let mut texels: Vec<(f32, f32)> = (0..env.height())
        .flat_map(|row| {
            let omega = env.solid_angle(row);
            (0..env.width()).map(move |col| (row, col, omega))
        })
        .map(|(row, col, omega)| (luminance(env.texel(row, col)), omega))
        .collect();
    texels.sort_by(|a, b| b.0.total_cmp(&a.0));
    let total: f64 = texels.iter().map(|(l, w)| (*l * *w) as f64).sum();
    let (mut held, mut omega) = (0.0f64, 0.0f32);
    for (l, w) in texels {
        if held >= fraction as f64 * total {
            break;
        }
        held += (l * w) as f64;
        omega += w;
    }
    omega
}

#[cfg(test)]
mod tests;
