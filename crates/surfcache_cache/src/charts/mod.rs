//! Lightmap UV generation for meshes without TEXCOORD_1: charts grown over smooth edges,
//! flattened, scaled to a texel density and packed by outline into one texture.
//!
//! 1. **Charts** ([`growing`]): breadth-first over edges between triangles whose normals
//!    are within [`SMOOTH_ANGLE_DEGREES`], each chart kept a topological disc (cut where
//!    growth fronts meet) and unfolded rigidly as it grows; charts smaller than
//!    [`SMALL_TEXELS`] merge across the creases between them.
//! 2. **Flattening** ([`parameterise`]): planar charts are projected onto their plane,
//!    curved ones get a least-squares conformal map; a chart whose texel density varies
//!    by more than [`MAX_STRETCH`], whose triangles overlap in the plane or which comes
//!    back near itself in texel space is bisected until its parts pass.
//! 3. **Texels**: each chart is turned to its minimum-area box, scaled to the density and
//!    snapped to texel centres (module docs of [`generate_atlas`]).
//! 4. **Packing** ([`packing`]): chart footprints dilated by the gutter, packed by their
//!    column outlines on a skyline.

mod growing;
mod packing;
mod parameterise;

pub use growing::SMOOTH_ANGLE_DEGREES;
pub use parameterise::{MAX_STRETCH, TEXEL_REACH, singular_values};

use crate::lightmap::texels_overlapped_by;
use glam::{Vec2, Vec3};
use growing::{ChartMesh, grow};
use packing::{Claim, pack_claims};
use parameterise::{FlatChart, flatten_or_split};
use rayon::prelude::*;
use std::collections::HashMap;
use surfcache_core::index::NO_INDEX;

/// Triangles sharing an edge join a chart when their normals lie within this angle of the
/// chart's seed triangle.
pub const CHART_ANGLE_DEGREES: f32 = 1.0;

/// Corner positions closer than this fraction of the mesh's bounding-box diagonal (in
/// every coordinate) count as the same vertex when finding shared edges.
pub const WELD_TOLERANCE: f32 = 1e-5;

/// Texel coordinates this close to a texel boundary count as on it (float round-off of
/// UV1 stored in UV units and scaled back to texels).
pub const TEXEL_EPSILON: f32 = 1e-3;

/// Groups of edge-connected triangles (coplanar ones from [`coplanar_charts`], the
/// charts of a generated atlas from [`generate_atlas`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Charts {
    /// Chart of each triangle.
    pub chart: Vec<u32>,
    /// Number of charts.
    pub count: u32,
}

/// Splits triangles (world corner positions, unit geometric normals) into charts by
/// region growing over shared edges: a chart starts at the lowest-numbered unassigned
/// triangle and takes every edge neighbour whose normal is within
/// [`CHART_ANGLE_DEGREES`] of the seed's (comparing with the seed rather than the
/// neighbour keeps a finely tessellated curve from drifting into one chart). Two
/// triangles share an edge when two of their corners coincide within
/// [`WELD_TOLERANCE`] of the mesh's diagonal.
pub fn coplanar_charts(positions: &[[Vec3; 3]], normals: &[Vec3]) -> Charts {
    let n = positions.len();
    if n == 0 {
        return Charts::default();
    }
    let weld = weld_corners(positions);
    // Edges as (lower vertex, higher vertex, triangle), sorted: equal edges are adjacent.
    let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * n);
    for (t, w) in weld.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (w[k], w[(k + 1) % 3]);
            if a != b {
                edges.push((a.min(b), a.max(b), t as u32));
            }
        }
    }
    edges.sort_unstable();
    // Adjacency in compressed rows: every pair of triangles on one edge.
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let mut start = 0;
    while start < edges.len() {
        let mut end = start + 1;
        while end < edges.len() && edges[end].0 == edges[start].0 && edges[end].1 == edges[start].1
        {
            end += 1;
        }
        for i in start..end {
            for j in start..end {
                if edges[i].2 != edges[j].2 {
                    pairs.push((edges[i].2, edges[j].2));
                }
            }
        }
        start = end;
    }
    pairs.sort_unstable();
    pairs.dedup();
    let mut row = vec![0u32; n + 1];
    for &(a, _) in &pairs {
        row[a as usize + 1] += 1;
    }
    for i in 0..n {
        row[i + 1] += row[i];
    }
    let cos_limit = CHART_ANGLE_DEGREES.to_radians().cos();
    let mut chart = vec![NO_INDEX; n];
    let mut count = 0u32;
    let mut queue: Vec<u32> = Vec::new();
    for seed in 0..n {
        if chart[seed] != NO_INDEX {
            continue;
        }
        let normal = normals[seed];
        chart[seed] = count;
        queue.clear();
        queue.push(seed as u32);
        while let Some(t) = queue.pop() {
            let t = t as usize;
            for &(_, nb) in &pairs[row[t] as usize..row[t + 1] as usize] {
                let nb = nb as usize;
                if chart[nb] == NO_INDEX && normals[nb].dot(normal) >= cos_limit {
                    chart[nb] = count;
                    queue.push(nb as u32);
                }
            }
        }
        count += 1;
    }
    Charts { chart, count }
}

