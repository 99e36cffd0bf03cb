//! What irradiance maps are asked for ([`IrradianceMapSettings`]) and the running totals
//! of the estimates they received.

use super::MAX_ORDER_LIMIT;
use crate::{CacheStats, filter::FilterSettings};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use surfcache_core::geometry::{longest_edge, triangle_area};
use surfcache_trace::{Estimate, TracedScene};

/// Grid spacing, in units of the density's spacing 1/density, from which a sample draws
/// the estimator's full sample cap; closer samples draw a share in proportion to their
/// spacing ([`IrradianceMapSettings::cap_share`]): the cap is what a sample one density
/// spacing from its neighbours may draw. Grids at their maximum order sit between one
/// half and one spacing apart (their samples draw one half to all of the cap), the
/// corners of small triangles closer.
pub const FULL_CAP_SPACING: f32 = 1.0;

/// How far a grid's longest edge may exceed its area's side, `√(2A)` (A the triangle's
/// area), before its samples' caps follow the area instead
/// ([`IrradianceMapSettings::cap_spacing`]): compact triangles, up to a right triangle
/// with legs 1 : 1.6, keep the longest edge; slivers do not.
pub const SLIVER_RATIO: f32 = 1.5;

/// How irradiance maps refine and what they store.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IrradianceMapSettings {
    /// Bound on the interpolation error e of new samples: a grid with a new sample above
    /// it refines (the thesis used 2.5–10 %). Default 0.05.
    pub interpolation_error: f32,
    /// Target samples per metre along a triangle's longest edge: sets each grid's maximum
    /// order, so equal-sized features get equal resolution. Default 64 (1.6 cm): with
    /// final gathering a sample point costs about a tenth of a full path-traced one, and
    /// on the built-in Cornell box contact shadows at the blocks' feet need this
    /// resolution to reach 1 % relative RMS error (32 gave 1.2 %, 16 gave 1.3–1.5 %).
    pub density: f32,
    /// Cap on every grid's order (rounded down to a power of two, in 1..=[`MAX_ORDER_LIMIT`]).
    /// Default 64.
    pub max_order: u32,
    /// Bake the back side of every triangle (true), or only of triangles whose material
    /// is double-sided (the back sides [`crate::SurfaceCache::publish`] needs). Lookups on a side
    /// that was not baked return zero. Default true.
    pub both_sides: bool,
    /// An estimate whose `back_face_share` exceeds this is buried (module docs).
    /// Default 0.5.
    pub buried_threshold: f32,
    /// k: how many combined standard errors of a difference are noise (module docs).
    /// Default 3.
    pub noise_sigmas: f32,
    /// ε (W/m²) of the relative interpolation error; use the estimator's floor
    /// ([`surfcache_trace::EstimatorSettings::floor`]). Default 0.
    pub floor: f32,
    /// Estimate a corner once for all triangles around its vertex that may share it
    /// (module docs, Shared corners). Default true.
    #[serde(default = "default_share_corners")]
    pub share_corners: bool,
    /// Largest angle in degrees between the geometric normals of two triangles that
    /// share a corner (module docs, Shared corners). Default 10.
    #[serde(default = "default_share_angle")]
    pub share_angle: f32,
    /// Sharing samples between neighbouring grid samples once the grids stop refining
    /// (module docs, Filtering; [`crate::filter::filter_points`]). Default: one pass;
    /// `iterations: 0` keeps every estimate on its own.
    #[serde(default)]
    pub filter: FilterSettings,
    /// Bound on the interpolation error e of new samples, with [`Self::cell_sigmas`] for
    /// k, within a grid that doubles for a crossing or a burial boundary alone: a cell
    /// whose new samples all stay below it is interpolated from then on (module docs,
    /// Local refinement). Default 0.01.
    #[serde(default = "default_cell_error")]
    pub cell_error: f32,
    /// k of the cell test ([`Self::cell_error`]). Default 2.
    #[serde(default = "default_cell_sigmas")]
    pub cell_sigmas: f32,
    /// New samples of a refining grid draw their directions through a guide learnt
    /// from its earlier rounds (module docs, Guiding; docs/design.md, Guiding).
    /// Default true.
    #[serde(default = "default_guiding")]
    pub guiding: bool,
}

fn default_guiding() -> bool {
    true
}

fn default_cell_error() -> f32 {
    0.01
}

fn default_cell_sigmas() -> f32 {
    2.0
}

fn default_share_corners() -> bool {
    true
}

fn default_share_angle() -> f32 {
    10.0
}

impl Default for IrradianceMapSettings {
    fn default() -> Self {
        Self {
            interpolation_error: 0.05,
            density: 64.0,
            max_order: 64,
            both_sides: true,
            buried_threshold: 0.5,
            noise_sigmas: 3.0,
            floor: 0.0,
            share_corners: default_share_corners(),
            share_angle: default_share_angle(),
            filter: FilterSettings::default(),
            cell_error: default_cell_error(),
            cell_sigmas: default_cell_sigmas(),
            guiding: default_guiding(),
        }
    }
}

impl IrradianceMapSettings {
    /// The cap on orders actually used: `max_order` rounded down to a power of two and
    /// clamped to 1..=[`MAX_ORDER_LIMIT`].
    pub fn order_cap(&self) -> u32 {
        let m = self.max_order.clamp(1, MAX_ORDER_LIMIT);
        1 << (31 - m.leading_zeros())
    }

