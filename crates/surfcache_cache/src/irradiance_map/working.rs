//! The state of a bake in progress: raw estimates, their errors and burial, and what the
//! current round asked for; dropped once the maps converge.

use super::{
    grid::{grid_size, order_of_level},
    guides::GridGuides,
};
use crate::{Prior, burial::Burial, crossings::SampleCrossing};
use glam::Vec3;

/// What only baking needs: raw estimates, their errors, burial flags, refinement state.
/// Arrays are parallel to the stored samples.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Working {
    /// Maximum order per triangle.
    pub(super) max_orders: Vec<u32>,
    /// Whether each grid slot asks to double (or, before its first round, to be baked).
    pub(super) refine: Vec<bool>,
    /// Grid slots whose new samples the current round estimates, ascending.
    pub(super) pending: Vec<u32>,
    /// Number of points the current round asked for.
    pub(super) pending_points: usize,
    /// Raw estimates E, their sample counts and standard errors.
    pub(super) raw: Vec<Vec3>,
    pub(super) samples: Vec<u32>,
    pub(super) std_error: Vec<Vec3>,
    /// Values after burial filling, and their standard errors.
    pub(super) filled: Vec<Vec3>,
    pub(super) filled_error: Vec<Vec3>,
    /// Burial state of every sample ([`Burial::Buried`] or [`Burial::Valid`] when estimated).
    pub(super) burial: Vec<Burial>,
    /// Per sample: interpolated from the two coarse samples of the edge it halves, not
    /// estimated (module docs, Local refinement).
    pub(super) derived: Vec<bool>,
    /// Per grid slot: the last refinement test failed, so every new sample of its next
    /// round is estimated (module docs, Local refinement).
    pub(super) whole: Vec<bool>,
    /// Per sample: whether the refinement test that saw it as a new sample found it
    /// off the coarse interpolation by more than the bound.
    pub(super) failed: Vec<bool>,
    /// Per sample of a crossed grid: how far from it its probe met a crossing surface,
    /// within the reach of the order that made it (infinite: none, or not crossed).
    pub(super) crossing_distance: Vec<f32>,
    /// Per sample: its crossing line in [`IrradianceMaps::lines`], or
    /// [`NO_INDEX`] (module docs, Crossings).
    pub(super) line_of: Vec<u32>,
    /// Per sample of a crossed grid: its probe in `probes`, or [`NO_INDEX`].
    pub(super) probe_of: Vec<u32>,
    /// The probes of crossed grids' samples, as made.
    pub(super) probes: Vec<SampleProbe>,
    /// Per new grid sample of the current round: its probe in `probes`, or [`NO_INDEX`].
    pub(super) round_probes: Vec<u32>,
    /// Grid slots another surface crosses ([`crossed_grids`]): their samples are probed.
    pub(super) crossed: Vec<bool>,
    /// Per new grid sample of the current round, in the order of `sources`: its line.
    pub(super) round_lines: Vec<u32>,
    /// Per new grid sample of the current round, in the order of `sources`: its
    /// crossing distance (as `crossing_distance`).
    pub(super) round_distances: Vec<f32>,
    /// Per line: the estimate at its sample's foot (NaN: none, or buried).
    pub(super) feet: Vec<Vec3>,
    /// This round's foot points: (line, round point).
    pub(super) round_feet: Vec<(u32, u32)>,
    /// Order (log2) of each grid slot's first round; empty: `min(2, n_max)` everywhere.
    pub(super) start_log2: Vec<u8>,
    /// Grid slots whose punctual lights' shadow boundary crosses them
    /// ([`punctual_shadow_edges`]): they refine to their maximum order everywhere.
    pub(super) shadow_edges: Vec<bool>,
    /// Corner links: `links[3·slot + k]` is `3·slot' + k'` when corner k of grid `slot`
    /// takes the estimate of corner k' of grid `slot'`, its representative, or
    /// [`NO_INDEX`]; empty when corners are not shared ([`corner_links`]).
    pub(super) links: Vec<u32>,
    /// Per new grid sample of the current round, in [`for_each_new_sample`] order over
    /// `pending`: the round point whose estimate it takes, or [`NO_INDEX`] for a sample
    /// interpolated from its coarse neighbours.
    pub(super) sources: Vec<u32>,
    /// Per sample: which estimate it holds, numbered over all rounds (copies of a shared
    /// corner hold the same one), or [`NO_INDEX`] before it has one.
    pub(super) estimate_id: Vec<u32>,
    /// Estimates received so far, over all rounds.
    pub(super) estimates_seen: u32,
    /// What the rounds after the one handed out are expected to ask for ([`LaterRounds`]):
    /// made with the first round, remade by every refinement test.
    pub(super) later: Option<LaterRounds>,
    /// Round points per estimated new grid sample in the last round that shared no
    /// corners (feet add points); 1 before there was one.
    pub(super) points_per_sample: f64,
    /// An incremental re-bake ([`SurfaceCache::remap`]): its estimates update filtered
    /// values and are not filtered again (module docs, Filtering).
    pub(super) rebake: bool,
    /// Re-bakes: values of the maps before an edit, grid by grid, for the first round
    /// ([`SamplePoint::prior`]); `prior_offsets[g]` is grid slot g's first, or
    /// [`NO_INDEX`] for a grid without one.
    pub(super) priors: Vec<Prior>,
    pub(super) prior_offsets: Vec<u32>,
    /// Re-bakes: the feet before the edit, by prior index (ascending), with the line each
    /// belonged to (NaN: the foot was buried and its line settled without it): a foot
    /// keeps its value as its prior where the edited scene gives its sample the same line
    /// (module docs, Crossings).
    pub(super) prior_feet: Vec<(u32, SampleCrossing, Vec3)>,
    /// Re-bakes: the probes before the edit of each crossed grid that no changed surface
    /// comes near, grid by grid in [`grid_index`](super::grid_index) order;
    /// `prior_probe_offsets[g]` is grid slot g's first, or [`NO_INDEX`] where its samples
    /// are probed again.
    pub(super) prior_probes: Vec<SampleProbe>,
    pub(super) prior_probe_offsets: Vec<u32>,
    /// Direction guides of refining grids ([`GridGuides`]; off until the first round of
    /// maps that guide).
    pub(super) guides: GridGuides,
}

