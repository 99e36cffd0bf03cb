//! Direction guides of refining grids (docs/design.md, Guiding).
//!
//! A grid that may refine for two more rounds records where the light of its samples came
//! from ([`GuideRecord`]); the new samples of its later rounds draw their directions
//! through a guide learnt from its rounds so far ([`DirectionGuide`]), as a lightmap's
//! texel blocks do ([`crate::lightmap`]). A round's new samples lie between the samples
//! of the rounds before on the same triangle side, and see the same openings and bright
//! surfaces; a guide depends only on earlier rounds, so every estimate stays unbiased.
//!
//! A large triangle sees different light in different places (a floor that runs from
//! a gallery out under the sky), so a grid records by *region*: the cells of a coarse
//! grid whose spacing is [`REGION_SPACINGS`] spacings of the grid's maximum order. A
//! region's guide is its own once it recorded [`REGION_SAMPLES`] samples, else the guide
//! of its whole grid. Grids of small triangles, which cannot refine that far, keep no
//! record: the records sit on the few large triangles whose deep rounds take most of a
//! level's samples. Points without a guide of their own draw through the guide a
//! lightmap bounce pass learnt where they lie (docs/design.md, Guiding, "Borrowed
//! guides").

use super::grid::grid_index;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::{
    Guidance,
    guiding::{DirectionGuide, GuideRecord},
};

/// Spacings of a grid's maximum order along a region's side.
pub const REGION_SPACINGS: u32 = 16;

/// Samples a region must have recorded for a guide of its own.
pub const REGION_SAMPLES: u64 = 1024;

/// Records of the grids that keep them, and the guides of the running round.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct GridGuides {
    /// Irradiance (W/m²) of one unit of a record ([`GuideRecord::new`]).
    unit: f32,
    /// Per grid slot: its first record in `records`, or [`NO_INDEX`].
    record_of: Vec<u32>,
    /// Per grid slot with records: the order of its region grid (regions are its cells).
    regions_of: Vec<u8>,
    records: Vec<GuideRecord>,
    /// Per record: the guide its region's samples draw through in this round, in
    /// `guides`, or [`NO_INDEX`].
    guide_of: Vec<u32>,
    guides: Vec<DirectionGuide>,
    /// Per point of this round: the record it adds to (and whose guide it draws
    /// through), or [`NO_INDEX`] (crossing feet, which lie at contacts their grid's other
    /// samples do not see, and grids without records).
    round_record: Vec<u32>,
}

/// The cell of the order-`r` grid that holds grid point (i, j) of order `n` (a point on
/// a cell boundary goes to the cell on its lower side), numbered as grid samples are.
fn region(i: u32, j: u32, n: u32, r: u32) -> usize {
    let (mut ci, mut cj) = (i * r / n, j * r / n);
    // Cells (ci, cj) with ci + cj ≤ r − 1; points on the long edge belong to the cells
    // beside it.
    while ci + cj > r - 1 {
        if ci >= cj { ci -= 1 } else { cj -= 1 }
    }
    grid_index(ci, cj)
}

impl GridGuides {
    /// Guides over `slots` grid slots, recording in units of `unit` W/m².
    pub(super) fn new(slots: usize, unit: f32) -> Self {
        Self {
            unit,
            record_of: vec![NO_INDEX; slots],
            regions_of: vec![0; slots],
            ..Default::default()
        }
    }

    /// Whether the guides were made ([`Self::new`]): a default one records nothing.
    pub(super) fn is_on(&self) -> bool {
        !self.record_of.is_empty()
    }

    /// Before a round: forgets the last round's guides and points.
    pub(super) fn start_round(&mut self) {
        self.guides.clear();
        self.guide_of.fill(NO_INDEX);
        self.round_record.clear();
    }

