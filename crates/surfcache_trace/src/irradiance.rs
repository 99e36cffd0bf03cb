//! Monte Carlo estimation of irradiance E(x, ν) = ∫_H L_in(x, ω) ⟨ν, ω⟩ dω at one point,
//! with a selectable sampler and the thesis' adaptive stopping rule (docs/design.md, Estimator).

use crate::{
    guiding::{DirectionGuide, GuideRecord},
    path_tracer::{FirstHit, IrradianceLookup, PathOptions, PathSample},
    traced_scene::{SurfacePoint, TracedScene},
};
use glam::{DVec3, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use surfcache_core::{
    color::luminance,
    geometry::{orthonormal_basis, to_world},
    sampling::{
        Cone, Rng, UNIFORM_HEMISPHERE_PDF, cosine_hemisphere, cosine_hemisphere_pdf,
        cosine_hemisphere_square, sobol_4d, splitmix64, uniform_hemisphere,
    },
};

/// How the hemisphere integral is sampled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    /// Uniform directions over the hemisphere, p = 1/(2π), pseudo-random: the thesis.
    Uniform,
    /// Cosine-weighted directions, p = cos θ/π, pseudo-random.
    Cosine,
    /// Cosine-weighted directions from Owen-scrambled Sobol points, scrambled per point.
    Qmc,
    /// Cosine-weighted directions plus next-event estimation to emissive triangles and the
    /// environment map (importance-sampled), combined by multiple importance sampling;
    /// pseudo-random.
    Mis,
    /// Everything: [`Sampler::Mis`] with its first-bounce dimensions (direction, light
    /// choice, point on the light) drawn from per-point scrambled Sobol points.
    #[default]
    Best,
}

impl Sampler {
    /// All samplers, in the order the CLI lists them.
    pub const ALL: [Sampler; 5] = [
        Sampler::Uniform,
        Sampler::Cosine,
        Sampler::Qmc,
        Sampler::Mis,
        Sampler::Best,
    ];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Uniform => "uniform",
            Sampler::Cosine => "cosine",
            Sampler::Qmc => "qmc",
            Sampler::Mis => "mis",
            Sampler::Best => "best",
        }
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Whether first-bounce dimensions come from scrambled Sobol points.
    pub fn quasi_random(self) -> bool {
        matches!(self, Sampler::Qmc | Sampler::Best)
    }

    /// Whether paths use next-event estimation with MIS.
    pub fn next_event(self) -> bool {
        matches!(self, Sampler::Mis | Sampler::Best)
    }
}

/// The relative-error floor ε of a bake is this fraction of the scene's mean irradiance
/// (`surfcache_cache::bake`); conversely ε / `FLOOR_FRACTION` is the irradiance scale of
/// the scene, the scale [`estimate`] gives light it has not seen (see [`ZERO_RUN_EVENTS`]).
pub const FLOOR_FRACTION: f32 = 0.01;

/// Light events that a run of n samples which are all exactly zero cannot rule out.
///
/// Zero samples have no spread, so the thesis' standard error of such a run is 0 and
/// C = 0 would stop it at `min_samples`, black, however rare but bright the paths that
/// carry light (a deep niche: "black blotches"). With k ≥ 1 samples carrying light X₊
/// the sample variance is already of the order k·X₊²/n², the size of the rare-event
/// uncertainty; only k = 0 is degenerate. Such a run is therefore given the standard
/// error of the light it could have missed: a Poisson count of zero events bounds their
/// rate at `ZERO_RUN_EVENTS`/n at 84 % (one-sided 1σ, the confidence the rule C ≤ bound
/// means elsewhere; the "rule of three" is the 95 % bound), each carrying about the
/// scene's irradiance scale S = ε / [`FLOOR_FRACTION`]. It stops once
/// 1.84·S/n ≤ bound · (E + ε), i.e. after about 184 / bound samples where nothing
/// else lights the point (or at `max_samples`).
pub const ZERO_RUN_EVENTS: f64 = 1.841;

/// Samples after which an estimate whose first rays all met the back of a single-sided
/// surface stops: the point is buried inside closed geometry (its back-face share is 1,
/// above any cache's burial threshold), and the caches fill it from its neighbours. A
/// point whose true back-face share is s stops here wrongly with probability s^16: below
/// 2·10⁻⁵ for the points (s ≤ ½) the caches keep.
pub const BURIED_PROBE_SAMPLES: u32 = 16;

