//! Guided hemisphere sampling: directions drawn where neighbouring estimates found the
//! light (docs/design.md, Guiding).
//!
//! Cosine-weighted directions come from points `u` of the unit square
//! ([`cosine_hemisphere`]). A [`DirectionGuide`] is a piecewise-constant density `g(u)`
//! over an 8 × 8 grid of that square, learned from a [`GuideRecord`] of earlier samples:
//! a direction is then drawn with density `p(ω) = cos θ/π · g(u(ω))` on the hemisphere.
//! The estimate stays unbiased for any guide, because `g` is a mixture
//! `g = α · h / mean(h) + (1 − α)` whose uniform part keeps it positive wherever the
//! cosine density is; a good guide only lowers the variance (Vorba et al. 2014 and Müller
//! et al. 2017 learn such densities over directions; here over the primary sample square,
//! so that the density needs no world-space table and follows each point's own frame).
//!
//! Recording is deterministic whatever the threads: a record sums fixed-point integers,
//! so the order in which samples arrive does not change it.
//!
//! ```
//! use surfcache_core::glam::Vec2;
//! use surfcache_trace::guiding::{DirectionGuide, GuideRecord};
//! let record = GuideRecord::new(1.0);
//! // All the light arrived through one cell of the square.
//! for _ in 0..100 {
//!     record.add(Vec2::new(0.9, 0.1), 5.0);
//! }
//! let guide = DirectionGuide::from_record(&record).unwrap();
//! assert!(guide.density(Vec2::new(0.9, 0.1)) > 10.0);
//! assert!(guide.density(Vec2::new(0.1, 0.9)) > 0.0);
//! ```

use glam::Vec2;
use std::sync::atomic::{AtomicU64, Ordering};
use surfcache_core::sampling::ONE_MINUS_EPSILON;

/// Cells along each side of the square.
pub const GUIDE_RESOLUTION: usize = 8;

/// Cells of a guide.
pub const GUIDE_CELLS: usize = GUIDE_RESOLUTION * GUIDE_RESOLUTION;

/// Share of a guide's density that follows the recorded light (α above); the rest is
/// uniform over the square, i.e. plain cosine sampling.
pub const GUIDE_SHARE: f32 = 0.75;

/// Least spread of the recorded light over the cells (coefficient of variation of the
/// cells) for which a guide is made: where light arrives from all over the hemisphere
/// (open sky), stratified cosine-weighted points already integrate it well, and a
/// piecewise-constant guide would only break their stratification
/// (docs/results.md, "Guiding").
pub const MIN_SPREAD: f64 = 0.75;

/// Each cell's recorded light is raised by this share of the mean cell before it is
/// normalised, so that a cell no recorded sample lit is still drawn now and then by the
/// guided part too.
const CELL_FLOOR: f32 = 0.05;

/// Fixed-point steps per unit of a record's scale.
const FIXED_POINT: f32 = 1024.0;

/// Light seen through each cell of the square by earlier samples, summed as fixed-point
/// integers (deterministic under any thread order).
#[derive(Debug)]
pub struct GuideRecord {
    /// Irradiance scale (W/m²) of one unit: values far below it are noise for a guide.
    unit: f32,
    cells: [AtomicU64; GUIDE_CELLS],
    samples: AtomicU64,
}

impl GuideRecord {
    /// An empty record whose values are counted in units of `unit` (a scene's irradiance
    /// scale; see [`crate::FLOOR_FRACTION`]).
    pub fn new(unit: f32) -> Self {
        Self {
            unit: if unit.is_finite() && unit > 0.0 {
                unit
            } else {
                1.0
            },
            cells: std::array::from_fn(|_| AtomicU64::new(0)),
            samples: AtomicU64::new(0),
        }
    }

    /// Adds one sample drawn at square point `u` that carried `value` (luminance of its
    /// contribution divided by the density it was drawn with on the square).
    #[inline]
    pub fn add(&self, u: Vec2, value: f32) {
        self.samples.fetch_add(1, Ordering::Relaxed);
        if !(value.is_finite() && value > 0.0) {
            return;
        }
        let steps = (value / self.unit * FIXED_POINT).min(1e12) as u64;
        if steps > 0 {
            self.cells[cell(u)].fetch_add(steps, Ordering::Relaxed);
        }
    }

    /// Samples recorded.
    pub fn samples(&self) -> u64 {
        self.samples.load(Ordering::Relaxed)
    }

