//! Potentially visible sets from a known animation (Kautz et al. 2004,
//! §3.2, "PVS"): "if prior knowledge of the animation is available, it is
//! possible to construct a potentially visible set for each vertex … by
//! analyzing the geometry visible to a vertex in the animation frames in an
//! offline preprocess". The paper's static PVSs cut the blockers per vertex
//! by 75–88% (Table 1, "Avg. #Tris (with PVS)").
//!
//! # What "visible" means here
//! A receiver's mask is the OR of its candidate triangles' masks, so a set
//! of triangles reproduces the mask exactly as soon as the OR of its masks
//! is the OR of all: a set cover of the mask's pixels. It is built frame by
//! frame. The triangles already in the set cover what they cover; of the
//! others that survive culling, the greedy cover takes the one that adds
//! the most uncovered pixels, again and again, until the mask is covered
//! (which keeps fewer triangles than taking the nearest or the largest
//! first). Each triangle's mask is [`Rasterizer::draw`]'s, which the
//! engine's per-receiver loop reproduces bit for bit, so **on every frame
//! the set was built from, the masks with the set are the masks without
//! it**, to the bit (tested). On other poses a triangle that was hidden in
//! all the known frames may show and be missed: the set is a subset of the
//! candidates, so masks can only lose pixels, never gain them.
//!
//! The sets are over the same candidates as the configured hierarchy: the
//! coarse and near triangles of [`crate::Hierarchy::TwoLevel`] or every
//! triangle of [`crate::Hierarchy::Flat`], with the same culling rules (back
//! faces, own-body near chords, tested per frame).
//!
//! # Replaced near chords
//! With two levels, a coarse triangle of the receiver's body that a frame
//! finds too close is replaced by the fine triangles of its region, in that
//! frame only. A fine triangle of a region is a candidate only in the frames
//! that replace its coarse triangle, so the cover takes it as such: a set
//! member is the coarse triangle with the fine triangles of its region that
//! showed while it was replaced (*kept*). Listed, the member is rasterized
//! as the loop would: itself where the frame keeps it, its kept fine
//! triangles where the frame replaces it. Both are candidates of that frame
//! whenever they are rasterized, so the two guarantees above hold; and a
//! region costs only the fine triangles of it that ever showed. On a tie
//! the cover takes a plain candidate over the same triangle kept under a
//! chord, which keeps fewer blockers.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use rayon::prelude::*;
use shadow_core::{FrameGeometry, Result};

use crate::blockers::{Blockers, Candidates, Entry, Layout};
use crate::csr::Csr;
use crate::hierarchy::{TwoLevel, replaced};
use crate::mask::{Mask, MaskRow};
use crate::raster::{Rasterizer, edge_planes};

/// Per receiver, the candidate triangles that showed in some known frame,
/// by their slots in the frame's [`Layout`] (both levels in one numbering).
#[derive(Clone, Debug)]
pub(crate) struct VisibleSets {
    /// Per receiver, its set: the near chords that keep fine triangles
    /// first, then the others, each part sorted by slot.
    sets: Csr<Entry>,
    /// For the near chords of the receivers' bodies that come first in
    /// their sets, the fine triangles of their regions that showed in the
    /// known frames that replaced them (module docs); receiver v's are rows
    /// `kept_from[v]..kept_from[v + 1]`, one per chord at the head of its
    /// set. The others (most) replace nothing.
    kept: Csr<Entry>,
    kept_from: Vec<u32>,
}

/// A member of a set being built: a candidate and, for a near chord, the
/// fine triangles of its region kept for the frames that replace it.
#[derive(Clone, Debug)]
struct Member {
    entry: Entry,
    kept: Vec<Entry>,
}

/// A candidate that survived culling in one frame, or (`fine`) one fine
/// triangle of the region that replaces a candidate in this frame.
struct Shown<W: MaskRow> {
    known: bool,
    entry: Entry,
    fine: Option<Entry>,
    mask: Mask<W>,
}

