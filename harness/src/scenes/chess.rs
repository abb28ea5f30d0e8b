//! The `chess` scene, after Kautz, Lehtinen and Aila 2004 (§4, Figure 4(c)–(d)
//! and Table 1 "Chess": 1897 vertices, 3704 triangles): "a simple scene with
//! moving chess pieces".
//!
//! Eight turned pieces stand on a checkered board; over six frames a rook
//! slides along the first rank up to its king, a pawn advances two squares,
//! and a bishop hops a knight's L through the air, so rigid objects move past
//! each other and their contact shadows on the board come and go.
//!
//! The board is two objects, the light and the dark squares, because a
//! material belongs to an object (shadow_core's `Object`) and the squares
//! need two albedos. Each square is one quad with its own four corners: the
//! board's vertices are the squares' corners only, so a piece standing on a
//! square's centre, or sliding along a rank or file, never buries a vertex
//! under its foot (a vertex inside a closed blocker is all shadow to a ray
//! tracer but sees only back faces, which hemi-raster culls).

use std::sync::Arc;

use glam::{Affine3A, Vec2, Vec3};
use shadow_core::{Brdf, Frame, Mesh, Object, Pose, Result, Scene};

use shadow_core::shapes;

use super::{framed, white};

/// Side of a square, metres (a tournament board's 57 mm, rounded).
const SQUARE: f32 = 0.06;
/// Steps of a full turn for every piece: facets of 22.5°, smoothed by the
/// normals, keep the total near Table 1's vertex count.
const SEGMENTS: u32 = 16;
/// Frames of the sequence and their spacing, seconds.
const FRAMES: usize = 6;
const FRAME_STEP: f32 = 0.2;
/// Highest lift of the hopping piece's foot above the board.
const HOP_HEIGHT: f32 = 0.06;

/// The turned shapes. Their profiles are (radius, height) in millimetres from
/// the centre of the foot to the top, Staunton-like proportions: a foot that
/// fits well inside a square, a tapering stem, a collar, a head.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shape {
    Pawn,
    Rook,
    Bishop,
    King,
}

impl Shape {
    const ALL: [Shape; 4] = [Shape::Pawn, Shape::Rook, Shape::Bishop, Shape::King];

    fn name(self) -> &'static str {
        match self {
            Shape::Pawn => "pawn",
            Shape::Rook => "rook",
            Shape::Bishop => "bishop",
            Shape::King => "king",
        }
    }

    fn profile(self) -> &'static [[f32; 2]] {
        match self {
            // A ball on a short stem.
            Shape::Pawn => &[
                [0.0, 0.0],
                [17.0, 0.0],
                [17.0, 5.0],
                [13.0, 9.0],
                [8.0, 14.0],
                [6.0, 25.0],
                [11.0, 27.0],
                [11.0, 29.0],
                [7.5, 31.0],
                [10.8, 37.0],
                [10.0, 43.7],
                [5.5, 48.5],
                [0.0, 50.0],
            ],
            // A turret whose top is hollowed into a bowl (no crenellations:
            // they are not a surface of revolution).
            Shape::Rook => &[
                [0.0, 0.0],
                [19.0, 0.0],
                [19.0, 5.0],
                [15.0, 9.0],
                [12.0, 13.0],
                [10.0, 36.0],
                [12.5, 38.0],
                [12.5, 40.0],
                [11.0, 41.5],
                [13.5, 44.0],
                [13.5, 57.0],
                [10.0, 57.0],
                [9.5, 52.0],
                [0.0, 52.0],
            ],
            // A tall stem, a mitre and a small ball on top.
            Shape::Bishop => &[
                [0.0, 0.0],
                [19.0, 0.0],
                [19.0, 5.0],
                [15.0, 9.0],
                [11.0, 14.0],
                [7.0, 42.0],
                [12.0, 45.0],
                [12.0, 47.0],
                [7.0, 49.0],
                [9.5, 53.0],
                [10.5, 59.0],
                [9.0, 65.0],
                [5.0, 70.0],
                [2.5, 72.0],
                [3.5, 74.5],
                [2.5, 77.5],
                [0.0, 79.0],
            ],
            // The tallest: a flared crown under a finial standing for the cross.
            Shape::King => &[
                [0.0, 0.0],
                [21.0, 0.0],
                [21.0, 6.0],
                [17.0, 10.0],
                [13.0, 16.0],
                [8.0, 52.0],
                [13.0, 55.0],
                [13.0, 58.0],
                [8.0, 60.0],
                [10.0, 68.0],
                [12.5, 78.0],
                [12.5, 81.0],
                [9.0, 82.5],
                [3.5, 84.0],
                [4.5, 89.0],
                [4.5, 95.0],
                [2.0, 99.0],
                [0.0, 100.0],
            ],
        }
    }

    /// The closed mesh, its foot centred on the origin at y = 0.
    fn mesh(self) -> Result<Mesh> {
        let profile: Vec<Vec2> = self
            .profile()
            .iter()
            .map(|&p| Vec2::from(p) * 1e-3)
            .collect();
        shapes::lathe(self.name(), &profile, SEGMENTS)
    }
}

