//! `surfcache bake`: bakes a surface cache and writes it, its textures, the scene with
//! UV1 and a report into an output directory (docs/cli.md).

use crate::{
    bake_dir::{self, StagingDir},
    baking::{self, BakeOptions, Baked, parse_method, parse_sampler},
    scene_args::{EnvArgs, LoadedWorld},
};
use anyhow::{Result, bail};
use serde_json::{Value, json};
use std::{
    path::PathBuf,
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
};
use surfcache_cache::{
    CacheStats, Method, SurfaceCache,
    archive::BakeArchive,
    bake::{BakeSettings, DEFAULT_GATHER_PASSES, FLOOR_FRACTION},
};
use surfcache_io::Untrusted;
use surfcache_trace::TracedScene;

/// `surfcache bake` options (docs/cli.md, plus the project's own).
#[derive(clap::Args)]
pub struct BakeArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// vertex, irradiance-map (per-triangle adaptive, the thesis) or lightmap (texels)
    /// [default: lightmap].
    #[arg(long)]
    method: Option<String>,
    /// Relative error bound of one surface estimate: sampling stops once the standard error
    /// of the mean is at most this fraction of E + ε (ε: 1 % of the scene's mean
    /// irradiance).
    #[arg(long, default_value_t = 0.01)]
    max_rel_error: f32,
    /// Fewest hemisphere samples per estimate [default: 64 for lightmaps and irradiance
    /// maps, whose samples are shared with their neighbours; 256 for vertex lighting].
    #[arg(long)]
    min_samples: Option<u32>,
    /// Most hemisphere samples per estimate [default: 1024 for lightmaps and irradiance
    /// maps; 65536 for vertex lighting].
    #[arg(long)]
    max_samples: Option<u32>,
    /// Sample budget: exactly N hemisphere samples per estimate (per texel, per sample
    /// point), as engine bakers count them, instead of the error bound; lightmaps still
    /// share samples between neighbours. Replaces --min-samples and --max-samples.
    #[arg(long)]
    samples: Option<u32>,
    /// Maximum number of indirect bounces [default: unlimited, Russian roulette].
    #[arg(long)]
    bounces: Option<u32>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Hemisphere sampler: uniform (the thesis), cosine, qmc, mis, best.
    #[arg(long, default_value = "best")]
    sampler: String,
    /// Irradiance maps: samples per metre that set each triangle's highest order;
    /// lightmaps: texels per metre [default: the method's own].
    #[arg(long)]
    density: Option<f32>,
    /// Irradiance maps: a grid cell stops refining when its new samples differ from the
    /// coarser interpolation by at most this relative error [default: the method's own].
    #[arg(long)]
    interpolation_error: Option<f32>,
    /// Most bounce passes before the final one: pass 0 bakes direct light, each later
    /// pass ends its paths at their first hit with the irradiance of the pass before
    /// (final gathering); they stop once the bounce series has converged. 0 traces every
    /// path to its end (Russian roulette).
    #[arg(long, default_value_t = DEFAULT_GATHER_PASSES)]
    gather: u32,
    /// Which sides of the surfaces to bake: both, or front (counter-clockwise) only.
    #[arg(long, default_value = "both")]
    sides: String,
    /// Irradiance maps: estimate every triangle's corners on its own instead of once for
    /// the triangles around a vertex that may share them.
    #[arg(long)]
    no_share_corners: bool,
    /// Lightmaps and irradiance maps: passes of the filter that shares samples between
    /// neighbouring texels or grid samples (docs/design.md, Filtering); 0 keeps every
    /// estimate on its own [default: 1].
    #[arg(long)]
    filter_passes: Option<u32>,
    /// Lightmaps and irradiance maps: draw every direction cosine-weighted instead of
    /// through the guides texel blocks and refining grids learn from their earlier
    /// rounds (docs/design.md, Guiding).
    #[arg(long)]
    no_guiding: bool,
    /// Output directory (created; replaced if it holds an earlier bake).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

