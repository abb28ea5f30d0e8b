//! The occluders drawn into the depth maps: every triangle, or each object
//! simplified (shadow-core's `simplify`; the tested vertices stay at full
//! resolution), and how far a pose may move a simplified surface.

use shadow_core::Mesh;

/// How much `posed` (the same mesh in a pose) stretches `rest`: the largest
/// ratio of an edge's posed length to its rest length, by which distances
/// in the rest mesh's units grow at most in the pose's.
pub fn stretch(rest: &Mesh, posed: &Mesh) -> f32 {
    let (a, b) = (rest.positions(), posed.positions());
    rest.triangles()
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .filter_map(|(i, j)| {
            let (i, j) = (i as usize, j as usize);
            let length = a[i].distance(a[j]);
            (length > 0.0).then(|| b[i].distance(b[j]) / length)
        })
        .fold(f32::MIN_POSITIVE, f32::max)
}
