//! Rounds: the new samples every refining grid asks for (probed for crossings, corners
//! shared), and how a round's estimates move into the grids' new layout.

use super::{
    IrradianceMapSettings, IrradianceMaps, Working,
    grid::{
        coarse_neighbours, corner_of, for_each_new_sample, grid_index, grid_size, order_of_level,
        sample_key,
    },
    guides::GridGuides,
    refinement::{halves_active_edge, near_reach},
    working::{LaterRounds, SampleProbe},
};
use crate::{
    Prior, SamplePoint, SampleSite,
    burial::Burial,
    crossings::{self, SampleCrossing},
    stored_rgb::StoreScale,
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use surfcache_core::{index::NO_INDEX, sampling::splitmix64};
use surfcache_trace::{Estimate, TracedScene};

/// Probes the new samples of this round's crossed grids ([`crossings::probe`]), in the
/// order [`SurfaceCache::next_round`] visits them: as far as one spacing of the grid's
/// maximum order, where lookups use the lines, each sample's site (a sample on a
/// crossing surface moves just beyond it, as lightmap texels do) and its crossing line,
/// oriented from the site, in barycentric coordinates; and as far as the order's
/// [`near_reach`], how far from it a crossing passes (local refinement; infinite for a
/// re-bake's carried probe).
fn probe_new_samples(scene: &TracedScene, w: &Working, levels: &[u8]) -> Vec<(SampleProbe, f32)> {
    // Per sample: its grid slot, its grid point, and the probe a re-bake carries for it.
    let mut sites = Vec::new();
    for &g in w.pending.iter().filter(|&&g| w.crossed[g as usize]) {
        let (coarse, n) = w.round_orders(g as usize, levels);
        let inv = 1.0 / n as f32;
        let carried = match w.prior_probe_offsets.get(g as usize) {
            Some(&o) if coarse == 0 && o != NO_INDEX => o,
            _ => NO_INDEX,
        };
        for_each_new_sample(coarse, n, |i, j, m| {
            let prior = match carried {
                NO_INDEX => NO_INDEX,
                o => o + m as u32,
            };
            sites.push((g, Vec2::new(i as f32 * inv, j as f32 * inv), n, prior));
        });
    }
    sites
        .par_iter()
        .map(|&(g, uv, n, prior)| {
            if prior != NO_INDEX {
                return (w.prior_probes[prior as usize], f32::INFINITY);
            }
            let (t, front) = (g / 2, g % 2 == 0);
            // Lines reach a spacing of the maximum order; nearness one of this order's.
            let reach = near_reach(scene, t, w.max_orders[t as usize]);
            let far = crossings::probe(scene, t, uv, front, near_reach(scene, t, n).max(reach));
            let probe = far.within(reach);
            let site = probe.site(uv);
            let kept = probe.crossing.and_then(|crossing| {
                SampleCrossing::new(scene, t, front, &crossing, crossings::BARYCENTRIC, site)
            });
            let made = (site, kept.map(|(c, _)| c), kept.and_then(|(_, foot)| foot));
            (made, far.crossing_distance)
        })
        .collect()
}

impl IrradianceMaps {
    /// Round points for the new samples of every grid that asks to double (or to be
    /// made), in ascending grid slot: a crossed grid's samples at their probed sites with
    /// the feet of their lines, and a shared corner once, at its representative.
    pub(super) fn ask_new_samples(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        let Some(w) = self.working.as_mut() else {
            return;
        };
        w.pending.clear();
        w.pending
            .extend((0..w.refine.len() as u32).filter(|&g| w.refine[g as usize]));
        if w.pending.is_empty() {
            self.working = None;
            return;
        }
        let start = points.len();
        let w = &mut **w;
        if w.later.is_none() {
            // Before the first test only the forced grids' later rounds are counted.
            let mut later = LaterRounds::default();
            // Crossed grids refine near their crossings, which the first test does not
            // know yet: counted as if forced.
            for &g in &w.pending {
                let (_, n) = w.round_orders(g as usize, &self.levels);
                let forced = w.shadow_edges.get(g as usize).copied().unwrap_or(false)
                    || w.crossed[g as usize];
                later.add_grid(n, w.max_orders[g as usize / 2], forced);
            }
            w.later = Some(later);
        }
        w.sources.clear();
        w.round_lines.clear();
        w.round_distances.clear();
        w.round_probes.clear();
        w.round_feet.clear();
        // New samples of grids refined locally, and how many of them are estimated.
        let (mut local_new, mut local_estimated) = (0u64, 0u64);
        let mut probed = probe_new_samples(scene, w, &self.levels).into_iter();
        // Round point of each corner asked for in this round (only rounds that make
        // grids have corners to share).
        let mut corner_points = Vec::new();
        let pending = std::mem::take(&mut w.pending);
        if self.settings.guiding && !w.guides.is_on() {
            w.guides = GridGuides::new(w.refine.len(), self.settings.floor);
        }
        w.guides.start_round();
        for &g in &pending {
            let (t, front) = (g / 2, g % 2 == 0);
            let (coarse, n) = w.round_orders(g as usize, &self.levels);
            w.guides.prepare_grid(g, n, w.max_orders[t as usize]);
            if coarse == 0 && !w.links.is_empty() && corner_points.is_empty() {
                corner_points = vec![NO_INDEX; w.links.len()];
            }
            let key = scene.triangle_key(t);
            let inv = 1.0 / n as f32;
            let prior_base = match w.prior_offsets.get(g as usize) {
                Some(&o) if coarse == 0 && o != NO_INDEX => Some(o as usize),
                _ => None,
            };
            let crossed = w.crossed[g as usize];
            // Local refinement (module docs): past the first doubling, a grid that
            // doubles for a crossing or a burial boundary alone estimates only the new
            // samples beside active cells of the coarse grid.
            let local = coarse >= 2
                && !w.shadow_edges.get(g as usize).copied().unwrap_or(false)
                && !w.whole.get(g as usize).copied().unwrap_or(false);
            let coarse_base = self.offsets[g as usize] as usize;
            let near = near_reach(scene, t, coarse);
            // Samples by area (module docs): the share of the sample cap this order's
            // samples may draw.
            let cap_share = {
                let [a, b, c] = scene.positions()[t as usize];
                self.settings
                    .cap_share(IrradianceMapSettings::cap_spacing(a, b, c, n))
            };
            for_each_new_sample(coarse, n, |i, j, m| {
                let mut uv = Vec2::new(i as f32 * inv, j as f32 * inv);
                let mut line = NO_INDEX;
                let mut probe = NO_INDEX;
                let mut distance = f32::INFINITY;
                let sample_key = sample_key(key, front, i, j, n);
                let mut estimate = !local || halves_active_edge(w, coarse_base, coarse, i, j, near);
                if crossed {
                    let (made, far) = probed.next().expect("one probe per new sample");
                    probe = w.probes.len() as u32;
                    w.probes.push(made);
                    distance = far;
                    let (site, crossing, foot) = made;
                    // A sample with a crossing line (and foot), or moved off a crossing
                    // surface, is always estimated.
                    estimate |= crossing.is_some() || site != uv;
                    uv = site;
                    if let Some(l) = crossing {
                        line = self.lines.len() as u32;
                        self.lines.push(l);
                        w.feet.push(Vec3::NAN);
                    }
                    if let Some(foot) = foot {
                        // A re-bake's foot on the same line as before starts from its
                        // value; one that was buried (its line settled without a foot,
                        // `crossings::settle_feet`) stays buried unless the stage
                        // estimates it.
                        let prior = prior_base.and_then(|b| {
                            let k = (b + m) as u32;
                            let i = w.prior_feet.binary_search_by_key(&k, |f| f.0).ok()?;
                            let (_, old_line, value) = w.prior_feet[i];
                            crossing?.foot_prior(&old_line, value)
                        });
                        w.round_feet.push((line, (points.len() - start) as u32));
                        w.guides.push_point(None);
                        points.push(SamplePoint {
                            site: SampleSite::Surface {
                                triangle: t,
                                uv: foot,
                                front,
                            },
                            key: splitmix64(sample_key ^ crossings::FOOT_KEY),
                            prior,
                            budget: None,
                            cap_share: 1.0,
                        });
                    }
                }
                w.round_lines.push(line);
                w.round_probes.push(probe);
                w.round_distances.push(distance);
                if local {
                    local_new += 1;
                    local_estimated += estimate as u64;
                }
                if !estimate {
                    w.sources.push(NO_INDEX);
                    return;
                }
                let corner = match (coarse, corner_of(i, j, n)) {
                    (0, Some(k)) if !corner_points.is_empty() => Some(3 * g as usize + k),
                    _ => None,
                };
                if let Some(c) = corner {
                    let link = w.links[c];
                    if link != NO_INDEX && corner_points[link as usize] != NO_INDEX {
                        w.sources.push(corner_points[link as usize]);
                        return;
                    }
                    corner_points[c] = (points.len() - start) as u32;
                }
                w.sources.push((points.len() - start) as u32);
                w.guides.push_point(Some((g, i, j, n)));
                points.push(SamplePoint {
                    site: SampleSite::Surface {
                        triangle: t,
                        uv,
                        front,
                    },
                    key: sample_key,
                    prior: prior_base.map(|b| w.priors[b + m]),
                    budget: None,
                    cap_share,
                });
            });
        }
        w.pending = pending;
        w.pending_points = points.len() - start;
        if local_new > 0
            && let Some(later) = w.later.as_mut()
        {
            later.estimated_share = Some(local_estimated as f64 / local_new as f64);
        }
        let estimated = w.sources.iter().filter(|&&s| s != NO_INDEX).count();
        if corner_points.is_empty() && estimated > 0 {
            w.points_per_sample = w.pending_points as f64 / estimated as f64;
        }
    }

    /// Packs the filled samples (half floats with a scale for the largest value, feet
    /// included) and the crossed grids' lines.
    pub(super) fn pack(&mut self, w: &Working) {
        let slots = self.levels.len();
        // Pack: half floats with a scale for the largest value.
        let max = w
            .filled
            .iter()
            .chain(w.feet.iter().filter(|f| !f.is_nan()))
            .fold(0.0f32, |m, v| m.max(v.max_element()));
        self.scale = StoreScale::for_max(max);
        self.packed.clear();
        self.packed
            .extend(w.filled.iter().map(|&v| self.scale.pack(v)));
        self.sample_counts.clone_from(&w.samples);
        self.buried_samples.clear();
        self.buried_samples
            .extend(w.burial.iter().map(|&b| b != Burial::Valid));
        let scale = self.scale;
        self.feet = crossings::settle_feet(&mut self.lines, &w.feet, |f| scale.pack(f));
        self.crossed_grids.clear();
        self.sample_lines.clear();
        self.sample_probes.clear();
        for g in (0..slots).filter(|&g| w.crossed[g] && self.levels[g] > 0) {
            let (base, n) = (self.offsets[g] as usize, order_of_level(self.levels[g]));
            self.crossed_grids
                .push([g as u32, self.sample_lines.len() as u32]);
            self.sample_lines
                .extend_from_slice(&w.line_of[base..base + grid_size(n)]);
            self.sample_probes.extend(
                w.probe_of[base..base + grid_size(n)]
                    .iter()
                    .map(|&p| w.probes[p as usize]),
            );
        }
    }
}

/// The grids' layout after a round: pending grids double (fresh ones start at their
/// first order); new levels, offsets and the total number of samples.
pub(super) fn grown_layout(levels: &[u8], w: &Working) -> (Vec<u8>, Vec<u32>, usize) {
    let slots = levels.len();
    let mut new_levels = levels.to_vec();
    for &g in &w.pending {
        let first = w.start_log2(g as usize) + 1;
        let l = &mut new_levels[g as usize];
        *l = if *l == 0 { first } else { *l + 1 };
    }
    let mut offsets = vec![0u32; slots];
    let mut total = 0usize;
    for g in 0..slots {
        offsets[g] = total as u32;
        if new_levels[g] > 0 {
            total += grid_size(order_of_level(new_levels[g]));
        }
    }
    (new_levels, offsets, total)
}

impl Working {
    /// Moves the samples of grids of `levels` at `offsets` to their places in the
    /// layout `new_levels`, `new_offsets` of `total` samples (a doubled grid's sample
    /// (i, j) becomes (2i, 2j)); the new samples are left empty.
    pub(super) fn regrid(
        &mut self,
        levels: &[u8],
        offsets: &[u32],
        new_levels: &[u8],
        new_offsets: &[u32],
        total: usize,
    ) {
        let slots = levels.len();
        let mut raw = vec![Vec3::ZERO; total];
        let mut samples = vec![0u32; total];
        let mut std_error = vec![Vec3::ZERO; total];
        let mut burial = vec![Burial::Valid; total];
        let mut line_of = vec![NO_INDEX; total];
        let mut probe_of = vec![NO_INDEX; total];
        let mut estimate_id = vec![NO_INDEX; total];
        let mut derived = vec![false; total];
        let mut crossing_distance = vec![f32::INFINITY; total];
        for g in 0..slots {
            let (old, new) = (order_of_level(levels[g]), order_of_level(new_levels[g]));
            if old == 0 {
                continue;
            }
            let (from, to) = (offsets[g] as usize, new_offsets[g] as usize);
            if old == new {
                let s = grid_size(old);
                raw[to..to + s].copy_from_slice(&self.raw[from..from + s]);
                samples[to..to + s].copy_from_slice(&self.samples[from..from + s]);
                std_error[to..to + s].copy_from_slice(&self.std_error[from..from + s]);
                burial[to..to + s].copy_from_slice(&self.burial[from..from + s]);
                line_of[to..to + s].copy_from_slice(&self.line_of[from..from + s]);
                probe_of[to..to + s].copy_from_slice(&self.probe_of[from..from + s]);
                estimate_id[to..to + s].copy_from_slice(&self.estimate_id[from..from + s]);
                derived[to..to + s].copy_from_slice(&self.derived[from..from + s]);
                crossing_distance[to..to + s]
                    .copy_from_slice(&self.crossing_distance[from..from + s]);
            } else {
                for d in 0..=old {
                    for j in 0..=d {
                        let i = d - j;
                        let (a, b) = (from + grid_index(i, j), to + grid_index(2 * i, 2 * j));
                        raw[b] = self.raw[a];
                        samples[b] = self.samples[a];
                        std_error[b] = self.std_error[a];
                        line_of[b] = self.line_of[a];
                        probe_of[b] = self.probe_of[a];
                        estimate_id[b] = self.estimate_id[a];
                        derived[b] = self.derived[a];
                        crossing_distance[b] = self.crossing_distance[a];
                        burial[b] = if self.burial[a] == Burial::Valid {
                            Burial::Valid
                        } else {
                            Burial::Buried
                        };
                    }
                }
            }
        }
        self.raw = raw;
        self.samples = samples;
        self.std_error = std_error;
        self.burial = burial;
        self.line_of = line_of;
        self.probe_of = probe_of;
        self.estimate_id = estimate_id;
        self.derived = derived;
        self.crossing_distance = crossing_distance;
        // Failures speak for the test that saw them only.
        self.failed = vec![false; total];
    }

    /// Stores the round's estimates as the new samples of the pending grids (now of
    /// `new_levels` at `offsets`, before the round of `levels`), in the order
    /// [`IrradianceMaps::ask_new_samples`] asked for them; a sample whose back-face
    /// share is above `threshold` is buried.
    pub(super) fn store_estimates(
        &mut self,
        levels: &[u8],
        new_levels: &[u8],
        offsets: &[u32],
        points: &[SamplePoint],
        estimates: &[Estimate],
        threshold: f32,
    ) {
        let mut next = 0usize;
        for p in 0..self.pending.len() {
            let g = self.pending[p];
            let n = order_of_level(new_levels[g as usize]);
            let coarse = order_of_level(levels[g as usize]);
            let base = offsets[g as usize] as usize;
            for_each_new_sample(coarse, n, |i, j, m| {
                let source = self.sources[next];
                self.line_of[base + m] = self.round_lines[next];
                self.probe_of[base + m] = self.round_probes[next];
                self.crossing_distance[base + m] = self.round_distances[next];
                next += 1;
                if source == NO_INDEX {
                    // Interpolated from the ends of the coarse edge it halves (their
                    // places in the new layout hold their values already).
                    let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
                    let (a, b) = (base + grid_index(ai, aj), base + grid_index(bi, bj));
                    self.derived[base + m] = true;
                    self.estimate_id[base + m] = NO_INDEX;
                    self.samples[base + m] = 0;
                    self.interpolate(base + m, a, b);
                    let both_valid =
                        self.burial[a] == Burial::Valid && self.burial[b] == Burial::Valid;
                    self.burial[base + m] = match both_valid {
                        true => Burial::Valid,
                        false => Burial::Buried,
                    };
                    return;
                }
                let point = source as usize;
                let e = &estimates[point];
                // A re-bake's buried sample that the edit did not reach stays buried.
                let kept_buried = Prior::kept_buried(points[point].prior, e);
                self.estimate_id[base + m] = self.estimates_seen + source;
                self.raw[base + m] = e.value;
                self.samples[base + m] = e.samples;
                self.std_error[base + m] = e.std_error;
                self.burial[base + m] = if e.back_face_share > threshold || kept_buried {
                    Burial::Buried
                } else {
                    Burial::Valid
                };
            });
        }
        self.estimates_seen += estimates.len() as u32;
    }

    /// Sets sample `k`'s value and standard error to the mean of samples `a` and `b`, the
    /// ends of the coarse edge it halves (an interpolated sample; module docs, Local
    /// refinement).
    pub(super) fn interpolate(&mut self, k: usize, a: usize, b: usize) {
        self.raw[k] = 0.5 * (self.raw[a] + self.raw[b]);
        self.std_error[k] = 0.5
            * (self.std_error[a] * self.std_error[a] + self.std_error[b] * self.std_error[b])
                .map(f32::sqrt);
    }

    /// Clears what only the round that just finished needs; priors serve the first
    /// round only.
    pub(super) fn end_round(&mut self) {
        self.pending.clear();
        self.pending_points = 0;
        self.sources.clear();
        self.round_lines.clear();
        self.round_distances.clear();
        self.round_probes.clear();
        self.round_feet.clear();
        // Priors serve the first round only.
        self.priors = Vec::new();
        self.prior_offsets = Vec::new();
        self.prior_feet = Vec::new();
        self.prior_probes = Vec::new();
        self.prior_probe_offsets = Vec::new();
    }
}
