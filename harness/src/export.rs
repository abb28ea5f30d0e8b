//! Results for other tools: per-vertex radiance as CSV or JSON, and what a
//! method computed (its [`Export`]) as a NumPy `.npz` archive.
//!
//! # The `.npz` layout
//!
//! `f = numpy.load("out.npz")` gives, for every kind:
//!
//! | array | dtype, shape | what |
//! |---|---|---|
//! | `meta` | unicode, 0-d | JSON (`json.loads(str(f["meta"]))`): `kind`, `method`, `scene`, `frame`, the conventions below in words, and each object's material (e.g. `{"Lambert": {"albedo": [0.8, 0.8, 0.8]}}`) |
//! | `object_offsets` | int64, (objects + 1) | object `o` is rows `offsets[o]..offsets[o+1]` of the per-vertex arrays |
//! | `positions`, `normals` | float32, (V, 3) | world space at the exported frame (metres, +Y up) |
//!
//! Kind `sh_transfer` (`hemi-raster`): `transfer`, float32 (V, n²), world
//! space. Column l² + l + m holds coefficient (l, m) of the real,
//! orthonormal SH basis without the Condon–Shortley phase, polar axis +Y,
//! φ from +X toward +Z (`shadow_core::sh`). With `L` (n², 3) the lighting's
//! SH coefficients in that basis, `E = transfer @ L` is each vertex's
//! irradiance and `albedo / π · E` its Lambert radiance. A glossy term is
//! view-dependent and is not in the transfer.
//!
//! Kind `directional_visibility`: `directions`, float32 (k, 3), unit,
//! toward the light; `weights`, float32 (k), solid angles in steradians
//! summing to 4π; `visible`, uint8 (V, ⌈k/8⌉), bit j of vertex i set when
//! direction j is visible from it, unpacked by
//! `numpy.unpackbits(f["visible"], axis=1, count=k, bitorder="little")`.
//! With `I` (k, 3) the radiance arriving from each direction (the
//! environment blurred by a Gaussian of `meta["prefilter_radians"]`, looked
//! up along it), `E = (V · weights · max(0, normals @ directions.T)) @ I`;
//! when `meta["cosine_normalized"]`, each row is then scaled by
//! π / Σ_j weights_j max(0, n·l_j), as the method shades.

use std::path::Path;

use glam::Vec3;
use serde::Serialize;
use shadow_core::{Error, Export, FrameGeometry, Result, Scene, VertexRadiance};

use crate::{
    io::write_atomic,
    npz::{self, Array},
    report::Table,
};

/// One vertex's row.
#[derive(Serialize)]
struct Row {
    object: usize,
    vertex: usize,
    position: [f32; 3],
    normal: [f32; 3],
    radiance: [f32; 3],
    std_error: Option<[f32; 3]>,
}

/// Writes per-vertex position, normal, radiance and standard error to `path`;
/// the format follows the extension (`.csv` or `.json`).
pub fn write_vertices(path: &Path, frame: &FrameGeometry, values: &VertexRadiance) -> Result<()> {
    let mut rows = Vec::new();
    for (o, object) in frame.objects.iter().enumerate() {
        for v in 0..object.vertex_count() {
            rows.push(Row {
                object: o,
                vertex: v,
                position: object.positions()[v].to_array(),
                normal: object.normals()[v].to_array(),
                radiance: values.radiance[o][v].to_array(),
                std_error: values.std_error.as_ref().map(|s| s[o][v].to_array()),
            });
        }
    }
    let bytes = match path.extension().and_then(|e| e.to_str()) {
        Some("csv") => {
            let mut table = Table::new(&[
                "object", "vertex", "px", "py", "pz", "nx", "ny", "nz", "r", "g", "b", "se_r",
                "se_g", "se_b",
            ]);
            for r in &rows {
                let mut cells = vec![r.object.to_string(), r.vertex.to_string()];
                let numbers = r.position.iter().chain(&r.normal).chain(&r.radiance);
                cells.extend(numbers.map(f32::to_string));
                let se = r.std_error.map(|e| e.map(|x| x.to_string()));
                cells.extend(se.unwrap_or_default());
                table.row(cells);
            }
            table.csv().into_bytes()
        }
        Some("json") => {
            serde_json::to_vec(&rows).map_err(|e| Error::format(path, e.to_string()))?
        }
        _ => return Err(Error::format(path, "output must end in .csv or .json")),
    };
    write_atomic(path, &bytes)
}

/// Where an export came from, for its `meta`.
#[derive(Clone, Copy, Debug)]
pub struct Provenance<'a> {
    pub method: &'a str,
    pub scene: &'a Scene,
    pub frame: &'a FrameGeometry,
}

