//! Which grids refine (module docs, Generator, Noise rule and Buried samples): buried
//! samples filled from their grid neighbours, then the noise-corrected test of the new
//! samples against the coarse interpolation.

use super::{
    IrradianceMaps, Working,
    grid::{coarse_neighbours, for_each_new_sample, grid_index, grid_size, order_of_level},
    working::LaterRounds,
};
use crate::{burial::Burial, crossings};
use glam::Vec3;
use surfcache_core::geometry::longest_edge;
use surfcache_trace::TracedScene;

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
    /// order, those a punctual shadow edge forces, those whose interpolation error is
    /// above the bound (whole: every new sample of theirs is estimated), and those with a
    /// cell active for a crossing or a burial boundary (module docs, Local refinement).
    /// Also forecasts the rounds after the next ([`LaterRounds`]).
    ///
    /// A re-bake decides on the samples it estimated again only: the priors it kept are
    /// the bake before's, whose burial and noise decided their grid's order then. A grid
    /// that kept every prior keeps its order (module docs, Filtering).
    pub(super) fn decide_refinement(&self, w: &mut Working, scene: &TracedScene) {
        w.refine.iter_mut().for_each(|r| *r = false);
        w.whole.clear();
        w.whole.resize(w.refine.len(), false);
        let mut later = LaterRounds::default();
        let (mut tested, mut doubled) = (0u64, 0u64);
        for p in 0..w.pending.len() {
            let g = w.pending[p];
            let n = order_of_level(self.levels[g as usize]);
            let t = g as usize / 2;
            if n >= w.max_orders[t] {
                continue;
            }
            let base = self.offsets[g as usize] as usize;
            let (mut valid, mut decided) = (false, false);
            for m in base..base + grid_size(n) {
                if w.decides(m) {
                    decided = true;
                    valid |= w.burial[m] == Burial::Valid;
                }
            }
            if w.rebake && !decided {
                continue;
            }
            // A grid buried all over needs no detail, whatever crosses it. An order-1
            // grid (a re-bake's prior) has no new samples to test: it doubles.
            let shadow = w.shadow_edges.get(g as usize).copied().unwrap_or(false) && valid;
            let forced = n == 1 || shadow;
            let worst = self.mark_failures(w, base, n);
            // The thesis' test refines the whole grid; a crossing or a burial boundary
            // alone, the cells around it (module docs, Local refinement).
            let whole = worst > self.settings.interpolation_error;
            w.whole[g as usize] = whole;
            let refine = forced
                || whole
                || has_active_cell(w, base, n, near_reach(scene, t as u32, n), false);
            w.refine[g as usize] = refine;
            if !forced {
                tested += 1;
                doubled += refine as u64;
            }
            if refine {
                // The next round takes it to 2n.
                later.add_grid(2 * n, w.max_orders[t], forced);
            }
        }
        later.rate = doubled as f64 / tested.max(1) as f64;
        w.later = Some(later);
    }

    /// The refinement test of a grid of order `n` at `base` that just doubled (or was
    /// just made): the largest noise-corrected relative difference e between a new,
    /// valid, estimated sample and the coarse interpolation there (module docs, Noise
    /// rule). Marks the samples whose difference fails the cell test (e with
    /// [`IrradianceMapSettings::cell_sigmas`] above
    /// [`IrradianceMapSettings::cell_error`]).
    fn mark_failures(&self, w: &mut Working, base: usize, n: u32) -> f32 {
        let s = &self.settings;
        // e with k standard errors taken for noise; NaN counts as infinite.
        let error = |difference: f32, sigma: f32, value: f32, k: f32| {
            let excess = (difference - k * sigma).max(0.0);
            match excess / (value.max(0.0) + s.floor) {
                _ if excess == 0.0 => 0.0,
                e if e.is_nan() => f32::INFINITY,
                e => e,
            }
        };
        let mut worst = 0.0f32;
        for_each_new_sample(n / 2, n, |i, j, m| {
            // Neither buried nor interpolated samples, nor a re-bake's kept priors.
            if w.burial[base + m] != Burial::Valid || w.derived[base + m] || !w.decides(base + m) {
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
            let mut failed = false;
            for c in 0..3 {
                let (d, sigma) = ((value[c] - interp[c]).abs(), sigma2[c].sqrt());
                worst = worst.max(error(d, sigma, value[c], s.noise_sigmas));
                failed |= error(d, sigma, value[c], s.cell_sigmas) > s.cell_error;
            }
            w.failed[base + m] = failed;
        });
        worst
    }
}

