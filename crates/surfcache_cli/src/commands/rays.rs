//! `surfcache rays`: ray files for `trace` benchmarks.

use crate::{
    camera::Camera,
    scene_args::{EnvArgs, LoadedWorld},
};
use anyhow::{Result, bail};
use glam::{Vec2, Vec3};
use std::path::PathBuf;
use surfcache_core::{
    geometry::to_world,
    sampling::{Rng, cosine_hemisphere, uniform_sphere},
};

#[derive(clap::Args)]
pub struct RaysArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell).
    scene: String,
    /// `surface`: origins uniform over the surface area (random side, lifted by the spawn
    /// offset) with cosine-distributed directions; `camera`: a pinhole camera's primary rays;
    /// `box`: incoherent rays, origins uniform in the scene's bounding box and directions
    /// uniform over the sphere.
    #[arg(long, default_value = "surface")]
    kind: String,
    /// Number of rays.
    #[arg(long, default_value_t = 1_000_000)]
    count: usize,
    /// `surface` rays per origin, one after the other (a point's hemisphere samples, as a
    /// bake draws them); the count is rounded up to a multiple of it.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    per_point: u32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Camera eye and target `ex,ey,ez,tx,ty,tz` [default: inside the scene's bounds,
    /// 45% of its depth in front of the centre, looking along +Z].
    #[arg(long, value_name = "EX,EY,EZ,TX,TY,TZ")]
    camera: Option<String>,
    /// Vertical field of view of the camera in degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f32,
    /// Output RAYS.bin.
    #[arg(short = 'o', long = "out")]
    output: PathBuf,
}

pub fn run(args: RaysArgs) -> Result<()> {
    let loaded = LoadedWorld::load(&args.scene, &EnvArgs::default())?;
    let scene = loaded.traced()?;
    let mut rng = Rng::new(args.seed, 0);
    let mut out = Vec::with_capacity(args.count * 32);
    let mut push = |o: Vec3, d: Vec3| {
        for v in [o.x, o.y, o.z, d.x, d.y, d.z, 0.0, f32::INFINITY] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    };
    match args.kind.as_str() {
        "surface" => {
            let areas = scene.area_distribution();
            let k = args.per_point as usize;
            for _ in 0..args.count.div_ceil(k) {
                let front = rng.next_f32() < 0.5;
                let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), front);
                let origin = scene.spawn_origin(&p);
                for _ in 0..k {
                    let d = to_world(cosine_hemisphere(rng.next_vec2()), p.geometric_normal);
                    push(origin, d);
                }
            }
        }
        "box" => {
            let (lo, hi) = bounds(scene.positions());
            for _ in 0..args.count {
                let u = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                push(lo + (hi - lo) * u, uniform_sphere(rng.next_vec2()));
            }
        }
        "camera" => {
            let (lo, hi) = bounds(scene.positions());
            // Default: inside the bounds, 45 % of the depth in front of the centre.
            let c = 0.5 * (lo + hi);
            let eye = c - Vec3::Z * 0.45 * (hi.z - lo.z);
            let camera = Camera::from_arg(args.camera.as_deref(), args.fov, (eye, eye + Vec3::Z))?;
            let side = (args.count as f32).sqrt().ceil() as usize;
            for k in 0..args.count {
                let (i, j) = (k % side, k / side);
                let s = (Vec2::new(i as f32, j as f32) + 0.5) / side as f32 * 2.0 - 1.0;
                push(camera.eye, camera.direction(s, 1.0));
            }
        }
        other => bail!("unknown ray kind '{other}' (known: surface, camera, box)"),
    }
    Ok(surfcache_io::write_file_atomically(&args.output, &out)?)
}

/// Bounding box of the triangles' corners.
pub(super) fn bounds(positions: &[[Vec3; 3]]) -> (Vec3, Vec3) {
    positions.iter().flatten().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}
