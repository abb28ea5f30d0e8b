//! `prepare`: the scene checked, occluders simplified, and the GPU
//! resources built for it.

use std::sync::Arc;

use glam::{Mat3, Vec3, Vec4};
use shadow_core::{Brdf, Mesh, Pose, Result, Scene, ShadowMethod, Stage, simplify};

use super::update::regions_of;
use super::{Gpu, OcclusionQuery, Prepared};
use crate::config::Occluder;
use crate::filter::{CameraFilter, vertices_of};
use crate::name::NAME;
use crate::occluder;
use crate::shading::Shading;
use crate::visibility::{Geometry, Visibility};

impl OcclusionQuery {
    /// Checks the scene and builds the GPU resources for it.
    pub(super) fn prepare_scene(&mut self, scene: &Scene) -> Result<Prepared> {
        self.capabilities().check(NAME, scene)?;
        let model = is_rigid(scene).then(|| Arc::clone(&scene.objects()[0].mesh));
        let mut triangles = Vec::new();
        let mut occluders = Vec::new();
        let mut objects = Vec::new();
        // The depth maps' texels at the first frame, for how far simplified
        // occluders may deviate: each object's region's, in world units.
        let first_frame = scene.frame_geometry(0)?;
        let meshes: Vec<&Mesh> = match &model {
            Some(model) => vec![model],
            None => first_frame.objects.iter().map(|o| &*o.mesh).collect(),
        };
        let points: Vec<Vec4> = meshes
            .iter()
            .flat_map(|m| m.positions())
            .map(|p| p.extend(1.0))
            .collect();
        let counts: Vec<usize> = meshes.iter().map(|m| m.vertex_count()).collect();
        let regions = regions_of(&points, &counts, model.is_some());
        let texel = |o: usize| {
            let region = regions.of_object.get(o).map_or(0, |&r| r as usize);
            2.0 * 1.01 * regions.spheres[region].1 / self.config.map_resolution as f32
        };
        let mut first = 0u32;
        let mut simplification = 0.0f32;
        for (o, object) in scene.objects().iter().enumerate() {
            let mesh = &object.mesh;
            triangles.extend(mesh.triangles().iter().flatten().map(|&v| v + first));
            let drawn = match self.config.occluder {
                Occluder::Full => mesh.triangles().to_vec(),
                Occluder::Simplified { texels } => {
                    // The bound is in the rest mesh's units, the maps' texel
                    // in the world's: the first pose's stretch relates them.
                    let stretch = match &model {
                        Some(_) => 1.0,
                        None => occluder::stretch(mesh, &first_frame.objects[o]),
                    };
                    let simplified = simplify::simplified(mesh, texels * texel(o) / stretch)?;
                    simplification = simplification.max(simplified.error * stretch);
                    simplified.triangles
                }
            };
            let drawn = meshopt::optimize_vertex_cache(drawn.as_flattened(), mesh.vertex_count());
            occluders.extend(drawn.iter().map(|&v| v + first));
            objects.extend(std::iter::repeat_n(o as u32, mesh.vertex_count()));
            first += mesh.vertex_count() as u32;
        }
        let vertices = first as usize;
        let every_triangle: Vec<u32> = (0..(triangles.len() / 3) as u32).collect();
        let in_triangle = vertices_of(&every_triangle, &triangles, vertices);
        let zeros = vec![Vec4::ZERO; vertices];
        let ctx = &self.ctx;
        let k = self.finest().len();
        let config = &self.config;
        let materials: Vec<Brdf> = scene.objects().iter().map(|o| o.material).collect();
        let gpu = ctx.capture("occlusion-query: prepare", || {
            let geometry = Geometry::new(ctx, &zeros, &zeros, &occluders);
            let visibility = Visibility::new(ctx, config, &geometry, k)?;
            let shading = Shading::new(
                ctx,
                &geometry,
                &visibility,
                visibility.directions(),
                &materials,
                objects,
                k,
            );
            let filter = config.filtering.map(|_| CameraFilter::new(ctx, &triangles));
            Ok(Gpu {
                geometry,
                visibility,
                shading,
                filter,
            })
        })?;
        self.profile.count(
            Stage::Prepare,
            "occluder triangles",
            (occluders.len() / 3) as u64,
        );
        Ok(Prepared {
            vertex_counts: scene
                .objects()
                .iter()
                .map(|o| o.mesh.vertex_count())
                .collect(),
            triangles,
            loose: (0..vertices as u32)
                .filter(|&v| !in_triangle[v as usize])
                .collect(),
            model,
            simplification,
            gpu,
        })
    }
}

/// A scene of one object whose every pose is rigid without shear or
/// non-uniform scale: its visibility turns with it (§6).
fn is_rigid(scene: &Scene) -> bool {
    scene.objects().len() == 1
        && scene.frames().iter().all(|f| match &f.poses[0] {
            Pose::Rigid(t) => is_similarity(t.matrix3.into()),
            Pose::Deformed { .. } => false,
        })
}

/// Whether `m` is a rotation times a positive uniform scale.
fn is_similarity(m: Mat3) -> bool {
    let scale = m.x_axis.length();
    let mtm = m.transpose() * m;
    scale > 0.0
        && m.determinant() > 0.0
        && mtm.abs_diff_eq(
            Mat3::from_diagonal(Vec3::splat(scale * scale)),
            1e-4 * scale * scale,
        )
}