/// Welded vertex ids of every corner: a hash grid of cell size τ (the tolerance), where
/// a corner takes the id of a representative within τ in every coordinate found in the
/// 27 surrounding cells, or becomes one itself (at most one per cell, since two points of
/// a cell are within τ). Deterministic: corners are visited in order.
fn weld_corners(positions: &[[Vec3; 3]]) -> Vec<[u32; 3]> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in positions.iter().flatten() {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let tol = ((hi - lo).length() * WELD_TOLERANCE).max(f32::MIN_POSITIVE);
    let cell = |p: Vec3| ((p - lo) / tol).floor().as_i64vec3().to_array();
    let mut grid: HashMap<[i64; 3], u32> = HashMap::with_capacity(positions.len());
    let mut reps: Vec<Vec3> = Vec::new();
    positions
        .iter()
        .map(|tri| {
            tri.map(|p| {
                let c = cell(p);
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            if let Some(&id) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz])
                                && (reps[id as usize] - p).abs().max_element() <= tol
                            {
                                return id;
                            }
                        }
                    }
                }
                let id = reps.len() as u32;
                reps.push(p);
                grid.insert(c, id);
                id
            })
        })
        .collect()
}

/// A generated lightmap layout of one mesh instance.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChartAtlas {
    /// Texture size in texels (multiples of 4).
    pub width: u32,
    pub height: u32,
    /// UV1 of every triangle corner (in input order), UV units: texel (x, y) covers
    /// [x/W, (x+1)/W] × [y/H, (y+1)/H].
    pub uv1: Vec<[Vec2; 3]>,
    /// The charts the layout is made of.
    pub charts: Charts,
    /// Texels each chart's triangles may cover: x, y, width, height (the box of the
    /// chart's footprint; other charts' texels keep 2 · gutter texels away from the
    /// footprint, not necessarily from the box).
    pub chart_texels: Vec<[u32; 4]>,
    /// The density asked of every chart (texels per metre), lower than the caller's when
    /// the atlas had to shrink to fit; each chart is stretched by less than a texel more.
    pub texels_per_metre: f32,
}

/// Texel coordinates this far outside a triangle still count as covered when reserving
/// its chart's footprint, so that the rasteriser's footprint (computed again from the
/// stored UV1, with rounding) stays inside the reservation.
const RESERVE_EPSILON: f32 = -2e-3;

/// Layouts tried at most while shrinking an atlas to the maximum size.
const MAX_LAYOUTS: usize = 12;