    /// Adds every cell of `other` (records of neighbouring points pooled into one guide).
    pub fn absorb(&self, other: &GuideRecord) {
        for (a, b) in self.cells.iter().zip(&other.cells) {
            a.fetch_add(b.load(Ordering::Relaxed), Ordering::Relaxed);
        }
        self.samples.fetch_add(other.samples(), Ordering::Relaxed);
    }
}

/// A copy holds what the record held when it was copied.
impl Clone for GuideRecord {
    fn clone(&self) -> Self {
        let copy = Self::new(self.unit);
        copy.absorb(self);
        copy
    }
}

/// Records are equal when they hold the same sums in the same units.
impl PartialEq for GuideRecord {
    fn eq(&self, other: &Self) -> bool {
        self.unit == other.unit
            && self.samples() == other.samples()
            && self
                .cells
                .iter()
                .zip(&other.cells)
                .all(|(a, b)| a.load(Ordering::Relaxed) == b.load(Ordering::Relaxed))
    }
}

/// The cell of square point `u` (row-major).
#[inline]
fn cell(u: Vec2) -> usize {
    let n = GUIDE_RESOLUTION as f32;
    let i = ((u.x * n) as usize).min(GUIDE_RESOLUTION - 1);
    let j = ((u.y * n) as usize).min(GUIDE_RESOLUTION - 1);
    j * GUIDE_RESOLUTION + i
}

/// A density over the unit square of cosine-weighted sampling, piecewise constant on
/// 8 × 8 cells, mean 1 (module docs). Rows are chosen by `u.y`, then a cell within the row
/// by `u.x` (marginal and conditional distributions, pbrt-v4 §A.5.6), so stratified
/// points stay stratified.
#[derive(Clone, Debug, PartialEq)]
pub struct DirectionGuide {
    density: [f32; GUIDE_CELLS],
    /// Cumulative shares of the rows, `row_cdf[0] = 0`, `row_cdf[R] = 1`.
    row_cdf: [f32; GUIDE_RESOLUTION + 1],
    /// Cumulative shares of the cells within each row.
    cell_cdf: [[f32; GUIDE_RESOLUTION + 1]; GUIDE_RESOLUTION],
}

impl DirectionGuide {
    /// The guide a record asks for, or `None` when it recorded no light or light spread
    /// over the hemisphere ([`MIN_SPREAD`]): plain cosine sampling is then as good.
    pub fn from_record(record: &GuideRecord) -> Option<Self> {
        let raw: [f64; GUIDE_CELLS] =
            std::array::from_fn(|k| record.cells[k].load(Ordering::Relaxed) as f64);
        let total: f64 = raw.iter().sum();
        if total <= 0.0 {
            return None;
        }
        let mean = total / GUIDE_CELLS as f64;
        let spread =
            (raw.iter().map(|&h| (h - mean) * (h - mean)).sum::<f64>() / GUIDE_CELLS as f64).sqrt()
                / mean;
        if spread < MIN_SPREAD {
            return None;
        }
        let floor = CELL_FLOOR as f64 * mean;
        let norm = mean + floor;
        let density: [f32; GUIDE_CELLS] = std::array::from_fn(|k| {
            (GUIDE_SHARE as f64 * (raw[k] + floor) / norm + (1.0 - GUIDE_SHARE as f64)) as f32
        });
        Some(Self::from_density(density))
    }

    /// Builds the tables of a density with mean 1 over the cells.
    fn from_density(density: [f32; GUIDE_CELLS]) -> Self {
        let r = GUIDE_RESOLUTION;
        let mut row_cdf = [0.0f32; GUIDE_RESOLUTION + 1];
        let mut cell_cdf = [[0.0f32; GUIDE_RESOLUTION + 1]; GUIDE_RESOLUTION];
        let row_sums: [f64; GUIDE_RESOLUTION] =
            std::array::from_fn(|j| density[j * r..(j + 1) * r].iter().map(|&d| d as f64).sum());
        let total: f64 = row_sums.iter().sum();
        let mut acc = 0.0f64;
        for j in 0..r {
            acc += row_sums[j];
            row_cdf[j + 1] = if j + 1 == r {
                1.0
            } else {
                (acc / total) as f32
            };
            let mut in_row = 0.0f64;
            for i in 0..r {
                in_row += density[j * r + i] as f64;
                cell_cdf[j][i + 1] = if i + 1 == r {
                    1.0
                } else {
                    (in_row / row_sums[j]) as f32
                };
            }
        }
        Self {
            density,
            row_cdf,
            cell_cdf,
        }
    }

