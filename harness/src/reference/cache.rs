//! The on-disk cache of vertex references, keyed by a content hash of
//! everything the result depends on. Files are written atomically and carry a
//! checksum: a truncated or corrupted file is recomputed, never trusted.

use std::path::{Path, PathBuf};

use glam::Vec3;
use shadow_core::{Environment, FrameGeometry, Result, Scene, VertexRadiance};

use super::{ReferenceSettings, VertexReference, split};
use crate::io::write_atomic;

/// Bumped whenever the estimator or the file layout changes meaning.
const FORMAT: &[u8; 8] = b"SSREF003";

/// The content hash of a vertex reference's inputs: geometry (positions,
/// normals, triangles of every object), materials, the environment's texels,
/// the view point and the estimator settings.
pub fn cache_key(
    scene: &Scene,
    frame: &FrameGeometry,
    environment: &Environment,
    eye: Vec3,
    settings: &ReferenceSettings,
) -> blake3::Hash {
    let mut h = blake3::Hasher::new();
    h.update(FORMAT);
    for (posed, object) in frame.objects.iter().zip(scene.objects()) {
        h.update(bytemuck::cast_slice(posed.positions()));
        h.update(bytemuck::cast_slice(posed.normals()));
        h.update(bytemuck::cast_slice(posed.triangles()));
        h.update(format!("{:?}", object.material).as_bytes());
    }
    h.update(&(environment.width() as u64).to_le_bytes());
    h.update(bytemuck::cast_slice(environment.texels()));
    h.update(bytemuck::bytes_of(&eye));
    h.update(format!("{settings:?}").as_bytes());
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

    /// The cached reference for `key`, or `None` when absent, truncated, of
    /// another format, or failing its checksum.
    pub fn get(&self, key: &blake3::Hash, shape: &FrameGeometry) -> Option<VertexReference> {
        let bytes = std::fs::read(self.path(key)).ok()?;
        decode(&bytes, key, shape)
    }

    /// Stores a reference atomically.
    pub fn put(&self, key: &blake3::Hash, reference: &VertexReference) -> Result<()> {
        write_atomic(&self.path(key), &encode(key, reference))
    }

    /// The cached reference, or computes and stores it.
    pub fn get_or_compute(
        &self,
        key: &blake3::Hash,
        shape: &FrameGeometry,
        compute: impl FnOnce() -> Result<VertexReference>,
    ) -> Result<(VertexReference, bool)> {
        if let Some(hit) = self.get(key, shape) {
            return Ok((hit, true));
        }
        let fresh = compute()?;
        self.put(key, &fresh)?;
        Ok((fresh, false))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// Layout: FORMAT, key (32), vertex count (u64), rays (u64), noise (f32),
/// seconds (f64), means (n·Vec3), standard errors (n·Vec3), replicates (n·u32),
/// then the blake3 hash of everything before it.
fn encode(key: &blake3::Hash, r: &VertexReference) -> Vec<u8> {
    let mean: Vec<Vec3> = r.radiance.flat().collect();
    let se: Vec<Vec3> = r
        .radiance
        .std_error
        .iter()
        .flatten()
        .flatten()
        .copied()
        .collect();
    let mut out = Vec::new();
    out.extend_from_slice(FORMAT);
    out.extend_from_slice(key.as_bytes());
    out.extend_from_slice(&(mean.len() as u64).to_le_bytes());
    out.extend_from_slice(&r.rays.to_le_bytes());
    out.extend_from_slice(&r.noise.to_le_bytes());
    out.extend_from_slice(&r.seconds.to_le_bytes());
    out.extend_from_slice(bytemuck::cast_slice(&mean));
    out.extend_from_slice(bytemuck::cast_slice(&se));
    out.extend_from_slice(bytemuck::cast_slice(&r.replicates));
    let check = blake3::hash(&out);
    out.extend_from_slice(check.as_bytes());
    out
}

fn decode(bytes: &[u8], key: &blake3::Hash, shape: &FrameGeometry) -> Option<VertexReference> {
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
    let n = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    if n != shape
        .objects
        .iter()
        .map(|o| o.vertex_count())
        .sum::<usize>()
    {
        return None;
    }
    let rays = u64::from_le_bytes(take(8)?.try_into().ok()?);
    let noise = f32::from_le_bytes(take(4)?.try_into().ok()?);
    let seconds = f64::from_le_bytes(take(8)?.try_into().ok()?);
    let vec3s = |b: &[u8]| -> Vec<Vec3> {
        b.chunks_exact(12)
            .map(|c| Vec3::from_array(bytemuck::pod_read_unaligned(c)))
            .collect()
    };
    let mean = vec3s(take(n * 12)?);
    let se = vec3s(take(n * 12)?);
    let replicates: Vec<u32> = take(n * 4)?
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Some(VertexReference {
        radiance: VertexRadiance {
            radiance: split(shape, &mean),
            std_error: Some(split(shape, &se)),
        },
        replicates,
        rays,
        noise,
        seconds,
    })
}
