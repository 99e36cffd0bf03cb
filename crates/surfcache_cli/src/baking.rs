//! The one bake code path of the command-line tool: options into [`BakeSettings`], and
//! the ECS plugin's schedule run until it publishes the bake, with a progress line (a bar
//! on a terminal, plain lines in a log).
//! `bake` and `chart` both use it.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::time::{Duration, Instant};
use surfcache_cache::{
    Cache, CacheSettings, IrradianceTexture, Method,
    bake::{BakeSettings, JobProgress},
};
use surfcache_trace::{EstimatorSettings, Sampler};

use crate::scene_args::LoadedWorld;
use surfcache_ecs::{
    BakeConfig, BakeStatus, BakeWaitError, BakedLightmap, BakedSurfaceCache, SurfcachePlugin,
};

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

/// Most à-trous passes `--filter-passes` accepts (the footprint doubles with each).
pub const MAX_FILTER_PASSES: u32 = 8;

/// Every option of a bake besides the scene (see `surfcache bake --help`).
#[derive(Clone, Debug)]
pub struct BakeOptions {
    pub method: Method,
    pub sampler: Sampler,
    pub max_rel_error: f32,
    pub min_samples: Option<u32>,
    pub max_samples: Option<u32>,
    /// A fixed sample budget per estimate instead of the error bound.
    pub samples: Option<u32>,
    pub bounces: Option<u32>,
    pub seed: u64,
    /// Irradiance-map samples or lightmap texels per metre (the method's own if `None`;
    /// an error with vertex lighting).
    pub density: Option<f32>,
    /// Irradiance maps: the refinement bound (the method's own if `None`; an error with
    /// any other method).
    pub interpolation_error: Option<f32>,
    pub gather: u32,
    pub both_sides: bool,
    /// Irradiance maps: estimate shared corners once (`--no-share-corners` turns it off;
    /// `false` is an error with any other method).
    pub share_corners: bool,
    /// Lightmaps: passes of the texel filter (the cache's own if `None`).
    pub filter_passes: Option<u32>,
    /// Lightmaps and irradiance maps: guided directions in later rounds (`--no-guiding`
    /// turns it off).
    pub guiding: bool,
}

impl BakeOptions {
    /// Every option as `surfcache bake` has it by default, but the method, the sampler,
    /// the bound and the seed.
    pub fn defaults(method: Method, sampler: Sampler, max_rel_error: f32, seed: u64) -> Self {
        Self {
            method,
            sampler,
            max_rel_error,
            min_samples: None,
            max_samples: None,
            samples: None,
            bounces: None,
            seed,
            density: None,
            interpolation_error: None,
            gather: surfcache_cache::bake::DEFAULT_GATHER_PASSES,
            both_sides: true,
            share_corners: true,
            filter_passes: None,
            guiding: true,
        }
    }

    /// Checks the options and turns them into the settings of a [`BakeJob`].
    pub fn settings(&self) -> Result<BakeSettings> {
        if !(self.max_rel_error.is_finite() && self.max_rel_error > 0.0) {
            bail!("--max-rel-error must be a positive number");
        }
        let (min_samples, max_samples) = self.sample_range()?;
        if self.gather > 64 {
            bail!("--gather takes at most 64 bounce passes");
        }
        let cache = self.cache_settings()?;
        Ok(BakeSettings {
            cache,
            estimator: EstimatorSettings {
                sampler: self.sampler,
                max_rel_error: if self.samples.is_some() {
                    0.0
                } else {
                    self.max_rel_error
                },
                min_samples,
                max_samples,
                floor: 0.0,
                max_bounces: self.bounces,
            },
            seed: self.seed,
            gather_passes: self.gather,
            density_budget: match self.density {
                Some(_) => None,
                None => Some(surfcache_cache::bake::DEFAULT_DENSITY_BUDGET),
            },
        })
    }

    /// The hemisphere samples per estimate, `--samples` or `--min-samples`/`--max-samples`
    /// over the method's defaults.
    fn sample_range(&self) -> Result<(u32, u32)> {
        let (default_min, default_max) = self.method.default_sample_range();
        if let Some(n) = self.samples
            && (n == 0 || self.min_samples.is_some() || self.max_samples.is_some())
        {
            bail!("--samples takes a positive count and replaces --min-samples/--max-samples");
        }
        let min_samples = self.samples.or(self.min_samples).unwrap_or(default_min);
        let max_samples = self
            .samples
            .or(self.max_samples)
            .unwrap_or(default_max.max(min_samples));
        if min_samples == 0 || max_samples < min_samples {
            bail!("need 1 ≤ --min-samples ≤ --max-samples (got {min_samples} and {max_samples})");
        }
        Ok((min_samples, max_samples))
    }

