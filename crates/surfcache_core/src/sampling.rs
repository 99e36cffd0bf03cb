//! Random numbers and the warps that turn them into directions and points.
//!
//! Every estimate draws from its own [`Rng`] stream keyed by (seed, point index), so a
//! result never depends on how work was split across threads or frames.

use core::f32::consts::{FRAC_1_PI, PI, TAU};
use glam::{Vec2, Vec3};
use rand_core::RngCore;
use rand_pcg::Pcg32;

/// A small, fast, reproducible random stream (PCG32).
#[derive(Clone, Debug)]
pub struct Rng(Pcg32);

impl Rng {
    /// The stream for work item `index` under the user's `seed`.
    ///
    /// ```
    /// use surfcache_core::sampling::Rng;
    /// let mut a = Rng::new(7, 42);
    /// let mut b = Rng::new(7, 42);
    /// assert_eq!(a.next_f32(), b.next_f32());
    /// ```
    pub fn new(seed: u64, index: u64) -> Self {
        // splitmix64 decorrelates neighbouring seeds and indices before PCG's own mixing.
        let state = splitmix64(seed ^ splitmix64(index.wrapping_add(0x9E37_79B9_7F4A_7C15)));
        Rng(Pcg32::new(state, splitmix64(index) | 1))
    }

    /// Uniform in [0, 1), 24 bits of precision.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniform numbers in [0, 1)².
    #[inline]
    pub fn next_vec2(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }

    /// Raw 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        self.0.next_u32()
    }
}

/// splitmix64 finaliser (Steele et al. 2014), a bijective 64-bit mixer.
#[inline]
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Uniform direction on the hemisphere around +z, density p(ω) = 1/(2π)
/// (pbrt-v4 §A.5.3, `SampleUniformHemisphere`).
#[inline]
pub fn uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`uniform_hemisphere`]: 1/(2π).
pub const UNIFORM_HEMISPHERE_PDF: f32 = 0.5 * FRAC_1_PI;

/// Cosine-weighted direction around +z, p(ω) = cos θ / π, by Malley's method on
/// Shirley–Chiu's concentric disk (pbrt-v4 §A.5.3, `SampleCosineHemisphere`).
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`cosine_hemisphere`] for a direction with cos θ = `cos_theta`.
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Shirley–Chiu concentric map from the unit square to the unit disk (pbrt-v4 §A.5.1).
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, 0.25 * PI * (o.y / o.x))
    } else {
        (o.y, 0.5 * PI - 0.25 * PI * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform barycentrics (u,v) on a triangle, area density 1/A (pbrt-v4 §A.5.4,
/// Heitz's low-distortion mapping).
#[inline]
pub fn uniform_triangle(u: Vec2) -> Vec2 {
    let (b0, b1);
    if u.x < u.y {
        b0 = u.x / 2.0;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.0;
        b0 = u.x - b1;
    }
    Vec2::new(b1, 1.0 - b0 - b1)
}

/// Uniform direction on the unit sphere, p(ω) = 1/(4π).
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warps_stay_on_hemisphere() {
        let mut rng = Rng::new(1, 2);
        for _ in 0..10_000 {
            let u = rng.next_vec2();
            for d in [uniform_hemisphere(u), cosine_hemisphere(u)] {
                assert!(d.z >= 0.0 && (d.length() - 1.0).abs() < 1e-5);
            }
            let b = uniform_triangle(u);
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn cosine_mean_matches_closed_form() {
        // E[cos θ] under cosine sampling = ∫cos² θ/π dω = 2/3.
        let mut rng = Rng::new(3, 4);
        let n = 200_000;
        let mean: f64 = (0..n)
            .map(|_| cosine_hemisphere(rng.next_vec2()).z as f64)
            .sum::<f64>()
            / n as f64;
        assert!((mean - 2.0 / 3.0).abs() < 3e-3, "{mean}");
    }

    #[test]
    fn streams_differ() {
        let a: Vec<u32> = (0..4).map(|i| Rng::new(0, i).next_u32()).collect();
        assert!(a.windows(2).all(|w| w[0] != w[1]));
    }
}
