//! The on-disk cache of references (per vertex and per pixel), keyed by a
//! content hash of everything the result depends on. Files are written
//! atomically and carry a checksum: a truncated or corrupted file is
//! recomputed, never trusted.

use std::path::{Path, PathBuf};

use glam::Vec3;
use shadow_core::{Brdf, Camera, Environment, FrameGeometry, Image, Result, Scene, VertexRadiance};

use super::{ImageReference, ReferenceSettings, VertexReference, split};
use crate::io::write_atomic;

/// Bumped whenever the estimator or the file layout changes meaning.
const FORMAT: &[u8; 8] = b"SSREF011";

/// What a reference is of: the vertices seen from an eye, or the pixels of
/// a camera's image.
#[derive(Clone, Copy, Debug)]
pub enum Domain<'a> {
    Vertices { eye: Vec3 },
    Pixels { camera: &'a Camera },
}

/// The content hash of a reference's inputs: geometry (positions, normals,
/// triangles of every object), materials, the environment's texels, the view
/// (eye, or the whole camera for images) and the estimator settings, each
/// value hashed as its little-endian bytes (never as it prints). The
/// material, the camera and the settings are destructured whole, so that a
/// field added to one must be added here.
pub fn cache_key(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    domain: Domain,
    settings: &ReferenceSettings,
) -> blake3::Hash {
    let mut h = blake3::Hasher::new();
    h.update(FORMAT);
    for (posed, object) in frame.objects.iter().zip(scene.objects()) {
        h.update(bytemuck::cast_slice(posed.positions()));
        h.update(bytemuck::cast_slice(posed.normals()));
        h.update(bytemuck::cast_slice(posed.triangles()));
        match object.material {
            Brdf::Lambert { albedo } => {
                h.update(b"lambert");
                h.update(bytemuck::bytes_of(&albedo));
            }
            Brdf::Phong {
                diffuse,
                specular,
                exponent,
            } => {
                h.update(b"phong");
                h.update(bytemuck::bytes_of(&diffuse));
                h.update(bytemuck::bytes_of(&specular));
                h.update(&exponent.to_le_bytes());
            }
        }
    }
    h.update(&(environment.width() as u64).to_le_bytes());
    h.update(bytemuck::cast_slice(environment.texels()));
    match domain {
        Domain::Vertices { eye } => {
            h.update(b"vertices");
            h.update(bytemuck::bytes_of(&eye));
        }
        Domain::Pixels { camera } => {
            let Camera {
                eye,
                target,
                up,
                fov_y,
                width,
                height,
            } = *camera;
            h.update(b"pixels");
            h.update(bytemuck::cast_slice(&[eye, target, up]));
            h.update(&fov_y.to_le_bytes());
            h.update(&width.to_le_bytes());
            h.update(&height.to_le_bytes());
        }
    };
    let ReferenceSettings {
        seed,
        replicate_size,
        min_replicates,
        max_replicates,
        target_noise,
    } = *settings;
    h.update(&seed.to_le_bytes());
    h.update(&replicate_size.to_le_bytes());
    h.update(&min_replicates.to_le_bytes());
    h.update(&max_replicates.to_le_bytes());
    match target_noise {
        Some(noise) => h.update(&[1]).update(&noise.to_le_bytes()),
        None => h.update(&[0]),
    };
    h.finalize()
}

/// A directory of cached references.
pub struct ReferenceCache {
    dir: PathBuf,
}

impl ReferenceCache {
    pub fn new(dir: impl Into<PathBuf>) -> ReferenceCache {
        ReferenceCache { dir: dir.into() }
    }

    fn path(&self, key: &blake3::Hash) -> PathBuf {
        self.dir.join(format!("{}.ref", key.to_hex()))
    }

    fn read(&self, key: &blake3::Hash) -> Option<Record> {
        let bytes = std::fs::read(self.path(key)).ok()?;
        Record::decode(&bytes, key)
    }

