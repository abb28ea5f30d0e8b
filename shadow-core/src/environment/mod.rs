//! Distant lighting: an equirectangular (lat-long) map of linear RGB radiance.
//!
//! The mapping is fixed once, here (DESIGN.md, "Conventions"): texel (row i,
//! column j) of a W×H map is centred on θ = π(i+½)/H, θ = 0 being +Y (straight
//! up), and φ = 2π(j+½)/W, with direction ω = (sin θ cos φ, cos θ, sin θ sin φ).
//! Row 0 is the top row (as OpenEXR and Radiance RGBE store it).
//!
//! Maps are read from OpenEXR files (feature `exr`) and Radiance RGBE files
//! (feature `hdr`); [`Environment::load`] picks the reader by extension.

#[cfg(feature = "exr")]
mod exr;
mod filter;
#[cfg(feature = "hdr")]
mod hdr;
mod sampling;

use std::f32::consts::{PI, TAU};
use std::path::Path;

use glam::Vec3;

use crate::{Error, Result};

pub use sampling::{EnvSample, EnvironmentSampler};

/// What loading or building an environment changed, for reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct EnvironmentReport {
    /// Texel channels that were negative (ringing from HDR filtering or lossy
    /// compression) and were clamped to zero.
    pub negative_clamped: usize,
    /// The most negative channel value seen before clamping (0 if none).
    pub most_negative: f32,
}

/// A lat-long environment map of linear radiance (W·sr⁻¹·m⁻² per channel).
///
/// Every texel is finite and non-negative: [`Environment::new`] rejects NaN and
/// infinite texels (there is no right value to put in their place) and clamps
/// negative ones to zero, counting them in the [`EnvironmentReport`].
#[derive(Clone, Debug)]
pub struct Environment {
    name: String,
    width: usize,
    height: usize,
    texels: Vec<Vec3>,
    report: EnvironmentReport,
}

impl Environment {
    /// Validates and builds a map from row-major texels, row 0 at the top.
    pub fn new(
        name: impl Into<String>,
        width: usize,
        height: usize,
        mut texels: Vec<Vec3>,
    ) -> Result<Environment> {
        let name = name.into();
        let bad = |what: String| Error::InvalidEnvironment {
            source_name: name.clone(),
            what,
        };
        if width == 0 || height == 0 {
            return Err(bad(format!("empty map ({width}×{height})")));
        }
        if texels.len() != width * height {
            return Err(bad(format!(
                "{} texels for a {width}×{height} map",
                texels.len()
            )));
        }
        let non_finite = texels.iter().filter(|t| !t.is_finite()).count();
        if non_finite > 0 {
            let first = texels.iter().position(|t| !t.is_finite()).unwrap_or(0);
            return Err(bad(format!(
                "{non_finite} texels are NaN or infinite (first at row {}, column {}: {:?})",
                first / width,
                first % width,
                texels[first]
            )));
        }
        let mut report = EnvironmentReport::default();
        for t in &mut texels {
            for c in t.as_mut() {
                if *c < 0.0 {
                    report.negative_clamped += 1;
                    report.most_negative = report.most_negative.min(*c);
                    *c = 0.0;
                }
            }
        }
        Ok(Environment {
            name,
            width,
            height,
            texels,
            report,
        })
    }

    /// A constant environment. With radiance 1 and a white Lambert surface this
    /// is the white furnace, and with occluders the result is ambient occlusion.
    pub fn uniform(radiance: Vec3) -> Environment {
        // Radiance is constant, so a small map represents it exactly.
        Environment::new(
            format!("uniform({radiance})"),
            16,
            8,
            vec![radiance; 16 * 8],
        )
        .expect("a finite uniform radiance")
    }

