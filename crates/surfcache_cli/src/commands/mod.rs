//! One module per subcommand.

mod compare;
mod export;
mod points;
mod rays;
mod reference;
mod trace;

use crate::scene_args::EnvArgs;
use anyhow::{Result, bail};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
    /// Brute-force path-traced irradiance E(x, n) at query points (no cache).
    Reference(reference::ReferenceArgs),
    /// Ray-tracing benchmark and oracle: traces RAYS.bin (8 little-endian f32 per ray:
    /// ox,oy,oz,dx,dy,dz,tmin,tmax; t in units of the direction's length).
    Trace(trace::TraceArgs),
    /// Writes a RAYS.bin for `trace`: incoherent rays leaving surfaces or camera rays.
    Rays(rays::RaysArgs),
    /// Writes a scene (e.g. a built-in one) as glTF, with its sky as OpenEXR beside it.
    Export(export::ExportArgs),
    /// Writes random query points (x,y,z,nx,ny,nz) uniformly distributed over a scene's
    /// surfaces.
    Points(points::PointsArgs),
    /// Error of a result CSV against a reference CSV (relative RMS; one JSON line).
    Compare(compare::CompareArgs),
    /// Bakes a surface cache (not yet implemented).
    Bake(BakeArgs),
    /// Answers E(x, n) from a finished bake (not yet implemented).
    Query(QueryArgs),
}

/// `surfcache bake` options (CONTRACT.md).
#[derive(clap::Args)]
pub struct BakeArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// vertex, irradiance-map or lightmap.
    #[arg(long)]
    method: Option<String>,
    /// Relative error bound of one surface estimate.
    #[arg(long, default_value_t = 0.01)]
    max_rel_error: f32,
    #[arg(long)]
    min_samples: Option<u32>,
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
    /// Output directory.
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

/// `surfcache query` options (CONTRACT.md).
#[derive(clap::Args)]
pub struct QueryArgs {
    out_dir: PathBuf,
    points: PathBuf,
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
}

pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Reference(args) => reference::run(args),
        Command::Trace(args) => trace::run(args),
        Command::Rays(args) => rays::run(args),
        Command::Export(args) => export::run(args),
        Command::Points(args) => points::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Bake(_) => {
            bail!("bake is not yet implemented (the surface caches land with the caches issue)")
        }
        Command::Query(_) => {
            bail!("query is not yet implemented (the surface caches land with the caches issue)")
        }
    }
}
