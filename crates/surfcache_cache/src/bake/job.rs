//! A complete bake ([`BakeJob`]): the scene's brightness floor, bounce passes gathered
//! one bounce at a time, then the final cache; and the progress of such multi-pass jobs.

use super::{BakeProgress, BakeSettings, Baker, FLOOR_FRACTION, fitted_density, mean_irradiance};
use crate::{Cache, CacheSettings, Method, SurfaceCache};
use glam::Vec2;
use std::sync::Arc;
use surfcache_core::{
    color::luminance,
    sampling::{Rng, splitmix64},
};
use surfcache_trace::{EstimatorSettings, TracedScene};

/// Bounce passes are baked at this share of the final cache's density (a quarter of
/// the texels): the light they carry is gathered over whole hemispheres, which smooths it.
pub const BOUNCE_PASS_DENSITY: f32 = 0.5;

/// Bounce passes stop once the energy the final pass would still leave out, predicted
/// from the geometric decay of the energy each pass added, is below this share of the
/// error bound.
pub const BOUNCE_TAIL_SHARE: f32 = 0.25;

/// Random surface points at which [`BakeJob`] compares consecutive bounce passes.
pub const BOUNCE_PROBES: u32 = 16_384;

/// Key of the random streams every bounce pass draws from (the same in each pass).
const BOUNCE_STREAM: u64 = 0x6761_7468_6572;

/// Estimator settings of bounce pass `k` of `method` before a final pass with
/// `final_estimator`: 4× the error bound (at most 10 %), a quarter of the sample limits
/// (at least 16), the limits first capped at `method`'s defaults where the final pass
/// bakes another method ([`CacheSettings::bounce_pass`]).
fn bounce_pass_estimator(
    k: u32,
    method: Method,
    final_estimator: &EstimatorSettings,
    final_method: Method,
) -> EstimatorSettings {
    let (mut min, mut max) = (final_estimator.min_samples, final_estimator.max_samples);
    if method != final_method {
        let (lo, hi) = method.default_sample_range();
        (min, max) = (min.min(lo), max.min(hi));
    }
    EstimatorSettings {
        max_rel_error: (final_estimator.max_rel_error * 4.0).min(0.1),
        min_samples: (min / 4).max(16),
        max_samples: (max / 4).max(16),
        // Pass 0 is direct light alone; later passes end every path at its first hit.
        max_bounces: if k == 0 {
            Some(0)
        } else {
            final_estimator.max_bounces
        },
        ..*final_estimator
    }
}

/// Irradiance maps bounce through a lightmap when more than this share of the triangles
/// is no longer than a sample spacing ([`CacheSettings::bounce_pass`]).
pub const FINE_MESH_SHARE: f32 = 0.5;

/// Where a [`BakeJob`] is.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JobProgress {
    /// Pass being baked (0-based) and the number of passes (bounce passes + the final
    /// one; while bounce passes run, the most there may be).
    pub pass: u32,
    pub passes: u32,
    /// The current pass's progress.
    pub current: BakeProgress,
    /// Samples and rays over all passes.
    pub samples: u64,
    pub rays: u64,
    /// Whether the final cache is complete.
    pub finished: bool,
    /// Expected work in units of the final pass, or in samples once the final pass can
    /// tell the samples it still needs (0 where a job does not weigh its passes: they
    /// then count alike): of the passes finished, of the running one, and of all passes
    /// including those still to come.
    pub work_done: f32,
    pub work_running: f32,
    pub work_total: f32,
    /// Whether the work still to come is known (the running pass can tell its samples,
    /// and the passes after it are weighed right), so that a time left derived from
    /// [`Self::fraction`] is an estimate rather than a lower bound.
    pub work_known: bool,
    /// Samples the job still needs, where it can tell them: its final pass runs and
    /// forecasts its rounds. Samples differ in cost between passes and rounds, so a time
    /// left is best taken from the recent rate of samples (the ECS plugin's `BakeStatus`
    /// does).
    pub samples_left: Option<u64>,
}

