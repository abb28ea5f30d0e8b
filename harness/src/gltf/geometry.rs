//! The triangle primitives of one glTF mesh, merged into one vertex and
//! triangle list with their skinning attributes and morph-target deltas.

use std::collections::BTreeMap;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use glam::Vec3;
use shadow_core::{Error, Result};

use super::accessor::Buffers;
use super::morph::MorphTarget;

/// Joint numbers and weights, `width` per vertex (four per JOINTS_n/WEIGHTS_n
/// set); primitives with fewer sets are padded with zero weights.
pub(super) struct RawInfluences {
    pub width: usize,
    pub joints: Vec<u32>,
    pub weights: Vec<f32>,
}

/// The merged primitives of one mesh, in the mesh's model space.
pub(super) struct Geometry {
    pub positions: Vec<Vec3>,
    /// Only when every triangle primitive has NORMAL: a mesh with some normals
    /// missing gets area-weighted normals everywhere rather than a mix.
    pub normals: Option<Vec<Vec3>>,
    pub triangles: Vec<[u32; 3]>,
    /// Deltas over all merged vertices (zero where a primitive's target lacks
    /// the attribute, as glTF 2.0 §3.7.2.2 prescribes).
    pub targets: Vec<MorphTarget>,
    /// Read only for skinned nodes: glTF ignores JOINTS/WEIGHTS without a skin.
    pub influences: Option<RawInfluences>,
    /// `COLOR_0` and application-specific (`_NAME`) attributes stored as
    /// floats or normalized integers in every triangle primitive alike.
    pub attributes: BTreeMap<String, VertexAttribute>,
    /// The triangle primitives merged, in vertex order: (index in the mesh,
    /// vertex count).
    pub primitives: Vec<(usize, usize)>,
    /// Point and line primitives: no surface to shade or to cast a shadow.
    pub skipped_primitives: usize,
    /// Triangle strips and fans turned into triangle lists.
    pub converted_primitives: usize,
}

/// Per-vertex values of one attribute: `components` floats a vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct VertexAttribute {
    pub components: usize,
    pub values: Vec<f32>,
}

/// One primitive read on its own, before merging.
struct Part {
    index: usize,
    attributes: BTreeMap<String, VertexAttribute>,
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    triangles: Vec<[u32; 3]>,
    targets: Vec<MorphTarget>,
    influences: Vec<(Vec<u32>, Vec<f32>)>,
}

/// Reads and merges the triangle primitives of `mesh`. `label` names the mesh
/// and node in errors. `None` when the mesh has no triangle primitive.
pub(super) fn read_mesh(
    buffers: &Buffers,
    mesh: &::gltf::Mesh,
    label: &str,
    skinned: bool,
) -> Result<Option<Geometry>> {
    let mut parts = Vec::new();
    let mut skipped_primitives = 0;
    let mut converted_primitives = 0;
    for primitive in mesh.primitives() {
        match primitive.mode() {
            Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => {
                skipped_primitives += 1
            }
            mode => {
                converted_primitives += usize::from(mode != Mode::Triangles);
                parts.push(read_primitive(buffers, &primitive, label, skinned)?);
            }
        }
    }
    let Some(first) = parts.first() else {
        return Ok(None);
    };
    let target_count = first.targets.len();
    if let Some(p) = parts.iter().position(|p| p.targets.len() != target_count) {
        return Err(Error::format(
            buffers.path,
            format!(
                "{label}: triangle primitive {p} has {} morph targets, the first has {target_count}",
                parts[p].targets.len()
            ),
        ));
    }
    let width = 4 * parts.iter().map(|p| p.influences.len()).max().unwrap_or(0);
    let vertex_count: usize = parts.iter().map(|p| p.positions.len()).sum();
    if u32::try_from(vertex_count).is_err() {
        return Err(Error::format(
            buffers.path,
            format!("{label}: {vertex_count} vertices exceed u32 indices"),
        ));
    }

    // An attribute some triangle primitive lacks, or stores with another
    // width, cannot be told per vertex: it is left out.
    let attributes = first
        .attributes
        .iter()
        .filter(|(name, a)| {
            parts.iter().all(|p| {
                p.attributes
                    .get(*name)
                    .is_some_and(|b| b.components == a.components)
            })
        })
        .map(|(name, a)| {
            let values = parts
                .iter()
                .flat_map(|p| p.attributes[name].values.iter().copied())
                .collect();
            let merged = VertexAttribute {
                components: a.components,
                values,
            };
            (name.clone(), merged)
        })
        .collect();
    let mut geometry = Geometry {
        attributes,
        primitives: parts.iter().map(|p| (p.index, p.positions.len())).collect(),
        positions: Vec::with_capacity(vertex_count),
        normals: parts
            .iter()
            .all(|p| p.normals.is_some())
            .then(|| Vec::with_capacity(vertex_count)),
        triangles: Vec::new(),
        targets: (0..target_count)
            .map(|_| MorphTarget {
                positions: Vec::with_capacity(vertex_count),
                normals: Vec::with_capacity(vertex_count),
            })
            .collect(),
        influences: skinned.then(|| RawInfluences {
            width,
            joints: Vec::with_capacity(vertex_count * width),
            weights: Vec::with_capacity(vertex_count * width),
        }),
        skipped_primitives,
        converted_primitives,
    };
    for part in parts {
        let base = geometry.positions.len() as u32;
        geometry
            .triangles
            .extend(part.triangles.iter().map(|t| t.map(|i| i + base)));
        if let (Some(all), Some(these)) = (&mut geometry.normals, &part.normals) {
            all.extend(these);
        }
        for (all, these) in geometry.targets.iter_mut().zip(part.targets) {
            all.positions.extend(these.positions);
            all.normals.extend(these.normals);
        }
        if let Some(all) = &mut geometry.influences {
            for v in 0..part.positions.len() {
                for set in 0..width / 4 {
                    match part.influences.get(set) {
                        Some((joints, weights)) => {
                            all.joints.extend(&joints[4 * v..4 * v + 4]);
                            all.weights.extend(&weights[4 * v..4 * v + 4]);
                        }
                        None => {
                            all.joints.extend([0; 4]);
                            all.weights.extend([0.0; 4]);
                        }
                    }
                }
            }
        }
        geometry.positions.extend(part.positions);
    }
    Ok(Some(geometry))
}

