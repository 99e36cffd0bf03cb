//! The baker of one cache: rounds of sample points, estimated in parallel in steps of a
//! bounded number of points.

use super::{Previous, estimate_point};
use crate::{SamplePoint, SampleSite, SurfaceCache};
use rayon::prelude::*;
use std::sync::Arc;
use surfcache_trace::{Estimate, EstimatorSettings, IrradianceLookup, TracedScene};

/// Figures of a bake in progress.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BakeProgress {
    /// Completed rounds.
    pub rounds: u32,
    /// Points estimated so far.
    pub points_done: u64,
    /// Points whose estimates traced rays (in a re-bake, the points it touched; the
    /// others kept their value).
    pub points_traced: u64,
    /// Points of the current round still to estimate.
    pub points_pending: u64,
    /// Hemisphere samples and rays so far.
    pub samples: u64,
    pub rays: u64,
    /// Samples still to take, as far as they can be told: the budgets of the current
    /// round's pending points (points without a budget at the samples per point of the
    /// latest rounds) and what the cache expects of later rounds
    /// ([`SurfaceCache::later_samples`]); `None` where either is unknown.
    pub samples_pending: Option<u64>,
    /// Whether the cache has converged.
    pub finished: bool,
}

impl BakeProgress {
    /// Share of the bake done: by samples where the samples still to take are known
    /// (a lightmap's later rounds hold most of its work in few points), else by points
    /// of the current round.
    pub fn fraction(&self) -> f32 {
        if self.finished {
            return 1.0;
        }
        let (done, left) = match self.samples_pending {
            Some(pending) => (self.samples, pending),
            None => (self.points_done, self.points_pending),
        };
        (done as f64 / (done + left).max(1) as f64) as f32
    }
}

/// Drives a [`SurfaceCache`] through its rounds. [`Baker::step`] estimates a bounded
/// number of pending points (in parallel on the current rayon pool); results are
/// identical however the work is split into steps, because every point has its own
/// random stream.
pub struct Baker<C: SurfaceCache> {
    cache: C,
    settings: EstimatorSettings,
    seed: u64,
    gather: Option<Arc<dyn IrradianceLookup + Send>>,
    previous: Option<Previous>,
    round: Vec<SamplePoint>,
    /// Sample budgets of the round's points not estimated yet (`None` if one has none).
    round_budget: Option<u64>,
    /// Samples and points of the pass when the running round began, and when the round
    /// before it began.
    round_start: (u64, u64),
    last_round_start: (u64, u64),
    estimates: Vec<Estimate>,
    progress: BakeProgress,
}

impl<C: SurfaceCache> Baker<C> {
    /// A baker for `cache` with per-point estimator `settings` (its `floor` is used as
    /// given: see [`mean_irradiance`]).
    pub fn new(mut cache: C, settings: EstimatorSettings, seed: u64) -> Self {
        cache.plan_sampling(&settings);
        Self {
            cache,
            settings,
            seed,
            gather: None,
            previous: None,
            round: Vec::new(),
            round_budget: None,
            round_start: (0, 0),
            last_round_start: (0, 0),
            estimates: Vec::new(),
            progress: BakeProgress::default(),
        }
    }

    /// Ends every path at its first hit with the irradiance `lookup` gives there (final
    /// gathering from a finished coarser cache, see [`IrradianceLookup`]).
    pub fn with_gather(mut self, lookup: Arc<dyn IrradianceLookup + Send>) -> Self {
        self.gather = Some(lookup);
        self
    }

    /// Updates points that carry a prior value by their change since `previous` (an
    /// incremental re-bake of a remapped cache, see [`SurfaceCache::remap`]).
    pub fn with_previous(mut self, previous: Previous) -> Self {
        self.previous = Some(previous);
        self
    }

    /// Estimates up to `max_points` points; returns true once the cache has converged.
    pub fn step(&mut self, scene: &TracedScene, max_points: usize) -> bool {
        if self.progress.finished {
            return true;
        }
        if self.estimates.len() == self.round.len() && !self.start_round(scene) {
            return true;
        }
        let start = self.estimates.len();
        let end = (start + max_points.max(1)).min(self.round.len());
        let batch = self.estimate_batch(scene, start, end);
        self.record_batch(batch, start, end);
        false
    }