impl JobProgress {
    /// Share of the job done: finished passes and the running pass' share of its own
    /// work ([`BakeProgress::fraction`]), each pass weighed by its expected work.
    ///
    /// ```
    /// use surfcache_cache::bake::{BakeProgress, JobProgress};
    /// let p = JobProgress {
    ///     pass: 1,
    ///     passes: 2,
    ///     current: BakeProgress { samples: 30, samples_pending: Some(10), ..Default::default() },
    ///     work_done: 0.25,
    ///     work_running: 1.0,
    ///     work_total: 1.25,
    ///     ..Default::default()
    /// };
    /// assert!((p.fraction() - 0.8).abs() < 1e-6);
    /// ```
    pub fn fraction(&self) -> f32 {
        if self.finished {
            return 1.0;
        }
        let running = self.current.fraction();
        let f = if self.work_total > 0.0 {
            (self.work_done + self.work_running * running) / self.work_total
        } else {
            (self.pass as f32 + running) / self.passes.max(1) as f32
        };
        f.clamp(0.0, 1.0)
    }

    /// These figures of finished passes together with pass `pass` running in `baker`.
    pub(crate) fn with_running<C: SurfaceCache>(
        mut self,
        pass: u32,
        baker: Option<&Baker<C>>,
    ) -> Self {
        if let Some(b) = baker {
            self.pass = pass;
            self.current = *b.progress();
            self.samples += self.current.samples;
            self.rays += self.current.rays;
            self.work_known = self.current.samples_pending.is_some();
        }
        self
    }
}

/// Set (to anything) in the environment, every finished pass of a [`BakeJob`] or an
/// incremental re-bake prints one line to stderr: its points, samples, rays and rounds
/// (where a bake's time goes; docs/results.md uses it).
pub const TRACE_PASSES_VAR: &str = "SURFCACHE_TRACE_PASSES";

/// Steps pass `pass` of a multi-pass job, running in `baker`, by up to `max_points`
/// points; once it finishes, takes it out of `baker`, adds its figures to `done` and
/// returns its cache.
pub(crate) fn step_pass<C: SurfaceCache>(
    baker: &mut Option<Baker<C>>,
    scene: &TracedScene,
    max_points: usize,
    pass: u32,
    done: &mut JobProgress,
) -> Option<C> {
    if !baker.as_mut()?.step(scene, max_points) {
        return None;
    }
    let b = baker.take()?;
    let p = *b.progress();
    if std::env::var_os(TRACE_PASSES_VAR).is_some() {
        eprintln!(
            "[pass {pass}] points {} traced {} samples {} rays {} rounds {}",
            p.points_done, p.points_traced, p.samples, p.rays, p.rounds
        );
    }
    done.samples += p.samples;
    done.rays += p.rays;
    done.pass = pass;
    done.current = p;
    Some(b.into_cache())
}

/// The caches of every pass of a finished bake (pre-passes first, the final cache last)
/// and the settings it used (floor filled in): what an incremental re-bake starts from.
#[derive(Clone)]
pub struct BakeOutcome {
    pub passes: Vec<Arc<Cache>>,
    pub settings: BakeSettings,
    pub progress: JobProgress,
}

impl BakeOutcome {
    /// The final cache.
    pub fn cache(&self) -> &Arc<Cache> {
        self.passes
            .last()
            .expect("a bake has at least its final pass")
    }
}

