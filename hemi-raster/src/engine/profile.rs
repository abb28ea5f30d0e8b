//! Where an update's time goes: the split of Kautz et al.'s Table 2 and
//! the blocker counts of its Table 1.

use std::time::Duration;

use shadow_core::{Profile, Stage};

/// Where the loop's time went, summed over receivers (the paper's Table 2
/// split): the setup ("transform": blockers into the receiver's frame,
/// culling, plane cells) and the lookups ("rasterization").
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LoopProfile {
    pub(crate) transform: Duration,
    pub(crate) rasterization: Duration,
    /// Triangles that survived culling and were looked up.
    pub(crate) survivors: u64,
    /// Fine triangles listed in place of replaced coarse ones.
    pub(crate) replacements: u64,
}

/// Where one profiled update spent its time, on one thread: the split of
/// Kautz et al.'s Table 2 ("transform includes backface culling and view
/// transformation of blockers") and the counts behind its Table 1, as
/// [`HemiRaster::profile_update`](crate::HemiRaster::profile_update)
/// reports them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct UpdateProfile {
    /// Receivers (vertices, all objects).
    pub receivers: usize,
    /// Blocker triangles considered, summed over receivers: divided by
    /// `receivers`, Table 1's "Avg. #Tris".
    pub candidates: u64,
    /// Of those, the ones that survived culling and were rasterized.
    pub survivors: u64,
    /// Gathering the frame's blockers into the loop's arrays, and the rest
    /// of the visibility stage outside the per-receiver loop ("Other").
    pub gather: Duration,
    /// Per receiver: blockers into its tangent frame, culling (horizon,
    /// receiver, back faces, boxes below the horizon), plane cells.
    pub transform: Duration,
    /// Per receiver: plane-mask look-ups, ANDs and ORs.
    pub rasterization: Duration,
    /// Masks to transfer vectors (or, for direct integration, to irradiance).
    pub integration: Duration,
}

impl UpdateProfile {
    /// Into `profile`'s update entries.
    pub(crate) fn record(&self, profile: &mut Profile) {
        let update = Stage::Update;
        profile.seconds(update, "gather", self.gather.as_secs_f64());
        profile.seconds(update, "transform", self.transform.as_secs_f64());
        profile.seconds(update, "rasterization", self.rasterization.as_secs_f64());
        profile.seconds(update, "integration", self.integration.as_secs_f64());
        profile.count(update, "receivers", self.receivers as u64);
        profile.count(update, "candidates", self.candidates);
        profile.count(update, "survivors", self.survivors);
    }
}
