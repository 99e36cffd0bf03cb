//! `surfcache render`: a camera view shaded from a bake (L = L_e + ρ/π · E), path-traced
//! for comparison, or the thesis' diagnostic pictures (samples per point, irradiance-map
//! order per triangle).

use super::rays::bounds;
use crate::{
    bake_dir::read_archive_of,
    camera::{Camera, default_view},
    picture::{auto_exposure, heat, write_png},
    scene_args::{EnvArgs, LoadedWorld, with_threads},
};
use anyhow::{Result, bail};
use glam::{Vec2, Vec3};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::path::PathBuf;
use surfcache_cache::{Diagnostic, PublishedLookup, SurfaceCache};
use surfcache_trace::{EstimatorSettings, Hit, PointInScene, Sampler, TracedScene, estimate};

#[derive(clap::Args)]
pub struct RenderArgs {
    /// A .gltf/.glb file or a built-in scene name (cornell): the scene that was baked.
    scene: String,
    #[command(flatten)]
    env: EnvArgs,
    /// Shade from this bake directory.
    #[arg(long, value_name = "OUT_DIR")]
    cache: Option<PathBuf>,
    /// Instead, path-trace E at every visible point with this many samples.
    #[arg(long, value_name = "N")]
    reference: Option<u32>,
    /// With --cache: a diagnostic picture instead of shading: `samples` (hemisphere
    /// samples of the nearest sample point, log scale) or `order` (irradiance-map order).
    #[arg(long)]
    show: Option<String>,
    /// With --cache: shade through the published textures, sampled plainly bilinear as a
    /// game engine does, instead of the cache's own lookup: what a player sees.
    #[arg(long)]
    published: bool,
    /// Camera eye and target `ex,ey,ez,tx,ty,tz` [default: in front of the scene's
    /// bounding box, looking along +Z].
    #[arg(long, value_name = "EX,EY,EZ,TX,TY,TZ")]
    camera: Option<String>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 40.0)]
    fov: f32,
    /// Image size WxH in pixels.
    #[arg(long, default_value = "512x512")]
    size: String,
    /// Exposure multiplier before tone mapping [default: automatic].
    #[arg(long)]
    exposure: Option<f32>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Output PNG (tone-mapped sRGB); the linear radiance is written beside it as .exr.
    #[arg(short = 'o', long = "out")]
    output: PathBuf,
}

/// Sub-pixel samples per axis (a fixed 2×2 grid: deterministic anti-aliasing).
const SUBPIXELS: u32 = 2;

pub fn run(args: RenderArgs) -> Result<()> {
    let (width, height) = parse_size(&args.size)?;
    check_modes(&args)?;
    let loaded = LoadedWorld::load(&args.scene, &args.env)?;
    let scene = loaded.traced()?;
    let archive = match &args.cache {
        Some(dir) => Some(read_archive_of(dir, &scene, &args.scene)?),
        None => None,
    };
    let (lo, hi) = bounds(scene.positions());
    let camera = Camera::from_arg(
        args.camera.as_deref(),
        args.fov,
        default_view(lo, hi, args.fov),
    )?;
    let reference = args
        .reference
        .map(|n| EstimatorSettings::fixed(Sampler::Best, n, None));
    let show = args.show.as_deref();
    let textures = match (&archive, args.published) {
        (Some(a), true) => a.cache.publish(&scene),
        _ => Vec::new(),
    };
    let published = args
        .published
        .then(|| PublishedLookup::new(&textures, &scene));
    let bar = ProgressBar::new(height as u64).with_style(
        ProgressStyle::with_template("render {bar:40} {pos}/{len} rows, eta {eta}")
            .expect("static template"),
    );
    let shade = |hit: &Hit, d: Vec3, key: u64| -> Vec3 {
        let front = scene.geometric_normals()[hit.triangle as usize].dot(d) < 0.0;
        if let (Some(kind), Some(a)) = (show, &archive) {
            return diagnostic_colour(a.cache.diagnostic(hit.triangle, hit.uv, front), kind);
        }
        let e = match (&archive, &reference) {
            (Some(a), _) => match &published {
                Some(p) => p.lookup(hit.triangle, hit.uv, front).unwrap_or(Vec3::ZERO),
                None => a.cache.lookup(hit.triangle, hit.uv, front),
            },
            (None, Some(settings)) => {
                reference_irradiance(&scene, hit, d, settings, args.seed, key)
            }
            (None, None) => Vec3::ZERO,
        };
        surface_radiance(&scene, hit, d, e)
    };
    let pixels = with_threads(args.threads, || {
        render_view(
            &scene,
            &camera,
            width,
            height,
            show.is_none(),
            &shade,
            || bar.inc(1),
        )
    })?;
    bar.finish_and_clear();
    write_picture(&args, width, height, &pixels)
}