/// A complete bake: the scene-brightness floor, then *bounce passes*, then the requested
/// cache (docs/design.md, "Baking").
///
/// Light is gathered one bounce at a time (final gathering, Jensen 1996; a Jacobi
/// iteration of the rendering equation over the cache): pass 0 bakes direct light alone
/// (emission, the environment, punctual lights, next-event estimation, no reflection);
/// every later pass ends its paths at their first hit y with
/// `L = L_e(y) + ρ/π · E_prev(y)` from the pass before
/// ([`IrradianceLookup`](surfcache_trace::IrradianceLookup)), so it holds one bounce
/// more, and a sample costs one bounce ray plus a shadow ray instead of a whole path.
/// Bounce passes bake lightmaps (vertex lighting for vertex lighting) at
/// [`BOUNCE_PASS_DENSITY`] of the final density ([`CacheSettings::bounce_pass`]) and a looser error
/// bound ([`bounce_pass_estimator`]); their noise reaches the final cache only averaged
/// over the hemispheres that gather it.
///
/// Every bounce pass draws the same random streams (*common random numbers*): a texel's
/// samples take the same directions in pass k as in pass k − 1, so the two passes differ
/// by the bounce pass k added and hardly by their noise. After every bounce pass k ≥ 1
/// the light it added, `a_k = mean (Y_k − Y_{k−1}) / (Y_k + ε)` (luminance of both caches
/// at the [`BOUNCE_PROBES`] random surface points that pass k lights above ε, each point's
/// share of its own irradiance, so that a gallery lit only by bounces counts as much as a
/// sunlit wall), is compared with the pass before: the series decays like
/// `r = a_k / a_{k−1}`, so the final pass (one more bounce) leaves out about
/// `a_k r² / (1 − r)` of a typical point's irradiance. Bounce passes stop once that is below
/// [`BOUNCE_TAIL_SHARE`] of the error bound, after `--bounces` passes, or after
/// [`BakeSettings::gather_passes`] passes; the final pass then gathers from the last. The
/// bias this leaves is that predicted tail (measured in docs/results.md against full
/// paths). `gather_passes = 0` traces every path of the final pass to its end (Russian
/// roulette, the thesis' model).
///
/// Re-bakes after an edit are [`crate::incremental::IncrementalJob`]s.
pub struct BakeJob {
    settings: BakeSettings,
    baker: Option<Baker<Cache>>,
    /// Whether the running pass is the final one.
    final_pass: bool,
    floor: Option<f32>,
    done: JobProgress,
    passes: Vec<Arc<Cache>>,
    /// Energy each finished bounce pass added (`a_k`, module docs).
    added: Vec<f64>,
    probes: Vec<(u32, Vec2, bool)>,
    /// The settings and an unbaked copy of the last cache laid out: bounce passes share
    /// one layout (a Sponza atlas takes seconds to make).
    layout: Option<(CacheSettings, Cache)>,
    /// The cache of the bounce passes ([`CacheSettings::bounce_pass`]), once chosen.
    bounce_cache: Option<CacheSettings>,
}

impl BakeJob {
    pub fn new(settings: BakeSettings) -> Self {
        Self {
            settings,
            baker: None,
            final_pass: false,
            floor: (settings.estimator.floor > 0.0).then_some(settings.estimator.floor),
            done: JobProgress {
                passes: settings
                    .gather_passes
                    .min(settings.estimator.max_bounces.unwrap_or(u32::MAX))
                    + 1,
                ..Default::default()
            },
            passes: Vec::new(),
            added: Vec::new(),
            probes: Vec::new(),
            layout: None,
            bounce_cache: None,
        }
    }

    /// The absolute floor ε of the relative errors (known after the first step).
    pub fn floor(&self) -> Option<f32> {
        self.floor
    }

    /// The settings, with the floor filled in once known.
    pub fn settings(&self) -> BakeSettings {
        let mut s = self.settings;
        if let Some(f) = self.floor {
            s.estimator.floor = f;
            // Only irradiance maps bound a relative error of their own.
            if let CacheSettings::IrradianceMap(m) = &mut s.cache {
                m.floor = f;
            }
        }
        s
    }

    /// Bounce passes this bake may run at most (`gather_passes`, and `--bounces` of them).
    fn most_bounce_passes(&self) -> u32 {
        let s = &self.settings;
        s.gather_passes
            .min(s.estimator.max_bounces.unwrap_or(u32::MAX))
    }