impl VisibleSets {
    /// Builds the sets from every frame of `frames` (posed geometry of one
    /// scene), with `cull` per object as the method culls back faces and the
    /// candidates of `hierarchy` (every triangle when `None`).
    pub(crate) fn build<W: MaskRow>(
        raster: &Rasterizer<W>,
        frames: impl IntoIterator<Item = Result<FrameGeometry>>,
        cull: &[bool],
        hierarchy: Option<&TwoLevel>,
    ) -> Result<VisibleSets> {
        let mut sets: Vec<Vec<Member>> = Vec::new();
        for frame in frames {
            let blockers = Blockers::new(&frame?, cull)?;
            sets.resize(blockers.vertex_count(), Vec::new());
            let coarse = hierarchy.map(|h| h.coarse_level(&blockers));
            let layout = Layout::new(&blockers, coarse.as_ref());
            sets.par_iter_mut()
                .enumerate()
                .for_each_init(Vec::new, |shown, (v, set)| {
                    let candidates = match hierarchy {
                        Some(h) => h.candidates(&layout, v),
                        None => Candidates::All(&layout),
                    };
                    grow(raster, &blockers, v, &candidates, &layout, set, shown);
                });
        }
        // The members that keep fine triangles first, so that only they
        // need a row of `kept`.
        for set in &mut sets {
            set.sort_by_key(|m| m.kept.is_empty());
        }
        fn keeping(set: &[Member]) -> impl Iterator<Item = &Member> {
            set.iter().take_while(|m| !m.kept.is_empty())
        }
        let mut kept_from = vec![0u32];
        for set in &sets {
            let rows = kept_from[kept_from.len() - 1] as usize + keeping(set).count();
            kept_from.push(u32::try_from(rows).expect("fewer than 2³² kept rows"));
        }
        let entries = |set: &Vec<Member>| set.iter().map(|m| m.entry).collect::<Vec<_>>();
        Ok(VisibleSets {
            sets: Csr::from_lists(sets.iter().map(entries)),
            kept: Csr::from_lists(sets.iter().flat_map(|set| keeping(set)).map(|m| &m.kept)),
            kept_from,
        })
    }

    /// What receiver `v` rasterizes in a frame laid out as `layout` (with
    /// the hierarchy's coarse level, when there is one, as the sets were
    /// built).
    pub(crate) fn candidates<'a>(&'a self, layout: &'a Layout, v: usize) -> Candidates<'a> {
        Candidates::Listed {
            layout,
            entries: self.sets.of(v),
            kept: Some((
                &self.kept,
                self.kept_from[v] as usize..self.kept_from[v + 1] as usize,
            )),
        }
    }
}

