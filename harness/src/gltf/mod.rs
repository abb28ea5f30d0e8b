//! glTF 2.0 assets (`.gltf` with external or `data:` buffers, `.glb`) as scene
//! objects and per-frame poses.
//!
//! Every node of the scene (the file's default scene, else its first, else
//! every root node) that instances a mesh becomes one [`Object`]: the mesh's
//! triangle primitives merged into one validated [`Mesh`] in the mesh's model
//! space. What each object does over time decides its [`Pose`]:
//!
//! * rigid (no skin, no animated morph weights): `Pose::Rigid` with the node's
//!   world matrix, animated or not;
//! * skinned: `Pose::Deformed` with linear-blend skinned world positions
//!   (skin.rs); the object's mesh is the bind pose as the file gives it, and
//!   the skinned node's own transform is ignored, as glTF 2.0 §3.7.3 requires;
//! * morph weights animated by some clip: `Pose::Deformed` with
//!   `world · (base + Σ w_k Δ_k)`; the object's mesh is the base shape.
//!   Morph targets whose weights no clip animates are baked into the mesh with
//!   the node's (or mesh's) default weights, and the object stays rigid.
//!
//! Choices, each counted in [`GltfReport`]:
//!
//! * point and line primitives are skipped (they have no surface to shade or
//!   to cast a shadow); triangle strips and fans become triangle lists;
//! * joint weights that do not sum to 1 are divided by their sum;
//! * a rigid or morphed node whose world transform mirrors (negative
//!   determinant) gets a mirrored model-space mesh with its winding reversed,
//!   posed by `world · diag(−1, 1, 1)`: glTF flips the front face of mirrored
//!   nodes (§3.7.2.1), the workspace keeps counter-clockwise front faces and
//!   rigid poses without mirrors. A singular world transform (a zero scale),
//!   or an animation that changes the determinant's sign, is an error naming
//!   the node (and the time);
//! * a mesh whose primitives do not all have NORMAL gets area-weighted normals
//!   everywhere ([`Mesh::new`]), and its deformed poses carry none, so they
//!   are recomputed from the posed positions.
//!
//! Of the extensions that change how geometry is stored, the two the common
//! pipelines write are read: `KHR_mesh_quantization` (attributes as integers,
//! the `accessor` module) and `EXT_meshopt_compression` (compressed buffer
//! views, decoded at load time, the `meshopt` module). Any other required
//! extension, Draco compression among them, is refused by name instead of
//! being read wrongly.
//! Accessors without a buffer view read as zeros and sparse accessors are
//! applied (glTF 2.0 §3.6.2.4, §3.6.2.3). Materials, textures, cameras and
//! lights are not read: the caller gives each object a [`Brdf`]. `COLOR_0`
//! and application-specific attributes (`_AO`) are kept per object
//! ([`GltfAsset::vertex_attribute`]), and [`patch`] writes one back.

mod accessor;
mod animation;
mod file;
mod geometry;
mod hierarchy;
mod instance;
mod meshopt;
mod morph;
pub mod patch;
mod skin;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Mat3, Mat4};
use serde::Serialize;
use shadow_core::{Brdf, Error, Frame, Mesh, Object, Pose, Result};

use accessor::Buffers;
use animation::Clip;
pub use file::SUPPORTED_EXTENSIONS;
use file::{
    QUANTIZATION, check_glb_header, default_weights, load_buffers, named, scene_nodes, validated,
};
pub use geometry::VertexAttribute;
use hierarchy::Hierarchy;
use instance::{Identity, Instance, rigid_or_morphed_instance, skinned_instance};

/// What loading changed or left out, for logs and reports.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct GltfReport {
    /// Mesh instances loaded, one object each.
    pub objects: usize,
    /// Objects deformed by a skin.
    pub skinned_objects: usize,
    /// Objects deformed by animated morph weights (and no skin).
    pub morphed_objects: usize,
    /// Objects whose static morph weights were baked into the mesh.
    pub baked_morphs: usize,
    /// Objects whose node transform mirrors (see the module docs).
    pub mirrored_objects: usize,
    /// Point and line primitives skipped.
    pub skipped_primitives: usize,
    /// Mesh nodes skipped because they have no triangle primitive.
    pub skipped_meshes: usize,
    /// Triangle strips and fans converted to triangle lists.
    pub converted_primitives: usize,
    /// Skinned vertices whose joint weights were renormalized to sum to 1.
    pub renormalized_weights: usize,
}

/// Which animation clip drives the poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimationChoice<'a> {
    /// The rest pose: no animation.
    None,
    Index(usize),
    Name(&'a str),
}

/// A loaded glTF asset: its mesh objects, node hierarchy, skins, morph
/// targets and animation clips. See the module docs for what is read and how.
pub struct GltfAsset {
    path: PathBuf,
    hierarchy: Hierarchy,
    /// Default morph weights per node (empty for nodes without targets).
    weights: Vec<Vec<f32>>,
    instances: Vec<Instance>,
    clips: Vec<Clip>,
    selected: Option<usize>,
    report: GltfReport,
}

