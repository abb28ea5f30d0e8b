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
mod geometry;
mod hierarchy;
mod meshopt;
mod morph;
pub mod patch;
mod skin;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Affine3A, Mat3, Mat4, Vec3};
use serde::Serialize;
use shadow_core::{Brdf, Error, Frame, Mesh, Object, Pose, Result};

use accessor::Buffers;
use animation::Clip;
use geometry::Geometry;
pub use geometry::VertexAttribute;
use hierarchy::Hierarchy;
use morph::Morph;
use skin::{Skin, normal_matrix};

/// The mirror that turns a mirrored node's mesh back into a rotation-only pose.
const MIRROR: Vec3 = Vec3::new(-1.0, 1.0, 1.0);

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

/// One node instancing a mesh.
struct Instance {
    node: usize,
    source: ObjectSource,
    attributes: BTreeMap<String, VertexAttribute>,
    label: String,
    mesh: Arc<Mesh>,
    motion: Motion,
}

enum Motion {
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
            .map(|instance| self.pose(instance, &world, &weights, time))
            .collect()
    }

    fn pose(
        &self,
        instance: &Instance,
        world: &[Mat4],
        weights: &[Vec<f32>],
        time: f32,
    ) -> Result<Pose> {
        let bad = |what: &str| {
            Error::format(
                &self.path,
                format!("{} at t = {time} s: {what}", instance.label),
            )
        };
        let node_world = world[instance.node];
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
        let (positions, normals) = match &instance.motion {
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
                    morph.apply(&weights[instance.node], positions, normals.as_deref());
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
                        &weights[instance.node],
                        instance.mesh.positions(),
                        normals.as_deref(),
                    );
                    skin.deform(world, &positions, normals.as_deref())
                }
                None => skin.deform(world, instance.mesh.positions(), normals.as_deref()),
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

/// `KHR_mesh_quantization`: attributes stored as integers (read by
/// [`Buffers::floats`]).
const QUANTIZATION: &str = "KHR_mesh_quantization";

/// The extensions a file may require: they change how geometry is stored,
/// and the loader reads them. Any other required extension (Draco
/// compression among them) is refused by name.
pub const SUPPORTED_EXTENSIONS: [&str; 2] = [QUANTIZATION, meshopt::EXTENSION];

/// `document` checked by the `gltf` crate's validation (every index in
/// range, required properties present), except for two things that crate
/// refuses although glTF 2.0 allows them: accessors without a `bufferView`
/// (zero-filled, §3.6.2.4, which [`Buffers`] reads) and the required
/// extensions this loader supports.
fn validated(document: ::gltf::Document) -> std::result::Result<::gltf::Document, String> {
    use ::gltf::json::validation::{Error as Invalid, Validate};
    let json = document.into_json();
    let mut errors = Vec::new();
    json.validate(&json, ::gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let zero_filled = error == Invalid::Missing
            && path.as_str().starts_with("accessors[")
            && path.as_str().ends_with("].bufferView");
        let supported = error == Invalid::Unsupported
            && path.as_str().starts_with("extensionsRequired[")
            && SUPPORTED_EXTENSIONS
                .iter()
                .any(|name| path.as_str().ends_with(&format!("{name:?}")));
        if !(zero_filled || supported) {
            errors.push(format!("{}: {error}", path.as_str()));
        }
    });
    if errors.is_empty() {
        Ok(::gltf::Document::from_json_without_validation(json))
    } else {
        Err(format!("invalid glTF: {}", errors.join(", ")))
    }
}

/// The buffers' bytes: the GLB's BIN chunk, external files next to `path`, or
/// `data:` URIs, each checked to be as long as the file declares. A fallback
/// buffer of `EXT_meshopt_compression` without a source stays empty: only
/// compressed views point into it, and they are decoded from elsewhere.
fn load_buffers(
    path: &Path,
    document: &::gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>> {
    let base = path.parent();
    document
        .buffers()
        .map(|buffer| {
            if meshopt::is_fallback(&buffer)
                && matches!(buffer.source(), ::gltf::buffer::Source::Bin)
            {
                return Ok(Vec::new());
            }
            let source = match buffer.source() {
                ::gltf::buffer::Source::Bin => "the GLB BIN chunk".to_string(),
                ::gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                    "a data: URI".to_string()
                }
                ::gltf::buffer::Source::Uri(uri) => format!("{uri:?}"),
            };
            let bad = |what: String| {
                Error::format(
                    path,
                    format!("buffer {} (from {source}): {what}", buffer.index()),
                )
            };
            let data = ::gltf::buffer::Data::from_source_and_blob(buffer.source(), base, &mut blob)
                .map_err(|e| bad(e.to_string()))?;
            if data.len() < buffer.length() {
                return Err(bad(format!(
                    "has {} bytes, the file declares {}",
                    data.len(),
                    buffer.length()
                )));
            }
            Ok(data.0)
        })
        .collect()
}

/// The nodes of the scene shown (the default scene, else the first, else all
/// root nodes), parents before children, each once.
fn scene_nodes<'a>(document: &'a ::gltf::Document) -> Vec<::gltf::Node<'a>> {
    let roots: Vec<_> = match document
        .default_scene()
        .or_else(|| document.scenes().next())
    {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut has_parent = vec![false; document.nodes().len()];
            for child in document.nodes().flat_map(|n| n.children()) {
                has_parent[child.index()] = true;
            }
            document
                .nodes()
                .filter(|n| !has_parent[n.index()])
                .collect()
        }
    };
    let mut visited = vec![false; document.nodes().len()];
    let mut stack: Vec<_> = roots.into_iter().rev().collect();
    let mut nodes = Vec::new();
    while let Some(node) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            continue;
        }
        let children: Vec<_> = node.children().collect();
        stack.extend(children.into_iter().rev());
        nodes.push(node);
    }
    nodes
}

/// "node 3" or "node 3 \"Head\"": how errors name glTF elements.
fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(name) if !name.is_empty() => format!("{kind} {index} {name:?}"),
        _ => format!("{kind} {index}"),
    }
}

/// The weights a node's morph targets have without animation: the node's,
/// else its mesh's, else zeros (glTF 2.0 §3.7.2.2).
fn default_weights(path: &Path, node: &::gltf::Node, count: usize) -> Result<Vec<f32>> {
    let given = node
        .weights()
        .or_else(|| node.mesh().and_then(|m| m.weights()));
    match given {
        None => Ok(vec![0.0; count]),
        Some(w) if w.len() == count && w.iter().all(|x| x.is_finite()) => Ok(w.to_vec()),
        Some(w) => Err(Error::format(
            path,
            format!(
                "{}: {count} finite default morph weights expected, found {w:?}",
                named("node", node.index(), node.name())
            ),
        )),
    }
}

/// A mesh instance's node, the name its [`Mesh`] gets, how errors call it,
/// and where its vertices and their other attributes are stored.
struct Identity {
    node: usize,
    name: String,
    label: String,
    source: ObjectSource,
    attributes: BTreeMap<String, VertexAttribute>,
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

fn skinned_instance(
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
    Ok(Instance {
        node: id.node,
        source: id.source,
        attributes: id.attributes,
        label: id.label,
        mesh,
        motion: Motion::Skinned {
            skin,
            morph,
            normals: geometry.normals,
        },
    })
}

fn rigid_or_morphed_instance(
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
    Ok(Instance {
        node: id.node,
        source: id.source,
        attributes: id.attributes,
        label: id.label,
        mesh,
        motion,
    })
}