/// Independent randomised QMC replicates: sample `k` of a point belongs to replicate
/// `k mod R`. The standard error comes from the spread of the replicate means, which
/// (unlike the spread of single samples) sees the stratification's gain.
pub const QMC_REPLICATES: u32 = 16;

/// Running sums of the samples X_i of one estimate (f64, so millions of samples stay exact).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Accumulator {
    pub count: u32,
    pub sum: DVec3,
    pub sum_sq: DVec3,
}

impl Accumulator {
    #[inline]
    pub fn add(&mut self, x: Vec3) {
        let x = x.as_dvec3();
        self.count += 1;
        self.sum += x;
        self.sum_sq += x * x;
    }

    /// The mean Ē = (1/n) Σ X_i.
    pub fn mean(&self) -> DVec3 {
        self.sum / self.count.max(1) as f64
    }

    /// Standard error of the mean, sqrt(Σ(X_i − Ē)² / (n(n−1))) per channel (docs/design.md, Estimator).
    pub fn std_error(&self) -> DVec3 {
        if self.count < 2 {
            return DVec3::splat(f64::INFINITY);
        }
        let n = self.count as f64;
        let var = ((self.sum_sq - self.sum * self.sum / n) / (n - 1.0)).max(DVec3::ZERO);
        (var / n).map(f64::sqrt)
    }
}

/// Coefficient of variation of the mean, C = se / (Ē + ε), the maximum over the channels
/// (docs/design.md, Estimator); a channel with no spread counts as exact.
pub fn relative_error(mean: DVec3, std_error: DVec3, floor: f64) -> f64 {
    (0..3)
        .map(|c| {
            if std_error[c] == 0.0 {
                0.0
            } else {
                std_error[c] / (mean[c].max(0.0) + floor)
            }
        })
        .fold(0.0, f64::max)
}

/// How one estimate is computed and when it stops.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatorSettings {
    pub sampler: Sampler,
    /// Stop once C = se/(Ē + ε) ≤ this bound (0: always draw `max_samples`).
    pub max_rel_error: f32,
    /// Never fewer hemisphere samples than this.
    pub min_samples: u32,
    /// Never more hemisphere samples than this.
    pub max_samples: u32,
    /// The absolute floor ε of the relative error, W/m².
    pub floor: f32,
    /// Bounce limit (next-event estimation follows from `sampler`).
    pub max_bounces: Option<u32>,
}

impl Default for EstimatorSettings {
    fn default() -> Self {
        Self {
            sampler: Sampler::Best,
            max_rel_error: 0.01,
            min_samples: 256,
            max_samples: 65_536,
            floor: 0.0,
            max_bounces: None,
        }
    }
}

impl EstimatorSettings {
    /// Exactly `samples` samples, no early stop.
    pub fn fixed(sampler: Sampler, samples: u32, max_bounces: Option<u32>) -> Self {
        Self {
            sampler,
            max_rel_error: 0.0,
            min_samples: samples,
            max_samples: samples,
            floor: 0.0,
            max_bounces,
        }
    }

    fn path_options(&self) -> PathOptions {
        PathOptions {
            max_bounces: self.max_bounces,
            next_event: self.sampler.next_event(),
        }
    }
}

/// One irradiance estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Ē in W/m² (hemisphere samples plus the exact punctual-light part).
    pub value: Vec3,
    /// Standard error of `value` per channel.
    pub std_error: Vec3,
    /// Hemisphere samples drawn.
    pub samples: u32,
    /// C = se / (Ē + ε), the largest over the channels.
    pub rel_error: f32,
    /// Share of samples whose first ray hit the back face of a single-sided surface: near
    /// 1 for points buried inside closed geometry.
    pub back_face_share: f32,
    /// Rays traced (closest-hit and shadow rays).
    pub rays: u64,
}

impl Estimate {
    /// Standard error over value, the largest over channels with light (0 for black).
    pub fn relative_std(&self) -> f32 {
        (0..3)
            .filter(|&c| self.value[c] > 0.0)
            .map(|c| self.std_error[c] / self.value[c])
            .fold(0.0, f32::max)
    }
}

