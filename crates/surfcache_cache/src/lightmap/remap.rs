//! Incremental re-bakes: a layout carried over to an edited scene with its values as
//! priors, and the change of each triangle's texels between two bakes.

use super::{BuiltInstance, Lightmaps, build_instance};
use crate::{Prior, UNMAPPED, stored_rgb::difference_beyond};
use glam::{Vec2, Vec3};
use surfcache_core::index::NO_INDEX;
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
                        && c != NO_INDEX
                    {
                        let foot = self.scale.unpack(self.crossing_feet[c as usize]);
                        prior_feet.insert(slot as u32, (self.crossing_lines[c as usize], foot));
                    }
                }
            }
            debug_assert_eq!((m.width, m.height), (m_old.width, m_old.height));
        }
        fresh.priors = priors;
        fresh.prior_feet = prior_feet;
        fresh
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
            .map(|t| {
                let t_old = triangle_map.get(t).copied().unwrap_or(UNMAPPED);
                let same_layout = t_old != UNMAPPED && {
                    let (i, io) = (
                        self.triangle_instance[t] as usize,
                        before.triangle_instance[t_old as usize] as usize,
                    );
                    let (m, mo) = (&self.maps[i], &before.maps[io]);
                    (m.width, m.height) == (mo.width, mo.height)
                        && self.uv1[t] == before.uv1[t_old as usize]
                        && self.layers == before.layers
                };
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
