//! Mesh-colour textures: per-triangle barycentric grids laid out as texel blocks so that
//! bilinear filtering reproduces their linear interpolation (docs/design.md, Publishing; Yuksel et al.,
//! "Mesh Colors", 2010, and its texture-mapped variant). Shared by the irradiance maps
//! (order-n grids) and vertex lighting (order-1 grids).
//!
//! **Block layout.** A grid of order `n` (samples E(i, j), `i + j ≤ n`, at barycentrics
//! `(i/n, j/n)`) becomes a block of `(n+1) × (n+1)` texels at texel origin `(x0, y0)`:
//! texel `(x0+i, y0+j)` holds E(i, j). Texels with `i + j = n + 1` (just past the
//! hypotenuse) hold the parallelogram extrapolation E(i, j−1) + E(i−1, j) − E(i−1, j−1)
//! ([`block_texel`]); texels farther out repeat that diagonal (they are never read).
//! The corners A, B, C get UV1 at the texel centres of E(0,0), E(n,0), E(0,n)
//! ([`corner_uv1`]), so the point at barycentrics `(u, v)` maps to texel coordinates
//! `(x0 + ½ + u·n, y0 + ½ + v·n)`.
//!
//! **What bilinear filtering gives.** At a point of grid cell `(i, j)` with fractions
//! `(fx, fy)`, bilinear filtering of the four texels differs from the two-triangle linear
//! interpolation of the grid (lower triangle (i,j),(i+1,j),(i,j+1) for `fx + fy ≤ 1`,
//! upper (i+1,j),(i,j+1),(i+1,j+1) otherwise) by
//! `fx·fy·(E00 + E11 − E10 − E01)` in the lower and `(1−fx)(1−fy)·(E00 + E11 − E10 − E01)`
//! in the upper triangle, so
//! - it is exact at texel centres (grid samples) and along the cell edges through them;
//! - it is exact on every cell along the hypotenuse (`i + j = n − 1`), because the
//!   extrapolated texel makes `E00 + E11 − E10 − E01 = 0` there; for order 1 (vertex
//!   lighting) that is the whole triangle;
//! - inside full cells it is off by at most `|E00 + E11 − E10 − E01| / 4` (at the cell
//!   centre), which vanishes wherever E is locally linear.
//!
//! (Exact in real arithmetic; f32 UVs put a point within ~1e-6 texel of where it belongs,
//! and GPUs quantise bilinear weights, typically to 1/256.)
//!
//! A point inside its triangle only ever reads texels of its own block (the bilinear
//! footprint of `[x0+½, x0+n+½]` is `[x0, x0+n]`), so blocks need no gutters when the
//! texture is sampled without mipmaps. The generated UV1 layout needs one vertex per
//! triangle corner ([`IrradianceTexture::uses_mesh_uv1`] is false).

use crate::{IrradianceTexture, atlas::pack_rectangles};
use glam::{Vec2, Vec3};
use surfcache_trace::TracedScene;

/// Side length in texels of the block of an order-`n` grid: `n + 1`.
#[inline]
pub const fn block_side(n: u32) -> u32 {
    n + 1
}

/// Texel `(i, j)` (`0 ≤ i, j ≤ n`) of the block of an order-`n` grid whose samples are
/// `grid(i, j)`: E(i, j) for `i + j ≤ n`; the parallelogram rule
/// E(i, j−1) + E(i−1, j) − E(i−1, j−1) for `i + j = n + 1`; beyond that a copy of texel
/// `(i, n + 1 − i)` (module docs).
#[inline]
pub fn block_texel(n: u32, i: u32, j: u32, grid: &impl Fn(u32, u32) -> Vec3) -> Vec3 {
    let d = i + j;
    if d <= n {
        grid(i, j)
    } else {
        // i, j ≥ 1 on the diagonal n + 1; farther out clamp j back onto it.
        let j = j.min(n + 1 - i);
        grid(i, j - 1) + grid(i - 1, j) - grid(i - 1, j - 1)
    }
}

/// UV1 of corners A, B, C of a triangle whose order-`n` block has its top-left texel at
/// `origin` in a `size[0] × size[1]` texture: the texel centres (x0+½, y0+½),
/// (x0+n+½, y0+½), (x0+½, y0+n+½) divided by the texture size (module docs).
#[inline]
pub fn corner_uv1(n: u32, origin: [u32; 2], size: [u32; 2]) -> [Vec2; 3] {
    let inv = Vec2::new(1.0 / size[0] as f32, 1.0 / size[1] as f32);
    let a = Vec2::new(origin[0] as f32 + 0.5, origin[1] as f32 + 0.5);
    let n = n as f32;
    [
        a * inv,
        (a + Vec2::new(n, 0.0)) * inv,
        (a + Vec2::new(0.0, n)) * inv,
    ]
}

/// The UV1 corners of a traced triangle, reordered into its mesh corner order: a mirrored
/// instance's traced triangles have corners B and C swapped relative to the mesh.
#[inline]
pub fn mesh_corner_order(uv: [Vec2; 3], mirrored: bool) -> [Vec2; 3] {
    if mirrored { [uv[0], uv[2], uv[1]] } else { uv }
}

/// Number of triangles of instance `instance`'s mesh as far as the traced scene knows it:
/// one more than the largest mesh index among its traced triangles (triangles the tracer
/// dropped as degenerate at the very end of a mesh are not seen).
pub fn mesh_triangle_count(scene: &TracedScene, instance: u32) -> usize {
    let range = scene.instance_triangles()[instance as usize].clone();
    scene.local_triangle()[range.start as usize..range.end as usize]
        .iter()
        .map(|&l| l as usize + 1)
        .max()
        .unwrap_or(0)
}