/// Generates UV1 for triangles without one (module docs): charts grown over smooth
/// edges and flattened ([`parameterise`]), each turned to its minimum-area bounding
/// rectangle (Freeman & Shapira 1975: one side lies on a convex-hull edge), laid
/// landscape, scaled by `texels_per_metre`, given `gutter` texels of its own on every
/// side and packed by outline ([`packing`]). If the atlas is wider or taller than
/// `max_size`, the density is lowered uniformly and the layout redone (the smallest
/// layout found is kept if none fits). Zero-area triangles carry no texels: their
/// corners collapse onto a point of a chart sharing one of their vertices.
///
/// Chart boxes are snapped to texel centres: a chart spanning `e · density ≥ 1` texels is
/// stretched to the next whole number `n` (at most one texel more) and placed from one
/// texel centre to another, over `n + 1` texels. Its border texels are then estimated on
/// the border itself and bilinear filtering interpolates linearly right up to it,
/// instead of holding the last texel's value over the outer half texel (which loses the
/// darkening into concave corners); filtering inside the box never reads a gutter texel.
/// A chart narrower than a texel is centred on one texel.
pub fn generate_atlas(
    positions: &[[Vec3; 3]],
    normals: &[Vec3],
    texels_per_metre: f32,
    gutter: u32,
    max_size: u32,
) -> ChartAtlas {
    let n = positions.len();
    let weld = weld_corners(positions);
    let degenerate: Vec<bool> = positions
        .iter()
        .zip(&weld)
        .map(|([a, b, c], w)| {
            w[0] == w[1]
                || w[1] == w[2]
                || w[2] == w[0]
                || (*b - *a).cross(*c - *a).length().is_nan()
                || (*b - *a).cross(*c - *a).length() <= 0.0
        })
        .collect();
    let mesh = ChartMesh::new(positions, normals, &weld, &degenerate);
    let mut chart = vec![NO_INDEX; n];
    let mut slot = vec![0u32; n];
    let mut parts: Vec<Vec<u32>> = Vec::new();
    for t in 0..n {
        if !degenerate[t] && chart[t] == NO_INDEX {
            let id = parts.len() as u32;
            parts.push(grow(&mesh, t as u32, id, &mut chart, &mut slot, |_| true).tris);
        }
    }
    let mut density = texels_per_metre.max(f32::MIN_POSITIVE);
    let mut best: Option<ChartAtlas> = None;
    for _ in 0..MAX_LAYOUTS {
        let merged = merge_small_parts(&mesh, &parts, &chart, density);
        let atlas = lay_out(&mesh, &merged, &weld, &degenerate, density, gutter);
        let size = atlas.width.max(atlas.height);
        if best.as_ref().is_some_and(|b| b.width.max(b.height) <= size) {
            break;
        }
        best = Some(atlas);
        if size <= max_size {
            break;
        }
        density *= (max_size as f32 / size as f32).min(0.98);
    }
    best.expect("at least one layout")
}

/// One flattened chart in texel units, as laid out and turned by 90°: corners relative
/// to the top-left of the footprint's box, the box size and the claim.
struct ChartTexels {
    corners: [Vec<[Vec2; 3]>; 2],
    size: [[u32; 2]; 2],
    claim: [Claim; 2],
}

/// Charts whose bounding box has a diagonal of at most this many texels merge with
/// their neighbours across creases while the union stays that small: a small block's
/// sides, a moulding's faces or a leaf's two halves are smaller than the texels that
/// light them, so a crease between them cannot be resolved, and apart each would pay
/// its own border texels and gutters.
pub const SMALL_TEXELS: f32 = 2.0;

