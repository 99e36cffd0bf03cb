//! Sharing samples between neighbouring texels: an edge-avoiding à-trous filter over a
//! texture of noisy irradiance estimates, guided by every texel's own standard error
//! (docs/design.md, "Filtering").
//!
//! Each of [`FilterSettings::iterations`] passes replaces a texel by a weighted mean of
//! the 5 × 5 taps `p + s·(i, j)`, `i, j ∈ −2..=2`, at the step `s = 2^k` of pass `k`
//! (Dammertz et al. 2010, "Edge-Avoiding À-Trous Wavelet Transform for fast Global
//! Illumination Filtering"): B3-spline weights `h(i) h(j)`, `h = (1, 4, 6, 4, 1)/16`,
//! times edge-stopping functions that keep the filter on one smooth surface and off real
//! changes of the light:
//!
//! - **normal**: `max(0, ⟨n_p, n_q⟩)^σ_n`, zero below [`MIN_NORMAL_COS`];
//! - **plane and distance**: `exp(−(⟨n_p, x_q − x_p⟩ / (σ_x · texel))²)` for the distance of
//!   `q`'s sample point from `p`'s tangent plane, and nothing farther than the tap's own
//!   texel distance allows ([`MAX_STRETCH`]) — chart borders and gutters neighbour texels
//!   that lie far apart on the surface;
//! - **value**: `exp(−|Y_p − Y_q| / (σ_l · sqrt(σ²_p + σ²_q) + ε))` on luminance with the
//!   texels' standard errors σ (Schied et al. 2017, "Spatiotemporal Variance-Guided
//!   Filtering", eq. 3–5): differences explained by noise are averaged away, differences
//!   the estimates resolve (a shadow edge, light through a doorway) stop the filter.
//!   Texels with precise estimates therefore keep their values; only noise is shared.
//!
//! Variances follow the weights, `σ²_out = Σ w² σ²_q / (Σ w)²` (the same reference, eq. 6),
//! which is what [`crate::lightmap`] compares with the error bound to decide where more
//! samples are needed. Correlation between passes is ignored there, as in that paper, so
//! the propagated variance is optimistic; the bias the filter adds is measured, not
//! modelled (docs/results.md).

use glam::Vec3;
use rayon::prelude::*;
use surfcache_core::color::luminance;

/// Taps whose normals are less parallel than this are never mixed.
pub const MIN_NORMAL_COS: f32 = 0.9;

/// A tap `k` texels away in the texture whose sample point lies farther than
/// `MAX_STRETCH · k · texel` away in the scene is on another chart or across a gutter.
pub const MAX_STRETCH: f32 = 2.0;

/// How strongly the filter shares samples.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterSettings {
    /// À-trous passes (steps 1, 2, 4, …): the footprint reaches 4·(2^iterations − 1) + 1
    /// texels across. 0 turns filtering off.
    pub iterations: u32,
    /// Exponent σ_n of the normal weight.
    pub sigma_normal: f32,
    /// Plane-distance scale σ_x, in texels.
    pub sigma_plane: f32,
    /// Value scale σ_l, in combined standard errors.
    pub sigma_value: f32,
}

impl Default for FilterSettings {
    fn default() -> Self {
        Self {
            iterations: 3,
            sigma_normal: 64.0,
            sigma_plane: 0.5,
            sigma_value: 4.0,
        }
    }
}

/// One texture's texels as the filter sees them.
pub struct FilterInput<'a> {
    pub width: usize,
    pub height: usize,
    /// Estimated irradiance per texel.
    pub value: &'a [Vec3],
    /// Variance of each estimate (per channel, of the mean).
    pub variance: &'a [Vec3],
    /// World position and unit normal of each texel's sample point.
    pub position: &'a [Vec3],
    pub normal: &'a [Vec3],
    /// Texels that take part (estimated, not buried).
    pub valid: &'a [bool],
    /// World size of one texel (metres).
    pub texel: f32,
    /// The absolute floor ε of relative errors (W/m²).
    pub floor: f32,
}

const B3: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// Filters `input` (module docs); returns the filtered values and their variances.
/// Texels that are not valid come back unchanged and are never read.
pub fn filter(input: &FilterInput, settings: &FilterSettings) -> (Vec<Vec3>, Vec<Vec3>) {
    let (w, h) = (input.width, input.height);
    let mut value = input.value.to_vec();
    let mut variance = input.variance.to_vec();
    if settings.iterations == 0 || w == 0 || h == 0 {
        return (value, variance);
    }
    let mut next_value = value.clone();
    let mut next_variance = variance.clone();
    for k in 0..settings.iterations {
        let step = 1isize << k;
        let (src_v, src_s) = (&value, &variance);
        next_value
            .par_chunks_mut(w)
            .zip(next_variance.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (row_v, row_s))| {
                for x in 0..w {
                    let p = y * w + x;
                    if !input.valid[p] {
                        continue;
                    }
                    let (v, s) = filter_texel(input, settings, src_v, src_s, x, y, step);
                    row_v[x] = v;
                    row_s[x] = s;
                }
            });
        std::mem::swap(&mut value, &mut next_value);
        std::mem::swap(&mut variance, &mut next_variance);
    }
    (value, variance)
}

