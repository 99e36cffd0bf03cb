//! Rounds of samples (module docs, Rounds): the sample point of every texel that still
//! needs samples, the feet of crossed texels, and after each round, which texels are
//! buried or moved and which need another round.

use super::{LightmapSettings, Lightmaps, TexelGuides, estimates::TexelEstimate};
use crate::{Prior, SamplePoint, SampleSite, burial::Burial, crossings, filter::FilterSettings};
use glam::Vec3;
use surfcache_core::{index::NO_INDEX, sampling::splitmix64};
use surfcache_trace::{Estimate, EstimatorSettings, TracedScene};

/// Before any estimate is in, a lightmap's progress report expects its later rounds to
/// take this many times the samples of the first; the guess is replaced by a prediction
/// once the first round is in.
pub const LATER_ROUNDS_GUESS: f32 = 2.0;

/// How a lightmap plans its rounds of samples (module docs, Rounds), from the bake's
/// estimator settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplingPlan {
    /// Samples of every texel in the first round (the estimator's `min_samples`).
    pub first: u32,
    /// Most samples of one texel over all rounds.
    pub max: u32,
    /// Bound on the filtered estimate's relative error, per channel (0: one round).
    pub bound: f32,
    /// The absolute floor ε of relative errors (W/m²).
    pub floor: f32,
    pub filter: FilterSettings,
}

impl SamplingPlan {
    pub(super) fn new(estimator: &EstimatorSettings, settings: &LightmapSettings) -> Self {
        let max = estimator.max_samples.max(1);
        Self {
            first: if estimator.max_rel_error > 0.0 {
                estimator.min_samples.clamp(1, max)
            } else {
                max
            },
            max,
            bound: estimator.max_rel_error,
            floor: estimator.floor,
            filter: settings.filter,
        }
    }

    /// C = σ / (E + ε), the largest over the channels, of a (filtered) estimate with
    /// value `v` and variance `s`.
    pub(super) fn relative_error(&self, v: Vec3, s: Vec3) -> f32 {
        let c = s.max(Vec3::ZERO).map(f32::sqrt) / (v.max(Vec3::ZERO) + Vec3::splat(self.floor));
        c.max_element()
    }
}

impl Lightmaps {
    /// The sample point of texel `i` of `layer` in `round` (its key differs per round, so
    /// rounds are independent estimates), with `budget` samples.
    fn texel_point(
        &self,
        scene: &TracedScene,
        layer: usize,
        i: usize,
        round: u32,
        budget: Option<u32>,
    ) -> SamplePoint {
        let triangle = self.owner[i];
        let m = self.maps[self.triangle_instance[triangle as usize] as usize];
        let k = (i - m.offset) as u32;
        let (x, y) = (k % m.width, k / m.width);
        let key = texel_key(scene.triangle_key(triangle), layer, x, y);
        let uv = self
            .site_uv
            .get(layer * self.layer_texels + i)
            .copied()
            .unwrap_or(self.sample_uv[i]);
        SamplePoint {
            site: SampleSite::Surface {
                triangle,
                uv,
                front: layer == 0,
            },
            key: if round == 0 {
                key
            } else {
                splitmix64(key ^ round as u64)
            },
            prior: self
                .priors
                .get(layer * self.layer_texels + i)
                .copied()
                .flatten(),
            budget,
            cap_share: 1.0,
        }
    }