    /// Loads a map file, the format chosen by its extension, in any case:
    /// `.exr` is OpenEXR (`load_exr`, feature `exr`) and `.hdr` is Radiance
    /// RGBE (`load_hdr`, feature `hdr`).
    ///
    /// Any other extension, or none, is an [`Error::Format`] naming the file
    /// and the formats `load` reads; so is a format whose feature is off in
    /// this build, naming the feature. Otherwise the errors are the reader's.
    pub fn load(path: &Path) -> Result<Environment> {
        let extension = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match extension.as_str() {
            #[cfg(feature = "exr")]
            "exr" => return Environment::load_exr(path),
            #[cfg(feature = "hdr")]
            "hdr" => return Environment::load_hdr(path),
            _ => {}
        }
        let what = match MAP_FORMATS.iter().find(|f| f.extension == extension) {
            Some(format) => format!(
                "{} maps need shadow-core's feature `{}`, which is off in this build",
                format.name, format.feature
            ),
            None => {
                let formats: Vec<String> = MAP_FORMATS
                    .iter()
                    .map(|f| format!(".{} ({})", f.extension, f.name))
                    .collect();
                let subject = if extension.is_empty() {
                    "no extension".to_string()
                } else {
                    format!("extension .{extension}")
                };
                format!(
                    "unknown environment map format ({subject}); the formats are {}",
                    formats.join(" and ")
                )
            }
        };
        Err(Error::format(path, what))
    }

