//! The barycentric grid of one (triangle, side): how samples are indexed and stored, how
//! a grid is interpolated, which samples a doubling adds, and the samples' random-stream
//! keys (the module docs of [`super`]).

use glam::{Vec2, Vec3};
use surfcache_core::sampling::splitmix64;

/// Sample keys locate a sample on a grid of this order ([`sample_key`]); grid orders are
/// at most [`MAX_ORDER_LIMIT`].
pub const KEY_RESOLUTION: u32 = 1 << 16;

/// The largest order a grid may have.
pub const MAX_ORDER_LIMIT: u32 = 1 << 15;

/// s(n) = (n+1)(n+2)/2: the number of samples of an order-`n` grid.
#[inline]
pub const fn grid_size(n: u32) -> usize {
    let n = n as usize;
    (n + 1) * (n + 2) / 2
}

/// m(i, j) = (i+j)(i+j+1)/2 + j: where sample (i, j) is stored (docs/design.md, Caches). Samples
/// are stored diagonal by diagonal (`d = i + j`), so the index does not depend on the
/// order and the samples of an order-`n` grid occupy `0..s(n)`.
#[inline]
pub const fn grid_index(i: u32, j: u32) -> usize {
    let (i, j) = (i as usize, j as usize);
    (i + j) * (i + j + 1) / 2 + j
}

/// The index coordinates of the coarse samples at the ends of the coarse edge halved by
/// the new sample `(i, j)` (at least one coordinate odd) of a grid that just doubled:
/// `(i∓1, j)` on rows, `(i, j∓1)` on columns and `(i+1, j−1), (i−1, j+1)` on the
/// diagonals (the hypotenuses of the coarse cells).
#[inline]
pub const fn coarse_neighbours(i: u32, j: u32) -> [[u32; 2]; 2] {
    match (i % 2 == 1, j % 2 == 1) {
        (true, false) => [[i - 1, j], [i + 1, j]],
        (false, true) => [[i, j - 1], [i, j + 1]],
        _ => [[i + 1, j - 1], [i - 1, j + 1]],
    }
}

/// Linear interpolation of an order-`n` grid with samples `grid(i, j)` at barycentrics
/// `uv` (clamped into the triangle): in the cell `(i, j)` holding `(u·n, v·n)` with
/// fractions `(fx, fy)`, the lower triangle (i,j),(i+1,j),(i,j+1) gives
/// `(1−fx−fy)E(i,j) + fx E(i+1,j) + fy E(i,j+1)` for `fx + fy ≤ 1`, the upper one
/// (i+1,j),(i,j+1),(i+1,j+1) gives `(1−fy)E(i+1,j) + (1−fx)E(i,j+1) + (fx+fy−1)E(i+1,j+1)`.
#[inline]
pub fn grid_interpolate(n: u32, uv: Vec2, grid: impl Fn(u32, u32) -> Vec3) -> Vec3 {
    let [(i0, j0, w0), (i1, j1, w1), (i2, j2, w2)] = grid_cell(n, uv);
    grid(i0, j0) * w0 + grid(i1, j1) * w1 + grid(i2, j2) * w2
}

/// The cell of an order-`n` grid holding barycentrics `uv` (clamped into the triangle):
/// its three samples `(i, j)` with their weights in [`grid_interpolate`].
#[inline]
pub(super) fn grid_cell(n: u32, uv: Vec2) -> [(u32, u32, f32); 3] {
    let mut uv = uv.max(Vec2::ZERO);
    let sum = uv.x + uv.y;
    if sum > 1.0 {
        uv /= sum;
    }
    let nf = n as f32;
    let (x, y) = (uv.x * nf, uv.y * nf);
    let i = (x.floor() as u32).min(n - 1);
    let j = (y.floor() as u32).min(n - 1 - i);
    let (fx, fy) = (x - i as f32, y - j as f32);
    if fx + fy <= 1.0 || i + j + 2 > n {
        [(i, j, 1.0 - fx - fy), (i + 1, j, fx), (i, j + 1, fy)]
    } else {
        [
            (i + 1, j, 1.0 - fy),
            (i, j + 1, 1.0 - fx),
            (i + 1, j + 1, fx + fy - 1.0),
        ]
    }
}

/// [`grid_interpolate`] leaving out the samples `keep` rejects (a crossing separates
/// them from the point looked up) and renormalising the others' weights; where every
/// sample with weight is rejected the plain interpolation is returned.
#[inline]
pub fn grid_interpolate_kept(
    n: u32,
    uv: Vec2,
    grid: impl Fn(u32, u32) -> Vec3,
    keep: impl Fn(u32, u32) -> bool,
) -> Vec3 {
    let taps = grid_cell(n, uv);
    let kept = taps.map(|(i, j, w)| w <= 0.0 || keep(i, j));
    if kept.iter().all(|&k| k) {
        return grid_interpolate(n, uv, grid);
    }
    let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
    for (&(i, j, w), _) in taps
        .iter()
        .zip(kept)
        .filter(|&(&(_, _, w), k)| k && w > 0.0)
    {
        sum += grid(i, j) * w;
        weight += w;
    }
    if weight > 0.0 {
        sum / weight
    } else {
        grid_interpolate(n, uv, grid)
    }
}

/// The random-stream key of sample `(i, j)` of the order-`n` grid on one side of the
/// triangle with key `triangle_key`: a hash of the key, the side and the sample's
/// position `(i, j)·KEY_RESOLUTION/n` on the finest grid, so that `(i, j)` of order `n`
/// and `(2i, 2j)` of order `2n` share a key.
#[inline]
pub fn sample_key(triangle_key: u64, front: bool, i: u32, j: u32, n: u32) -> u64 {
    let step = (KEY_RESOLUTION / n) as u64;
    let (x, y) = (i as u64 * step, j as u64 * step);
    let position = ((!front) as u64) << 42 | x << 21 | y;
    splitmix64(triangle_key ^ splitmix64(position ^ 0x1aa4_0000_0000_0000))
}

/// The order of a grid slot's level `log2(order) + 1` (0: not baked).
#[inline]
pub(super) const fn order_of_level(level: u8) -> u32 {
    match level {
        0 => 0,
        l => 1 << (l - 1),
    }
}

/// Which corner (A, B, C = 0, 1, 2) sample `(i, j)` of an order-`n` grid is, if any.
#[inline]
pub(super) const fn corner_of(i: u32, j: u32, n: u32) -> Option<usize> {
    match (i, j) {
        (0, 0) => Some(0),
        (0, _) if j == n => Some(2),
        (_, 0) if i == n => Some(1),
        _ => None,
    }
}

/// Visits the samples of an order-`n` grid that an order-`n/2` grid lacks (all of them
/// when `coarse` is 0: a fresh grid), in storage order: `f(i, j, m)`.
#[inline]
pub(super) fn for_each_new_sample(coarse: u32, n: u32, mut f: impl FnMut(u32, u32, usize)) {
    for d in 0..=n {
        for j in 0..=d {
            let i = d - j;
            if coarse == 0 || i % 2 == 1 || j % 2 == 1 {
                f(i, j, grid_index(i, j));
            }
        }
    }
}
