//! Baking a surface cache: rounds of sample points estimated in parallel, in steps that a
//! caller can spread over frames, cancel, and watch.
//!
//! The parts: [`estimation`] (where and how one sample point is estimated, afresh or by
//! its change since an edit), [`baker`] (one cache through its rounds), [`settings`]
//! (what a bake needs besides the scene, and the density a scene's size allows) and
//! [`job`] (a complete bake: the floor, bounce passes, the final pass).

mod baker;
mod estimation;
mod job;
mod settings;

pub use baker::{BakeProgress, Baker, bake_to_convergence};
pub use estimation::{Previous, estimate_point, map_site, mean_irradiance, sample_frame};
pub(crate) use job::step_pass;
pub use job::{
    BOUNCE_PASS_DENSITY, BOUNCE_PROBES, BOUNCE_TAIL_SHARE, BakeJob, BakeOutcome, FINE_MESH_SHARE,
    JobProgress, TRACE_PASSES_VAR,
};
pub use settings::{
    BakeSettings, DEFAULT_DENSITY_BUDGET, DEFAULT_GATHER_PASSES, MIN_FITTED_DENSITY, fitted_density,
};

/// The relative-error floor ε is this fraction of the scene's mean irradiance (defined by
/// the estimator, which also takes ε / `FLOOR_FRACTION` as the scale of light an all-zero
/// run of samples may have missed: [`surfcache_trace::ZERO_RUN_EVENTS`]).
pub use surfcache_trace::FLOOR_FRACTION;
