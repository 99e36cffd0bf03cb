//! Flattening a grown chart into the plane, in metres, and checking that the result can
//! carry texels: least-squares conformal maps for curved charts, splitting charts that
//! fail.
//!
//! - **Planar** charts (all normals within [`super::CHART_ANGLE_DEGREES`] of their
//!   area-weighted mean) are projected onto their plane (an isometry up to cos 1°).
//! - **Curved** charts get a least-squares conformal map (LSCM, Lévy, Petitjean, Ray &
//!   Maillot 2002): the per-triangle Cauchy–Riemann residual of the map, weighted by
//!   area, minimised with two vertices pinned, by Jacobi-preconditioned conjugate
//!   gradients on the normal equations from the rigid unfolding of the growth (exact on
//!   developable surfaces, so columns and arches converge at once).
//! - The map is scaled so that its area equals the surface's (mean density = the asked
//!   one) and **accepted** when (1) every triangle's texel density σ (singular values of
//!   the metre-to-metre map) lies within [`MAX_STRETCH`] of every other's, (2) no two
//!   triangles overlap by more than [`TEXEL_EPSILON`] texels (separating axes), and (3)
//!   no texel is reached by two parts of the chart that are far apart on the surface:
//!   texels a triangle overlaps, and their 8 neighbours that bilinear filtering reads
//!   with them, map to points within [`TEXEL_REACH`] texels of each other.
//!   Otherwise the chart is bisected ([`super::growing::split`]) and each part tried
//!   again; a single triangle is always accepted (unfolded, it is an isometry).

use super::{
    CHART_ANGLE_DEGREES, TEXEL_EPSILON,
    growing::{ChartMesh, Grown, farthest, grow, split},
};
use crate::lightmap::texels_overlapped_by;
use glam::{Mat2, Vec2, Vec3};
use surfcache_core::geometry::{closest_point_barycentric, interpolate, orthonormal_basis};
use surfcache_core::index::NO_INDEX;

/// Largest ratio of texel densities (singular values of the map) within one chart.
pub const MAX_STRETCH: f32 = 1.25;

/// Two points of a chart whose texels bilinear filtering reads together lie at most this
/// many texels apart on the surface (more: the chart comes back near itself in the plane).
pub const TEXEL_REACH: f32 = 4.0;

/// Charts less than this many texels across are not held to [`MAX_STRETCH`]: their
/// texel density is not defined below a texel or two.
pub const STRETCH_TEXELS: f32 = 2.0;

/// Conjugate-gradient iterations of one conformal solve at most, and the residual
/// reduction that ends it earlier.
const CG_ITERATIONS: usize = 500;
const CG_TOLERANCE: f32 = 1e-4;

/// A flattened chart: input triangles and their corners in the plane (metres).
pub(super) struct FlatChart {
    pub triangles: Vec<u32>,
    pub uv: Vec<[Vec2; 3]>,
}

/// Flattens the connected `mesh` (a grown chart's triangles) as one chart, or as parts
/// when it fails the checks (module docs), at `density` texels per metre.
pub(super) fn flatten_or_split(mesh: &ChartMesh, density: f32, out: &mut Vec<FlatChart>) {
    let mut chart = vec![NO_INDEX; mesh.len()];
    let mut slot = vec![0u32; mesh.len()];
    let grown = grow(mesh, 0, 0, &mut chart, &mut slot, |_| true);
    debug_assert_eq!(grown.tris.len(), mesh.len());
    match flatten(mesh, &grown, density) {
        Ok(uv) => out.push(FlatChart {
            triangles: grown
                .tris
                .iter()
                .map(|&t| mesh.triangle[t as usize])
                .collect(),
            uv,
        }),
        Err((a, b)) => {
            let (a, b) = (grown.tris[a as usize], grown.tris[b as usize]);
            let b = if a == b {
                farthest(mesh, mesh.positions[a as usize][0], a)
            } else {
                b
            };
            for part in split(mesh, a, b) {
                flatten_or_split(&mesh.subset(&part, false), density, out);
            }
        }
    }
}

