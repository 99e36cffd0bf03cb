//! Sharing samples between neighbouring grid samples once the grids stop refining (the
//! module docs of [`super`], Filtering).

use super::{
    IrradianceMaps, Working,
    grid::{coarse_neighbours, for_each_new_sample, grid_index, grid_size, order_of_level},
};
use crate::{
    burial::Burial,
    filter::{PointFilterInput, filter_points},
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use surfcache_core::{geometry::longest_edge, index::NO_INDEX};
use surfcache_trace::TracedScene;

/// Where one estimate lies: its first sample's grid (triangle, side) and barycentrics,
/// and the spacing of that grid.
struct Node {
    triangle: u32,
    uv: Vec2,
    front: bool,
    spacing: f32,
    /// On a grid another surface crosses.
    guarded: bool,
}

impl IrradianceMaps {
    /// Filters the valid estimates with their neighbours in space ([`filter_points`]),
    /// each estimate once however many grids share it, its spacing the distance to the
    /// nearest other estimated sample of its grid along a grid line ([`local_step`]; at
    /// most one sample spacing of the density); replaces `raw` and `std_error` of their
    /// samples (interpolated samples follow in [`Self::rederive`]). Samples with a crossing line keep their own estimates and lend
    /// them to nobody; the other samples of crossed grids share only with neighbours
    /// that nothing separates from them (an any-hit ray between the two ray origins).
    /// Estimates without samples, and estimates whose samples were all zero (lent as exact
    /// zeros), are taps, not filtered. An incremental re-bake filters nothing (module
    /// docs, Filtering). Returns whether it filtered.
    pub(super) fn share_samples(&self, scene: &TracedScene, w: &mut Working) -> bool {
        if self.settings.filter.iterations == 0 || w.rebake {
            return false;
        }
        let cap = 1.0 / self.settings.density.max(f32::MIN_POSITIVE);
        let mut node_of = vec![NO_INDEX; w.estimates_seen as usize];
        let mut members: Vec<(u32, u32)> = Vec::new();
        let mut nodes = Vec::new();
        let (mut value, mut variance, mut filtered) = (Vec::new(), Vec::new(), Vec::new());
        for g in 0..self.levels.len() {
            let n = order_of_level(self.levels[g]);
            if n == 0 {
                continue;
            }
            let (t, front) = ((g / 2) as u32, g % 2 == 0);
            let [a, b, c] = scene.positions()[t as usize];
            let cell = longest_edge(a, b, c) / n as f32;
            let base = self.offsets[g] as usize;
            for d in 0..=n {
                for j in 0..=d {
                    let k = base + grid_index(d - j, j);
                    let id = w.estimate_id[k];
                    if w.burial[k] != Burial::Valid || id == NO_INDEX || w.line_of[k] != NO_INDEX {
                        continue;
                    }
                    if node_of[id as usize] == NO_INDEX {
                        node_of[id as usize] = nodes.len() as u32;
                        let step = local_step(w, base, n, d - j, j);
                        nodes.push(Node {
                            triangle: t,
                            uv: Vec2::new((d - j) as f32, j as f32) / n as f32,
                            front,
                            spacing: (cell * step as f32).clamp(1e-4 * cap, cap),
                            guarded: w.crossed[g],
                        });
                        value.push(w.raw[k]);
                        // An estimate whose every sample was zero carries the standard
                        // error of the light it may have missed (`ZERO_RUN_EVENTS`),
                        // not noise: it is kept as it is and lends the filter an exact
                        // zero, so that it takes no light from taps beyond a wall (the
                        // inside of a sealed box under its lit top) and darkens its
                        // neighbours no more than a measured zero would.
                        let zero_run = w.raw[k] == Vec3::ZERO;
                        let se = if zero_run { Vec3::ZERO } else { w.std_error[k] };
                        variance.push(se * se);
                        filtered.push(w.samples[k] > 0 && !zero_run);
                    }
                    members.push((k as u32, node_of[id as usize]));
                }
            }
        }
        let ((position, normal), origin): ((Vec<Vec3>, Vec<Vec3>), Vec<Vec3>) = nodes
            .par_iter()
            .map(|n| {
                let p = scene.surface_point(n.triangle, n.uv, n.front);
                ((p.position, p.shading_normal), scene.spawn_origin(&p))
            })
            .unzip();
        let guarded: Vec<bool> = nodes.iter().map(|n| n.guarded).collect();
        let spacing: Vec<f32> = nodes.iter().map(|n| n.spacing).collect();
        let valid = vec![true; nodes.len()];
        let (value, variance) = filter_points(
            &PointFilterInput {
                value: &value,
                variance: &variance,
                position: &position,
                normal: &normal,
                spacing: &spacing,
                valid: &valid,
                filtered: &filtered,
                guarded: &guarded,
                floor: self.settings.floor,
            },
            &self.settings.filter,
            &|p, q| {
                let d = origin[q] - origin[p];
                let length = d.length();
                length == 0.0 || !scene.occluded(origin[p], d / length, length)
            },
        );
        for (k, node) in members {
            let (k, node) = (k as usize, node as usize);
            if filtered[node] {
                w.raw[k] = value[node];
                w.std_error[k] = variance[node].max(Vec3::ZERO).map(f32::sqrt);
            }
        }
        true
    }

    /// Interpolates every interpolated sample anew from the ends of the coarse edge it
    /// halves, coarser orders first (filtering changed the estimates at the ends).
    pub(super) fn rederive(&self, w: &mut Working) {
        for g in 0..self.levels.len() {
            let n = order_of_level(self.levels[g]);
            let base = self.offsets[g] as usize;
            if n < 4 || !w.derived[base..base + grid_size(n)].contains(&true) {
                continue;
            }
            let mut o = 2;
            while o <= n {
                let step = n / o;
                for_each_new_sample(o / 2, o, |i, j, _| {
                    let k = base + grid_index(i * step, j * step);
                    if !w.derived[k] {
                        return;
                    }
                    let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
                    let a = base + grid_index(ai * step, aj * step);
                    let b = base + grid_index(bi * step, bj * step);
                    w.interpolate(k, a, b);
                });
                o *= 2;
            }
        }
    }
}

/// The distance, in spacings of the order-`n` grid at `base`, from sample `(i, j)` to
/// the nearest estimated (not interpolated) sample along one of its six grid lines, a
/// power of two; `n` when there is none. Where local refinement stopped early, estimates
/// lie that many spacings apart and share with neighbours that far.
fn local_step(w: &Working, base: usize, n: u32, i: u32, j: u32) -> u32 {
    let (i, j, n) = (i as i64, j as i64, n as i64);
    let mut h = 1;
    while h < n {
        for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1)] {
            let (a, b) = (i + di * h, j + dj * h);
            if a >= 0 && b >= 0 && a + b <= n && !w.derived[base + grid_index(a as u32, b as u32)] {
                return h as u32;
            }
        }
        h *= 2;
    }
    n as u32
}
