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