    /// The cache to bake: the method's defaults with the options that apply to it; an
    /// option for another method is an error.
    fn cache_settings(&self) -> Result<CacheSettings> {
        let mut cache = CacheSettings::for_method(self.method);
        cache.set_both_sides(self.both_sides);
        if !self.share_corners {
            let CacheSettings::IrradianceMap(maps) = &mut cache else {
                bail!("--no-share-corners applies to --method irradiance-map only");
            };
            maps.share_corners = false;
        }
        if let Some(d) = self.density {
            let Some(density) = cache.density_mut() else {
                bail!("--density applies to --method irradiance-map and lightmap only");
            };
            if !(d.is_finite() && d > 0.0) {
                bail!("--density must be a positive number");
            }
            *density = d;
        }
        if let Some(e) = self.interpolation_error {
            let CacheSettings::IrradianceMap(maps) = &mut cache else {
                bail!("--interpolation-error applies to --method irradiance-map only");
            };
            if !(e.is_finite() && e > 0.0) {
                bail!("--interpolation-error must be a positive number");
            }
            maps.interpolation_error = e;
        }
        if let Some(n) = self.filter_passes {
            if n > MAX_FILTER_PASSES {
                bail!("--filter-passes takes at most {MAX_FILTER_PASSES} passes");
            }
            match &mut cache {
                CacheSettings::Lightmap(lightmap) => lightmap.filter.iterations = n,
                CacheSettings::IrradianceMap(maps) => maps.filter.iterations = n,
                _ => bail!("--filter-passes applies to --method lightmap and irradiance-map only"),
            }
        }
        if !self.guiding {
            match &mut cache {
                CacheSettings::Lightmap(lightmap) => lightmap.guiding = false,
                CacheSettings::IrradianceMap(maps) => maps.guiding = false,
                _ => bail!("--no-guiding applies to --method lightmap and irradiance-map only"),
            }
        }
        Ok(cache)
    }
}

/// Set to a number of seconds, the interval between progress lines when stderr is not a
/// terminal (default [`PROGRESS_SECONDS`]; `0` prints one every frame).
pub const PROGRESS_SECONDS_ENV: &str = "SURFCACHE_PROGRESS_SECONDS";

/// Seconds between progress lines when stderr is not a terminal.
pub const PROGRESS_SECONDS: f64 = 10.0;

/// How a bake shows its progress on stderr: a redrawn line on a terminal; elsewhere (a log,
/// a pipe) a plain line every [`PROGRESS_SECONDS`], which a log keeps as it is.
enum Progress {
    Bar(ProgressBar),
    Lines { every: Duration, next: Instant },
}

impl Progress {
    fn new() -> Self {
        use std::io::IsTerminal;
        if std::io::stderr().is_terminal() {
            return Progress::Bar(
                ProgressBar::new_spinner().with_style(
                    ProgressStyle::with_template("bake {spinner} {msg} [{elapsed_precise}]")
                        .expect("static template"),
                ),
            );
        }
        let seconds = std::env::var(PROGRESS_SECONDS_ENV)
            .ok()
            .and_then(|s| s.trim().parse::<f64>().ok())
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(PROGRESS_SECONDS);
        let every = Duration::from_secs_f64(seconds);
        Progress::Lines {
            every,
            next: Instant::now() + every,
        }
    }

    /// Shows `status`, `elapsed` after the bake began (a line is printed only when its
    /// interval has passed). `elapsed` is the wall clock, since `status` is only refreshed
    /// when a step of the job returns.
    fn show(&mut self, status: &BakeStatus, elapsed: Duration) {
        let p = &status.job;
        let eta = status
            .time_left()
            .map(|t| format!(", {t}"))
            .unwrap_or_default();
        match self {
            Progress::Bar(bar) => {
                bar.set_message(format!(
                    "pass {}/{} round {}: {:.1} % done, {} points done, {} pending, {:.1} Mrays/s{eta}",
                    p.pass + 1,
                    p.passes.max(1),
                    p.current.rounds + 1,
                    100.0 * status.fraction,
                    p.current.points_done,
                    p.current.points_pending,
                    status.rays_per_second / 1e6,
                ));
                bar.tick();
            }
            Progress::Lines { every, next } => {
                let now = Instant::now();
                if now < *next {
                    return;
                }
                *next = now + *every;
                eprintln!(
                    "bake: pass {}/{}, round {}, {:.1} % done, {:.1} Mrays/s{eta} ({:.0} s so far)",
                    p.pass + 1,
                    p.passes.max(1),
                    p.current.rounds + 1,
                    100.0 * status.fraction,
                    status.rays_per_second / 1e6,
                    elapsed.as_secs_f64(),
                );
            }
        }
    }