/// One sample X of the hemisphere integral at `at` (shading normal ν, geometric normal μ).
/// `root` holds the first-bounce dimensions: direction (0, 1), light choice (2) and point
/// on the light (3, 4); deeper bounces draw from `rng`.
///
/// Without next-event estimation X = L_in(ω) ⟨ν, ω⟩ / p(ω), with ω drawn uniformly
/// (p = 1/2π) or cosine-weighted (p = cos θ/π, X = π L_in). With it, X adds the light
/// sample of [`TracedScene::direct_light_sample`] and the continuation's emission is
/// MIS-weighted. Directions under the geometric surface carry no light (docs/cli.md).
///
/// With a guide ([`PointInScene::guidance`]), cosine-weighted directions are drawn through
/// it, p(ω) = cos θ/π · g(u(ω)), and both MIS weights use that density (docs/design.md,
/// Guiding); with a record, the light the cosine-weighted ray brought is recorded at its
/// point of the square.
///
/// With `focus`, X estimates the integral over the directions of that cone only: ω is
/// drawn uniformly in the cone (p = 1/Ω), and next-event samples count only inside it,
/// MIS-weighted against the cone density. Guidance is not used then.
#[inline]
pub fn hemisphere_sample(
    at: &PointInScene,
    settings: &EstimatorSettings,
    root: [f32; 5],
    rng: &mut Rng,
    focus: Option<&Cone>,
) -> (Vec3, PathSample) {
    let (scene, p, origin) = (at.scene, &at.point, at.origin);
    let options = settings.path_options();
    let cosine = focus.is_none() && settings.sampler != Sampler::Uniform;
    let guide = at.guidance.guide.filter(|_| cosine);
    let u = Vec2::new(root[0], root[1]);
    let mut x = Vec3::ZERO;
    let mut rays = 0;
    if options.next_event {
        let light = Vec2::new(root[3], root[4]);
        x += match (focus, guide) {
            (None, None) => scene.direct_light_sample(p, origin, root[2], light, &mut rays),
            (None, Some(g)) => {
                let (t, b) = orthonormal_basis(p.shading_normal);
                scene.direct_light_sample_against(p, origin, root[2], light, &mut rays, |cos, w| {
                    let square = cosine_hemisphere_square(Vec3::new(t.dot(w), b.dot(w), cos));
                    Some(cosine_hemisphere_pdf(cos) * g.density(square))
                })
            }
            (Some(cone), _) => {
                let pdf = 1.0 / cone.solid_angle();
                scene.direct_light_sample_against(p, origin, root[2], light, &mut rays, |_, w| {
                    cone.contains(w).then_some(pdf)
                })
            }
        };
    }
    // The point of the square the direction comes from and the guide's density there.
    let (square, density) = match guide {
        Some(g) => g.sample(u),
        None => (u, 1.0),
    };
    let (w, weight, pdf) = match (focus, settings.sampler) {
        (Some(cone), _) => {
            let w = cone.sample(u);
            let omega = cone.solid_angle();
            (w, p.shading_normal.dot(w) * omega, 1.0 / omega)
        }
        (None, Sampler::Uniform) => {
            let l = uniform_hemisphere(u);
            let w = to_world(l, p.shading_normal);
            (w, l.z / UNIFORM_HEMISPHERE_PDF, UNIFORM_HEMISPHERE_PDF)
        }
        // cos θ / (cos θ/π · g) = π / g
        (None, _) => {
            let l = cosine_hemisphere(square);
            let w = to_world(l, p.shading_normal);
            (
                w,
                core::f32::consts::PI / density,
                cosine_hemisphere_pdf(l.z) * density,
            )
        }
    };
    let record = at.guidance.record.filter(|_| cosine);
    if w.dot(p.geometric_normal) <= 0.0 || w.dot(p.shading_normal) <= 0.0 {
        if let Some(r) = record {
            r.add(square, 0.0);
        }
        let path = PathSample {
            rays,
            ..Default::default()
        };
        return (x, path);
    }
    let mut path = scene.incident_radiance(origin, w, Some(pdf), rng, options, at.gather);
    path.rays += rays;
    let carried = path.radiance * weight;
    if let Some(r) = record {
        r.add(square, luminance(carried));
    }
    (x + carried, path)
}

