//! Growing charts over a mesh's edges, each a topological disc unfolded into the plane.
//!
//! A chart grows breadth-first from a seed across *smooth* edges (shared by exactly two
//! consistently oriented triangles whose normals are within [`SMOOTH_ANGLE_DEGREES`]).
//! Corners are identified as chart vertices only through the edges the growth glued: a
//! triangle joins across its entry edge, and also glues a second edge when that edge's
//! shared corner is already the same chart vertex on both sides, never a third (that
//! would close the chart). Every corner's fan is thus connected through glued edges and
//! every boundary vertex has two boundary edges, so each addition keeps the chart a disc;
//! where growth fronts meet (around a column, a hole in a wall) the chart is cut along the
//! meeting edges instead of closing. Each new vertex is placed by unfolding its triangle
//! rigidly across the entry edge, an isometry on developable surfaces and the start of
//! the conformal solve ([`super::parameterise`]) elsewhere.

use glam::{Vec2, Vec3};
use std::collections::{HashMap, VecDeque};
use surfcache_core::index::NO_INDEX;

/// Triangles sharing an edge grow into one chart when their normals are within this
/// angle: sharper creases always end a chart (irradiance changes across them, and each
/// side's border texels are then estimated on the crease itself).
pub const SMOOTH_ANGLE_DEGREES: f32 = 45.0;

/// Triangles (a mesh, or a chart's part of it) and the smooth edges between them.
#[derive(Clone, Debug, Default)]
pub(super) struct ChartMesh {
    /// Input index of each triangle.
    pub triangle: Vec<u32>,
    pub positions: Vec<[Vec3; 3]>,
    pub normals: Vec<Vec3>,
    /// Across edge k (corners k and k + 1): the neighbour triangle and its edge, or
    /// (NO_INDEX, 0).
    pub across: Vec<[(u32, u8); 3]>,
    /// The same for the edges that are manifold and consistently oriented but sharper
    /// than [`SMOOTH_ANGLE_DEGREES`] (creases), which charts grow over only when merged
    /// across them ([`ChartMesh::subset`]).
    pub creases: Vec<[(u32, u8); 3]>,
}

