//! `prepare`: the scene checked for rigid poses, each object's transfer
//! precomputed (§4.1, §5.1), the geometry uploaded.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Mat4};
use shadow_core::{Brdf, Capability, Error, Pose, Result, Scene, ShadowMethod, Stage, sh::Zonal};

use super::inputs::rigid;
use super::{DeferredShadow, Part, Prepared, Shading};
use crate::gpu::{Geometry, Gpu, GpuObject, LEVELS};
use crate::groups::Groups;
use crate::name::NAME;
use crate::transfer::{DIFFUSE_ORDER, GLOSSY_ORDER, Transfer};

impl DeferredShadow {
    /// Checks that every pose of the scene is rigid, precomputes each
    /// object's transfer and builds the GPU resources.
    pub(super) fn prepare_scene(&mut self, scene: &Scene) -> Result<Prepared> {
        self.capabilities().check(&self.name, scene)?;
        for frame in scene.frames() {
            for (pose, object) in frame.poses.iter().zip(scene.objects()) {
                match pose {
                    Pose::Rigid(t) => {
                        rigid(object.mesh.name(), *t)?;
                    }
                    Pose::Deformed { .. } => {
                        return Err(Error::Unsupported {
                            method: self.name.clone(),
                            capability: Capability::DeformingMeshes,
                        });
                    }
                }
            }
        }
        let shadings = scene
            .objects()
            .iter()
            .map(|o| shading_of(o.mesh.name(), o.material))
            .collect::<Result<Vec<_>>>()?;
        let start = Instant::now();
        let mut parts = Vec::new();
        let mut first_vertex = 0;
        for (object, shading) in scene.objects().iter().zip(shadings) {
            let order = match shading {
                Shading::Diffuse { .. } => DIFFUSE_ORDER,
                Shading::Glossy { .. } => GLOSSY_ORDER,
            };
            parts.push(Part {
                mesh: Arc::clone(&object.mesh),
                transfer: Transfer::precompute(&object.mesh, order, self.config.rays)?,
                material: object.material,
                shading,
                first_vertex,
                bounds: object.mesh.bounds(),
            });
            first_vertex += object.mesh.vertex_count();
        }
        self.profile.seconds(
            Stage::Prepare,
            "self transfer (ray-traced)",
            start.elapsed().as_secs_f64(),
        );
        self.profile.count(
            Stage::Prepare,
            "transfer bytes",
            parts.iter().map(|p| p.transfer.bytes() as u64).sum(),
        );
        let start = Instant::now();
        let frame = scene.frame_geometry(0)?;
        let transforms: Vec<Affine3A> = Self::poses_of(&frame)?.into_iter().map(|p| p.0).collect();
        let groups = Groups::of_scene(&self.config.grouping, scene)?;
        let geometry = Geometry::new(parts.iter().map(|p| &*p.mesh), self.config.map_resolution)?;
        for (level, name) in [(0, "occluder triangles"), (LEVELS as usize - 1, "coarsest")] {
            let triangles = geometry
                .occluder_levels
                .iter()
                .map(|l| l[level].indices.len() / 3);
            self.profile
                .count(Stage::Prepare, name, triangles.sum::<usize>() as u64);
        }
        let objects: Vec<GpuObject> = parts
            .iter()
            .zip(&transforms)
            .zip(&groups.of_object)
            .map(|((part, t), &g)| GpuObject::new(Mat4::from(*t), &part.material, g))
            .collect();
        let mut gpu = Gpu::new(Arc::clone(&self.ctx), &geometry, &objects, &self.config)?;
        gpu.check_shading(self.config.lights)?;
        self.profile.seconds(
            Stage::Prepare,
            "pipelines and buffers",
            start.elapsed().as_secs_f64(),
        );
        gpu.warm_up()?;
        if let Some(lit) = &self.lit {
            gpu.set_lights(&lit.gpu)?;
        }
        Ok(Prepared {
            parts,
            triangles: geometry.triangles,
            groups,
            gpu,
        })
    }
}

/// How object `name` shades: a glossy material with its Phong lobe's
/// zonal expansion (eq. 12), which every exponent a scene accepts has.
fn shading_of(name: &str, material: Brdf) -> Result<Shading> {
    let refused = |what: String| Error::InvalidScene(format!("{NAME}: object {name}: {what}"));
    match material {
        Brdf::Phong {
            diffuse,
            specular,
            exponent,
        } if material.is_glossy() => Ok(Shading::Glossy {
            diffuse,
            specular,
            lobe: Zonal::phong(GLOSSY_ORDER, exponent)
                .ok_or_else(|| refused(format!("Phong exponent {exponent} has no lobe")))?,
        }),
        material => Ok(Shading::Diffuse {
            albedo: material.diffuse(),
        }),
    }
}