/// One à-trous tap sum at texel (x, y) with step `step` (module docs).
#[inline]
fn filter_texel(
    input: &FilterInput,
    settings: &FilterSettings,
    value: &[Vec3],
    variance: &[Vec3],
    x: usize,
    y: usize,
    step: isize,
) -> (Vec3, Vec3) {
    let (w, h) = (input.width as isize, input.height as isize);
    let p = y * input.width + x;
    let (xp, np) = (input.position[p], input.normal[p]);
    let lp = luminance(value[p]);
    let sp = luminance(variance[p]);
    let plane_scale = 1.0 / (settings.sigma_plane * input.texel);
    let (mut sum_w, mut sum_v, mut sum_s) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
    for (j, hj) in B3.iter().enumerate() {
        let qy = y as isize + (j as isize - 2) * step;
        if qy < 0 || qy >= h {
            continue;
        }
        for (i, hi) in B3.iter().enumerate() {
            let qx = x as isize + (i as isize - 2) * step;
            if qx < 0 || qx >= w {
                continue;
            }
            let q = qy as usize * input.width + qx as usize;
            let weight = if q == p {
                hi * hj
            } else {
                if !input.valid[q] {
                    continue;
                }
                let cos = np.dot(input.normal[q]);
                if cos < MIN_NORMAL_COS {
                    continue;
                }
                let d = input.position[q] - xp;
                let reach = ((i as isize - 2).abs().max((j as isize - 2).abs()) * step) as f32
                    * std::f32::consts::SQRT_2
                    * MAX_STRETCH
                    * input.texel;
                if d.length_squared() > reach * reach {
                    continue;
                }
                let plane = np.dot(d) * plane_scale;
                let lq = luminance(value[q]);
                let sigma = settings.sigma_value * (sp + luminance(variance[q])).max(0.0).sqrt();
                let dv = (lp - lq).abs() / (sigma + 1e-3 * input.floor + f32::MIN_POSITIVE);
                hi * hj * cos.powf(settings.sigma_normal) * (-plane * plane - dv).exp()
            };
            sum_w += weight;
            sum_v += weight * value[q];
            sum_s += weight * weight * variance[q];
        }
    }
    (sum_v / sum_w, sum_s / (sum_w * sum_w))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(w: usize, h: usize) -> (Vec<Vec3>, Vec<Vec3>) {
        let pos = (0..w * h)
            .map(|k| Vec3::new((k % w) as f32, 0.0, (k / w) as f32) * 0.1)
            .collect();
        (pos, vec![Vec3::Y; w * h])
    }

    #[test]
    fn noise_is_shared_and_variance_falls() {
        let (w, h) = (32, 32);
        let (pos, nrm) = plane(w, h);
        let mut rng = surfcache_core::sampling::Rng::new(1, 2);
        let value: Vec<Vec3> = (0..w * h)
            .map(|_| Vec3::splat(1.0 + 0.1 * (rng.next_f32() - 0.5) * 3.46))
            .collect();
        let variance = vec![Vec3::splat(0.01); w * h];
        let valid = vec![true; w * h];
        let input = FilterInput {
            width: w,
            height: h,
            value: &value,
            variance: &variance,
            position: &pos,
            normal: &nrm,
            valid: &valid,
            texel: 0.1,
            floor: 0.01,
        };
        let (v, s) = filter(&input, &FilterSettings::default());
        let rms = |v: &[Vec3]| {
            (v.iter().map(|x| (x.x - 1.0).powi(2)).sum::<f32>() / v.len() as f32).sqrt()
        };
        assert!(rms(&v) < 0.35 * rms(&value), "{} {}", rms(&v), rms(&value));
        assert!(s.iter().all(|s| s.x < 0.01 * 0.2));
    }

    #[test]
    fn a_resolved_edge_stays_sharp() {
        // Left half lit (E = 1), right half dark (E = 0.1), precise estimates.
        let (w, h) = (16, 8);
        let (pos, nrm) = plane(w, h);
        let value: Vec<Vec3> = (0..w * h)
            .map(|k| Vec3::splat(if k % w < w / 2 { 1.0 } else { 0.1 }))
            .collect();
        let variance = vec![Vec3::splat(1e-4); w * h];
        let valid = vec![true; w * h];
        let input = FilterInput {
            width: w,
            height: h,
            value: &value,
            variance: &variance,
            position: &pos,
            normal: &nrm,
            valid: &valid,
            texel: 0.1,
            floor: 0.01,
        };
        let (v, _) = filter(&input, &FilterSettings::default());
        for (k, (a, b)) in v.iter().zip(&value).enumerate() {
            assert!(
                (a.x - b.x).abs() < 1e-3 * b.x.max(0.1),
                "texel {k}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn creases_and_invalid_texels_are_not_mixed() {
        // Two rows folded at 90°: the lower row faces +Y, the upper +Z.
        let (w, h) = (8, 2);
        let pos: Vec<Vec3> = (0..w * h)
            .map(|k| Vec3::new((k % w) as f32 * 0.1, 0.0, 0.0))
            .collect();
        let nrm: Vec<Vec3> = (0..w * h)
            .map(|k| if k < w { Vec3::Y } else { Vec3::Z })
            .collect();
        let value: Vec<Vec3> = (0..w * h)
            .map(|k| Vec3::splat(if k < w { 1.0 } else { 5.0 }))
            .collect();
        let variance = vec![Vec3::splat(100.0); w * h];
        let mut valid = vec![true; w * h];
        valid[3] = false;
        let mut poisoned = value.clone();
        poisoned[3] = Vec3::splat(1e6);
        let input = FilterInput {
            width: w,
            height: h,
            value: &poisoned,
            variance: &variance,
            position: &pos,
            normal: &nrm,
            valid: &valid,
            texel: 0.1,
            floor: 0.01,
        };
        let (v, _) = filter(&input, &FilterSettings::default());
        for k in (0..w * h).filter(|&k| k != 3) {
            assert!((v[k].x - value[k].x).abs() < 1e-4, "texel {k}: {}", v[k]);
        }
    }
}