/// Adds to `set` (sorted) the candidates of receiver `v` that show in this
/// frame (module docs), laid out in `layout`.
fn grow<W: MaskRow>(
    raster: &Rasterizer<W>,
    blockers: &Blockers,
    v: usize,
    candidates: &Candidates,
    layout: &Layout,
    set: &mut Vec<Member>,
    shown: &mut Vec<Shown<W>>,
) {
    let frame = blockers.frame(v);
    shown.clear();
    let mut covered = Mask::EMPTY;
    let local = |entry: Entry| layout.triangle(entry.slot()).map(|p| frame.to_local(p));
    for entry in candidates.entries() {
        let triangle = local(entry);
        let planes = edge_planes(triangle, entry.cull(), frame.contact());
        if entry.chords() && replaced(triangle, planes.above, planes.behind) {
            // Replaced in this frame: each fine triangle of its region is a
            // candidate of its own, kept under the near chord.
            let kept = member(set, entry).map(|i| &set[i].kept);
            for &fine in candidates.replacements(entry) {
                let mut mask = Mask::EMPTY;
                if raster.draw(local(fine), fine.cull(), frame.contact(), &mut mask)
                    && !mask.is_empty()
                {
                    let known = kept.is_some_and(|k| k.contains(&fine));
                    shown.push(Shown {
                        known,
                        entry,
                        fine: Some(fine),
                        mask,
                    });
                }
            }
        } else if planes.kept {
            let mut mask = Mask::EMPTY;
            raster.draw(triangle, entry.cull(), frame.contact(), &mut mask);
            let known = member(set, entry).is_some();
            shown.push(Shown {
                known,
                entry,
                fine: None,
                mask,
            });
        }
    }
    // Plain candidates first: on a tie the cover takes a triangle that is a
    // candidate in every frame over the same one kept under a chord.
    shown.sort_by_key(|s| s.fine.is_some());
    for s in shown.iter().filter(|s| s.known) {
        covered = covered.or(&s.mask);
    }
    // Greedy set cover, lazily: the candidate that adds the most pixels
    // first. A gain only falls as pixels get covered, so a popped gain that
    // is still current is the largest.
    let mut gains: BinaryHeap<(usize, Reverse<usize>)> = shown
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.known)
        .map(|(i, s)| (s.mask.and_not(&covered).count(), Reverse(i)))
        .filter(|&(gain, _)| gain > 0)
        .collect();
    while let Some((gain, Reverse(i))) = gains.pop() {
        let now = shown[i].mask.and_not(&covered).count();
        if now == gain {
            covered = covered.or(&shown[i].mask);
            let Shown { entry, fine, .. } = shown[i];
            let at = match set.binary_search_by_key(&entry, |m| m.entry) {
                Ok(at) => at,
                Err(at) => {
                    let kept = Vec::new();
                    set.insert(at, Member { entry, kept });
                    at
                }
            };
            set[at].kept.extend(fine);
        } else if now > 0 {
            gains.push((now, Reverse(i)));
        }
    }
}

/// Where `entry` is in `set`, if it is a member.
fn member(set: &[Member], entry: Entry) -> Option<usize> {
    set.binary_search_by_key(&entry, |m| m.entry).ok()
}

#[cfg(test)]
mod tests {
    use std::num::NonZeroU32;
    use std::sync::Arc;

    use glam::{Affine3A, Quat, Vec3};
    use shadow_core::{
        Brdf, Camera, Frame, Mesh, Object, Pose, Profile, Scene, ShadowMethod, Stage,
    };

    use crate::config::{Config, Hierarchy, Pvs};
    use crate::method::HemiRaster;
    use crate::test_util::{grid, icosphere};

