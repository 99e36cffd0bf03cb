//! Baking a surface cache: rounds of sample points estimated in parallel, in steps that a
//! caller can spread over frames, cancel, and watch.

use crate::{SamplePoint, SampleSite, SurfaceCache};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::Arc;
use surfcache_core::{color::luminance, sampling::Rng};
use surfcache_trace::{
    Estimate, EstimatorSettings, IrradianceLookup, Sampler, SurfacePoint, TracedScene, estimate,
};

/// The relative-error floor ε is this fraction of the scene's mean irradiance.
pub const FLOOR_FRACTION: f32 = 0.01;

/// The point and ray origin at which `site` is estimated.
///
/// A [`SampleSite::Surface`] uses [`TracedScene::surface_point`] and the leak-guarded
/// [`TracedScene::spawn_origin`]. A [`SampleSite::Vertex`] sits exactly on the vertex, with
/// the vertex normal μ_X (negated for the back side) as both shading and geometric normal
/// and the origin lifted along it by [`TracedScene::spawn_offset`].
pub fn sample_frame(scene: &TracedScene, site: &SampleSite) -> (SurfacePoint, Vec3) {
    match *site {
        SampleSite::Surface {
            triangle,
            uv,
            front,
        } => {
            let p = scene.surface_point(triangle, uv, front);
            let origin = scene.spawn_origin(&p);
            (p, origin)
        }
        SampleSite::Vertex {
            triangle,
            corner,
            front,
        } => {
            let k = corner as usize;
            let sign = if front { 1.0 } else { -1.0 };
            let n = scene.normals[triangle as usize][k] * sign;
            let position = scene.positions[triangle as usize][k];
            let uv = [Vec2::ZERO, Vec2::X, Vec2::Y][k];
            let p = SurfacePoint {
                position,
                triangle,
                uv,
                geometric_normal: n,
                shading_normal: n,
            };
            (p, position + n * scene.spawn_offset())
        }
    }
}

/// Estimates E at one sample point of a cache (with final gathering from `gather` when
/// given: see [`IrradianceLookup`]).
pub fn estimate_point(
    scene: &TracedScene,
    point: &SamplePoint,
    settings: &EstimatorSettings,
    seed: u64,
    gather: Option<&dyn IrradianceLookup>,
) -> Estimate {
    let (p, origin) = sample_frame(scene, &point.site);
    estimate(scene, &p, origin, settings, seed, point.key, gather)
}

/// The scene's mean irradiance (luminance, W/m²) over the front sides of its surfaces,
/// from `points` area-weighted random points with 64 samples each: the scale the
/// relative-error floor ε follows ([`FLOOR_FRACTION`] of it).
pub fn mean_irradiance(scene: &TracedScene, points: u32, seed: u64) -> f32 {
    let areas = scene.area_distribution();
    let settings = EstimatorSettings::fixed(Sampler::Best, 64, None);
    let total: f64 = (0..points)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::new(seed ^ 0xF100_F100, i as u64);
            let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), true);
            let origin = scene.spawn_origin(&p);
            let e = estimate(
                scene,
                &p,
                origin,
                &settings,
                seed,
                u64::MAX - i as u64,
                None,
            );
            luminance(e.value) as f64
        })
        .sum();
    (total / points.max(1) as f64) as f32
}

/// Figures of a bake in progress.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BakeProgress {
    /// Completed rounds.
    pub rounds: u32,
    /// Points estimated so far.
    pub points_done: u64,
    /// Points of the current round still to estimate.
    pub points_pending: u64,
    /// Hemisphere samples and rays so far.
    pub samples: u64,
    pub rays: u64,
    /// Whether the cache has converged.
    pub finished: bool,
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
    round: Vec<SamplePoint>,
    estimates: Vec<Estimate>,
    progress: BakeProgress,
}

impl<C: SurfaceCache> Baker<C> {
    /// A baker for `cache` with per-point estimator `settings` (its `floor` is used as
    /// given: see [`mean_irradiance`]).
    pub fn new(cache: C, settings: EstimatorSettings, seed: u64) -> Self {
        Self {
            cache,
            settings,
            seed,
            gather: None,
            round: Vec::new(),
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

    /// Estimates up to `max_points` points; returns true once the cache has converged.
    pub fn step(&mut self, scene: &TracedScene, max_points: usize) -> bool {
        if self.progress.finished {
            return true;
        }
        if self.estimates.len() == self.round.len() {
            if !self.round.is_empty() {
                self.cache.finish_round(scene, &self.round, &self.estimates);
                self.progress.rounds += 1;
            }
            self.round.clear();
            self.estimates.clear();
            self.cache.next_round(scene, &mut self.round);
            if self.round.is_empty() {
                self.progress.finished = true;
                self.progress.points_pending = 0;
                return true;
            }
        }
        let start = self.estimates.len();
        let end = (start + max_points.max(1)).min(self.round.len());
        let (settings, seed) = (&self.settings, self.seed);
        let gather = self.gather.as_deref().map(|g| g as &dyn IrradianceLookup);
        let batch: Vec<Estimate> = self.round[start..end]
            .par_iter()
            .map(|p| estimate_point(scene, p, settings, seed, gather))
            .collect();
        for e in &batch {
            self.progress.samples += e.samples as u64;
            self.progress.rays += e.rays;
        }
        self.progress.points_done += batch.len() as u64;
        self.estimates.extend(batch);
        self.progress.points_pending = (self.round.len() - self.estimates.len()) as u64;
        false
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
