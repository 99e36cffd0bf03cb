//! Environment lighting: radiance arriving from infinitely far away, by direction.
//!
//! Maps are equirectangular with +Y up (docs/cli.md): pixel (i, j) of a W×H image, row 0
//! at the top, covers u = (i+½)/W, v = (j+½)/H and looks along
//! θ = vπ, φ = (u−½)2π, d = (sin θ sin φ, cos θ, −sin θ cos φ).

use crate::{color::luminance, prefetch::prefetch, sampling::Distribution1D};
use core::f32::consts::{PI, TAU};
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// An equirectangular radiance map in linear RGB, W/(m²·sr).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    pub width: u32,
    pub height: u32,
    /// Row-major texels, row 0 = zenith.
    pub texels: Vec<Vec3>,
}

/// Direction of image coordinates (u, v) ∈ [0,1]² (docs/cli.md, environment maps).
#[inline]
pub fn uv_to_direction(uv: Vec2) -> Vec3 {
    let theta = uv.y * PI;
    let phi = (uv.x - 0.5) * TAU;
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * sp, ct, -st * cp)
}

/// Image coordinates (u, v) ∈ [0,1]² of a unit direction; the inverse of [`uv_to_direction`].
#[inline]
pub fn direction_to_uv(d: Vec3) -> Vec2 {
    let theta = d.y.clamp(-1.0, 1.0).acos();
    let phi = d.x.atan2(-d.z);
    Vec2::new(phi / TAU + 0.5, theta / PI)
}

impl EnvironmentMap {
    /// A map filled with one radiance.
    pub fn constant(width: u32, height: u32, radiance: Vec3) -> Self {
        Self {
            width,
            height,
            texels: vec![radiance; (width * height) as usize],
        }
    }

    /// Builds a map by evaluating `f` at every pixel's centre direction.
    pub fn from_fn(width: u32, height: u32, f: impl Fn(Vec3) -> Vec3) -> Self {
        let mut texels = Vec::with_capacity((width * height) as usize);
        for j in 0..height {
            for i in 0..width {
                let uv = Vec2::new(
                    (i as f32 + 0.5) / width as f32,
                    (j as f32 + 0.5) / height as f32,
                );
                texels.push(f(uv_to_direction(uv)));
            }
        }
        Self {
            width,
            height,
            texels,
        }
    }

    #[inline]
    pub fn texel(&self, i: u32, j: u32) -> Vec3 {
        self.texels[(j * self.width + i) as usize]
    }

    /// Bilinear lookup in direction `d` (unit), wrapping horizontally and clamping at the poles.
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        self.radiance_uv(direction_to_uv(d))
    }

    /// [`Self::radiance`] at image coordinates `uv` ([`direction_to_uv`]).
    #[inline]
    pub fn radiance_uv(&self, uv: Vec2) -> Vec3 {
        let ([i0, i1], [j0, j1], fx, fy) = self.footprint(uv);
        let top = self.texel(i0, j0) * (1.0 - fx) + self.texel(i1, j0) * fx;
        let bottom = self.texel(i0, j1) * (1.0 - fx) + self.texel(i1, j1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Asks the processor to fetch the texels [`Self::radiance_uv`] reads at `uv` into its
    /// caches, so that a lookup after other work (a shadow ray) does not wait for memory.
    /// A hint only: it changes no result.
    #[inline]
    pub fn prefetch_uv(&self, uv: Vec2) {
        let ([i0, _], [j0, j1], _, _) = self.footprint(uv);
        for j in [j0, j1] {
            prefetch(&self.texels[(j * self.width + i0) as usize]);
        }
    }

    /// Columns, rows and weights of the bilinear lookup at `uv`.
    #[inline]
    fn footprint(&self, uv: Vec2) -> ([u32; 2], [u32; 2], f32, f32) {
        let x = uv.x * self.width as f32 - 0.5;
        let y = (uv.y * self.height as f32 - 0.5).clamp(0.0, (self.height - 1) as f32);
        let x0 = x.floor();
        let y0 = y.floor();
        let w = self.width as i64;
        let i0 = (x0 as i64).rem_euclid(w) as u32;
        let i1 = (x0 as i64 + 1).rem_euclid(w) as u32;
        let j0 = y0 as u32;
        let j1 = (j0 + 1).min(self.height - 1);
        ([i0, i1], [j0, j1], x - x0, y - y0)
    }

    /// cos θ_j of the upper edge of pixel row `j` (θ_j = jπ/H; `j = H` is the lower edge
    /// of the last row).
    pub fn row_edge_cos(&self, j: u32) -> f32 {
        (j as f32 / self.height as f32 * PI).cos()
    }

    /// Solid angle of pixel row `j`: (2π/W)·(cos θ₀ − cos θ₁).
    pub fn row_solid_angle(&self, j: u32) -> f32 {
        TAU / self.width as f32 * (self.row_edge_cos(j) - self.row_edge_cos(j + 1))
    }
}

/// What the sky contributes: a uniform radiance or a map, times an intensity.
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    /// Uniform radiance, used where there is no map.
    pub color: Vec3,
    pub map: Option<Arc<EnvironmentMap>>,
    /// Scale applied to `color` or `map`.
    pub intensity: f32,
}

