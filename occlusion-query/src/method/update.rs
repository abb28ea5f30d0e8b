//! `update`: the state brought to a frame (uploads, vertex lists) and the
//! depth maps and vertex tests it needs, run or recorded.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat4, Vec3, Vec4};
use shadow_core::{Camera, Error, FrameGeometry, Mesh, Result, Stage};

use super::{Job, OcclusionQuery, Prepared, State};
use crate::config::{Config, DepthOffset};
use crate::filter::vertices_of;
use crate::lightsphere::Lightsphere;
use crate::name::NAME;
use crate::views::{self, GpuDirection};
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
        let (positions, normals, transform) = Self::geometry_of(frame, scene)?;
        let vertices = positions.len();
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
            let (centre, radius) = bounding_sphere(&positions);
            let finest = &self.spheres[self.config.finest().get() as usize];
            let (directions, offset) =
                fitted(finest, centre, radius, &self.config, scene.simplification);
            scene.gpu.geometry.write(&ctx, &positions, &normals);
            scene.gpu.visibility.set_view(&ctx, &directions, offset);
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

/// A sphere holding every point: the centre of their bounds, and the largest
/// distance from it.
pub(super) fn bounding_sphere(positions: &[Vec4]) -> (Vec3, f32) {
    let points = positions.iter().map(|p| p.truncate());
    let bounds = shadow_core::Aabb::from_points(points.clone());
    let centre = bounds.center();
    let radius = points.map(|p| p.distance(centre)).fold(0.0f32, f32::max);
    (centre, radius.max(1e-6))
}

/// Every direction's view of the sphere (`centre`, `radius`), grown so that
/// the tested vertices, once moved by their offsets, stay inside the view
/// volume (where the paper's queries are reliable), and those offsets in
/// world units; `simplification` adds to the move along the normal.
fn fitted(
    sphere: &Lightsphere,
    centre: Vec3,
    radius: f32,
    config: &Config,
    simplification: f32,
) -> (Vec<GpuDirection>, TestOffset) {
    let inner = radius * 1.01;
    let texel = 2.0 * inner / config.map_resolution as f32;
    let offset = TestOffset {
        toward_light: config.offset.toward_light * texel,
        along_normal: config.offset.along_normal * texel + simplification,
        slope: config.offset.receiver_slope * texel,
        max_tan: DepthOffset::MAX_TAN,
    };
    let outer = inner + offset.toward_light + offset.slope * offset.max_tan + offset.along_normal;
    (views::directions(sphere, centre, outer), offset)
}
