//! Adding a per-vertex attribute to a user's glTF file and writing it back
//! with everything else as it was.
//!
//! The file's JSON is patched, not re-serialized from a model of it: nodes,
//! materials, skins, animations, extensions, extras and every other
//! attribute stay byte-for-byte the values they were, and the new data is
//! appended to the binary payload. What changes:
//!
//! * each triangle primitive of a baked object gets the attribute: a new
//!   accessor over a new buffer view of 32-bit floats;
//! * a mesh several nodes instance sees different values per instance: every
//!   baked instance but the mesh's last user gets its own copy of the mesh
//!   (sharing every other accessor), and its node points to the copy;
//! * the data goes into the GLB's BIN chunk (`.glb` out) or a new
//!   `NAME.bin` beside the output (`.gltf` out, or the BIN chunk of a `.glb`
//!   in becomes that file); relative URIs of the other buffers and of images
//!   are rewritten to resolve from the output's folder.
//!
//! Output files are written atomically; for a `.gltf` the `.bin` first, so
//! that an interruption never leaves a `.gltf` pointing at missing data.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use ::gltf::binary::{Glb, Header};
use percent_encoding::{AsciiSet, NON_ALPHANUMERIC, utf8_percent_encode};

use serde_json::{Value, json};
use shadow_core::{Error, Result};

use super::{ObjectSource, VertexAttribute};
use crate::io::write_atomic;

/// `componentType` FLOAT and `target` ARRAY_BUFFER.
const FLOAT: u32 = 5126;
const ARRAY_BUFFER: u32 = 34962;

/// The attribute to write and what to do when a primitive already has it.
#[derive(Clone, Debug)]
pub struct AttributeSpec {
    /// `COLOR_0` or an application-specific name starting with `_`.
    pub name: String,
    /// Overwrite an attribute of that name instead of refusing.
    pub replace: bool,
}

impl AttributeSpec {
    /// Checks the name: `COLOR_0` (one or three components written as an RGB
    /// colour) or `_NAME` (any of 1–4 components).
    pub fn new(name: &str, replace: bool) -> Result<AttributeSpec> {
        let custom = name.len() > 1
            && name.starts_with('_')
            && name[1..]
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_');
        if name == "COLOR_0" || custom {
            Ok(AttributeSpec {
                name: name.to_string(),
                replace,
            })
        } else {
            Err(Error::InvalidScene(format!(
                "cannot write the attribute {name:?}: glTF takes COLOR_0 or an \
                 application-specific name that starts with `_` (such as _AO)"
            )))
        }
    }
}

/// What [`write_with_attribute`] changed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PatchSummary {
    /// Primitives given the attribute.
    pub primitives: usize,
    /// Meshes copied so that each instance holds its own values.
    pub copied_meshes: usize,
    /// Primitives whose attribute of that name was overwritten.
    pub replaced: usize,
}

/// Writes `input` to `output` (`.glb` or `.gltf`) with `spec`'s attribute on
/// every triangle primitive of the objects in `sources` (as
/// [`super::GltfAsset::sources`] gives them), `values[o]` holding object
/// `o`'s per-vertex values.
pub fn write_with_attribute(
    input: &Path,
    output: &Path,
    sources: &[ObjectSource],
    values: &[VertexAttribute],
    spec: &AttributeSpec,
) -> Result<PatchSummary> {
    let bad_in = |what: String| Error::format(input, what);
    let binary_out = match output.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("glb") => true,
        Some(e) if e.eq_ignore_ascii_case("gltf") => false,
        _ => {
            return Err(Error::format(
                output,
                "the output must end in .glb or .gltf",
            ));
        }
    };
    if sources.len() != values.len() {
        return Err(Error::InvalidScene(format!(
            "{} objects to bake, {} value sets",
            sources.len(),
            values.len()
        )));
    }
    let bytes = std::fs::read(input).map_err(|e| Error::io(input, e))?;
    let (mut json, glb_bin) = parse(&bytes).map_err(bad_in)?;
    let mut file = Patched::new(&mut json, glb_bin).map_err(bad_in)?;
    let mut summary = PatchSummary::default();

    let mut users = vec![0usize; file.count("meshes")];
    for node in file.json["nodes"].as_array().into_iter().flatten() {
        if let Some(m) = node["mesh"]
            .as_u64()
            .and_then(|m| users.get_mut(m as usize))
        {
            *m += 1;
        }
    }
    for (source, values) in sources.iter().zip(values) {
        let vertices: usize = source.primitives.iter().map(|(_, n)| n).sum();
        let components = values.components;
        if values.values.len() != vertices * components {
            return Err(Error::InvalidScene(format!(
                "node {}: {} values for {vertices} vertices of {components} components",
                source.node,
                values.values.len()
            )));
        }
        let uses = users
            .get_mut(source.mesh)
            .ok_or_else(|| bad_in(format!("mesh {} does not exist", source.mesh)))?;
        let mesh = if *uses > 1 {
            *uses -= 1;
            summary.copied_meshes += 1;
            file.copy_mesh(source)
        } else {
            source.mesh
        };
        let mut offset = 0;
        for &(p, count) in &source.primitives {
            let slice = &values.values[offset * components..(offset + count) * components];
            offset += count;
            let attributes = &file.json["meshes"][mesh]["primitives"][p]["attributes"];
            if !attributes.is_object() {
                return Err(bad_in(format!(
                    "mesh {mesh}, primitive {p} has no attributes"
                )));
            }
            if attributes.get(&spec.name).is_some() {
                if !spec.replace {
                    return Err(bad_in(format!(
                        "mesh {}, primitive {p} already has {}: choose another attribute \
                         (such as _AO) or allow replacing it",
                        source.mesh, spec.name
                    )));
                }
                summary.replaced += 1;
            }
            let accessor = file.push_accessor(slice, components, &spec.name);
            let attributes = &mut file.json["meshes"][mesh]["primitives"][p]["attributes"];
            attributes[&spec.name] = json!(accessor);
            summary.primitives += 1;
        }
    }
    file.write(input, output, binary_out)?;
    Ok(summary)
}