/// Checks that the arguments name exactly one source of irradiance (--cache or
/// --reference) and that --show and --published come with --cache.
fn check_modes(args: &RenderArgs) -> Result<()> {
    if args.cache.is_some() == args.reference.is_some() {
        bail!("give exactly one of --cache OUT_DIR and --reference N");
    }
    if (args.show.is_some() || args.published) && args.cache.is_none() {
        bail!("--show and --published need --cache");
    }
    if let Some(show) = &args.show
        && show != "samples"
        && show != "order"
    {
        bail!("unknown --show '{show}' (known: samples, order)");
    }
    Ok(())
}

/// The colour of a diagnostic picture (`--show order` or `samples`) at a point: its
/// irradiance-map order (grey without one) or sample count, on a log-scale heat map.
fn diagnostic_colour(diag: Diagnostic, kind: &str) -> Vec3 {
    match kind {
        "order" => match diag.order {
            Some(o) => heat((o.max(1) as f32).log2() / 7.0),
            None => Vec3::splat(0.2),
        },
        _ => heat((diag.samples.max(1) as f32).log2() / 18.0),
    }
}

/// Path-traced irradiance E at a primary hit (direction `d` from the camera), with the
/// sample sequence of `seed` and the sub-pixel `key`.
fn reference_irradiance(
    scene: &TracedScene,
    hit: &Hit,
    d: Vec3,
    settings: &EstimatorSettings,
    seed: u64,
    key: u64,
) -> Vec3 {
    let p = scene.hit_point(hit, d);
    let origin = scene.spawn_origin(&p);
    estimate(&PointInScene::new(scene, p, origin), settings, seed, key).value
}

/// Writes the picture tone-mapped to the output PNG (exposure 1 for diagnostic pictures,
/// else --exposure or automatic) and, when shaded, its linear radiance beside it as .exr.
fn write_picture(args: &RenderArgs, width: u32, height: u32, pixels: &[Vec3]) -> Result<()> {
    let exposure = match (args.exposure, args.show.as_deref()) {
        (_, Some(_)) => 1.0,
        (Some(e), None) => e,
        (None, None) => auto_exposure(pixels),
    };
    write_png(&args.output, width, height, pixels, exposure)?;
    if args.show.is_none() {
        let exr = args.output.with_extension("exr");
        surfcache_io::write_rgb_exr(&exr, width, height, pixels)?;
    }
    eprintln!("wrote {} (exposure {exposure:.3})", args.output.display());
    Ok(())
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let parsed = s
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if (1..=16384).contains(&w) && (1..=16384).contains(&h) => Ok((w, h)),
        _ => bail!("--size must be WxH with each side between 1 and 16384, got '{s}'"),
    }
}

/// Radiance leaving a primary hit towards the camera (direction `d` from it):
/// L = L_e + ρ/π · E, with E the irradiance on the side facing the camera.
pub fn surface_radiance(scene: &TracedScene, hit: &Hit, d: Vec3, e: Vec3) -> Vec3 {
    let front = scene.geometric_normals()[hit.triangle as usize].dot(d) < 0.0;
    let material = scene.material_of(hit.triangle);
    let uv0 = scene.uv0_at(hit.triangle, hit.uv);
    material.emission_at(uv0, front) + material.albedo_at(uv0) * core::f32::consts::FRAC_1_PI * e
}

/// Renders `camera`'s view of `scene` (row 0 at the top), 2×2 fixed sub-pixel samples:
/// `shade(hit, direction, key)` gives the radiance seen at each primary hit (`key` is
/// unique per sub-pixel sample), and missed rays see the environment when `background`.
/// Calls `row_done` after each row.
pub fn render_view(
    scene: &TracedScene,
    camera: &Camera,
    width: u32,
    height: u32,
    background: bool,
    shade: &(dyn Fn(&Hit, Vec3, u64) -> Vec3 + Sync),
    row_done: impl Fn() + Sync,
) -> Vec<Vec3> {
    let aspect = width as f32 / height as f32;
    (0..height)
        .into_par_iter()
        .flat_map_iter(|y| {
            let row: Vec<Vec3> = (0..width)
                .map(|x| {
                    let mut sum = Vec3::ZERO;
                    for s in 0..SUBPIXELS * SUBPIXELS {
                        let sub = Vec2::new((s % SUBPIXELS) as f32, (s / SUBPIXELS) as f32);
                        let px = Vec2::new(x as f32, y as f32) + (sub + 0.5) / SUBPIXELS as f32;
                        let ndc = px / Vec2::new(width as f32, height as f32) * 2.0 - 1.0;
                        let d = camera.direction(ndc, aspect);
                        match scene.closest_hit(camera.eye, d, f32::INFINITY) {
                            Some(hit) => {
                                let key = ((y * width + x) * SUBPIXELS * SUBPIXELS + s) as u64;
                                sum += shade(&hit, d, key);
                            }
                            None if background => sum += scene.environment().radiance(d),
                            None => {}
                        }
                    }
                    sum / (SUBPIXELS * SUBPIXELS) as f32
                })
                .collect();
            row_done();
            row
        })
        .collect()
}
