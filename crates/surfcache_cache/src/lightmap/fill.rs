//! Filling texels without an estimate of their own (module docs): buried texels from
//! their valid neighbours, and the gutters around charts by dilation.

use super::Lightmaps;
use crate::burial::Burial;
use glam::Vec3;
use rayon::prelude::*;
use surfcache_core::index::NO_INDEX;

impl Lightmaps {
    /// Refills buried texels ([`fill_buried`]) and dilates into the gutters ([`dilate`]),
    /// texture by texture (in parallel); returns how many texels dilation filled.
    pub(super) fn fill_textures(&self, values: &mut [Vec3], state: &mut [Burial]) -> u64 {
        // Chart of each texel of a layer (for the same-chart preference of the fill).
        let texel_chart: Vec<u32> = self
            .owner
            .iter()
            .map(|&t| {
                if t == NO_INDEX {
                    NO_INDEX
                } else {
                    self.chart[t as usize]
                }
            })
            .collect();
        // The textures tile the values: layer by layer, instance by instance.
        let mut textures = Vec::with_capacity(self.layers * self.maps.len());
        let (mut values, mut state) = (values, state);
        for _ in 0..self.layers {
            for m in &self.maps {
                let (v, rest_v) = std::mem::take(&mut values).split_at_mut(m.texels());
                let (s, rest_s) = std::mem::take(&mut state).split_at_mut(m.texels());
                (values, state) = (rest_v, rest_s);
                textures.push((m, v, s));
            }
        }
        textures
            .into_par_iter()
            .map(|(m, values, state)| {
                let (w, h) = (m.width as usize, m.height as usize);
                let chart = &texel_chart[m.offset..m.offset + m.texels()];
                fill_buried(values, state, chart, w, h);
                dilate(values, state, w, h, self.settings.gutter)
            })
            .sum()
    }
}

/// The up-to-8 neighbours of texel `k` of a `w × h` image.
#[inline]
fn neighbours(k: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((k % w) as isize, (k / w) as isize);
    (-1isize..=1)
        .flat_map(move |dy| (-1isize..=1).map(move |dx| (x + dx, y + dy)))
        .filter(move |&(i, j)| {
            (i, j) != (x, y) && i >= 0 && j >= 0 && (i as usize) < w && (j as usize) < h
        })
        .map(move |(i, j)| j as usize * w + i as usize)
}

/// The mean of texel `k`'s valid 8-neighbours (of its own chart unless `any_chart`), if
/// it has any.
fn valid_mean(
    k: usize,
    values: &[Vec3],
    state: &[Burial],
    chart: &[u32],
    any_chart: bool,
    w: usize,
    h: usize,
) -> Option<Vec3> {
    let (mut sum, mut count) = (Vec3::ZERO, 0u32);
    for j in neighbours(k, w, h) {
        if state[j] == Burial::Valid && (any_chart || chart[j] == chart[k]) {
            sum += values[j];
            count += 1;
        }
    }
    (count > 0).then(|| sum / count as f32)
}

/// Refills buried texels of one texture from valid 8-neighbours by iterative averaging
/// (a Jacobi-style flood fill: each pass sets every buried texel that touches a valid one
/// to the mean of those, which then count as valid), preferring neighbours of the same
/// chart; only when no buried texel has such a neighbour does a pass take any valid
/// neighbour. Buried texels that no valid texel reaches keep their own estimate.
///
/// A pass looks only at the buried neighbours of the texels the pass before filled (no
/// other can have gained a valid neighbour), so the fill costs the texels it fills, not
/// their number times the passes.
fn fill_buried(values: &mut [Vec3], state: &mut [Burial], chart: &[u32], w: usize, h: usize) {
    let still_buried = |state: &[Burial]| {
        (0..state.len())
            .filter(|&k| state[k] == Burial::Buried)
            .collect::<Vec<usize>>()
    };
    let mut candidates = still_buried(state);
    // The pass in which a texel last became a candidate (none yet: 0).
    let mut queued = vec![0u32; values.len()];
    let mut updates: Vec<(usize, Vec3)> = Vec::new();
    let mut any_chart = false;
    let mut pass = 0u32;
    loop {
        pass += 1;
        updates.clear();
        updates.extend(
            candidates.iter().filter_map(|&k| {
                valid_mean(k, values, state, chart, any_chart, w, h).map(|v| (k, v))
            }),
        );
        if updates.is_empty() {
            if any_chart {
                break;
            }
            // No buried texel has a valid neighbour of its own chart: one pass takes
            // any valid neighbour, looking at every texel still buried.
            any_chart = true;
            candidates = still_buried(state);
            if candidates.is_empty() {
                break;
            }
            continue;
        }
        any_chart = false;
        for &(k, v) in &updates {
            values[k] = v;
            state[k] = Burial::Valid;
        }
        candidates.clear();
        for &(k, _) in &updates {
            for j in neighbours(k, w, h) {
                if state[j] == Burial::Buried && queued[j] != pass {
                    queued[j] = pass;
                    candidates.push(j);
                }
            }
        }
    }
}