    /// Whether the bounce series has converged after the passes so far (module docs).
    fn bounces_converged(&self) -> bool {
        let k = self.added.len();
        if k < 2 {
            return false;
        }
        let (a, before) = (self.added[k - 1].max(0.0), self.added[k - 2].max(0.0));
        let r = if before > 0.0 {
            (a / before).min(0.95)
        } else {
            0.0
        };
        let tail = a * r * r / (1.0 - r);
        tail <= (BOUNCE_TAIL_SHARE * self.settings.estimator.max_rel_error) as f64
    }

    fn start_pass(&mut self, scene: &TracedScene) {
        let s = self.settings();
        let k = self.passes.len() as u32;
        self.final_pass = k >= self.most_bounce_passes() || self.bounces_converged();
        let (cache_settings, estimator) = if self.final_pass {
            let mut estimator = s.estimator;
            if k > 0 {
                // Gathering ends every path at its first hit: the bounces are in the passes.
                estimator.max_bounces = None;
            }
            (s.cache, estimator)
        } else {
            let cache = *self
                .bounce_cache
                .get_or_insert_with(|| s.cache.bounce_pass(scene));
            let estimator =
                bounce_pass_estimator(k, cache.method(), &s.estimator, s.cache.method());
            (cache, estimator)
        };
        // Bounce passes draw from streams of their own, the same stream in every bounce
        // pass (module docs: common random numbers).
        let seed = if self.final_pass {
            s.seed
        } else {
            s.seed ^ splitmix64(BOUNCE_STREAM)
        };
        let cache = match self.layout.take() {
            Some((settings, fresh)) if settings == cache_settings => fresh,
            _ => Cache::new(scene, &cache_settings),
        };
        if !self.final_pass {
            self.layout = Some((cache_settings, cache.clone()));
        }
        let mut baker = Baker::new(cache, estimator, seed);
        if let Some(prev) = self.passes.last().cloned() {
            baker = baker.with_gather(prev);
        }
        self.done.passes = if self.final_pass {
            k + 1
        } else {
            self.most_bounce_passes() + 1
        };
        self.baker = Some(baker);
    }

    /// Random surface points (both sides where the cache bakes both) at which bounce
    /// passes are compared, by area.
    fn probe_points(&mut self, scene: &TracedScene) {
        if !self.probes.is_empty() || scene.triangle_count() == 0 {
            return;
        }
        let areas = scene.area_distribution();
        let both = self.settings.cache.both_sides();
        let mut rng = Rng::new(self.settings.seed ^ 0x0098_06e5, 0);
        self.probes = (0..BOUNCE_PROBES)
            .map(|_| {
                let (t, _, _) = areas.sample(rng.next_f32());
                let uv = surfcache_core::sampling::uniform_triangle(rng.next_vec2());
                let front = !both || rng.next_f32() < 0.5;
                (t as u32, uv, front)
            })
            .collect();
    }

    /// `a_k` of the pass just finished (module docs): the mean over the probes that the
    /// pass lights (above the floor ε) of the share of their light it added.
    fn energy_added(&self) -> f64 {
        let k = self.passes.len();
        let Some(latest) = self.passes.last() else {
            return 0.0;
        };
        let before = k.checked_sub(2).map(|p| &self.passes[p]);
        let floor = self.floor.unwrap_or(0.0) as f64;
        let (mut sum, mut count) = (0.0f64, 0u32);
        for &(t, uv, front) in &self.probes {
            let now = luminance(latest.lookup(t, uv, front)) as f64;
            let was = before.map_or(0.0, |b| luminance(b.lookup(t, uv, front)) as f64);
            if now.is_finite() && was.is_finite() && now > floor {
                sum += (now - was) / (now + floor);
                count += 1;
            }
        }
        sum / count.max(1) as f64
    }

