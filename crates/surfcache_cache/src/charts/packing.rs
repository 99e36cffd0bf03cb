//! Packing chart shapes into one texture: exact claim bitmaps, first fit.
//!
//! Each chart claims the texels its triangles may cover (its *footprint*, a superset of
//! what the rasteriser gives them) dilated by the gutter (Chebyshev distance); claims
//! never overlap, so two charts' texels are at least 2 · gutter texels apart and each
//! chart's gutter is its own (dilated from it alone). Charts, largest claim first, go to
//! the lowest row, then the lowest column, where their claim bitmap fits between the
//! claims already placed (bottom-left first fit over chart bitmaps, as xatlas packs;
//! Jylänki, "A Thousand Ways to Pack the Bin", 2010, §5 on bottom-left placement), trying
//! each chart as laid out and turned by 90° and keeping the lower top edge (the turned
//! claim searched only where it could end lower). Rows are
//! 64-texel words; a row whose longest free run is shorter than the chart's longest run of claimed texels in a row
//! is skipped whole, and so is every column where the chart's longest run of claimed
//! texels in a row would not land on free ones.

/// A chart's claim: `width × height` texels, each row as 64-texel words (bit i of word k
/// is column 64k + i).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) struct Claim {
    pub width: u32,
    pub height: u32,
    words: usize,
    bits: Vec<u64>,
    /// The longest run of claimed texels in a row: its row, first column and length.
    key_row: u32,
    key_start: u32,
    key_length: u32,
}

impl Claim {
    /// The claim of a footprint (`w × h` texels, row-major) dilated by `gutter`.
    pub fn of_footprint(footprint: &[bool], w: u32, h: u32, gutter: u32) -> Self {
        let (width, height) = (w + 2 * gutter, h + 2 * gutter);
        let words = (width as usize).div_ceil(64).max(1);
        let mut bits = vec![0u64; words * height as usize];
        let g = gutter as usize;
        // Dilate along rows into the claim's rows, then along columns.
        let mut rows = vec![false; (width * h) as usize];
        for y in 0..h as usize {
            for x in 0..w as usize {
                if footprint[y * w as usize + x] {
                    for c in x..=x + 2 * g {
                        rows[y * width as usize + c] = true;
                    }
                }
            }
        }
        for y in 0..h as usize {
            for c in 0..width as usize {
                if rows[y * width as usize + c] {
                    for r in y..=y + 2 * g {
                        bits[r * words + c / 64] |= 1 << (c % 64);
                    }
                }
            }
        }
        let mut claim = Self {
            width,
            height,
            words,
            bits,
            ..Default::default()
        };
        for r in 0..height {
            let (mut run, mut start) = (0u32, 0u32);
            for c in 0..width {
                if claim.row(r)[(c / 64) as usize] >> (c % 64) & 1 == 1 {
                    if run == 0 {
                        start = c;
                    }
                    run += 1;
                    if run > claim.key_length {
                        (claim.key_row, claim.key_start, claim.key_length) = (r, start, run);
                    }
                } else {
                    run = 0;
                }
            }
        }
        claim
    }

    fn row(&self, r: u32) -> &[u64] {
        &self.bits[r as usize * self.words..(r as usize + 1) * self.words]
    }

    /// Texels claimed.
    pub fn area(&self) -> u64 {
        self.bits.iter().map(|w| w.count_ones() as u64).sum()
    }
}

/// Where a chart went: its claim's top-left texel and whether it is the turned claim.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Placement {
    pub x: u32,
    pub y: u32,
    pub turned: bool,
}

/// The texture being filled: one bit per texel, rows of `words` words, and the longest
/// run of free texels of every row.
struct Occupancy {
    width: u32,
    words: usize,
    bits: Vec<u64>,
    longest_free: Vec<u32>,
}

impl Occupancy {
    fn rows(&self) -> u32 {
        self.longest_free.len() as u32
    }

