//! Embree 3 beside `surfcache trace` (scripts/bench_embree.sh).
//!
//! - `embree_compare trace SCENE RAYS.bin [--any-hit] [--threads N] [-o HITS.bin]`: the same
//!   rays, file formats and JSON line as `surfcache trace`, traced by Embree's single-ray
//!   queries (`rtcIntersect1` / `rtcOccluded1`, incoherent context) over the triangles
//!   surfcache traces (the scene flattened by `TracedScene`), built at Embree's high quality.
//! - `embree_compare compare A.bin B.bin [--any-hit]`: how many rays two HITS.bin files
//!   agree on (closest hit: both miss, or relative t difference ≤ 1e-4), as one JSON line.

use anyhow::{Context, Result, bail};
use embree::{BuildQuality, Device, Geometry, IntersectContext, Ray, RayHit, Scene, TriangleMesh};
use rayon::prelude::*;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().any(|a| a == name);
    let value = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let positional: Vec<&String> = {
        let mut out = Vec::new();
        let mut skip = false;
        for a in &args {
            if skip {
                skip = false;
            } else if a == "--threads" || a == "-o" {
                skip = true;
            } else if !a.starts_with("--") {
                out.push(a);
            }
        }
        out
    };
    match positional.first().map(|s| s.as_str()) {
        Some("trace") if positional.len() == 3 => trace(
            positional[1],
            positional[2],
            flag("--any-hit"),
            value("--threads").map(|t| t.parse()).transpose()?,
            value("-o"),
        ),
        Some("compare") if positional.len() == 3 => {
            compare(positional[1], positional[2], flag("--any-hit"))
        }
        _ => bail!(
            "usage: embree_compare trace SCENE RAYS.bin [--any-hit] [--threads N] [-o HITS.bin] \
             | compare A.bin B.bin [--any-hit]"
        ),
    }
}

fn read_f32(path: &str) -> Result<Vec<f32>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read '{path}'"))?;
    if bytes.len() % 4 != 0 {
        bail!("'{path}' is not a list of f32");
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

fn trace(
    scene: &str,
    rays: &str,
    any_hit: bool,
    threads: Option<usize>,
    out: Option<String>,
) -> Result<()> {
    let values = read_f32(rays)?;
    if values.len() % 8 != 0 {
        bail!("rays file '{rays}' is not a list of 8-f32 records");
    }
    let loaded = surfcache_io::load_scene(scene)?;
    let traced = surfcache_trace::TracedScene::new(&loaded.scene)?;
    let positions = traced.positions();

    let device = Device::new();
    let build = Instant::now();
    let mut mesh = TriangleMesh::unanimated(&device, positions.len(), 3 * positions.len());
    {
        let mut v = mesh.vertex_buffer.map();
        for (i, p) in positions.iter().flatten().enumerate() {
            v[i] = cgmath::Vector4::new(p.x, p.y, p.z, 0.0);
        }
    }
    {
        let mut idx = mesh.index_buffer.map();
        for i in 0..positions.len() {
            let k = 3 * i as u32;
            idx[i] = cgmath::Vector3::new(k, k + 1, k + 2);
        }
    }
    let mut geometry = Geometry::Triangle(mesh);
    geometry.commit();
    let mut scene = Scene::new(&device);
    // SAFETY: a valid scene handle.
    unsafe { embree::sys::rtcSetSceneBuildQuality(scene.handle(), BuildQuality::HIGH) };
    scene.attach_geometry(geometry);
    let committed = scene.commit();
    let build_seconds = build.elapsed().as_secs_f64();

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()?;
    let mut results = vec![0f32; values.len() / 8];
    const CHUNK: usize = 4096;
    let trace_seconds = pool.install(|| {
        let start = Instant::now();
        results
            .par_chunks_mut(CHUNK)
            .zip(values.par_chunks(8 * CHUNK))
            .for_each(|(out, rays)| {
                let mut ctx = IntersectContext::incoherent();
                for (r, v) in out.iter_mut().zip(rays.chunks_exact(8)) {
                    let o = cgmath::Vector3::new(v[0], v[1], v[2]);
                    let d = cgmath::Vector3::new(v[3], v[4], v[5]);
                    let ray = Ray::segment(o, d, v[6].max(0.0), v[7]);
                    *r = if any_hit {
                        let mut ray = ray;
                        committed.occluded(&mut ctx, &mut ray);
                        (ray.tfar == f32::NEG_INFINITY) as u32 as f32
                    } else {
                        let mut hit = RayHit::new(ray);
                        committed.intersect(&mut ctx, &mut hit);
                        if hit.hit.hit() {
                            hit.ray.tfar
                        } else {
                            f32::INFINITY
                        }
                    };
                }
            });
        start.elapsed().as_secs_f64()
    });
    let hits = if any_hit {
        results.iter().filter(|&&r| r == 1.0).count()
    } else {
        results.iter().filter(|r| r.is_finite()).count()
    };
    if let Some(path) = out {
        let bytes: Vec<u8> = results.iter().flat_map(|r| r.to_le_bytes()).collect();
        std::fs::write(&path, bytes).with_context(|| format!("cannot write '{path}'"))?;
    }
    let n = results.len();
    println!(
        "{}",
        serde_json::json!({
            "rays": n,
            "hits": hits,
            "build_seconds": build_seconds,
            "trace_seconds": trace_seconds,
            "mrays_per_s": n as f64 / trace_seconds / 1e6,
        })
    );
    Ok(())
}

fn compare(a: &str, b: &str, any_hit: bool) -> Result<()> {
    let (a, b) = (read_f32(a)?, read_f32(b)?);
    if a.len() != b.len() {
        bail!("the files hold {} and {} rays", a.len(), b.len());
    }
    let (mut same, mut close, mut hit_miss, mut different_t) = (0usize, 0usize, 0usize, 0usize);
    for (&x, &y) in a.iter().zip(&b) {
        if x == y {
            same += 1;
        } else if any_hit || x.is_finite() != y.is_finite() {
            hit_miss += 1;
        } else if (x - y).abs() <= 1e-4 * x.abs().max(y.abs()) {
            close += 1;
        } else {
            different_t += 1;
        }
    }
    println!(
        "{}",
        serde_json::json!({
            "rays": a.len(),
            "identical": same,
            "t_within_1e-4": close,
            "hit_vs_miss": hit_miss,
            "different_t": different_t,
        })
    );
    Ok(())
}
