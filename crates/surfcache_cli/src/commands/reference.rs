//! `surfcache reference`: brute-force path-traced E(x, n) at query points.

use crate::{
    points::{read_points, write_results},
    scene_args::{EnvArgs, LoadedWorld, with_threads},
};
use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use surfcache_trace::{EstimatorSettings, Sampler, reference_irradiance};

#[derive(clap::Args)]
pub struct ReferenceArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// CSV with header x,y,z,nx,ny,nz: points on surfaces (metres) and the unit normal of
    /// the side asked about.
    points: PathBuf,
    /// Hemisphere samples per point.
    #[arg(long)]
    samples: u32,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Hemisphere sampler: uniform (the thesis), cosine, qmc (cosine + scrambled Sobol),
    /// mis (cosine + next-event estimation with MIS), best (mis + scrambled Sobol).
    #[arg(long, default_value = "best")]
    sampler: String,
    /// Maximum number of indirect bounces [default: unlimited, Russian roulette].
    #[arg(long)]
    bounces: Option<u32>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Output CSV x,y,z,r,g,b,rel_std (W/m²) [default: stdout].
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
}

pub fn run(args: ReferenceArgs) -> Result<()> {
    let Some(sampler) = Sampler::from_name(&args.sampler) else {
        let known: Vec<&str> = Sampler::ALL.iter().map(|s| s.name()).collect();
        bail!(
            "unknown sampler '{}' (known: {})",
            args.sampler,
            known.join(", ")
        );
    };
    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    let queries = read_points(&args.points)?;
    let loaded = LoadedWorld::load(&args.scene, &args.env)?;
    let scene = loaded.traced()?;
    let bar = ProgressBar::new(queries.len() as u64).with_style(
        ProgressStyle::with_template("reference {bar:40} {pos}/{len} points, eta {eta}")
            .expect("static template"),
    );
    let settings = EstimatorSettings::fixed(sampler, args.samples, args.bounces);
    let results = with_threads(args.threads, || {
        reference_irradiance(&scene, &queries, &settings, args.seed, &|| bar.inc(1))
    })?;
    bar.finish_and_clear();
    let mut off_surface = 0;
    let rows: Vec<String> = queries
        .iter()
        .zip(&results)
        .map(|(q, r)| {
            let p = q.position;
            match r {
                Some(e) => {
                    let v = e.value;
                    format!(
                        "{},{},{},{},{},{},{}",
                        p.x,
                        p.y,
                        p.z,
                        v.x,
                        v.y,
                        v.z,
                        e.relative_std()
                    )
                }
                None => {
                    off_surface += 1;
                    format!("{},{},{},nan,nan,nan,nan", p.x, p.y, p.z)
                }
            }
        })
        .collect();
    if off_surface > 0 {
        crate::warn(&format!(
            "{off_surface} point(s) lie farther than 1e-4 of the scene diagonal from every surface: nan"
        ));
    }
    write_results(args.output.as_deref(), "x,y,z,r,g,b,rel_std", &rows)
}
