//! Direction guides of a lightmap's texel blocks (docs/design.md, Guiding).
//!
//! Every round records, for every block of [`BLOCK`] × [`BLOCK`] texels of one texture
//! and side, where the light of its texels' samples came from ([`GuideRecord`]); texels
//! that need another round draw their directions through a guide learnt from all
//! earlier rounds of their block ([`DirectionGuide`]). Neighbouring texels see the same
//! openings and bright surfaces, so a block's pooled samples learn a guide that no
//! texel's own samples could, and as rounds double their samples, the guides of the
//! texels still sampling improve with them (the training schedule of Müller et al.
//! 2017). A round's guide depends only on earlier rounds, so every round stays unbiased.
//!
//! A lightmap records whether or not it draws through guides itself (the bounce passes
//! do not), and keeps its records once baked: the pass that gathers from it borrows
//! them for points that have no guide of their own ([`super::Lightmaps::guide_at`]).

use super::InstanceMap;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::guiding::{DirectionGuide, GuideRecord};

/// Side of a block in texels.
pub const BLOCK: u32 = 4;

/// Records of all rounds so far, and the guides of the next round.
#[derive(Debug, Default)]
pub(super) struct TexelGuides {
    /// Block of each texel of a layer (its index within the layer), or [`NO_INDEX`] for a
    /// texel no triangle owns.
    block: Vec<u32>,
    /// Blocks per layer.
    layer_blocks: usize,
    records: Vec<GuideRecord>,
    /// Per block of all layers: index into `guides`, or [`NO_INDEX`].
    block_guide: Vec<u32>,
    guides: Vec<DirectionGuide>,
}

/// A copy starts without records or guides: they are working state of one bake, which
/// copies of a lightmap (an unbaked layout shared between passes) do not carry over.
impl Clone for TexelGuides {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl TexelGuides {
    /// Empty records for every block that holds an owned texel, on `layers` sides;
    /// record values count in units of `unit` W/m².
    pub(super) fn recording(maps: &[InstanceMap], owner: &[u32], layers: usize, unit: f32) -> Self {
        let mut block = vec![NO_INDEX; owner.len()];
        // Blocks are numbered densely, only where a texel is owned.
        let mut numbered = std::collections::HashMap::new();
        for (m_index, m) in maps.iter().enumerate() {
            for k in 0..m.texels() {
                if owner[m.offset + k] == NO_INDEX {
                    continue;
                }
                let (x, y) = (k as u32 % m.width, k as u32 / m.width);
                let key = (m_index, x / BLOCK, y / BLOCK);
                let next = numbered.len() as u32;
                block[m.offset + k] = *numbered.entry(key).or_insert(next);
            }
        }
        let layer_blocks = numbered.len();
        Self {
            block,
            layer_blocks,
            records: (0..layer_blocks * layers)
                .map(|_| GuideRecord::new(unit))
                .collect(),
            block_guide: Vec::new(),
            guides: Vec::new(),
        }
    }

    /// The block of texel slot `slot` (layer · `layer_texels` + texel) over all layers.
    fn block_of(&self, slot: usize) -> Option<usize> {
        let layer_texels = self.block.len();
        if layer_texels == 0 {
            return None;
        }
        match self.block[slot % layer_texels] {
            NO_INDEX => None,
            b => Some((slot / layer_texels) * self.layer_blocks + b as usize),
        }
    }

    /// Where the samples of `slot` record their light.
    pub(super) fn record(&self, slot: usize) -> Option<&GuideRecord> {
        self.records.get(self.block_of(slot)?)
    }

    /// The guide `slot` draws its directions through in this round.
    pub(super) fn guide(&self, slot: usize) -> Option<&DirectionGuide> {
        let g = *self.block_guide.get(self.block_of(slot)?)?;
        self.guides.get(g as usize)
    }

    /// Drops the guides of the last round, keeping the records.
    pub(super) fn forget_guides(&mut self) {
        self.block_guide = Vec::new();
        self.guides = Vec::new();
    }

    /// Replaces the guides by those the records ask for in the blocks that hold one of
    /// `slots` (the texels of the next round).
    pub(super) fn learn(&mut self, slots: impl Iterator<Item = usize>) {
        let mut wanted = vec![false; self.records.len()];
        for slot in slots {
            if let Some(b) = self.block_of(slot) {
                wanted[b] = true;
            }
        }
        self.block_guide = vec![NO_INDEX; self.records.len()];
        self.guides.clear();
        for (b, record) in self.records.iter().enumerate() {
            if !wanted[b] {
                continue;
            }
            if let Some(guide) = DirectionGuide::from_record(record) {
                self.block_guide[b] = self.guides.len() as u32;
                self.guides.push(guide);
            }
        }
    }
}
