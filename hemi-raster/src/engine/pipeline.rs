//! The method's work per mask resolution: every receiver's mask through
//! the loop, and the masks to transfer vectors, irradiance or glossy
//! radiance, each on the SIMD path detected once.

use std::f32::consts::FRAC_1_PI;
use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;
use shadow_core::sh::{ShOrder, ShRgb};
use shadow_core::{Environment, Result};

use super::simd::{Kernel, SimdToken};
use super::{Columns, Scratch, UpdateProfile, receiver_mask};
use crate::blockers::{Blockers, Candidates, Layout};
use crate::config::{Config, MaskResolution};
use crate::hierarchy::TwoLevel;
use crate::mask::{Mask, MaskRow};
use crate::pvs::VisibleSets;
use crate::raster::{Rasterizer, TangentFrame};
use crate::transfer::{
    LobeGrid, PhongLobe, TangentBasis, direct_glossy, direct_irradiance, glossy_transfer,
};

/// The lighting of the last `relight`, as the integration wants it.
pub(crate) enum Lighting {
    /// Projected to SH, for the transfer vectors.
    Sh(ShRgb),
    /// Prefiltered to the mask's pixel size.
    Direct(Environment),
}

/// The pipeline of the configured mask resolution.
pub(crate) enum Engine {
    R16(Box<Pipeline<u16>>),
    R32(Box<Pipeline<u32>>),
    R64(Box<Pipeline<u64>>),
}

/// Runs `$body` with `$p` bound to the engine's pipeline, whatever its
/// resolution.
macro_rules! with_pipeline {
    ($engine:expr, $p:ident => $body:expr) => {
        match $engine {
            $crate::engine::Engine::R16($p) => $body,
            $crate::engine::Engine::R32($p) => $body,
            $crate::engine::Engine::R64($p) => $body,
        }
    };
}
pub(crate) use with_pipeline;

/// Everything one mask resolution needs: the plane table, the SH tables,
/// the SIMD path, and the current frame's masks.
pub(crate) struct Pipeline<W: MaskRow> {
    raster: Rasterizer<W>,
    /// The compilation of the per-receiver loop and of the integration that
    /// this CPU runs.
    simd: SimdToken,
    /// The SH basis over the mask, up to the configured order.
    basis: TangentBasis<W>,
    /// The current frame's masks, one per vertex, all objects together.
    masks: Vec<Mask<W>>,
}

impl<W: MaskRow> Pipeline<W> {
    pub(crate) fn new(config: &Config) -> Result<Pipeline<W>> {
        let raster = Rasterizer::new(config.lut_resolution)?;
        Ok(Pipeline {
            basis: TangentBasis::new(raster.grid(), config.order),
            raster,
            simd: SimdToken::detect(config.simd)?,
            masks: Vec::new(),
        })
    }

    /// Every receiver's mask, in parallel; or, with `profile`, on the
    /// calling thread with the loop's phases timed. A receiver that
    /// `enclosed` marks (pressed on another object or buried in one,
    /// [`shadow_core::contact`]) sees nothing: its mask is the whole disk.
    /// Returns the mean number of candidate blockers per receiver (Table
    /// 1's "Avg. #Tris", before the frame's replacements of near chords).
    pub(crate) fn rasterize(
        &mut self,
        blockers: &Blockers,
        enclosed: &[bool],
        hierarchy: Option<&TwoLevel>,
        visible: Option<&VisibleSets>,
        profile: Option<&mut UpdateProfile>,
    ) -> f64 {
        let coarse = hierarchy.map(|h| h.coarse_level(blockers));
        let layout = Layout::new(blockers, coarse.as_ref());
        // Visible sets list every triangle they read: no whole clusters.
        let columns = match visible {
            Some(_) => Columns::default(),
            None => Columns::new(&layout),
        };
        let (lut, simd) = (self.raster.lut(), self.simd);
        let candidates = |v: usize| match (visible, hierarchy) {
            (Some(sets), _) => sets.candidates(&layout, v),
            (None, Some(h)) => h.candidates(&layout, v),
            (None, None) => Candidates::All(&layout),
        };
        let full = *self.raster.grid().disk();
        let mask = |scratch: &mut Scratch, v: usize| {
            if enclosed[v] {
                return full;
            }
            let frame = blockers.frame(v);
            receiver_mask(simd, lut, &frame, &candidates(v), &columns, scratch)
        };
        let receivers = 0..blockers.vertex_count();
        let candidates_per_receiver = receivers
            .clone()
            .into_par_iter()
            .map(|v| candidates(v).count() as f64)
            .sum::<f64>()
            / receivers.len().max(1) as f64;
        self.masks = match profile {
            None => receivers
                .into_par_iter()
                .map_init(Scratch::default, mask)
                .collect(),
            Some(profile) => {
                let mut scratch = Scratch::profiling();
                let masks = receivers
                    .clone()
                    .map(|v| {
                        profile.candidates += candidates(v).count() as u64;
                        mask(&mut scratch, v)
                    })
                    .collect();
                let phases = scratch.profile().unwrap_or_default();
                profile.transform = phases.transform;
                profile.rasterization = phases.rasterization;
                profile.survivors = phases.survivors;
                profile.candidates += phases.replacements;
                profile.receivers = receivers.len();
                masks
            }
        };
        candidates_per_receiver
    }

