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
    /// Sample points a player can see instead: first hits of rays in uniformly random
    /// directions from random viewpoints in the open air of the scene (points of its
    /// bounding box from which none of 64 random rays meets the back of a single-sided
    /// surface first and at least one escapes to the sky), each on the side facing its
    /// viewpoint. `--side` is then ignored.
    #[arg(long)]
    visible: bool,
    /// Instead of sampling points, reads POINTS.csv (x,y,z,nx,ny,nz) and writes each point
    /// with its *sky view*: the share of cosine-weighted directions about its normal that
    /// meet no surface (1024 stratified rays), as x,y,z,nx,ny,nz,sky. Levels report their
    /// open-sky points (sky view 1: roofs, outer walls) apart from the rest
    /// (docs/results.md).
    #[arg(long, value_name = "POINTS.csv", conflicts_with = "visible")]
    sky_view: Option<PathBuf>,
    /// Output CSV x,y,z,nx,ny,nz [default: stdout].
    #[arg(short = 'o', long = "out")]
    output: Option<PathBuf>,
}

pub fn run(args: PointsArgs) -> Result<()> {
    let loaded = LoadedWorld::load(&args.scene, &EnvArgs::default())?;
    let scene = loaded.traced()?;
    if let Some(path) = &args.sky_view {
        let queries = crate::points::read_points(path)?;
        let rows: Vec<String> = queries
            .iter()
            .map(|q| {
                let (x, n) = (q.position, q.normal);
                let sky = sky_view(&scene, x, n).map_or("nan".to_string(), |s| s.to_string());
                format!("{},{},{},{},{},{},{sky}", x.x, x.y, x.z, n.x, n.y, n.z)
            })
            .collect();
        return crate::points::write_results(args.output.as_deref(), "x,y,z,nx,ny,nz,sky", &rows);
    }
    if args.visible {
        let rows: Vec<String> = visible_points(&scene, args.count, args.seed)?
            .into_iter()
            .map(|(x, n)| format!("{},{},{},{},{},{}", x.x, x.y, x.z, n.x, n.y, n.z))
            .collect();
        return crate::points::write_results(args.output.as_deref(), "x,y,z,nx,ny,nz", &rows);
    }
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
        // Report the side through the geometric normal: docs/cli.md picks the side whose
        // geometric normal points along n.
        let (x, n) = (p.position, p.geometric_normal);
        rows.push(format!("{},{},{},{},{},{}", x.x, x.y, x.z, n.x, n.y, n.z));
    }
    crate::points::write_results(args.output.as_deref(), "x,y,z,nx,ny,nz", &rows)
}

/// Stratified cosine-weighted rays per point of [`sky_view`] (32 × 32 cells).
const SKY_VIEW_SIDE: u32 = 32;

/// The share of cosine-weighted directions about the point's normal that escape to the
/// sky (one jittered direction per cell of a 32 × 32 grid of the sample square); `None`
/// for a point on no surface.
fn sky_view(scene: &surfcache_trace::TracedScene, x: glam::Vec3, n: glam::Vec3) -> Option<f32> {
    use surfcache_core::{geometry::to_world, sampling::cosine_hemisphere};
    let p = scene.locate(x, n)?;
    let origin = scene.spawn_origin(&p);
    let mut rng = Rng::new(0x5c1e, 0);
    let mut open = 0u32;
    for k in 0..SKY_VIEW_SIDE * SKY_VIEW_SIDE {
        let cell = glam::Vec2::new((k % SKY_VIEW_SIDE) as f32, (k / SKY_VIEW_SIDE) as f32);
        let w = to_world(
            cosine_hemisphere((cell + rng.next_vec2()) / SKY_VIEW_SIDE as f32),
            p.shading_normal,
        );
        if w.dot(p.geometric_normal) > 0.0 && scene.closest_hit(origin, w, f32::INFINITY).is_none()
        {
            open += 1;
        }
    }
    Some(open as f32 / (SKY_VIEW_SIDE * SKY_VIEW_SIDE) as f32)
}

/// Rays a candidate viewpoint sends to tell open air from the inside of a solid.
const VIEWPOINT_PROBES: u32 = 64;

/// `count` points a player can see, with the geometric normal of the side facing the
/// viewer ([`PointsArgs::visible`]); deterministic for a seed.
fn visible_points(
    scene: &surfcache_trace::TracedScene,
    count: usize,
    seed: u64,
) -> Result<Vec<(glam::Vec3, glam::Vec3)>> {
    use glam::Vec3;
    use surfcache_core::sampling::uniform_sphere;
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for t in scene.positions() {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    if scene.triangle_count() == 0 {
        bail!("the scene has no triangles to sample points on");
    }
    let mut rng = Rng::new(seed, 0x7615_1b1e);
    let mut out = Vec::with_capacity(count);
    let mut tries = 0u64;
    while out.len() < count {
        tries += 1;
        if tries > 1000 * count as u64 + 100_000 {
            bail!("found no open air to look from in the scene (is it closed everywhere?)");
        }
        let eye = lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let (mut inside, mut sky) = (false, false);
        for _ in 0..VIEWPOINT_PROBES {
            let d = uniform_sphere(rng.next_vec2());
            match scene.closest_hit(eye, d, f32::INFINITY) {
                None => sky = true,
                Some(h) => {
                    let front = scene.geometric_normals()[h.triangle as usize].dot(d) < 0.0;
                    if !front && !scene.material_of(h.triangle).double_sided {
                        inside = true;
                        break;
                    }
                }
            }
        }
        if inside || !sky {
            continue;
        }
        let d = uniform_sphere(rng.next_vec2());
        let Some(h) = scene.closest_hit(eye, d, f32::INFINITY) else {
            continue;
        };
        let mu = scene.geometric_normals()[h.triangle as usize];
        let n = if mu.dot(d) < 0.0 { mu } else { -mu };
        let p = scene.surface_point(h.triangle, h.uv, mu.dot(d) < 0.0);
        out.push((p.position, n));
    }
    Ok(out)
}