/// How near (metres) a crossing must pass a corner of a cell of an order-`n` grid on
/// `triangle` for the cell to be active: [`crossings::LINE_REACH`] spacings of that
/// order, as far as the probes of the samples that order made reach.
pub(super) fn near_reach(scene: &TracedScene, triangle: u32, n: u32) -> f32 {
    let [a, b, c] = scene.positions()[triangle as usize];
    crossings::LINE_REACH * longest_edge(a, b, c) / n.max(1) as f32
}

/// Whether the cell of the grid at `base` with corners `corners` (grid indices) is active
/// (module docs, Local refinement): of its corners that decide ([`Working::decides`]:
/// all in a bake), one is valid, and they span buried and valid samples, or a crossing
/// passes one within `near`, or (with `failures`) one failed the cell test.
fn cell_active(w: &Working, base: usize, corners: [usize; 3], near: f32, failures: bool) -> bool {
    let (mut valid, mut other, mut hot) = (false, false, false);
    for k in corners
        .map(|k| base + k)
        .into_iter()
        .filter(|&k| w.decides(k))
    {
        match w.burial[k] == Burial::Valid {
            true => valid = true,
            false => other = true,
        }
        hot |= (failures && w.failed[k]) || w.crossing_distance[k] <= near;
    }
    valid && (other || hot)
}

/// Whether any cell of the order-`n` grid at `base` is active ([`cell_active`]; with
/// `failures` false, for burial or a crossing alone).
fn has_active_cell(w: &Working, base: usize, n: u32, near: f32, failures: bool) -> bool {
    for d in 0..n {
        for q in 0..=d {
            let p = d - q;
            let lower = [grid_index(p, q), grid_index(p + 1, q), grid_index(p, q + 1)];
            if cell_active(w, base, lower, near, failures) {
                return true;
            }
            if d + 2 <= n {
                let upper = [
                    grid_index(p + 1, q),
                    grid_index(p, q + 1),
                    grid_index(p + 1, q + 1),
                ];
                if cell_active(w, base, upper, near, failures) {
                    return true;
                }
            }
        }
    }
    false
}

/// Whether the new sample `(i, j)` of a grid doubling from order `c` (at `base`) to `2c`
/// is estimated: one of the two order-`c` cells beside the edge it halves is active
/// ([`cell_active`]); otherwise it is interpolated from the edge's ends.
pub(super) fn halves_active_edge(
    w: &Working,
    base: usize,
    c: u32,
    i: u32,
    j: u32,
    near: f32,
) -> bool {
    let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
    let (a, b) = (grid_index(ai / 2, aj / 2), grid_index(bi / 2, bj / 2));
    // The third corners of the cells on either side of the edge.
    let (p, q) = (ai.min(bi) / 2, aj.min(bj) / 2);
    let thirds: [Option<(u32, u32)>; 2] = match (i % 2 == 1, j % 2 == 1) {
        // Along i: (p, q)–(p+1, q).
        (true, false) => [Some((p, q + 1)), (q >= 1).then(|| (p + 1, q - 1))],
        // Along j: (p, q)–(p, q+1).
        (false, true) => [Some((p + 1, q)), (p >= 1).then(|| (p - 1, q + 1))],
        // The diagonal (p+1, q)–(p, q+1).
        _ => [Some((p, q)), (p + q + 2 <= c).then_some((p + 1, q + 1))],
    };
    thirds
        .iter()
        .flatten()
        .any(|&(x, y)| cell_active(w, base, [a, b, grid_index(x, y)], near, true))
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