/// Draws samples of E at `p` until C ≤ `settings.max_rel_error` (checked after every
/// round of [`QMC_REPLICATES`] samples, from `min_samples` on) or `max_samples` are
/// drawn (docs/design.md, Estimator), and adds the punctual lights' exact part.
///
/// `key` identifies the point: sample streams are keyed by (`seed`, `key`), so the
/// result does not depend on threads, batching or frames. Pseudo-random samplers take
/// the standard error from single samples (the thesis' formula); quasi-random ones from
/// the spread of [`QMC_REPLICATES`] independently scrambled replicates.
///
/// A run whose samples are all exactly zero is not taken as converged at 0 until the
/// light it could have missed is below the bound ([`ZERO_RUN_EVENTS`]; needs a floor
/// ε > 0, which sets the scale), except where most first rays hit the back of a
/// single-sided surface: such a point lies inside geometry (a buried sample, which the
/// caches discard at their default `buried_threshold` of 0.5), and keeps stopping at
/// `min_samples` (at [`BURIED_PROBE_SAMPLES`] when every first ray so far met a back
/// face); and except for direct light alone (`max_bounces = Some(0)`) and with
/// `gather`, where every sample meets the lights or the gathered cache: an all-zero run
/// then means that nothing the point sees is lit (a light-tight interior, a sealed void),
/// and stops at `min_samples` too.
///
/// `at` holds the point, the origin of its rays, the gathering lookup and the guidance.
/// With a lookup, paths end at their first hit with its irradiance there (final
/// gathering, see [`IrradianceLookup`]); without, they are traced to the end.
pub fn estimate(at: &PointInScene, settings: &EstimatorSettings, seed: u64, key: u64) -> Estimate {
    let mut punctual_rays = 0;
    let punctual = at
        .scene
        .punctual_irradiance_from(&at.point, at.origin, &mut punctual_rays);
    let mut e = sample_adaptively(
        settings,
        seed,
        key,
        punctual,
        settings.max_rel_error,
        settings.min_samples,
        // Direct light alone, or one bounce gathered from a cache: every sample meets
        // the cache or the lights, so an all-zero run is a dark point, not missed light.
        if at.gather.is_some() || settings.max_bounces == Some(0) {
            0.0
        } else {
            settings.floor as f64 / FLOOR_FRACTION as f64
        },
        |root, rng| {
            let (x, path) = hemisphere_sample(at, settings, root, rng, None);
            (x, path.first_hit, path.rays)
        },
    );
    e.rays += punctual_rays as u64;
    e
}

/// A point as one scene sees it: where it is, where its rays leave from, the gathering
/// lookup of that scene's previous pass (if any), and the guide its directions follow.
#[derive(Clone, Copy)]
pub struct PointInScene<'a> {
    pub scene: &'a TracedScene,
    pub point: SurfacePoint,
    pub origin: Vec3,
    pub gather: Option<&'a dyn IrradianceLookup>,
    pub guidance: Guidance<'a>,
}

impl<'a> PointInScene<'a> {
    /// `point` of `scene` with rays leaving from `origin`, paths traced to their end,
    /// plain cosine-weighted directions.
    pub fn new(scene: &'a TracedScene, point: SurfacePoint, origin: Vec3) -> Self {
        Self {
            scene,
            point,
            origin,
            gather: None,
            guidance: Guidance::default(),
        }
    }

    /// Ends every path at its first hit with `gather`'s irradiance there (final gathering).
    pub fn with_gather(mut self, gather: Option<&'a dyn IrradianceLookup>) -> Self {
        self.gather = gather;
        self
    }

    /// Draws and records directions as `guidance` says.
    pub fn with_guidance(mut self, guidance: Guidance<'a>) -> Self {
        self.guidance = guidance;
        self
    }
}

/// How an estimate learns and follows where its light comes from (docs/design.md,
/// Guiding): a guide to draw cosine-weighted directions through, and a record the light
/// of its samples goes into for later guides. Either may be absent.
#[derive(Clone, Copy, Debug, Default)]
pub struct Guidance<'a> {
    pub guide: Option<&'a DirectionGuide>,
    pub record: Option<&'a GuideRecord>,
}

/// The least number of sample pairs of [`estimate_change`].
pub const CHANGE_MIN_SAMPLES: u32 = QMC_REPLICATES;

/// The share of the error bound a change estimate may add to its prior's error.
pub const CHANGE_ERROR_SHARE: f32 = 0.5;

