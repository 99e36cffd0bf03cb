//! Packing rectangles (per-triangle blocks, lightmap charts) into one texture.

use serde::{Deserialize, Serialize};

/// Where each rectangle went, and the size of the texture that holds them.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasLayout {
    pub width: u32,
    pub height: u32,
    /// Top-left texel of each rectangle, in input order.
    pub origins: Vec<[u32; 2]>,
}

/// Shelf packing (Jylänki, "A Thousand Ways to Pack the Bin", 2010, §2.2 SHELF-NEXT-FIT on
/// rectangles sorted by decreasing height): rows of rectangles filled left to right in a
/// texture whose width is about the square root of the total area, rounded up to a
/// multiple of 4. Deterministic: ties keep input order. Zero-sized rectangles get origin
/// (0, 0).
///
/// ```
/// use surfcache_cache::atlas::pack_rectangles;
/// let layout = pack_rectangles(&[[4, 4], [2, 3], [4, 1]]);
/// assert!(layout.width >= 4 && layout.height >= 4);
/// ```
pub fn pack_rectangles(sizes: &[[u32; 2]]) -> AtlasLayout {
    let area: u64 = sizes.iter().map(|s| s[0] as u64 * s[1] as u64).sum();
    let widest = sizes.iter().map(|s| s[0]).max().unwrap_or(0);
    if area == 0 {
        return AtlasLayout {
            width: 1,
            height: 1,
            origins: vec![[0, 0]; sizes.len()],
        };
    }
    let target = ((area as f64 * 1.15).sqrt().ceil() as u32).max(widest);
    let width = target.div_ceil(4) * 4;
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| sizes[b][1].cmp(&sizes[a][1]).then(a.cmp(&b)));
    let mut origins = vec![[0u32; 2]; sizes.len()];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for i in order {
        let [w, h] = sizes[i];
        if w == 0 || h == 0 {
            continue;
        }
        if x + w > width {
            y += shelf;
            x = 0;
            shelf = 0;
        }
        origins[i] = [x, y];
        x += w;
        shelf = shelf.max(h);
    }
    AtlasLayout {
        width,
        height: (y + shelf).max(1),
        origins,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangles_do_not_overlap_and_fit() {
        let sizes: Vec<[u32; 2]> = (0..200u32)
            .map(|i| [1 + (i * 7919) % 17, 1 + (i * 104_729) % 13])
            .collect();
        let l = pack_rectangles(&sizes);
        let mut used = vec![false; (l.width * l.height) as usize];
        for (s, o) in sizes.iter().zip(&l.origins) {
            assert!(o[0] + s[0] <= l.width && o[1] + s[1] <= l.height);
            for y in o[1]..o[1] + s[1] {
                for x in o[0]..o[0] + s[0] {
                    let k = (y * l.width + x) as usize;
                    assert!(!used[k], "overlap at {x},{y}");
                    used[k] = true;
                }
            }
        }
        let area: u32 = sizes.iter().map(|s| s[0] * s[1]).sum();
        assert!(
            l.width * l.height < 2 * area,
            "{}x{} for {area}",
            l.width,
            l.height
        );
    }
}