    /// Grid slot `g`, at order `n` this round and maximum order `max`, gets the guides
    /// its records ask for if it recorded in earlier rounds, and starts recording if it
    /// may still refine twice after this round's order (`4·n ≤ n_max`).
    pub(super) fn prepare_grid(&mut self, g: u32, n: u32, max: u32) {
        if !self.is_on() {
            return;
        }
        let g = g as usize;
        match self.record_of[g] {
            NO_INDEX if 4 * n <= max => {
                let r = (max / REGION_SPACINGS).clamp(1, 128);
                self.record_of[g] = self.records.len() as u32;
                self.regions_of[g] = r as u8;
                let cells = (r * (r + 1) / 2) as usize;
                self.records
                    .extend((0..cells).map(|_| GuideRecord::new(self.unit)));
                self.guide_of.resize(self.records.len(), NO_INDEX);
            }
            NO_INDEX => {}
            first => self.learn(first as usize, self.regions_of[g] as u32),
        }
    }

    /// Guides for the regions of the grid whose `r`-order regions' records start at
    /// `first`: a region's own where it recorded enough, else the whole grid's.
    fn learn(&mut self, first: usize, r: u32) {
        let records = first..first + (r * (r + 1) / 2) as usize;
        // The whole grid's guide, made once, when a region first needs it.
        let mut whole: Option<u32> = None;
        for k in records.clone() {
            let guide = if r == 1 || self.records[k].samples() >= REGION_SAMPLES {
                self.push_guide(DirectionGuide::from_record(&self.records[k]))
            } else {
                *whole.get_or_insert_with(|| {
                    let pooled = GuideRecord::new(self.unit);
                    self.records[records.clone()]
                        .iter()
                        .for_each(|rec| pooled.absorb(rec));
                    let guide = DirectionGuide::from_record(&pooled);
                    self.push_guide(guide)
                })
            };
            self.guide_of[k] = guide;
        }
    }

    /// Stores `guide`, if any: its index in `guides`, or [`NO_INDEX`].
    fn push_guide(&mut self, guide: Option<DirectionGuide>) -> u32 {
        match guide {
            Some(guide) => {
                self.guides.push(guide);
                self.guides.len() as u32 - 1
            }
            None => NO_INDEX,
        }
    }

    /// The next point of the round samples grid point (i, j) of order `n` of grid slot
    /// `grid`; `None`: it samples for no grid's record (a crossing foot).
    pub(super) fn push_point(&mut self, grid: Option<(u32, u32, u32, u32)>) {
        if !self.is_on() {
            return;
        }
        let record = match grid {
            Some((g, i, j, n)) => match self.record_of[g as usize] {
                NO_INDEX => NO_INDEX,
                first => {
                    let r = self.regions_of[g as usize] as u32;
                    first + region(i, j, n, r) as u32
                }
            },
            None => NO_INDEX,
        };
        self.round_record.push(record);
    }

    /// How point `i` of the round draws its directions and where it records them.
    pub(super) fn guidance(&self, i: usize) -> Guidance<'_> {
        let Some(&k) = self.round_record.get(i).filter(|&&k| k != NO_INDEX) else {
            return Guidance::default();
        };
        Guidance {
            record: self.records.get(k as usize),
            guide: self.guides.get(self.guide_of[k as usize] as usize),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_cover_the_grid_with_its_coarse_cells() {
        // Every point of an order-8 grid falls in one of the 10 cells of order 4, and
        // each cell holds its own corner points.
        let (n, r) = (8, 4);
        let mut seen = vec![0; 10];
        for i in 0..=n {
            for j in 0..=n - i {
                let k = region(i, j, n, r);
                assert!(k < 10, "({i}, {j}) in cell {k}");
                seen[k] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c > 0), "{seen:?}");
        assert_eq!(region(0, 0, n, r), grid_index(0, 0));
        assert_eq!(region(8, 0, n, r), grid_index(3, 0));
        assert_eq!(region(0, 8, n, r), grid_index(0, 3));
        assert_eq!(region(4, 4, n, r), grid_index(1, 2));
        assert_eq!(region(1, 1, n, r), grid_index(0, 0));
        // One region: everything in cell 0.
        assert_eq!(region(5, 3, n, 1), 0);
    }
}
