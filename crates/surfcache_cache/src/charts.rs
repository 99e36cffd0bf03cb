//! Lightmap UV generation for meshes without TEXCOORD_1: coplanar charts, each flattened
//! onto its plane in world units, turned to its tightest bounding box, scaled to a texel
//! density, padded by a gutter and packed into one texture (DESIGN.md §3.3, §4).
//!
//! Charts are *planar* (all normals within [`CHART_ANGLE_DEGREES`] of the chart's seed),
//! so flattening is an isometry up to cos 1° and a chart never folds over itself unless
//! the surface itself overlaps in projection (a helical ramp flatter than 1°).

use crate::atlas::pack_rectangles;
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use surfcache_core::geometry::orthonormal_basis;

/// Triangles sharing an edge join a chart when their normals lie within this angle of the
/// chart's seed triangle.
pub const CHART_ANGLE_DEGREES: f32 = 1.0;

/// Corner positions closer than this fraction of the mesh's bounding-box diagonal (in
/// every coordinate) count as the same vertex when finding shared edges.
pub const WELD_TOLERANCE: f32 = 1e-5;

/// Texel coordinates this close to a texel boundary count as on it (float round-off of
/// UV1 stored in UV units and scaled back to texels).
pub const TEXEL_EPSILON: f32 = 1e-3;

/// Groups of edge-connected, coplanar triangles.
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
    let mut chart = vec![u32::MAX; n];
    let mut count = 0u32;
    let mut queue: Vec<u32> = Vec::new();
    for seed in 0..n {
        if chart[seed] != u32::MAX {
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
                if chart[nb] == u32::MAX && normals[nb].dot(normal) >= cos_limit {
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
    /// Texels each chart's triangles may cover: x, y, width, height (the chart's packed
    /// rectangle without its gutter).
    pub chart_texels: Vec<[u32; 4]>,
    /// The density asked of every chart (texels per metre), lower than the caller's when
    /// the atlas had to shrink to fit; each chart is stretched by less than a texel more.
    pub texels_per_metre: f32,
}

/// One chart flattened in metres: corners in a frame where its tightest bounding box is
/// [0, extent].
struct FlatChart {
    extent: Vec2,
}

/// Generates UV1 for triangles without one: [`coplanar_charts`], each chart projected to
/// its plane (mean normal, basis of Duff et al. 2017), turned to its minimum-area
/// bounding rectangle (Freeman & Shapira 1975: one side lies on a convex-hull edge),
/// laid landscape, scaled by `texels_per_metre`, padded by `gutter` texels on every side
/// and packed with [`pack_rectangles`]. If the atlas is wider or taller than `max_size`,
/// the density is lowered uniformly and the layout redone (a layout whose charts are all
/// minimal is kept even if too big).
///
/// Chart boxes are snapped to texel centres: a chart spanning `e · density` texels is
/// stretched to the next whole number `n ≥ 1` (at most one texel more) and placed from
/// one texel centre to another, over `n + 1` texels. Its border texels are then
/// estimated on the border itself and bilinear filtering interpolates linearly right up
/// to it, instead of holding the last texel's value over the outer half texel (which
/// loses the darkening into concave corners); filtering inside the box never reads a
/// gutter texel.
pub fn generate_atlas(
    positions: &[[Vec3; 3]],
    normals: &[Vec3],
    texels_per_metre: f32,
    gutter: u32,
    max_size: u32,
) -> ChartAtlas {
    let charts = coplanar_charts(positions, normals);
    let n_charts = charts.count as usize;
    // Triangles of each chart, in order.
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); n_charts];
    for (t, &c) in charts.chart.iter().enumerate() {
        members[c as usize].push(t as u32);
    }
    let mut local = vec![[Vec2::ZERO; 3]; positions.len()];
    let flat: Vec<FlatChart> = members
        .iter()
        .map(|tris| flatten_chart(positions, normals, tris, &mut local))
        .collect();
    let mut density = texels_per_metre.max(f32::MIN_POSITIVE);
    // Whole texel spans of a chart's box (the chart covers one texel more).
    let spans = |extent: Vec2, density: f32| {
        let s = extent * density - TEXEL_EPSILON;
        [s.x.ceil().max(1.0) as u32, s.y.ceil().max(1.0) as u32]
    };
    let (layout, sizes) = loop {
        let sizes: Vec<[u32; 2]> = flat
            .iter()
            .map(|f| spans(f.extent, density).map(|s| s + 1 + 2 * gutter))
            .collect();
        let layout = pack_rectangles(&sizes);
        let size = layout.width.max(layout.height.div_ceil(4) * 4);
        let minimal = flat.iter().all(|f| spans(f.extent, density) == [1, 1]);
        if size <= max_size || minimal {
            break (layout, sizes);
        }
        density *= (max_size as f32 / size as f32).min(0.98);
    };
    let width = layout.width.max(4);
    let height = (layout.height.div_ceil(4) * 4).max(4);
    let scale = Vec2::new(width as f32, height as f32).recip();
    let mut uv1 = vec![[Vec2::ZERO; 3]; positions.len()];
    let mut chart_texels = Vec::with_capacity(n_charts);
    for (c, tris) in members.iter().enumerate() {
        let [ox, oy] = layout.origins[c];
        // The box's corner on the centre of the first texel inside the gutter.
        let corner = Vec2::new((ox + gutter) as f32, (oy + gutter) as f32) + 0.5;
        let extent = flat[c].extent;
        let n = spans(extent, density);
        let stretch = Vec2::new(
            if extent.x > 0.0 {
                n[0] as f32 / extent.x
            } else {
                density
            },
            if extent.y > 0.0 {
                n[1] as f32 / extent.y
            } else {
                density
            },
        );
        for &t in tris {
            uv1[t as usize] = local[t as usize].map(|p| (corner + p * stretch) * scale);
        }
        let [w, h] = sizes[c];
        chart_texels.push([ox + gutter, oy + gutter, w - 2 * gutter, h - 2 * gutter]);
    }
    ChartAtlas {
        width,
        height,
        uv1,
        charts,
        chart_texels,
        texels_per_metre: density,
    }
}

