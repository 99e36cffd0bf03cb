//! Irradiance of an edited scene from its value before the edit plus the change,
//! estimated by correlated sampling (docs/design.md, Estimator).

use super::{
    Estimate, EstimatorSettings, PointInScene, QMC_REPLICATES, adaptive::sample_adaptively,
    estimate, hemisphere_sample,
};
use glam::Vec3;
use surfcache_core::sampling::Cone;

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
/// [`ZERO_RUN_EVENTS`](super::ZERO_RUN_EVENTS) bound: a re-bake would otherwise sample
/// every untouched point hundreds of times). When a probe of [`CHANGE_PROBE_SAMPLES`]
/// pairs projects the change to need more than [`CHANGE_FALLBACK_FACTOR`] × `min_samples`
/// pairs, E is estimated afresh instead ([`estimate`] in the edited scene, with its
/// gathering lookup).
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
    let (punctual_new, punctual_old) = punctual_parts(old, new, &mut punctual_rays);
    let change = Change {
        old,
        new,
        settings,
        seed,
        key,
        focus,
        offset: prior + punctual_new - punctual_old,
        bound: settings.max_rel_error * CHANGE_ERROR_SHARE,
    };
    let (mut e, fresh) = change.probe_then_estimate();
    if !fresh {
        change.settle(&mut e);
    }
    e.rays += punctual_rays as u64;
    e
}

/// The punctual lights' exact parts (E_new, E_old) at the point of [`estimate_change`],
/// their shadow rays added to `rays`; both zero within one scene (the indirect stages of
/// a re-bake), where they cancel.
fn punctual_parts(old: &PointInScene, new: &PointInScene, rays: &mut u32) -> (Vec3, Vec3) {
    if std::ptr::eq(old.scene, new.scene) {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    (
        new.scene
            .punctual_irradiance_from(&new.point, new.origin, rays),
        old.scene
            .punctual_irradiance_from(&old.point, old.origin, rays),
    )
}

/// One point's change as [`estimate_change`] samples it: the point in both scenes, the
/// settings and random stream, the value of a zero change, and the change's error bound.
struct Change<'a> {
    old: &'a PointInScene<'a>,
    new: &'a PointInScene<'a>,
    settings: &'a EstimatorSettings,
    seed: u64,
    key: u64,
    focus: Option<&'a Cone>,
    /// prior + E_new − E_old of the punctual lights: the value if the sampled change is zero.
    offset: Vec3,
    /// [`CHANGE_ERROR_SHARE`] × `max_rel_error`.
    bound: f32,
}

impl Change<'_> {
    /// offset + E[X_new − X_old] by correlated sampling, with at most `max_samples` pairs:
    /// each pair traces the same root dimensions and random numbers in both scenes.
    fn sample(&self, max_samples: u32) -> Estimate {
        let settings = EstimatorSettings {
            max_samples,
            ..*self.settings
        };
        let (old, new, focus) = (self.old, self.new, self.focus);
        sample_adaptively(
            &settings,
            self.seed,
            self.key,
            self.offset,
            self.bound,
            CHANGE_MIN_SAMPLES,
            None,
            0.0,
            |root, rng| {
                let mut twin = rng.clone();
                let (x_new, path_new) = hemisphere_sample(new, &settings, root, rng, focus);
                let (x_old, path_old) = hemisphere_sample(old, &settings, root, &mut twin, focus);
                (
                    x_new - x_old,
                    path_new.first_hit,
                    path_new.rays + path_old.rays,
                    path_new.first_weight,
                )
            },
        )
    }

    /// The estimate after a probe of [`CHANGE_PROBE_SAMPLES`] pairs: the probe itself if
    /// it met the bound (or drew every pair allowed), else the change sampled up to
    /// `max_samples`, or E afresh ([`estimate`]) when the probe projects more than
    /// [`CHANGE_FALLBACK_FACTOR`] × `min_samples` pairs ([`projected_pairs`]); and whether
    /// it is E afresh. The probe's rays are counted in.
    fn probe_then_estimate(&self) -> (Estimate, bool) {
        let settings = self.settings;
        // A probe tells whether the change is cheaper to estimate than E itself: where the
        // edit changes a large part of a dark point's light (a shadow moved onto it), the
        // change has the variance of the old, bright E but must reach the precision of the
        // new, dim one; a fresh estimate of E is then cheaper.
        let probe_samples = CHANGE_PROBE_SAMPLES.min(settings.max_samples);
        let probe = self.sample(probe_samples);
        if probe.samples < probe_samples || probe.rel_error <= self.bound {
            return (probe, false);
        }
        let projected = projected_pairs(&probe, self.bound);
        let (mut e, fresh) = if projected > CHANGE_FALLBACK_FACTOR * settings.min_samples as f32 {
            (estimate(self.new, settings, self.seed, self.key), true)
        } else {
            (self.sample(settings.max_samples), false)
        };
        e.rays += probe.rays;
        (e, fresh)
    }

    /// The sampled change's final value and error: zero (the value is `offset`) when it
    /// lies within one standard error of zero in every channel, and the prior's error
    /// added ([`with_prior_error`]).
    fn settle(&self, e: &mut Estimate) {
        // A sampled change within one standard error of zero in every channel is noise
        // as far as this estimate can tell: keep the prior (plus the exact punctual
        // change). The value then differs from the unbiased one by at most that standard
        // error, within the change's error share, and re-bakes do not spread the noise
        // of far points, which an edit barely touches, through their indirect stages.
        if (e.value - self.offset).abs().cmple(e.std_error).all() {
            e.value = self.offset;
        }
        e.std_error = with_prior_error(e.value, e.std_error, self.settings);
    }
}

/// The pairs a change would need to meet `bound` at the rate of `probe`, since C falls
/// as 1/√n: n_probe × (C_probe / bound)².
fn projected_pairs(probe: &Estimate, bound: f32) -> f32 {
    probe.samples as f32 * (probe.rel_error / bound).powi(2)
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