/// What probing a crossed grid's sample gives ([`crossings::probe`](crate::crossings::probe)):
/// the site it is estimated at, its crossing line, oriented from the site, and the
/// barycentrics of the line's foot.
pub(super) type SampleProbe = (glam::Vec2, Option<SampleCrossing>, Option<glam::Vec2>);

/// A forecast of the grid samples of the rounds after the one handed out (progress
/// reports, [`SurfaceCache::later_samples`]). Every grid of that round will double up to
/// its maximum order: a forced grid (an order-1 grid, a punctual shadow edge's) surely, a
/// tested one in each further round with the share of tested grids the last test
/// doubled, estimating the share of its new samples that the last round estimated
/// (module docs, Local refinement). Before the first test only the forced and the
/// crossed grids are counted, in full (some of them turn out buried all over and stop,
/// so that forecast is no lower bound; docs/results.md, "Progress of irradiance maps").
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct LaterRounds {
    /// New samples of forced grids over all later rounds.
    pub(super) forced: u64,
    /// New samples of tested grids in the k-th later round (`tested[k - 1]`), if each of
    /// them doubled every time.
    pub(super) tested: Vec<u64>,
    /// The share of tested grids the last test doubled (0 before the first test).
    pub(super) rate: f64,
    /// The share of the new samples of locally refined grids that the last round
    /// estimated (the others are interpolated; module docs, Local refinement), taken to
    /// hold again in each later round; `None` (all) before such a round.
    pub(super) estimated_share: Option<f64>,
}

impl LaterRounds {
    /// Counts a grid that the round handed out takes to order `n`, forced or tested,
    /// with its later doublings up to order `max`.
    pub(super) fn add_grid(&mut self, n: u32, max: u32, forced: bool) {
        let (mut m, mut k) = (2 * n, 0);
        while m <= max {
            let new = (grid_size(m) - grid_size(m / 2)) as u64;
            if forced {
                self.forced += new;
            } else {
                if self.tested.len() <= k {
                    self.tested.push(0);
                }
                self.tested[k] += new;
            }
            m *= 2;
            k += 1;
        }
    }

    /// Expected new grid samples, `forced + Σ_k (rate · share)^k · tested[k−1]` with
    /// `share` the estimated share (before the first test, the forced grids' alone).
    pub(super) fn samples(&self) -> f64 {
        let mut survive = 1.0;
        let mut total = self.forced as f64;
        for &t in &self.tested {
            survive *= self.rate * self.estimated_share.unwrap_or(1.0);
            total += survive * t as f64;
        }
        total
    }
}

impl Working {
    /// The order grid slot `g` has (`coarse`, 0 before its first round) and the order
    /// this round gives it: its first order, or double.
    pub(super) fn round_orders(&self, g: usize, levels: &[u8]) -> (u32, u32) {
        match order_of_level(levels[g]) {
            0 => (0, 1 << self.start_log2(g)),
            coarse => (coarse, 2 * coarse),
        }
    }

    /// Whether sample `m` counts in refinement decisions: every sample of a bake; of a
    /// re-bake only those it estimated again (kept priors are the bake before's, which
    /// decided on them).
    pub(super) fn decides(&self, m: usize) -> bool {
        !self.rebake || self.samples[m] > 0
    }

    /// log2 of the order grid slot `g` starts at: a re-bake's prior order, else
    /// `min(2, n_max)`.
    pub(super) fn start_log2(&self, g: usize) -> u8 {
        match self.start_log2.get(g) {
            Some(&l) => l,
            None => (self.max_orders[g / 2] >= 2) as u8,
        }
    }
}