/// Dilation: `passes` times, every texel no triangle owns that touches a set texel takes
/// the mean of its set 8-neighbours and becomes set (texels beyond stay black). Returns
/// how many texels were filled.
fn dilate(values: &mut [Vec3], state: &mut [Burial], w: usize, h: usize, passes: u32) -> u64 {
    let mut filled = 0;
    let mut updates: Vec<(usize, Vec3)> = Vec::new();
    for _ in 0..passes {
        updates.clear();
        for k in (0..values.len()).filter(|&k| state[k] == Burial::Empty) {
            let (mut sum, mut count) = (Vec3::ZERO, 0u32);
            for j in neighbours(k, w, h) {
                if state[j] != Burial::Empty {
                    sum += values[j];
                    count += 1;
                }
            }
            if count > 0 {
                updates.push((k, sum / count as f32));
            }
        }
        if updates.is_empty() {
            break;
        }
        for &(k, v) in &updates {
            values[k] = v;
            state[k] = Burial::Valid;
        }
        filled += updates.len() as u64;
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;
    use surfcache_core::sampling::Rng;

    /// The fill as its docs state it: every pass looks at every buried texel.
    fn fill_buried_by_passes(
        values: &mut [Vec3],
        state: &mut [Burial],
        chart: &[u32],
        w: usize,
        h: usize,
    ) {
        let mut pending: Vec<usize> = (0..values.len())
            .filter(|&k| state[k] == Burial::Buried)
            .collect();
        let mut any_chart = false;
        while !pending.is_empty() {
            let mut updates = Vec::new();
            for &k in &pending {
                if let Some(v) = valid_mean(k, values, state, chart, any_chart, w, h) {
                    updates.push((k, v));
                }
            }
            if updates.is_empty() {
                if any_chart {
                    break;
                }
                any_chart = true;
                continue;
            }
            any_chart = false;
            for (k, v) in updates {
                values[k] = v;
                state[k] = Burial::Valid;
            }
            pending.retain(|&k| state[k] == Burial::Buried);
        }
    }

    /// Filling from the texels the pass before filled gives exactly what passes over
    /// every buried texel give: on random textures of mostly buried texels in a few
    /// charts, with gutters and texels no valid one reaches.
    #[test]
    fn fill_from_the_front_equals_fill_by_passes() {
        for seed in 0..200u64 {
            let mut rng = Rng::new(seed, 0);
            let (w, h) = (
                1 + (rng.next_f32() * 24.0) as usize,
                1 + (rng.next_f32() * 24.0) as usize,
            );
            let n = w * h;
            let buried = rng.next_f32();
            let state: Vec<Burial> = (0..n)
                .map(|_| match rng.next_f32() {
                    x if x < 0.1 => Burial::Empty,
                    x if x < 0.1 + 0.9 * buried => Burial::Buried,
                    _ => Burial::Valid,
                })
                .collect();
            // Charts in vertical bands, so that same-chart neighbours run out.
            let bands = 1 + (rng.next_f32() * 4.0) as usize;
            let chart: Vec<u32> = (0..n).map(|k| ((k % w) * bands / w) as u32).collect();
            let values: Vec<Vec3> = (0..n)
                .map(|_| rng.next_vec2().extend(rng.next_f32()))
                .collect();
            let (mut v1, mut s1) = (values.clone(), state.clone());
            let (mut v2, mut s2) = (values, state);
            fill_buried(&mut v1, &mut s1, &chart, w, h);
            fill_buried_by_passes(&mut v2, &mut s2, &chart, w, h);
            assert_eq!(s1, s2, "seed {seed}");
            assert_eq!(v1, v2, "seed {seed}");
        }
    }
}
