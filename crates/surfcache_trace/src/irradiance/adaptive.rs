//! The adaptive stopping rule of [`estimate`](super::estimate) and
//! [`estimate_change`](super::estimate_change): samples in rounds until the relative
//! error C = se / (Ē + ε) meets its bound (docs/design.md, Estimator), and the statistics
//! it reads (single samples, or randomised QMC replicates).

use super::{
    BURIED_PROBE_SAMPLES, BURIED_SIGMAS, Estimate, EstimatorSettings, QMC_REPLICATES,
    ZERO_RUN_EVENTS,
};
use crate::path_tracer::FirstHit;
use glam::{DVec3, Vec3};
use surfcache_core::sampling::{Rng, sobol_4d, splitmix64};

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

/// The adaptive loop of [`estimate`](super::estimate) and
/// [`estimate_change`](super::estimate_change): draws X = `draw(root, rng)` in rounds of
/// [`QMC_REPLICATES`] (root dimensions from per-replicate scrambled Sobol points or from
/// the stream) until C = se / (|offset + mean| + ε) ≤ `bound` from `min` samples on, or
/// `settings.max_samples`; the value is offset + mean.
///
/// `buried_share`: stops once the back-face count is surely above that share
/// ([`surely_buried`]).
///
/// `unseen` > 0: while every sample is exactly zero (and at most half the first rays hit a
/// back face), the standard error is at least [`zero_run_std_error`]`(n, unseen)` in every
/// channel, compared with the brightest channel of the value (the missed light's colour is
/// unknown).
#[allow(clippy::too_many_arguments)]
pub(super) fn sample_adaptively(
    settings: &EstimatorSettings,
    seed: u64,
    key: u64,
    offset: Vec3,
    bound: f32,
    min: u32,
    buried_share: Option<f32>,
    unseen: f64,
    mut draw: impl FnMut([f32; 5], &mut Rng) -> (Vec3, FirstHit, u32, f32),
) -> Estimate {
    let mut rng = Rng::new(seed, key);
    let floor = settings.floor as f64;
    let max = settings.max_samples.max(1);
    let min = min.clamp(1, max);
    let streams = replicate_streams(seed, key);
    let mut tally = Tally::new(settings.sampler.quasi_random());
    let (mean, std_error) = loop {
        let round_end = (tally.n + QMC_REPLICATES).min(max);
        while tally.n < round_end {
            let root = root_dimensions(tally.quasi, tally.n, &streams, &mut rng);
            let (x, first_hit, path_rays, weight) = draw(root, &mut rng);
            tally.add(x, first_hit, path_rays, weight);
        }
        let (n, back, weight) = (tally.n, tally.back, tally.weight);
        let (mean, se) = tally.statistics();
        let total = (mean + offset.as_dvec3()).abs();
        let zero_run = zero_run_error(n, tally.lit, (back, weight), unseen, total, floor);
        let c = relative_error(total, se, floor).max(zero_run.1);
        // Every first ray so far met the back of a single-sided surface: the point lies
        // inside a solid, and the caches discard it whatever more samples would say.
        let buried = n >= BURIED_PROBE_SAMPLES
            && (back == weight || buried_share.is_some_and(|s| surely_buried(back, weight, s)));
        if n >= max || (n >= min && c <= bound as f64) || buried {
            break (mean, se.max(DVec3::splat(zero_run.0)));
        }
    };
    tally.estimate(mean, std_error, offset, unseen, floor)
}

/// Whether `back` of `n` first rays meeting a back face show a share above `share` by
/// [`BURIED_SIGMAS`] binomial standard deviations: `back − s·n > k·√(n·s·(1 − s))`.
/// Counts are weighted as in [`Tally`] (whole numbers where no ray was guided).
/// Never for `share` ≥ 1 (burial detection off).
fn surely_buried(back: f64, n: f64, share: f32) -> bool {
    let s = share as f64;
    s < 1.0 && back - s * n > BURIED_SIGMAS * (n * s * (1.0 - s)).max(0.0).sqrt()
}

/// One Owen scrambling per QMC replicate, keyed by (seed, key, replicate).
fn replicate_streams(seed: u64, key: u64) -> [u32; QMC_REPLICATES as usize] {
    let point = splitmix64(seed ^ splitmix64(key ^ 0x5bd1_e995_0000_0000));
    core::array::from_fn(|r| splitmix64(point ^ r as u64) as u32)
}