pub fn run(args: BakeArgs) -> Result<()> {
    let options = args.options()?;
    let settings = options.settings()?;
    let sample_range = (
        settings.estimator.min_samples,
        settings.estimator.max_samples,
    );
    let staging = StagingDir::create(&args.out)?;

    let mut loaded = LoadedWorld::load(&args.scene, &args.env)?;
    let scene = loaded.traced()?;
    let cancel = cancel_on_ctrl_c();
    let Some(baked) = baking::bake(&mut loaded, settings, args.threads, &|_, _| {
        cancel.load(Ordering::SeqCst)
    })?
    else {
        bail!(
            "interrupted: nothing was written to '{}'",
            Untrusted::path(&args.out)
        );
    };
    let stats = baked.cache.stats();

    // Outputs: archive for `query`, textures, the scene with UV1, the report.
    let lightmaps = bake_dir::write_lightmaps(&staging, &loaded, &scene, &baked.textures)?;
    let settings = settings_report(&args, &options, sample_range, &baked.settings);
    let report = bake_report(
        &loaded,
        &scene,
        &baked,
        &stats,
        options.method,
        lightmaps,
        settings,
    );
    let archive = BakeArchive::new(&scene, baked.cache);
    staging.write("cache.bin", &archive.to_bytes())?;
    staging.write(
        "report.json",
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    staging.commit()?;
    eprintln!(
        "baked {} ({}) in {:.1} s: {} sample points, {} bytes -> {}",
        loaded.name,
        options.method.name(),
        baked.seconds,
        stats.sample_points,
        stats.cache_bytes,
        Untrusted::path(&args.out)
    );
    Ok(())
}

impl BakeArgs {
    /// The bake options these arguments ask for (method, sampler and sides parsed).
    fn options(&self) -> Result<BakeOptions> {
        let method = match &self.method {
            None => Method::default(),
            Some(m) => parse_method(m)?,
        };
        let sampler = parse_sampler(&self.sampler)?;
        let both_sides = match self.sides.as_str() {
            "both" => true,
            "front" => false,
            other => bail!("unknown --sides '{other}' (known: both, front)"),
        };
        Ok(BakeOptions {
            method,
            sampler,
            max_rel_error: self.max_rel_error,
            min_samples: self.min_samples,
            max_samples: self.max_samples,
            samples: self.samples,
            bounces: self.bounces,
            seed: self.seed,
            density: self.density,
            interpolation_error: self.interpolation_error,
            gather: self.gather,
            both_sides,
            share_corners: !self.no_share_corners,
            filter_passes: self.filter_passes,
            guiding: !self.no_guiding,
        })
    }
}

/// A flag that Ctrl-C raises, for the bake to stop at.
fn cancel_on_ctrl_c() -> Arc<AtomicBool> {
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // A second handler cannot be installed (e.g. in tests); cancelling then falls back
        // to the default signal behaviour, which still leaves only the staging directory.
        let _ = ctrlc::set_handler(move || cancel.store(true, Ordering::SeqCst));
    }
    cancel
}

/// The `report.json` of a bake: the cache's figures, the bake's progress and timing, the
/// lightmaps written and the `settings` object ([`settings_report`]).
fn bake_report(
    loaded: &LoadedWorld,
    scene: &TracedScene,
    baked: &Baked,
    stats: &CacheStats,
    method: Method,
    lightmaps: Value,
    settings: Value,
) -> Value {
    let floor = baked.settings.estimator.floor;
    let mean = floor / FLOOR_FRACTION;
    let progress = &baked.progress;
    json!({
        "scene": loaded.name,
        "method": method.name(),
        "triangles": scene.triangle_count(),
        "sample_points": stats.sample_points,
        "rays_traced": progress.rays,
        "bake_seconds": baked.seconds,
        "cache_bytes": stats.cache_bytes,
        "samples": stats.samples,
        "mean_samples_per_point": stats.samples as f64 / stats.sample_points.max(1) as f64,
        "max_samples_per_point": stats.max_samples_per_point,
        "mean_rel_error": stats.mean_rel_error,
        "order_histogram": stats.order_histogram,
        "buried": stats.buried,
        "dilated_texels": stats.dilated_texels,
        "rounds": progress.current.rounds,
        "passes": progress.passes,
        "scene_mean_irradiance": mean,
        "relative_error_floor": floor,
        "lightmaps": lightmaps,
        "settings": settings,
    })
}

/// The `settings` object of `report.json`: the options as given, the sample range
/// (`min_samples`, `max_samples`) they resolved to and the cache settings `baked` used.
fn settings_report(
    args: &BakeArgs,
    options: &BakeOptions,
    (min_samples, max_samples): (u32, u32),
    baked: &BakeSettings,
) -> Value {
    json!({
        "scene": args.scene,
        "env": args.env.env.as_ref().map(|p| p.display().to_string()),
        "env_color": args.env.env_color.map(|c| c.to_array()),
        "env_intensity": args.env.env_intensity,
        "method": options.method.name(),
        "max_rel_error": args.max_rel_error,
        "min_samples": min_samples,
        "max_samples": max_samples,
        "samples": args.samples,
        "bounces": args.bounces,
        "seed": args.seed,
        "threads": args.threads.unwrap_or_else(rayon::current_num_threads),
        "sampler": options.sampler.name(),
        "sides": args.sides,
        "gather": args.gather,
        "cache": baked.cache,
    })
}
