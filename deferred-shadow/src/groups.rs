//! Occluder groups (§4.2.3): objects near each other cast through one
//! occlusion map.

use glam::{Affine3A, Vec3};
use shadow_core::{Aabb, Error, Pose, Result, Scene};

use crate::config::Grouping;

/// A partition of a scene's objects into occluder groups.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Groups {
    /// The group of each object.
    pub of_object: Vec<u32>,
    /// The objects of each group, ascending.
    pub members: Vec<Vec<usize>>,
}

/// The box holding the eight corners of `model` turned by `t`: an object's
/// bounds in the world as the method groups and plans with them.
pub(crate) fn posed_bounds(model: Aabb, t: &Affine3A) -> Aabb {
    Aabb::from_points((0..8).map(|c| {
        t.transform_point3(Vec3::new(
            if c & 1 == 0 { model.min.x } else { model.max.x },
            if c & 2 == 0 { model.min.y } else { model.max.y },
            if c & 4 == 0 { model.min.z } else { model.max.z },
        ))
    }))
}

/// Of the padding that gives a flat box a volume: this share of the
/// smaller box's diagonal.
const PAD: f32 = 1e-3;

/// Whether boxes `a` and `b`, each padded by [`PAD`] of the smaller one's
/// diagonal, share more than `overlap` of the smaller padded volume. The
/// pad follows the pair, not the scene: a 1 m model on a 200 m floor
/// stays apart from it as it does on a 3 m one. Extents are differences
/// of the boxes' own corners, so the test reads the same wherever the
/// pair sits.
fn overlaps(a: &Aabb, b: &Aabb, overlap: f32) -> bool {
    let pad = 2.0 * PAD * a.diagonal().min(b.diagonal());
    let volume = |e: Vec3| (e + pad).max(Vec3::ZERO).element_product();
    let common = volume(a.max.min(b.max) - a.min.max(b.min));
    common > overlap * volume(a.max - a.min).min(volume(b.max - b.min))
}

impl Groups {
    /// The groups [`crate::DeferredShadow`] forms when it prepares `scene`:
    /// [`Groups::of_frame`] at the first frame.
    pub fn of_scene(grouping: &Grouping, scene: &Scene) -> Result<Groups> {
        Groups::of_frame(grouping, scene, 0)
    }

    /// The groups of `scene`'s objects as posed at `frame` (the method
    /// regroups at each frame whose poses moved): each object's mesh bounds
    /// posed there (the box of its eight corners turned by the pose),
    /// grouped by `grouping`. A deformed object (which the method refuses)
    /// counts with the bounds of its posed vertices. Fails on a frame
    /// the scene does not have.
    pub fn of_frame(grouping: &Grouping, scene: &Scene, frame: usize) -> Result<Groups> {
        let poses = &scene
            .frames()
            .get(frame)
            .ok_or_else(|| {
                Error::config(
                    "deferred-shadow",
                    format!("frame {frame} of a scene of {}", scene.frames().len()),
                )
            })?
            .poses;
        let boxes: Vec<Aabb> = scene
            .objects()
            .iter()
            .zip(poses)
            .map(|(object, pose)| match pose {
                Pose::Rigid(t) => posed_bounds(object.mesh.bounds(), t),
                Pose::Deformed { positions, .. } => Aabb::from_points(positions.iter().copied()),
            })
            .collect();
        Groups::new(grouping, &boxes)
    }

