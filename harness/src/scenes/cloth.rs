//! The `cloth` scene, after Kautz, Lehtinen and Aila 2004 (§4, Figure 1 and
//! Table 1 "Cloth": 1378 vertices, 2560 triangles): a sheet whose wrinkles
//! shadow themselves and which casts a soft shadow on the floor below.
//!
//! The paper's cloth was simulated; here an analytic deformation stands in
//! (DESIGN.md, "model no more than a scene needs"): the sheet is pinned at its
//! four corners, sags as it settles, and two trains of folds travel across it.
//! It is a height field over a fixed square grid, so it cannot pass through
//! itself however deep the folds, and its normals follow from the height's
//! gradient exactly. The folds stretch the sheet a little rather than
//! conserving its length: what the scene must show is visibility, not cloth
//! mechanics.

use std::{f32::consts::TAU, sync::Arc};

use glam::{Affine3A, Vec2, Vec3};
use shadow_core::{Frame, Mesh, Object, Pose, Result, Scene};

use shadow_core::shapes;

use super::{framed, white};

/// Vertices along each side of the sheet: 37² sheet vertices and the floor's
/// 3² make Table 1's 1378.
const SIDE: u32 = 37;
/// Half the side of the sheet, metres.
const HALF: f32 = 0.6;
/// Height of the pinned corners above the floor.
const PIN_HEIGHT: f32 = 0.6;
/// Half the side of the floor: wide enough to hold the sheet's penumbra.
const FLOOR_HALF: f32 = 0.9;
/// Frames of the sequence (as the other animated scenes) and their spacing.
const FRAMES: usize = 6;
const FRAME_STEP: f32 = 0.2;
/// Sag of the sheet's middle below its corners, from the first frame to the
/// last: it settles, quickly at first.
const SAG_START: f32 = 0.12;
const SAG_END: f32 = 0.22;

/// One train of parallel folds travelling across the sheet.
struct Folds {
    /// Unit direction of travel in the floor plane (x, z).
    direction: Vec2,
    wavelength: f32,
    /// Height of a ridge above its trough, metres.
    depth: f32,
    /// Phase speed, metres per second.
    speed: f32,
}

/// Deep, narrow folds across the sheet and shallower ones crossing them the
/// other way: ridges about as steep as 45° cast shadows into the troughs
/// beside them.
const FOLDS: [Folds; 2] = [
    Folds {
        direction: Vec2::new(0.940, 0.342),
        wavelength: 0.3,
        depth: 0.065,
        speed: 0.15,
    },
    Folds {
        direction: Vec2::new(-0.342, 0.940),
        wavelength: 0.45,
        depth: 0.03,
        speed: -0.1,
    },
];

/// The scene: the sheet over a floor of 2×2 quads, both white.
pub fn scene(name: &str) -> Result<Scene> {
    let cells = SIDE - 1;
    let step = 2.0 * HALF / cells as f32;
    let corner = Vec3::new(-HALF, PIN_HEIGHT, -HALF);
    // Front face up (Z × X = +Y). The model-space mesh is the first frame's
    // drape, not the flat sheet: what a method builds once from the mesh's
    // own positions (hemi-raster's coarse level, §3.2) then starts from a
    // shape the sequence shows.
    let flat = shapes::grid(
        "cloth",
        corner,
        Vec3::Z * step,
        Vec3::X * step,
        cells,
        cells,
    )?;
    let (positions, normals) = draped(&flat, 0.0);
    let sheet = Mesh::new("cloth", positions, Some(normals), flat.triangles().to_vec())?;
    let floor = shapes::floor("floor", Vec3::ZERO, FLOOR_HALF, 2)?;
    let frames = (0..FRAMES)
        .map(|k| {
            let time = k as f32 * FRAME_STEP;
            let (positions, normals) = draped(&sheet, time);
            let sheet = Pose::Deformed {
                positions: positions.into(),
                normals: Some(normals.into()),
            };
            Frame {
                time,
                poses: vec![sheet, Pose::Rigid(Affine3A::IDENTITY)],
            }
        })
        .collect();
    let objects = [sheet, floor]
        .into_iter()
        .map(|mesh| Object {
            mesh: Arc::new(mesh),
            material: white(),
        })
        .collect();
    framed(name, objects, frames)
}