/// How a piece gets from its first square to its last.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Motion {
    /// Along the board, foot on it throughout.
    Slide,
    /// Up a parabolic arc and down again, like a knight's jump.
    Hop,
}

/// One piece: its shape and side, and its squares at the first and last
/// frame, named as in chess notation (`*b"e1"`: file a–h, rank 1–8).
struct Piece {
    shape: Shape,
    white: bool,
    from: [u8; 2],
    to: [u8; 2],
    motion: Motion,
}

impl Piece {
    const fn new(shape: Shape, white: bool, from: &[u8; 2], to: &[u8; 2], motion: Motion) -> Piece {
        Piece {
            shape,
            white,
            from: *from,
            to: *to,
            motion,
        }
    }

    /// Where the centre of the foot is at fraction `s` ∈ [0, 1] of the move.
    fn foot(&self, s: f32) -> Vec3 {
        let along = square_centre(self.from).lerp(square_centre(self.to), s);
        match self.motion {
            Motion::Slide => along,
            Motion::Hop => along + Vec3::Y * (HOP_HEIGHT * 4.0 * s * (1.0 - s)),
        }
    }
}

/// The position: a quiet endgame. Pieces whose two squares are the same stay.
const PIECES: [Piece; 8] = [
    Piece::new(Shape::King, true, b"e1", b"e1", Motion::Slide),
    Piece::new(Shape::Rook, true, b"a1", b"d1", Motion::Slide),
    Piece::new(Shape::Pawn, true, b"d3", b"d3", Motion::Slide),
    Piece::new(Shape::Pawn, true, b"g2", b"g4", Motion::Slide),
    Piece::new(Shape::King, false, b"e8", b"e8", Motion::Slide),
    Piece::new(Shape::Bishop, false, b"d6", b"e4", Motion::Hop),
    Piece::new(Shape::Pawn, false, b"c5", b"c5", Motion::Slide),
    Piece::new(Shape::Pawn, false, b"f7", b"f7", Motion::Slide),
];

/// Centre of a square on the board's top (y = 0). The board is centred on
/// the origin, files a–h along +X, rank 1 nearest +Z, where the camera is.
fn square_centre([file, rank]: [u8; 2]) -> Vec3 {
    let file = f32::from(file) - f32::from(b'a');
    let rank = f32::from(rank) - f32::from(b'1');
    Vec3::new((file - 3.5) * SQUARE, 0.0, (3.5 - rank) * SQUARE)
}

/// The light (`light` true) or dark squares of the board as one mesh, each
/// square a quad facing +Y with its own corners. a1 is dark.
fn squares(light: bool) -> Result<Mesh> {
    let mut positions = Vec::with_capacity(4 * 32);
    let mut triangles = Vec::with_capacity(2 * 32);
    for file in 0..8u8 {
        for rank in 0..8u8 {
            if ((file + rank) % 2 == 1) != light {
                continue;
            }
            let centre = square_centre([b'a' + file, b'1' + rank]);
            let o = centre - Vec3::new(0.5, 0.0, 0.5) * SQUARE;
            let (du, dv) = (Vec3::Z * SQUARE, Vec3::X * SQUARE);
            let base = positions.len() as u32;
            positions.extend([o, o + du, o + du + dv, o + dv]);
            // Counter-clockwise seen from above: du × dv = +Y.
            triangles.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
        }
    }
    let name = if light {
        "light squares"
    } else {
        "dark squares"
    };
    Mesh::new(name, positions, None, triangles)
}

