//! Sharing samples between scattered points (the grid samples of irradiance maps): the
//! texels' edge-stopping weights (the module docs of [`super`]) over neighbours found in
//! space instead of in a texture.
//!
//! Every point p carries its own sample spacing `h_p` (the spacing of its grid). Pass k
//! replaces p by the weighted mean of the points q closer than `REACH · 2^k · h_pq`,
//! `h_pq = min(h_p, h_q)`, with the Gaussian `exp(−d² / (2 (2^k h_pq)²))`, whose variance per axis is the B3 kernel's
//! (one step), times the normal, plane distance (in units of `2^k h_p`) and value
//! weights of texels. Taking the smaller spacing keeps a fine grid's resolution (a
//! contact that the grid resolves at 2 cm is not averaged over the 12.5 cm of a coarse
//! neighbour) and makes the spatial weight symmetric.
//!
//! Variances follow the weights, `σ²_out = gain · Σ w² σ²_q / (Σ w)²`, with the texels'
//! correlation gain for passes after the first, scaled by the share of an unconstrained
//! pass' taps the point has. A mean noisier than the point's own estimate is not used.
//!
//! **Scale.** A mean over E is biased where E curves within the kernel (about σ²E''/2
//! for a Gaussian of scale σ) and, to first order, wherever the taps are lopsided: at a
//! border, where all taps lie on one side (the end of a dark tunnel takes the brighter
//! light of the tunnel behind it), and where a fine and a coarse grid meet. An
//! irradiance-map grid that stopped refining interpolates linearly with an error up to
//! h²E''/8, which its refinement test bounds; at σ = h/2 a mean adds no more than that,
//! at σ = h four times as much, and where a grid is held at its maximum order (E falling
//! off along a dark tunnel, a crossed grid) nothing bounds E'' at all (docs/results.md,
//! "Irradiance maps share samples"). So each point takes the means at the scales h/2,
//! h/√2 and h ([`SCALES`]) and keeps the largest whose value lies within
//! [`SCALE_SIGMAS`] standard errors of every smaller scale's (the intersection of
//! confidence intervals, Katkovnik 1999): where E is flat the noise decides and the
//! largest scale shares the most samples; where E curves or the taps are lopsided the
//! means disagree and the point stays at a smaller scale.
//!
//! Neighbours are found through one hashed uniform grid per spacing class (spacings
//! within a factor of two share a class), each with cells as large as its points'
//! reach: a point visits at most 27 cells of each class present.

use super::{Centre, FilterSettings, correlation_gain, shared_gain};
use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;
use surfcache_core::{color::luminance, sampling::splitmix64};

/// Reach of a pass in kernel scales: the B3 taps reach two steps along an axis and
/// 2√2 steps on a diagonal.
pub const REACH: f32 = 2.0 * std::f32::consts::SQRT_2;

/// Effective taps `(Σw)² / Σw²` of an unconstrained Gaussian of scale h over points
/// spaced h apart: 4π.
const FULL_TAPS: f32 = 4.0 * std::f32::consts::PI;

/// Spacing classes: spacings from the largest down to 2^−(CLASSES−1) of it each have a
/// class, smaller ones share the last.
const CLASSES: u32 = 8;

/// Scattered points as the filter sees them.
pub struct PointFilterInput<'a> {
    /// Estimated irradiance per point.
    pub value: &'a [Vec3],
    /// Variance of each estimate (per channel, of the mean).
    pub variance: &'a [Vec3],
    /// World position and unit normal of each point.
    pub position: &'a [Vec3],
    pub normal: &'a [Vec3],
    /// Sample spacing at each point (metres, positive): the kernel's scale.
    pub spacing: &'a [f32],
    /// Points that take part as taps (estimated, not buried).
    pub valid: &'a [bool],
    /// Valid points whose value the filter replaces; the others keep theirs.
    pub filtered: &'a [bool],
    /// Points that share samples only with taps the `visible` test passes (both ways):
    /// points near a surface that may stand between them and a neighbour.
    pub guarded: &'a [bool],
    /// The absolute floor ε of relative errors (W/m²).
    pub floor: f32,
}