    /// The guide's density at square point `u` (mean 1 over the square).
    #[inline]
    pub fn density(&self, u: Vec2) -> f32 {
        self.density[cell(u)]
    }

    /// Warps a uniform point of the square to one distributed as the guide, and returns
    /// it with its density there.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (j, y) = invert(&self.row_cdf, u.y);
        let (i, x) = invert(&self.cell_cdf[j], u.x);
        let n = GUIDE_RESOLUTION as f32;
        let warped =
            Vec2::new((i as f32 + x) / n, (j as f32 + y) / n).min(Vec2::splat(ONE_MINUS_EPSILON));
        (warped, self.density[j * GUIDE_RESOLUTION + i])
    }
}

/// The bin of `cdf` that holds `u`, and `u` remapped to [0, 1) inside it.
#[inline]
fn invert(cdf: &[f32; GUIDE_RESOLUTION + 1], u: f32) -> (usize, f32) {
    let i = (cdf[1..].partition_point(|&c| c <= u)).min(GUIDE_RESOLUTION - 1);
    let (lo, hi) = (cdf[i], cdf[i + 1]);
    let t = if hi > lo {
        ((u - lo) / (hi - lo)).clamp(0.0, ONE_MINUS_EPSILON)
    } else {
        0.5
    };
    (i, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use surfcache_core::sampling::Rng;

    fn skewed() -> DirectionGuide {
        let record = GuideRecord::new(0.5);
        let mut rng = Rng::new(3, 4);
        for _ in 0..5_000 {
            let u = rng.next_vec2();
            // Bright where u.x is large and u.y small, nothing in the top half.
            let v = if u.y < 0.5 { 10.0 * u.x * u.x } else { 0.0 };
            record.add(u, v);
        }
        DirectionGuide::from_record(&record).unwrap()
    }

    #[test]
    fn density_has_mean_one_and_stays_positive() {
        let g = skewed();
        let mean: f32 = g.density.iter().sum::<f32>() / GUIDE_CELLS as f32;
        assert!((mean - 1.0).abs() < 1e-4, "{mean}");
        let least = g.density.iter().copied().fold(f32::INFINITY, f32::min);
        assert!(least >= 1.0 - GUIDE_SHARE, "{least}");
    }

    #[test]
    fn samples_follow_the_density() {
        let g = skewed();
        let mut counts = [0u32; GUIDE_CELLS];
        let mut rng = Rng::new(5, 6);
        let n = 400_000;
        for _ in 0..n {
            let (w, d) = g.sample(rng.next_vec2());
            assert!(w.cmpge(Vec2::ZERO).all() && w.cmplt(Vec2::ONE).all());
            assert_eq!(d, g.density(w));
            counts[cell(w)] += 1;
        }
        for (k, (&count, &density)) in counts.iter().zip(&g.density).enumerate() {
            let expected = density / GUIDE_CELLS as f32;
            let got = count as f32 / n as f32;
            assert!(
                (got - expected).abs() < 4.0 * (expected / n as f32).sqrt() + 1e-4,
                "cell {k}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn light_from_everywhere_gives_no_guide() {
        // An open sky seen cosine-weighted: the same light in every cell.
        let record = GuideRecord::new(1.0);
        let mut rng = Rng::new(7, 8);
        for _ in 0..4096 {
            record.add(rng.next_vec2(), 3.0 + 0.5 * rng.next_f32());
        }
        assert!(DirectionGuide::from_record(&record).is_none());
    }

    #[test]
    fn an_empty_record_gives_no_guide() {
        let record = GuideRecord::new(1.0);
        record.add(Vec2::splat(0.5), 0.0);
        assert_eq!(record.samples(), 1);
        assert!(DirectionGuide::from_record(&record).is_none());
    }

    #[test]
    fn records_sum_alike_in_any_order() {
        let (a, b) = (GuideRecord::new(0.1), GuideRecord::new(0.1));
        let values: Vec<(Vec2, f32)> = (0..100)
            .map(|i| (Vec2::new(i as f32 / 100.0, 0.3), 0.1 + i as f32 * 0.37))
            .collect();
        values.iter().for_each(|&(u, v)| a.add(u, v));
        values.iter().rev().for_each(|&(u, v)| b.add(u, v));
        assert_eq!(
            DirectionGuide::from_record(&a),
            DirectionGuide::from_record(&b)
        );
    }
}
