//! One node instancing a mesh: how its mesh was built from the file and how
//! it moves (rigid, morphed or skinned).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use glam::{Affine3A, Mat3, Mat4, Vec3};
use shadow_core::{Error, Mesh, Pose, Result};

use super::accessor::Buffers;
use super::geometry::{Geometry, VertexAttribute};
use super::morph::Morph;
use super::skin::{Skin, normal_matrix};
use super::{GltfReport, ObjectSource};

/// The mirror that turns a mirrored node's mesh back into a rotation-only pose.
const MIRROR: Vec3 = Vec3::new(-1.0, 1.0, 1.0);

/// One node instancing a mesh.
pub(super) struct Instance {
    pub(super) node: usize,
    pub(super) source: ObjectSource,
    pub(super) attributes: BTreeMap<String, VertexAttribute>,
    pub(super) label: String,
    pub(super) mesh: Arc<Mesh>,
    pub(super) motion: Motion,
}

pub(super) enum Motion {
    /// `Pose::Rigid(world · diag(−1, 1, 1))` when `mirrored`, else `world`.
    Rigid { mirrored: bool },
    /// `world · (base + Σ w Δ)`, from the file's (unmirrored) base shape.
    Morphed {
        mirrored: bool,
        morph: Morph,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
    },
    /// Morph (if any), then skinning of the mesh's bind-pose geometry.
    Skinned {
        skin: Skin,
        morph: Option<Morph>,
        normals: Option<Vec<Vec3>>,
    },
}

impl Instance {
    /// The pose at `time`, from every node's world matrix and morph weights
    /// then; errors name `path`, the node and the time.
    pub(super) fn pose(
        &self,
        path: &Path,
        world: &[Mat4],
        weights: &[Vec<f32>],
        time: f32,
    ) -> Result<Pose> {
        let bad =
            |what: &str| Error::format(path, format!("{} at t = {time} s: {what}", self.label));
        let node_world = world[self.node];
        let check_mirror = |mirrored: bool| {
            let determinant = Mat3::from_mat4(node_world).determinant();
            if determinant == 0.0 || (determinant < 0.0) != mirrored {
                Err(bad(&format!(
                    "the animation changes the sign of the world transform's determinant to {determinant}"
                )))
            } else {
                Ok(())
            }
        };
        let (positions, normals) = match &self.motion {
            Motion::Rigid { mirrored } => {
                check_mirror(*mirrored)?;
                let mirror = if *mirrored {
                    Mat4::from_scale(MIRROR)
                } else {
                    Mat4::IDENTITY
                };
                let transform = Affine3A::from_mat4(node_world * mirror);
                if !transform.is_finite() {
                    return Err(bad("the world transform is not finite"));
                }
                return Ok(Pose::Rigid(transform));
            }
            Motion::Morphed {
                mirrored,
                morph,
                positions,
                normals,
            } => {
                check_mirror(*mirrored)?;
                let (positions, normals) =
                    morph.apply(&weights[self.node], positions, normals.as_deref());
                let normal_world = normal_matrix(Mat3::from_mat4(node_world));
                (
                    positions
                        .iter()
                        .map(|p| node_world.transform_point3(*p))
                        .collect::<Vec<_>>(),
                    normals.map(|n| {
                        n.iter()
                            .map(|n| (normal_world * *n).normalize_or_zero())
                            .collect::<Vec<_>>()
                    }),
                )
            }
            Motion::Skinned {
                skin,
                morph,
                normals,
            } => match morph {
                Some(morph) => {
                    let (positions, normals) = morph.apply(
                        &weights[self.node],
                        self.mesh.positions(),
                        normals.as_deref(),
                    );
                    skin.deform(world, &positions, normals.as_deref())
                }
                None => skin.deform(world, self.mesh.positions(), normals.as_deref()),
            },
        };
        if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
            return Err(bad(&format!("vertex {v} has a non-finite position")));
        }
        Ok(Pose::Deformed {
            positions: positions.into(),
            normals: normals.map(Into::into),
        })
    }
}

/// A mesh instance's node, the name its [`Mesh`] gets, how errors call it,
/// and where its vertices and their other attributes are stored.
pub(super) struct Identity {
    pub(super) node: usize,
    pub(super) name: String,
    pub(super) label: String,
    pub(super) source: ObjectSource,
    pub(super) attributes: BTreeMap<String, VertexAttribute>,
}

impl Identity {
    /// The instance of this node, of `mesh` moving as `motion` says.
    fn instance(self, mesh: Arc<Mesh>, motion: Motion) -> Instance {
        Instance {
            node: self.node,
            source: self.source,
            attributes: self.attributes,
            label: self.label,
            mesh,
            motion,
        }
    }
}

/// A validated mesh, its errors naming the file and the node and mesh.
fn build_mesh(
    path: &Path,
    id: &Identity,
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    triangles: Vec<[u32; 3]>,
) -> Result<Arc<Mesh>> {
    Mesh::new(id.name.clone(), positions, normals, triangles)
        .map(Arc::new)
        .map_err(|e| Error::format(path, format!("{}: {e}", id.label)))
}

pub(super) fn skinned_instance(
    path: &Path,
    buffers: &Buffers,
    id: Identity,
    skin: &::gltf::Skin,
    geometry: Geometry,
    report: &mut GltfReport,
) -> Result<Instance> {
    let label = &id.label;
    let raw = geometry
        .influences
        .as_ref()
        .filter(|r| r.width > 0)
        .ok_or_else(|| {
            Error::format(
                path,
                format!("{label}: skinned, but has no JOINTS_0/WEIGHTS_0"),
            )
        })?;
    let skin = Skin::new(path, label, skin, buffers, raw)?;
    report.renormalized_weights += skin.renormalized;
    let morph = (!geometry.targets.is_empty()).then_some(Morph {
        targets: geometry.targets,
    });
    let mesh = build_mesh(
        path,
        &id,
        geometry.positions,
        geometry.normals.clone(),
        geometry.triangles,
    )?;
    Ok(id.instance(
        mesh,
        Motion::Skinned {
            skin,
            morph,
            normals: geometry.normals,
        },
    ))
}

pub(super) fn rigid_or_morphed_instance(
    path: &Path,
    id: Identity,
    geometry: Geometry,
    mirrored: bool,
    animated_weights: bool,
    weights: &[f32],
) -> Result<Instance> {
    let Geometry {
        positions,
        normals,
        mut triangles,
        targets,
        ..
    } = geometry;
    let morph = Morph { targets };
    // Without animated weights the shape never changes: bake the defaults.
    let (mesh_positions, mesh_normals) = if animated_weights {
        (positions.clone(), normals.clone())
    } else {
        morph.apply(weights, &positions, normals.as_deref())
    };
    let (mesh_positions, mesh_normals) = if mirrored {
        for t in &mut triangles {
            t.swap(1, 2);
        }
        (
            mesh_positions.into_iter().map(|p| p * MIRROR).collect(),
            mesh_normals.map(|n| n.into_iter().map(|n| n * MIRROR).collect()),
        )
    } else {
        (mesh_positions, mesh_normals)
    };
    let mesh = build_mesh(path, &id, mesh_positions, mesh_normals, triangles)?;
    let motion = if animated_weights {
        Motion::Morphed {
            mirrored,
            morph,
            positions,
            normals,
        }
    } else {
        Motion::Rigid { mirrored }
    };
    Ok(id.instance(mesh, motion))
}
