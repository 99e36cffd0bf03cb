//! `surfcache bake`: bakes a surface cache and writes it, its textures, the scene with
//! UV1 and a report into an output directory (CONTRACT.md).

use crate::{
    bake_dir::{self, StagingDir},
    scene_args::{EnvArgs, LoadedWorld},
};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::{
    path::PathBuf,
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::Instant,
};
use surfcache_cache::{
    CacheSettings, Method, SurfaceCache,
    archive::BakeArchive,
    bake::{BakeSettings, DEFAULT_GATHER_PASSES, FLOOR_FRACTION},
};
use surfcache_ecs::{
    BakeConfig, BakeStatus, BakeWaitError, PublishedLightmaps, SurfaceCacheResource,
    SurfcachePlugin,
};
use surfcache_trace::{EstimatorSettings, Sampler};

/// `surfcache bake` options (CONTRACT.md, plus the project's own).
#[derive(clap::Args)]
pub struct BakeArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// vertex, irradiance-map (per-triangle adaptive, the thesis) or lightmap (texels)
    /// [default: irradiance-map].
    #[arg(long)]
    method: Option<String>,
    /// Relative error bound of one surface estimate: sampling stops once the standard error
    /// of the mean is at most this fraction of E + ε (ε: 1 % of the scene's mean
    /// irradiance).
    #[arg(long, default_value_t = 0.01)]
    max_rel_error: f32,
    /// Fewest hemisphere samples per estimate [default: 256].
    #[arg(long)]
    min_samples: Option<u32>,
    /// Most hemisphere samples per estimate [default: 65536].
    #[arg(long)]
    max_samples: Option<u32>,
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
    /// Irradiance maps: refinement stops when new samples differ from the coarser
    /// interpolation by at most this relative error [default: the method's own].
    #[arg(long)]
    interpolation_error: Option<f32>,
    /// Gathering pre-passes: coarse irradiance maps whose irradiance ends the next pass's
    /// paths at their first hit (final gathering). 0 traces every path to its end.
    #[arg(long, default_value_t = DEFAULT_GATHER_PASSES)]
    gather: u32,
    /// Which sides of the surfaces to bake: both, or front (counter-clockwise) only.
    #[arg(long, default_value = "both")]
    sides: String,
    /// Output directory (created; replaced if it holds an earlier bake).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

