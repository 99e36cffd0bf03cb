//! Seen, not assumed: the built-in Cornell box, spawned as an ordinary Bevy scene, baked by
//! the plugin inside a real Bevy app with a window, and captured from the screen; against
//! `surfcache render`'s view of the same bake from the same camera at the same exposure
//! (`surfcache_cli::render_view` shading L = L_e + ρ/π · E from the baked cache). The mean
//! relative difference of the shaded pixels must stay within 5 %.
//!
//! Needs an X display: `DISPLAY`, or else it starts `Xvfb` itself (Debian `xvfb`; Mesa's
//! software Vulkan `mesa-vulkan-drivers` renders). Without either it says it was skipped,
//! and fails instead when `SURFCACHE_REQUIRE_DISPLAY=1` (CI). Pictures and the figure go to
//! `SURFCACHE_SCREENSHOT_DIR` (default: a folder in the system's temporary directory).
//! A test without the libtest harness: Bevy's window must live on the main thread.

use bevy::{
    core_pipeline::tonemapping::Tonemapping,
    prelude::*,
    render::render_resource::TextureFormat,
    window::{WindowPlugin, WindowResolution},
};
use glam::Vec3 as V3;
use std::{
    path::{Path, PathBuf},
    process::{Child, Command, ExitCode},
    sync::{Arc, Mutex},
    time::{Duration, Instant},
};
use surfcache_bevy::{
    SceneSpawner, SurfcacheBevyPlugin,
    view::{CaptureWhenBaked, capture_when_baked, matched_camera},
};
use surfcache_cache::SurfaceCache;
use surfcache_cli::{
    camera::{Camera as PinholeCamera, default_view},
    picture::srgb_encode,
    render_view, surface_radiance,
};
use surfcache_core::{color::luminance, scenes};
use surfcache_ecs::BakedSurfaceCache;

const WIDTH: u32 = 480;
const HEIGHT: u32 = 480;
const FOV: f32 = 40.0;
/// Radiance × this is the pixel value, as `surfcache render --exposure`; the box's walls
/// stay below 1 (no clipping), its lamp (L = 17) is clipped and left out.
const EXPOSURE: f32 = 0.5;
/// The largest mean relative difference allowed.
const BOUND: f64 = 0.05;