/// The grown chart's corners in the plane, area-preserving, if they pass the checks
/// ([`accept`]).
fn flatten(mesh: &ChartMesh, g: &Grown, density: f32) -> Result<Vec<[Vec2; 3]>, (u32, u32)> {
    let tris = &g.tris;
    let mut normal = Vec3::ZERO;
    for &t in tris {
        let [a, b, c] = mesh.positions[t as usize];
        normal += (b - a).cross(c - a);
    }
    let normal = normal.normalize_or(mesh.normals[tris[0] as usize]);
    let cos_planar = CHART_ANGLE_DEGREES.to_radians().cos();
    let planar = tris
        .iter()
        .all(|&t| mesh.normals[t as usize].dot(normal) >= cos_planar);
    if planar {
        let (tu, tv) = orthonormal_basis(normal);
        let origin = mesh.positions[tris[0] as usize][0];
        let uv = tris
            .iter()
            .map(|&t| {
                mesh.positions[t as usize]
                    .map(|p| Vec2::new((p - origin).dot(tu), (p - origin).dot(tv)))
            })
            .collect();
        return accept(mesh, tris, uv, density);
    }
    if tris.len() == 1 {
        // Unfolded, a single triangle is an isometry.
        let unfolded = g
            .corners
            .iter()
            .map(|c| c.map(|v| g.uv[v as usize]))
            .collect();
        return accept(mesh, tris, unfolded, density);
    }
    let x = conformal_map(mesh, g);
    let uv = g.corners.iter().map(|c| c.map(|v| x[v as usize])).collect();
    accept(mesh, tris, uv, density)
}

/// A chart's corners in the plane scaled to the surface's area, if they pass the checks
/// (module docs); else two triangles (positions in the chart) to split it between: the
/// least and most stretched, two that overlap, or two whose texels disagree.
fn accept(
    mesh: &ChartMesh,
    tris: &[u32],
    mut uv: Vec<[Vec2; 3]>,
    density: f32,
) -> Result<Vec<[Vec2; 3]>, (u32, u32)> {
    if tris.len() == 1 {
        return Ok(uv);
    }
    let (mut world, mut flat) = (0.0f64, 0.0f64);
    for (&t, q) in tris.iter().zip(&uv) {
        let [a, b, c] = mesh.positions[t as usize];
        world += 0.5 * (b - a).cross(c - a).length() as f64;
        flat += 0.5 * ((q[1] - q[0]).perp_dot(q[2] - q[0]) as f64).abs();
    }
    if !(flat > 0.0 && flat.is_finite()) {
        return Err((0, 0));
    }
    let scale = (world / flat).sqrt() as f32;
    uv.iter_mut().for_each(|q| *q = q.map(|p| p * scale));
    let (ratio, lo, hi) = stretch(mesh, tris, &uv, density);
    if ratio > MAX_STRETCH {
        return Err((lo, hi));
    }
    if let Some(pair) = overlapping(&uv, TEXEL_EPSILON / density) {
        return Err(pair);
    }
    if let Some(pair) = texels_disagree(mesh, tris, &uv, density) {
        return Err(pair);
    }
    Ok(uv)
}

/// Singular values (σ_min, σ_max) of the linear map taking triangle `p` (3D) to `q`
/// (plane): the square roots of the eigenvalues of JᵀJ, J the map's Jacobian in an
/// orthonormal frame of the triangle. None for a degenerate triangle.
pub fn singular_values(p: [Vec3; 3], q: [Vec2; 3]) -> Option<(f32, f32)> {
    let [a, b, c] = p;
    let n = (b - a).cross(c - a).try_normalize()?;
    let (u, v) = orthonormal_basis(n);
    let e1 = Vec2::new((b - a).dot(u), (b - a).dot(v));
    let e2 = Vec2::new((c - a).dot(u), (c - a).dot(v));
    let world = Mat2::from_cols(e1, e2);
    let det = world.determinant();
    if det.is_nan() || det == 0.0 {
        return None;
    }
    let j = Mat2::from_cols(q[1] - q[0], q[2] - q[0]) * world.inverse();
    let (m00, m01, m11) = (
        j.x_axis.length_squared(),
        j.x_axis.dot(j.y_axis),
        j.y_axis.length_squared(),
    );
    let mean = 0.5 * (m00 + m11);
    let root = (0.25 * (m00 - m11).powi(2) + m01 * m01).sqrt();
    Some(((mean - root).max(0.0).sqrt(), (mean + root).sqrt()))
}

