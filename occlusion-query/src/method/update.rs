//! `update`: the state brought to a frame (uploads, vertex lists) and the
//! depth maps and vertex tests it needs, run or recorded.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat4, Vec3, Vec4};
use shadow_core::contact::Contacts;
use shadow_core::{Camera, Error, FrameGeometry, Mesh, Result, Stage};

use super::{Job, OcclusionQuery, Prepared, State};
use crate::config::{Config, DepthOffset};
use crate::filter::vertices_of;
use crate::name::NAME;
use crate::views::{self, Regions};
use crate::visibility::{Counts, TestOffset};

impl OcclusionQuery {
    /// The positions and normals to upload for `frame` (model space when
    /// rigid), and its model-to-world transform.
    fn geometry_of(
        frame: &FrameGeometry,
        scene: &Prepared,
    ) -> Result<(Vec<Vec4>, Vec<Vec4>, Affine3A)> {
        let counts: Vec<usize> = frame.objects.iter().map(|o| o.vertex_count()).collect();
        if counts != scene.vertex_counts {
            return Err(Error::InvalidScene(format!(
                "{NAME}: frame {} has vertex counts {counts:?} per object, the prepared scene {:?}",
                frame.frame, scene.vertex_counts
            )));
        }
        let meshes: Vec<&Mesh> = match &scene.model {
            Some(model) => vec![model],
            None => frame.objects.iter().map(|o| &*o.mesh).collect(),
        };
        let positions = meshes
            .iter()
            .flat_map(|m| m.positions())
            .map(|p| p.extend(1.0));
        let normals = meshes
            .iter()
            .flat_map(|m| m.normals())
            .map(|n| n.extend(0.0));
        let transform = match &scene.model {
            Some(_) => frame.objects[0].transform.unwrap_or(Affine3A::IDENTITY),
            None => Affine3A::IDENTITY,
        };
        Ok((positions.collect(), normals.collect(), transform))
    }

