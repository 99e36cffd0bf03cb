//! The one bake code path of the command-line tool: options into [`BakeSettings`], and a
//! [`BakeJob`] driven to its final cache with a progress line. `bake` and `chart` both
//! use it.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::time::{Duration, Instant};
use surfcache_cache::{
    Cache, CacheSettings, Method,
    bake::{BakeJob, BakeSettings, JobProgress},
};
use surfcache_trace::{EstimatorSettings, Sampler, TracedScene};

use crate::scene_args::with_threads;

/// Parses a method name, listing the known ones on error.
pub fn parse_method(name: &str) -> Result<Method> {
    Method::from_name(name).with_context(|| {
        let known: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        format!("unknown method '{name}' (known: {})", known.join(", "))
    })
}

/// Parses a sampler name, listing the known ones on error.
pub fn parse_sampler(name: &str) -> Result<Sampler> {
    Sampler::from_name(name).with_context(|| {
        let known: Vec<&str> = Sampler::ALL.iter().map(|s| s.name()).collect();
        format!("unknown sampler '{name}' (known: {})", known.join(", "))
    })
}

/// Every option of a bake besides the scene (see `surfcache bake --help`).
#[derive(Clone, Debug)]
pub struct BakeOptions {
    pub method: Method,
    pub sampler: Sampler,
    pub max_rel_error: f32,
    pub min_samples: Option<u32>,
    pub max_samples: Option<u32>,
    pub bounces: Option<u32>,
    pub seed: u64,
    /// Irradiance-map samples or lightmap texels per metre (the method's own if `None`).
    pub density: Option<f32>,
    pub interpolation_error: Option<f32>,
    pub gather: u32,
    pub both_sides: bool,
}

impl BakeOptions {
    /// Checks the options and turns them into the settings of a [`BakeJob`].
    pub fn settings(&self) -> Result<BakeSettings> {
        if !(self.max_rel_error.is_finite() && self.max_rel_error > 0.0) {
            bail!("--max-rel-error must be a positive number");
        }
        let defaults = EstimatorSettings::default();
        let min_samples = self.min_samples.unwrap_or(defaults.min_samples);
        let max_samples = self
            .max_samples
            .unwrap_or(defaults.max_samples.max(min_samples));
        if min_samples == 0 || max_samples < min_samples {
            bail!("need 1 ≤ --min-samples ≤ --max-samples (got {min_samples} and {max_samples})");
        }
        if self.gather > 4 {
            bail!("--gather takes at most 4 pre-passes");
        }
        let mut cache = CacheSettings::for_method(self.method);
        cache.set_both_sides(self.both_sides);
        if let Some(d) = self.density {
            if !(d.is_finite() && d > 0.0) {
                bail!("--density must be a positive number");
            }
            cache.set_density(d);
        }
        if let Some(e) = self.interpolation_error {
            if !(e.is_finite() && e > 0.0) {
                bail!("--interpolation-error must be a positive number");
            }
            cache.set_interpolation_error(e);
        }
        Ok(BakeSettings {
            cache,
            estimator: EstimatorSettings {
                sampler: self.sampler,
                max_rel_error: self.max_rel_error,
                min_samples,
                max_samples,
                floor: 0.0,
                max_bounces: self.bounces,
            },
            seed: self.seed,
            gather_passes: self.gather,
        })
    }
}

/// A finished bake: the final cache, the job's figures, the settings it used (floor
/// filled in) and its wall-clock time.
pub struct Baked {
    pub cache: Cache,
    pub progress: JobProgress,
    pub settings: BakeSettings,
    pub seconds: f64,
}

/// Bakes `settings` on `scene` on a pool of `threads` workers, showing a progress line.
/// `stop` is asked between steps with the time and progress so far; when it says so the
/// bake is abandoned and `Ok(None)` returned.
pub fn bake(
    scene: &TracedScene,
    settings: BakeSettings,
    threads: Option<usize>,
    stop: &(dyn Fn(Duration, &JobProgress) -> bool + Sync),
) -> Result<Option<Baked>> {
    let start = Instant::now();
    let baked = with_threads(threads, || -> Result<_> {
        let mut job = BakeJob::new(settings);
        let bar = ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("bake {spinner} {msg} [{elapsed_precise}]")
                .expect("static template"),
        );
        while !job.step(scene, 1024) {
            let p = job.progress();
            if stop(start.elapsed(), &p) {
                bar.finish_and_clear();
                return Ok(None);
            }
            let secs = start.elapsed().as_secs_f64().max(1e-9);
            bar.set_message(format!(
                "pass {}/{} round {}: {} points done, {} pending, {:.1} Mrays/s",
                p.pass + 1,
                p.passes,
                p.current.rounds + 1,
                p.current.points_done,
                p.current.points_pending,
                p.rays as f64 / secs / 1e6
            ));
            bar.tick();
        }
        bar.finish_and_clear();
        let mut outcome = job
            .into_outcome()
            .context("internal error: the bake did not finish")?;
        let cache = outcome
            .passes
            .pop()
            .context("internal error: no final pass")?;
        let cache = std::sync::Arc::try_unwrap(cache).unwrap_or_else(|shared| (*shared).clone());
        Ok(Some((cache, outcome.progress, outcome.settings)))
    })??;
    Ok(baked.map(|(cache, progress, settings)| Baked {
        cache,
        progress,
        settings,
        seconds: start.elapsed().as_secs_f64(),
    }))
}