/// Ratio of the largest to the smallest singular value over the chart's triangles of at
/// least a thousandth of a texel (smaller ones carry no texel of their own), and the
/// positions of the triangles holding the two (infinite when one is folded flat). A
/// chart less than [`STRETCH_TEXELS`] texels across passes (ratio 1).
fn stretch(mesh: &ChartMesh, tris: &[u32], uv: &[[Vec2; 3]], density: f32) -> (f32, u32, u32) {
    let (lo, hi) = bounds(uv);
    if (hi - lo).max_element() * density < STRETCH_TEXELS {
        return (1.0, 0, 0);
    }
    let min_area = 1e-3 / (density * density);
    let (mut lo, mut hi) = ((f32::INFINITY, 0u32), (0.0f32, 0u32));
    for (i, (&t, &q)) in tris.iter().zip(uv).enumerate() {
        let p = mesh.positions[t as usize];
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        if area < min_area {
            continue;
        }
        let (s0, s1) = singular_values(p, q).unwrap_or((0.0, 0.0));
        if s0 < lo.0 {
            lo = (s0, i as u32);
        }
        if s1 > hi.0 {
            hi = (s1, i as u32);
        }
    }
    if hi.0 == 0.0 {
        return (1.0, 0, 0);
    }
    let ratio = if lo.0 > 0.0 {
        hi.0 / lo.0
    } else {
        f32::INFINITY
    };
    (ratio, lo.1, hi.1)
}

/// Lowest and highest corner of a chart.
fn bounds(uv: &[[Vec2; 3]]) -> (Vec2, Vec2) {
    point_bounds(uv.as_flattened())
}

/// Lowest and highest of `points`, per axis.
fn point_bounds(points: &[Vec2]) -> (Vec2, Vec2) {
    points
        .iter()
        .fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(l, h), &p| {
            (l.min(p), h.max(p))
        })
}

/// The LSCM solution (module docs) for every chart vertex, from the unfolded positions.
fn conformal_map(mesh: &ChartMesh, g: &Grown) -> Vec<Vec2> {
    let nv = g.uv.len();
    let coeff = cauchy_riemann_coefficients(mesh, &g.tris);
    let corners = &g.corners;
    let mut diag = vec![0.0f32; nv];
    for (c, v) in coeff.iter().zip(corners) {
        for j in 0..3 {
            diag[v[j] as usize] += c[j].length_squared();
        }
    }
    // Pins: the extreme vertices along the unfolding's wider axis.
    let x = g.uv.clone();
    let (lo, hi) = point_bounds(&x);
    let axis = usize::from(hi.y - lo.y > hi.x - lo.x);
    let key = |i: usize| x[i][axis];
    let p0 = (0..nv)
        .min_by(|&i, &j| key(i).total_cmp(&key(j)))
        .unwrap_or(0);
    let p1 = (0..nv)
        .max_by(|&i, &j| key(i).total_cmp(&key(j)))
        .unwrap_or(0);
    if p0 == p1 {
        return x;
    }
    let free: Vec<f32> = (0..nv)
        .map(|i| {
            if i == p0 || i == p1 || diag[i] <= 0.0 {
                0.0
            } else {
                1.0 / diag[i]
            }
        })
        .collect();
    solve_pinned(&coeff, corners, &free, x)
}

/// Per triangle of `tris` and corner j: the edge opposite j in the triangle's own frame
/// over 2√area, so that the residual is
///   r = Σ_j (−e_x U_j + e_y V_j,  −e_y U_j − e_x V_j)
/// (rot90 ∇U − ∇V times √area; zero for a similarity).
fn cauchy_riemann_coefficients(mesh: &ChartMesh, tris: &[u32]) -> Vec<[Vec2; 3]> {
    tris.iter()
        .map(|&t| {
            let [a, b, c] = mesh.positions[t as usize];
            let x = b - a;
            let l = x.length();
            let (px, py) = if l > 0.0 {
                let along = (c - a).dot(x) / l;
                (along, ((c - a) - x * (along / l)).length())
            } else {
                (0.0, 0.0)
            };
            let p = [Vec2::ZERO, Vec2::new(l, 0.0), Vec2::new(px, py)];
            let area = 0.5 * l * py;
            let w = if area > 0.0 { 0.5 / area.sqrt() } else { 0.0 };
            [0, 1, 2].map(|j| (p[(j + 2) % 3] - p[(j + 1) % 3]) * w)
        })
        .collect()
}

