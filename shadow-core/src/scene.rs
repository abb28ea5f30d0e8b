//! Scenes: meshes with materials, posed per frame, seen by one camera.
//!
//! No scene graph and no engine (DESIGN.md, "model no more than a scene needs"):
//! a scene is a list of objects, a list of frames giving each object a pose, and
//! a camera.

use std::sync::Arc;

use glam::{Affine3A, Vec3};

use crate::{Aabb, Brdf, Camera, Error, Mesh, Result, SurfacePoint};

/// One object: a mesh in its own model space, and its material.
#[derive(Clone, Debug)]
pub struct Object {
    pub mesh: Arc<Mesh>,
    pub material: Brdf,
}

/// Where an object is in one frame.
#[derive(Clone, Debug)]
pub enum Pose {
    /// The model-space mesh moved rigidly (rotation, translation, uniform or
    /// non-uniform scale). Methods that precompute per object (Tamura et al.)
    /// need every pose of an object to be of this kind.
    Rigid(Affine3A),
    /// New world-space positions for the mesh's vertices (skinning, morphs,
    /// cloth), with normals if the source gave them; otherwise area-weighted
    /// normals are recomputed.
    Deformed {
        positions: Arc<[Vec3]>,
        normals: Option<Arc<[Vec3]>>,
    },
}

/// The poses of every object at one instant.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Seconds from the start of the sequence.
    pub time: f32,
    pub poses: Vec<Pose>,
}

/// Objects, their poses over a sequence of frames, and a camera.
#[derive(Clone, Debug)]
pub struct Scene {
    name: String,
    objects: Vec<Object>,
    frames: Vec<Frame>,
    camera: Camera,
}

impl Scene {
    /// Validates and builds a scene: at least one object and one frame, one pose
    /// per object in every frame, deformed poses with one finite position (and
    /// normal) per vertex, finite rigid transforms.
    pub fn new(
        name: impl Into<String>,
        objects: Vec<Object>,
        frames: Vec<Frame>,
        camera: Camera,
    ) -> Result<Scene> {
        let name = name.into();
        let bad = |what: String| Error::InvalidScene(format!("{name}: {what}"));
        if objects.is_empty() {
            return Err(bad("no objects".into()));
        }
        if frames.is_empty() {
            return Err(bad("no frames".into()));
        }
        for (o, object) in objects.iter().enumerate() {
            object.material.check().map_err(|e| {
                bad(format!(
                    "object {o} ({}): {}",
                    object.mesh.name(),
                    match e {
                        Error::InvalidScene(what) => what,
                        e => e.to_string(),
                    }
                ))
            })?;
        }
        for (f, frame) in frames.iter().enumerate() {
            if frame.poses.len() != objects.len() {
                return Err(bad(format!(
                    "frame {f} has {} poses for {} objects",
                    frame.poses.len(),
                    objects.len()
                )));
            }
            for (o, (pose, object)) in frame.poses.iter().zip(&objects).enumerate() {
                let n = object.mesh.vertex_count();
                match pose {
                    Pose::Rigid(t) if !t.is_finite() => {
                        return Err(bad(format!("frame {f}, object {o}: non-finite transform")));
                    }
                    Pose::Deformed { positions, normals } => {
                        if positions.len() != n || normals.as_ref().is_some_and(|nn| nn.len() != n)
                        {
                            return Err(bad(format!(
                                "frame {f}, object {o} ({}): deformed pose does not have {n} vertices",
                                object.mesh.name()
                            )));
                        }
                        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
                            return Err(bad(format!(
                                "frame {f}, object {o}: vertex {i} has a non-finite position"
                            )));
                        }
                    }
                    Pose::Rigid(_) => {}
                }
            }
        }
        Ok(Scene {
            name,
            objects,
            frames,
            camera,
        })
    }

    /// A single static frame: every object at the identity pose.
    pub fn still(name: impl Into<String>, objects: Vec<Object>, camera: Camera) -> Result<Scene> {
        let poses = vec![Pose::Rigid(Affine3A::IDENTITY); objects.len()];
        Scene::new(name, objects, vec![Frame { time: 0.0, poses }], camera)
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn objects(&self) -> &[Object] {
        &self.objects
    }

    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// A copy of the scene seen through another camera.
    pub fn with_camera(mut self, camera: Camera) -> Scene {
        self.camera = camera;
        self
    }

    /// True when some object changes shape (not only place) over the frames.
    pub fn deforms(&self) -> bool {
        self.frames
            .iter()
            .flat_map(|f| &f.poses)
            .any(|p| matches!(p, Pose::Deformed { .. }))
    }

    /// True when some object's pose differs between frames.
    pub fn moves(&self) -> bool {
        self.frames.len() > 1
    }

    /// Total number of vertices over all objects.
    pub fn vertex_count(&self) -> usize {
        self.objects.iter().map(|o| o.mesh.vertex_count()).sum()
    }

    /// Total number of triangles over all objects.
    pub fn triangle_count(&self) -> usize {
        self.objects.iter().map(|o| o.mesh.triangle_count()).sum()
    }

    /// The world-space geometry of frame `index`.
    pub fn frame_geometry(&self, index: usize) -> Result<FrameGeometry> {
        let frame = self.frames.get(index).ok_or_else(|| {
            Error::InvalidScene(format!(
                "{}: frame {index} of {}",
                self.name,
                self.frames.len()
            ))
        })?;
        let objects = self
            .objects
            .iter()
            .zip(&frame.poses)
            .map(|(object, pose)| PosedObject::new(&object.mesh, pose))
            .collect::<Result<_>>()?;
        Ok(FrameGeometry {
            frame: index,
            objects,
        })
    }
}

