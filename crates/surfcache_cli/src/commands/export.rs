//! `surfcache export`: writes a scene (built-in or loaded) as glTF, its sky as OpenEXR.

use crate::scene_args::EnvArgs;
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ExportArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// Output .gltf (a .bin, and an _environment.exr for a map sky, are written beside it).
    #[arg(short = 'o', long = "out")]
    output: PathBuf,
}

pub fn run(args: ExportArgs) -> Result<()> {
    let mut scene = surfcache_io::load_scene(&args.scene)?.scene;
    args.env.apply(&mut scene)?;
    surfcache_io::write_gltf(&scene, &args.output, &[])?;
    Ok(())
}