/// Where an object's vertices are stored in the file: the node that
/// instances it, that node's mesh, and the mesh's triangle primitives whose
/// vertices the object holds one after another.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjectSource {
    pub node: usize,
    pub mesh: usize,
    /// (primitive index in the mesh, vertex count), in the object's vertex
    /// order; point and line primitives are not among them.
    pub primitives: Vec<(usize, usize)>,
}

impl GltfAsset {
    /// Loads the asset and selects its first animation, if it has one.
    ///
    /// Errors (all naming the file): unreadable file, truncated GLB, malformed
    /// JSON, references or accessor byte ranges out of range, vertex indices
    /// out of range (naming the mesh), required extensions ("unsupported
    /// extension `<name>`"), invalid skins or animations, no triangle mesh.
    pub fn load(path: &Path) -> Result<GltfAsset> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let bad = |what: String| Error::format(path, what);
        check_glb_header(&bytes).map_err(bad)?;
        let raw = ::gltf::Gltf::from_slice_without_validation(&bytes)
            .map_err(|e| bad(format!("not a readable glTF or GLB file: {e}")))?;
        if let Some(name) = raw
            .document
            .extensions_required()
            .find(|name| !SUPPORTED_EXTENSIONS.contains(name))
        {
            return Err(bad(format!(
                "unsupported extension {name} (listed in extensionsRequired)"
            )));
        }
        let ::gltf::Gltf { document, blob } = raw;
        let document = validated(document).map_err(bad)?;
        let data = load_buffers(path, &document, blob)?;
        let decoded = meshopt::decode_views(path, &document, &data)?;
        let buffers = Buffers {
            path,
            data: &data,
            decoded: &decoded,
            quantized: document.extensions_used().any(|name| name == QUANTIZATION),
        };

        let hierarchy = Hierarchy::new(path, &document)?;
        let target_counts: Vec<usize> = document
            .nodes()
            .map(|n| {
                n.mesh()
                    .and_then(|m| m.primitives().next())
                    .map_or(0, |p| p.morph_targets().len())
            })
            .collect();
        let weights = document
            .nodes()
            .zip(&target_counts)
            .map(|(node, &count)| default_weights(path, &node, count))
            .collect::<Result<Vec<_>>>()?;
        let clips = document
            .animations()
            .map(|a| Clip::new(path, &a, &buffers, hierarchy.rest(), &target_counts))
            .collect::<Result<Vec<_>>>()?;
        let rest_world = hierarchy.world(hierarchy.rest());

