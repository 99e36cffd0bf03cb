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
//! samples are needed. That formula holds for independent taps, which only the first pass
//! has: from the second pass on, neighbouring taps already share inputs, and the formula
//! alone under-states the variance of three passes 8.7-fold (σ 2.95-fold), so the bake
//! stopped sampling at about three times its bound. Each pass therefore multiplies it by
//! its correlation gain ([`correlation_gain`]), exact for the unconstrained kernel and
//! scaled down where edge-stopping leaves a texel fewer taps to share. What remains
//! optimistic is the weights' dependence on the noise they average (taps near a texel's own
//! value weigh more): on pure noise the claim is about 1.5× below the output's variance.
//! The bias the filter adds is measured, not modelled (docs/results.md).
//!
//! [`filter_points`] applies the same weights to scattered points (irradiance-map grid
//! samples), finding neighbours in space ([`points`]).

use glam::Vec3;
use rayon::prelude::*;
use surfcache_core::color::luminance;

mod points;
pub use points::{PointFilterInput, filter_points};

/// Taps whose normals are less parallel than this are never mixed.
pub const MIN_NORMAL_COS: f32 = 0.9;

/// A tap `k` texels away in the texture whose sample point lies farther than
/// `MAX_STRETCH · k · texel` away in the scene is on another chart or across a gutter.
pub const MAX_STRETCH: f32 = 2.0;

/// How strongly the filter shares samples.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterSettings {
    /// À-trous passes (steps 1, 2, 4, …): the footprint reaches 4·(2^iterations − 1) + 1
    /// texels across. 0 turns filtering off. Default 1: more passes share more samples but
    /// blur where E curves within the footprint, which costs more than they save
    /// (docs/results.md, "Sponza: error against time").
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
            iterations: 1,
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
    let full_taps = 1.0 / b3_square_sum().powi(2);
    for k in 0..settings.iterations {
        let pass = Pass {
            step: 1isize << k,
            gain: correlation_gain(k),
            full_taps,
        };
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
                    let (v, s) = filter_texel(input, settings, src_v, src_s, x, y, &pass);
                    row_v[x] = v;
                    row_s[x] = s;
                }
            });
        std::mem::swap(&mut value, &mut next_value);
        std::mem::swap(&mut variance, &mut next_variance);
    }
    (value, variance)
}

/// Σ h² of the 1-D B3 kernel; squared, the variance factor of one unconstrained 2-D pass
/// over independent taps, whose inverse is the pass' effective count of taps.
fn b3_square_sum() -> f32 {
    B3.iter().map(|h| h * h).sum()
}

/// What one à-trous pass needs besides the texels.
struct Pass {
    /// Tap spacing in texels, `2^k` for pass `k`.
    step: isize,
    /// The pass' [`correlation_gain`].
    gain: f32,
    /// Effective taps of an unconstrained pass, `1/(Σ h²)²`.
    full_taps: f32,
}

/// Correlation gain of à-trous pass `k` (steps 1, 2, 4, …; module docs): for i.i.d. input
/// of variance σ² and no edge-stopping, the composite kernel `M` of passes `0..=k` gives
/// the exact variance `σ² Σ_q M²_pq` (variance of a linear filter of independent samples),
/// while the per-pass formula gives `σ² (Σ h²)^(2(k+1))`. The gain is the ratio of that
/// ratio between pass `k` and pass `k − 1`: 1 for the first pass, 2.73 for the second, 3.19
/// for the third, tending to 3.33. Computed from the separable 1-D kernels.
pub fn correlation_gain(k: u32) -> f32 {
    // 1-D composite kernels of passes 0..k (without and with pass k).
    let mut composite = vec![1.0f64];
    let mut ratios = [1.0f64; 2];
    let h1 = b3_square_sum() as f64;
    for pass in 0..=k.min(16) {
        let step = 1usize << pass;
        let mut next = vec![0.0f64; composite.len() + 4 * step];
        for (i, a) in composite.iter().enumerate() {
            for (j, b) in B3.iter().enumerate() {
                next[i + j * step] += a * *b as f64;
            }
        }
        composite = next;
        let exact: f64 = composite.iter().map(|c| c * c).sum();
        ratios = [ratios[1], exact / h1.powi(pass as i32 + 1)];
    }
    ((ratios[1] / ratios[0]).powi(2)) as f32
}

/// The texel or point a tap sum is for, as the edge-stopping functions see it.
struct Centre {
    position: Vec3,
    normal: Vec3,
    /// Luminance of its value and of its variance.
    luminance: f32,
    variance: f32,
    /// 1 / (σ_x · spacing): the plane distance's scale.
    plane_scale: f32,
}