/// A GLB's JSON and BIN chunk (read by the `gltf` crate), or a `.gltf`'s
/// JSON.
fn parse(bytes: &[u8]) -> std::result::Result<(Value, Option<Vec<u8>>), String> {
    let (json, bin) = if bytes.starts_with(b"glTF") {
        super::file::check_glb_header(bytes)?;
        let glb = Glb::from_slice(bytes).map_err(|e| format!("malformed GLB: {e}"))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes.to_vec(), None)
    };
    let json = serde_json::from_slice(&json).map_err(|e| format!("malformed JSON: {e}"))?;
    Ok((json, bin))
}

/// The JSON being patched and the binary data to append to.
struct Patched<'a> {
    json: &'a mut Value,
    /// The GLB BIN chunk's bytes, if the input had one (buffer 0), with the
    /// new data appended.
    bin: Vec<u8>,
    /// Whether buffer 0 is the GLB BIN chunk.
    has_bin: bool,
    /// The buffer views made for the new data.
    new_views: Vec<usize>,
}

impl<'a> Patched<'a> {
    fn new(json: &'a mut Value, glb_bin: Option<Vec<u8>>) -> std::result::Result<Self, String> {
        if !json.is_object() {
            return Err("the glTF JSON is not an object".into());
        }
        let first_is_bin =
            json["buffers"][0].is_object() && json["buffers"][0].get("uri").is_none();
        let has_bin = glb_bin.is_some() && first_is_bin;
        let mut bin = if has_bin {
            glb_bin.unwrap_or_default()
        } else {
            Vec::new()
        };
        if has_bin {
            let declared = json["buffers"][0]["byteLength"].as_u64().unwrap_or(0) as usize;
            if bin.len() < declared {
                return Err(format!(
                    "the BIN chunk has {} bytes, buffer 0 declares {declared}",
                    bin.len()
                ));
            }
            bin.truncate(declared);
        }
        Ok(Patched {
            json,
            bin,
            has_bin,
            new_views: Vec::new(),
        })
    }

    fn count(&self, array: &str) -> usize {
        self.json[array].as_array().map_or(0, Vec::len)
    }

    /// Appends `value` to the top-level array `array`, returning its index.
    fn push(&mut self, array: &str, value: Value) -> usize {
        if !self.json[array].is_array() {
            self.json[array] = json!([]);
        }
        let list = self.json[array].as_array_mut().expect("just made an array");
        list.push(value);
        list.len() - 1
    }

    /// A copy of `source`'s mesh for its node alone; returns the copy's index.
    fn copy_mesh(&mut self, source: &ObjectSource) -> usize {
        let mut copy = self.json["meshes"][source.mesh].clone();
        if let Some(name) = copy["name"].as_str() {
            copy["name"] = json!(format!("{name} (node {})", source.node));
        }
        let index = self.push("meshes", copy);
        self.json["nodes"][source.node]["mesh"] = json!(index);
        index
    }