/// The root dimensions of sample `n`: quasi-random, the `n / R`-th scrambled Sobol'
/// point of replicate `n mod R`'s stream; pseudo-random, the next five numbers of `rng`.
#[inline]
fn root_dimensions(
    quasi: bool,
    n: u32,
    streams: &[u32; QMC_REPLICATES as usize],
    rng: &mut Rng,
) -> [f32; 5] {
    if quasi {
        let stream = streams[(n % QMC_REPLICATES) as usize];
        let index = n / QMC_REPLICATES;
        let [a, b, c, d] = sobol_4d(index, 0, stream);
        let [e, ..] = sobol_4d(index, 1, stream);
        [a, b, c, d, e]
    } else {
        let mut r = [0.0; 5];
        r.iter_mut().for_each(|v| *v = rng.next_f32());
        r
    }
}

/// The running sums of [`sample_adaptively`]: the samples drawn, their sums
/// (pseudo-random: one accumulator; quasi-random: one per replicate), and how many were
/// non-zero, met a back face first, and the rays they traced.
///
/// The back-face count is of cosine-weighted first rays, whatever drew them: each first
/// ray counts with its weight `cos θ/π / p(ω)` (1/g through a guide, 1 otherwise), so
/// that `back / weight` estimates the share of cosine-weighted rays that meet a back face
/// (the burial verdict's measure) even when a guide draws more of them towards an
/// opening or away from a wall.
struct Tally {
    quasi: bool,
    n: u32,
    single: Accumulator,
    replicates: [Accumulator; QMC_REPLICATES as usize],
    lit: u32,
    /// Σ weight over first rays that met a back face, and over all.
    back: f64,
    weight: f64,
    rays: u64,
}

impl Tally {
    /// No samples yet, for a quasi-random (`quasi`) or pseudo-random sampler.
    fn new(quasi: bool) -> Self {
        Self {
            quasi,
            n: 0,
            single: Accumulator::default(),
            replicates: [Accumulator::default(); QMC_REPLICATES as usize],
            lit: 0,
            back: 0.0,
            weight: 0.0,
            rays: 0,
        }
    }

    /// Adds sample X_n, whose path met `first_hit` first with a first ray of `weight`
    /// (see the type) and traced `path_rays` rays.
    #[inline]
    fn add(&mut self, x: Vec3, first_hit: FirstHit, path_rays: u32, weight: f32) {
        let weight = weight as f64;
        if first_hit == FirstHit::Back {
            self.back += weight;
        }
        self.weight += weight;
        self.lit += (x != Vec3::ZERO) as u32;
        self.rays += path_rays as u64;
        if self.quasi {
            self.replicates[(self.n % QMC_REPLICATES) as usize].add(x);
        } else {
            self.single.add(x);
        }
        self.n += 1;
    }

    /// Mean and standard error of the samples so far: from the replicates
    /// ([`replicate_statistics`]) or from the single accumulator.
    fn statistics(&self) -> (DVec3, DVec3) {
        if self.quasi {
            replicate_statistics(&self.replicates)
        } else {
            (self.single.mean(), self.single.std_error())
        }
    }

    /// The estimate once sampling stopped at `mean` and `std_error`: the value
    /// offset + mean, and C = se / (|value| + ε), at least the all-zero run's
    /// ([`zero_run_error`]).
    fn estimate(
        &self,
        mean: DVec3,
        std_error: DVec3,
        offset: Vec3,
        unseen: f64,
        floor: f64,
    ) -> Estimate {
        let n = self.n;
        let value = (mean + offset.as_dvec3()).as_vec3();
        let std_error = if n < 2 {
            Vec3::ZERO
        } else {
            std_error.as_vec3()
        };
        let zero_run = zero_run_error(
            n,
            self.lit,
            (self.back, self.weight),
            unseen,
            value.as_dvec3().abs(),
            floor,
        )
        .1;
        Estimate {
            value,
            std_error,
            samples: n,
            rel_error: relative_error(value.as_dvec3().abs(), std_error.as_dvec3(), floor)
                .max(zero_run) as f32,
            back_face_share: self.back as f32 / self.weight as f32,
            rays: self.rays,
        }
    }
}

/// The standard error [`ZERO_RUN_EVENTS`] × `unseen` / n of a run of `n` samples that are
/// all exactly zero, where light events would each carry about `unseen`.
pub fn zero_run_std_error(n: u32, unseen: f64) -> f64 {
    ZERO_RUN_EVENTS * unseen / n.max(1) as f64
}

/// (standard error, relative error) of the light an all-zero run may have missed, against
/// the brightest channel of `total` (0, 0 unless the run is all zero, `unseen` > 0 and at
/// most half the first rays hit a back face: `back` of `weight`, weighted as in [`Tally`]).
fn zero_run_error(
    n: u32,
    lit: u32,
    (back, weight): (f64, f64),
    unseen: f64,
    total: DVec3,
    floor: f64,
) -> (f64, f64) {
    if lit > 0 || 2.0 * back > weight || unseen <= 0.0 {
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