/// y = AᵀA x, A the residuals ([`cauchy_riemann_coefficients`] `coeff`) of the triangles
/// with chart vertices `corners`.
fn apply_normal_matrix(coeff: &[[Vec2; 3]], corners: &[[u32; 3]], x: &[Vec2], y: &mut [Vec2]) {
    y.fill(Vec2::ZERO);
    for (c, v) in coeff.iter().zip(corners) {
        let (mut r1, mut r2) = (0.0, 0.0);
        for j in 0..3 {
            let (e, u) = (c[j], x[v[j] as usize]);
            r1 += -e.x * u.x + e.y * u.y;
            r2 += -e.y * u.x - e.x * u.y;
        }
        for j in 0..3 {
            let e = c[j];
            y[v[j] as usize] += Vec2::new(-e.x * r1 - e.y * r2, e.y * r1 - e.x * r2);
        }
    }
}

/// Σ_i a_i · b_i, summed in f64.
fn inner_product(a: &[Vec2], b: &[Vec2]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(*b) as f64).sum::<f64>()
}

/// Preconditioned conjugate gradients on AᵀA x = 0 ([`apply_normal_matrix`]) from `x`,
/// with the vertices whose Jacobi preconditioner `free` (1/diag AᵀA) is 0 fixed: the pins.
fn solve_pinned(
    coeff: &[[Vec2; 3]],
    corners: &[[u32; 3]],
    free: &[f32],
    mut x: Vec<Vec2>,
) -> Vec<Vec2> {
    let nv = x.len();
    let mut r = vec![Vec2::ZERO; nv];
    apply_normal_matrix(coeff, corners, &x, &mut r);
    for (ri, &f) in r.iter_mut().zip(free) {
        *ri = if f > 0.0 { -*ri } else { Vec2::ZERO };
    }
    let mut z: Vec<Vec2> = r.iter().zip(free).map(|(&ri, &f)| ri * f).collect();
    let mut p = z.clone();
    let mut q = vec![Vec2::ZERO; nv];
    let mut rz = inner_product(&r, &z);
    let target = rz * (CG_TOLERANCE as f64).powi(2);
    for _ in 0..CG_ITERATIONS {
        if !(rz > target && rz > 0.0) {
            break;
        }
        apply_normal_matrix(coeff, corners, &p, &mut q);
        for (qi, &f) in q.iter_mut().zip(free) {
            if f == 0.0 {
                *qi = Vec2::ZERO;
            }
        }
        let pq = inner_product(&p, &q);
        if pq.is_nan() || pq <= 0.0 {
            break;
        }
        let alpha = (rz / pq) as f32;
        for i in 0..nv {
            x[i] += p[i] * alpha;
            r[i] -= q[i] * alpha;
            z[i] = r[i] * free[i];
        }
        let rz_new = inner_product(&r, &z);
        let beta = (rz_new / rz) as f32;
        rz = rz_new;
        for i in 0..nv {
            p[i] = z[i] + p[i] * beta;
        }
    }
    x
}