impl Centre {
    /// The weight of a tap at `position` with `normal`, `value` and `variance`: its
    /// spatial `kernel` weight times the edge-stopping functions (module docs: normal,
    /// plane distance, value); 0 for a tap whose normal is less parallel than
    /// [`MIN_NORMAL_COS`].
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn weight(
        &self,
        settings: &FilterSettings,
        kernel: f32,
        floor: f32,
        position: Vec3,
        normal: Vec3,
        value: Vec3,
        variance: Vec3,
    ) -> f32 {
        let cos = self.normal.dot(normal);
        if cos < MIN_NORMAL_COS {
            return 0.0;
        }
        let plane = self.normal.dot(position - self.position) * self.plane_scale;
        let sigma = settings.sigma_value * (self.variance + luminance(variance)).max(0.0).sqrt();
        let dv =
            (self.luminance - luminance(value)).abs() / (sigma + 1e-3 * floor + f32::MIN_POSITIVE);
        kernel * cos.powf(settings.sigma_normal) * (-plane * plane - dv).exp()
    }
}

/// One à-trous tap sum at texel (x, y) for `pass` (module docs); the pass' correlation
/// gain applies in full where the texel shares as many taps as an unconstrained pass and
/// not at all where it shares none.
#[inline]
fn filter_texel(
    input: &FilterInput,
    settings: &FilterSettings,
    value: &[Vec3],
    variance: &[Vec3],
    x: usize,
    y: usize,
    pass: &Pass,
) -> (Vec3, Vec3) {
    let step = pass.step;
    let (w, h) = (input.width as isize, input.height as isize);
    let p = y * input.width + x;
    let centre = Centre {
        position: input.position[p],
        normal: input.normal[p],
        luminance: luminance(value[p]),
        variance: luminance(variance[p]),
        plane_scale: 1.0 / (settings.sigma_plane * input.texel),
    };
    let (mut sum_w, mut sum_w2, mut sum_v, mut sum_s) = (0.0f32, 0.0f32, Vec3::ZERO, Vec3::ZERO);
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
                let reach = ((i as isize - 2).abs().max((j as isize - 2).abs()) * step) as f32
                    * std::f32::consts::SQRT_2
                    * MAX_STRETCH
                    * input.texel;
                if (input.position[q] - centre.position).length_squared() > reach * reach {
                    continue;
                }
                let weight = centre.weight(
                    settings,
                    hi * hj,
                    input.floor,
                    input.position[q],
                    input.normal[q],
                    value[q],
                    variance[q],
                );
                if weight == 0.0 {
                    continue;
                }
                weight
            };
            sum_w += weight;
            sum_w2 += weight * weight;
            sum_v += weight * value[q];
            sum_s += weight * weight * variance[q];
        }
    }
    // Effective taps (Σw)²/Σw² against the unconstrained pass' 1/(Σh²)².
    let gain = shared_gain(sum_w * sum_w / sum_w2, pass.full_taps, pass.gain);
    (sum_v / sum_w, gain * sum_s / (sum_w * sum_w))
}