    /// A FLOAT accessor over `values` (SCALAR to VEC4; three values for an
    /// RGB `COLOR_0` given one), with its own buffer view; returns its index.
    fn push_accessor(&mut self, values: &[f32], components: usize, name: &str) -> usize {
        let (data, width): (Vec<f32>, usize) = if name == "COLOR_0" && components == 1 {
            (values.iter().flat_map(|&v| [v; 3]).collect(), 3)
        } else {
            (values.to_vec(), components)
        };
        let count = data.len() / width;
        let mut min = vec![f32::INFINITY; width];
        let mut max = vec![f32::NEG_INFINITY; width];
        for element in data.chunks_exact(width) {
            for (c, &v) in element.iter().enumerate() {
                min[c] = min[c].min(v);
                max[c] = max[c].max(v);
            }
        }
        // Views start on 4-byte boundaries, as FLOAT data requires.
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend(data.iter().flat_map(|v| v.to_le_bytes()));
        // Its buffer is set once known, in `write`.
        let view = self.push(
            "bufferViews",
            json!({
                "buffer": 0,
                "byteOffset": offset,
                "byteLength": data.len() * 4,
                "target": ARRAY_BUFFER,
            }),
        );
        self.new_views.push(view);
        let kind = ["SCALAR", "VEC2", "VEC3", "VEC4"][width - 1];
        self.push(
            "accessors",
            json!({
                "bufferView": view,
                "componentType": FLOAT,
                "count": count,
                "type": kind,
                "min": min,
                "max": max,
            }),
        )
    }

    /// Points the new views at their buffer, fixes URIs and byte lengths,
    /// and writes the output.
    fn write(mut self, input: &Path, output: &Path, binary_out: bool) -> Result<()> {
        let in_dir = folder(input)?;
        let out_dir = folder(output)?;
        let bin_name = format!(
            "{}.bin",
            output
                .file_stem()
                .map_or("baked".into(), |s| s.to_string_lossy())
        );
        // Where the new data (and, with `has_bin`, buffer 0's) goes.
        let target = if binary_out || self.has_bin {
            if !self.has_bin {
                // The BIN chunk must be buffer 0: make room for it.
                self.shift_buffers();
                let list = self.json["buffers"].as_array_mut().expect("made by shift");
                list.insert(0, json!({ "byteLength": 0 }));
            }
            0
        } else {
            self.push("buffers", json!({ "byteLength": 0 }))
        };
        let total = self.bin.len();
        self.json["buffers"][target]["byteLength"] = json!(total);
        for &view in &self.new_views {
            self.json["bufferViews"][view]["buffer"] = json!(target);
        }
        for kind in ["buffers", "images"] {
            let items = self.json.get_mut(kind).and_then(Value::as_array_mut);
            for item in items.into_iter().flatten() {
                if let Some(moved) = item["uri"]
                    .as_str()
                    .and_then(|uri| relocated(uri, &in_dir, &out_dir))
                {
                    item["uri"] = json!(moved);
                }
            }
        }
        if binary_out {
            self.json["buffers"][0]
                .as_object_mut()
                .expect("buffer 0")
                .remove("uri");
            let json =
                serde_json::to_vec(&self.json).map_err(|e| Error::format(output, e.to_string()))?;
            write_atomic(output, &glb(&json, &self.bin))
        } else {
            self.json["buffers"][target]["uri"] = json!(encode_uri(&bin_name));
            write_atomic(&out_dir.join(&bin_name), &self.bin)?;
            let json = serde_json::to_vec_pretty(&self.json)
                .map_err(|e| Error::format(output, e.to_string()))?;
            write_atomic(output, &json)
        }
    }

    /// Raises every buffer index by one (buffer views' own and those of
    /// `EXT_meshopt_compression`), for a new buffer 0.
    fn shift_buffers(&mut self) {
        if !self.json["buffers"].is_array() {
            self.json["buffers"] = json!([]);
        }
        let views = self.json["bufferViews"]
            .as_array_mut()
            .into_iter()
            .flatten();
        for (i, view) in views.enumerate() {
            if self.new_views.contains(&i) {
                continue;
            }
            for slot in ["/buffer", "/extensions/EXT_meshopt_compression/buffer"] {
                if let Some(b) = view.pointer_mut(slot).filter(|b| b.is_u64()) {
                    *b = json!(b.as_u64().unwrap_or_default() + 1);
                }
            }
        }
    }
}