    /// A bumpy closed ball rolling over a floor under a sheet that sags
    /// onto it, at `times` in [0, 1]: rigid motion, deformation, contact.
    fn scene(times: &[f32]) -> Scene {
        let ball = icosphere(Vec3::ZERO, 0.35, 3);
        let bumpy = ball
            .positions()
            .iter()
            .map(|&p| p * (1.0 + 0.2 * (9.0 * p.x).sin() * (7.0 * p.z).cos()))
            .collect();
        let ball = Mesh::new("ball", bumpy, None, ball.triangles().to_vec()).unwrap();
        let sheet = grid(0.9, 0.8, 14);
        let frames = times
            .iter()
            .map(|&t| {
                let sag = sheet
                    .positions()
                    .iter()
                    .map(|p| p - Vec3::Y * (0.5 * t * (1.0 - p.x * p.x - p.z * p.z)))
                    .collect();
                let roll = Affine3A::from_rotation_translation(
                    Quat::from_rotation_z(-2.0 * t),
                    Vec3::new(-0.5 + t, 0.4, 0.1),
                );
                Frame {
                    time: t,
                    poses: vec![
                        Pose::Rigid(Affine3A::IDENTITY),
                        Pose::Rigid(roll),
                        Pose::Deformed {
                            positions: sag,
                            normals: None,
                        },
                    ],
                }
            })
            .collect();
        let material = Brdf::lambert(Vec3::splat(0.5)).unwrap();
        let objects = [grid(0.0, 1.2, 10), ball, sheet]
            .into_iter()
            .map(|mesh| Object {
                mesh: Arc::new(mesh),
                material,
            })
            .collect();
        let camera = Camera::new(Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
        Scene::new("ball under a sheet", objects, frames, camera).unwrap()
    }

    fn hierarchies() -> [Hierarchy; 2] {
        [
            Hierarchy::Flat,
            Hierarchy::default().with_min_coarse_triangles(60),
        ]
    }

    fn prepared(hierarchy: Hierarchy, pvs: Pvs, scene: &Scene) -> HemiRaster {
        let mut method = HemiRaster::new(Config {
            hierarchy,
            pvs,
            ..Config::default()
        });
        method.prepare(scene).unwrap();
        method
    }

    /// `value(object, vertex)` of every vertex, all objects, concatenated.
    fn per_vertex<T: Clone>(scene: &Scene, value: impl Fn(usize, usize) -> Vec<T>) -> Vec<T> {
        let objects = scene.objects().iter().enumerate();
        objects
            .flat_map(|(o, object)| (0..object.mesh.vertex_count()).map(move |v| (o, v)))
            .flat_map(|(o, v)| value(o, v))
            .collect()
    }

    fn transfers(method: &HemiRaster, scene: &Scene) -> Vec<f32> {
        per_vertex(scene, |o, v| method.transfer(o, v).unwrap().to_vec())
    }

    fn blocked(method: &HemiRaster, scene: &Scene) -> Vec<f32> {
        per_vertex(scene, |o, v| vec![method.blocked_fraction(o, v).unwrap()])
    }

    /// On the frames it was built from, the sets change no mask: the
    /// transfer vectors are equal to the bit, with far fewer blockers.
    #[test]
    fn known_frames_are_reproduced_exactly() {
        let scene = scene(&[0.0, 0.4, 0.7, 1.0]);
        for hierarchy in hierarchies() {
            let mut all = prepared(hierarchy, Pvs::Off, &scene);
            let mut sets = prepared(hierarchy, Pvs::EVERY_FRAME, &scene);
            let mut shadowed = 0;
            for f in 0..scene.frames().len() {
                let frame = scene.frame_geometry(f).unwrap();
                let every = all.profile_update(&frame).unwrap();
                let visible = sets.profile_update(&frame).unwrap();
                assert_eq!(
                    transfers(&all, &scene),
                    transfers(&sets, &scene),
                    "{hierarchy:?}, frame {f}"
                );
                shadowed += blocked(&all, &scene).iter().filter(|&&b| b > 0.05).count();
                let candidates = |p: &Profile| p.count_in(Stage::Update, "candidates").unwrap();
                assert!(
                    3 * candidates(&visible) < candidates(&every),
                    "{hierarchy:?}, frame {f}: {} of {} candidates",
                    candidates(&visible),
                    candidates(&every)
                );
            }
            assert!(shadowed > 500, "the scene must shadow: {shadowed}");
        }
    }

    /// On a pose between the known ones a set may miss a blocker, never add
    /// one: every vertex is blocked at most as much as without the sets.
    #[test]
    fn other_poses_only_lose_blockers() {
        // Sets from the first and last frame only.
        let known = scene(&[0.0, 0.5, 1.0]);
        let pvs = Pvs::Animation {
            stride: NonZeroU32::new(2).unwrap(),
        };
        let between = known.frame_geometry(1).unwrap();
        for hierarchy in hierarchies() {
            let mut all = prepared(hierarchy, Pvs::Off, &known);
            let mut sets = prepared(hierarchy, pvs, &known);
            all.update(&between, known.camera()).unwrap();
            sets.update(&between, known.camera()).unwrap();
            let (every, visible) = (blocked(&all, &known), blocked(&sets, &known));
            for (v, (e, s)) in every.iter().zip(&visible).enumerate() {
                assert!(s <= e, "{hierarchy:?}, vertex {v}: {s} > {e}");
            }
            // Two frames far apart leave many blockers out between them
            // (two thirds of the blocked area is kept here): a set should be
            // built from frames as dense as those it will be used on.
            let (sum_every, sum_visible) = (every.iter().sum::<f32>(), visible.iter().sum::<f32>());
            assert!(sum_every > 100.0, "the scene must shadow: {sum_every}");
            assert!(sum_visible < sum_every, "{sum_visible} of {sum_every}");
        }
    }
}
