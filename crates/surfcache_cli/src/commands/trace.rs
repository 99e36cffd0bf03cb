//! `surfcache trace`: throughput benchmark and correctness oracle for the BVH.

use crate::scene_args::{EnvArgs, LoadedWorld, with_threads};
use anyhow::{Context, Result, bail};
use glam::Vec3;
use rayon::prelude::*;
use std::{path::PathBuf, time::Instant};
use surfcache_io::Untrusted;

#[derive(clap::Args)]
pub struct TraceArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    /// Little-endian f32 records ox,oy,oz,dx,dy,dz,tmin,tmax (32 bytes per ray).
    rays: PathBuf,
    /// Occlusion query: hit = anything within [tmin, tmax].
    #[arg(long)]
    any_hit: bool,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Per ray one little-endian f32: closest-hit t (+inf for a miss), or 1.0/0.0 with --any-hit.
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
}

/// Rays per parallel work item: large enough to amortise scheduling, small enough to balance.
const CHUNK: usize = 4096;

pub fn run(args: TraceArgs) -> Result<()> {
    let bytes = std::fs::read(&args.rays)
        .with_context(|| format!("cannot read rays file '{}'", Untrusted::path(&args.rays)))?;
    if bytes.len() % 32 != 0 {
        bail!(
            "rays file '{}' has {} bytes, not a multiple of 32 (8 f32 per ray)",
            Untrusted::path(&args.rays),
            bytes.len()
        );
    }
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let loaded = LoadedWorld::load(&args.scene, &EnvArgs::default())?;
    let scene = loaded.traced()?;
    let bvh = scene.bvh();
    let mut results = vec![0f32; values.len() / 8];
    let any_hit = args.any_hit;
    let trace_seconds = with_threads(args.threads, || {
        let start = Instant::now();
        results
            .par_chunks_mut(CHUNK)
            .zip(values.par_chunks(8 * CHUNK))
            .for_each(|(out, rays)| {
                for (r, ray) in out.iter_mut().zip(rays.chunks_exact(8)) {
                    let o = Vec3::new(ray[0], ray[1], ray[2]);
                    let d = Vec3::new(ray[3], ray[4], ray[5]);
                    let (tmin, tmax) = (ray[6], ray[7]);
                    let valid = o.is_finite()
                        && d.is_finite()
                        && d.length_squared() > 0.0
                        && !tmin.is_nan()
                        && !tmax.is_nan()
                        && tmin <= tmax;
                    *r = if !valid {
                        if any_hit { 0.0 } else { f32::INFINITY }
                    } else if any_hit {
                        bvh.occluded(o, d, tmin.max(0.0), tmax) as u32 as f32
                    } else {
                        bvh.closest_hit(o, d, tmin.max(0.0), tmax)
                            .map_or(f32::INFINITY, |h| h.t)
                    };
                }
            });
        start.elapsed().as_secs_f64()
    })?;
    let (hits, sum_t) = if any_hit {
        let h = results.iter().filter(|&&r| r == 1.0).count();
        (h, h as f64)
    } else {
        results
            .iter()
            .filter(|r| r.is_finite())
            .fold((0, 0.0), |(n, s), &t| (n + 1, s + t as f64))
    };
    if let Some(path) = &args.output {
        let out: Vec<u8> = results.iter().flat_map(|r| r.to_le_bytes()).collect();
        surfcache_io::write_file_atomically(path, &out)?;
    }
    let rays = results.len();
    let json = serde_json::json!({
        "rays": rays,
        "hits": hits,
        "build_seconds": bvh.build_seconds,
        "trace_seconds": trace_seconds,
        "mrays_per_s": if trace_seconds > 0.0 { rays as f64 / trace_seconds / 1e6 } else { 0.0 },
        "sum_t": sum_t,
    });
    println!("{json}");
    Ok(())
}