    /// Hands the finished round (if any) to the cache and asks it for the next; false
    /// once the cache asks for no more points (it has converged).
    fn start_round(&mut self, scene: &TracedScene) -> bool {
        if !self.round.is_empty() {
            self.cache.finish_round(scene, &self.round, &self.estimates);
            self.progress.rounds += 1;
            self.last_round_start = self.round_start;
        }
        self.round_start = (self.progress.samples, self.progress.points_done);
        self.round.clear();
        self.estimates.clear();
        self.cache.next_round(scene, &mut self.round);
        self.round_budget = self
            .round
            .iter()
            .map(|p| p.budget.map(u64::from))
            .sum::<Option<u64>>();
        if self.round.is_empty() {
            self.progress.finished = true;
            self.progress.points_pending = 0;
            return false;
        }
        true
    }

    /// Estimates the round's points `start..end` in parallel: a point with a prior by its
    /// change since the edit ([`Previous::update`]), any other afresh.
    fn estimate_batch(&self, scene: &TracedScene, start: usize, end: usize) -> Vec<Estimate> {
        let (settings, seed) = (&self.settings, self.seed);
        let gather = self.gather.as_deref().map(|g| g as &dyn IrradianceLookup);
        let previous = self.previous.as_ref();
        let cache = &self.cache;
        let borrows = cache.borrows_guides();
        self.round[start..end]
            .par_iter()
            .enumerate()
            .map(|(j, p)| {
                previous
                    .and_then(|prev| prev.update(scene, p, settings, seed, gather))
                    .unwrap_or_else(|| {
                        let i = start + j;
                        let (mut guidance, buried) = (cache.guidance(i), cache.buried_share(i));
                        // No guide of its own yet: the gathered pass's, where it learnt one.
                        let borrowed = match (gather, p.site) {
                            (
                                Some(g),
                                SampleSite::Surface {
                                    triangle,
                                    uv,
                                    front,
                                },
                            ) if borrows && guidance.guide.is_none() => {
                                g.guide(triangle, uv, front)
                            }
                            _ => None,
                        };
                        if borrowed.is_some() {
                            guidance.guide = borrowed.as_ref();
                        }
                        estimate_point(scene, p, settings, seed, gather, guidance, buried)
                    })
            })
            .collect()
    }

    /// Keeps the estimates of the round's points `start..end` and counts them in the
    /// progress.
    fn record_batch(&mut self, batch: Vec<Estimate>, start: usize, end: usize) {
        for e in &batch {
            self.progress.samples += e.samples as u64;
            self.progress.rays += e.rays;
            self.progress.points_traced += (e.rays > 0) as u64;
        }
        self.progress.points_done += batch.len() as u64;
        self.estimates.extend(batch);
        self.progress.points_pending = (self.round.len() - self.estimates.len()) as u64;
        if let Some(left) = &mut self.round_budget {
            *left -= self.round[start..end]
                .iter()
                .map(|p| p.budget.unwrap_or(0) as u64)
                .sum::<u64>();
        }
        let per_point = self.recent_mean();
        let round = self
            .round_budget
            .unwrap_or((self.progress.points_pending as f64 * per_point) as u64);
        self.progress.samples_pending = self
            .cache
            .later_samples(per_point)
            .map(|later| later + round);
    }

    /// Samples per point of the round before the running one and of the running one so
    /// far: what a point without a budget is expected to take (later rounds sample
    /// where earlier ones found detail, which takes other samples than the first round's;
    /// the running round's first points lie in one place and alone would mislead).
    fn recent_mean(&self) -> f64 {
        let samples = self.progress.samples - self.last_round_start.0;
        let points = self.progress.points_done - self.last_round_start.1;
        samples as f64 / points.max(1) as f64
    }

    /// Runs to convergence; `on_step` sees the progress after every step of
    /// `points_per_step` points and may return false to cancel (then `None`).
    pub fn run(
        mut self,
        scene: &TracedScene,
        points_per_step: usize,
        mut on_step: impl FnMut(&BakeProgress) -> bool,
    ) -> Option<C> {
        while !self.step(scene, points_per_step) {
            if !on_step(&self.progress) {
                return None;
            }
        }
        on_step(&self.progress);
        Some(self.cache)
    }

    /// Progress so far.
    pub fn progress(&self) -> &BakeProgress {
        &self.progress
    }

    /// The cache (complete once [`Self::step`] returned true).
    pub fn cache(&self) -> &C {
        &self.cache
    }

    /// Takes the cache out.
    pub fn into_cache(self) -> C {
        self.cache
    }
}

/// Bakes `cache` to convergence on the current rayon pool (a convenience for tests and
/// tools; the ECS plugin and the CLI step a [`Baker`] themselves).
pub fn bake_to_convergence<C: SurfaceCache>(
    scene: &TracedScene,
    cache: C,
    settings: &EstimatorSettings,
    seed: u64,
) -> C {
    let mut baker = Baker::new(cache, *settings, seed);
    while !baker.step(scene, 4096) {}
    baker.into_cache()
}