/// The correlation gain that a texel or point with `taps` effective taps, `(Σw)²/Σw²`,
/// takes from a pass of correlation gain `gain` whose unconstrained kernel has
/// `full_taps`: all of it where it shares as many taps, none where it shares none.
#[inline]
fn shared_gain(taps: f32, full_taps: f32, gain: f32) -> f32 {
    let share = ((taps - 1.0) / (full_taps - 1.0)).clamp(0.0, 1.0);
    1.0 + (gain - 1.0) * share
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` lattice of points 0.1 apart on the plane y = 0, facing +Y.
    pub(super) fn plane(w: usize, h: usize) -> (Vec<Vec3>, Vec<Vec3>) {
        let pos = (0..w * h)
            .map(|k| Vec3::new((k % w) as f32, 0.0, (k / w) as f32) * 0.1)
            .collect();
        (pos, vec![Vec3::Y; w * h])
    }

    /// Filters `value` with `variance` on a `w × h` plane of 0.1 texels, every texel valid.
    fn filter_plane(
        w: usize,
        h: usize,
        value: &[Vec3],
        variance: &[Vec3],
        settings: &FilterSettings,
    ) -> (Vec<Vec3>, Vec<Vec3>) {
        let (pos, nrm) = plane(w, h);
        let valid = vec![true; w * h];
        let input = FilterInput {
            width: w,
            height: h,
            value,
            variance,
            position: &pos,
            normal: &nrm,
            valid: &valid,
            texel: 0.1,
            floor: 0.01,
        };
        filter(&input, settings)
    }

    #[test]
    fn noise_is_shared_and_variance_falls() {
        let (w, h) = (32, 32);
        let mut rng = surfcache_core::sampling::Rng::new(1, 2);
        let value: Vec<Vec3> = (0..w * h)
            .map(|_| Vec3::splat(1.0 + 0.1 * (rng.next_f32() - 0.5) * 3.46))
            .collect();
        let variance = vec![Vec3::splat(0.01); w * h];
        let (v, s) = filter_plane(w, h, &value, &variance, &FilterSettings::default());
        let rms = |v: &[Vec3]| {
            (v.iter().map(|x| (x.x - 1.0).powi(2)).sum::<f32>() / v.len() as f32).sqrt()
        };
        assert!(rms(&v) < 0.35 * rms(&value), "{} {}", rms(&v), rms(&value));
        // One pass: a texel with all 25 taps claims (Σh²)² ≈ 0.075 of its input variance,
        // a corner texel (9 taps) about 0.19; none claims more than half.
        assert!(s.iter().all(|s| s.x < 0.01 * 0.5));
        let interior = s[(h / 2) * w + w / 2].x;
        assert!(interior < 0.01 * 0.1, "{interior}");
    }

    /// The variance the filter claims for a texel against the variance of its output over
    /// many independent noise fields (the centre texel of a plane, far from the borders).
    fn claimed_and_measured_variance(settings: &FilterSettings) -> (f32, f32) {
        let (w, h) = (64, 64);
        let variance = vec![Vec3::splat(0.01); w * h];
        let centre = (h / 2) * w + w / 2;
        let (mut claimed, mut sum, mut sum_sq) = (0.0, 0.0, 0.0);
        let fields = 400;
        for seed in 0..fields {
            let mut rng = surfcache_core::sampling::Rng::new(seed, 7);
            // Uniform noise of variance 0.01 around 1.
            let value: Vec<Vec3> = (0..w * h)
                .map(|_| Vec3::splat(1.0 + 0.1 * (rng.next_f32() - 0.5) * 12f32.sqrt()))
                .collect();
            let (v, s) = filter_plane(w, h, &value, &variance, settings);
            claimed += s[centre].x as f64 / fields as f64;
            sum += v[centre].x as f64;
            sum_sq += (v[centre].x as f64).powi(2);
        }
        let n = fields as f64;
        let measured = (sum_sq - sum * sum / n) / (n - 1.0);
        (claimed as f32, measured as f32)
    }

    #[test]
    fn claimed_variance_is_the_variance_of_the_output() {
        // Without edge-stopping the filter is linear and the claim is exact (up to the
        // 7 % sampling error of a variance from 400 fields).
        let linear = FilterSettings {
            sigma_value: 1e9,
            ..FilterSettings::default()
        };
        for iterations in 1..=4 {
            let settings = FilterSettings {
                iterations,
                ..linear
            };
            let (claimed, measured) = claimed_and_measured_variance(&settings);
            assert!(
                (claimed / measured - 1.0).abs() < 0.25,
                "{iterations} passes: claimed {claimed}, measured {measured}"
            );
        }
        // The value weights depend on the noise they average (taps close to the texel's
        // own value weigh more), which keeps more of its own noise than Σw² says: on pure
        // noise the claim is about 1.5× optimistic in variance (module docs), on top of
        // the passes' 8.7× without the correlation gains.
        let (claimed, measured) = claimed_and_measured_variance(&FilterSettings::default());
        assert!(
            claimed > 0.55 * measured,
            "claimed {claimed}, measured {measured}"
        );
    }

    #[test]
    fn correlation_gains_of_the_first_passes() {
        // Values from the composite B3 kernels (module docs).
        let expected = [1.0, 2.73, 3.19, 3.31];
        for (k, e) in expected.iter().enumerate() {
            let g = correlation_gain(k as u32);
            assert!((g - e).abs() < 0.01, "pass {k}: {g}");
        }
    }

    #[test]
    fn a_resolved_edge_stays_sharp() {
        // Left half lit (E = 1), right half dark (E = 0.1), precise estimates.
        let (w, h) = (16, 8);
        let value: Vec<Vec3> = (0..w * h)
            .map(|k| Vec3::splat(if k % w < w / 2 { 1.0 } else { 0.1 }))
            .collect();
        let variance = vec![Vec3::splat(1e-4); w * h];
        let (v, _) = filter_plane(w, h, &value, &variance, &FilterSettings::default());
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