/// A GLB container of `json` (padded with spaces) and `bin` (with zeros;
/// no BIN chunk when empty), written by the `gltf` crate.
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let glb = Glb {
        header: Header {
            magic: *b"glTF",
            version: 2,
            // Not read: `to_vec` writes the length of the chunks it writes.
            length: 0,
        },
        json: Cow::Borrowed(json),
        bin: (!bin.is_empty()).then_some(Cow::Borrowed(bin)),
    };
    glb.to_vec().expect("writing to memory cannot fail")
}

/// The absolute folder a file is in (the folder must exist).
fn folder(file: &Path) -> Result<PathBuf> {
    let dir = file
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    dir.canonicalize().map_err(|e| Error::io(dir, e))
}

/// `uri`, relative to `from`, rewritten relative to `to`; `None` when it
/// needs no change (a `data:` or absolute URI, or the same folder).
fn relocated(uri: &str, from: &Path, to: &Path) -> Option<String> {
    let scheme = uri
        .find(':')
        .is_some_and(|i| !uri[..i].contains('/') && i > 1);
    if scheme || uri.starts_with('/') || from == to {
        return None;
    }
    let target = from.join(decode_uri(uri));
    let path = pathdiff::diff_paths(&target, to)?;
    Some(encode_uri(&path.to_string_lossy()))
}

/// Percent-decodes a URI reference (RFC 3986 §2.1).
fn decode_uri(uri: &str) -> String {
    percent_encoding::percent_decode_str(uri)
        .decode_utf8_lossy()
        .into_owned()
}

/// What a relative path's URI reference percent-encodes: everything but
/// unreserved characters (RFC 3986 §2.3) and `/`.
const PATH: &AsciiSet = &NON_ALPHANUMERIC
    .remove(b'-')
    .remove(b'.')
    .remove(b'_')
    .remove(b'~')
    .remove(b'/');

/// Percent-encodes a relative path as a URI reference.
fn encode_uri(path: &str) -> String {
    utf8_percent_encode(path, PATH).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_are_rewritten_to_resolve_from_the_new_folder() {
        let from = Path::new("/a/models");
        let to = Path::new("/a/out/baked");
        assert_eq!(
            relocated("tex/wood%20grain.png", from, to).as_deref(),
            Some("../../models/tex/wood%20grain.png")
        );
        assert_eq!(
            relocated("data:application/octet-stream;base64,AA", from, to),
            None
        );
        assert_eq!(relocated("https://example.com/x.bin", from, to), None);
        assert_eq!(relocated("x.bin", from, from), None);
        assert_eq!(decode_uri("a%2Fb%20c"), "a/b c");
    }

    #[test]
    fn attribute_names_follow_gltf() {
        assert!(AttributeSpec::new("COLOR_0", false).is_ok());
        assert!(AttributeSpec::new("_AO", false).is_ok());
        for bad in ["AO", "_", "COLOR_1", "_A O", "NORMAL"] {
            let e = AttributeSpec::new(bad, false).unwrap_err().to_string();
            assert!(e.contains("application-specific"), "{bad}: {e}");
        }
    }

    #[test]
    fn glb_chunks_are_padded_and_parse_back() {
        let json = br#"{"asset":{"version":"2.0"}}"#;
        let bytes = glb(json, &[1, 2, 3]);
        assert_eq!(bytes.len() % 4, 0);
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
            bytes.len()
        );
        let (parsed, bin) = parse(&bytes).unwrap();
        assert_eq!(parsed["asset"]["version"], "2.0");
        assert_eq!(&bin.unwrap()[..3], &[1, 2, 3]);
        // No BIN chunk when there is no data; errors, not panics, for
        // truncated files and short declared lengths.
        let (_, bin) = parse(&glb(json, &[])).unwrap();
        assert!(bin.is_none());
        for cut in [4, 12, 20, bytes.len() - 2] {
            assert!(parse(&bytes[..cut]).is_err(), "{cut}");
        }
        let mut short = bytes.clone();
        short[8..12].copy_from_slice(&8u32.to_le_bytes());
        assert!(parse(&short).unwrap_err().contains("less than the header"));
    }

    #[test]
    fn uris_are_percent_coded_paths() {
        assert_eq!(decode_uri("d%C3%A9j%C3%A0%20vu.bin"), "déjà vu.bin");
        assert_eq!(decode_uri("100%"), "100%");
        assert_eq!(
            encode_uri("../tex/déjà vu.png"),
            "../tex/d%C3%A9j%C3%A0%20vu.png"
        );
        assert_eq!(encode_uri("a%b"), "a%25b");
    }
}