impl Default for Environment {
    fn default() -> Self {
        Self::black()
    }
}

impl Environment {
    /// No light from the environment.
    pub fn black() -> Self {
        Self {
            color: Vec3::ZERO,
            map: None,
            intensity: 1.0,
        }
    }

    /// A uniform sky of radiance `color`.
    pub fn uniform(color: Vec3) -> Self {
        Self {
            color,
            map: None,
            intensity: 1.0,
        }
    }

    /// A map-based sky.
    pub fn from_map(map: Arc<EnvironmentMap>) -> Self {
        Self {
            color: Vec3::ZERO,
            map: Some(map),
            intensity: 1.0,
        }
    }

    /// Radiance arriving from direction `d` (unit, pointing away from the scene).
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        match &self.map {
            Some(map) => map.radiance(d) * self.intensity,
            None => self.color * self.intensity,
        }
    }

    /// [`Self::radiance`] at image coordinates `uv` of the map ([`direction_to_uv`]).
    #[inline]
    pub fn radiance_uv(&self, uv: Vec2) -> Vec3 {
        match &self.map {
            Some(map) => map.radiance_uv(uv) * self.intensity,
            None => self.color * self.intensity,
        }
    }

    /// Prefetches what [`Self::radiance_uv`] reads at `uv` ([`EnvironmentMap::prefetch_uv`];
    /// nothing for a uniform sky).
    #[inline]
    pub fn prefetch_uv(&self, uv: Vec2) {
        if let Some(map) = &self.map {
            map.prefetch_uv(uv);
        }
    }

    /// True when the environment delivers no light at all.
    pub fn is_black(&self) -> bool {
        self.intensity == 0.0
            || match &self.map {
                Some(map) => map.texels.iter().all(|t| *t == Vec3::ZERO),
                None => self.color == Vec3::ZERO,
            }
    }
}

/// Importance sampling of an [`EnvironmentMap`]: pixels are chosen with probability
/// proportional to their weight × solid angle, then a direction uniformly in solid angle
/// inside the pixel, so p(ω) = P(pixel) / ΔΩ(pixel) (piecewise-constant 2D distribution,
/// pbrt-v4 §A.5 `PiecewiseConstant2D`, with the sin θ Jacobian folded into exact row solid
/// angles).
///
/// A pixel's weight is the largest luminance among it and its eight neighbours (wrapping
/// horizontally, clamped at the poles): [`EnvironmentMap::radiance`] filters bilinearly,
/// so inside pixel (i, j) it blends texels of that 3×3 neighbourhood, and the weight
/// bounds it from above. Weighting by the pixel's own texel alone would give the outer
/// half of a one-pixel sun's bilinear footprint, up to half its radiance, the density of
/// the dim sky around it: cosine-sampled directions would find it once in ~10⁴ samples
/// (fireflies), and estimates that stop early would miss ~40 % of the sun.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnvironmentSampler {
    width: u32,
    height: u32,
    /// Marginal over rows.
    rows: Distribution1D,
    /// Conditional over columns, one per row.
    columns: Vec<Distribution1D>,
    /// Solid angle of one pixel of each row.
    pixel_solid_angle: Vec<f32>,
    /// [`EnvironmentMap::row_edge_cos`] of every row edge (H + 1 entries), so that a
    /// sample computes no cosine of its own.
    row_edge_cos: Vec<f32>,
    /// (1/4π) Σ Y(texel) ΔΩ: the map's mean luminance (the weights are dilated).
    mean_luminance: f32,
}