    fn finish(self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// A finished bake: the final cache, the job's figures, the settings it used (floor
/// filled in) and its wall-clock time.
pub struct Baked {
    pub cache: Cache,
    /// The textures the plugin published, in instance order, front side first.
    pub textures: Vec<IrradianceTexture>,
    pub progress: JobProgress,
    pub settings: BakeSettings,
    pub seconds: f64,
}

/// Bakes `settings` on the scene loaded in `loaded` through the ECS plugin (the one bake
/// path: a [`BakeConfig`] goes into the world and frames run until the plugin publishes
/// the bake), on a pool of `threads` workers, showing a progress line. `stop` is asked
/// every frame with the time and progress so far; when it says so the bake is cancelled
/// and `Ok(None)` returned.
pub fn bake(
    loaded: &mut LoadedWorld,
    settings: BakeSettings,
    threads: Option<usize>,
    stop: &(dyn Fn(Duration, &JobProgress) -> bool + Sync),
) -> Result<Option<Baked>> {
    let start = Instant::now();
    loaded.world.insert_resource(BakeConfig {
        settings,
        enabled: true,
        threads,
        points_per_step: 1024,
        ..Default::default()
    });
    let mut progress = Progress::new();
    let result = SurfcachePlugin::run_until_baked(
        &mut loaded.world,
        &mut loaded.schedule,
        Duration::from_millis(10),
        |world| {
            let status = world.resource::<BakeStatus>();
            if stop(start.elapsed(), &status.job) {
                return false;
            }
            progress.show(status, start.elapsed());
            true
        },
    );
    progress.finish();
    match result {
        Err(BakeWaitError::Stopped) => Ok(None),
        Err(BakeWaitError::Failed(e)) => bail!("bake failed: {e}"),
        Ok(done) => {
            let outcome = loaded
                .world
                .resource::<BakedSurfaceCache>()
                .outcome
                .clone()
                .context("internal error: the bake did not finish")?;
            let mut textures: Vec<IrradianceTexture> = loaded
                .world
                .query::<&BakedLightmap>()
                .iter(&loaded.world)
                .flat_map(|l| l.front.iter().chain(l.back.iter()))
                .map(|t| (**t).clone())
                .collect();
            textures.sort_by_key(|t| (t.instance, !t.front));
            Ok(Some(Baked {
                cache: (**outcome.cache()).clone(),
                textures,
                progress: outcome.progress,
                settings: outcome.settings,
                seconds: done.seconds,
            }))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Options that change nothing, with `method`.
    fn options(method: Method) -> BakeOptions {
        BakeOptions::defaults(method, Sampler::default(), 0.01, 0)
    }

    fn error(options: &BakeOptions) -> String {
        format!("{:#}", options.settings().unwrap_err())
    }

    #[test]
    fn method_options_reach_their_cache() {
        let mut maps = options(Method::IrradianceMap);
        maps.density = Some(8.0);
        maps.interpolation_error = Some(0.2);
        maps.share_corners = false;
        let settings = maps.settings().unwrap();
        let s = settings.cache.irradiance_map().unwrap();
        assert_eq!((s.density, s.interpolation_error), (8.0, 0.2));
        assert!(!s.share_corners);
        assert_eq!(settings.density_budget, None);

        let mut lightmap = options(Method::Lightmap);
        lightmap.density = Some(12.0);
        lightmap.filter_passes = Some(2);
        lightmap.guiding = false;
        let settings = lightmap.settings().unwrap();
        let s = settings.cache.lightmap().unwrap();
        assert_eq!((s.texels_per_metre, s.filter.iterations), (12.0, 2));
        assert!(!s.guiding);

        // The defaults apply to every method.
        for method in Method::ALL {
            let settings = options(method).settings().unwrap();
            assert_eq!(settings.cache, CacheSettings::for_method(method));
        }
    }

    #[test]
    fn method_options_with_another_method_are_errors() {
        let mut o = options(Method::Vertex);
        o.density = Some(8.0);
        assert_eq!(
            error(&o),
            "--density applies to --method irradiance-map and lightmap only"
        );
        for method in [Method::Vertex, Method::Lightmap] {
            let mut o = options(method);
            o.interpolation_error = Some(0.1);
            assert_eq!(
                error(&o),
                "--interpolation-error applies to --method irradiance-map only"
            );
            let mut o = options(method);
            o.share_corners = false;
            assert_eq!(
                error(&o),
                "--no-share-corners applies to --method irradiance-map only"
            );
        }
    }
}