fn read_primitive(
    buffers: &Buffers,
    primitive: &::gltf::Primitive,
    label: &str,
    skinned: bool,
) -> Result<Part> {
    let p = primitive.index();
    let bad = |what: String| Error::format(buffers.path, format!("{label}, primitive {p}: {what}"));
    let what = |attribute: &str| format!("{label}, primitive {p}, {attribute}");
    let positions_accessor = primitive
        .get(&Semantic::Positions)
        .ok_or_else(|| bad("has no POSITION".into()))?;
    let positions = buffers.vec3s(&positions_accessor, &what("POSITION"))?;
    let n = positions.len();
    let same_count = |attribute: &str, count: usize| {
        if count == n {
            Ok(())
        } else {
            Err(bad(format!(
                "{attribute} has {count} elements for {n} positions"
            )))
        }
    };

    let normals = match primitive.get(&Semantic::Normals) {
        Some(accessor) => {
            let normals = buffers.vec3s(&accessor, &what("NORMAL"))?;
            same_count("NORMAL", normals.len())?;
            Some(normals)
        }
        None => None,
    };

    let mut attributes = BTreeMap::new();
    for (semantic, accessor) in primitive.attributes() {
        let readable = accessor.data_type() == DataType::F32 || accessor.normalized();
        if !(readable && matches!(semantic, Semantic::Colors(0) | Semantic::Extras(_))) {
            continue;
        }
        let name = semantic.to_string();
        let dims = accessor.dimensions();
        let components = dims.multiplicity();
        if components > 4 {
            continue;
        }
        let values = buffers.floats(&accessor, &what(&name), dims)?;
        same_count(&name, values.len() / components)?;
        attributes.insert(name, VertexAttribute { components, values });
    }

    let indices = match primitive.indices() {
        Some(accessor) => {
            let indices = buffers.uints(&accessor, &what("indices"), Dimensions::Scalar)?;
            if let Some((k, i)) = indices.iter().enumerate().find(|(_, i)| **i as usize >= n) {
                return Err(bad(format!(
                    "index {k} is {i}, out of range for {n} vertices"
                )));
            }
            indices
        }
        None => (0..n as u32).collect(),
    };
    let triangles = match primitive.mode() {
        Mode::Triangles => {
            if !indices.len().is_multiple_of(3) {
                return Err(bad(format!(
                    "{} indices do not make whole triangles",
                    indices.len()
                )));
            }
            indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect()
        }
        // glTF 2.0 §3.7.2.1: p_i = {v_i, v_{i+1+i%2}, v_{i+2-i%2}}.
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| [indices[i], indices[i + 1 + i % 2], indices[i + 2 - i % 2]])
            .collect(),
        // glTF 2.0 §3.7.2.1: p_i = {v_{i+1}, v_{i+2}, v_0}.
        _ => (0..indices.len().saturating_sub(2))
            .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
            .collect(),
    };

    let mut targets = Vec::new();
    for (t, target) in primitive.morph_targets().enumerate() {
        let deltas = |accessor: Option<::gltf::Accessor>, attribute: &str| -> Result<Vec<Vec3>> {
            match accessor {
                Some(accessor) => {
                    let deltas = buffers
                        .vec3s(&accessor, &what(&format!("morph target {t} {attribute}")))?;
                    same_count(&format!("morph target {t} {attribute}"), deltas.len())?;
                    Ok(deltas)
                }
                None => Ok(vec![Vec3::ZERO; n]),
            }
        };
        let positions = deltas(target.positions(), "POSITION")?;
        let normals = deltas(target.normals(), "NORMAL")?;
        targets.push(MorphTarget { positions, normals });
    }

    let mut influences = Vec::new();
    if skinned {
        for set in 0.. {
            let (joints, weights) = match (
                primitive.get(&Semantic::Joints(set)),
                primitive.get(&Semantic::Weights(set)),
            ) {
                (Some(j), Some(w)) => (j, w),
                (None, None) => break,
                _ => {
                    return Err(bad(format!(
                        "JOINTS_{set} and WEIGHTS_{set} must come together"
                    )));
                }
            };
            let joints =
                buffers.uints(&joints, &what(&format!("JOINTS_{set}")), Dimensions::Vec4)?;
            let weights =
                buffers.floats(&weights, &what(&format!("WEIGHTS_{set}")), Dimensions::Vec4)?;
            same_count(&format!("JOINTS_{set}"), joints.len() / 4)?;
            same_count(&format!("WEIGHTS_{set}"), weights.len() / 4)?;
            influences.push((joints, weights));
        }
    }
    Ok(Part {
        index: p,
        attributes,
        positions,
        normals,
        triangles,
        targets,
        influences,
    })
}