impl EnvironmentSampler {
    /// Builds the distribution of `map` (radiance scale does not matter).
    pub fn new(map: &EnvironmentMap) -> Self {
        let (w, h) = (map.width, map.height);
        let pixel_solid_angle: Vec<f32> = (0..h).map(|j| map.row_solid_angle(j)).collect();
        let lum: Vec<f32> = map.texels.iter().map(|&t| luminance(t).max(0.0)).collect();
        let at = |i: u32, j: u32| lum[(j * w + i) as usize];
        let mut row_weights = Vec::with_capacity(h as usize);
        let mut columns = Vec::with_capacity(h as usize);
        let mut total = 0.0f64;
        for j in 0..h {
            let near_rows = [j.saturating_sub(1), j, (j + 1).min(h - 1)];
            let weights: Vec<f32> = (0..w)
                .map(|i| {
                    let near_columns = [(i + w - 1) % w, i, (i + 1) % w];
                    near_rows
                        .iter()
                        .flat_map(|&r| near_columns.iter().map(move |&c| at(c, r)))
                        .fold(0.0, f32::max)
                })
                .collect();
            let row_sum: f64 = weights.iter().map(|&x| x as f64).sum();
            row_weights.push((row_sum * pixel_solid_angle[j as usize] as f64) as f32);
            columns.push(Distribution1D::new(&weights));
            let own: f64 = (0..w).map(|i| at(i, j) as f64).sum();
            total += own * pixel_solid_angle[j as usize] as f64;
        }
        Self {
            width: w,
            height: h,
            rows: Distribution1D::new(&row_weights),
            columns,
            pixel_solid_angle,
            row_edge_cos: (0..=h).map(|j| map.row_edge_cos(j)).collect(),
            mean_luminance: (total / (4.0 * std::f64::consts::PI)) as f32,
        }
    }

    /// Solid-angle-weighted mean luminance of the map, (1/4π) Σ Y(texel) ΔΩ(texel).
    pub fn mean_luminance(&self) -> f32 {
        self.mean_luminance
    }

