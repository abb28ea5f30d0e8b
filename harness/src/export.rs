//! Per-vertex results as CSV or JSON, for other tools to check.

use std::{fmt::Write, path::Path};

use glam::Vec3;
use serde::Serialize;
use shadow_core::{Error, FrameGeometry, Result, VertexRadiance};

use crate::io::write_atomic;

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
            let mut s = String::from("object,vertex,px,py,pz,nx,ny,nz,r,g,b,se_r,se_g,se_b\n");
            for r in &rows {
                let se = r.std_error.map(Vec3::from_array);
                let se = se.map_or(",,".to_string(), |e| format!("{},{},{}", e.x, e.y, e.z));
                let [px, py, pz] = r.position;
                let [nx, ny, nz] = r.normal;
                let [cr, cg, cb] = r.radiance;
                writeln!(
                    s,
                    "{},{},{px},{py},{pz},{nx},{ny},{nz},{cr},{cg},{cb},{se}",
                    r.object, r.vertex
                )
                .expect("write to String");
            }
            s.into_bytes()
        }
        Some("json") => {
            serde_json::to_vec(&rows).map_err(|e| Error::format(path, e.to_string()))?
        }
        _ => return Err(Error::format(path, "output must end in .csv or .json")),
    };
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
