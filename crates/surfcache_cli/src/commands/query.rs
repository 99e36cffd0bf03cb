//! `surfcache query`: baked irradiance E(x, n) at query points, from a bake directory
//! alone (docs/cli.md).

use crate::{
    bake_dir::{read_archive, read_archive_of},
    points::{lookup_points, lookup_published, read_points, write_results},
    scene_args::{EnvArgs, LoadedWorld},
};
use anyhow::{Context, Result};
use std::path::PathBuf;
use surfcache_cache::SurfaceCache;
use surfcache_io::Untrusted;

/// `surfcache query` options (docs/cli.md).
#[derive(clap::Args)]
pub struct QueryArgs {
    /// A directory written by `surfcache bake`.
    out_dir: PathBuf,
    /// CSV with header x,y,z,nx,ny,nz: points on surfaces (metres) and the unit normal of
    /// the side asked about.
    points: PathBuf,
    /// Output CSV x,y,z,r,g,b (W/m²) [default: stdout].
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
    /// Look up through the textures the bake publishes for this scene (the .gltf/.glb or
    /// built-in scene that was baked), sampled plainly bilinear as a game engine does
    /// (UV1, then the texture of the instance and side), instead of the cache's own lookup
    /// (which also honours crossings): what a player sees.
    #[arg(long, value_name = "SCENE")]
    published: Option<String>,
}

pub fn run(args: QueryArgs) -> Result<()> {
    let queries = read_points(&args.points)?;
    let values = match &args.published {
        Some(scene_name) => {
            let scene = LoadedWorld::load(scene_name, &EnvArgs::default())?.traced()?;
            let archive = read_archive_of(&args.out_dir, &scene, scene_name)?;
            lookup_published(&scene, &archive.cache.publish(&scene), &queries)
        }
        None => {
            let archive = read_archive(&args.out_dir)?;
            let geometry = archive
                .geometry()
                .with_context(|| format!("'{}'", Untrusted::path(&args.out_dir)))?;
            lookup_points(&geometry, &archive.cache, &queries)
        }
    };
    let mut off_surface = 0;
    let rows: Vec<String> = queries
        .iter()
        .zip(&values)
        .map(|(q, v)| {
            let p = q.position;
            match v {
                Some(e) => format!("{},{},{},{},{},{}", p.x, p.y, p.z, e.x, e.y, e.z),
                None => {
                    off_surface += 1;
                    format!("{},{},{},nan,nan,nan", p.x, p.y, p.z)
                }
            }
        })
        .collect();
    if off_surface > 0 {
        crate::warn(&format!(
            "{off_surface} point(s) lie farther than 1e-4 of the scene diagonal from every surface: nan"
        ));
    }
    write_results(args.output.as_deref(), "x,y,z,r,g,b", &rows)
}
