//! The methods the harness can run, by name.

use shadow_core::{Error, Result, ShadowMethod, sh::ShOrder};

use crate::baselines::{RayTrace, Unshadowed};

/// Names accepted by [`by_name`], with what each is.
pub const METHODS: &[(&str, &str)] = &[
    (
        "unshadowed",
        "SH lighting (order 9) with no visibility: the upper bound",
    ),
    (
        "hemi-raster",
        "Kautz et al. 2004: CPU hemispherical rasterization to SH transfer (32×32 masks, order 5, two-level mesh hierarchy)",
    ),
    (
        "hemi-raster:flat",
        "the same without the hierarchy: every triangle blocks every vertex (what the hierarchy costs in error)",
    ),
    (
        "hemi-raster:pvs",
        "hemi-raster with per-vertex potentially visible sets built from the scene's own frames (§3.2): the same masks on those frames, from far fewer blockers",
    ),
    (
        "raytrace:N",
        "Monte-Carlo ray tracing, N MIS iterations per vertex and per pixel (e.g. raytrace:16)",
    ),
    (
        "raytrace:N:vertex",
        "the same per vertex, its images interpolated from the vertices as a per-vertex method's",
    ),
];

/// The methods of the standard report.
pub const REPORT_METHODS: &[&str] = &[
    "unshadowed",
    "hemi-raster",
    "hemi-raster:flat",
    "hemi-raster:pvs",
    "raytrace:4",
    "raytrace:16",
    "raytrace:64",
    "raytrace:64:vertex",
];

/// Builds a method from its name.
pub fn by_name(name: &str) -> Result<Box<dyn ShadowMethod>> {
    if name == "unshadowed" {
        let order = ShOrder::new(9).expect("9 is a valid SH order");
        return Ok(Box::new(Unshadowed::new(order)));
    }
    if name == "hemi-raster" {
        return Ok(Box::new(hemi_raster::HemiRaster::new(
            hemi_raster::Config::default(),
        )));
    }
    if name == "hemi-raster:flat" {
        let config = hemi_raster::Config {
            hierarchy: hemi_raster::Hierarchy::Flat,
            ..hemi_raster::Config::default()
        };
        return Ok(Box::new(hemi_raster::HemiRaster::new(config)));
    }
    if name == "hemi-raster:pvs" {
        let config = hemi_raster::Config {
            pvs: hemi_raster::Pvs::EVERY_FRAME,
            ..hemi_raster::Config::default()
        };
        return Ok(Box::new(hemi_raster::HemiRaster::new(config)));
    }
    if let Some(n) = name.strip_prefix("raytrace:") {
        let (count, vertex) = match n.strip_suffix(":vertex") {
            Some(count) => (count, true),
            None => (n, false),
        };
        let iterations: u32 = count.parse().ok().filter(|&i| i >= 2).ok_or_else(|| {
            Error::config(
                name,
                "the iteration count must be an integer ≥ 2 (raytrace:N or raytrace:N:vertex)",
            )
        })?;
        return Ok(Box::new(if vertex {
            RayTrace::per_vertex(iterations, 0xba5e)
        } else {
            RayTrace::new(iterations, 0xba5e)
        }));
    }
    Err(Error::config(
        name,
        format!(
            "no such method; methods are {}",
            METHODS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_and_reported_method_builds() {
        for name in REPORT_METHODS {
            assert!(by_name(name).is_ok(), "{name}");
        }
        for (name, _) in METHODS {
            let name = name.replace(":N", ":8");
            assert!(by_name(&name).is_ok(), "{name}");
        }
        assert_eq!(
            by_name("hemi-raster:flat").unwrap().name(),
            "hemi-raster-flat"
        );
        assert_eq!(
            by_name("hemi-raster:pvs").unwrap().name(),
            "hemi-raster-pvs"
        );
        assert!(by_name("raytrace:1").is_err());
        assert!(by_name("raytrace:1:vertex").is_err());
        assert_eq!(
            by_name("raytrace:8:vertex").unwrap().name(),
            "raytrace-8-vertex"
        );
        let unknown = by_name("nonesuch").err().map(|e| e.to_string());
        assert!(unknown.is_some_and(|e| e.contains("unshadowed")));
    }
}
