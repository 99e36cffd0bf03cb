//! Incremental re-bakes: a layout carried over to an edited scene with its values as
//! priors, and the change of each triangle's texels between two bakes.

use super::{BuiltInstance, Lightmaps, Probed, build_instance};
use crate::{
    Prior, SurfaceCache, UNMAPPED, crossings,
    incremental::{ChangePatch, changed_region, near_changed_region},
    stored_rgb::difference_beyond,
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::Arc;
use surfcache_core::{
    geometry::{interpolate, triangle_area},
    index::NO_INDEX,
};
use surfcache_trace::TracedScene;

impl Lightmaps {
    /// Instances whose triangles all correspond one to one (same mesh, same mirroring)
    /// keep their layout, and their texels' values become priors (filled ones for texels
    /// that were buried), as do the values at their crossings' feet; the others are laid
    /// out afresh.
    pub(super) fn remapped(
        &self,
        old: &TracedScene,
        new: &TracedScene,
        triangle_map: &[u32],
    ) -> Self {
        let mut reused: Vec<Option<usize>> = vec![None; new.instance_triangles().len()];
        let built: Vec<BuiltInstance> = (0..new.instance_triangles().len())
            .map(|i| {
                let range = new.instance_triangles()[i].clone();
                let first_old = triangle_map
                    .get(range.start as usize)
                    .copied()
                    .unwrap_or(UNMAPPED);
                let i_old = old.instance().get(first_old as usize).map(|&k| k as usize);
                let one_to_one = i_old.is_some_and(|io| {
                    let old_range = &old.instance_triangles()[io];
                    old_range.len() == range.len()
                        && old.mirrored()[io] == new.mirrored()[i]
                        && range
                            .clone()
                            .enumerate()
                            .all(|(k, t)| triangle_map[t as usize] == old_range.start + k as u32)
                        && !self.owner.is_empty()
                });
                match i_old.filter(|_| one_to_one) {
                    Some(io) => {
                        reused[i] = Some(io);
                        self.instance_layout(old, io, range.start)
                    }
                    None => build_instance(new, i, &self.settings),
                }
            })
            .collect();
        let mut fresh = Self::from_instances(new, self.settings, built);
        let mut priors = vec![None; fresh.layers * fresh.layer_texels];
        let mut prior_feet = std::collections::HashMap::new();
        for (i, io) in reused.iter().enumerate() {
            let Some(io) = *io else { continue };
            let (m, m_old) = (fresh.maps[i], self.maps[io]);
            for layer in 0..fresh.layers.min(self.layers) {
                let slice = self.texture_slice(layer, io);
                for (k, &stored) in slice.iter().enumerate().take(m.texels()) {
                    let old_slot = layer * self.layer_texels + m_old.offset + k;
                    let slot = layer * fresh.layer_texels + m.offset + k;
                    if fresh.owner[m.offset + k] == NO_INDEX {
                        continue;
                    }
                    let value = self.scale.unpack(stored);
                    let buried = self.buried_slots.get(old_slot).copied().unwrap_or(true);
                    priors[slot] = Some(if buried {
                        Prior::Filled(value)
                    } else {
                        Prior::Estimated(value)
                    });
                    if let Some(&c) = self.crossing_slot.get(old_slot)
                        && let Some(&stored) = self.crossing_feet.get(c as usize)
                    {
                        // A line settled without its foot had a buried one: NaN.
                        let line = self.crossing_lines[c as usize];
                        let foot = match line.foot == line.site {
                            true => Vec3::NAN,
                            false => self.scale.unpack(stored),
                        };
                        prior_feet.insert(slot as u32, (line, foot));
                    }
                }
            }
            debug_assert_eq!((m.width, m.height), (m_old.width, m_old.height));
        }
        fresh.priors = priors;
        fresh.prior_feet = prior_feet;
        fresh.probed = self.carried_probes(&fresh, &reused, old, new, triangle_map);
        fresh
    }
    /// Whether triangle `t` has the texels that `t_old` had in `before` (same texture
    /// size, same UV1, same layers): its texels then compare one to one.
    fn kept_layout(&self, before: &Lightmaps, t: usize, t_old: u32) -> bool {
        t_old != UNMAPPED && {
            let (m, mo) = (
                &self.maps[self.triangle_instance[t] as usize],
                &before.maps[before.triangle_instance[t_old as usize] as usize],
            );
            (m.width, m.height) == (mo.width, mo.height)
                && self.uv1[t] == before.uv1[t_old as usize]
                && self.layers == before.layers
        }
    }

    /// Per triangle (of the scene `self` was laid out over): the largest change, in any
    /// channel and layer, of the texels a lookup on it can read (its UV1 box plus the
    /// bilinear footprint), against `before` looked up on `triangle_map[t]`, leaving out
    /// differences within `share` of the values ([`difference_beyond`]). Where the layouts
    /// differ, the sum of both sides' largest values bounds the change.
    pub fn triangle_changes(
        &self,
        before: &Lightmaps,
        triangle_map: &[u32],
        share: f32,
    ) -> Vec<f32> {
        (0..self.triangle_instance.len())
            .into_par_iter()
            .map(|t| {
                let t_old = triangle_map.get(t).copied().unwrap_or(UNMAPPED);
                let same_layout = self.kept_layout(before, t, t_old);
                let mut change = 0.0f32;
                for layer in 0..self.layers {
                    let after = self.footprint(layer, t as u32);
                    if same_layout {
                        let old = before.footprint(layer, t_old);
                        for (a, b) in after.zip(old) {
                            change = change.max(difference_beyond(a, b, share).max_element());
                        }
                    } else {
                        let a = after.fold(0.0f32, |m, v| m.max(v.abs().max_element()));
                        let b = if t_old == UNMAPPED || layer >= before.layers {
                            0.0
                        } else {
                            before
                                .footprint(layer, t_old)
                                .fold(0.0f32, |m, v| m.max(v.abs().max_element()))
                        };
                        change = change.max(a + b);
                    }
                }
                change
            })
            .collect()
    }

    /// The texels of `layer` that bilinear lookups on `triangle` read, row by row.
    fn footprint(&self, layer: usize, triangle: u32) -> impl Iterator<Item = Vec3> + '_ {
        let instance = self.triangle_instance[triangle as usize] as usize;
        let m = self.maps[instance];
        let texels = self.texture_slice(layer, instance);
        let [a, b, c] = self.uv1[triangle as usize];
        let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
        let size = Vec2::new(m.width as f32, m.height as f32);
        let first = ((lo * size - 0.5).floor().max(Vec2::ZERO)).as_uvec2();
        let last = (hi * size - 0.5).floor().max(Vec2::ZERO).as_uvec2() + 1;
        let last = last.min(glam::UVec2::new(m.width - 1, m.height - 1));
        let first = first.min(last);
        (first.y..=last.y).flat_map(move |y| {
            (first.x..=last.x).map(move |x| self.scale.unpack(texels[(y * m.width + x) as usize]))
        })
    }
}