/// Projects a chart's triangles onto the plane of its area-weighted mean normal and
/// rotates them into their minimum-area bounding rectangle (landscape), writing the
/// corners in metres to `local`.
fn flatten_chart(
    positions: &[[Vec3; 3]],
    normals: &[Vec3],
    tris: &[u32],
    local: &mut [[Vec2; 3]],
) -> FlatChart {
    let mut normal = Vec3::ZERO;
    for &t in tris {
        let [a, b, c] = positions[t as usize];
        normal += (b - a).cross(c - a).length() * normals[t as usize];
    }
    let normal = normal.normalize_or(normals[tris[0] as usize]);
    let (tu, tv) = orthonormal_basis(normal);
    let origin = positions[tris[0] as usize][0];
    let mut points: Vec<Vec2> = Vec::with_capacity(3 * tris.len());
    for &t in tris {
        let p =
            positions[t as usize].map(|p| Vec2::new((p - origin).dot(tu), (p - origin).dot(tv)));
        local[t as usize] = p;
        points.extend_from_slice(&p);
    }
    let hull = convex_hull(&mut points);
    let (axis, _) = min_area_rectangle(&hull);
    let perp = axis.perp();
    let mut lo = Vec2::splat(f32::INFINITY);
    let mut hi = Vec2::splat(f32::NEG_INFINITY);
    for p in &hull {
        let q = Vec2::new(p.dot(axis), p.dot(perp));
        lo = lo.min(q);
        hi = hi.max(q);
    }
    let extent = hi - lo;
    let landscape = extent.x >= extent.y;
    for &t in tris {
        local[t as usize] = local[t as usize].map(|p| {
            let q = Vec2::new(p.dot(axis), p.dot(perp)) - lo;
            (if landscape { q } else { Vec2::new(q.y, q.x) }).max(Vec2::ZERO)
        });
    }
    FlatChart {
        extent: if landscape {
            extent
        } else {
            Vec2::new(extent.y, extent.x)
        },
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