    /// The words of claim row `row` shifted to start at column `x`, as (word index, bits)
    /// pairs of the texture row.
    fn shifted(claim_row: &[u64], x: u32) -> impl Iterator<Item = (usize, u64)> + '_ {
        let (base, s) = ((x / 64) as usize, x % 64);
        claim_row.iter().enumerate().flat_map(move |(k, &w)| {
            let lo = (base + k, w << s);
            let hi = (base + k + 1, if s == 0 { 0 } else { w >> (64 - s) });
            [lo, hi]
        })
    }

    /// Whether `claim` fits with its top-left texel at (x, y) (its last row tried first:
    /// in a filling texture the lower rows collide most).
    fn fits(&self, claim: &Claim, x: u32, y: u32) -> bool {
        let rows = claim.height.min(self.rows().saturating_sub(y));
        (0..rows).rev().all(|r| {
            let row = &self.bits[(y + r) as usize * self.words..(y + r + 1) as usize * self.words];
            Self::shifted(claim.row(r), x)
                .all(|(i, w)| w == 0 || row.get(i).is_none_or(|&a| a & w == 0))
        })
    }

    fn place(&mut self, claim: &Claim, x: u32, y: u32) {
        while self.rows() < y + claim.height {
            self.bits.extend(std::iter::repeat_n(0, self.words));
            self.longest_free.push(self.width);
        }
        for r in 0..claim.height {
            let start = (y + r) as usize * self.words;
            for (i, w) in Self::shifted(claim.row(r), x) {
                if w != 0 {
                    self.bits[start + i] |= w;
                }
            }
            self.longest_free[(y + r) as usize] = self.longest_run(y + r);
        }
    }

    /// Longest run of free texels of row `y`.
    fn longest_run(&self, y: u32) -> u32 {
        let (mut best, mut run) = (0u32, 0u32);
        for x in 0..self.width {
            if self.bits[y as usize * self.words + (x / 64) as usize] >> (x % 64) & 1 == 0 {
                run += 1;
                best = best.max(run);
            } else {
                run = 0;
            }
        }
        best
    }

    /// Bottom-left first fit of `claim`: the lowest row, then column, where it fits, if
    /// that row is below `below`. `runs` is scratch space of one row.
    fn first_fit(&self, claim: &Claim, below: u32, runs: &mut Vec<u64>) -> Option<(u32, u32)> {
        let max_x = self.width - claim.width;
        for y in 0..self.rows().min(below) {
            let key = y + claim.key_row;
            if key >= self.rows() {
                break;
            }
            if self.longest_free[key as usize] < claim.key_length {
                continue;
            }
            // Bit c of `runs`: columns c .. c + key_length of the key row are all free.
            let row = &self.bits[key as usize * self.words..(key as usize + 1) * self.words];
            runs.clear();
            runs.extend(row.iter().map(|w| !w));
            let tail = self.width % 64;
            if tail != 0 {
                runs[self.words - 1] &= (1u64 << tail) - 1;
            }
            let mut length = 1;
            while length < claim.key_length {
                let s = length.min(claim.key_length - length);
                shift_and(runs, s);
                length += s;
            }
            for (k, &word) in runs.iter().enumerate() {
                let mut word = word;
                while word != 0 {
                    let start = 64 * k as u32 + word.trailing_zeros();
                    word &= word - 1;
                    let Some(x) = start.checked_sub(claim.key_start) else {
                        continue;
                    };
                    if x > max_x {
                        break;
                    }
                    if self.fits(claim, x, y) {
                        return Some((x, y));
                    }
                }
            }
        }
        // Beyond the texture's rows with its key row: the first fit from there on.
        let y = self.rows().saturating_sub(claim.key_row);
        (0..=max_x)
            .map(|x| (x, y))
            .chain((y + 1..).map(|y| (0, y)))
            .take_while(|&(_, y)| y < below)
            .find(|&(x, y)| self.fits(claim, x, y))
    }
}

/// `bits &= bits >> s` over a row of words (bit c takes bit c + s; beyond the row: 0).
fn shift_and(bits: &mut [u64], s: u32) {
    let (q, r) = ((s / 64) as usize, s % 64);
    for i in 0..bits.len() {
        let lo = bits.get(i + q).copied().unwrap_or(0);
        let hi = bits.get(i + q + 1).copied().unwrap_or(0);
        let shifted = if r == 0 { lo } else { lo >> r | hi << (64 - r) };
        bits[i] &= shifted;
    }
}

