//! Surfaces that cross or touch a surface: walls standing on a floor, props piercing it,
//! closed solids overlapping at corners (docs/design.md, "Crossings").
//!
//! A cache sample stands for a patch of its surface (a texel's footprint, a grid cell).
//! Where another surface cuts through that patch, the two sides of the cut see different
//! light, and a sample placed on one side must neither stand for the other nor be blended
//! with samples from it. Crossings are found by *in-plane probes*: from a sample's ray
//! origin ([`TracedScene::spawn_origin`], lifted the spawn offset off its side)
//! [`PROBE_DIRECTIONS`] rays run parallel to the surface, as far as the patch reaches. A
//! surface that meets or pierces the patch stops one of them; surfaces of the same smooth
//! mesh (within [`SAME_SURFACE_DEGREES`] of the patch's normal, e.g. a concave curve
//! rising from the lifted ray) are not crossings, nor are surfaces that meet the
//! triangle only along its boundary (the neighbouring wall at a box's concave edge: no
//! corner of the triangle lies beyond it).
//!
//! What a probe tells ([`Probe`]):
//! - whether the patch is crossed, and the crossing nearest to the sample: a line in the
//!   surface's plane (where the crossing surface's plane cuts it) with the sample on its
//!   positive side;
//! - an *exit*: the nearest point of the sample's own triangle just beyond a crossing
//!   surface that the probe met from behind (the back face of a single-sided surface:
//!   the sample lies inside a solid, e.g. a floor under a wall that pierces it). A buried
//!   sample moves there and is estimated on the visible part of its patch.

use glam::{Vec2, Vec3};
use surfcache_core::geometry::{orthonormal_basis, plane_barycentric};
use surfcache_trace::TracedScene;

/// In-plane probe rays per sample, evenly spread in angle.
pub const PROBE_DIRECTIONS: u32 = 8;

/// Hit surfaces whose normal is within this angle of the probed surface's (either
/// orientation) count as the same surface, not as a crossing.
pub const SAME_SURFACE_DEGREES: f32 = 30.0;

/// A crossing line in a surface's plane: the points x with `normal · (x − point) = 0`,
/// `normal` in the plane, pointing to the side of the probed sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CrossingLine {
    pub point: Vec3,
    pub normal: Vec3,
}

impl CrossingLine {
    /// Signed distance of `x` from the line, positive on the sample's side.
    #[inline]
    pub fn side(&self, x: Vec3) -> f32 {
        self.normal.dot(x - self.point)
    }
}

/// What the in-plane probes of one sample found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Probe {
    /// The nearest crossing within reach, if any.
    pub crossing: Option<CrossingLine>,
    /// Barycentrics on the sample's triangle just beyond the nearest crossing met from
    /// behind, if that point lies on the triangle (module docs).
    pub exit: Option<Vec2>,
    /// The sample lies on a crossing surface (met from behind within the boundary
    /// tolerance: a texel centre on the line where a wall stands). Its own estimate would
    /// see that surface at t ≈ 0 in every direction; it belongs at [`Probe::exit`].
    pub touching: bool,
}

/// Probes the surface around barycentrics `uv` of `triangle` on the given side within
/// `reach` metres (module docs).
pub fn probe(scene: &TracedScene, triangle: u32, uv: Vec2, front: bool, reach: f32) -> Probe {
    let p = scene.surface_point(triangle, uv, front);
    let origin = scene.spawn_origin(&p);
    let mu = p.geometric_normal;
    let (e1, e2) = orthonormal_basis(mu);
    let same = SAME_SURFACE_DEGREES.to_radians().cos();
    let [a, b, c] = scene.positions[triangle as usize];
    let off = scene.spawn_offset();
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    let boundary_tolerance = (4.0 * off).max(1e-4 * longest);
    let mut best: Option<(f32, CrossingLine)> = None;
    let mut exit: Option<(f32, Vec2)> = None;
    for k in 0..PROBE_DIRECTIONS {
        let angle = k as f32 * std::f32::consts::TAU / PROBE_DIRECTIONS as f32;
        let d = e1 * angle.cos() + e2 * angle.sin();
        let Some(hit) = scene.closest_hit(origin, d, reach) else {
            continue;
        };
        let n_hit = scene.geometric_normals[hit.triangle as usize];
        if n_hit.dot(mu).abs() >= same {
            continue;
        }
        let t = hit.t;
        // Where the crossing surface's plane cuts this one: through the hit point (lifted
        // by the offset, negligible), along μ × n_hit; its normal in the plane faces the
        // sample.
        let along = mu.cross(n_hit);
        let Some(along) = along.try_normalize() else {
            continue;
        };
        let mut normal = mu.cross(along);
        let q = origin + d * t - mu * off;
        // The probe ran from the sample's side towards the crossing: orient by the ray,
        // not by the sample point, which may lie on the line (a sample on the edge where a
        // wall stands).
        if normal.dot(d) > 0.0 {
            normal = -normal;
        }
        // A surface meeting this triangle only along or beyond its boundary (the next wall
        // at a box's concave edge) cuts no patch of it: a crossing must leave some corner
        // of the triangle on its far side.
        let far = [a, b, c]
            .iter()
            .map(|&v| normal.dot(v - q))
            .fold(f32::INFINITY, f32::min);
        if far > -boundary_tolerance {
            continue;
        }
        if best.is_none_or(|(tb, _)| t < tb) {
            best = Some((t, CrossingLine { point: q, normal }));
        }
        let back = n_hit.dot(d) > 0.0 && !scene.material_of(hit.triangle).double_sided;
        if back && exit.is_none_or(|(te, _)| t < te) {
            // Just beyond the crossing surface, on this triangle's plane: step far enough
            // past the surface that the moved sample's origin clears it at this angle.
            let sin = n_hit.dot(d).abs().max(0.05);
            let beyond = p.position + d * (t + 4.0 * off / sin);
            let bary = plane_barycentric(beyond, a, b, c);
            let w = 1.0 - bary.x - bary.y;
            if bary.min_element().min(w) > 1e-4 {
                exit = Some((t, bary));
            }
        }
    }
    let touching = exit.is_some_and(|(t, _)| t < boundary_tolerance);
    let exit = exit.map(|(_, uv)| uv);
    Probe {
        crossing: best.map(|(_, line)| line),
        exit,
        touching,
    }
}

/// Whether any cell of the order-`n` grid of `triangle` (on the given side) is crossed:
/// probes from every grid point as far as one grid spacing (the longest edge over `n`).
pub fn grid_crossed(scene: &TracedScene, triangle: u32, front: bool, n: u32) -> bool {
    let [a, b, c] = scene.positions[triangle as usize];
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    let reach = longest / n.max(1) as f32;
    let inv = 1.0 / n.max(1) as f32;
    for d in 0..=n {
        for j in 0..=d {
            let uv = Vec2::new((d - j) as f32 * inv, j as f32 * inv);
            if probe(scene, triangle, uv, front, reach).crossing.is_some() {
                return true;
            }
        }
    }
    false
}
