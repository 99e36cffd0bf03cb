//! Monte Carlo estimation of irradiance E(x, ν) = ∫_H L_in(x, ω) ⟨ν, ω⟩ dω at one point,
//! with a selectable sampler and the thesis' adaptive stopping rule (docs/design.md, Estimator).
//!
//! This module holds the samplers, the estimator's settings, one sample of the hemisphere
//! integral, [`estimate`] and the brute-force [`reference_irradiance`]; `adaptive` the
//! stopping rule's loop and its statistics ([`Accumulator`], [`relative_error`],
//! [`zero_run_std_error`]); `change` E of an edited scene from its prior value by
//! correlated sampling ([`estimate_change`], [`unchanged`], the `CHANGE_*` constants).

mod adaptive;
mod change;

pub use adaptive::{Accumulator, relative_error, zero_run_std_error};
pub use change::{
    CHANGE_ERROR_SHARE, CHANGE_FALLBACK_FACTOR, CHANGE_MIN_SAMPLES, CHANGE_PROBE_SAMPLES,
    estimate_change, unchanged,
};

use crate::{
    guiding::{DirectionGuide, GuideRecord},
    path_tracer::{IrradianceLookup, PathOptions, PathSample},
    traced_scene::{SurfacePoint, TracedScene},
};
use adaptive::sample_adaptively;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use surfcache_core::{
    color::luminance,
    geometry::{orthonormal_basis, to_world},
    sampling::{
        Cone, Rng, UNIFORM_HEMISPHERE_PDF, cosine_hemisphere, cosine_hemisphere_pdf,
        cosine_hemisphere_square, uniform_hemisphere,
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

/// Binomial standard deviations by which a point's count of first rays that met a back
/// face must exceed its cache's burial threshold before sampling stops
/// ([`PointInScene::with_buried_share`]).
pub const BURIED_SIGMAS: f64 = 3.0;

/// Independent randomised QMC replicates: sample `k` of a point belongs to replicate
/// `k mod R`. The standard error comes from the spread of the replicate means, which
/// (unlike the spread of single samples) sees the stratification's gain.
pub const QMC_REPLICATES: u32 = 16;

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
    /// Share of samples whose first ray hit the back face of a single-sided surface, as
    /// cosine-weighted first rays would (a guided ray counts with weight 1/g): near 1 for
    /// points buried inside closed geometry.
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
    let light = Vec2::new(root[3], root[4]);
    // The light sample is drawn after the cosine-weighted path, whose ray gives the
    // prefetched sampling tables time to arrive (the sample's random numbers are fixed
    // in advance, so the order changes no result).
    if options.next_event {
        scene.light_sampler().prefetch(root[2], light);
    }
    let next_event = |rays: &mut u32| {
        if !options.next_event {
            return Vec3::ZERO;
        }
        match (focus, guide) {
            (None, None) => scene.direct_light_sample(p, origin, root[2], light, rays),
            (None, Some(g)) => {
                let (t, b) = orthonormal_basis(p.shading_normal);
                scene.direct_light_sample_against(p, origin, root[2], light, rays, |cos, w| {
                    let square = cosine_hemisphere_square(Vec3::new(t.dot(w), b.dot(w), cos));
                    Some(cosine_hemisphere_pdf(cos) * g.density(square))
                })
            }
            (Some(cone), _) => {
                let pdf = 1.0 / cone.solid_angle();
                scene.direct_light_sample_against(p, origin, root[2], light, rays, |_, w| {
                    cone.contains(w).then_some(pdf)
                })
            }
        }
    };
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
        let mut rays = 0;
        let x = next_event(&mut rays);
        let path = PathSample {
            rays,
            first_weight: 1.0 / density,
            ..Default::default()
        };
        return (x, path);
    }
    let mut path = scene.incident_radiance(origin, w, Some(pdf), rng, options, at.gather);
    path.first_weight = 1.0 / density;
    let x = next_event(&mut path.rays);
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
        at.buried_share,
        // Direct light alone, or one bounce gathered from a cache: every sample meets
        // the cache or the lights, so an all-zero run is a dark point, not missed light.
        if at.gather.is_some() || settings.max_bounces == Some(0) {
            0.0
        } else {
            settings.floor as f64 / FLOOR_FRACTION as f64
        },
        |root, rng| {
            let (x, path) = hemisphere_sample(at, settings, root, rng, None);
            (x, path.first_hit, path.rays, path.first_weight)
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
    /// The back-face share above which the cache discards this point as buried, if it
    /// does ([`Self::with_buried_share`]).
    pub buried_share: Option<f32>,
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
            buried_share: None,
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

    /// Stops sampling once the point is surely buried for a cache that discards points
    /// whose back-face share ([`Estimate::back_face_share`]) is above `share`: from
    /// [`BURIED_PROBE_SAMPLES`] samples on, at the end of every round, once the count of
    /// first rays that met a back face passes the binomial test of docs/design.md
    /// (Estimator, "Buried points"; [`BURIED_SIGMAS`]). Its estimate then says buried
    /// as a full one would, after a few dozen samples instead of the point's cap.
    pub fn with_buried_share(mut self, share: Option<f32>) -> Self {
        self.buried_share = share;
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