/// Two triangles of `uv` that overlap by more than `epsilon` along every separating
/// axis candidate (their edge normals), found through a uniform grid over their boxes.
fn overlapping(uv: &[[Vec2; 3]], epsilon: f32) -> Option<(u32, u32)> {
    let m = uv.len();
    let (lo, hi) = bounds(uv);
    let span = (hi - lo).max(Vec2::splat(f32::MIN_POSITIVE));
    let cell = ((span.x * span.y) / m as f32)
        .sqrt()
        .max(span.max_element() / 4096.0);
    let dims = (span / cell).ceil().as_uvec2().max(glam::UVec2::ONE);
    let cell_of = |p: Vec2| {
        ((p - lo) / cell)
            .floor()
            .as_uvec2()
            .min(dims - glam::UVec2::ONE)
    };
    let mut entries: Vec<(u64, u32)> = Vec::with_capacity(2 * m);
    for (t, q) in uv.iter().enumerate() {
        let (a, b) = (
            cell_of(q[0].min(q[1]).min(q[2])),
            cell_of(q[0].max(q[1]).max(q[2])),
        );
        for y in a.y..=b.y {
            for x in a.x..=b.x {
                entries.push(((y as u64) << 32 | x as u64, t as u32));
            }
        }
    }
    entries.sort_unstable();
    let mut start = 0;
    while start < entries.len() {
        let mut end = start + 1;
        while end < entries.len() && entries[end].0 == entries[start].0 {
            end += 1;
        }
        for i in start..end {
            for j in i + 1..end {
                let (p, q) = (entries[i].1, entries[j].1);
                if triangles_overlap(uv[p as usize], uv[q as usize], epsilon) {
                    return Some((p, q));
                }
            }
        }
        start = end;
    }
    None
}

/// Separating-axis test of two triangles in the plane: they overlap unless their
/// projections onto one edge normal are at most `epsilon` deep into each other.
fn triangles_overlap(p: [Vec2; 3], q: [Vec2; 3], epsilon: f32) -> bool {
    let mut any_axis = false;
    for tri in [p, q] {
        for k in 0..3 {
            let axis = (tri[(k + 1) % 3] - tri[k]).perp();
            let length = axis.length();
            if length.is_nan() || length <= 0.0 {
                continue;
            }
            any_axis = true;
            let range = |t: [Vec2; 3]| {
                t.iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), v| {
                        let d = v.dot(axis);
                        (l.min(d), h.max(d))
                    })
            };
            let ((p0, p1), (q0, q1)) = (range(p), range(q));
            if p1 <= q0 + epsilon * length || q1 <= p0 + epsilon * length {
                return false;
            }
        }
    }
    any_axis
}

/// Two triangles (positions in the chart) whose texels at `density` bilinear filtering
/// reads together, among a texel a triangle overlaps and its 8 neighbours, map to
/// points of the surface more than [`TEXEL_REACH`] texels (stretched by at most
/// [`MAX_STRETCH`]) apart: each texel keeps the first point that reached it, and every
/// later one is compared with the kept points of the 3 × 3 block around it.
fn texels_disagree(
    mesh: &ChartMesh,
    tris: &[u32],
    uv: &[[Vec2; 3]],
    density: f32,
) -> Option<(u32, u32)> {
    let (lo, hi) = bounds(uv);
    let size = ((hi - lo) * density).ceil().as_uvec2() + 2;
    if size.x as u64 * size.y as u64 > 1 << 26 {
        return Some((0, 0));
    }
    let (w, h) = (size.x as usize, size.y as usize);
    let limit = TEXEL_REACH * MAX_STRETCH / density;
    let limit2 = limit * limit;
    let mut kept: Vec<(Vec3, u32)> = vec![(Vec3::NAN, NO_INDEX); w * h];
    let mut conflict = None;
    for (i, (&t, q)) in tris.iter().zip(uv).enumerate() {
        let [a, b, c] = mesh.positions[t as usize];
        let corners = q.map(|p| (p - lo) * density + 0.5);
        let [qa, qb, qc] = corners.map(|p| p.extend(0.0));
        texels_overlapped_by(corners, [0, 0, size.x, size.y], TEXEL_EPSILON, |x, y| {
            if conflict.is_some() {
                return;
            }
            let centre = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, 0.0);
            let point = interpolate(a, b, c, closest_point_barycentric(centre, qa, qb, qc));
            let (x, y) = (x as usize, y as usize);
            for j in y.saturating_sub(1)..(y + 2).min(h) {
                for k in x.saturating_sub(1)..(x + 2).min(w) {
                    let (other, owner) = kept[j * w + k];
                    if owner != NO_INDEX && (other - point).length_squared() > limit2 {
                        conflict = Some((owner, i as u32));
                    }
                }
            }
            if kept[y * w + x].1 == NO_INDEX {
                kept[y * w + x] = (point, i as u32);
            }
        });
        if conflict.is_some() {
            return conflict;
        }
    }
    None
}