/// Filters `input` (module docs); returns the values and variances of every point
/// (unchanged where it is not filtered). `visible(p, q)` says whether nothing separates
/// points p and q; it is asked only for taps of or at guarded points.
pub fn filter_points(
    input: &PointFilterInput,
    settings: &FilterSettings,
    visible: &(dyn Fn(usize, usize) -> bool + Sync),
) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut value = input.value.to_vec();
    let mut variance = input.variance.to_vec();
    let largest = (0..value.len())
        .filter(|&p| input.valid[p])
        .map(|p| input.spacing[p])
        .fold(0.0f32, f32::max);
    if settings.iterations == 0 || largest <= 0.0 {
        return (value, variance);
    }
    for k in 0..settings.iterations {
        let scale = (1u32 << k.min(20)) as f32;
        let grid = ClassGrids::new(input, largest * scale);
        let gain = correlation_gain(k);
        let pass = PointPass {
            input,
            settings,
            grid: &grid,
            value: &value,
            variance: &variance,
            scale,
            gain,
            visible,
        };
        (value, variance) = (0..value.len())
            .into_par_iter()
            .map_init(Vec::new, |taps, p| {
                if input.valid[p] && input.filtered[p] {
                    pass.filter_point(p, taps)
                } else {
                    (value[p], variance[p])
                }
            })
            .unzip();
    }
    (value, variance)
}

/// The valid points, sorted by spacing class and hashed cell, and where each cell's
/// points lie in that order.
struct ClassGrids {
    /// Cell size of class 0 (the largest spacing's reach); class c has `size / 2^c`.
    size: f32,
    /// Classes that hold points.
    present: Vec<u32>,
    order: Vec<u32>,
    cells: HashMap<u64, (u32, u32)>,
}

impl ClassGrids {
    /// Grids of cells as large as the reach of their class' largest spacing, the
    /// largest being `largest` (times the pass' scale).
    fn new(input: &PointFilterInput, largest: f32) -> Self {
        let size = REACH * largest;
        let mut keyed: Vec<(u64, u32)> = (0..input.value.len() as u32)
            .into_par_iter()
            .filter(|&p| input.valid[p as usize])
            .map(|p| {
                let p = p as usize;
                let class = class_of(input.spacing[p], largest);
                let cell = cell_of(input.position[p], size / (1u32 << class) as f32);
                (cell_key(class, cell), p as u32)
            })
            .collect();
        keyed.par_sort_unstable();
        let mut cells = HashMap::new();
        let mut present = Vec::new();
        let mut start = 0;
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            cells.insert(group[0].0, (start as u32, (start + group.len()) as u32));
            let class = class_of(input.spacing[group[0].1 as usize], largest);
            if !present.contains(&class) {
                present.push(class);
            }
            start += group.len();
        }
        present.sort_unstable();
        Self {
            size,
            present,
            order: keyed.into_iter().map(|(_, p)| p).collect(),
            cells,
        }
    }

    /// Visits every point of class `class` in the cells within `radius` of `x`.
    #[inline]
    fn visit(&self, class: u32, x: Vec3, radius: f32, mut f: impl FnMut(usize)) {
        let size = self.size / (1u32 << class) as f32;
        let (lo, hi) = (cell_of(x - radius, size), cell_of(x + radius, size));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    if let Some(&(a, b)) = self.cells.get(&cell_key(class, IVec3::new(x, y, z))) {
                        self.order[a as usize..b as usize]
                            .iter()
                            .for_each(|&q| f(q as usize));
                    }
                }
            }
        }
    }
}

/// The class of `spacing`: c where it lies in (largest / 2^(c+1), largest / 2^c].
#[inline]
fn class_of(spacing: f32, largest: f32) -> u32 {
    let ratio = (largest / spacing.max(f32::MIN_POSITIVE)).max(1.0);
    (ratio.log2().floor() as u32).min(CLASSES - 1)
}