    /// Estimates up to `max_points` points (the first call of a fresh bake measures the
    /// scene's brightness instead); returns true once the final cache is complete.
    pub fn step(&mut self, scene: &TracedScene, max_points: usize) -> bool {
        if self.done.finished {
            return true;
        }
        if self.floor.is_none() {
            // The budget fits the density of caches that have one (not vertex lighting).
            if let (Some(budget), Some(density)) = (
                self.settings.density_budget,
                self.settings.cache.density_mut(),
            ) {
                let area = scene.area_distribution().total();
                *density = fitted_density(*density, area, budget);
                self.settings.density_budget = None;
            }
            let mean = mean_irradiance(scene, 512, self.settings.seed);
            self.floor = Some((FLOOR_FRACTION * mean).max(f32::MIN_POSITIVE));
            return false;
        }
        if self.baker.is_none() {
            self.probe_points(scene);
            self.start_pass(scene);
        }
        let pass = self.passes.len() as u32;
        let Some(cache) = step_pass(&mut self.baker, scene, max_points, pass, &mut self.done)
        else {
            return false;
        };
        // Later passes on the same layout take this pass' probes instead of probing again.
        if let Some((_, layout)) = &mut self.layout {
            layout.adopt_probes(&cache);
        }
        self.passes.push(Arc::new(cache));
        if self.final_pass {
            self.done.finished = true;
            return true;
        }
        let a = self.energy_added();
        if std::env::var_os(TRACE_PASSES_VAR).is_some() {
            eprintln!("[pass {pass}] energy added {:.5}", a);
        }
        self.added.push(a);
        false
    }

    /// Progress so far, passes weighed by their expected work: a bounce pass
    /// [`Self::bounce_pass_work`] of the final one, and one more bounce pass expected
    /// after the running one until the series converges or the passes run out. Once the
    /// final pass can tell the samples it still needs, every pass weighs its samples
    /// (the guess of a bounce pass' share is far off where the final cache is not a
    /// lightmap: docs/results.md, "Progress of irradiance maps").
    pub fn progress(&self) -> JobProgress {
        let mut p = self
            .done
            .with_running(self.passes.len() as u32, self.baker.as_ref());
        if let Some(pending) = p.current.samples_pending.filter(|_| self.final_pass) {
            p.work_done = (p.samples - p.current.samples) as f32;
            p.work_running = (p.current.samples + pending) as f32;
            p.work_total = p.work_done + p.work_running;
            p.samples_left = Some(pending);
            return p;
        }
        // Only a lightmap's final pass is weighed right before it runs.
        p.work_known &= self.final_pass || self.settings.cache.method() == Method::Lightmap;
        let bounce = self.bounce_pass_work();
        let finished = self.passes.len() as f32;
        p.work_done = finished * bounce;
        p.work_running = if self.final_pass { 1.0 } else { bounce };
        let to_come = if self.final_pass {
            0.0
        } else {
            let more = (self.passes.len() as u32 + 1) < self.most_bounce_passes();
            1.0 + if more { bounce } else { 0.0 }
        };
        p.work_total = p.work_done + p.work_running + to_come;
        p
    }

    /// A bounce pass' work relative to the final pass: its share of the final cache's
    /// points ([`BOUNCE_PASS_DENSITY`]² where the cache has a density) times its share of
    /// the samples per point ([`bounce_pass_estimator`]).
    fn bounce_pass_work(&self) -> f32 {
        let s = &self.settings;
        let points = match s.cache.density() {
            Some(_) => BOUNCE_PASS_DENSITY * BOUNCE_PASS_DENSITY,
            None => 1.0,
        };
        let bounce_method = self.bounce_cache.map_or(s.cache.method(), |c| c.method());
        let bounce = bounce_pass_estimator(1, bounce_method, &s.estimator, s.cache.method());
        let samples = bounce.min_samples.max(1) as f32 / s.estimator.min_samples.max(1) as f32;
        points * samples.min(1.0)
    }

    /// Every pass's cache and the settings, once [`Self::step`] returned true.
    pub fn into_outcome(self) -> Option<BakeOutcome> {
        let settings = self.settings();
        self.done.finished.then_some(BakeOutcome {
            passes: self.passes,
            settings,
            progress: self.done,
        })
    }
}