/// The sheet at `time`: its vertices moved vertically onto the height field
/// (so any pose of the sheet will do as input), and the field's normals.
fn draped(sheet: &Mesh, time: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    sheet
        .positions()
        .iter()
        .map(|p| {
            let (y, gradient) = height(Vec2::new(p.x, p.z), time);
            let normal = Vec3::new(-gradient.x, 1.0, -gradient.y).normalize();
            (Vec3::new(p.x, y, p.z), normal)
        })
        .unzip()
}

/// Height of the sheet above the floor at `p` = (x, z), and its gradient
/// (∂y/∂x, ∂y/∂z).
///
/// y = PIN_HEIGHT + e(u, v) · (F(p, t) − sag(t)), with u = x/HALF, v = z/HALF
/// and the pinning envelope e = 1 − u²v², which is 0 at the four corners and
/// 1 − v² along an edge: the free edges hang in arcs between the pins. F sums
/// the fold trains.
fn height(p: Vec2, time: f32) -> (f32, Vec2) {
    let (u, v) = (p.x / HALF, p.y / HALF);
    let envelope = 1.0 - u * u * v * v;
    let envelope_gradient = Vec2::new(-2.0 * u * v * v, -2.0 * u * u * v) / HALF;
    let (folds, folds_gradient) = FOLDS.iter().fold((0.0, Vec2::ZERO), |(f, g), train| {
        let k = TAU / train.wavelength;
        let (ridge, slope) = ridge(k * (train.direction.dot(p) - train.speed * time));
        (
            f + train.depth * ridge,
            g + train.direction * (train.depth * slope * k),
        )
    });
    let offset = folds - sag(time);
    (
        PIN_HEIGHT + envelope * offset,
        envelope_gradient * offset + envelope * folds_gradient,
    )
}

/// A fold's cross-section over one period and its derivative: ((1 + cos s)/2)²
/// less its mean 3/8, a narrow ridge between broad troughs, rising 1 from
/// trough to crest.
fn ridge(s: f32) -> (f32, f32) {
    let half = 0.5 * (1.0 + s.cos());
    (half * half - 0.375, -half * s.sin())
}

/// How far the middle of the sheet hangs below its corners at `time`: eases
/// from SAG_START to SAG_END over the sequence.
fn sag(time: f32) -> f32 {
    let s = (time / ((FRAMES - 1) as f32 * FRAME_STEP)).clamp(0.0, 1.0);
    SAG_START + (SAG_END - SAG_START) * (s * (2.0 - s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f32::consts::PI;

    #[test]
    fn gradient_matches_central_differences() {
        let h = 1e-3;
        for &(x, z, t) in &[
            (0.0, 0.0, 0.0),
            (0.31, -0.17, 0.4),
            (-0.55, 0.52, 1.0),
            (0.6, 0.2, 0.6),
        ] {
            let p = Vec2::new(x, z);
            let (_, g) = height(p, t);
            let dx = (height(p + Vec2::X * h, t).0 - height(p - Vec2::X * h, t).0) / (2.0 * h);
            let dz = (height(p + Vec2::Y * h, t).0 - height(p - Vec2::Y * h, t).0) / (2.0 * h);
            assert_relative_eq!(g, Vec2::new(dx, dz), epsilon = 2e-3);
        }
    }

    #[test]
    fn corners_stay_pinned_and_the_middle_settles() {
        for t in [0.0, 0.5, 1.0] {
            let (y, _) = height(Vec2::new(HALF, -HALF), t);
            assert_relative_eq!(y, PIN_HEIGHT, epsilon = 1e-6);
        }
        assert_relative_eq!(sag(0.0), SAG_START);
        assert_relative_eq!(sag((FRAMES - 1) as f32 * FRAME_STEP), SAG_END);
        assert!(sag(0.2) - sag(0.0) > sag(1.0) - sag(0.8));
    }

    #[test]
    fn ridge_has_zero_mean_and_unit_rise() {
        let n = 1000;
        let mean: f32 = (0..n)
            .map(|i| ridge(TAU * i as f32 / n as f32).0)
            .sum::<f32>()
            / n as f32;
        assert_relative_eq!(mean, 0.0, epsilon = 1e-5);
        assert_relative_eq!(ridge(0.0).0 - ridge(PI).0, 1.0);
    }
}
