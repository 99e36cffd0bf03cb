//! Lightmap atlas figures: texels, overhead factor and stretch of the generated layouts.
//!
//! Lays out every instance of a scene as `surfcache bake --method lightmap` does (charts,
//! parameterisation, packing and rasterisation, in parallel over instances) at each asked
//! density and prints, per density: the texels of all textures, the overhead factor
//! (texels / (surface area · density²); 1 would be a perfect fit), the texels owned by a
//! triangle (the estimated ones) and their overhead factor, the charts, the
//! texel-density stretch of the triangles of at least a thousandth of a texel (σ/density
//! over the singular values σ of each triangle's metre-to-texel map: area-weighted mean
//! and the extremes) and the layout time. Figures go in docs/results.md ("Lightmap atlas").
//!
//! ```text
//! cargo run --release --example atlas_overhead -- SCENE [DENSITY...] [--gutter N]
//! ```
//! SCENE is a glTF file or a built-in scene name (`cornell`); densities default to
//! 1 4 8 16, the gutter to `LightmapSettings`' default. Instances with their own
//! TEXCOORD_1 are counted but not re-laid out. All figures are per side (one layer).

use std::time::Instant;
use surfcache::{
    cache::{
        charts::singular_values,
        lightmap::{LightmapSettings, Lightmaps},
    },
    core::geometry::triangle_area,
    io::load_scene,
    trace::TracedScene,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: atlas_overhead SCENE [DENSITY...] [--gutter N]".into());
    };
    let mut gutter = LightmapSettings::default().gutter;
    let mut densities: Vec<f32> = Vec::new();
    let mut rest = args[2..].iter();
    while let Some(arg) = rest.next() {
        if arg == "--gutter" {
            gutter = rest.next().ok_or("--gutter needs a value")?.parse()?;
        } else {
            densities.push(arg.parse()?);
        }
    }
    if densities.is_empty() {
        densities = vec![1.0, 4.0, 8.0, 16.0];
    }
    let scene = load_scene(path)?.scene;
    let traced = TracedScene::new(&scene)?;
    let area: f64 = traced
        .positions()
        .iter()
        .map(|&[a, b, c]| triangle_area(a, b, c) as f64)
        .sum();
    println!(
        "{path}: {} instances, {} triangles, {area:.1} m², {} threads",
        traced.instance_triangles().len(),
        traced.triangle_count(),
        rayon::current_num_threads()
    );
    println!(
        "{:>8} {:>11} {:>9} {:>11} {:>11} {:>9} {:>7} {:>7} {:>7} {:>8}",
        "texels/m",
        "texels",
        "overhead",
        "owned",
        "owned/ideal",
        "charts",
        "mean σ",
        "min σ",
        "max σ",
        "layout s"
    );
    for &density in &densities {
        let settings = LightmapSettings {
            texels_per_metre: density,
            max_size: 16384,
            gutter,
            ..Default::default()
        };
        let start = Instant::now();
        let maps = Lightmaps::new(&traced, settings);
        let seconds = start.elapsed().as_secs_f64();
        let mut texels = 0u64;
        for i in 0..traced.instance_triangles().len() {
            let [w, h] = maps.texture_size(i as u32);
            texels += w as u64 * h as u64;
        }
        let owned = maps.owned_texels();
        let charts = maps.chart_count();
        let (mut sum, mut weight, mut lo, mut hi) = (0.0f64, 0.0f64, f32::INFINITY, 0.0f32);
        for t in 0..traced.triangle_count() {
            let [a, b, c] = traced.positions()[t];
            let area = triangle_area(a, b, c);
            let i = traced.instance()[t];
            let [w, h] = maps.texture_size(i);
            let d = maps.texels_per_metre(i);
            // Triangles under a thousandth of a texel carry no texel of their own.
            if area * d * d < 1e-3 {
                continue;
            }
            let size = glam::Vec2::new(w as f32, h as f32);
            let [p, q, r] = maps.triangle_uv1(t as u32).map(|p| p * size);
            let Some((s_min, s_max)) = singular_values([a, b, c], [p, q, r]) else {
                continue;
            };
            sum += area as f64 * 0.5 * (s_min + s_max) as f64 / d as f64;
            weight += area as f64;
            lo = lo.min(s_min / d);
            hi = hi.max(s_max / d);
        }
        println!(
            "{density:>8} {texels:>11} {:>9.2} {owned:>11} {:>11.2} {charts:>9} {:>7.3} {lo:>7.3} {hi:>7.3} {seconds:>8.2}",
            texels as f64 / (area * (density as f64).powi(2)),
            owned as f64 / (area * (density as f64).powi(2)),
            sum / weight.max(1e-30),
        );
    }
    Ok(())
}