    fn write(&self, key: &blake3::Hash, record: &Record) -> Result<()> {
        write_atomic(&self.path(key), &record.encode(key))
    }

    /// The cached vertex reference for `key` (of a frame shaped like
    /// `shape`), or computes and stores it; also says whether it was cached.
    /// A file that is absent, truncated, of another format or shape, or
    /// fails its checksum is recomputed.
    pub fn vertex(
        &self,
        key: &blake3::Hash,
        shape: &FrameGeometry,
        compute: impl FnOnce() -> Result<VertexReference>,
    ) -> Result<(VertexReference, bool)> {
        let vertices: usize = shape.objects.iter().map(|o| o.vertex_count()).sum();
        let cached = self.read(key);
        if let Some(record) = cached.filter(|r| r.mean.len() == vertices && r.covered.is_none()) {
            return Ok((record.into_vertex(shape), true));
        }
        let fresh = compute()?;
        self.write(key, &Record::of_vertex(&fresh))?;
        Ok((fresh, false))
    }

    /// The cached image reference for `key` (of a `width × height` image),
    /// or computes and stores it, as [`ReferenceCache::vertex`].
    pub fn image(
        &self,
        key: &blake3::Hash,
        (width, height): (u32, u32),
        compute: impl FnOnce() -> Result<ImageReference>,
    ) -> Result<(ImageReference, bool)> {
        if let Some(reference) = self.read(key).and_then(|r| r.into_image(width, height)) {
            return Ok((reference, true));
        }
        let fresh = compute()?;
        self.write(key, &Record::of_image(&fresh))?;
        Ok((fresh, false))
    }

