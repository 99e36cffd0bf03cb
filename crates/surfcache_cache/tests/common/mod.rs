//! Helpers shared by the cache tests: estimator settings, a small random stream, a tiled
//! floor, a driver that feeds a cache synthetic estimates (no ray tracing), and where a
//! world point lies.

#![allow(dead_code)]

use surfcache_cache::{SamplePoint, SurfaceCache, bake::sample_frame};
use surfcache_core::glam::{Vec2, Vec3};
use surfcache_trace::{Estimate, EstimatorSettings, Sampler, SurfacePoint, TracedScene};

pub const PI: f32 = std::f32::consts::PI;

/// Adaptive estimator settings with a floor.
pub fn estimator(
    sampler: Sampler,
    max_rel_error: f32,
    min_samples: u32,
    max_samples: u32,
    floor: f32,
) -> EstimatorSettings {
    EstimatorSettings {
        sampler,
        max_rel_error,
        min_samples,
        max_samples,
        floor,
        max_bounces: None,
    }
}

/// xorshift32: reproducible test points.
pub struct Points(pub u32);

impl Points {
    pub fn next_f32(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 8) as f32 / 16_777_216.0
    }

    /// Uniform barycentrics (u, v) in the triangle.
    pub fn barycentrics(&mut self) -> Vec2 {
        let (u, v) = (self.next_f32(), self.next_f32());
        if u + v > 1.0 {
            Vec2::new(1.0 - u, 1.0 - v)
        } else {
            Vec2::new(u, v)
        }
    }
}

/// Drives `cache` to convergence with synthetic estimates: `f(point)` gives E and the
/// back-face share at each sample's surface point, with zero standard error. Returns the
/// cache and the points of every round.
pub fn bake_synthetic<C: SurfaceCache>(
    scene: &TracedScene,
    cache: C,
    f: impl Fn(&SurfacePoint) -> (Vec3, f32),
) -> (C, Vec<Vec<SamplePoint>>) {
    bake_synthetic_watched(scene, cache, f, |_| {})
}

/// [`bake_synthetic`], showing the cache to `watch` after it handed out each round.
pub fn bake_synthetic_watched<C: SurfaceCache>(
    scene: &TracedScene,
    mut cache: C,
    f: impl Fn(&SurfacePoint) -> (Vec3, f32),
    mut watch: impl FnMut(&C),
) -> (C, Vec<Vec<SamplePoint>>) {
    let mut rounds = Vec::new();
    loop {
        let mut points = Vec::new();
        cache.next_round(scene, &mut points);
        if points.is_empty() {
            return (cache, rounds);
        }
        watch(&cache);
        let estimates: Vec<Estimate> = points
            .iter()
            .map(|p| {
                let (sp, _) = sample_frame(scene, &p.site);
                let (value, back_face_share) = f(&sp);
                Estimate {
                    value,
                    std_error: Vec3::ZERO,
                    samples: 1,
                    rel_error: 0.0,
                    back_face_share,
                    rays: 0,
                }
            })
            .collect();
        cache.finish_round(scene, &points, &estimates);
        rounds.push(points);
    }
}

/// Where a world point with normal `n` lies: (triangle, barycentrics, front side).
pub fn locate(scene: &TracedScene, x: Vec3, n: Vec3) -> (u32, Vec2, bool) {
    let p = scene.locate(x, n).expect("point on a surface");
    let front = p
        .geometric_normal
        .dot(scene.geometric_normals()[p.triangle as usize])
        > 0.0;
    (p.triangle, p.uv, front)
}

/// The centres of an `n` × `n` grid of cells over the 0.5 m square 2 m above the origin,
/// and the cells' side.
pub fn square_cells(n: u32) -> (impl Iterator<Item = Vec3>, f32) {
    let cell = 0.5 / n as f32;
    let centres = (0..n).flat_map(move |i| {
        (0..n).map(move |j| {
            Vec3::new(
                -0.25 + (i as f32 + 0.5) * cell,
                2.0,
                -0.25 + (j as f32 + 0.5) * cell,
            )
        })
    });
    (centres, cell)
}

/// `∫ cos θ_x dω` over the 0.5 m square 2 m above the origin (facing down), seen from
/// floor point `x` (normal +Y): the midpoint rule on a 200 × 200 grid
/// ([`square_cells`]), `cos θ_x cos θ_p dA / r²` (both cosines are `d.y / r` here).
pub fn square_projected_solid_angle(x: Vec3) -> f32 {
    let (centres, cell) = square_cells(200);
    centres
        .map(|p| {
            let d = p - x;
            let r2 = d.length_squared();
            (d.y / r2.sqrt()).powi(2) * cell * cell / r2
        })
        .sum()
}