        let mut report = GltfReport::default();
        let mut instances = Vec::new();
        for node in scene_nodes(&document) {
            let Some(mesh) = node.mesh() else { continue };
            let label = format!(
                "{}, {}",
                named("node", node.index(), node.name()),
                named("mesh", mesh.index(), mesh.name())
            );
            let skin = node.skin();
            let Some(mut geometry) = geometry::read_mesh(&buffers, &mesh, &label, skin.is_some())?
            else {
                report.skipped_meshes += 1;
                continue;
            };
            report.skipped_primitives += geometry.skipped_primitives;
            report.converted_primitives += geometry.converted_primitives;
            let source = ObjectSource {
                node: node.index(),
                mesh: mesh.index(),
                primitives: std::mem::take(&mut geometry.primitives),
            };
            let attributes = std::mem::take(&mut geometry.attributes);
            let id = Identity {
                node: node.index(),
                name: node
                    .name()
                    .or(mesh.name())
                    .map_or_else(|| format!("node {}", node.index()), str::to_string),
                label,
                source,
                attributes,
            };
            let animated_weights = clips.iter().any(|c| c.animates_weights(node.index()));
            let determinant = Mat3::from_mat4(rest_world[node.index()]).determinant();
            let instance = match skin {
                Some(skin) => {
                    report.skinned_objects += 1;
                    skinned_instance(path, &buffers, id, &skin, geometry, &mut report)?
                }
                None => {
                    if determinant == 0.0 || !determinant.is_finite() {
                        return Err(bad(format!(
                            "{}: world transform is singular (determinant {determinant})",
                            id.label
                        )));
                    }
                    let mirrored = determinant < 0.0;
                    report.mirrored_objects += usize::from(mirrored);
                    if animated_weights {
                        report.morphed_objects += 1;
                    } else if !geometry.targets.is_empty() {
                        report.baked_morphs += 1;
                    }
                    let node_weights = &weights[node.index()];
                    rigid_or_morphed_instance(
                        path,
                        id,
                        geometry,
                        mirrored,
                        animated_weights,
                        node_weights,
                    )?
                }
            };
            instances.push(instance);
        }
        if instances.is_empty() {
            return Err(bad(
                "no node of the scene instances a mesh with triangles".into()
            ));
        }
        report.objects = instances.len();
        Ok(GltfAsset {
            path: path.to_path_buf(),
            hierarchy,
            weights,
            selected: (!clips.is_empty()).then_some(0),
            instances,
            clips,
            report,
        })
    }

    /// The file the asset was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What loading changed or left out.
    pub fn report(&self) -> &GltfReport {
        &self.report
    }

    /// The model-space mesh of every object, in object order.
    pub fn meshes(&self) -> impl Iterator<Item = &Arc<Mesh>> {
        self.instances.iter().map(|i| &i.mesh)
    }

    /// Where each object's vertices are stored in the file, in object order.
    pub fn sources(&self) -> impl Iterator<Item = &ObjectSource> {
        self.instances.iter().map(|i| &i.source)
    }

    /// Object `object`'s per-vertex `COLOR_0` or application-specific
    /// attribute (`_AO`) as the file stores it, when every one of its
    /// triangle primitives has it as floats or normalized integers.
    pub fn vertex_attribute(&self, object: usize, name: &str) -> Option<&VertexAttribute> {
        self.instances.get(object)?.attributes.get(name)
    }

    /// One object per mesh instance, all with the same material.
    pub fn objects(&self, material: Brdf) -> Vec<Object> {
        self.meshes()
            .map(|mesh| Object {
                mesh: Arc::clone(mesh),
                material,
            })
            .collect()
    }

    /// The names of the animation clips ("animation i" for unnamed ones).
    pub fn animation_names(&self) -> Vec<&str> {
        self.clips.iter().map(|c| c.name.as_str()).collect()
    }

    /// Index of the clip that drives [`GltfAsset::pose_at`], if any.
    pub fn selected_animation(&self) -> Option<usize> {
        self.selected
    }

    /// Chooses the clip that drives [`GltfAsset::pose_at`].
    pub fn select_animation(&mut self, choice: AnimationChoice) -> Result<()> {
        let names = || self.animation_names().join(", ");
        self.selected = match choice {
            AnimationChoice::None => None,
            AnimationChoice::Index(i) if i < self.clips.len() => Some(i),
            AnimationChoice::Index(i) => {
                return Err(Error::format(
                    &self.path,
                    format!(
                        "animation {i} requested, the file has {} ({})",
                        self.clips.len(),
                        names()
                    ),
                ));
            }
            AnimationChoice::Name(name) => Some(
                self.clips
                    .iter()
                    .position(|c| c.name == name)
                    .ok_or_else(|| {
                        Error::format(
                            &self.path,
                            format!("no animation named {name:?} (there are: {})", names()),
                        )
                    })?,
            ),
        };
        Ok(())
    }

    /// True when a clip is selected.
    pub fn is_animated(&self) -> bool {
        self.selected.is_some()
    }

    /// Length of the selected clip in seconds (its last key time); 0 without one.
    pub fn duration(&self) -> f32 {
        self.clip().map_or(0.0, |c| c.duration)
    }

    fn clip(&self) -> Option<&Clip> {
        self.selected.map(|i| &self.clips[i])
    }

    /// Every node's world matrix at `time` (clamped to the clip).
    fn world_at(&self, time: f32) -> (Vec<Mat4>, Vec<Vec<f32>>) {
        let mut locals = self.hierarchy.rest().to_vec();
        let mut weights = self.weights.clone();
        if let Some(clip) = self.clip() {
            clip.apply(time, &mut locals, &mut weights);
        }
        (self.hierarchy.world(&locals), weights)
    }

    /// The pose of every object at `time` seconds into the selected clip
    /// (clamped to [0, duration]; the rest pose without a clip), in object
    /// order. Deformed poses are in world space.
    pub fn pose_at(&self, time: f32) -> Result<Vec<Pose>> {
        if !time.is_finite() {
            return Err(Error::InvalidScene(format!(
                "{}: animation time {time} is not finite",
                self.path.display()
            )));
        }
        let (world, weights) = self.world_at(time);
        self.instances
            .iter()
            .map(|instance| instance.pose(&self.path, &world, &weights, time))
            .collect()
    }

    /// The objects (one material for all) and frames sampled from the
    /// selected clip at `fps` from t = 0 up to its duration, at most
    /// `max_frames` of them; one frame at t = 0 without a clip.
    pub fn to_scene_parts(
        &self,
        material: Brdf,
        fps: f32,
        max_frames: usize,
    ) -> Result<(Vec<Object>, Vec<Frame>)> {
        if !(fps.is_finite() && fps > 0.0) || max_frames == 0 {
            return Err(Error::InvalidScene(format!(
                "{}: sampling at {fps} frames per second, at most {max_frames} frames",
                self.path.display()
            )));
        }
        // A small tolerance keeps the last frame when duration · fps is a whole
        // number up to rounding.
        let count = if self.is_animated() {
            ((self.duration() * fps + 1e-3).floor() as usize + 1).min(max_frames)
        } else {
            1
        };
        let frames = (0..count)
            .map(|k| {
                let time = k as f32 / fps;
                Ok(Frame {
                    time,
                    poses: self.pose_at(time)?,
                })
            })
            .collect::<Result<_>>()?;
        Ok((self.objects(material), frames))
    }
}
