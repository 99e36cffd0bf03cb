//! Baking a surface cache: rounds of sample points estimated in parallel, in steps that a
//! caller can spread over frames, cancel, and watch.

use crate::{
    Cache, CacheSettings, Method, SamplePoint, SampleSite, SurfaceCache, UNMAPPED,
    incremental::{ChangePlan, INDIRECT_SKIP_SHARE},
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use surfcache_core::{
    color::luminance,
    sampling::{Cone, Rng, splitmix64},
};
use surfcache_trace::{
    Estimate, EstimatorSettings, Guidance, IrradianceLookup, PointInScene, Sampler, SurfacePoint,
    TracedScene, estimate, estimate_change, unchanged,
};

/// The relative-error floor ε is this fraction of the scene's mean irradiance (defined by
/// the estimator, which also takes ε / `FLOOR_FRACTION` as the scale of light an all-zero
/// run of samples may have missed: [`surfcache_trace::ZERO_RUN_EVENTS`]).
pub use surfcache_trace::FLOOR_FRACTION;

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

/// `site` of an edited scene `new` as the scene `old` before the edit had it (same
/// barycentrics on the corresponding triangle, the same mesh vertex for vertex sites);
/// `None` for a site without a counterpart.
pub fn map_site(
    old: &TracedScene,
    new: &TracedScene,
    site: &SampleSite,
    triangle_map: &[u32],
) -> Option<SampleSite> {
    match *site {
        SampleSite::Surface {
            triangle,
            uv,
            front,
        } => {
            let t = *triangle_map.get(triangle as usize)?;
            (t != UNMAPPED).then_some(SampleSite::Surface {
                triangle: t,
                uv,
                front,
            })
        }
        SampleSite::Vertex {
            triangle,
            corner,
            front,
        } => {
            let t = *triangle_map.get(triangle as usize)?;
            if t == UNMAPPED {
                return None;
            }
            let vertex = new.vertex_indices[triangle as usize][corner as usize];
            let corner = old.vertex_indices[t as usize]
                .iter()
                .position(|&v| v == vertex)? as u8;
            Some(SampleSite::Vertex {
                triangle: t,
                corner,
                front,
            })
        }
    }
}

/// The scene before an edit, for incremental re-bakes: sample points that carry a
/// [`SamplePoint::prior`] are updated by the change between it and the edited scene
/// ([`surfcache_trace::estimate_change`]).
#[derive(Clone)]
pub struct Previous {
    pub scene: Arc<TracedScene>,
    /// `triangle_map[t_new]`: the corresponding triangle of `scene` ([`crate::triangle_map`]).
    pub triangle_map: Arc<Vec<u32>>,
    /// The gathering lookup the pass used before the edit.
    pub gather: Option<Arc<dyn IrradianceLookup + Send>>,
    /// A sphere (centre, radius) holding every surface the edit changed: changes are then
    /// integrated over the cone of directions towards it only.
    pub focus: Option<(Vec3, f32)>,
    /// A bound on the change (indirect stages of a re-bake): points it proves unchanged
    /// keep their value, the others integrate over the cone it gives
    /// ([`crate::incremental::ChangeBound::plan`]).
    pub bound: Option<Arc<crate::incremental::ChangeBound>>,
}

/// Estimates E at one sample point of a cache (with final gathering from `gather` when
/// given: see [`IrradianceLookup`]), guided as the cache says.
pub fn estimate_point(
    scene: &TracedScene,
    point: &SamplePoint,
    settings: &EstimatorSettings,
    seed: u64,
    gather: Option<&dyn IrradianceLookup>,
    guidance: Guidance,
) -> Estimate {
    let (p, origin) = sample_frame(scene, &point.site);
    let at = PointInScene::new(scene, p, origin)
        .with_gather(gather)
        .with_guidance(guidance);
    match point.budget {
        Some(n) => {
            let fixed = EstimatorSettings {
                max_rel_error: 0.0,
                min_samples: n,
                max_samples: n,
                ..*settings
            };
            estimate(&at, &fixed, seed, point.key)
        }
        None => estimate(&at, settings, seed, point.key),
    }
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
                &PointInScene::new(scene, p, origin),
                &settings,
                seed,
                u64::MAX - i as u64,
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
    /// Samples still to take, as far as they can be told: the budgets of the current
    /// round's pending points and what the cache expects of later rounds
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
        if self.estimates.len() == self.round.len() {
            if !self.round.is_empty() {
                self.cache.finish_round(scene, &self.round, &self.estimates);
                self.progress.rounds += 1;
            }
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
                return true;
            }
        }
        let start = self.estimates.len();
        let end = (start + max_points.max(1)).min(self.round.len());
        let (settings, seed) = (&self.settings, self.seed);
        let gather = self.gather.as_deref().map(|g| g as &dyn IrradianceLookup);
        let previous = self.previous.as_ref();
        let cache = &self.cache;
        let batch: Vec<Estimate> = self.round[start..end]
            .par_iter()
            .enumerate()
            .map(|(j, p)| {
                let change = previous.zip(p.prior).and_then(|(prev, prior)| {
                    let old_site = map_site(&prev.scene, scene, &p.site, &prev.triangle_map)?;
                    Some((prev, prior, old_site))
                });
                match change {
                    Some((prev, prior, old_site)) => {
                        let (new_point, new_origin) = sample_frame(scene, &p.site);
                        let (old_point, old_origin) = sample_frame(&prev.scene, &old_site);
                        let new =
                            PointInScene::new(scene, new_point, new_origin).with_gather(gather);
                        let old = PointInScene::new(&prev.scene, old_point, old_origin)
                            .with_gather(
                                prev.gather.as_deref().map(|g| g as &dyn IrradianceLookup),
                            );
                        let focus = match &prev.bound {
                            Some(bound) => {
                                let allowance = INDIRECT_SKIP_SHARE
                                    * settings.max_rel_error
                                    * (prior.min_element().max(0.0) + settings.floor);
                                match bound.plan(new_origin, new_point.geometric_normal, allowance)
                                {
                                    ChangePlan::Unchanged => return unchanged(prior, settings),
                                    ChangePlan::Cone(cone) => Some(cone),
                                    ChangePlan::Hemisphere => None,
                                }
                            }
                            None => prev
                                .focus
                                .map(|(c, r)| Cone::towards_sphere(new_origin, c, r)),
                        };
                        estimate_change(&old, &new, prior, settings, seed, p.key, focus.as_ref())
                    }
                    None => {
                        estimate_point(scene, p, settings, seed, gather, cache.guidance(start + j))
                    }
                }
            })
            .collect();
        for e in &batch {
            self.progress.samples += e.samples as u64;
            self.progress.rays += e.rays;
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
        self.progress.samples_pending = self
            .round_budget
            .zip(self.cache.later_samples())
            .map(|(round, later)| round + later);
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

/// Everything a bake needs besides the scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeSettings {
    /// The cache to bake and its own settings.
    pub cache: CacheSettings,
    /// Per-point estimation; a `floor` of 0 is replaced by [`FLOOR_FRACTION`] of the
    /// scene's mean irradiance ([`mean_irradiance`]).
    pub estimator: EstimatorSettings,
    pub seed: u64,
    /// Most bounce passes before the final one (0: no passes, every path of the final
    /// pass is traced to its end). See [`BakeJob`].
    pub gather_passes: u32,
    /// Lower the cache's density for large scenes so that one side of all surfaces holds
    /// about this many samples or texels ([`fitted_density`]); `None` keeps the density
    /// as set.
    #[serde(default)]
    pub density_budget: Option<u64>,
}

impl Default for BakeSettings {
    fn default() -> Self {
        let method = Method::default();
        let (min_samples, max_samples) = method.default_sample_range();
        Self {
            cache: CacheSettings::for_method(method),
            estimator: EstimatorSettings {
                floor: 0.0,
                min_samples,
                max_samples,
                ..Default::default()
            },
            seed: 0,
            gather_passes: DEFAULT_GATHER_PASSES,
            density_budget: Some(DEFAULT_DENSITY_BUDGET),
        }
    }
}

/// Samples or texels on one side of a scene's surfaces by default: 2¹⁹, 8 texels per
/// metre over a level of 8,000 m² (Crytek Sponza), the caches' full density (64 per
/// metre) on scenes up to 128 m².
pub const DEFAULT_DENSITY_BUDGET: u64 = 1 << 19;

/// The coarsest density (samples or texels per metre) a budget may lower a cache to:
/// texels of 12.5 cm, what game levels are lightmapped at.
pub const MIN_FITTED_DENSITY: f32 = 8.0;

/// The density a bake at `density` per metre uses on a scene whose surfaces have `area`
/// m² (one side) within `budget` samples: `min(density, max(MIN, sqrt(budget / area)))`.
pub fn fitted_density(density: f32, area: f64, budget: u64) -> f32 {
    if area.is_nan() || area <= 0.0 {
        return density;
    }
    let fit = (budget as f64 / area).sqrt() as f32;
    density.min(fit.max(MIN_FITTED_DENSITY))
}

/// Most bounce passes before the final one by default: enough for the bounce series of
/// any scene whose surfaces reflect at most about 75 % of the light (0.75^16 ≈ 1 %);
/// passes normally stop earlier, once the series has converged ([`BakeJob`]).
pub const DEFAULT_GATHER_PASSES: u32 = 16;

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

/// Estimator settings of a bounce pass before a final pass with `final_estimator`: 4×
/// the error bound (at most 10 %), a quarter of the sample limits (at least 16).
fn bounce_pass_estimator(k: u32, final_estimator: &EstimatorSettings) -> EstimatorSettings {
    EstimatorSettings {
        max_rel_error: (final_estimator.max_rel_error * 4.0).min(0.1),
        min_samples: (final_estimator.min_samples / 4).max(16),
        max_samples: (final_estimator.max_samples / 4).max(16),
        // Pass 0 is direct light alone; later passes end every path at its first hit.
        max_bounces: if k == 0 {
            Some(0)
        } else {
            final_estimator.max_bounces
        },
        ..*final_estimator
    }
}

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
    /// Expected work in units of the final pass (0 where a job does not weigh its
    /// passes: they then count alike): of the passes finished, of the running one, and
    /// of all passes including those still to come.
    pub work_done: f32,
    pub work_running: f32,
    pub work_total: f32,
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
            "[pass {pass}] points {} samples {} rays {} rounds {}",
            p.points_done, p.samples, p.rays, p.rounds
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
/// `L = L_e(y) + ρ/π · E_prev(y)` from the pass before ([`IrradianceLookup`]), so it holds
/// one bounce more, and a sample costs one bounce ray plus a shadow ray instead of a
/// whole path. Bounce passes bake the final method at [`BOUNCE_PASS_DENSITY`] and a
/// looser error bound ([`bounce_pass_estimator`]); their noise reaches the final cache
/// only averaged over the hemispheres that gather it.
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
            s.cache.set_floor(f);
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
            let mut cache = s.cache;
            cache.scale_density(BOUNCE_PASS_DENSITY);
            // A bounce pass reaches the final cache only through gathers over whole
            // hemispheres, which average its noise: guiding would cost more than it buys.
            cache.disable_guiding();
            (cache, bounce_pass_estimator(k, &s.estimator))
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
            if let (Some(budget), Some(density)) =
                (self.settings.density_budget, self.settings.cache.density())
            {
                let area = scene.area_distribution().total();
                self.settings
                    .cache
                    .set_density(fitted_density(density, area, budget));
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
    /// after the running one until the series converges or the passes run out.
    pub fn progress(&self) -> JobProgress {
        let mut p = self
            .done
            .with_running(self.passes.len() as u32, self.baker.as_ref());
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
        let bounce = bounce_pass_estimator(1, &s.estimator);
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
