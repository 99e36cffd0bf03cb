//! Measurement, not a test: bakes the built-in Cornell box with irradiance maps (and
//! vertex lighting for comparison) on 2 threads with the CLI's estimator settings and
//! prints wall and CPU time (the machine may be shared: CPU seconds / 2 is the time an
//! idle machine would take), rays, sample points, order histogram, bytes and the error against a fixed-sample
//! reference at 256 random points. Run by hand:
//!
//! ```text
//! IMAP_DENSITY=32 IMAP_ERROR=0.05 cargo test --release -p surfcache_cache \
//!     --test measure_cornell -- --ignored --nocapture
//! ```
//! (`IMAP_DENSITY`, `IMAP_ERROR`, `IMAP_MAX_ORDER` and `IMAP_BOTH_SIDES` take
//! comma-separated lists; every combination is baked.)

mod common;

use common::Points;
use std::time::Instant;
use surfcache_cache::{
    SurfaceCache,
    bake::{Baker, FLOOR_FRACTION, mean_irradiance},
    irradiance_map::{IrradianceMapSettings, IrradianceMaps},
    vertex_lighting::{VertexLighting, VertexLightingSettings},
};
use surfcache_core::{color::luminance, scenes::cornell};
use surfcache_trace::{EstimatorSettings, Sampler, TracedScene, estimate};

/// CPU seconds of this process so far (user + system, from /proc/self/stat): robust to
/// other work on the machine, unlike wall time.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = |k: usize| {
        fields
            .get(k)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // Fields 14 and 15 (utime, stime) of proc(5), counted from the state field (3).
    (ticks(11) + ticks(12)) / 100.0
}

/// Bakes to convergence; returns the cache, wall seconds, CPU seconds and rays.
fn timed_bake<C: SurfaceCache>(
    traced: &TracedScene,
    cache: C,
    settings: &EstimatorSettings,
) -> (C, f64, f64, u64) {
    let (wall, cpu) = (Instant::now(), cpu_seconds());
    let mut baker = Baker::new(cache, *settings, 0);
    while !baker.step(traced, 4096) {}
    let rays = baker.progress().rays;
    let cpu = cpu_seconds() - cpu;
    (baker.into_cache(), wall.elapsed().as_secs_f64(), cpu, rays)
}

fn list<T: std::str::FromStr>(name: &str, default: &str) -> Vec<T> {
    std::env::var(name)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .map(|s| s.trim().parse().ok().expect(name))
        .collect()
}

#[test]
#[ignore = "measurement: run by hand with --ignored --nocapture"]
fn measure_cornell() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    pool.install(|| {
        let traced = TracedScene::new(&cornell()).unwrap();
        let floor = FLOOR_FRACTION * mean_irradiance(&traced, 1024, 0);
        let settings = EstimatorSettings {
            sampler: Sampler::Best,
            max_rel_error: 0.01,
            min_samples: 256,
            max_samples: 65_536,
            floor,
            max_bounces: None,
        };
        // Reference: 256 area-weighted random points on front sides, 16,384 samples each,
        // leaving out buried ones.
        let started = Instant::now();
        let areas: Vec<f32> = traced
            .positions
            .iter()
            .map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length())
            .collect();
        let total: f32 = areas.iter().sum();
        let mut rng = Points(2024);
        let mut points = Vec::new();
        while points.len() < 256 {
            let mut x = rng.next_f32() * total;
            let mut t = 0;
            while t + 1 < areas.len() && x >= areas[t] {
                x -= areas[t];
                t += 1;
            }
            points.push((t as u32, rng.barycentrics()));
        }
        let fixed = EstimatorSettings::fixed(Sampler::Best, 16_384, None);
        use rayon::prelude::*;
        let reference: Vec<_> = points
            .par_iter()
            .enumerate()
            .map(|(k, &(t, uv))| {
                let p = traced.surface_point(t, uv, true);
                estimate(&traced, &p, traced.spawn_origin(&p), &fixed, 99, k as u64)
            })
            .collect();
        eprintln!(
            "floor ε = {floor:.4} W/m²; reference at {} points in {:.1} s",
            points.len(),
            started.elapsed().as_secs_f64()
        );
        // The yardstick's own noise: a second reference with another seed; the RMS of
        // the difference over √2 is the noise of one.
        let second: Vec<_> = points
            .par_iter()
            .enumerate()
            .map(|(k, &(t, uv))| {
                let p = traced.surface_point(t, uv, true);
                estimate(&traced, &p, traced.spawn_origin(&p), &fixed, 98, k as u64)
            })
            .collect();
        let (mut sum, mut count) = (0.0f64, 0);
        for (a, b) in reference.iter().zip(&second) {
            if a.back_face_share <= 0.5 {
                let (la, lb) = (luminance(a.value), luminance(b.value));
                sum += (((la - lb) / (la + floor)) as f64).powi(2);
                count += 1;
            }
        }
        eprintln!(
            "reference noise (rel. RMS of one reference): {:.4}",
            (sum / count as f64 / 2.0).sqrt()
        );
        let error = |cache: &dyn SurfaceCache| {
            let (mut sum, mut count) = (0.0f64, 0);
            for (&(t, uv), r) in points.iter().zip(&reference) {
                if r.back_face_share > 0.5 {
                    continue;
                }
                let e = luminance(cache.lookup(t, uv, true));
                let want = luminance(r.value);
                sum += (((e - want) / (want + floor)) as f64).powi(2);
                count += 1;
            }
            (sum / count as f64).sqrt()
        };
        let report = |name: &str, (wall, cpu, rays): (f64, f64, u64), cache: &dyn SurfaceCache| {
            let s = cache.stats();
            eprintln!(
                "{name}: {wall:.1} s wall, {cpu:.1} s CPU, {:.1} Mrays, {} points, {} samples ({:.0}/point, max {}), {} bytes \
                 ({:.1} KiB), buried {}, mean C {:.4}, rel. RMS error {:.4}, orders {:?}",
                rays as f64 * 1e-6,
                s.sample_points,
                s.samples,
                s.samples as f64 / s.sample_points.max(1) as f64,
                s.max_samples_per_point,
                s.cache_bytes,
                s.cache_bytes as f64 / 1024.0,
                s.buried,
                s.mean_rel_error,
                error(cache),
                s.order_histogram
            );
        };
        if std::env::var("IMAP_VERTEX").is_ok() {
            let vertex = VertexLighting::new(&traced, VertexLightingSettings::default());
            let (vertex, wall, cpu, rays) = timed_bake(&traced, vertex, &settings);
            report("vertex", (wall, cpu, rays), &vertex);
        }
        for &density in &list::<f32>("IMAP_DENSITY", "32") {
            for &interpolation_error in &list::<f32>("IMAP_ERROR", "0.05") {
                for &max_order in &list::<u32>("IMAP_MAX_ORDER", "64") {
                    for &both_sides in &list::<bool>("IMAP_BOTH_SIDES", "true") {
                        let map_settings = IrradianceMapSettings {
                            density,
                            interpolation_error,
                            max_order,
                            both_sides,
                            floor,
                            ..Default::default()
                        };
                        let maps = IrradianceMaps::new(&traced, map_settings);
                        let (maps, wall, cpu, rays) = timed_bake(&traced, maps, &settings);
                        let name = format!(
                            "maps density {density} error {interpolation_error} max order \
                             {max_order} both sides {both_sides}"
                        );
                        report(&name, (wall, cpu, rays), &maps);
                    }
                }
            }
        }
    });
}