    /// n_max = clamp(next_pow2(ceil(longest_edge · density)), 1, cap): the largest order of
    /// a triangle whose longest edge is `longest_edge` metres (1: its corners are at most
    /// one sample spacing apart).
    pub fn max_order_for(&self, longest_edge: f32) -> u32 {
        let target = (longest_edge * self.density).ceil();
        let target = if target.is_finite() && target > 1.0 {
            (target.min(MAX_ORDER_LIMIT as f32) as u32).next_power_of_two()
        } else {
            1
        };
        target.clamp(1, self.order_cap())
    }

    /// The spacing whose share of the cap ([`Self::cap_share`]) the samples of an order-`n`
    /// grid over triangle (`a`, `b`, `c`) draw: `min(L, SLIVER_RATIO · √(2A)) / n`, L the
    /// longest edge and A the area. The grid's order follows L, so that equal features
    /// get equal resolution along it, and its (n + 1)(n + 2)/2 samples share the area A:
    /// each stands for about 2A/n², whose side √(2A)/n is L/n on a compact triangle but
    /// far less on a sliver (a 10 m × 20 cm moulding: 2,145 samples on 1 m² at order 64).
    /// There the cap follows the area a sample stands for, as samples by area intend
    /// (module docs): on Sponza before this, the grids whose longest edge is 3× their
    /// area's side or more held 11 % of the area and 46 % of the samples.
    pub fn cap_spacing(a: Vec3, b: Vec3, c: Vec3, n: u32) -> f32 {
        let side = (2.0 * triangle_area(a, b, c)).sqrt();
        longest_edge(a, b, c).min(SLIVER_RATIO * side) / n.max(1) as f32
    }

    /// The share of the estimator's sample cap a sample of a grid with spacing `spacing`
    /// (metres) may draw: `min(1, spacing · density / FULL_CAP_SPACING)`. A sample closer
    /// to its neighbours than [`FULL_CAP_SPACING`] of the density's spacing stands for less
    /// surface, so it draws fewer samples (module docs, Samples by area).
    pub fn cap_share(&self, spacing: f32) -> f32 {
        let share = spacing * self.density / FULL_CAP_SPACING;
        if share.is_finite() {
            share.min(1.0)
        } else {
            1.0
        }
    }
}

impl IrradianceMapSettings {
    /// The share of `scene`'s triangles no longer than one sample spacing, whose grids
    /// keep order 1 (their three corners): where it is large, the grids sample the mesh
    /// rather than the light.
    pub fn order_one_share(&self, scene: &TracedScene) -> f32 {
        let positions = scene.positions();
        let small = positions
            .iter()
            .filter(|[a, b, c]| self.max_order_for(longest_edge(*a, *b, *c)) == 1)
            .count();
        small as f32 / positions.len().max(1) as f32
    }
}

/// Running totals over all estimates a cache received.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct EstimateTotals {
    pub points: u64,
    pub samples: u64,
    pub max_samples: u32,
    pub rel_error_sum: f64,
}

impl EstimateTotals {
    pub fn add(&mut self, e: &Estimate) {
        self.points += 1;
        self.samples += e.samples as u64;
        self.max_samples = self.max_samples.max(e.samples);
        self.rel_error_sum += e.rel_error as f64;
    }

    pub fn stats(&self) -> CacheStats {
        CacheStats {
            sample_points: self.points,
            samples: self.samples,
            max_samples_per_point: self.max_samples,
            mean_rel_error: if self.points == 0 {
                0.0
            } else {
                self.rel_error_sum / self.points as f64
            },
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_draw_the_cap_in_proportion_to_their_spacing() {
        let s = IrradianceMapSettings {
            density: 8.0,
            ..Default::default()
        };
        // One density spacing and more: the whole cap.
        assert_eq!(s.cap_share(0.125), 1.0);
        assert_eq!(s.cap_share(3.0), 1.0);
        // Grids at their maximum order: one half to all of it.
        for edge in [0.07f32, 0.3, 1.0, 4.9] {
            let n = s.max_order_for(edge);
            let share = s.cap_share(edge / n as f32);
            assert!(
                (0.5..=1.0).contains(&share),
                "edge {edge}: order {n}, share {share}"
            );
        }
        // The corners of a 2-cm triangle: its spacing over the density's.
        assert!((s.cap_share(0.02) - 0.16).abs() < 1e-6);
    }

    #[test]
    fn slivers_draw_by_their_area() {
        let n = 64;
        // A compact triangle (legs 1 : 1.5, longest edge 1.47 √(2A)) keeps its longest
        // edge; one of legs 1 : 2 (1.58 √(2A)) is a sliver.
        let (a, b, c) = (
            Vec3::ZERO,
            Vec3::new(1.5, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        );
        let spacing = IrradianceMapSettings::cap_spacing(a, b, c, n);
        assert!((spacing - 3.25f32.sqrt() / 64.0).abs() < 1e-6, "{spacing}");
        let b = Vec3::new(2.0, 0.0, 0.0);
        let spacing = IrradianceMapSettings::cap_spacing(a, b, c, n);
        assert!(
            (spacing - SLIVER_RATIO * 2f32.sqrt() / 64.0).abs() < 1e-6,
            "{spacing}"
        );
        // A 10 m × 20 cm sliver (A = 1 m²): 1.5 √2 m over the order, not 10 m.
        let c = Vec3::new(0.0, 0.2, 0.0);
        let b = Vec3::new(10.0, 0.0, 0.0);
        let spacing = IrradianceMapSettings::cap_spacing(a, b, c, n);
        assert!(
            (spacing - SLIVER_RATIO * 2f32.sqrt() / 64.0).abs() < 1e-6,
            "{spacing}"
        );
        // A degenerate triangle draws the least share, not NaN.
        let spacing = IrradianceMapSettings::cap_spacing(a, b, b, n);
        assert_eq!(spacing, 0.0);
    }
}