impl Lightmaps {
    /// The probes of `self` (laid out over `old`) carried onto `fresh`, its remap onto
    /// `new` ([`Probed`]): a slot of a kept layout takes its old probe unless a surface
    /// that the edit changed lies within twice a probe's reach of it; every other slot
    /// is probed again.
    fn carried_probes(
        &self,
        fresh: &Lightmaps,
        reused: &[Option<usize>],
        old: &TracedScene,
        new: &TracedScene,
        triangle_map: &[u32],
    ) -> Option<Arc<Probed>> {
        let p = self.probed.as_deref()?;
        if p.site_uv.len() != self.layers * self.layer_texels || fresh.layers != self.layers {
            return None;
        }
        let region = changed_region(old, new, triangle_map);
        let total = fresh.layers * fresh.layer_texels;
        let mut out = Probed {
            site_uv: vec![Vec2::ZERO; total],
            exits: vec![None; total],
            crossing_slot: vec![NO_INDEX; total],
            stale: vec![true; total],
            ..Default::default()
        };
        for (i, io) in reused.iter().enumerate() {
            let Some(io) = *io else { continue };
            let (m, m_old) = (fresh.maps[i], self.maps[io]);
            let reach = Vec3::splat(
                2.0 * crossings::LINE_REACH / m.texels_per_metre.max(f32::MIN_POSITIVE),
            );
            for k in 0..m.texels() {
                let t = fresh.owner[m.offset + k];
                if t == NO_INDEX {
                    continue;
                }
                let [a, b, c] = new.positions()[t as usize];
                let x = interpolate(a, b, c, fresh.sample_uv[m.offset + k]);
                if near_changed_region(region, x, x, reach) {
                    continue;
                }
                for layer in 0..fresh.layers {
                    let slot = layer * fresh.layer_texels + m.offset + k;
                    let old_slot = layer * self.layer_texels + m_old.offset + k;
                    out.stale[slot] = false;
                    out.site_uv[slot] = p.site_uv[old_slot];
                    out.exits[slot] = p.exits[old_slot];
                    let c = p.crossing_slot[old_slot];
                    if c != NO_INDEX {
                        out.crossing_slot[slot] = out.crossing_lines.len() as u32;
                        out.crossing_lines.push(p.crossing_lines[c as usize]);
                        out.foot_sites.push(p.foot_sites[c as usize]);
                    }
                }
            }
        }
        Some(Arc::new(out))
    }