    /// Groups the objects whose bounds are `boxes` by `grouping`.
    pub fn new(grouping: &Grouping, boxes: &[Aabb]) -> Result<Groups> {
        let n = boxes.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        match grouping {
            Grouping::Overlapping { overlap } => {
                for a in 0..n {
                    for b in a + 1..n {
                        if overlaps(&boxes[a], &boxes[b], *overlap) {
                            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                            parent[ra.max(rb)] = ra.min(rb);
                        }
                    }
                }
            }
            Grouping::Explicit(groups) => {
                let mut seen = vec![false; n];
                for group in groups {
                    for &o in group {
                        if o >= n || seen[o] {
                            return Err(Error::config(
                                "deferred-shadow",
                                format!(
                                    "explicit groups {groups:?}: object {o} is out of range or in two groups ({n} objects)"
                                ),
                            ));
                        }
                        seen[o] = true;
                        parent[o] = group[0];
                    }
                }
                if let Some(o) = seen.iter().position(|s| !s) {
                    return Err(Error::config(
                        "deferred-shadow",
                        format!("explicit groups {groups:?} leave object {o} out"),
                    ));
                }
            }
        }
        let mut of_object = vec![u32::MAX; n];
        let mut members: Vec<Vec<usize>> = Vec::new();
        for o in 0..n {
            let r = root(&mut parent, o);
            if of_object[r] == u32::MAX {
                of_object[r] = members.len() as u32;
                members.push(Vec::new());
            }
            of_object[o] = of_object[r];
            members[of_object[o] as usize].push(o);
        }
        Ok(Groups { of_object, members })
    }

    pub fn len(&self) -> usize {
        self.members.len()
    }

    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn boxed(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb {
            min: Vec3::from(min),
            max: Vec3::from(max),
        }
    }

    #[test]
    fn a_board_in_two_colours_is_one_group_and_a_piece_on_it_another() {
        let light = boxed([-1.0, 0.0, -1.0], [1.0, 0.0, 1.0]);
        let dark = boxed([-1.0, 0.0, -0.9], [0.9, 0.0, 1.0]);
        let piece = boxed([0.0, 0.0, 0.0], [0.1, 0.3, 0.1]);
        let other = boxed([0.5, 0.0, 0.5], [0.6, 0.3, 0.6]);
        let groups = Groups::new(
            &Grouping::Overlapping { overlap: 0.5 },
            &[light, piece, dark, other],
        )
        .unwrap();
        assert_eq!(groups.members, vec![vec![0, 2], vec![1], vec![3]]);
        assert_eq!(groups.of_object, vec![0, 1, 0, 2]);
    }

    /// The pad follows each pair: a 1 m model on a floor stays apart from
    /// it whether the floor is 3 m or 200 m across (padded by a thousandth
    /// of the scene's diagonal, the model on the 200 m floor shared 36% of
    /// its box with the floor's and the 1 cm cubes merged), two 1 cm cubes
    /// 5 cm apart stay apart beside it, and none of it changes 10 km away.
    #[test]
    fn groups_do_not_depend_on_the_scene_around_the_pair() {
        let grouping = Grouping::Overlapping { overlap: 0.2 };
        let model = boxed([-0.5, 0.0, -0.5], [0.5, 1.0, 0.5]);
        let cubes = [
            boxed([2.0, 0.0, 0.0], [2.01, 0.01, 0.01]),
            boxed([2.06, 0.0, 0.0], [2.07, 0.01, 0.01]),
        ];
        for half in [1.5, 100.0] {
            let floor = boxed([-half, 0.0, -half], [half, 0.0, half]);
            for shift in [Vec3::ZERO, Vec3::new(6000.0, 0.0, -8000.0)] {
                let moved: Vec<Aabb> = [floor, model, cubes[0], cubes[1]]
                    .iter()
                    .map(|b| Aabb {
                        min: b.min + shift,
                        max: b.max + shift,
                    })
                    .collect();
                let groups = Groups::new(&grouping, &moved).unwrap();
                assert_eq!(
                    groups.members,
                    vec![vec![0], vec![1], vec![2], vec![3]],
                    "floor {half} m, shifted {shift}"
                );
            }
        }
    }

    #[test]
    fn explicit_groups_must_partition_the_objects() {
        let b = boxed([0.0; 3], [1.0; 3]);
        let ok = Groups::new(&Grouping::Explicit(vec![vec![1, 2], vec![0]]), &[b; 3]).unwrap();
        assert_eq!(ok.of_object, vec![0, 1, 1]);
        for bad in [
            vec![vec![0, 1]],
            vec![vec![0, 1], vec![1, 2]],
            vec![vec![0, 1, 2, 3]],
        ] {
            assert!(matches!(
                Groups::new(&Grouping::Explicit(bad), &[b; 3]),
                Err(Error::InvalidConfig { .. })
            ));
        }
    }
}