    /// Brings the state to `frame` (uploads, lists) and says which vertices
    /// to test against which directions. With filtering, runs the camera
    /// pass, which reads query results back.
    pub(super) fn plan(&mut self, frame: &FrameGeometry, camera: &Camera) -> Result<Vec<Job>> {
        let scene = self.prepared()?;
        let (positions, mut normals, transform) = Self::geometry_of(frame, scene)?;
        let vertices = positions.len();
        // Each vertex's region rides as its normal's w (module docs of
        // `crate::views`).
        let regions = regions_of(&positions, &scene.vertex_counts, scene.model.is_some());
        let vertex_regions = vertex_regions(&regions, &scene.vertex_counts, vertices);
        for (n, &r) in normals.iter_mut().zip(&vertex_regions) {
            n.w = r as f32;
        }
        let changed = match &self.state {
            None => true,
            // The rigid object's model-space mesh never changes.
            Some(_) if scene.model.is_some() => false,
            Some(state) => state.positions != positions || state.normals != normals,
        };
        let ctx = Arc::clone(&self.ctx);
        let scene = self.scene.as_mut().expect("checked above");
        let mut jobs = Vec::new();
        if changed {
            let finest = &self.spheres[self.config.finest().get() as usize];
            let offset = test_offset(&self.config, finest.len(), scene.simplification);
            let directions = views::views(finest, &regions, self.config.map_resolution, &offset);
            scene.gpu.geometry.write(&ctx, &positions, &normals);
            (scene.gpu.visibility).set_view(&ctx, &directions, offset, vertex_regions.clone());
            let (blocked, push) = match scene.model {
                Some(_) => (Vec::new(), Vec::new()),
                None => {
                    // How far each vertex moves along its normal at most.
                    let texels: Vec<f32> = (regions.spheres.iter())
                        .map(|s| 2.0 * 1.01 * s.1 / self.config.map_resolution as f32)
                        .collect();
                    let reach = |v: usize| {
                        offset.along_normal * texels[vertex_regions[v] as usize]
                            + offset.simplification
                    };
                    contacts(frame, finest.directions(), reach)?
                }
            };
            scene.gpu.visibility.set_contacts(&ctx, &blocked, &push);
            let push = match push.is_empty() {
                true => vec![Vec4::ZERO; vertices],
                false => push,
            };
            if let Some(filter) = &mut scene.gpu.filter {
                filter.reset();
            }
            let level = self.config.level;
            self.state = Some(State {
                frame: frame.clone(),
                transform,
                positions,
                normals,
                views: directions,
                offset,
                vertex_regions,
                push,
                level,
                evaluated: vec![scene.gpu.filter.is_none(); vertices],
                lit: None,
            });
            let state = self.state.as_mut().expect("set above");
            let list = match scene.gpu.filter {
                None => (0..vertices as u32).collect(),
                Some(_) => scene.loose.clone(),
            };
            for &v in &list {
                state.evaluated[v as usize] = true;
            }
            if !list.is_empty() {
                jobs.push(Job {
                    list,
                    directions: 0..level.directions(),
                });
            }
        } else {
            let state = self.state.as_mut().expect("not changed, so present");
            state.frame = frame.clone();
            state.transform = transform;
            let idle = self.config.idle_level.filter(|&idle| idle > state.level);
            if let Some(finer) = idle.and_then(|_| state.level.finer()) {
                let list: Vec<u32> = (0..vertices as u32)
                    .filter(|&v| state.evaluated[v as usize])
                    .collect();
                jobs.push(Job {
                    list,
                    directions: state.level.directions()..finer.directions(),
                });
                state.level = finer;
            }
        }
        let state = self.state.as_mut().expect("set above");
        if let (Some(filter), Some(filtering)) = (&mut scene.gpu.filter, self.config.filtering) {
            let model = Mat4::from(state.transform);
            let start = Instant::now();
            let seen = filter.newly_seen(
                &ctx,
                &scene.gpu.geometry,
                camera,
                model,
                filtering.threshold,
            )?;
            let touched = vertices_of(&seen, &scene.triangles, vertices);
            let list: Vec<u32> = (0..vertices as u32)
                .filter(|&v| touched[v as usize] && !state.evaluated[v as usize])
                .collect();
            for &v in &list {
                state.evaluated[v as usize] = true;
            }
            self.profile.seconds(
                Stage::Update,
                "camera queries",
                start.elapsed().as_secs_f64(),
            );
            self.profile
                .count(Stage::Update, "triangles unseen", filter.remaining() as u64);
            if !list.is_empty() {
                jobs.push(Job {
                    list,
                    directions: 0..state.level.directions(),
                });
            }
        }
        scene.gpu.shading.set_evaluated(&ctx, &state.evaluated);
        Ok(jobs)
    }

    /// Records `jobs` into `encoder`, or, with `timed`, runs each batch's
    /// maps and tests as their own blocking submissions and profiles them.
    pub(super) fn run_jobs(
        &mut self,
        jobs: Vec<Job>,
        mut encoder: Option<&mut wgpu::CommandEncoder>,
    ) -> Result<()> {
        let ctx = Arc::clone(&self.ctx);
        let gpu = &mut self.scene.as_mut().expect("planned").gpu;
        let (mut maps_seconds, mut tests_seconds, mut counts) = (0.0, 0.0, Counts::default());
        for job in jobs {
            gpu.visibility.set_list(&ctx, &job.list);
            for (index, batch) in gpu
                .visibility
                .batches(job.directions)
                .into_iter()
                .enumerate()
            {
                let (visibility, geometry) = (&gpu.visibility, &gpu.geometry);
                let (maps, tests) = match encoder.as_deref_mut() {
                    Some(encoder) => (
                        visibility.record_maps(encoder, geometry, batch.clone()),
                        visibility.record_tests(&ctx, encoder, geometry, batch, index)?,
                    ),
                    None => {
                        let start = Instant::now();
                        let maps = ctx.run("occlusion-query: depth maps", |encoder| {
                            Ok(visibility.record_maps(encoder, geometry, batch.clone()))
                        })?;
                        let middle = Instant::now();
                        let tests = ctx.run("occlusion-query: vertex tests", |encoder| {
                            visibility.record_tests(&ctx, encoder, geometry, batch, index)
                        })?;
                        maps_seconds += (middle - start).as_secs_f64();
                        tests_seconds += middle.elapsed().as_secs_f64();
                        (maps, tests)
                    }
                };
                counts.maps += maps.maps;
                counts.tests += tests.tests;
            }
        }
        if encoder.is_none() {
            self.profile
                .seconds(Stage::Update, "depth maps", maps_seconds);
            self.profile
                .seconds(Stage::Update, "vertex tests", tests_seconds);
        }
        self.profile
            .count(Stage::Update, "maps rendered", counts.maps);
        self.profile
            .count(Stage::Update, "vertex-direction tests", counts.tests);
        Ok(())
    }
}