    /// The cached image reference for `key` (of a `width × height` image),
    /// if a valid one is stored; computes nothing.
    pub fn cached_image(
        &self,
        key: &blake3::Hash,
        (width, height): (u32, u32),
    ) -> Option<ImageReference> {
        self.read(key).and_then(|r| r.into_image(width, height))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// What a file holds: per-point estimates, and for an image which pixels
/// the points are (covered ones, in row order).
struct Record {
    rays: u64,
    noise: f32,
    seconds: f64,
    mean: Vec<Vec3>,
    std_error: Vec<Vec3>,
    replicates: Vec<u32>,
    /// `(width, height, covered)` of an image.
    covered: Option<(u32, u32, Vec<bool>)>,
}

impl Record {
    fn of_vertex(r: &VertexReference) -> Record {
        Record {
            rays: r.rays,
            noise: r.noise,
            seconds: r.seconds,
            mean: r.radiance.flat().collect(),
            std_error: r
                .radiance
                .std_error
                .iter()
                .flatten()
                .flatten()
                .copied()
                .collect(),
            replicates: r.replicates.clone(),
            covered: None,
        }
    }

    fn into_vertex(self, shape: &FrameGeometry) -> VertexReference {
        VertexReference {
            radiance: VertexRadiance {
                radiance: split(shape, &self.mean),
                std_error: Some(split(shape, &self.std_error)),
                evaluated: None,
            },
            replicates: self.replicates,
            rays: self.rays,
            noise: self.noise,
            seconds: self.seconds,
        }
    }

    fn of_image(r: &ImageReference) -> Record {
        let image = &r.image;
        let covered = || (0..image.pixels.len()).filter(|&i| image.covered[i]);
        let se = image.std_error.as_deref().unwrap_or(&[]);
        Record {
            rays: r.rays,
            noise: r.noise,
            seconds: r.seconds,
            mean: covered().map(|i| image.pixels[i]).collect(),
            std_error: covered()
                .map(|i| se.get(i).copied().unwrap_or(Vec3::ZERO))
                .collect(),
            replicates: Vec::new(),
            covered: Some((image.width, image.height, image.covered.clone())),
        }
    }

    fn into_image(self, width: u32, height: u32) -> Option<ImageReference> {
        let (w, h, covered) = self.covered?;
        if (w, h) != (width, height) {
            return None;
        }
        let mut pixels = vec![Vec3::ZERO; covered.len()];
        let mut std_error = vec![Vec3::ZERO; covered.len()];
        let slots = (0..covered.len()).filter(|&i| covered[i]);
        for (k, slot) in slots.enumerate() {
            pixels[slot] = self.mean[k];
            std_error[slot] = self.std_error[k];
        }
        Some(ImageReference {
            image: Image {
                width,
                height,
                pixels,
                covered,
                std_error: Some(std_error),
            },
            rays: self.rays,
            noise: self.noise,
            seconds: self.seconds,
        })
    }

    /// Layout: FORMAT, key (32), point count n (u64), rays (u64), noise
    /// (f32), seconds (f64), means (n·Vec3), standard errors (n·Vec3),
    /// replicate count r (u64) and replicates (r·u32), image flag (u8) and,
    /// for an image, width and height (u32 each) and one byte per pixel
    /// (covered or not); then the blake3 hash of everything before it.
    fn encode(&self, key: &blake3::Hash) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(FORMAT);
        out.extend_from_slice(key.as_bytes());
        out.extend_from_slice(&(self.mean.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.rays.to_le_bytes());
        out.extend_from_slice(&self.noise.to_le_bytes());
        out.extend_from_slice(&self.seconds.to_le_bytes());
        out.extend_from_slice(bytemuck::cast_slice(&self.mean));
        out.extend_from_slice(bytemuck::cast_slice(&self.std_error));
        out.extend_from_slice(&(self.replicates.len() as u64).to_le_bytes());
        out.extend_from_slice(bytemuck::cast_slice(&self.replicates));
        match &self.covered {
            None => out.push(0),
            Some((width, height, covered)) => {
                out.push(1);
                out.extend_from_slice(&width.to_le_bytes());
                out.extend_from_slice(&height.to_le_bytes());
                out.extend(covered.iter().map(|&c| u8::from(c)));
            }
        }
        let check = blake3::hash(&out);
        out.extend_from_slice(check.as_bytes());
        out
    }

    fn decode(bytes: &[u8], key: &blake3::Hash) -> Option<Record> {
        let (body, check) = bytes.split_at_checked(bytes.len().checked_sub(32)?)?;
        if blake3::hash(body).as_bytes() != check {
            return None;
        }
        let mut rest = body.strip_prefix(FORMAT)?.strip_prefix(key.as_bytes())?;
        let mut take = |n: usize| -> Option<&[u8]> {
            let (head, tail) = rest.split_at_checked(n)?;
            rest = tail;
            Some(head)
        };
        let u64_at = |b: &[u8]| u64::from_le_bytes(b.try_into().expect("8 bytes"));
        let u32_at = |b: &[u8]| u32::from_le_bytes(b.try_into().expect("4 bytes"));
        let vec3s = |b: &[u8]| -> Vec<Vec3> {
            b.chunks_exact(12)
                .map(|c| Vec3::from_array(bytemuck::pod_read_unaligned(c)))
                .collect()
        };
        let n = usize::try_from(u64_at(take(8)?)).ok()?;
        let rays = u64_at(take(8)?);
        let noise = f32::from_le_bytes(take(4)?.try_into().ok()?);
        let seconds = f64::from_le_bytes(take(8)?.try_into().ok()?);
        let mean = vec3s(take(n.checked_mul(12)?)?);
        let std_error = vec3s(take(n * 12)?);
        let r = usize::try_from(u64_at(take(8)?)).ok()?;
        let replicates = take(r.checked_mul(4)?)?
            .chunks_exact(4)
            .map(u32_at)
            .collect();
        let covered = match take(1)?[0] {
            0 => None,
            1 => {
                let width = u32_at(take(4)?);
                let height = u32_at(take(4)?);
                let pixels = (width as usize).checked_mul(height as usize)?;
                let covered: Vec<bool> = take(pixels)?.iter().map(|&b| b == 1).collect();
                if covered.iter().filter(|c| **c).count() != n {
                    return None;
                }
                Some((width, height, covered))
            }
            _ => return None,
        };
        Some(Record {
            rays,
            noise,
            seconds,
            mean,
            std_error,
            replicates,
            covered,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use shadow_core::{Object, shapes};

    use super::*;

    fn scene(material: Brdf) -> Scene {
        let floor = Arc::new(shapes::floor("floor", Vec3::ZERO, 1.0, 1).unwrap());
        let camera = Camera::framing(Vec3::ZERO, 2.0, Vec3::ONE, 8, 8).unwrap();
        let object = Object {
            mesh: floor,
            material,
        };
        Scene::still("floor", vec![object], camera).unwrap()
    }

    /// The key is a function of the values: equal inputs give equal keys,
    /// and changing any one field of the material, the view or the
    /// settings changes it.
    #[test]
    fn the_key_follows_every_input() {
        let grey = Brdf::lambert(Vec3::splat(0.5)).unwrap();
        let env = Environment::uniform(Vec3::ONE);
        let camera = Camera::framing(Vec3::ZERO, 2.0, Vec3::ONE, 8, 8).unwrap();
        let settings = ReferenceSettings::CONVERGED;
        let key = |material: Brdf, domain: Domain, settings: &ReferenceSettings| {
            let scene = scene(material);
            let frame = scene.frame_geometry(0).unwrap();
            cache_key(&scene, &frame, &env, domain, settings)
        };
        let eye = Domain::Vertices { eye: Vec3::ONE };
        let base = key(grey, eye, &settings);
        assert_eq!(base, key(grey, eye, &settings));

        let phong = Brdf::Phong {
            diffuse: Vec3::splat(0.5),
            specular: Vec3::ZERO,
            exponent: 1.0,
        };
        let mut keys = vec![
            key(Brdf::lambert(Vec3::splat(0.4)).unwrap(), eye, &settings),
            key(phong, eye, &settings),
            key(
                Brdf::Phong {
                    diffuse: Vec3::splat(0.5),
                    specular: Vec3::splat(0.1),
                    exponent: 1.0,
                },
                eye,
                &settings,
            ),
            key(
                Brdf::Phong {
                    diffuse: Vec3::splat(0.5),
                    specular: Vec3::ZERO,
                    exponent: 2.0,
                },
                eye,
                &settings,
            ),
            key(grey, Domain::Vertices { eye: Vec3::X }, &settings),
            key(grey, Domain::Pixels { camera: &camera }, &settings),
        ];
        let cameras = [
            Camera {
                fov_y: camera.fov_y * 0.5,
                ..camera
            },
            Camera { width: 9, ..camera },
            Camera {
                height: 9,
                ..camera
            },
            Camera {
                target: camera.target + Vec3::X,
                ..camera
            },
            Camera {
                eye: camera.eye + Vec3::X,
                ..camera
            },
            Camera {
                up: Vec3::X,
                ..camera
            },
        ];
        keys.extend(
            cameras
                .iter()
                .map(|camera| key(grey, Domain::Pixels { camera }, &settings)),
        );
        let changed = [
            ReferenceSettings {
                seed: 1,
                ..settings
            },
            ReferenceSettings {
                replicate_size: 64,
                ..settings
            },
            ReferenceSettings {
                min_replicates: 8,
                ..settings
            },
            ReferenceSettings {
                max_replicates: 8,
                ..settings
            },
            ReferenceSettings {
                target_noise: None,
                ..settings
            },
            ReferenceSettings {
                target_noise: Some(0.01),
                ..settings
            },
        ];
        keys.extend(changed.iter().map(|s| key(grey, eye, s)));
        keys.push(base);
        let distinct: std::collections::HashSet<_> = keys.iter().collect();
        assert_eq!(distinct.len(), keys.len());
    }
}