#[inline]
fn cell_of(x: Vec3, size: f32) -> IVec3 {
    (x / size).floor().as_ivec3()
}

/// A hash of (class, cell); two cells that share one only cost time: candidates are
/// checked by distance.
#[inline]
fn cell_key(class: u32, cell: IVec3) -> u64 {
    let [x, y, z] = cell.to_array().map(|c| c as u32 as u64);
    splitmix64(splitmix64(x ^ (y << 32)) ^ z ^ ((class as u64) << 40))
}

/// What one pass reads: the input, the values and variances of the pass before, the
/// neighbour grids, the pass' scale (2^k) and correlation gain, and the visibility test.
struct PointPass<'a> {
    input: &'a PointFilterInput<'a>,
    settings: &'a FilterSettings,
    grid: &'a ClassGrids,
    value: &'a [Vec3],
    variance: &'a [Vec3],
    scale: f32,
    gain: f32,
    visible: &'a (dyn Fn(usize, usize) -> bool + Sync),
}

/// One tap of a point: its index, its edge-stopping weight and its squared distance in
/// units of h_pq.
type Tap = (u32, f32, f32);

/// Kernel scales the mean tries, as fractions of h (module docs, Scale): the first one's
/// bias is at most the grid's own interpolation error.
const SCALES: [f32; 3] = [0.5, std::f32::consts::FRAC_1_SQRT_2, 1.0];

/// A mean at a larger scale is kept while its value lies within this many standard
/// errors of every smaller scale's.
const SCALE_SIGMAS: f32 = 1.0;

