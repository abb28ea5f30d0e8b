//! What the test binaries share.

use glam::Vec3;
use shadow_core::Environment;

/// An environment with a bright patch above the +X horizon over a dim sky.
pub fn patchy() -> Environment {
    let (w, h) = (64, 32);
    let texels = (0..w * h)
        .map(|i| {
            let (row, col) = (i / w, i % w);
            if (8..14).contains(&row) && (2..10).contains(&col) {
                Vec3::new(20.0, 18.0, 15.0)
            } else {
                Vec3::new(0.3, 0.4, 0.6)
            }
        })
        .collect();
    Environment::new("patchy", w, h, texels).unwrap()
}
