//! Per-texel estimates: merged over rounds, filtered with their neighbours' samples
//! ([`crate::filter`]), and after the last round counted, filled and packed into stored
//! texels.

use super::{Lightmaps, SamplingPlan};
use crate::{
    CacheStats,
    burial::Burial,
    crossings,
    filter::{self, FilterInput},
    stored_rgb::{STORED_RGB_BYTES, StoreScale},
};
use glam::Vec3;
use rayon::prelude::*;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::{Estimate, TracedScene};

/// The estimates of one texel over all rounds, merged.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct TexelEstimate {
    pub(super) samples: u32,
    pub(super) mean: Vec3,
    /// Variance of the mean, per channel.
    pub(super) variance: Vec3,
}

impl TexelEstimate {
    /// Merges an independent estimate of the same texel: means weighted by sample
    /// counts, `σ² = (n_a² σ_a² + n_b² σ_b²) / (n_a + n_b)²`. An estimate that is exactly
    /// zero (every sample was zero: in a gathering pass every ray met unlit surfaces)
    /// counts as exact. An estimate without samples (a re-bake's prior kept as it is,
    /// [`surfcache_trace::irradiance::unchanged`]) is taken as it is until samples
    /// arrive.
    pub(super) fn merge(&mut self, e: &Estimate) {
        let variance = if e.value == Vec3::ZERO {
            Vec3::ZERO
        } else {
            e.std_error * e.std_error
        };
        let (na, nb) = (self.samples as f32, e.samples as f32);
        let n = na + nb;
        if n == 0.0 {
            self.mean = e.value;
            self.variance = variance;
            return;
        }
        self.mean = (self.mean * na + e.value * nb) / n;
        self.variance = (self.variance * na * na + variance * nb * nb) / (n * n);
        self.samples += e.samples;
    }
}

impl Lightmaps {
    /// Sample point and shading normal of every owned slot (zero elsewhere).
    pub(super) fn texel_guides(&self, scene: &TracedScene) -> Vec<(Vec3, Vec3)> {
        (0..self.layers * self.layer_texels)
            .into_par_iter()
            .map(|slot| {
                let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
                match self.owner[i] {
                    NO_INDEX => (Vec3::ZERO, Vec3::ZERO),
                    t => {
                        let p = scene.surface_point(t, self.site_uv[slot], layer == 0);
                        (p.position, p.shading_normal)
                    }
                }
            })
            .collect()
    }

    /// The merged estimates, filtered texture by texture when `plan` filters (else as
    /// they are): value and variance per slot.
    pub(super) fn filtered(&self, plan: Option<&SamplingPlan>) -> Vec<(Vec3, Vec3)> {
        let mut out: Vec<(Vec3, Vec3)> = self
            .merged
            .par_iter()
            .map(|e| (e.mean, e.variance))
            .collect();
        let Some(plan) = plan.filter(|p| p.filter.iterations > 0) else {
            return out;
        };
        for layer in 0..self.layers {
            for m in &self.maps {
                let range = layer * self.layer_texels + m.offset
                    ..layer * self.layer_texels + m.offset + m.texels();
                let value: Vec<Vec3> = out[range.clone()].iter().map(|v| v.0).collect();
                let variance: Vec<Vec3> = out[range.clone()].iter().map(|v| v.1).collect();
                let position: Vec<Vec3> = self.guide[range.clone()].iter().map(|g| g.0).collect();
                let normal: Vec<Vec3> = self.guide[range.clone()].iter().map(|g| g.1).collect();
                // Crossed texels keep their own estimates: their neighbours may lie beyond
                // the crossing.
                let valid: Vec<bool> = range
                    .clone()
                    .map(|k| {
                        self.state[k] == Burial::Valid
                            && self.crossing_slot.get(k).is_none_or(|&c| c == NO_INDEX)
                    })
                    .collect();
                let (v, s) = filter::filter(
                    &FilterInput {
                        width: m.width as usize,
                        height: m.height as usize,
                        value: &value,
                        variance: &variance,
                        position: &position,
                        normal: &normal,
                        valid: &valid,
                        texel: 1.0 / m.texels_per_metre.max(f32::MIN_POSITIVE),
                        floor: plan.floor,
                    },
                    &plan.filter,
                );
                for (o, vs) in out[range].iter_mut().zip(v.into_iter().zip(s)) {
                    *o = vs;
                }
            }
        }
        out
    }

