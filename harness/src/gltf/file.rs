//! The file itself: its JSON validated, its buffers loaded, the nodes of
//! its scene listed, and how errors name what they point at.

use std::path::Path;

use shadow_core::{Error, Result};

use super::meshopt;

/// `KHR_mesh_quantization`: attributes stored as integers (read by
/// [`Buffers::floats`](super::accessor::Buffers::floats)).
pub(super) const QUANTIZATION: &str = "KHR_mesh_quantization";

/// The extensions a file may require: they change how geometry is stored,
/// and the loader reads them. Any other required extension (Draco
/// compression among them) is refused by name.
pub const SUPPORTED_EXTENSIONS: [&str; 2] = [QUANTIZATION, meshopt::EXTENSION];

/// `document` checked by the `gltf` crate's validation (every index in
/// range, required properties present), except for two things that crate
/// refuses although glTF 2.0 allows them: accessors without a `bufferView`
/// (zero-filled, §3.6.2.4, which [`Buffers`](super::accessor::Buffers) reads) and the required
/// extensions this loader supports.
pub(super) fn validated(
    document: ::gltf::Document,
) -> std::result::Result<::gltf::Document, String> {
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
pub(super) fn load_buffers(
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
pub(super) fn scene_nodes<'a>(document: &'a ::gltf::Document) -> Vec<::gltf::Node<'a>> {
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
pub(super) fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(name) if !name.is_empty() => format!("{kind} {index} {name:?}"),
        _ => format!("{kind} {index}"),
    }
}

/// The weights a node's morph targets have without animation: the node's,
/// else its mesh's, else zeros (glTF 2.0 §3.7.2.2).
pub(super) fn default_weights(path: &Path, node: &::gltf::Node, count: usize) -> Result<Vec<f32>> {
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

/// A GLB's 12-byte header checked before the `gltf` crate reads the file:
/// a declared length shorter than the header makes that crate's reader
/// subtract past zero. Anything not starting with GLB's magic passes.
pub(super) fn check_glb_header(bytes: &[u8]) -> std::result::Result<(), String> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    match bytes.get(8..12) {
        None => Err(format!(
            "GLB truncated in its header ({} bytes)",
            bytes.len()
        )),
        Some(b) => match u32::from_le_bytes([b[0], b[1], b[2], b[3]]) {
            length @ 0..12 => Err(format!(
                "GLB header declares a length of {length} bytes, less than the header itself"
            )),
            _ => Ok(()),
        },
    }
}