    /// A direction drawn from the map's distribution and its solid-angle density.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, f32) {
        let (j, p_row, v) = self.rows.sample(u.y);
        let (i, p_col, s) = self.columns[j].sample(u.x);
        // Uniform in (φ, cos θ) over the pixel is uniform in solid angle.
        let (c0, c1) = (self.row_edge_cos[j], self.row_edge_cos[j + 1]);
        let cos_theta = c0 + (c1 - c0) * v;
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = ((i as f32 + s) / self.width as f32 - 0.5) * TAU;
        let d = Vec3::new(sin_theta * phi.sin(), cos_theta, -sin_theta * phi.cos());
        let pdf = p_row * p_col / self.pixel_solid_angle[j];
        (d, pdf)
    }

    /// Prefetches the table entries [`Self::sample`] reads at `u` (the row's column
    /// distribution near `u.x`), so that a sample drawn after other work finds them in
    /// the caches ([`crate::prefetch`]).
    #[inline]
    pub fn prefetch(&self, u: Vec2) {
        let (j, _, _) = self.rows.sample(u.y);
        self.columns[j].prefetch(u.x);
    }

    /// The solid-angle density [`Self::sample`] has at direction `d` (unit).
    #[inline]
    pub fn pdf(&self, d: Vec3) -> f32 {
        self.pdf_uv(direction_to_uv(d))
    }

    /// [`Self::pdf`] at image coordinates `uv` ([`direction_to_uv`]).
    #[inline]
    pub fn pdf_uv(&self, uv: Vec2) -> f32 {
        let i = ((uv.x * self.width as f32) as i64).clamp(0, self.width as i64 - 1) as usize;
        let j = ((uv.y * self.height as f32) as i64).clamp(0, self.height as i64 - 1) as usize;
        self.rows.pmf(j) * self.columns[j].pmf(i) / self.pixel_solid_angle[j]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convention_matches_contract() {
        // Image centre looks along −Z, a quarter turn right is +X, the top is +Y.
        assert!((uv_to_direction(Vec2::new(0.5, 0.5)) - Vec3::NEG_Z).length() < 1e-6);
        assert!((uv_to_direction(Vec2::new(0.75, 0.5)) - Vec3::X).length() < 1e-6);
        assert!((uv_to_direction(Vec2::new(0.3, 0.0)) - Vec3::Y).length() < 1e-6);
        for d in [Vec3::new(0.3, 0.4, -0.5), Vec3::new(-0.7, -0.1, 0.2)] {
            let d = d.normalize();
            assert!((uv_to_direction(direction_to_uv(d)) - d).length() < 1e-5);
        }
    }

    #[test]
    fn importance_sampling_is_consistent() {
        // A map with a bright spot: sampled directions cluster there, the density returned
        // by `sample` equals `pdf`, and E[L/p] over the sphere equals ∫L dω.
        let map = EnvironmentMap::from_fn(32, 16, |d| {
            if d.dot(Vec3::new(0.6, 0.3, -0.74).normalize()) > 0.95 {
                Vec3::new(50.0, 40.0, 30.0)
            } else {
                Vec3::splat(0.2)
            }
        });
        let sampler = EnvironmentSampler::new(&map);
        let mut rng = crate::sampling::Rng::new(1, 1);
        let n = 200_000;
        let (mut integral, mut square) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let (d, pdf) = sampler.sample(rng.next_vec2());
            assert!((d.length() - 1.0).abs() < 1e-4);
            let p2 = sampler.pdf(d);
            assert!((pdf - p2).abs() <= 1e-3 * pdf.max(p2), "{pdf} vs {p2}");
            // Nearest-pixel radiance: piecewise constant, so ∫L dω is a finite sum. The
            // weights are dilated (a pixel next to the spot is drawn as often as the spot),
            // so L/p is not constant: compare within the estimate's standard error.
            let uv = direction_to_uv(d);
            let i = ((uv.x * 32.0) as u32).min(31);
            let j = ((uv.y * 16.0) as u32).min(15);
            let x = (luminance(map.texel(i, j)) / pdf) as f64;
            integral += x;
            square += x * x;
        }
        integral /= n as f64;
        let std_error = ((square / n as f64 - integral * integral) / (n - 1) as f64).sqrt();
        let exact: f64 = (0..16)
            .map(|j| {
                (0..32)
                    .map(|i| (luminance(map.texel(i, j)) * map.row_solid_angle(j)) as f64)
                    .sum::<f64>()
            })
            .sum();
        assert!(
            (integral - exact).abs() < 4.0 * std_error + 1e-4 * exact,
            "{integral} ± {std_error} vs {exact}"
        );
        assert!(std_error < 3e-3 * exact, "{std_error}");
        assert!(
            (sampler.mean_luminance() as f64 - exact / (4.0 * std::f64::consts::PI)).abs() < 1e-4
        );
    }

    #[test]
    fn bilinear_footprint_of_a_hot_pixel_is_sampled() {
        // One hot texel in a dim map: the bilinear lookup spreads it over the eight
        // pixels around it, and the density must follow it there. With weights w and
        // p(ω) = w(pixel) / Σ w ΔΩ, L(ω)/p(ω) ≤ Σ w ΔΩ wherever w bounds L.
        let (w, h) = (64, 32);
        let mut map = EnvironmentMap::constant(w, h, Vec3::splat(0.1));
        let (hi, hj) = (20u32, 10u32);
        map.texels[(hj * w + hi) as usize] = Vec3::splat(1e5);
        let sampler = EnvironmentSampler::new(&map);
        let bound = sampler.rows.total() as f32;
        let sub = 16;
        for y in 0..5 * sub {
            for x in 0..5 * sub {
                let u = (hi as f32 - 2.0 + (x as f32 + 0.5) / sub as f32) / w as f32;
                let v = (hj as f32 - 2.0 + (y as f32 + 0.5) / sub as f32) / h as f32;
                let d = uv_to_direction(Vec2::new(u, v));
                let ratio = luminance(map.radiance(d)) / sampler.pdf(d);
                assert!(ratio <= 1.001 * bound, "({u}, {v}): {ratio} > {bound}");
            }
        }
        // The mean luminance is still the map's own.
        let exact: f64 = (0..h)
            .map(|j| {
                (0..w)
                    .map(|i| (luminance(map.texel(i, j)) * map.row_solid_angle(j)) as f64)
                    .sum::<f64>()
            })
            .sum::<f64>()
            / (4.0 * std::f64::consts::PI);
        assert!((sampler.mean_luminance() as f64 - exact).abs() < 1e-4 * exact);
    }

    #[test]
    fn row_solid_angles_sum_to_sphere() {
        let map = EnvironmentMap::constant(16, 8, Vec3::ONE);
        let total: f32 = (0..8).map(|j| map.row_solid_angle(j) * 16.0).sum();
        assert!((total - 4.0 * PI).abs() < 1e-4);
    }
}
