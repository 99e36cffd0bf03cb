//! Filling texels without an estimate of their own (module docs): buried texels from
//! their valid neighbours, and the gutters around charts by dilation.

use super::Lightmaps;
use crate::burial::Burial;
use glam::Vec3;
use surfcache_core::index::NO_INDEX;

impl Lightmaps {
    /// Refills buried texels ([`fill_buried`]) and dilates into the gutters ([`dilate`]),
    /// texture by texture; returns how many texels dilation filled.
    pub(super) fn fill_textures(&self, values: &mut [Vec3], state: &mut [Burial]) -> u64 {
        let mut dilated = 0;
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
        for layer in 0..self.layers {
            for m in &self.maps {
                let range = layer * self.layer_texels + m.offset
                    ..layer * self.layer_texels + m.offset + m.texels();
                let (w, h) = (m.width as usize, m.height as usize);
                let chart = &texel_chart[m.offset..m.offset + m.texels()];
                fill_buried(
                    &mut values[range.clone()],
                    &mut state[range.clone()],
                    chart,
                    w,
                    h,
                );
                dilated += dilate(
                    &mut values[range.clone()],
                    &mut state[range],
                    w,
                    h,
                    self.settings.gutter,
                );
            }
        }
        dilated
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

/// Refills buried texels of one texture from valid 8-neighbours by iterative averaging
/// (a Jacobi-style flood fill: each pass sets every buried texel that touches a valid one
/// to the mean of those, which then count as valid), preferring neighbours of the same
/// chart; only when no buried texel has such a neighbour does a pass take any valid
/// neighbour. Buried texels that no valid texel reaches keep their own estimate.
fn fill_buried(values: &mut [Vec3], state: &mut [Burial], chart: &[u32], w: usize, h: usize) {
    let mut pending: Vec<usize> = (0..values.len())
        .filter(|&k| state[k] == Burial::Buried)
        .collect();
    let mut updates: Vec<(usize, Vec3)> = Vec::new();
    let mut any_chart = false;
    while !pending.is_empty() {
        updates.clear();
        for &k in &pending {
            let (mut sum, mut count) = (Vec3::ZERO, 0u32);
            for j in neighbours(k, w, h) {
                if state[j] == Burial::Valid && (any_chart || chart[j] == chart[k]) {
                    sum += values[j];
                    count += 1;
                }
            }
            if count > 0 {
                updates.push((k, sum / count as f32));
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
        for &(k, v) in &updates {
            values[k] = v;
            state[k] = Burial::Valid;
        }
        pending.retain(|&k| state[k] == Burial::Buried);
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