/// The scene: light and dark squares, then the pieces in `PIECES` order.
pub fn scene(name: &str) -> Result<Scene> {
    let ebony = Brdf::lambert(Vec3::splat(0.15))?;
    let mut objects = vec![
        Object {
            mesh: Arc::new(squares(true)?),
            material: white(),
        },
        Object {
            mesh: Arc::new(squares(false)?),
            material: ebony,
        },
    ];
    // One mesh per shape, shared by the pieces of that shape; `Shape::ALL`
    // lists the shapes in declaration order, so a shape indexes its mesh.
    let meshes = Shape::ALL
        .iter()
        .map(|s| s.mesh().map(Arc::new))
        .collect::<Result<Vec<_>>>()?;
    objects.extend(PIECES.iter().map(|piece| Object {
        mesh: Arc::clone(&meshes[piece.shape as usize]),
        material: if piece.white { white() } else { ebony },
    }));
    let frames = (0..FRAMES)
        .map(|k| {
            let s = k as f32 / (FRAMES - 1) as f32;
            let board = [
                Pose::Rigid(Affine3A::IDENTITY),
                Pose::Rigid(Affine3A::IDENTITY),
            ];
            let pieces = PIECES
                .iter()
                .map(|p| Pose::Rigid(Affine3A::from_translation(p.foot(s))));
            Frame {
                time: k as f32 * FRAME_STEP,
                poses: board.into_iter().chain(pieces).collect(),
            }
        })
        .collect();
    framed(name, objects, frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn squares_are_named_like_a_chess_board() {
        assert_relative_eq!(square_centre(*b"a1"), Vec3::new(-0.21, 0.0, 0.21));
        assert_relative_eq!(square_centre(*b"h8"), Vec3::new(0.21, 0.0, -0.21));
        for p in &PIECES {
            for [file, rank] in [p.from, p.to] {
                assert!((b'a'..=b'h').contains(&file) && (b'1'..=b'8').contains(&rank));
            }
        }
        for (i, shape) in Shape::ALL.into_iter().enumerate() {
            assert_eq!(shape as usize, i);
        }
        // a1 is dark and h1 light: find them among the quads' centres.
        let centres = |m: &Mesh| -> Vec<Vec3> {
            m.positions()
                .chunks(4)
                .map(|q| q.iter().sum::<Vec3>() / 4.0)
                .collect()
        };
        let has = |m: &Mesh, name: &[u8; 2]| {
            let c = square_centre(*name);
            centres(m).iter().any(|p| p.distance(c) < 1e-6)
        };
        let (light, dark) = (squares(true).unwrap(), squares(false).unwrap());
        assert_eq!((light.triangle_count(), dark.triangle_count()), (64, 64));
        assert!(has(&dark, b"a1") && !has(&light, b"a1"));
        assert!(has(&light, b"h1") && !has(&dark, b"h1"));
        assert!(has(&light, b"a8") && has(&dark, b"h8"));
    }

    #[test]
    fn no_board_vertex_lies_under_a_foot() {
        let board: Vec<Vec3> = [squares(true).unwrap(), squares(false).unwrap()]
            .iter()
            .flat_map(|m| m.positions().to_vec())
            .collect();
        for shape in Shape::ALL {
            let foot = shape.profile()[1][0] * 1e-3;
            for piece in PIECES.iter().filter(|p| p.shape == shape) {
                for k in 0..FRAMES {
                    let at = piece.foot(k as f32 / (FRAMES - 1) as f32);
                    if at.y > 0.0 {
                        continue;
                    }
                    for v in &board {
                        assert!((*v - at).length() > foot * 1.2, "{:?} at {at}", shape);
                    }
                }
            }
        }
    }
}