    pub(crate) fn transfer(&self, blockers: &Blockers, blocks: bool, out: &mut Vec<f32>) {
        let n = self.basis.order().coeff_count();
        out.resize(self.masks.len() * n, 0.0);
        out.par_chunks_mut(n)
            .zip(self.masks.par_iter())
            .enumerate()
            .for_each(|(v, (out, mask))| {
                let frame = blockers.frame(v);
                lambert_transfer(self.simd, &self.basis, mask, &frame, blocks, out)
            });
    }

    pub(crate) fn direct(&self, blockers: &Blockers, environment: &Environment) -> Vec<Vec3> {
        let grid = self.raster.grid();
        self.masks
            .par_iter()
            .enumerate()
            .map(|(v, mask)| direct_irradiance(grid, mask, &blockers.frame(v), environment))
            .collect()
    }

    /// The specular radiance toward `eye` (without ρ_s) of the global
    /// `vertices`, in parallel: each vertex's glossy transfer for its own
    /// view direction, from its stored mask, dotted with the SH lighting; or,
    /// for direct integration, the lobe-weighted sum of the environment.
    pub(crate) fn glossy(
        &self,
        blockers: &Blockers,
        vertices: Range<usize>,
        eye: Vec3,
        exponent: f32,
        lighting: &Lighting,
        blocks: bool,
    ) -> Vec<Vec3> {
        let lobes = LobeGrid::new(self.raster.grid());
        let eye = blockers.to_local(eye);
        vertices
            .into_par_iter()
            .map(|v| {
                let frame = blockers.frame(v);
                // As the harness's reference: the normal when the eye sits
                // on the vertex.
                let view = (eye - frame.origin()).normalize_or(frame.normal());
                let lobe = PhongLobe::new(&frame, view, exponent);
                let mask = &self.masks[v];
                match lighting {
                    Lighting::Sh(light) => {
                        let mut t = [0.0f32; ShOrder::MAX.coeff_count()];
                        glossy_transfer(&self.basis, &lobes, mask, &frame, &lobe, blocks, &mut t);
                        light.dot(&t[..light.order().coeff_count()])
                    }
                    Lighting::Direct(env) => direct_glossy(&lobes, mask, &frame, &lobe, env),
                }
            })
            .collect()
    }

    /// The plane table and the disk grid.
    pub(crate) fn raster(&self) -> &Rasterizer<W> {
        &self.raster
    }

    /// The current frame's masks, one per vertex, all objects together.
    #[cfg(test)]
    pub(crate) fn masks(&self) -> &[Mask<W>] {
        &self.masks
    }

    /// The cosine-weighted fraction of global vertex `v`'s hemisphere its
    /// mask marks as blocked.
    pub(crate) fn blocked_fraction(&self, v: usize) -> f32 {
        self.raster.grid().coverage(&self.masks[v]) * FRAC_1_PI
    }
}

impl Engine {
    pub(crate) fn new(config: &Config) -> Result<Engine> {
        Ok(match config.mask_resolution {
            MaskResolution::R16 => Engine::R16(Box::new(Pipeline::new(config)?)),
            MaskResolution::R32 => Engine::R32(Box::new(Pipeline::new(config)?)),
            MaskResolution::R64 => Engine::R64(Box::new(Pipeline::new(config)?)),
        })
    }
}

/// [`TangentBasis::lambert`] compiled for `simd`: the table sums in the
/// path's registers.
pub(super) fn lambert_transfer<W: MaskRow>(
    simd: SimdToken,
    basis: &TangentBasis<W>,
    mask: &Mask<W>,
    frame: &TangentFrame,
    blocks: bool,
    out: &mut [f32],
) {
    simd.run(Lambert {
        basis,
        mask,
        frame,
        blocks,
        out,
    });
}

/// One vertex's Lambert transfer, for [`SimdToken::run`].
struct Lambert<'a, W: MaskRow> {
    basis: &'a TangentBasis<W>,
    mask: &'a Mask<W>,
    frame: &'a TangentFrame,
    blocks: bool,
    out: &'a mut [f32],
}

impl<W: MaskRow> Kernel for Lambert<'_, W> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        self.basis
            .lambert(self.mask, self.frame, self.blocks, self.out);
    }
}