/// Grown `parts` (`part[t]`: part of triangle t) merged across creases while their
/// union's bounding box stays within [`SMALL_TEXELS`] at `density`, greedily over the
/// creases in triangle order; each group comes with whether it merged parts (its
/// creases are then glued).
fn merge_small_parts(
    mesh: &ChartMesh,
    parts: &[Vec<u32>],
    part: &[u32],
    density: f32,
) -> Vec<(Vec<u32>, bool)> {
    // Per part: bounding box (kept at the root of its group).
    let mut bounds: Vec<(Vec3, Vec3)> = parts
        .iter()
        .map(|tris| {
            tris.iter()
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &t| {
                    let [a, b, c] = mesh.positions[t as usize];
                    (lo.min(a.min(b).min(c)), hi.max(a.max(b).max(c)))
                })
        })
        .collect();
    let mut root: Vec<u32> = (0..parts.len() as u32).collect();
    fn find(root: &mut [u32], mut p: u32) -> u32 {
        while root[p as usize] != p {
            root[p as usize] = root[root[p as usize] as usize];
            p = root[p as usize];
        }
        p
    }
    let limit = SMALL_TEXELS / density;
    for t in 0..mesh.len() {
        for &(u, _) in &mesh.creases[t] {
            if u == NO_INDEX
                || (u as usize) < t
                || part[t] == NO_INDEX
                || part[u as usize] == NO_INDEX
            {
                continue;
            }
            let (a, b) = (find(&mut root, part[t]), find(&mut root, part[u as usize]));
            if a == b {
                continue;
            }
            let (ba, bb) = (bounds[a as usize], bounds[b as usize]);
            let (lo, hi) = (ba.0.min(bb.0), ba.1.max(bb.1));
            if (hi - lo).length() <= limit {
                let (keep, gone) = (a.min(b), a.max(b));
                root[gone as usize] = keep;
                bounds[keep as usize] = (lo, hi);
            }
        }
    }
    let mut groups: Vec<Vec<u32>> = vec![Vec::new(); parts.len()];
    for p in 0..parts.len() as u32 {
        let r = find(&mut root, p);
        groups[r as usize].push(p);
    }
    groups
        .into_iter()
        .filter(|g| !g.is_empty())
        .map(|g| {
            let merged = g.len() > 1;
            (
                g.iter()
                    .flat_map(|&p| parts[p as usize].iter().copied())
                    .collect(),
                merged,
            )
        })
        .collect()
}