/// What contacts with other objects do to the tests of each vertex of
/// `frame` (all objects one after another; [`shadow_core::contact`]):
/// `⌈k/32⌉` words of the directions `lights` (k of them) blocked whatever
/// the maps say (every direction of a vertex pressed on another object's
/// surface; at a contact, the floor under a box's side or the wall's foot
/// on the floor, the directions that see the other surface's front), and
/// the direction the vertex moves off the surfaces it touches before its
/// tests (xyz) and how much of its move along its own normal (`reach`, per
/// vertex) is cut short (w): no further than halfway to another object's
/// surface. The paper's maps see the other surface edge-on there, and the
/// vertex on it passes or fails their depth test by chance; and half a
/// texel along the normal takes the underside of a model resting a
/// millimetre over a floor through the floor, into the light below it.
/// Buried vertices need no rule: the maps see the closed object around
/// them. Empty when no vertex touches or nears anything.
fn contacts(
    frame: &FrameGeometry,
    lights: &[Vec3],
    reach: impl Fn(usize) -> f32 + Sync,
) -> Result<(Vec<u32>, Vec<Vec4>)> {
    use rayon::prelude::*;
    let words = lights.len().div_ceil(32);
    let contacts = Contacts::new(frame, &vec![false; frame.objects.len()])?;
    let vertices: Vec<(usize, usize)> = (frame.objects.iter().enumerate())
        .flat_map(|(o, object)| (0..object.vertex_count()).map(move |v| (o, v)))
        .collect();
    let mut bits = vec![0u32; vertices.len() * words];
    let mut push = vec![Vec4::ZERO; vertices.len()];
    bits.par_chunks_mut(words)
        .zip(push.par_iter_mut())
        .zip(vertices.par_iter().enumerate())
        .for_each(|((out, push), (i, &(o, v)))| {
            let contact = contacts.at(o, v);
            for (j, l) in lights.iter().enumerate() {
                if contact.enclosed || contact.planes.iter().any(|c| c.blocks(*l)) {
                    out[j / 32] |= 1 << (j % 32);
                }
            }
            let most = reach(i);
            let cut = 1.0 - (0.5 * contacts.clearance(o, v, 2.0 * most) / most).min(1.0);
            *push = (contact.planes.iter().map(|c| c.front).sum::<Vec3>())
                .normalize_or_zero()
                .extend(cut);
        });
    Ok(
        if bits.iter().all(|&w| w == 0) && push.iter().all(|&p| p == Vec4::ZERO) {
            (Vec::new(), Vec::new())
        } else {
            (bits, push)
        },
    )
}

/// The regions of a frame whose objects have `counts` vertices each, one
/// after another in `positions` (one region for a rigid object in model
/// space).
pub(super) fn regions_of(positions: &[Vec4], counts: &[usize], rigid: bool) -> Regions {
    if rigid {
        return Regions::whole(positions);
    }
    let mut objects = Vec::with_capacity(counts.len());
    let mut first = 0;
    for &n in counts {
        objects.push(&positions[first..first + n]);
        first += n;
    }
    Regions::new(&objects)
}

/// Each of `vertices` vertices' region.
fn vertex_regions(regions: &Regions, counts: &[usize], vertices: usize) -> Vec<u32> {
    if regions.of_object.len() != counts.len() {
        return vec![0; vertices];
    }
    (counts.iter().zip(&regions.of_object))
        .flat_map(|(&n, &r)| std::iter::repeat_n(r, n))
        .collect()
}

/// The tested vertices' offset in texels of their region's maps
/// (`config.offset`), the simplified occluders' bound in world units, and
/// the views of a region per `directions` directions.
fn test_offset(config: &Config, directions: usize, simplification: f32) -> TestOffset {
    TestOffset {
        toward_light: config.offset.toward_light,
        along_normal: config.offset.along_normal,
        slope: config.offset.receiver_slope,
        max_tan: DepthOffset::MAX_TAN,
        simplification,
        stride: directions as u32,
        _pad: [0; 2],
    }
}