    /// The map with every texel multiplied by `factor`: an exposure change,
    /// e.g. to bring a map stored in arbitrary units to the radiance a scene
    /// is lit with. The name and the [`EnvironmentReport`] stay.
    ///
    /// `factor` must be finite and positive (zero would turn the light off, a
    /// negative factor would make radiance negative), and no texel may
    /// overflow to infinity: otherwise [`Error::InvalidEnvironment`].
    pub fn scaled(mut self, factor: f32) -> Result<Environment> {
        let bad = |name: String, what: String| Error::InvalidEnvironment {
            source_name: name,
            what,
        };
        if !(factor.is_finite() && factor > 0.0) {
            return Err(bad(
                self.name,
                format!("exposure factor {factor} is not finite and positive"),
            ));
        }
        for t in &mut self.texels {
            *t *= factor;
        }
        let overflowed = self.texels.iter().filter(|t| !t.is_finite()).count();
        if overflowed > 0 {
            return Err(bad(
                self.name,
                format!("exposure factor {factor} overflows {overflowed} texels to infinity"),
            ));
        }
        Ok(self)
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The same map under another name (loaded maps are named by their path,
    /// which errors need; reports want a short name).
    pub fn renamed(mut self, name: impl Into<String>) -> Environment {
        self.name = name.into();
        self
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Row-major texels, row 0 at the top (θ near 0, +Y).
    pub fn texels(&self) -> &[Vec3] {
        &self.texels
    }

    pub fn texel(&self, row: usize, col: usize) -> Vec3 {
        self.texels[row * self.width + col]
    }

    pub fn report(&self) -> EnvironmentReport {
        self.report
    }

    /// The direction at the centre of texel (row, col).
    pub fn direction(&self, row: usize, col: usize) -> Vec3 {
        let theta = PI * (row as f32 + 0.5) / self.height as f32;
        let phi = TAU * (col as f32 + 0.5) / self.width as f32;
        direction_from_angles(theta, phi)
    }

    /// Continuous texel coordinates (column, row) of a direction, texel centres
    /// at integers: the inverse of [`Environment::direction`].
    pub fn texel_coords(&self, dir: Vec3) -> (f32, f32) {
        let (theta, phi) = angles_from_direction(dir);
        (
            phi / TAU * self.width as f32 - 0.5,
            theta / PI * self.height as f32 - 0.5,
        )
    }

    /// The texel (row, col) whose cell holds `dir`.
    pub fn texel_of(&self, dir: Vec3) -> (usize, usize) {
        let (x, y) = self.texel_coords(dir);
        let row = ((y + 0.5).floor().max(0.0) as usize).min(self.height - 1);
        let col = ((x + 0.5).floor().max(0.0) as usize) % self.width;
        (row, col)
    }

    /// Solid angle of a texel in `row`: the exact integral
    /// (cos θ₀ − cos θ₁) · 2π/W over the cell's latitude band, so that the
    /// weights of a map add up to 4π to float precision. DESIGN.md states the
    /// midpoint rule sin θ · (π/H) · (2π/W); the two agree to O((π/H)³).
    pub fn solid_angle(&self, row: usize) -> f32 {
        let h = self.height as f64;
        let t0 = std::f64::consts::PI * row as f64 / h;
        let t1 = std::f64::consts::PI * (row + 1) as f64 / h;
        ((t0.cos() - t1.cos()) * std::f64::consts::TAU / self.width as f64) as f32
    }

    /// Radiance in direction `dir`, bilinear between texel centres, wrapping in
    /// φ and clamping at the poles.
    pub fn lookup(&self, dir: Vec3) -> Vec3 {
        let (x, y) = self.texel_coords(dir);
        let y = y.clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let c0 = (x0 as i64).rem_euclid(w) as usize;
        let c1 = (x0 as i64 + 1).rem_euclid(w) as usize;
        let r0 = y0 as usize;
        let r1 = (r0 + 1).min(self.height - 1);
        let top = self.texel(r0, c0).lerp(self.texel(r0, c1), fx);
        let bottom = self.texel(r1, c0).lerp(self.texel(r1, c1), fx);
        top.lerp(bottom, fy)
    }

    /// Radiant power per unit area arriving from the whole sphere,
    /// Σ L·dω over texels (the integral of radiance over 4π).
    pub fn integral(&self) -> Vec3 {
        (0..self.height)
            .map(|r| {
                let row: Vec3 = self.texels[r * self.width..(r + 1) * self.width]
                    .iter()
                    .copied()
                    .sum();
                row * self.solid_angle(r)
            })
            .sum()
    }
}

/// A map file format [`Environment::load`] knows.
struct MapFormat {
    /// Lower case, without the dot.
    extension: &'static str,
    name: &'static str,
    /// The shadow-core feature that reads it.
    feature: &'static str,
}

const MAP_FORMATS: [MapFormat; 2] = [
    MapFormat {
        extension: "exr",
        name: "OpenEXR",
        feature: "exr",
    },
    MapFormat {
        extension: "hdr",
        name: "Radiance RGBE",
        feature: "hdr",
    },
];

/// ω = (sin θ cos φ, cos θ, sin θ sin φ).
pub fn direction_from_angles(theta: f32, phi: f32) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * cp, ct, st * sp)
}

/// (θ ∈ [0, π], φ ∈ [0, 2π)) of a unit direction.
pub fn angles_from_direction(dir: Vec3) -> (f32, f32) {
    let theta = dir.y.clamp(-1.0, 1.0).acos();
    let mut phi = dir.z.atan2(dir.x);
    if phi < 0.0 {
        phi += TAU;
    }
    (theta, phi)
}

/// Luminance of linear Rec. 709 RGB, the scalar that importance sampling and
/// reports use.
pub fn luminance(rgb: Vec3) -> f32 {
    rgb.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn gradient(w: usize, h: usize) -> Environment {
        let texels = (0..w * h)
            .map(|i| Vec3::new((i % w) as f32, (i / w) as f32, 1.0))
            .collect();
        Environment::new("gradient", w, h, texels).unwrap()
    }

    #[test]
    fn direction_texel_round_trip() {
        let env = gradient(64, 32);
        for row in 0..32 {
            for col in 0..64 {
                let d = env.direction(row, col);
                assert_relative_eq!(d.length(), 1.0, epsilon = 1e-6);
                assert_eq!(env.texel_of(d), (row, col));
                let (x, y) = env.texel_coords(d);
                assert_relative_eq!(x, col as f32, epsilon = 1e-3);
                assert_relative_eq!(y, row as f32, epsilon = 1e-3);
                // Bilinear lookup at a texel centre returns the texel.
                assert_relative_eq!(env.lookup(d), env.texel(row, col), epsilon = 2e-3);
            }
        }
    }

    #[test]
    fn top_row_is_up() {
        let env = gradient(8, 4);
        assert!(env.direction(0, 0).y > 0.9);
        assert!(env.direction(3, 0).y < -0.9);
        // φ = 0 is +X, φ = π/2 is +Z.
        let (_, phi) = angles_from_direction(Vec3::Z);
        assert_relative_eq!(phi, PI / 2.0);
    }

    #[test]
    fn solid_angles_sum_to_four_pi_and_match_midpoint_rule() {
        for (w, h) in [(4, 2), (64, 32), (1024, 512)] {
            let env = Environment::uniform(Vec3::ONE);
            let _ = env;
            let env = gradient(w, h);
            let total: f64 = (0..h).map(|r| env.solid_angle(r) as f64 * w as f64).sum();
            assert_relative_eq!(total, 4.0 * std::f64::consts::PI, epsilon = 1e-4);
        }
        let env = gradient(1024, 512);
        let row = 100;
        let theta = PI * (row as f32 + 0.5) / 512.0;
        let midpoint = theta.sin() * (PI / 512.0) * (TAU / 1024.0);
        assert_relative_eq!(env.solid_angle(row), midpoint, max_relative = 1e-4);
    }

    #[test]
    fn uniform_integral_is_four_pi() {
        let env = Environment::uniform(Vec3::splat(2.0));
        assert_relative_eq!(env.integral(), Vec3::splat(8.0 * PI), max_relative = 1e-5);
    }

    #[test]
    fn non_finite_texels_are_rejected_with_count() {
        let mut texels = vec![Vec3::ONE; 8 * 4];
        texels[9] = Vec3::new(f32::NAN, 0.0, 0.0);
        texels[10] = Vec3::new(0.0, f32::INFINITY, 0.0);
        let msg = Environment::new("bad.exr", 8, 4, texels)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("bad.exr") && msg.contains("2 texels") && msg.contains("row 1, column 1"),
            "{msg}"
        );
    }