/// The layout of the grown `parts` (with whether their creases are glued) at `density`
/// (one attempt of [`generate_atlas`]).
fn lay_out(
    mesh: &ChartMesh,
    parts: &[(Vec<u32>, bool)],
    weld: &[[u32; 3]],
    degenerate: &[bool],
    density: f32,
    gutter: u32,
) -> ChartAtlas {
    let n = mesh.len();
    let flat: Vec<FlatChart> = parts
        .par_iter()
        .map(|(part, glue)| {
            let mut out = Vec::new();
            flatten_or_split(&mesh.subset(part, *glue), density, &mut out);
            out
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    let texels: Vec<ChartTexels> = flat
        .par_iter()
        .map(|f| chart_texels(&f.uv, density, gutter))
        .collect();
    // The texture: as wide as a square holding every claim, at least as wide as every
    // chart's narrow side.
    let area: u64 = texels.iter().map(|c| c.claim[0].area()).sum();
    let narrow = texels
        .iter()
        .map(|c| c.claim[0].width.min(c.claim[1].width))
        .max()
        .unwrap_or(1);
    let width = ((area as f64).sqrt().ceil() as u32)
        .max(narrow)
        .max(1)
        .div_ceil(4)
        * 4;
    let claims: Vec<[Claim; 2]> = texels.iter().map(|c| c.claim.clone()).collect();
    let (placements, rows) = pack_claims(&claims, width);
    let height = (rows.div_ceil(4) * 4).max(4);
    let size = Vec2::new(width as f32, height as f32);
    let mut uv1 = vec![[Vec2::ZERO; 3]; n];
    let mut chart = vec![NO_INDEX; n];
    let mut boxes = Vec::with_capacity(flat.len());
    for (c, ((f, t), p)) in flat.iter().zip(&texels).zip(&placements).enumerate() {
        let turn = usize::from(p.turned);
        let origin = Vec2::new((p.x + gutter) as f32, (p.y + gutter) as f32);
        for (&tri, q) in f.triangles.iter().zip(&t.corners[turn]) {
            uv1[tri as usize] = q.map(|q| (q + origin) / size);
            chart[tri as usize] = c as u32;
        }
        let [w, h] = t.size[turn];
        boxes.push([p.x + gutter, p.y + gutter, w, h]);
    }
    if boxes.is_empty() {
        boxes.push([0, 0, 1, 1]);
    }
    // Zero-area triangles: onto a chart corner at one of their welded vertices.
    let mut host: HashMap<u32, (Vec2, u32)> = HashMap::new();
    for t in 0..n {
        if !degenerate[t] {
            for k in 0..3 {
                host.entry(weld[t][k]).or_insert((uv1[t][k], chart[t]));
            }
        }
    }
    let fallback = (Vec2::splat(0.5) / size, 0);
    for t in (0..n).filter(|&t| degenerate[t]) {
        let (uv, c) = weld[t]
            .iter()
            .find_map(|w| host.get(w).copied())
            .unwrap_or(fallback);
        uv1[t] = [uv; 3];
        chart[t] = c;
    }
    ChartAtlas {
        width,
        height,
        uv1,
        charts: Charts {
            chart,
            count: boxes.len() as u32,
        },
        chart_texels: boxes,
        texels_per_metre: density,
    }
}

/// A flattened chart (corners in metres) in texels (module docs of [`generate_atlas`]):
/// turned to its minimum-area box, landscape, scaled and snapped, then turned by 90° for
/// the packer's second choice; with the footprint each way dilated by `gutter`.
fn chart_texels(uv: &[[Vec2; 3]], density: f32, gutter: u32) -> ChartTexels {
    let mut points: Vec<Vec2> = uv.iter().flatten().copied().collect();
    let hull = convex_hull(&mut points);
    let (axis, _) = min_area_rectangle(&hull);
    let perp = axis.perp();
    let rotate = |p: Vec2| Vec2::new(p.dot(axis), p.dot(perp));
    let bounds = |f: &dyn Fn(Vec2) -> Vec2| {
        hull.iter()
            .fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(l, h), &p| {
                (l.min(f(p)), h.max(f(p)))
            })
    };
    let (lo, hi) = bounds(&rotate);
    // Portrait boxes turn by 90° (a rotation, keeping the corners' winding).
    let upright = |p: Vec2| {
        let q = rotate(p);
        if hi.x - lo.x >= hi.y - lo.y {
            q
        } else {
            Vec2::new(q.y, -q.x)
        }
    };
    let (lo, hi) = bounds(&upright);
    let extent = hi - lo;
    // Per axis: texel coordinate of lo, texels per metre, footprint texels.
    let axis_map = |e: f32| {
        let span = e * density;
        if span < 1.0 {
            (0.5 - 0.5 * span, density, 1u32)
        } else {
            let whole = (span - TEXEL_EPSILON).ceil().max(1.0);
            (0.5, whole / e, whole as u32 + 1)
        }
    };
    let (mx, my) = (axis_map(extent.x), axis_map(extent.y));
    let laid: Vec<[Vec2; 3]> = uv
        .iter()
        .map(|q| {
            q.map(|p| {
                let d = upright(p) - lo;
                Vec2::new(mx.0 + d.x * mx.1, my.0 + d.y * my.1)
            })
        })
        .collect();
    let size = [mx.2, my.2];
    let turned: Vec<[Vec2; 3]> = laid
        .iter()
        .map(|q| q.map(|p| Vec2::new(p.y, size[0] as f32 - p.x)))
        .collect();
    let claim = |corners: &[[Vec2; 3]], [w, h]: [u32; 2]| {
        let mut footprint = vec![false; (w * h) as usize];
        for &q in corners {
            texels_overlapped_by(q, [0, 0, w, h], RESERVE_EPSILON, |x, y| {
                footprint[(y * w + x) as usize] = true;
            });
        }
        Claim::of_footprint(&footprint, w, h, gutter)
    };
    let turned_size = [size[1], size[0]];
    ChartTexels {
        claim: [claim(&laid, size), claim(&turned, turned_size)],
        corners: [laid, turned],
        size: [size, turned_size],
    }
}

/// Convex hull, counter-clockwise, by Andrew's monotone chain (sorts `points`).
fn convex_hull(points: &mut [Vec2]) -> Vec<Vec2> {
    points.sort_unstable_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    if points.len() < 3 {
        return points.to_vec();
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(points.len() + 1);
    for pass in 0..2 {
        let floor = hull.len();
        let push = |p: Vec2, hull: &mut Vec<Vec2>| {
            while hull.len() >= floor + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        };
        if pass == 0 {
            points.iter().for_each(|&p| push(p, &mut hull));
        } else {
            points.iter().rev().for_each(|&p| push(p, &mut hull));
        }
        hull.pop(); // the last point starts the other chain
    }
    hull
}

/// The direction of the minimum-area bounding rectangle of a convex polygon, and its
/// area: one of its sides lies on a hull edge (Freeman & Shapira 1975), so every hull
/// edge is tried (at most 256 evenly spread ones on large hulls, an approximation).
fn min_area_rectangle(hull: &[Vec2]) -> (Vec2, f32) {
    let mut best = (Vec2::X, f32::INFINITY);
    let stride = hull.len().div_ceil(256).max(1);
    for i in (0..hull.len()).step_by(stride) {
        let Some(axis) = (hull[(i + 1) % hull.len()] - hull[i]).try_normalize() else {
            continue;
        };
        let perp = axis.perp();
        let mut lo = Vec2::splat(f32::INFINITY);
        let mut hi = Vec2::splat(f32::NEG_INFINITY);
        for p in hull {
            let q = Vec2::new(p.dot(axis), p.dot(perp));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        let area = (hi - lo).x * (hi - lo).y;
        if area < best.1 {
            best = (axis, area);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_rectangle_of_a_rotated_box() {
        let angle = 0.3f32;
        let (s, c) = angle.sin_cos();
        let rot = |p: Vec2| Vec2::new(c * p.x - s * p.y, s * p.x + c * p.y);
        let mut pts: Vec<Vec2> = [
            Vec2::new(0.0, 0.0),
            Vec2::new(2.0, 0.0),
            Vec2::new(2.0, 1.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 0.5),
            Vec2::new(0.5, 0.0),
        ]
        .into_iter()
        .map(rot)
        .collect();
        let hull = convex_hull(&mut pts);
        assert_eq!(hull.len(), 4, "{hull:?}");
        let (_, area) = min_area_rectangle(&hull);
        assert!((area - 2.0).abs() < 1e-5, "{area}");
    }

    #[test]
    fn welded_quads_share_edges() {
        // Two quads meeting at x = 1 (vertices not shared, positions equal) and one
        // folded up by 90 degrees: two charts.
        let v = Vec3::new;
        let tris = [
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., -1.)],
            [v(0., 0., 0.), v(1., 0., -1.), v(0., 0., -1.)],
            [v(1., 0., 0.), v(2., 0., 0.), v(2., 0., -1.)],
            [v(1., 0., 0.), v(2., 0., -1.), v(1., 0., -1.)],
            [v(2., 0., 0.), v(2., 1., 0.), v(2., 0., -1.)],
        ];
        let normals: Vec<Vec3> = tris
            .iter()
            .map(|[a, b, c]| (*b - *a).cross(*c - *a).normalize())
            .collect();
        let charts = coplanar_charts(&tris, &normals);
        assert_eq!(charts.count, 2);
        assert_eq!(charts.chart, vec![0, 0, 0, 0, 1]);
    }
}