/// World-space positions and unit normals of every object in one frame. The
/// triangles are the objects' meshes' own ([`Mesh::triangles`]).
#[derive(Clone, Debug)]
pub struct FrameGeometry {
    /// Index of the frame in its scene.
    pub frame: usize,
    pub objects: Vec<PosedObject>,
}

impl FrameGeometry {
    pub fn bounds(&self) -> Aabb {
        self.objects
            .iter()
            .map(|o| o.bounds())
            .fold(Aabb::EMPTY, Aabb::union)
    }

    /// Every vertex's world position and unit normal, the objects' vertices
    /// one after another: the flat order of per-vertex buffers.
    pub fn vertices(&self) -> impl Iterator<Item = (Vec3, Vec3)> + '_ {
        self.object_vertices()
            .map(|(_, v)| (v.position.as_vec3(), v.normal))
    }

    /// Every vertex as (object index, the surface point it is), objects in
    /// order.
    pub fn object_vertices(&self) -> impl Iterator<Item = (u32, SurfacePoint)> + '_ {
        self.objects.iter().enumerate().flat_map(|(i, o)| {
            (o.positions().iter().zip(o.normals()).zip(o.lifts())).map(
                move |((&position, &normal), &lift)| {
                    let point = SurfacePoint {
                        position: position.as_dvec3(),
                        normal,
                        lift,
                    };
                    (i as u32, point)
                },
            )
        })
    }
}

/// One object in world space.
#[derive(Clone, Debug)]
pub struct PosedObject {
    /// The mesh in world space (positions and unit normals), same topology as
    /// the scene object's.
    pub mesh: Arc<Mesh>,
    /// The rigid transform from model to world space when the pose is rigid.
    pub transform: Option<Affine3A>,
}

impl std::ops::Deref for PosedObject {
    type Target = Mesh;
    fn deref(&self) -> &Mesh {
        &self.mesh
    }
}

