//! Lightmap atlas figures: texels, overhead factor and stretch of the generated layouts.
//!
//! Lays out every instance of a scene as `surfcache bake --method lightmap` does (charts,
//! parameterisation, packing and rasterisation, in parallel over instances) at each asked
//! density and prints, per density: the texels of all textures, the overhead factor
//! (texels / (surface area · density²); 1 would be a perfect fit), the texels owned by a
//! triangle, the charts, the texel-density stretch of the triangles (σ/density over the
//! singular values σ of each triangle's metre-to-texel map: area-weighted mean and the
//! extremes) and the layout time. Figures go in docs/results.md ("Lightmap atlas").
//!
//! ```text
//! cargo run --release --example atlas_overhead -- SCENE [DENSITY...]
//! ```
//! SCENE is a glTF file or a built-in scene name (`cornell`); densities default to
//! 1 4 8 16. Instances with their own TEXCOORD_1 are counted but not re-laid out.

use std::time::Instant;
use surfcache::{
    cache::lightmap::{LightmapSettings, Lightmaps},
    core::geometry::{orthonormal_basis, triangle_area},
    io::load_scene,
    trace::TracedScene,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: atlas_overhead SCENE [DENSITY...]".into());
    };
    let densities: Vec<f32> = if args.len() > 2 {
        args[2..]
            .iter()
            .map(|s| s.parse::<f32>())
            .collect::<Result<_, _>>()?
    } else {
        vec![1.0, 4.0, 8.0, 16.0]
    };
    let scene = load_scene(path)?.scene;
    let traced = TracedScene::new(&scene)?;
    let area: f64 = traced
        .positions
        .iter()
        .map(|&[a, b, c]| triangle_area(a, b, c) as f64)
        .sum();
    println!(
        "{path}: {} instances, {} triangles, {area:.1} m², {} threads",
        traced.instance_triangles.len(),
        traced.triangle_count(),
        rayon::current_num_threads()
    );
    println!(
        "{:>8} {:>11} {:>9} {:>11} {:>9} {:>7} {:>7} {:>7} {:>8}",
        "texels/m",
        "texels",
        "overhead",
        "owned",
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
            gutter: std::env::var("ATLAS_GUTTER")
                .ok()
                .and_then(|g| g.parse().ok())
                .unwrap_or(LightmapSettings::default().gutter),
            ..Default::default()
        };
        let start = Instant::now();
        let maps = Lightmaps::new(&traced, settings);
        let seconds = start.elapsed().as_secs_f64();
        let mut texels = 0u64;
        for i in 0..traced.instance_triangles.len() {
            let [w, h] = maps.texture_size(i as u32);
            texels += w as u64 * h as u64;
        }
        let owned = maps.owned_texels();
        let charts = maps.chart_count();
        let (mut sum, mut weight, mut lo, mut hi) = (0.0f64, 0.0f64, f32::INFINITY, 0.0f32);
        for t in 0..traced.triangle_count() {
            let [a, b, c] = traced.positions[t];
            let area = triangle_area(a, b, c);
            if area <= 1e-12 {
                continue;
            }
            let i = traced.instance[t];
            let [w, h] = maps.texture_size(i);
            let d = maps.texels_per_metre(i);
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
        if std::env::var_os("ATLAS_INSTANCES").is_some() {
            for i in 0..traced.instance_triangles.len() {
                let range = traced.instance_triangles[i].clone();
                let a: f64 = range
                    .clone()
                    .map(|t| {
                        let [p, q, r] = traced.positions[t as usize];
                        triangle_area(p, q, r) as f64
                    })
                    .sum();
                let [w, h] = maps.texture_size(i as u32);
                let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
                for t in range.clone() {
                    let [p, q, r] = traced.positions[t as usize];
                    let d = maps.texels_per_metre(i as u32);
                    let size = glam::Vec2::new(w as f32, h as f32);
                    if let Some((s0, s1)) =
                        singular_values([p, q, r], maps.triangle_uv1(t).map(|x| x * size))
                    {
                        if triangle_area(p, q, r) * d * d > 1e-3 {
                            lo = lo.min(s0 / d);
                            hi = hi.max(s1 / d);
                        }
                    }
                }
                println!(
                    "  {:>3} {:<24} {:>7} tris {:>9.1} m² {:>5}×{:<5} overhead {:>7.2} σ {lo:.3}..{hi:.3}",
                    i,
                    traced.instance_names[i],
                    range.len(),
                    a,
                    w,
                    h,
                    (w as f64 * h as f64) / (a * (density as f64).powi(2)),
                );
            }
        }
        println!(
            "{density:>8} {texels:>11} {:>9.2} {owned:>11} {charts:>9} {:>7.3} {lo:>7.3} {hi:>7.3} {seconds:>8.2}",
            texels as f64 / (area * (density as f64).powi(2)),
            sum / weight.max(1e-30),
        );
    }
    Ok(())
}

/// Singular values of the linear map from a triangle (metres, in its own plane) to its
/// texel-space image: the texel density along the least and most stretched directions.
fn singular_values(
    [a, b, c]: [glam::Vec3; 3],
    [p, q, r]: [glam::Vec2; 3],
) -> Option<(f32, f32)> {
    let n = (b - a).cross(c - a).try_normalize()?;
    let (u, v) = orthonormal_basis(n);
    let e1 = glam::Vec2::new((b - a).dot(u), (b - a).dot(v));
    let e2 = glam::Vec2::new((c - a).dot(u), (c - a).dot(v));
    let world = glam::Mat2::from_cols(e1, e2);
    let det = world.determinant();
    if det.abs() <= 1e-20 {
        return None;
    }
    let j = glam::Mat2::from_cols(q - p, r - p) * world.inverse();
    // σ² are the eigenvalues of JᵀJ.
    let (m00, m01, m11) = (
        j.x_axis.length_squared(),
        j.x_axis.dot(j.y_axis),
        j.y_axis.length_squared(),
    );
    let mean = 0.5 * (m00 + m11);
    let root = (0.25 * (m00 - m11).powi(2) + m01 * m01).sqrt();
    Some(((mean - root).max(0.0).sqrt(), (mean + root).sqrt()))
}
