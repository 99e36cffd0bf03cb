//! `surfcache points`: random query points on a scene's surfaces, for `reference` and
//! `query`.

use crate::scene_args::{EnvArgs, LoadedWorld};
use anyhow::{Result, bail};
use std::path::PathBuf;
use surfcache_core::sampling::Rng;

#[derive(clap::Args)]
pub struct PointsArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    /// Number of points, distributed uniformly by surface area.
    #[arg(long, default_value_t = 2000)]
    count: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Which side each point's normal selects: front (counter-clockwise face), back, or
    /// random.
    #[arg(long, default_value = "front")]
    side: String,
    /// Output CSV x,y,z,nx,ny,nz [default: stdout].
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
}

pub fn run(args: PointsArgs) -> Result<()> {
    let loaded = LoadedWorld::load(&args.scene, &EnvArgs::default())?;
    let scene = loaded.traced()?;
    let areas = scene.area_distribution();
    let mut rng = Rng::new(args.seed, 0x9017_5000);
    let mut rows = Vec::with_capacity(args.count);
    for _ in 0..args.count {
        let front = match args.side.as_str() {
            "front" => true,
            "back" => false,
            "random" => rng.next_f32() < 0.5,
            other => bail!("unknown side '{other}' (known: front, back, random)"),
        };
        let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), front);
        // Report the side through the geometric normal: CONTRACT.md picks the side whose
        // geometric normal points along n.
        let (x, n) = (p.position, p.geometric_normal);
        rows.push(format!("{},{},{},{},{},{}", x.x, x.y, x.z, n.x, n.y, n.z));
    }
    crate::points::write_results(args.output.as_deref(), "x,y,z,nx,ny,nz", &rows)
}