/// Writes `export` to `path` as an `.npz` archive in the layout of the
/// module docs, atomically. Fails when the export's vertex counts are not the
/// frame's.
pub fn write_npz(path: &Path, export: &Export, from: Provenance) -> Result<()> {
    let counts: Vec<usize> = from
        .frame
        .objects
        .iter()
        .map(|o| o.vertex_count())
        .collect();
    if export.vertex_counts() != counts {
        return Err(Error::format(
            path,
            format!(
                "the export has {:?} vertices per object, the frame {counts:?}",
                export.vertex_counts()
            ),
        ));
    }
    let vertices: usize = counts.iter().sum();
    let mut offsets = vec![0i64];
    for n in &counts {
        offsets.push(offsets.last().copied().unwrap_or(0) + *n as i64);
    }
    let flat = |f: fn(&shadow_core::Mesh) -> &[Vec3]| -> Vec<f32> {
        from.frame
            .objects
            .iter()
            .flat_map(|o| f(o).iter().flat_map(|v| v.to_array()))
            .collect()
    };
    let materials: Vec<serde_json::Value> = from
        .scene
        .objects()
        .iter()
        .map(|o| serde_json::to_value(o.material).unwrap_or_default())
        .collect();
    let mut meta = serde_json::json!({
        "method": from.method,
        "scene": from.scene.name(),
        "frame": from.frame.frame,
        "materials": materials,
        "space": "world: right-handed, +Y up, metres",
    });
    let mut arrays = vec![
        ("object_offsets", Array::i64(&[offsets.len()], &offsets)),
        (
            "positions",
            Array::f32(&[vertices, 3], &flat(|m| m.positions())),
        ),
    ];
    let normals: Vec<f32> = match export {
        Export::Visibility(v) => v.normals.iter().flat_map(|n| n.to_array()).collect(),
        _ => flat(|m| m.normals()),
    };
    arrays.push(("normals", Array::f32(&[vertices, 3], &normals)));
    match export {
        Export::Transfer(t) => {
            let n = t.order.coeff_count();
            meta["kind"] = "sh_transfer".into();
            meta["sh"] = serde_json::json!({
                "order": t.order.get(),
                "coefficients": n,
                "index": "column l*l + l + m holds (l, m)",
                "basis": "real, orthonormal, no Condon-Shortley phase, polar axis +Y, phi from +X toward +Z",
                "use": "irradiance E = transfer @ L; Lambert radiance = albedo / pi * E",
            });
            arrays.push(("transfer", Array::f32(&[vertices, n], &t.coefficients)));
        }
        Export::Visibility(v) => {
            let k = v.directions.len();
            let bytes = k.div_ceil(8);
            let packed: Vec<u8> = (0..vertices)
                .flat_map(|i| {
                    let words = &v.visible[i * v.words_per_vertex()..][..v.words_per_vertex()];
                    words
                        .iter()
                        .flat_map(|w| w.to_le_bytes())
                        .take(bytes)
                        .collect::<Vec<_>>()
                })
                .collect();
            let directions: Vec<f32> = v.directions.iter().flat_map(|d| d.to_array()).collect();
            meta["kind"] = "directional_visibility".into();
            meta["use"] = "E = (unpackbits(visible, axis=1, count=k, bitorder='little') * weights * max(0, normals @ directions.T)) @ I".into();
            meta["cosine_normalized"] = v.cosine_normalized.into();
            meta["prefilter_radians"] = v.prefilter.into();
            arrays.push(("directions", Array::f32(&[k, 3], &directions)));
            arrays.push(("weights", Array::f32(&[k], &v.weights)));
            arrays.push(("visible", Array::u8(&[vertices, bytes], &packed)));
        }
        _ => {
            return Err(Error::format(
                path,
                "this kind of export has no .npz layout",
            ));
        }
    }
    arrays.push(("meta", Array::text(&meta.to_string())));
    let bytes = npz::archive(&arrays).map_err(|e| Error::io(path, e))?;
    write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenes;

    fn sample() -> (FrameGeometry, VertexRadiance) {
        let scene = scenes::builtin("wall").unwrap();
        let frame = scene.frame_geometry(0).unwrap();
        let radiance: Vec<Vec<Vec3>> = frame
            .objects
            .iter()
            .map(|o| {
                (0..o.vertex_count())
                    .map(|v| Vec3::splat(v as f32))
                    .collect()
            })
            .collect();
        let std_error = Some(
            radiance
                .iter()
                .map(|o| vec![Vec3::splat(0.5); o.len()])
                .collect(),
        );
        (
            frame,
            VertexRadiance {
                radiance,
                std_error,
                evaluated: None,
            },
        )
    }

    #[test]
    fn csv_has_a_header_and_one_row_per_vertex() {
        let (frame, values) = sample();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        write_vertices(&path, &frame, &values).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let vertices: usize = frame.objects.iter().map(|o| o.vertex_count()).sum();
        assert_eq!(text.lines().count(), vertices + 1);
        assert!(text.starts_with("object,vertex,px"));
        let row: Vec<&str> = text.lines().nth(3).unwrap().split(',').collect();
        assert_eq!(row.len(), 14);
        assert_eq!((row[0], row[1], row[8], row[11]), ("0", "2", "2", "0.5"));
    }

    #[test]
    fn json_round_trips_through_serde() {
        let (frame, values) = sample();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.json");
        write_vertices(&path, &frame, &values).unwrap();
        let rows: Vec<serde_json::Value> =
            serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(rows[5]["radiance"][0], 5.0);
        assert_eq!(rows[5]["std_error"][2], 0.5);
        assert_eq!(rows[5]["normal"][1], 1.0);
    }

    #[test]
    fn unknown_extension_is_an_error_naming_the_file() {
        let (frame, values) = sample();
        let err = write_vertices(Path::new("results.txt"), &frame, &values).unwrap_err();
        assert!(err.to_string().contains("results.txt"), "{err}");
    }
}