/// Sample pairs of the probe that decides between estimating a change and estimating
/// E afresh ([`estimate_change`]).
pub const CHANGE_PROBE_SAMPLES: u32 = 4 * QMC_REPLICATES;

/// [`estimate_change`] estimates E afresh when the probe projects more than this many
/// times the estimator's `min_samples` pairs for the change (each pair traces two paths).
pub const CHANGE_FALLBACK_FACTOR: f32 = 2.0;

/// E at a point of an edited scene from its value `prior` before the edit plus the
/// change, estimated by *correlated sampling*: every sample traces the same directions
/// and random numbers in both scenes, X = X_new − X_old, so wherever the edit does not
/// touch a path the difference is exactly zero and the estimate stops after
/// [`CHANGE_MIN_SAMPLES`] pairs; it stops when its standard error is at most
/// [`CHANGE_ERROR_SHARE`] × bound × (E + ε). Unbiased, E = E_old + E[X_new − X_old],
/// except that a change within one standard error of zero is taken as zero (it moves
/// the value by less than the change's error share; far from an edit it is noise).
/// The punctual lights' exact parts enter as their difference too. An all-zero run of
/// differences is exact where no path meets the edit, so it stops as it is (no
/// [`ZERO_RUN_EVENTS`] bound: a re-bake would otherwise sample every untouched point
/// hundreds of times). When a probe of [`CHANGE_PROBE_SAMPLES`] pairs projects the
/// change to need more than [`CHANGE_FALLBACK_FACTOR`] × `min_samples` pairs, E is
/// estimated afresh instead ([`estimate`] in the edited scene, with its gathering lookup).
///
/// With `focus`, only directions in that cone can differ (the edit lies inside it, and
/// both scenes' gathering lookups agree elsewhere): the change is integrated over the
/// cone alone ([`hemisphere_sample`]), and is exactly zero, with no rays traced, when
/// the cone lies below the point's surface.
pub fn estimate_change(
    old: &PointInScene,
    new: &PointInScene,
    prior: Vec3,
    settings: &EstimatorSettings,
    seed: u64,
    key: u64,
    focus: Option<&Cone>,
) -> Estimate {
    if let Some(cone) = focus
        && cone.below(new.point.geometric_normal)
        && cone.below(old.point.geometric_normal)
        && new.scene.lights().is_empty()
        && old.scene.lights().is_empty()
    {
        return unchanged(prior, settings);
    }
    let mut punctual_rays = 0;
    // Within one scene (the indirect stages of a re-bake) the punctual parts cancel.
    let (punctual_new, punctual_old) = if std::ptr::eq(old.scene, new.scene) {
        (Vec3::ZERO, Vec3::ZERO)
    } else {
        (
            new.scene
                .punctual_irradiance_from(&new.point, new.origin, &mut punctual_rays),
            old.scene
                .punctual_irradiance_from(&old.point, old.origin, &mut punctual_rays),
        )
    };
    let bound = settings.max_rel_error * CHANGE_ERROR_SHARE;
    let change = |max_samples: u32| {
        let settings = EstimatorSettings {
            max_samples,
            ..*settings
        };
        sample_adaptively(
            &settings,
            seed,
            key,
            prior + punctual_new - punctual_old,
            bound,
            CHANGE_MIN_SAMPLES,
            0.0,
            |root, rng| {
                let mut twin = rng.clone();
                let (x_new, path_new) = hemisphere_sample(new, &settings, root, rng, focus);
                let (x_old, path_old) = hemisphere_sample(old, &settings, root, &mut twin, focus);
                (
                    x_new - x_old,
                    path_new.first_hit,
                    path_new.rays + path_old.rays,
                )
            },
        )
    };
    // A probe tells whether the change is cheaper to estimate than E itself: where the
    // edit changes a large part of a dark point's light (a shadow moved onto it), the
    // change has the variance of the old, bright E but must reach the precision of the
    // new, dim one; a fresh estimate of E is then cheaper.
    let probe_samples = CHANGE_PROBE_SAMPLES.min(settings.max_samples);
    let probe = change(probe_samples);
    let (mut e, fresh) = if probe.samples < probe_samples || probe.rel_error <= bound {
        (probe, false)
    } else {
        let projected = probe.samples as f32 * (probe.rel_error / bound).powi(2);
        let (mut e, fresh) = if projected > CHANGE_FALLBACK_FACTOR * settings.min_samples as f32 {
            let e = estimate(new, settings, seed, key);
            (e, true)
        } else {
            (change(settings.max_samples), false)
        };
        e.rays += probe.rays;
        (e, fresh)
    };
    if !fresh {
        // A sampled change within one standard error of zero in every channel is noise
        // as far as this estimate can tell: keep the prior (plus the exact punctual
        // change). The value then differs from the unbiased one by at most that standard
        // error, within the change's error share, and re-bakes do not spread the noise
        // of far points, which an edit barely touches, through their indirect stages.
        let offset = prior + punctual_new - punctual_old;
        if (e.value - offset).abs().cmple(e.std_error).all() {
            e.value = offset;
        }
        e.std_error = with_prior_error(e.value, e.std_error, settings);
    }
    e.rays += punctual_rays as u64;
    e
}