fn main() -> ExitCode {
    match run() {
        Ok(Some(figure)) => {
            println!(
                "screenshot: mean relative difference {:.2} % over {} shaded pixels (bound {:.0} %)",
                100.0 * figure.mean,
                figure.pixels,
                100.0 * BOUND
            );
            if figure.mean <= BOUND && figure.pixels > 10_000 {
                println!("1 passed, 0 failed");
                ExitCode::SUCCESS
            } else {
                println!("0 passed, 1 failed");
                ExitCode::FAILURE
            }
        }
        Ok(None) => {
            println!("0 passed, 0 failed, 1 skipped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("screenshot: {e}");
            println!("0 passed, 1 failed");
            ExitCode::FAILURE
        }
    }
}

/// An Xvfb server this test started, stopped when dropped.
struct Xvfb(Child);

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A display to open the window on: `DISPLAY`, or an Xvfb started here.
fn display() -> Result<Option<Option<Xvfb>>, String> {
    if std::env::var_os("DISPLAY").is_some() {
        return Ok(Some(None));
    }
    let number = 90 + std::process::id() % 400;
    let child = match Command::new("Xvfb")
        .args([
            &format!(":{number}"),
            "-screen",
            "0",
            "1024x768x24",
            "-nolisten",
            "tcp",
        ])
        .spawn()
    {
        Ok(c) => Xvfb(c),
        Err(e) => {
            let why = format!(
                "no DISPLAY and Xvfb cannot start ({e}); apt-get install xvfb mesa-vulkan-drivers"
            );
            if std::env::var("SURFCACHE_REQUIRE_DISPLAY").as_deref() == Ok("1") {
                return Err(why);
            }
            eprintln!("screenshot: skipped: {why}");
            return Ok(None);
        }
    };
    let socket = PathBuf::from(format!("/tmp/.X11-unix/X{number}"));
    let start = Instant::now();
    while !socket.exists() {
        if start.elapsed() > Duration::from_secs(20) {
            return Err("Xvfb did not come up within 20 s".into());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // SAFETY: no other thread runs yet.
    unsafe { std::env::set_var("DISPLAY", format!(":{number}")) };
    Ok(Some(Some(child)))
}

struct Figure {
    mean: f64,
    pixels: usize,
}

fn run() -> Result<Option<Figure>, String> {
    let Some(_xvfb) = display()? else {
        return Ok(None);
    };
    let out = std::env::var_os("SURFCACHE_SCREENSHOT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("surfcache_bevy_screenshot"));
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;

    // The Bevy app: the built-in box as a Bevy scene, the plugin, a matched camera.
    let scene = scenes::cornell();
    let (lo, hi) = scene.bounds();
    let (eye, target) = default_view(lo, hi, FOV);
    let bevy_vec = |v: V3| Vec3::new(v.x, v.y, v.z);
    let capture = CaptureWhenBaked::every(10);
    let picture = capture.picture.clone();
    let baked: Arc<Mutex<Option<BakedSurfaceCache>>> = Arc::default();
    let baked_out = baked.clone();
    let mut plugin = SurfcacheBevyPlugin::default();
    plugin.config.threads = Some(2);
    let started = Instant::now();
    let mut app = App::new();
    app.add_plugins((
        DefaultPlugins.set(WindowPlugin {
            primary_window: Some(Window {
                title: "surfcache: Cornell box".into(),
                resolution: WindowResolution::new(WIDTH, HEIGHT).with_scale_factor_override(1.0),
                resizable: false,
                ..Default::default()
            }),
            ..Default::default()
        }),
        plugin,
    ))
    .insert_resource(GlobalAmbientLight::NONE)
    .insert_resource(ClearColor(Color::BLACK))
    .insert_resource(capture)
    .add_systems(Startup, move |mut spawner: SceneSpawner| {
        spawner.spawn(&scenes::cornell());
        spawner.commands.spawn((
            matched_camera(
                bevy_vec(eye),
                bevy_vec(target),
                FOV,
                EXPOSURE,
                Tonemapping::None,
            ),
            Msaa::Off,
        ));
    })
    .add_systems(
        Update,
        (capture_when_baked, move |cache: Res<BakedSurfaceCache>| {
            if cache.is_changed()
                && let Ok(mut slot) = baked_out.lock()
            {
                *slot = Some(cache.clone());
            }
        }),
    );
    app.run();
    let shot = picture
        .lock()
        .map_err(|_| "the capture lock was poisoned")?
        .take()
        .ok_or("the app closed before a screenshot settled")?;
    eprintln!(
        "screenshot: baked and captured in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let baked = baked
        .lock()
        .map_err(|_| "the bake lock was poisoned")?
        .take()
        .ok_or("no bake was published")?;
    let (traced, cache) = match (&baked.scene, baked.cache()) {
        (Some(s), Some(c)) => (s.clone(), c.clone()),
        _ => return Err("no bake was published".into()),
    };

    // surfcache render's view of the same bake.
    let camera = PinholeCamera::look_at(eye, target, FOV);
    let shade = |hit: &surfcache_trace::Hit, d: V3, _key: u64| {
        let front = traced.geometric_normals()[hit.triangle as usize].dot(d) < 0.0;
        surface_radiance(&traced, hit, d, cache.lookup(hit.triangle, hit.uv, front))
    };
    let reference = render_view(&traced, &camera, WIDTH, HEIGHT, false, &shade, || {});

    // Bevy's pixels back to radiance: sRGB decoded, divided by the exposure.
    let bevy = screenshot_radiance(&shot)?;
    // Shaded pixels: the 3 × 3 pixel centres around them see one plane (no silhouette
    // edge, where 2 × 2 sub-pixels and a single sample differ), nothing clipped, not black.
    let plane = |x: i64, y: i64| -> Option<(glam::IVec3, i64)> {
        let s = glam::Vec2::new(
            (x as f32 + 0.5) / WIDTH as f32 * 2.0 - 1.0,
            (y as f32 + 0.5) / HEIGHT as f32 * 2.0 - 1.0,
        );
        let d = camera.direction(s, WIDTH as f32 / HEIGHT as f32);
        let hit = traced.closest_hit(camera.eye, d, f32::INFINITY)?;
        let n = traced.geometric_normals()[hit.triangle as usize];
        let p = camera.eye + d * hit.t;
        Some((
            (n * 64.0).round().as_ivec3(),
            (n.dot(p) * 1e3).round() as i64,
        ))
    };
    let mut sum = 0.0f64;
    let mut pixels = 0usize;
    let mut diff_image = vec![V3::ZERO; (WIDTH * HEIGHT) as usize];
    for y in 1..HEIGHT as i64 - 1 {
        for x in 1..WIDTH as i64 - 1 {
            let k = (y * WIDTH as i64 + x) as usize;
            let (a, b) = (bevy[k], reference[k]);
            let Some(centre) = plane(x, y) else { continue };
            let interior = (-1..=1).all(|j| (-1..=1).all(|i| plane(x + i, y + j) == Some(centre)));
            let clipped =
                (a * EXPOSURE).max_element() >= 0.99 || (b * EXPOSURE).max_element() >= 0.99;
            if !interior || clipped || luminance(b) * EXPOSURE < 0.01 {
                continue;
            }
            let d = (a - b).abs().element_sum() as f64 / b.element_sum() as f64;
            diff_image[k] = V3::splat(d as f32 * 10.0);
            sum += d;
            pixels += 1;
        }
    }
    let mean = sum / pixels.max(1) as f64;
    write_png(&out.join("bevy_cornell.png"), &bevy)?;
    write_png(&out.join("bevy_cornell_surfcache_render.png"), &reference)?;
    write_png(
        &out.join("bevy_cornell_difference_x10.png"),
        &diff_image.iter().map(|d| *d / EXPOSURE).collect::<Vec<_>>(),
    )?;
    eprintln!("screenshot: pictures in {}", out.display());
    Ok(Some(Figure { mean, pixels }))
}

/// Linear radiance of every pixel of a window screenshot (sRGB, 8 bits) at [`EXPOSURE`].
fn screenshot_radiance(shot: &Image) -> Result<Vec<V3>, String> {
    let (w, h) = (shot.width(), shot.height());
    if (w, h) != (WIDTH, HEIGHT) {
        return Err(format!("the window is {w}x{h}, not {WIDTH}x{HEIGHT}"));
    }
    let data = shot.data.as_ref().ok_or("the screenshot has no pixels")?;
    let bgra = match shot.texture_descriptor.format {
        TextureFormat::Bgra8UnormSrgb | TextureFormat::Bgra8Unorm => true,
        TextureFormat::Rgba8UnormSrgb | TextureFormat::Rgba8Unorm => false,
        other => return Err(format!("unexpected screenshot format {other:?}")),
    };
    let lut = surfcache_core::color::srgb8_to_linear();
    Ok(data
        .chunks_exact(4)
        .take((w * h) as usize)
        .map(|p| {
            let (r, g, b) = if bgra {
                (p[2], p[1], p[0])
            } else {
                (p[0], p[1], p[2])
            };
            V3::new(lut[r as usize], lut[g as usize], lut[b as usize]) / EXPOSURE
        })
        .collect())
}

/// Radiance × [`EXPOSURE`], clamped and sRGB-encoded (no tone mapping, as the Bevy camera
/// shows it), as an 8-bit PNG written under a temporary name and renamed.
fn write_png(path: &Path, pixels: &[V3]) -> Result<(), String> {
    let bytes: Vec<u8> = pixels
        .iter()
        .flat_map(|p| p.to_array())
        .map(|c| (srgb_encode((c * EXPOSURE).clamp(0.0, 1.0)) * 255.0 + 0.5) as u8)
        .collect();
    let mut file = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut file, WIDTH, HEIGHT);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&bytes).map_err(|e| e.to_string())?;
    }
    surfcache_io::write_file_atomically(path, &file).map_err(|e| format!("{}: {e}", path.display()))
}
