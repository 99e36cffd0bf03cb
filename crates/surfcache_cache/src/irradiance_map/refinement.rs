//! Which grids refine (module docs, Generator, Noise rule and Buried samples): buried
//! samples filled from their grid neighbours, then the noise-corrected test of the new
//! samples against the coarse interpolation.

use super::{
    IrradianceMaps, Working,
    grid::{coarse_neighbours, for_each_new_sample, grid_index, grid_size, order_of_level},
    working::LaterRounds,
};
use crate::burial::Burial;
use glam::Vec3;

impl IrradianceMaps {
    /// Fills the buried samples of every grid (cheap, and independent of history) into
    /// `filled` and `filled_error` (`total` samples).
    pub(super) fn fill_buried(&self, w: &mut Working, total: usize) {
        let slots = self.levels.len();
        w.filled = vec![Vec3::ZERO; total];
        w.filled_error = vec![Vec3::ZERO; total];
        for g in 0..slots {
            let n = order_of_level(self.levels[g]);
            if n > 0 {
                fill_grid(w, self.offsets[g] as usize, n);
            }
        }
    }

    /// Decides which of the grids that just doubled double again: below their maximum
    /// order, those with both buried and valid samples, those a shadow edge or a
    /// crossing forces, and those whose interpolation error is above the bound. Also
    /// forecasts the rounds after the next ([`LaterRounds`]).
    ///
    /// A re-bake decides on the samples it estimated again only: the priors it kept are
    /// the bake before's, whose burial and noise decided their grid's order then (their
    /// error is taken at the bound). A grid that kept every
    /// prior keeps its order (module docs, Filtering).
    pub(super) fn decide_refinement(&self, w: &mut Working) {
        w.refine.iter_mut().for_each(|r| *r = false);
        let bound = self.settings.interpolation_error;
        let mut later = LaterRounds::default();
        let (mut tested, mut doubled) = (0u64, 0u64);
        for &g in &w.pending {
            let n = order_of_level(self.levels[g as usize]);
            if n < w.max_orders[g as usize / 2] {
                let base = self.offsets[g as usize] as usize;
                let (mut valid, mut other) = (false, false);
                for m in base..base + grid_size(n) {
                    if w.decides(m) {
                        if w.burial[m] == Burial::Valid {
                            valid = true;
                        } else {
                            other = true;
                        }
                    }
                }
                if w.rebake && !(valid || other) {
                    continue;
                }
                let mixed = valid && other;
                // A grid buried all over needs no detail, whatever crosses it.
                let shadow = w.shadow_edges.get(g as usize).copied().unwrap_or(false) && valid;
                // An order-1 grid (a re-bake's prior) has no new samples to test: it
                // doubles.
                let forced = n == 1 || mixed || shadow;
                let refine = forced || self.interpolation_error(w, base, n) > bound;
                w.refine[g as usize] = refine;
                if !forced {
                    tested += 1;
                    doubled += refine as u64;
                }
                if refine {
                    // The next round takes it to 2n.
                    later.add_grid(2 * n, w.max_orders[g as usize / 2], forced);
                }
            }
        }
        later.rate = doubled as f64 / tested.max(1) as f64;
        w.later = Some(later);
    }

    /// The refinement test of a grid of order `n` at `base` that just doubled (or was
    /// just made): the largest noise-corrected relative difference e between a new,
    /// non-buried sample and the coarse interpolation there (module docs).
    fn interpolation_error(&self, w: &Working, base: usize, n: u32) -> f32 {
        let k = self.settings.noise_sigmas;
        let eps = self.settings.floor;
        let mut worst = 0.0f32;
        for_each_new_sample(n / 2, n, |i, j, m| {
            // Neither buried samples nor a re-bake's kept priors.
            if w.burial[base + m] != Burial::Valid || !w.decides(base + m) {
                return;
            }
            let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
            let (a, b) = (base + grid_index(ai, aj), base + grid_index(bi, bj));
            let interp = 0.5 * (w.filled[a] + w.filled[b]);
            let sigma2 = w.std_error[base + m] * w.std_error[base + m]
                + 0.25
                    * (w.filled_error[a] * w.filled_error[a]
                        + w.filled_error[b] * w.filled_error[b]);
            let value = w.raw[base + m];
            for c in 0..3 {
                let excess = ((value[c] - interp[c]).abs() - k * sigma2[c].sqrt()).max(0.0);
                if excess > 0.0 {
                    let e = excess / (value[c].max(0.0) + eps);
                    worst = worst.max(if e.is_nan() { f32::INFINITY } else { e });
                }
            }
        });
        worst
    }
}

/// Fills the buried samples of the grid at `base` of order `n` from their valid
/// neighbours, ring by ring (module docs); writes `filled` and `filled_error`.
fn fill_grid(w: &mut Working, base: usize, n: u32) {
    let size = grid_size(n);
    let range = base..base + size;
    w.filled[range.clone()].copy_from_slice(&w.raw[range.clone()]);
    w.filled_error[range.clone()].copy_from_slice(&w.std_error[range.clone()]);
    let burial = &mut w.burial[range];
    if burial.iter().all(|&b| b == Burial::Valid) || burial.iter().all(|&b| b != Burial::Valid) {
        return;
    }
    burial.iter_mut().for_each(|b| {
        if *b != Burial::Valid {
            *b = Burial::Buried;
        }
    });
    loop {
        let mut changed = false;
        for d in 0..=n {
            for j in 0..=d {
                let i = d - j;
                let m = grid_index(i, j);
                if burial[m] != Burial::Buried {
                    continue;
                }
                let (mut sum, mut err, mut count) = (Vec3::ZERO, Vec3::ZERO, 0u32);
                let (ii, jj) = (i as i64, j as i64);
                for (di, dj) in [(-1, 0), (1, 0), (0, -1), (0, 1), (1, -1), (-1, 1)] {
                    let (a, b) = (ii + di, jj + dj);
                    if a < 0 || b < 0 || a + b > n as i64 {
                        continue;
                    }
                    let k = grid_index(a as u32, b as u32);
                    if burial[k] == Burial::Valid || burial[k] == Burial::Filled {
                        sum += w.filled[base + k];
                        err += w.filled_error[base + k];
                        count += 1;
                    }
                }
                if count > 0 {
                    w.filled[base + m] = sum / count as f32;
                    w.filled_error[base + m] = err / count as f32;
                    burial[m] = Burial::FilledNow;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
        burial.iter_mut().for_each(|b| {
            if *b == Burial::FilledNow {
                *b = Burial::Filled;
            }
        });
    }
}