/// Packs charts, each given as its claim laid out and turned, into a texture `width`
/// texels wide (at least the narrow side of every claim); returns the placements and the
/// rows used. Deterministic: ties go to the lower row, then column, then input order.
pub(super) fn pack_claims(charts: &[[Claim; 2]], width: u32) -> (Vec<Placement>, u32) {
    let mut order: Vec<usize> = (0..charts.len()).collect();
    let area: Vec<u64> = charts.iter().map(|c| c[0].area()).collect();
    order.sort_by(|&a, &b| area[b].cmp(&area[a]).then(a.cmp(&b)));
    let words = (width as usize).div_ceil(64).max(1);
    let mut occupancy = Occupancy {
        width,
        words,
        bits: Vec::new(),
        longest_free: Vec::new(),
    };
    let mut placements = vec![Placement::default(); charts.len()];
    let mut runs = Vec::with_capacity(words);
    for i in order {
        // The lower claim first; the other only where its top edge could end lower.
        let lower = usize::from(charts[i][1].height < charts[i][0].height);
        let mut best: Option<(u32, u32, u32, bool)> = None;
        for turned in [lower == 1, lower == 0] {
            let claim = &charts[i][usize::from(turned)];
            if claim.width > width {
                continue;
            }
            let below = best.map_or(u32::MAX, |b| b.0.saturating_sub(claim.height));
            if let Some((x, y)) = occupancy.first_fit(claim, below, &mut runs) {
                let spot = (y + claim.height, y, x, turned);
                if best.is_none_or(|b| spot < b) {
                    best = Some(spot);
                }
            }
        }
        let Some((_, y, x, turned)) = best else {
            unreachable!("the texture is as wide as every chart's narrow side");
        };
        occupancy.place(&charts[i][usize::from(turned)], x, y);
        placements[i] = Placement { x, y, turned };
    }
    (placements, occupancy.rows())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn claims_do_not_overlap_and_fill_holes() {
        // Rectangles and triangles of footprints, every claim drawn into the texture.
        let mut charts = Vec::new();
        for i in 0..150u32 {
            let (w, h) = (1 + (i * 7919) % 13, 1 + (i * 104_729) % 9);
            let mut fp = vec![false; (w * h) as usize];
            for y in 0..h {
                for x in 0..w {
                    fp[(y * w + x) as usize] = i % 2 == 0 || x * h <= (y + 1) * w;
                }
            }
            let mut turned = vec![false; (w * h) as usize];
            for y in 0..h {
                for x in 0..w {
                    turned[(x * h + (h - 1 - y)) as usize] = fp[(y * w + x) as usize];
                }
            }
            charts.push([
                Claim::of_footprint(&fp, w, h, 1),
                Claim::of_footprint(&turned, h, w, 1),
            ]);
        }
        let width = 96;
        let (placed, rows) = pack_claims(&charts, width);
        let mut used = vec![false; (width * rows) as usize];
        let mut area = 0;
        for (c, p) in charts.iter().zip(&placed) {
            let claim = &c[usize::from(p.turned)];
            area += claim.area();
            assert!(p.x + claim.width <= width && p.y + claim.height <= rows);
            for y in 0..claim.height {
                for x in 0..claim.width {
                    if claim.row(y)[(x / 64) as usize] >> (x % 64) & 1 == 1 {
                        let k = ((p.y + y) * width + p.x + x) as usize;
                        assert!(!used[k], "overlap at {},{}", p.x + x, p.y + y);
                        used[k] = true;
                    }
                }
            }
        }
        assert!(
            (width * rows) as f64 <= 1.3 * area as f64,
            "{width} × {rows} for {area}"
        );
    }

    #[test]
    fn a_claim_is_its_footprint_dilated() {
        // An L of three texels, gutter 1: the union of three 3 × 3 squares.
        let fp = [true, false, true, true];
        let claim = Claim::of_footprint(&fp, 2, 2, 1);
        assert_eq!((claim.width, claim.height), (4, 4));
        assert_eq!(claim.area(), 15);
        assert_eq!(
            (claim.key_row, claim.key_start, claim.key_length),
            (1, 0, 4)
        );
    }
}
