//! Lookups near crossings (module docs): the probes that find, while baking, the surfaces
//! that cross each texel's footprint, and the bilinear lookup that keeps texels beyond
//! such a crossing out.

use super::{Lightmaps, Probed};
use crate::{
    crossings::{self, Probe},
    stored_rgb::{StoreScale, StoredRgb},
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::TracedScene;

/// How far (in texels) a buried texel's exit may lie: within its footprint (¾ of a texel
/// reaches its corners' direction closely enough).
const EXIT_REACH: f32 = 0.75;

impl Lightmaps {
    /// Takes `other`'s probes where it has the same layout ([`crate::Cache::adopt_probes`]).
    pub(crate) fn adopt_probes(&mut self, other: &Lightmaps) {
        if (self.layers, self.layer_texels) == (other.layers, other.layer_texels)
            && self.maps == other.maps
            && self.owner == other.owner
        {
            self.probed = other.probed.clone();
        }
    }

    /// Probes every owned slot for crossings near its texel ([`crossings::probe`], as far
    /// as [`crossings::LINE_REACH`] texels): records exits within its footprint
    /// ([`EXIT_REACH`]) for buried texels, and each crossing as a line in UV1 space with
    /// its foot for lookups.
    pub(super) fn probe_crossings(&mut self, scene: &TracedScene) {
        let total = self.layers * self.layer_texels;
        // A re-bake carries the probes of slots that no changed surface came near
        // ([`Probed::stale`]).
        let carried = self.probed.take().filter(|p| p.site_uv.len() == total);
        // The slots probed afresh (all but those a re-bake carries), and their probes.
        let fresh: Vec<usize> = (0..total)
            .filter(|&slot| {
                carried
                    .as_deref()
                    .is_none_or(|p| p.stale.get(slot).copied().unwrap_or(false))
            })
            .collect();
        let probes: Vec<(Vec2, Probe)> = fresh
            .par_iter()
            .map(|&slot| {
                let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
                let uv = self.sample_uv[i];
                match self.owner[i] {
                    NO_INDEX => (uv, Probe::default()),
                    t => {
                        let m = &self.maps[self.triangle_instance[t as usize] as usize];
                        let texel = 1.0 / m.texels_per_metre.max(f32::MIN_POSITIVE);
                        let mut probe = crossings::probe(
                            scene,
                            t,
                            uv,
                            layer == 0,
                            crossings::LINE_REACH * texel,
                        );
                        // A buried texel moves only within its own footprint.
                        if probe.exit_distance > EXIT_REACH * texel {
                            probe.exit = None;
                        }
                        // A centre on a crossing surface is estimated just beyond it, on
                        // the open side, from the first round on; its crossing line is
                        // oriented from there.
                        let site = probe.site(uv);
                        if probe.touching {
                            probe.exit = None;
                        }
                        (site, probe)
                    }
                }
            })
            .collect();
        let mut found = Probed {
            site_uv: Vec::with_capacity(total),
            exits: Vec::with_capacity(total),
            crossing_slot: vec![NO_INDEX; total],
            ..Default::default()
        };
        let mut fresh = fresh.iter().zip(probes).peekable();
        for slot in 0..total {
            let crossing = match fresh.next_if(|(s, _)| **s == slot) {
                Some((_, (uv, probe))) => {
                    found.site_uv.push(uv);
                    found.exits.push(probe.exit);
                    probe.crossing.and_then(|line| {
                        let t = self.owner[slot % self.layer_texels];
                        let front = slot < self.layer_texels;
                        let corners = self.uv1[t as usize];
                        crossings::SampleCrossing::new(scene, t, front, &line, corners, uv)
                    })
                }
                None => {
                    let p = carried
                        .as_deref()
                        .expect("a slot not probed afresh is carried");
                    found.site_uv.push(p.site_uv[slot]);
                    found.exits.push(p.exits[slot]);
                    let c = p.crossing_slot[slot];
                    (c != NO_INDEX)
                        .then(|| (p.crossing_lines[c as usize], p.foot_sites[c as usize]))
                }
            };
            if let Some((line, foot)) = crossing {
                found.crossing_slot[slot] = found.crossing_lines.len() as u32;
                found.crossing_lines.push(line);
                found.foot_sites.push(foot);
            }
        }
        // What baking changes (a moved site, settled lines) is copied out; exits and
        // feet are read from the probes themselves.
        self.site_uv = found.site_uv.clone();
        self.crossing_slot = found.crossing_slot.clone();
        self.crossing_lines = found.crossing_lines.clone();
        self.probed = Some(std::sync::Arc::new(found));
    }
}

/// Bilinear lookup with clamp-to-edge in stored texels, arithmetic identical to
/// [`crate::texture::bilinear`] on the unpacked image (what the GPU sampler computes),
/// except near crossings: `line_of(k)` is texel k's crossing line ([`NO_INDEX`]: none) and
/// `crossing(line)` the line with the value at its foot; texels whose crossing separates
/// them from the point looked up are left out and the others' weights renormalised, and
/// a texel whose line lies between it and the point takes the value linear from its foot
/// to it ([`crossings::SampleCrossing::value`]). Where every texel is rejected the plain
/// bilinear value is returned.
#[inline]
pub(super) fn bilinear_packed(
    texels: &[StoredRgb],
    width: u32,
    height: u32,
    uv: Vec2,
    scale: StoreScale,
    line_of: impl Fn(usize) -> u32,
    crossing: impl Fn(u32) -> (crossings::SampleCrossing, Vec3),
) -> Vec3 {
    let x = (uv.x * width as f32 - 0.5).clamp(0.0, (width - 1) as f32);
    let y = (uv.y * height as f32 - 0.5).clamp(0.0, (height - 1) as f32);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let taps = [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x1, y0, fx * (1.0 - fy)),
        (x0, y1, (1.0 - fx) * fy),
        (x1, y1, fx * fy),
    ];
    let keys = taps.map(|(i, j, _)| (j * width + i) as usize);
    let values = keys.map(|k| scale.unpack(texels[k]));
    // Exactly the published texture's bilinear ([`crate::texture::bilinear`]).
    let plain = || {
        let top = values[0] * (1.0 - fx) + values[1] * fx;
        let bottom = values[2] * (1.0 - fx) + values[3] * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let lines = keys.map(&line_of);
    if lines.iter().all(|&l| l == NO_INDEX) {
        return plain();
    }
    let (mut sum, mut weight, mut changed) = (Vec3::ZERO, 0.0f32, false);
    for n in 0..4 {
        let w = taps[n].2;
        if w <= 0.0 {
            continue;
        }
        let mut value = values[n];
        if lines[n] != NO_INDEX {
            let (c, foot) = crossing(lines[n]);
            let Some((tapped, blended)) = c.tap(uv, value, foot) else {
                changed = true;
                continue;
            };
            changed |= blended;
            value = tapped;
        }
        sum += value * w;
        weight += w;
    }
    if !changed || weight <= 0.0 {
        plain()
    } else {
        sum / weight
    }
}