impl PosedObject {
    fn new(mesh: &Arc<Mesh>, pose: &Pose) -> Result<PosedObject> {
        match pose {
            Pose::Rigid(t) if *t == Affine3A::IDENTITY => Ok(PosedObject {
                mesh: Arc::clone(mesh),
                transform: Some(*t),
            }),
            Pose::Rigid(t) => {
                // Normals transform by the inverse transpose; a mirroring
                // transform flips winding, which the CCW convention forbids.
                let linear = t.matrix3;
                if linear.determinant() <= 0.0 {
                    return Err(Error::InvalidScene(format!(
                        "{}: rigid transform mirrors or flattens the mesh (determinant {})",
                        mesh.name(),
                        linear.determinant()
                    )));
                }
                let normal_matrix = linear.inverse().transpose();
                let positions = mesh
                    .positions()
                    .iter()
                    .map(|p| t.transform_point3(*p))
                    .collect();
                let normals = mesh.normals().iter().map(|n| normal_matrix * *n).collect();
                Ok(PosedObject {
                    mesh: Arc::new(mesh.with_pose(positions, Some(normals))?),
                    transform: Some(*t),
                })
            }
            Pose::Deformed { positions, normals } => Ok(PosedObject {
                mesh: Arc::new(
                    mesh.with_pose(positions.to_vec(), normals.as_ref().map(|n| n.to_vec()))?,
                ),
                transform: None,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use glam::Quat;

    fn triangle() -> Arc<Mesh> {
        Arc::new(
            Mesh::new(
                "tri",
                vec![Vec3::ZERO, Vec3::X, Vec3::NEG_Z],
                None,
                vec![[0, 1, 2]],
            )
            .unwrap(),
        )
    }

    fn camera() -> Camera {
        Camera::new(Vec3::new(0.0, 1.0, 3.0), Vec3::ZERO, Vec3::Y, 1.0, 16, 16).unwrap()
    }

    #[test]
    fn rigid_pose_moves_positions_and_normals() {
        let object = Object {
            mesh: triangle(),
            material: Brdf::lambert(Vec3::ONE).unwrap(),
        };
        let t = Affine3A::from_rotation_translation(
            Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            Vec3::new(0.0, 2.0, 0.0),
        );
        let frames = vec![Frame {
            time: 0.0,
            poses: vec![Pose::Rigid(t)],
        }];
        let scene = Scene::new("s", vec![object], frames, camera()).unwrap();
        let g = scene.frame_geometry(0).unwrap();
        assert_relative_eq!(g.objects[0].positions()[0], Vec3::new(0.0, 2.0, 0.0));
        assert_relative_eq!(g.objects[0].normals()[0], Vec3::Z, epsilon = 1e-6);
        assert!(!scene.deforms());
    }

    /// Materials built by hand past the BRDF constructors' checks are
    /// refused by the scene, naming the object: no method sees them.
    #[test]
    fn hand_built_materials_out_of_range_are_refused() {
        let phong = |exponent| Brdf::Phong {
            diffuse: Vec3::splat(0.3),
            specular: Vec3::splat(0.5),
            exponent,
        };
        let materials = [
            phong(-1.0),
            phong(f32::NAN),
            phong(f32::INFINITY),
            Brdf::Lambert {
                albedo: Vec3::splat(1.5),
            },
        ];
        for material in materials {
            let object = Object {
                mesh: triangle(),
                material,
            };
            let msg = Scene::still("s", vec![object], camera())
                .unwrap_err()
                .to_string();
            assert!(msg.contains("object 0 (tri)"), "{material:?}: {msg}");
        }
    }

    #[test]
    fn mismatched_poses_are_errors() {
        let object = Object {
            mesh: triangle(),
            material: Brdf::lambert(Vec3::ONE).unwrap(),
        };
        let frames = vec![Frame {
            time: 0.0,
            poses: vec![Pose::Deformed {
                positions: vec![Vec3::ZERO; 2].into(),
                normals: None,
            }],
        }];
        let msg = Scene::new("s", vec![object.clone()], frames, camera())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("does not have 3 vertices"), "{msg}");
        assert!(Scene::still("empty", vec![], camera()).is_err());
        let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let frames = vec![Frame {
            time: 0.0,
            poses: vec![Pose::Rigid(mirror)],
        }];
        let scene = Scene::new("m", vec![object], frames, camera()).unwrap();
        assert!(scene.frame_geometry(0).is_err());
    }
}