/// The estimate of a point whose change is known to be zero (or is left out): its
/// `prior`, with the prior's error ([`estimate_change`]); no samples, no rays.
pub fn unchanged(prior: Vec3, settings: &EstimatorSettings) -> Estimate {
    Estimate {
        value: prior,
        std_error: with_prior_error(prior, Vec3::ZERO, settings),
        ..Default::default()
    }
}

/// The standard error of prior + change: the prior's, taken at the bound its estimate
/// met (its own is not kept), and the change's `se`, added in quadrature.
fn with_prior_error(value: Vec3, se: Vec3, settings: &EstimatorSettings) -> Vec3 {
    let prior = settings.max_rel_error * (value.abs() + Vec3::splat(settings.floor));
    (se * se + prior * prior).map(f32::sqrt)
}

/// The adaptive loop of [`estimate`] and [`estimate_change`]: draws X = `draw(root, rng)`
/// in rounds of [`QMC_REPLICATES`] (root dimensions from per-replicate scrambled Sobol
/// points or from the stream) until C = se / (|offset + mean| + ε) ≤ `bound` from `min`
/// samples on, or `settings.max_samples`; the value is offset + mean.
///
/// `unseen` > 0: while every sample is exactly zero (and at most half the first rays hit a
/// back face), the standard error is at least [`zero_run_std_error`]`(n, unseen)` in every
/// channel, compared with the brightest channel of the value (the missed light's colour is
/// unknown).
#[allow(clippy::too_many_arguments)]
fn sample_adaptively(
    settings: &EstimatorSettings,
    seed: u64,
    key: u64,
    offset: Vec3,
    bound: f32,
    min: u32,
    unseen: f64,
    mut draw: impl FnMut([f32; 5], &mut Rng) -> (Vec3, FirstHit, u32),
) -> Estimate {
    let sampler = settings.sampler;
    let mut rng = Rng::new(seed, key);
    let floor = settings.floor as f64;
    let max = settings.max_samples.max(1);
    let min = min.clamp(1, max);
    let (mut back, mut rays, mut lit) = (0u32, 0u64, 0u32);
    // Pseudo-random: one accumulator. Quasi-random: one per replicate.
    let mut single = Accumulator::default();
    let mut replicates = [Accumulator::default(); QMC_REPLICATES as usize];
    // One Owen scrambling per replicate, keyed by (seed, key, replicate).
    let point = splitmix64(seed ^ splitmix64(key ^ 0x5bd1_e995_0000_0000));
    let streams: [u32; QMC_REPLICATES as usize] =
        core::array::from_fn(|r| splitmix64(point ^ r as u64) as u32);
    let mut n = 0u32;
    let (mean, std_error) = loop {
        let round_end = (n + QMC_REPLICATES).min(max);
        while n < round_end {
            let root = if sampler.quasi_random() {
                let stream = streams[(n % QMC_REPLICATES) as usize];
                let index = n / QMC_REPLICATES;
                let [a, b, c, d] = sobol_4d(index, 0, stream);
                let [e, ..] = sobol_4d(index, 1, stream);
                [a, b, c, d, e]
            } else {
                let mut r = [0.0; 5];
                r.iter_mut().for_each(|v| *v = rng.next_f32());
                r
            };
            let (x, first_hit, path_rays) = draw(root, &mut rng);
            back += (first_hit == FirstHit::Back) as u32;
            lit += (x != Vec3::ZERO) as u32;
            rays += path_rays as u64;
            if sampler.quasi_random() {
                replicates[(n % QMC_REPLICATES) as usize].add(x);
            } else {
                single.add(x);
            }
            n += 1;
        }
        let (mean, se) = if sampler.quasi_random() {
            replicate_statistics(&replicates)
        } else {
            (single.mean(), single.std_error())
        };
        let total = (mean + offset.as_dvec3()).abs();
        let zero_run = zero_run_error(n, lit, back, unseen, total, floor);
        let c = relative_error(total, se, floor).max(zero_run.1);
        // Every first ray so far met the back of a single-sided surface: the point lies
        // inside a solid, and the caches discard it whatever more samples would say.
        let buried = n >= BURIED_PROBE_SAMPLES && back == n;
        if n >= max || (n >= min && c <= bound as f64) || buried {
            break (mean, se.max(DVec3::splat(zero_run.0)));
        }
    };
    let value = (mean + offset.as_dvec3()).as_vec3();
    let std_error = if n < 2 {
        Vec3::ZERO
    } else {
        std_error.as_vec3()
    };
    let zero_run = zero_run_error(n, lit, back, unseen, value.as_dvec3().abs(), floor).1;
    Estimate {
        value,
        std_error,
        samples: n,
        rel_error: relative_error(value.as_dvec3().abs(), std_error.as_dvec3(), floor).max(zero_run)
            as f32,
        back_face_share: back as f32 / n as f32,
        rays,
    }
}