/// The mesh-colour texture of one side of one instance: every traced triangle `t` of the
/// instance contributes the block of its grid of order `order(t) ≥ 1` with samples
/// `value(t, i, j)`; blocks are packed with [`pack_rectangles`] in triangle order.
/// `uv1` is in mesh triangle and corner order; `uv_rect` is the whole image.
pub fn instance_texture(
    scene: &TracedScene,
    instance: u32,
    front: bool,
    order: impl Fn(u32) -> u32,
    value: impl Fn(u32, u32, u32) -> Vec3,
) -> IrradianceTexture {
    let range = scene.instance_triangles()[instance as usize].clone();
    let orders: Vec<u32> = range.clone().map(|t| order(t).max(1)).collect();
    let sizes: Vec<[u32; 2]> = orders
        .iter()
        .map(|&n| [block_side(n), block_side(n)])
        .collect();
    let layout = pack_rectangles(&sizes);
    let (width, height) = (layout.width, layout.height);
    let mut texels = vec![Vec3::ZERO; width as usize * height as usize];
    let mut uv1 = vec![[Vec2::ZERO; 3]; mesh_triangle_count(scene, instance)];
    let mirrored = scene.mirrored()[instance as usize];
    for (k, t) in range.enumerate() {
        let n = orders[k];
        let [x0, y0] = layout.origins[k];
        let grid = |i: u32, j: u32| value(t, i, j);
        for j in 0..block_side(n) {
            let row = (y0 + j) as usize * width as usize;
            for i in 0..block_side(n) {
                texels[row + (x0 + i) as usize] = block_texel(n, i, j, &grid);
            }
        }
        let corners = corner_uv1(n, [x0, y0], [width, height]);
        uv1[scene.local_triangle()[t as usize] as usize] = mesh_corner_order(corners, mirrored);
    }
    IrradianceTexture {
        instance,
        name: scene.instance_names()[instance as usize].clone(),
        front,
        width,
        height,
        texels,
        uv1,
        uses_mesh_uv1: false,
        uv_rect: [0.0, 0.0, 1.0, 1.0],
    }
}

/// Mesh-colour textures of every instance of `scene`: the front side of each, and the back
/// side of instances whose material is double-sided (the [`crate::SurfaceCache::publish`]
/// rule). `order(t, front)` and `value(t, front, i, j)` describe the grids; an index into
/// the grid is [`crate::irradiance_map::grid_index`]`(i, j)`.
pub fn publish_all(
    scene: &TracedScene,
    order: impl Fn(u32, bool) -> u32,
    value: impl Fn(u32, bool, u32, u32) -> Vec3,
) -> Vec<IrradianceTexture> {
    let mut out = Vec::new();
    for instance in 0..scene.instance_triangles().len() as u32 {
        let range = scene.instance_triangles()[instance as usize].clone();
        let double_sided = !range.is_empty() && scene.material_of(range.start).double_sided;
        for front in [true, false] {
            if front || double_sided {
                out.push(instance_texture(
                    scene,
                    instance,
                    front,
                    |t| order(t, front),
                    |t, i, j| value(t, front, i, j),
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{irradiance_map::grid_index, texture::bilinear};

    /// A block of a random order-n grid, sampled bilinearly, against the two-triangle
    /// interpolation: exact at samples and on hypotenuse cells, within the bound inside.
    #[test]
    fn bilinear_reproduces_grid_interpolation_within_bound() {
        let mut x = 0x9e37_79b9u32;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 8) as f32 / 16_777_216.0
        };
        for n in [1u32, 2, 4, 8] {
            let values: Vec<Vec3> = (0..crate::irradiance_map::grid_size(n))
                .map(|_| Vec3::new(rnd(), rnd(), rnd()) * 10.0)
                .collect();
            let grid = |i: u32, j: u32| values[grid_index(i, j)];
            let side = block_side(n);
            // One block at origin (1, 2) in a slightly larger texture.
            let (w, h) = (side + 3, side + 4);
            // Other blocks' texels around it (UV rounding may give them ~1e-6 weight).
            let mut texels = vec![Vec3::splat(5.0); (w * h) as usize];
            for j in 0..side {
                for i in 0..side {
                    texels[((2 + j) * w + 1 + i) as usize] = block_texel(n, i, j, &grid);
                }
            }
            let [a, b, c] = corner_uv1(n, [1, 2], [w, h]);
            for _ in 0..2000 {
                let (mut u, mut v) = (rnd(), rnd());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let uv = Vec2::new(u, v);
                let tex = bilinear(&texels, w, h, a * (1.0 - u - v) + b * u + c * v);
                let lin = crate::irradiance_map::grid_interpolate(n, uv, grid);
                let (cx, cy) = (u * n as f32, v * n as f32);
                let (i, j) = ((cx.floor() as u32).min(n - 1), 0);
                let j = (cy.floor() as u32).min(n - 1 - i).max(j);
                let bound = if i + j + 1 >= n {
                    2e-4
                } else {
                    let d = grid(i, j) + grid(i + 1, j + 1) - grid(i + 1, j) - grid(i, j + 1);
                    d.abs().max_element() / 4.0 + 2e-4
                };
                let err = (tex - lin).abs().max_element();
                assert!(
                    err <= bound,
                    "n={n} uv={uv}: {tex} vs {lin} (bound {bound})"
                );
            }
            // Texel centres: exact.
            for d in 0..=n {
                for j in 0..=d {
                    let i = d - j;
                    let uv = Vec2::new(i as f32, j as f32) / n as f32;
                    let at = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
                    let tex = bilinear(&texels, w, h, at);
                    let g = grid(i, j);
                    assert!(
                        (tex - g).abs().max_element() < 2e-4,
                        "n={n} ({i},{j}): {tex} vs {g}"
                    );
                }
            }
        }
    }
}