    #[test]
    fn scaled_multiplies_every_texel_and_keeps_name_and_report() {
        let mut texels = vec![Vec3::new(1.0, 2.0, 0.5); 8 * 4];
        texels[3] = Vec3::new(-1.0, 1.0, 1.0);
        let env = Environment::new("sky", 8, 4, texels).unwrap();
        let report = env.report();
        let brighter = env.clone().scaled(2.5).unwrap();
        assert_eq!(brighter.name(), "sky");
        assert_eq!(brighter.report(), report);
        for (b, t) in brighter.texels().iter().zip(env.texels()) {
            assert_relative_eq!(*b, *t * 2.5);
        }
        assert_relative_eq!(
            brighter.integral(),
            env.integral() * 2.5,
            max_relative = 1e-6
        );
    }

    #[test]
    fn scaled_refuses_factors_that_are_not_finite_and_positive() {
        for factor in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let err = Environment::uniform(Vec3::ONE)
                .renamed("sky")
                .scaled(factor)
                .unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::InvalidEnvironment { .. }), "{msg}");
            assert!(
                msg.contains("sky") && msg.contains(&format!("factor {factor}")),
                "{msg}"
            );
        }
        let err = Environment::uniform(Vec3::splat(1e30))
            .scaled(1e10)
            .unwrap_err();
        assert!(err.to_string().contains("overflows 128 texels"), "{err}");
    }

    #[test]
    fn load_refuses_other_extensions_naming_file_and_formats() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["sky.png", "sky"] {
            let path = dir.path().join(name);
            std::fs::write(&path, "not read").unwrap();
            let err = Environment::load(&path).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::Format { .. }), "{msg}");
            assert!(
                msg.contains(&path.display().to_string())
                    && msg.contains(".exr (OpenEXR)")
                    && msg.contains(".hdr (Radiance RGBE)"),
                "{msg}"
            );
        }
    }

    #[cfg(not(feature = "exr"))]
    #[test]
    fn load_names_the_feature_a_format_needs() {
        let path = Path::new("maps/Sky.EXR");
        let msg = Environment::load(path).unwrap_err().to_string();
        assert!(
            msg.contains("maps/Sky.EXR") && msg.contains("feature `exr`"),
            "{msg}"
        );
    }

    #[cfg(all(feature = "exr", feature = "hdr"))]
    #[test]
    fn load_dispatches_by_extension_in_any_case() {
        let dir = tempfile::tempdir().unwrap();
        let env = gradient(8, 4);
        let exr = dir.path().join("Map.EXR");
        env.write_exr(&exr).unwrap();
        let loaded = Environment::load(&exr).unwrap();
        assert_eq!(loaded.texels(), env.texels());

        // An OpenEXR file under an .hdr name goes to the Radiance reader.
        let hdr = dir.path().join("map.Hdr");
        std::fs::copy(&exr, &hdr).unwrap();
        let msg = Environment::load(&hdr).unwrap_err().to_string();
        assert!(msg.contains("map.Hdr") && msg.contains("Radiance"), "{msg}");
    }

    #[test]
    fn negative_texels_are_clamped_and_counted() {
        let mut texels = vec![Vec3::ONE; 8 * 4];
        texels[3] = Vec3::new(-5.0, 1.0, -0.5);
        let env = Environment::new("ringing", 8, 4, texels).unwrap();
        assert_eq!(env.report().negative_clamped, 2);
        assert_eq!(env.report().most_negative, -5.0);
        assert_eq!(env.texel(0, 3), Vec3::new(0.0, 1.0, 0.0));
    }
}