pub fn run(args: BakeArgs) -> Result<()> {
    let method = match &args.method {
        None => Method::default(),
        Some(m) => Method::from_name(m).with_context(|| {
            let known: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
            format!("unknown method '{m}' (known: {})", known.join(", "))
        })?,
    };
    let Some(sampler) = Sampler::from_name(&args.sampler) else {
        let known: Vec<&str> = Sampler::ALL.iter().map(|s| s.name()).collect();
        bail!(
            "unknown sampler '{}' (known: {})",
            args.sampler,
            known.join(", ")
        );
    };
    if !(args.max_rel_error.is_finite() && args.max_rel_error > 0.0) {
        bail!("--max-rel-error must be a positive number");
    }
    let defaults = EstimatorSettings::default();
    let min_samples = args.min_samples.unwrap_or(defaults.min_samples);
    let max_samples = args
        .max_samples
        .unwrap_or(defaults.max_samples.max(min_samples));
    if min_samples == 0 || max_samples < min_samples {
        bail!("need 1 ≤ --min-samples ≤ --max-samples (got {min_samples} and {max_samples})");
    }
    let both_sides = match args.sides.as_str() {
        "both" => true,
        "front" => false,
        other => bail!("unknown --sides '{other}' (known: both, front)"),
    };
    let mut cache_settings = CacheSettings::for_method(method);
    cache_settings.set_both_sides(both_sides);
    if let Some(d) = args.density {
        if !(d.is_finite() && d > 0.0) {
            bail!("--density must be a positive number");
        }
        cache_settings.set_density(d);
    }
    if let Some(e) = args.interpolation_error {
        if !(e.is_finite() && e > 0.0) {
            bail!("--interpolation-error must be a positive number");
        }
        cache_settings.set_interpolation_error(e);
    }
    let staging = StagingDir::create(&args.out)?;

    let mut loaded = LoadedWorld::load(&args.scene, &args.env)?;
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // A second handler cannot be installed (e.g. in tests); cancelling then falls back
        // to the default signal behaviour, which still leaves only the staging directory.
        let _ = ctrlc::set_handler(move || cancel.store(true, Ordering::SeqCst));
    }
    let threads = args.threads;
    if threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    if args.gather > 4 {
        bail!("--gather takes at most 4 pre-passes");
    }
    let settings = BakeSettings {
        cache: cache_settings,
        estimator: EstimatorSettings {
            sampler,
            max_rel_error: args.max_rel_error,
            min_samples,
            max_samples,
            floor: 0.0,
            max_bounces: args.bounces,
        },
        seed: args.seed,
        gather_passes: args.gather,
    };
    // The bake is the ECS plugin's: turn baking on and run frames until it published.
    let start = Instant::now();
    loaded.world.insert_resource(BakeConfig {
        settings,
        enabled: true,
        threads,
        points_per_step: 1024,
        ..Default::default()
    });
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("bake [{elapsed_precise}] {bar:30} {msg}")
            .expect("static template"),
    );
    SurfcachePlugin::run_until_baked(
        &mut loaded.world,
        &mut loaded.schedule,
        std::time::Duration::from_millis(20),
        |world| {
            let status = world.resource::<BakeStatus>();
            bar.set_position((status.fraction * 1000.0) as u64);
            bar.set_message(format!(
                "{} samples, {:.1} Mrays/s{}",
                status.samples,
                status.rays_per_second / 1e6,
                status
                    .eta_seconds
                    .map(|s| format!(", about {s:.0} s left"))
                    .unwrap_or_default()
            ));
            !cancel.load(Ordering::SeqCst)
        },
    )
    .map_err(|e| {
        bar.finish_and_clear();
        match e {
            BakeWaitError::Stopped => anyhow::anyhow!(
                "interrupted: nothing was written to '{}'",
                args.out.display()
            ),
            BakeWaitError::Failed(e) => anyhow::anyhow!("bake failed: {e}"),
        }
    })?;
    bar.finish_and_clear();
    let baked = loaded.world.resource::<SurfaceCacheResource>().clone();
    let (Some(outcome), Some(scene)) = (baked.outcome, baked.scene) else {
        bail!("internal error: the bake did not finish");
    };
    let progress = outcome.progress;
    let settings = outcome.settings;
    let cache = outcome.cache().clone();
    // The textures the plugin published, in instance order, front before back.
    let mut textures: Vec<_> = loaded
        .world
        .resource::<PublishedLightmaps>()
        .by_entity
        .values()
        .flat_map(|l| l.front.iter().chain(l.back.iter()))
        .map(|t| (**t).clone())
        .collect();
    textures.sort_by_key(|t| (t.instance, !t.front));
    let floor = settings.estimator.floor;
    let mean = floor / FLOOR_FRACTION;
    let bake_seconds = start.elapsed().as_secs_f64();
    let stats = cache.stats();

    // Outputs: archive for `query`, textures, the scene with UV1, the report.
    let lightmaps = bake_dir::write_lightmaps(&staging, &loaded, &scene, &textures)?;
    let archive = BakeArchive::new(&scene, Arc::unwrap_or_clone(cache));
    staging.write("cache.bin", &archive.to_bytes())?;
    let report = json!({
        "scene": loaded.name,
        "method": method.name(),
        "triangles": scene.triangle_count(),
        "sample_points": stats.sample_points,
        "rays_traced": progress.rays,
        "bake_seconds": bake_seconds,
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
        "settings": {
            "scene": args.scene,
            "env": args.env.env.as_ref().map(|p| p.display().to_string()),
            "env_color": args.env.env_color.map(|c| c.to_array()),
            "env_intensity": args.env.env_intensity,
            "method": method.name(),
            "max_rel_error": args.max_rel_error,
            "min_samples": min_samples,
            "max_samples": max_samples,
            "bounces": args.bounces,
            "seed": args.seed,
            "threads": threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
            "sampler": sampler.name(),
            "sides": args.sides,
            "gather": args.gather,
            "cache": settings.cache,
        },
    });
    staging.write(
        "report.json",
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    staging.commit()?;
    eprintln!(
        "baked {} ({}) in {:.1} s: {} sample points, {} bytes -> {}",
        loaded.name,
        method.name(),
        bake_seconds,
        stats.sample_points,
        stats.cache_bytes,
        args.out.display()
    );
    Ok(())
}