impl PointPass<'_> {
    /// The filtered value and variance of point `p` (module docs): the weighted mean of
    /// its taps (collected into `taps`) at the largest scale the smaller ones agree with.
    fn filter_point(&self, p: usize, taps: &mut Vec<Tap>) -> (Vec3, Vec3) {
        let (input, value, variance) = (self.input, self.value, self.variance);
        let h_p = input.spacing[p] * self.scale;
        let centre = Centre {
            position: input.position[p],
            normal: input.normal[p],
            luminance: luminance(value[p]),
            variance: luminance(variance[p]),
            plane_scale: 1.0 / (self.settings.sigma_plane * h_p),
        };
        taps.clear();
        taps.push((p as u32, 1.0, 0.0));
        for &class in &self.grid.present {
            let class_h = self.grid.size / REACH / (1u32 << class) as f32;
            let radius = REACH * h_p.min(class_h);
            self.grid.visit(class, centre.position, radius, |q| {
                if q == p {
                    return;
                }
                let h = h_p.min(input.spacing[q] * self.scale);
                let d = input.position[q] - centre.position;
                let r2 = d.length_squared() / (h * h);
                if r2 > REACH * REACH {
                    return;
                }
                let stop = centre.weight(
                    self.settings,
                    1.0,
                    input.floor,
                    input.position[q],
                    input.normal[q],
                    value[q],
                    variance[q],
                );
                if stop == 0.0 || ((input.guarded[p] || input.guarded[q]) && !(self.visible)(p, q))
                {
                    return;
                }
                taps.push((q as u32, stop, r2));
            });
        }
        // Intersection of confidence intervals over the scales, smallest first.
        let mut kept = (value[p], variance[p]);
        let (mut lo, mut hi) = (f32::NEG_INFINITY, f32::INFINITY);
        for k in SCALES {
            let Some((v, s)) = self.mean(taps, k) else {
                continue;
            };
            let (y, e) = (luminance(v), SCALE_SIGMAS * luminance(s).max(0.0).sqrt());
            if y < lo || y > hi {
                break;
            }
            (lo, hi) = (lo.max(y - e), hi.min(y + e));
            kept = (v, s);
        }
        kept
    }

    /// The weighted mean of `taps` with the Gaussian of scale k·h: value and variance,
    /// or `None` where it would be noisier than the point's own estimate.
    fn mean(&self, taps: &[Tap], k: f32) -> Option<(Vec3, Vec3)> {
        let (reach2, inv) = ((REACH * k).powi(2), -0.5 / (k * k));
        let (mut sum_w, mut sum_w2) = (0.0f32, 0.0f32);
        let (mut sum_v, mut sum_s) = (Vec3::ZERO, Vec3::ZERO);
        for &(q, stop, r2) in taps.iter().filter(|t| t.2 <= reach2) {
            let w = stop * (r2 * inv).exp();
            sum_w += w;
            sum_w2 += w * w;
            sum_v += w * self.value[q as usize];
            sum_s += w * w * self.variance[q as usize];
        }
        // Effective taps (Σw)²/Σw² against an unconstrained pass'.
        let gain = shared_gain(sum_w * sum_w / sum_w2, FULL_TAPS, self.gain);
        let variance = gain * sum_s / (sum_w * sum_w);
        let own = self.variance[taps[0].0 as usize];
        (luminance(variance) <= luminance(own)).then_some((sum_v / sum_w, variance))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::tests::plane as lattice;

    fn run(
        position: &[Vec3],
        normal: &[Vec3],
        value: &[Vec3],
        variance: &[Vec3],
        spacing: &[f32],
        valid: &[bool],
    ) -> (Vec<Vec3>, Vec<Vec3>) {
        let input = PointFilterInput {
            value,
            variance,
            position,
            normal,
            spacing,
            valid,
            filtered: valid,
            guarded: &vec![false; valid.len()],
            floor: 0.01,
        };
        filter_points(&input, &FilterSettings::default(), &|_, _| true)
    }

    #[test]
    fn noise_is_shared_and_variance_falls() {
        let (w, h) = (32, 32);
        let (pos, nrm) = lattice(w, h);
        let mut rng = surfcache_core::sampling::Rng::new(1, 2);
        let value: Vec<Vec3> = (0..w * h)
            .map(|_| Vec3::splat(1.0 + 0.1 * (rng.next_f32() - 0.5) * 3.46))
            .collect();
        let variance = vec![Vec3::splat(0.01); w * h];
        let spacing = vec![0.1; w * h];
        let valid = vec![true; w * h];
        let (v, s) = run(&pos, &nrm, &value, &variance, &spacing, &valid);
        let rms = |v: &[Vec3]| {
            (v.iter().map(|x| (x.x - 1.0).powi(2)).sum::<f32>() / v.len() as f32).sqrt()
        };
        assert!(rms(&v) < 0.4 * rms(&value), "{} {}", rms(&v), rms(&value));
        let interior = s[(h / 2) * w + w / 2].x;
        assert!(interior < 0.01 * 0.15, "{interior}");
        // One pass: a point with all its taps claims about 1/4π of its input variance,
        // a corner point more; none claims more than half.
        assert!(s.iter().all(|s| s.x < 0.01 * 0.5));
    }

    #[test]
    fn a_resolved_edge_stays_sharp() {
        // Left half lit (E = 1), right half dark (E = 0.1), precise estimates.
        let (w, h) = (16, 8);
        let (pos, nrm) = lattice(w, h);
        let value: Vec<Vec3> = (0..w * h)
            .map(|k| Vec3::splat(if k % w < w / 2 { 1.0 } else { 0.1 }))
            .collect();
        let variance = vec![Vec3::splat(1e-4); w * h];
        let (v, _) = run(&pos, &nrm, &value, &variance, &[0.1; 128], &[true; 128]);
        for (k, (a, b)) in v.iter().zip(&value).enumerate() {
            assert!(
                (a.x - b.x).abs() < 1e-3 * b.x.max(0.1),
                "point {k}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn fine_points_keep_their_resolution() {
        // A fine row (spacing 1 cm) of alternating precise values 1 and 2 beside a
        // coarse row (10 cm) of noisy ones: a coarse point never reaches the fine ones
        // farther than the fine reach, and the fine points mix only within theirs.
        let fine: Vec<Vec3> = (0..20)
            .map(|i| Vec3::new(i as f32 * 0.01, 0.0, 0.0))
            .collect();
        let coarse: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new(i as f32 * 0.1, 0.0, 0.5))
            .collect();
        let position: Vec<Vec3> = fine.iter().chain(&coarse).copied().collect();
        let n = position.len();
        let value: Vec<Vec3> = (0..n)
            .map(|k| Vec3::splat(if k < 20 { 1.0 + (k / 10) as f32 } else { 1.5 }))
            .collect();
        let variance = vec![Vec3::splat(1e-2); n];
        let spacing: Vec<f32> = (0..n).map(|k| if k < 20 { 0.01 } else { 0.1 }).collect();
        let (v, _) = run(
            &position,
            &vec![Vec3::Y; n],
            &value,
            &variance,
            &spacing,
            &vec![true; n],
        );
        // The coarse row lies 0.5 m from the fine one: farther than any reach.
        for (k, v) in v.iter().enumerate().skip(20) {
            assert!(
                (v.x - 1.5).abs() < 1e-5,
                "coarse point {k} took from the fine row: {v}"
            );
        }
        // Fine points three spacings or more from the step keep their value.
        for k in (0..7).chain(13..20) {
            assert!(
                (v[k].x - value[k].x).abs() < 1e-3,
                "fine point {k}: {}",
                v[k]
            );
        }
    }

    #[test]
    fn creases_and_invalid_points_are_not_mixed() {
        // Two rows folded at 90°: one faces +Y, the other +Z; one point is invalid.
        let w = 8;
        let position: Vec<Vec3> = (0..2 * w)
            .map(|k| Vec3::new((k % w) as f32 * 0.1, 0.0, 0.0))
            .collect();
        let normal: Vec<Vec3> = (0..2 * w)
            .map(|k| if k < w { Vec3::Y } else { Vec3::Z })
            .collect();
        let value: Vec<Vec3> = (0..2 * w)
            .map(|k| Vec3::splat(if k < w { 1.0 } else { 5.0 }))
            .collect();
        let mut poisoned = value.clone();
        poisoned[3] = Vec3::splat(1e6);
        let mut valid = vec![true; 2 * w];
        valid[3] = false;
        let (v, _) = run(
            &position,
            &normal,
            &poisoned,
            &vec![Vec3::splat(100.0); 2 * w],
            &vec![0.1; 2 * w],
            &valid,
        );
        for k in (0..2 * w).filter(|&k| k != 3) {
            assert!((v[k].x - value[k].x).abs() < 1e-4, "point {k}: {}", v[k]);
        }
        assert_eq!(v[3], poisoned[3]);
    }

    #[test]
    fn guarded_points_share_only_with_visible_taps() {
        // One row of noisy values around 1 and 3 (a wall between x < 0.4 and x ≥ 0.4
        // that the value weights alone would not always see: large variances).
        let w = 8;
        let position: Vec<Vec3> = (0..w)
            .map(|k| Vec3::new(k as f32 * 0.1, 0.0, 0.0))
            .collect();
        let value: Vec<Vec3> = (0..w)
            .map(|k| Vec3::splat(if k < 4 { 1.0 } else { 3.0 }))
            .collect();
        let variance = vec![Vec3::splat(100.0); w];
        let spacing = vec![0.1; w];
        let valid = vec![true; w];
        let guarded: Vec<bool> = (0..w).map(|k| k == 3).collect();
        let input = PointFilterInput {
            value: &value,
            variance: &variance,
            position: &position,
            normal: &vec![Vec3::Y; w],
            spacing: &spacing,
            valid: &valid,
            filtered: &valid,
            guarded: &guarded,
            floor: 0.01,
        };
        let side = |k: usize| k < 4;
        let (v, _) = filter_points(&input, &FilterSettings::default(), &|p, q| {
            side(p) == side(q)
        });
        // The guarded point next to the wall takes nothing from across it.
        assert!((v[3].x - 1.0).abs() < 1e-5, "{}", v[3]);
        // Unguarded points do (the test is asked only where a point is guarded).
        assert!(v[2].x > 1.01, "{}", v[2]);
    }
}