    /// Every owned texel, not buried, whose value changed beyond `share` ([`difference_beyond`])
    /// against `before` looked up on `triangle_map[t]`: texel against texel where the
    /// triangle kept its layout, against `before`'s lookup at the texel's sample point
    /// elsewhere (zero where the triangle did not exist before). Each texel as a
    /// [`ChangePatch`] at its sample point, with the world area it stands for.
    pub fn texel_changes(
        &self,
        scene: &TracedScene,
        before: &Lightmaps,
        triangle_map: &[u32],
        share: f32,
    ) -> Vec<ChangePatch> {
        // World area per texel of each triangle: its area over its UV1 area in texels.
        let texel_area = |t: u32| {
            let [a, b, c] = scene.positions()[t as usize];
            let m = &self.maps[self.triangle_instance[t as usize] as usize];
            let [p, q, r] = self.uv1[t as usize];
            let texels = 0.5 * ((q - p).perp_dot(r - p)).abs() * (m.width as f32 * m.height as f32);
            triangle_area(a, b, c) / texels.max(f32::MIN_POSITIVE)
        };
        (0..self.maps.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let m = self.maps[i];
                (0..self.layers).flat_map(move |layer| {
                    (0..m.texels()).filter_map(move |k| {
                        let t = self.owner[m.offset + k];
                        // A buried texel's value is filled in from its neighbours: no
                        // surface sees its light.
                        let slot = layer * self.layer_texels + m.offset + k;
                        if t == NO_INDEX || self.buried_slots.get(slot) == Some(&true) {
                            return None;
                        }
                        let uv = self.sample_uv[m.offset + k];
                        let front = layer == 0;
                        let after = self.scale.unpack(self.texture_slice(layer, i)[k]);
                        let t_old = triangle_map.get(t as usize).copied().unwrap_or(UNMAPPED);
                        let old = if self.kept_layout(before, t as usize, t_old) {
                            let io = before.triangle_instance[t_old as usize] as usize;
                            before.scale.unpack(before.texture_slice(layer, io)[k])
                        } else if t_old == UNMAPPED {
                            Vec3::ZERO
                        } else {
                            before.lookup(t_old, uv, front)
                        };
                        ChangePatch::of_sample(t, front, uv, texel_area(t), after, old, share)
                    })
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{LightmapSettings, incremental::cornell_moved};

    /// A re-bake carries the probes of the texels an edit did not come near, and probes
    /// the others again: together they must be exactly the probes of the edited scene.
    #[test]
    fn carried_probes_are_the_probes_of_the_edited_scene() {
        let (old, new, map) = cornell_moved(|name| name == "short_block", Vec3::X * 0.1);
        let settings = LightmapSettings {
            texels_per_metre: 16.0,
            ..Default::default()
        };
        let mut before = Lightmaps::new(&old, settings);
        before.probe_crossings(&old);
        let mut carried = before.remapped(&old, &new, &map);
        let mut fresh = carried.clone();
        fresh.probed = None;
        let stale = carried.probed.as_ref().unwrap().stale.clone();
        let owned = |slot: &usize| carried.owner[slot % carried.layer_texels] != NO_INDEX;
        let (kept, probed): (Vec<usize>, Vec<usize>) =
            (0..stale.len()).filter(owned).partition(|&s| !stale[s]);
        assert!(
            !kept.is_empty() && !probed.is_empty(),
            "{} kept, {} probed",
            kept.len(),
            probed.len()
        );
        carried.probe_crossings(&new);
        fresh.probe_crossings(&new);
        assert_eq!(carried.site_uv, fresh.site_uv);
        let (c, f) = (carried.probed.unwrap(), fresh.probed.unwrap());
        assert_eq!(c.exits, f.exits);
        assert_eq!(carried.crossing_slot, fresh.crossing_slot);
        assert_eq!(carried.crossing_lines, fresh.crossing_lines);
        assert_eq!(c.foot_sites, f.foot_sites);
        // The short block's floor contact moved: some texel there crosses it afresh.
        assert!(probed.iter().any(|&s| fresh.crossing_slot[s] != NO_INDEX));
    }
}