    /// After the last round: statistics, buried texels refilled from valid neighbours,
    /// dilation into the gutters, packing ([`crate::stored_rgb`]); the working state is dropped.
    pub(super) fn finish(&mut self, mut values: Vec<Vec3>, plan: Option<&SamplingPlan>) {
        let total = self.layers * self.layer_texels;
        let mut state = std::mem::take(&mut self.state);
        let merged = std::mem::take(&mut self.merged);
        let mut stats = estimate_stats(&merged, &state, plan);
        self.sample_counts = merged.iter().map(|e| e.samples).collect();
        self.buried_slots = state.iter().map(|&st| st == Burial::Buried).collect();
        stats.dilated_texels += self.fill_textures(&mut values, &mut state);
        self.pack(&values);
        stats.sample_points +=
            self.probed
                .as_deref()
                .map_or(0, |p| p.foot_sites.iter().flatten().count()) as u64;
        stats.samples += self.foot_samples;
        // UV1: three f32 pairs per triangle corner (a generated layout needs a vertex per
        // corner); the per-triangle instance index is the engine's mesh binding.
        stats.cache_bytes = STORED_RGB_BYTES * total as u64
            + 24 * self.uv1.len() as u64
            + 4 * self.crossing_slot.len() as u64
            + (20 + STORED_RGB_BYTES) * self.crossing_lines.len() as u64;
        self.stats = stats;
        self.drop_working_state();
    }

    /// Packs the finished values with one scale for their largest value
    /// ([`crate::stored_rgb`]), and the crossings' feet with it.
    fn pack(&mut self, values: &[Vec3]) {
        let max = values
            .par_iter()
            .map(|v| v.max_element())
            .reduce(|| 0.0f32, f32::max);
        self.scale = StoreScale::for_max(max);
        let scale = self.scale;
        self.packed = values.par_iter().map(|&v| scale.pack(v)).collect();
        // Feet share the texels' scale (clamped to their largest value, so that the
        // texels are stored as without them).
        self.crossing_feet = crossings::settle_feet(&mut self.crossing_lines, &self.feet, |f| {
            scale.pack(f.min(Vec3::splat(max)))
        });
    }

    /// Drops what only baking needs (the guides' records stay: a pass gathering from
    /// this one borrows them, `Lightmaps::guide_at`).
    fn drop_working_state(&mut self) {
        self.slots = Vec::new();
        self.priors = Vec::new();
        self.prior_feet = Default::default();
        self.guide = Vec::new();
        self.pending = Vec::new();
        self.site_uv = Vec::new();
        self.feet = Vec::new();
        self.guides.forget_guides();
    }
}

/// Statistics of the merged estimates: points and samples of the texels, and their mean
/// relative error (C = σ / (E + ε), buried texels left out).
fn estimate_stats(
    merged: &[TexelEstimate],
    state: &[Burial],
    plan: Option<&SamplingPlan>,
) -> CacheStats {
    let mut stats = CacheStats::default();
    let mut rel_error = 0.0f64;
    for (slot, e) in merged.iter().enumerate() {
        if e.samples == 0 {
            continue;
        }
        stats.sample_points += 1;
        stats.samples += e.samples as u64;
        stats.max_samples_per_point = stats.max_samples_per_point.max(e.samples);
        match state[slot] {
            Burial::Buried => stats.buried += 1,
            _ => {
                let floor = plan.map_or(0.0, |p| p.floor).max(f32::MIN_POSITIVE);
                let c = e.variance.map(f32::sqrt) / (e.mean.max(Vec3::ZERO) + Vec3::splat(floor));
                rel_error += c.max_element() as f64;
            }
        }
    }
    stats.mean_rel_error = rel_error / (stats.sample_points - stats.buried).max(1) as f64;
    stats
}