/// The standard error [`ZERO_RUN_EVENTS`] × `unseen` / n of a run of `n` samples that are
/// all exactly zero, where light events would each carry about `unseen`.
pub fn zero_run_std_error(n: u32, unseen: f64) -> f64 {
    ZERO_RUN_EVENTS * unseen / n.max(1) as f64
}

/// (standard error, relative error) of the light an all-zero run may have missed, against
/// the brightest channel of `total` (0, 0 unless the run is all zero, `unseen` > 0 and at
/// most half the first rays hit a back face).
fn zero_run_error(
    n: u32,
    lit: u32,
    back: u32,
    unseen: f64,
    total: DVec3,
    floor: f64,
) -> (f64, f64) {
    if lit > 0 || 2 * back > n || unseen <= 0.0 {
        return (0.0, 0.0);
    }
    let se = zero_run_std_error(n, unseen);
    (se, se / (total.max_element() + floor))
}

/// Mean and standard error from randomised QMC replicates: the mean of all samples, and
/// the spread of the replicate means over √R.
fn replicate_statistics(replicates: &[Accumulator]) -> (DVec3, DVec3) {
    let filled = || replicates.iter().filter(|a| a.count > 0);
    let n: u32 = filled().map(|a| a.count).sum();
    let sum: DVec3 = filled().map(|a| a.sum).sum();
    let mean = sum / n.max(1) as f64;
    let r = filled().count();
    if r < 2 {
        return (mean, DVec3::splat(f64::INFINITY));
    }
    // Unbiased variance of replicate means around the overall mean (equal counts at
    // round boundaries, where it is evaluated).
    let var_means: DVec3 = filled()
        .map(|a| {
            let d = a.mean() - mean;
            d * d
        })
        .sum::<DVec3>()
        / (r as f64 - 1.0);
    (mean, (var_means / r as f64).map(f64::sqrt))
}

/// A query: a world-space point on a surface and the normal of the side asked about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Query {
    pub position: Vec3,
    pub normal: Vec3,
}

/// Brute-force reference E(x, n) at each query point with a fixed number of samples,
/// in parallel over points. Point `i` is keyed `i`, so the result does not depend on the
/// thread count. `None` marks a point that is not on any surface. `progress` is called
/// once per finished point.
pub fn reference_irradiance(
    scene: &TracedScene,
    queries: &[Query],
    settings: &EstimatorSettings,
    seed: u64,
    progress: &(dyn Fn() + Sync),
) -> Vec<Option<Estimate>> {
    use rayon::prelude::*;
    queries
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let p = scene.locate(q.position, q.normal)?;
            let origin = scene.spawn_origin(&p);
            let e = estimate(
                &PointInScene::new(scene, p, origin),
                settings,
                seed,
                i as u64,
            );
            progress();
            Some(e)
        })
        .collect()
}