impl ChartMesh {
    /// The mesh of `positions` with corners welded to `weld` ids; triangles marked
    /// `degenerate` get no edges.
    pub fn new(
        positions: &[[Vec3; 3]],
        normals: &[Vec3],
        weld: &[[u32; 3]],
        degenerate: &[bool],
    ) -> Self {
        let n = positions.len();
        // Directed edges (lower id, higher id, triangle, edge): equal edges are adjacent.
        let mut edges: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(3 * n);
        for (t, w) in weld.iter().enumerate() {
            if degenerate[t] {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (w[k], w[(k + 1) % 3]);
                edges.push((a.min(b), a.max(b), t as u32, k as u8));
            }
        }
        edges.sort_unstable();
        let cos_smooth = SMOOTH_ANGLE_DEGREES.to_radians().cos();
        let mut across = vec![[(NO_INDEX, 0u8); 3]; n];
        let mut creases = vec![[(NO_INDEX, 0u8); 3]; n];
        let mut start = 0;
        while start < edges.len() {
            let mut end = start + 1;
            while end < edges.len()
                && (edges[end].0, edges[end].1) == (edges[start].0, edges[start].1)
            {
                end += 1;
            }
            // Manifold, consistently oriented (the edge runs opposite ways) and smooth.
            if end - start == 2 {
                let (_, _, t, k) = edges[start];
                let (_, _, u, j) = edges[start + 1];
                let (t, u) = (t as usize, u as usize);
                let opposite = weld[t][k as usize] == weld[u][(j as usize + 1) % 3];
                if t != u && opposite {
                    let edges = if normals[t].dot(normals[u]) >= cos_smooth {
                        &mut across
                    } else {
                        &mut creases
                    };
                    edges[t][k as usize] = (u as u32, j);
                    edges[u][j as usize] = (t as u32, k);
                }
            }
            start = end;
        }
        Self {
            triangle: (0..n as u32).collect(),
            positions: positions.to_vec(),
            normals: normals.to_vec(),
            across,
            creases,
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// The triangles `tris` (indices into `self`) with the edges between them; with
    /// `glue_creases`, the creases between them become edges to grow over.
    pub fn subset(&self, tris: &[u32], glue_creases: bool) -> Self {
        let local: HashMap<u32, u32> = tris
            .iter()
            .enumerate()
            .map(|(i, &t)| (t, i as u32))
            .collect();
        let inside = |edges: [(u32, u8); 3]| {
            edges.map(|(u, j)| match local.get(&u) {
                Some(&l) if u != NO_INDEX => (l, j),
                _ => (NO_INDEX, 0),
            })
        };
        let (mut across, mut creases): (Vec<_>, Vec<_>) = tris
            .iter()
            .map(|&t| {
                (
                    inside(self.across[t as usize]),
                    inside(self.creases[t as usize]),
                )
            })
            .unzip();
        if glue_creases {
            for (a, c) in across.iter_mut().zip(&mut creases) {
                for k in 0..3 {
                    if c[k].0 != NO_INDEX {
                        a[k] = std::mem::replace(&mut c[k], (NO_INDEX, 0));
                    }
                }
            }
        }
        Self {
            triangle: tris.iter().map(|&t| self.triangle[t as usize]).collect(),
            positions: tris.iter().map(|&t| self.positions[t as usize]).collect(),
            normals: tris.iter().map(|&t| self.normals[t as usize]).collect(),
            across,
            creases,
        }
    }
}

/// One grown chart: its triangles in growth order, the chart vertex of each corner and
/// the unfolded position of each vertex (metres).
#[derive(Clone, Debug, Default)]
pub(super) struct Grown {
    pub tris: Vec<u32>,
    pub corners: Vec<[u32; 3]>,
    pub uv: Vec<Vec2>,
}

/// Where C lands when triangle (A, B, C) is unfolded across its edge AB, placed at
/// `a`, `b` in the plane, counter-clockwise: the triangle similar to ABC on the segment
/// ab (congruent when |ab| = |AB|).
fn unfold(a: Vec2, b: Vec2, pa: Vec3, pb: Vec3, pc: Vec3) -> Vec2 {
    let edge = pb - pa;
    let length = edge.length();
    let d = pc - pa;
    let along = d.dot(edge) / length;
    let height = edge.cross(d).length() / length;
    let ab = b - a;
    let scale = ab.length() / length;
    let dir = ab.try_normalize().unwrap_or(Vec2::X);
    a + (dir * along + dir.perp() * height) * scale
}

/// Grows chart `id` from `seed` over unassigned triangles for which `allowed` holds
/// (module docs), marking `chart` and recording each triangle's position in the chart
/// in `slot`.
pub(super) fn grow(
    mesh: &ChartMesh,
    seed: u32,
    id: u32,
    chart: &mut [u32],
    slot: &mut [u32],
    allowed: impl Fn(u32) -> bool,
) -> Grown {
    let [pa, pb, pc] = mesh.positions[seed as usize];
    let ab = (pb - pa).length();
    let a = Vec2::ZERO;
    let b = Vec2::new(ab, 0.0);
    let mut g = Grown {
        tris: vec![seed],
        corners: vec![[0, 1, 2]],
        uv: vec![a, b, unfold(a, b, pa, pb, pc)],
    };
    chart[seed as usize] = id;
    slot[seed as usize] = 0;
    // Candidates: (triangle, its entry edge, the chart triangle across, that one's edge).
    let mut queue: VecDeque<(u32, u8, u32, u8)> = VecDeque::new();
    queue_neighbours(mesh, seed, &mut queue, chart);
    while let Some((t, k, p, kp)) = queue.pop_front() {
        let tu = t as usize;
        if chart[tu] != NO_INDEX || !allowed(t) {
            continue;
        }
        let (k, kp) = (k as usize, kp as usize);
        // Corner k of t is corner kp + 1 of p, corner k + 1 is corner kp.
        let pcorners = g.corners[slot[p as usize] as usize];
        let mut corners = [NO_INDEX; 3];
        corners[k] = pcorners[(kp + 1) % 3];
        corners[(k + 1) % 3] = pcorners[kp];
        let third = (k + 2) % 3;
        let placed = |u: u32| {
            (u != NO_INDEX && chart[u as usize] == id).then(|| g.corners[slot[u as usize] as usize])
        };
        corners[third] = glued_third_corner(mesh.across[tu], k, corners, placed);
        if corners[third] == NO_INDEX {
            let p3 = mesh.positions[tu];
            let (ua, ub) = (
                g.uv[corners[k] as usize],
                g.uv[corners[(k + 1) % 3] as usize],
            );
            corners[third] = g.uv.len() as u32;
            g.uv.push(unfold(ua, ub, p3[k], p3[(k + 1) % 3], p3[third]));
        }
        chart[tu] = id;
        slot[tu] = g.tris.len() as u32;
        g.tris.push(t);
        g.corners.push(corners);
        queue_neighbours(mesh, t, &mut queue, chart);
    }
    g
}

/// Queues the neighbours of `t` across its smooth edges that no chart holds yet, as growth
/// candidates (triangle, its entry edge, `t`, `t`'s edge).
fn queue_neighbours(
    mesh: &ChartMesh,
    t: u32,
    queue: &mut VecDeque<(u32, u8, u32, u8)>,
    chart: &[u32],
) {
    for (e, &(u, j)) in mesh.across[t as usize].iter().enumerate() {
        if u != NO_INDEX && chart[u as usize] == NO_INDEX {
            queue.push_back((u, j, t, e as u8));
        }
    }
}

/// The chart vertex of the third corner (k + 2) of a triangle joining across its edge k
/// (`corners` k and k + 1 known, `across` its neighbours), through a second glued edge
/// when that edge's known corner is the same chart vertex on both sides; NO_INDEX when
/// there is none, or when gluing all three edges would close the chart (it is cut
/// instead). `placed(u)` gives the chart vertices of triangle `u` when it is in the chart.
fn glued_third_corner(
    across: [(u32, u8); 3],
    k: usize,
    mut corners: [u32; 3],
    placed: impl Fn(u32) -> Option<[u32; 3]>,
) -> u32 {
    let third = (k + 2) % 3;
    for e in [(k + 1) % 3, third] {
        let (q, j) = across[e];
        let Some(qc) = placed(q) else {
            continue;
        };
        let j = j as usize;
        // Corner e of t is corner j + 1 of q, corner e + 1 is corner j.
        let (known, theirs, candidate) = if e == third {
            (corners[k], qc[j], qc[(j + 1) % 3])
        } else {
            (corners[e], qc[(j + 1) % 3], qc[j])
        };
        if known == theirs {
            corners[third] = candidate;
            break;
        }
    }
    if corners[third] == NO_INDEX {
        return NO_INDEX;
    }
    // Gluing all three edges would close the chart: cut instead.
    let glued = (0..3)
        .filter(|&e| {
            let (q, j) = across[e];
            placed(q).is_some_and(|qc| {
                let j = j as usize;
                corners[e] == qc[(j + 1) % 3] && corners[(e + 1) % 3] == qc[j]
            })
        })
        .count();
    if glued == 3 { NO_INDEX } else { corners[third] }
}

/// Breadth-first hop counts from `seed` over the mesh's edges (NO_INDEX where unreachable).
fn hops(mesh: &ChartMesh, seed: u32) -> Vec<u32> {
    let mut dist = vec![NO_INDEX; mesh.len()];
    let mut queue = VecDeque::from([seed]);
    dist[seed as usize] = 0;
    while let Some(t) = queue.pop_front() {
        for &(u, _) in &mesh.across[t as usize] {
            if u != NO_INDEX && dist[u as usize] == NO_INDEX {
                dist[u as usize] = dist[t as usize] + 1;
                queue.push_back(u);
            }
        }
    }
    dist
}

/// Splits a connected mesh in two around the triangles `a` and `b` (distinct): the
/// first part grows from `a` over the triangles at least as close to it as to `b` (in
/// edge hops), the second from `b` over the rest, and any triangle left out starts a
/// part of its own. Returns the parts' triangles.
pub(super) fn split(mesh: &ChartMesh, a: u32, b: u32) -> Vec<Vec<u32>> {
    let (da, db) = (hops(mesh, a), hops(mesh, b));
    let mut chart = vec![NO_INDEX; mesh.len()];
    let mut slot = vec![0u32; mesh.len()];
    let mut parts = vec![
        grow(mesh, a, 0, &mut chart, &mut slot, |t| {
            da[t as usize] <= db[t as usize]
        })
        .tris,
    ];
    for seed in std::iter::once(b).chain(0..mesh.len() as u32) {
        if chart[seed as usize] == NO_INDEX {
            let id = parts.len() as u32;
            parts.push(grow(mesh, seed, id, &mut chart, &mut slot, |_| true).tris);
        }
    }
    parts
}

/// The triangle of `mesh` whose centroid is farthest from `from` (ties: the lower index),
/// other than `not`.
pub(super) fn farthest(mesh: &ChartMesh, from: Vec3, not: u32) -> u32 {
    let centroid = |t: usize| mesh.positions[t].iter().sum::<Vec3>() / 3.0;
    (0..mesh.len())
        .filter(|&t| t as u32 != not)
        .max_by(|&s, &t| {
            (centroid(s) - from)
                .length_squared()
                .total_cmp(&(centroid(t) - from).length_squared())
                .then(t.cmp(&s))
        })
        .unwrap_or(0) as u32
}