    /// Round 0: every owned texel of every layer, instance by instance, row-major, with
    /// the plan's first budget (none in an incremental re-bake), then the feet of crossed
    /// texels.
    pub(super) fn first_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        // An incremental re-bake (no refining plan) keeps one round of estimates stopped
        // by the estimator itself: they update filtered values, which are not filtered
        // again.
        let budget = self.refining_plan().map(|plan| plan.first);
        // Records are kept whether or not this cache draws through guides (`guiding`):
        // a pass that gathers from it borrows them (`Lightmaps::guide_at`).
        if let Some(plan) = self
            .refining_plan()
            .filter(|p| p.bound > 0.0 && p.max > p.first)
        {
            self.guides = TexelGuides::recording(&self.maps, &self.owner, self.layers, plan.floor);
        }
        self.probe_crossings(scene);
        let texels = self.layers * self.owned_texels();
        points.reserve(texels + self.crossing_lines.len());
        self.slots.reserve(texels);
        for layer in 0..self.layers {
            for m in &self.maps {
                for i in m.offset..m.offset + m.texels() {
                    if self.owner[i] == NO_INDEX {
                        continue;
                    }
                    points.push(self.texel_point(scene, layer, i, 0, budget));
                    self.slots.push((layer * self.layer_texels + i) as u32);
                }
            }
        }
        self.foot_points(scene, points);
        self.later_samples = budget.map_or(0, |b| {
            (LATER_ROUNDS_GUESS * b as f32 * self.slots.len() as f32) as u64
        });
    }

    /// The feet of crossed texels (module docs, Crossings): estimated once, unfiltered,
    /// with a quarter of the most samples a texel may take (about what a texel takes on
    /// average at the defaults); without a plan, to the estimator's own bound.
    fn foot_points(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        let foot_budget = self.plan.map(|p| (p.max / 4).max(p.first));
        self.feet = vec![Vec3::NAN; self.crossing_lines.len()];
        self.foot_lines.clear();
        for (slot, &c) in self.crossing_slot.iter().enumerate() {
            let foot_site = self
                .probed
                .as_deref()
                .and_then(|p| p.foot_sites.get(c as usize));
            let Some(foot) = foot_site.copied().flatten() else {
                continue;
            };
            let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
            let texel = self.texel_point(scene, layer, i, 0, None);
            // A re-bake keeps the foot's value where the crossing is the same; a foot
            // that was buried (its line settled without one, `crossings::settle_feet`)
            // stays buried unless the stage estimates it.
            let line = self.crossing_lines[c as usize];
            let prior = self
                .prior_feet
                .get(&(slot as u32))
                .and_then(|(old, foot)| line.foot_prior(old, *foot));
            points.push(SamplePoint {
                site: SampleSite::Surface {
                    triangle: self.owner[i],
                    uv: foot,
                    front: layer == 0,
                },
                key: splitmix64(texel.key ^ crossings::FOOT_KEY),
                prior,
                budget: foot_budget,
                cap_share: 1.0,
            });
            self.foot_lines
                .push((c, matches!(prior, Some(Prior::Filled(_)))));
        }
    }

    /// A later round: the texels whose filtered estimate was still above the bound, with
    /// the budgets [`Self::plan_next_round`] gave them.
    pub(super) fn later_round(
        &mut self,
        scene: &TracedScene,
        round: u32,
        points: &mut Vec<SamplePoint>,
    ) {
        for &(slot, budget) in &self.pending {
            let (layer, i) = (
                slot as usize / self.layer_texels,
                slot as usize % self.layer_texels,
            );
            points.push(self.texel_point(scene, layer, i, round, Some(budget)));
            self.slots.push(slot);
        }
        self.pending.clear();
        if self.slots.is_empty() {
            self.emitted = true;
        }
    }

    /// Keeps the estimates of the round's feet (they follow its texels' points).
    pub(super) fn record_feet(&mut self, estimates: &[Estimate]) {
        let foot_estimates = &estimates[self.slots.len().min(estimates.len())..];
        for (&(line, buried), e) in self.foot_lines.iter().zip(foot_estimates) {
            self.foot_samples += e.samples as u64;
            self.feet[line as usize] = if buried && e.samples == 0 {
                Vec3::NAN
            } else {
                crossings::foot_value(e)
            };
        }
        self.foot_lines.clear();
    }

    /// Merges the round's estimates into their texels and marks buried ones (first
    /// estimate of a texel): a buried texel with an exit in its footprint moves there and
    /// starts afresh. Returns the moved slots.
    pub(super) fn merge_round(&mut self, scene: &TracedScene, estimates: &[Estimate]) -> Vec<u32> {
        let total = self.layers * self.layer_texels;
        if self.merged.len() != total {
            self.merged = vec![TexelEstimate::default(); total];
            self.state = vec![Burial::Empty; total];
            // Guides serve the filter alone.
            if self.refining_plan().is_some() {
                self.guide = self.texel_guides(scene);
            }
        }
        let mut moved = Vec::new();
        for (&slot, e) in self.slots.iter().zip(estimates) {
            let slot = slot as usize;
            self.merged[slot].merge(e);
            if matches!(self.state[slot], Burial::Empty | Burial::Moved) {
                // A re-bake's buried texel that the edit did not reach stays buried.
                let kept_buried = Prior::kept_buried(self.priors.get(slot).copied().flatten(), e);
                let buried = e.back_face_share > self.settings.buried_threshold || kept_buried;
                let exit = self
                    .probed
                    .as_deref()
                    .and_then(|p| p.exits.get(slot).copied().flatten());
                self.state[slot] = match (buried, exit, self.state[slot]) {
                    (false, _, _) => Burial::Valid,
                    // Inside a solid, with a visible part of the footprint beyond the
                    // crossing: estimate there instead.
                    (true, Some(uv), Burial::Empty) if self.refining_plan().is_some() => {
                        self.site_uv[slot] = uv;
                        self.merged[slot] = TexelEstimate::default();
                        moved.push(slot as u32);
                        Burial::Moved
                    }
                    _ => Burial::Buried,
                };
            }
        }
        if !moved.is_empty() {
            self.guide = self.texel_guides(scene);
        }
        moved
    }

    /// The next round's slots and budgets: moved texels start with the plan's first
    /// budget, and valid texels whose filtered error is above the bound double their
    /// samples; [`Lightmaps::later_samples`] becomes what reaching the bound would take
    /// beyond that.
    pub(super) fn plan_next_round(
        &mut self,
        plan: Option<SamplingPlan>,
        moved: &[u32],
        filtered: &[(Vec3, Vec3)],
    ) {
        self.pending.clear();
        if let Some(plan) = plan {
            self.pending
                .extend(moved.iter().map(|&slot| (slot, plan.first)));
        }
        self.later_samples = 0;
        if let Some(plan) = plan.filter(|p| p.bound > 0.0) {
            for (slot, (e, (v, s))) in self.merged.iter().zip(filtered).enumerate() {
                if self.state[slot] != Burial::Valid || e.samples == 0 || e.samples >= plan.max {
                    continue;
                }
                let error = plan.relative_error(*v, *s);
                if error > plan.bound {
                    // Double the samples; σ² falls like 1/n, so about n·(C/bound)² in all
                    // would meet the bound: what that needs beyond this round is the
                    // progress report's guess of the later rounds.
                    let more = e.samples.min(plan.max - e.samples);
                    let needed = (e.samples as f32 * (error / plan.bound).powi(2))
                        .min(plan.max as f32) as u64;
                    self.later_samples += needed.saturating_sub((e.samples + more) as u64);
                    self.pending.push((slot as u32, more));
                }
            }
        }
    }
}

/// The random-stream key of a texel: its owner's stable key, the side and the texel
/// coordinates, so that results never depend on scheduling.
fn texel_key(triangle_key: u64, layer: usize, x: u32, y: u32) -> u64 {
    splitmix64(triangle_key ^ splitmix64(((layer as u64) << 62) | ((x as u64) << 31) | y as u64))
}
