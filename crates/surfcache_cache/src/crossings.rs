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

use crate::stored_rgb::StoredRgb;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use surfcache_core::geometry::{interpolate, longest_edge, orthonormal_basis, plane_barycentric};
use surfcache_trace::{Estimate, TracedScene};

/// How far, in sample spacings (a texel, a grid spacing), a cache probes its samples for
/// the crossing lines its lookups use: a little over one, so that the samples on both
/// sides of a crossing between two of them know it, and one of the
/// [`PROBE_DIRECTIONS`] reaches a plane one spacing away (at most 22.5° off its normal:
/// 1/cos 22.5° = 1.08).
pub const LINE_REACH: f32 = 1.1;

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

    /// The line on triangle `t` as a line in a 2-D parameterisation of it whose corners
    /// sit at `corners` (UV1, or `[(0,0), (1,0), (0,1)]` for barycentrics): `[a, b, c]`
    /// with `a·u + b·v + c` the signed distance there, positive on the side of the point
    /// at barycentrics `uv` (the sample, which may have moved since it was probed);
    /// `None` if it cannot be mapped (a degenerate parameterisation).
    pub fn in_uv(
        &self,
        scene: &TracedScene,
        t: u32,
        corners: [Vec2; 3],
        uv: Vec2,
    ) -> Option<[f32; 3]> {
        let [a, b, c] = scene.positions()[t as usize];
        let mu = scene.geometric_normals()[t as usize];
        let along = mu.cross(self.normal);
        let to_uv = |x: Vec3| {
            interpolate(
                corners[0],
                corners[1],
                corners[2],
                plane_barycentric(x, a, b, c),
            )
        };
        let scale = (b - a)
            .length()
            .max((c - a).length())
            .max(f32::MIN_POSITIVE);
        let (u0, u1) = (to_uv(self.point), to_uv(self.point + along * scale));
        let normal = (u1 - u0).perp().try_normalize()?;
        let sample = interpolate(corners[0], corners[1], corners[2], uv);
        let (normal, offset) = if normal.dot(sample - u0) >= 0.0 {
            (normal, -normal.dot(u0))
        } else {
            (-normal, normal.dot(u0))
        };
        Some([normal.x, normal.y, offset])
    }
}

/// What the in-plane probes of one sample found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Probe {
    /// The nearest crossing within reach, if any.
    pub crossing: Option<CrossingLine>,
    /// How far from the sample the probe met the surface of [`Probe::crossing`]
    /// (infinite without one).
    pub crossing_distance: f32,
    /// Barycentrics on the sample's triangle just beyond the nearest crossing met from
    /// behind, if that point lies on the triangle (module docs).
    pub exit: Option<Vec2>,
    /// How far from the sample the probe met the crossing surface of [`Probe::exit`].
    pub exit_distance: f32,
    /// The sample lies on a crossing surface (met from behind within the boundary
    /// tolerance: a texel centre on the line where a wall stands). Its own estimate would
    /// see that surface at t ≈ 0 in every direction; it belongs at [`Probe::exit`].
    pub touching: bool,
}

/// A sample's crossing line as a cache keeps it: `line` in a 2-D parameterisation of its
/// triangle (barycentrics for irradiance maps, UV1 for lightmaps;
/// [`CrossingLine::in_uv`]), positive on the sample's side; `site` and `foot` the signed
/// distances of the sample and of its foot ([`foot`]) from it, `foot ≥ site` where the
/// sample has no foot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleCrossing {
    pub line: [f32; 3],
    pub site: f32,
    pub foot: f32,
}

impl SampleCrossing {
    /// The crossing `crossing` of the sample at barycentrics `site` on one side of
    /// `triangle`, kept as a line in the parameterisation with corners `corners`
    /// ([`CrossingLine::in_uv`]), with the barycentrics of its foot ([`foot`]) if it has
    /// one; `None` if the line cannot be mapped.
    pub fn new(
        scene: &TracedScene,
        triangle: u32,
        front: bool,
        crossing: &CrossingLine,
        corners: [Vec2; 3],
        site: Vec2,
    ) -> Option<(Self, Option<Vec2>)> {
        let line = crossing.in_uv(scene, triangle, corners, site)?;
        let mut kept = Self {
            line,
            site: 0.0,
            foot: 0.0,
        };
        let distance =
            |bary: Vec2| kept.distance(interpolate(corners[0], corners[1], corners[2], bary));
        let site_distance = distance(site);
        let foot_site = crossing
            .in_uv(scene, triangle, BARYCENTRIC, site)
            .and_then(|bary_line| foot(scene, triangle, front, crossing, bary_line, site))
            .filter(|&bary| distance(bary) < site_distance);
        let foot_distance = foot_site.map_or(site_distance, distance);
        kept.site = site_distance;
        kept.foot = foot_distance;
        Some((kept, foot_site))
    }

    /// Whether `at` lies on the sample's side of the line.
    #[inline]
    pub fn on_side(&self, at: Vec2) -> bool {
        self.distance(at) >= 0.0
    }

    /// A re-bake's prior for the foot of this line, given the line `old` the sample had
    /// before the edit and the foot's value then (NaN: it was buried and `old` settled
    /// without it, [`settle_feet`]): the value where the line is the same, a buried foot
    /// ([`Prior::Filled`], stays buried unless the stage estimates it) where the settled
    /// line is, `None` otherwise.
    pub fn foot_prior(&self, old: &SampleCrossing, value: Vec3) -> Option<crate::Prior> {
        if value.is_nan() {
            let settled = SampleCrossing {
                foot: self.site,
                ..*self
            };
            (settled == *old).then_some(crate::Prior::Filled(Vec3::ZERO))
        } else {
            (self == old).then_some(crate::Prior::Estimated(value))
        }
    }

    /// Whether the sample has a foot (`foot < site`; otherwise it keeps its own value
    /// up to the line).
    #[inline]
    pub fn has_foot(&self) -> bool {
        self.foot < self.site
    }

    /// The signed distance of `at` from the line (in the parameterisation's units).
    #[inline]
    pub fn distance(&self, at: Vec2) -> f32 {
        self.line[0] * at.x + self.line[1] * at.y + self.line[2]
    }

    /// The value a lookup at `at` takes for the sample of value `e` whose foot has value
    /// `foot`: E along the line's normal, linear from the foot to the sample,
    /// `E_f + (E − E_f)·(s − s_f)/(s_site − s_f)` for `s < s_site` (continued to the
    /// line), the sample's own value beyond it.
    #[inline]
    pub fn value(&self, at: Vec2, e: Vec3, foot: Vec3) -> Vec3 {
        let s = self.distance(at);
        if !self.has_foot() || s >= self.site {
            return e;
        }
        self.blend(s, e, foot)
    }

    /// E at distance `s < site` from the line, linear from the foot to the sample.
    #[inline]
    fn blend(&self, s: f32, e: Vec3, foot: Vec3) -> Vec3 {
        let t = (s.max(0.0) - self.foot) / (self.site - self.foot);
        (foot + (e - foot) * t).max(Vec3::ZERO)
    }

    /// What a lookup at `at` takes from the sample of value `e` whose foot has value
    /// `foot`: `None` where the line separates `at` from the sample, else
    /// [`Self::value`] and whether it differs from `e` (the line lies between them).
    #[inline]
    pub fn tap(&self, at: Vec2, e: Vec3, foot: Vec3) -> Option<(Vec3, bool)> {
        let s = self.distance(at);
        if s.is_nan() || s < 0.0 {
            None
        } else if !self.has_foot() || s >= self.site {
            Some((e, false))
        } else {
            Some((self.blend(s, e, foot), true))
        }
    }
}

/// The corners of barycentric coordinates as a parameterisation ([`CrossingLine::in_uv`]).
pub const BARYCENTRIC: [Vec2; 3] = [Vec2::ZERO, Vec2::X, Vec2::Y];

/// A foot's estimate as a cache keeps it: its value, or NaN where it is buried
/// ([`FOOT_BURIED_SHARE`]).
pub fn foot_value(e: &Estimate) -> Vec3 {
    if e.back_face_share > FOOT_BURIED_SHARE {
        Vec3::NAN
    } else {
        e.value
    }
}

/// After a bake: the stored values of the feet ([`foot_value`]s, NaN where none was
/// usable, then zero), packed by `pack`; a line whose foot is unusable stops blending
/// (its foot distance becomes its site's).
pub fn settle_feet(
    lines: &mut [SampleCrossing],
    feet: &[Vec3],
    pack: impl Fn(Vec3) -> StoredRgb,
) -> Vec<StoredRgb> {
    for (line, foot) in lines.iter_mut().zip(feet) {
        if foot.is_nan() {
            line.foot = line.site;
        }
    }
    feet.iter()
        .map(|&f| pack(if f.is_nan() { Vec3::ZERO } else { f }))
        .collect()
}

/// A foot's estimate counts as buried (inside other geometry) past this share of rays on
/// back faces: more than a texel's or grid sample's threshold, since a foot next to the
/// back of a single-sided wall sees that back over up to half its hemisphere and is
/// still in the open.
pub const FOOT_BURIED_SHARE: f32 = 0.75;

/// Salt of a foot's random-stream key (xor-ed into its sample's key, then hashed).
pub const FOOT_KEY: u64 = 0x0f00_7000_0000_0000;

/// How close (metres) to `triangle`'s boundary, or to a crossing surface, a point counts
/// as on it: four spawn offsets, at least 10⁻⁴ of the longest edge.
pub fn boundary_tolerance(scene: &TracedScene, triangle: u32) -> f32 {
    let [a, b, c] = scene.positions()[triangle as usize];
    let longest = longest_edge(a, b, c);
    (4.0 * scene.spawn_offset()).max(1e-4 * longest)
}

/// The *foot* of a sample at barycentrics `site` on one side of `triangle` on its
/// crossing `crossing` (the same line in barycentrics: `line`, [`CrossingLine::in_uv`]):
/// the point of the triangle nearest to the line on the sample's side, two boundary
/// tolerances short of it, where E next to the contact is estimated. Returns its
/// barycentrics, or `None` if it does not lie on the
/// triangle, the sample is no farther from the line than the foot would be, or the
/// crossing surface does not reach the foot (the line runs on past the end of a wall or
/// a box's corner: an in-plane ray from the foot towards the line meets nothing).
pub fn foot(
    scene: &TracedScene,
    triangle: u32,
    front: bool,
    crossing: &CrossingLine,
    line: [f32; 3],
    site: Vec2,
) -> Option<Vec2> {
    let [a, b, c] = scene.positions()[triangle as usize];
    let normal = Vec2::new(line[0], line[1]);
    let metres = (normal.x * (b - a) + normal.y * (c - a)).length();
    if metres <= 0.0 {
        return None;
    }
    let tolerance = boundary_tolerance(scene, triangle);
    let gap = 2.0 * tolerance / metres;
    let side = normal.dot(site) + line[2];
    if side <= 2.0 * gap {
        return None;
    }
    let foot = site - normal * (side - gap);
    if foot.min_element() <= 1e-4 || 1.0 - foot.x - foot.y <= 1e-4 {
        return None;
    }
    let origin = scene.spawn_origin(&scene.surface_point(triangle, foot, front));
    scene
        .occluded(origin, -crossing.normal, 4.0 * tolerance)
        .then_some(foot)
}

impl Probe {
    /// What a probe of the same sample reaching only `reach` (no farther than this one's
    /// reach) finds: the crossing and exit met within it. Each in-plane ray's nearest hit
    /// is the same however far it may go, so this equals that shorter probe.
    pub fn within(&self, reach: f32) -> Probe {
        let crossing_kept = self.crossing_distance <= reach;
        let exit_kept = self.exit_distance <= reach;
        Probe {
            crossing: self.crossing.filter(|_| crossing_kept),
            crossing_distance: match crossing_kept {
                true => self.crossing_distance,
                false => f32::INFINITY,
            },
            exit: self.exit.filter(|_| exit_kept),
            exit_distance: match exit_kept {
                true => self.exit_distance,
                false => f32::INFINITY,
            },
            touching: self.touching && exit_kept,
        }
    }

    /// Where the sample at `uv` that this probe describes is estimated: just beyond the
    /// crossing surface it lies on ([`Probe::touching`]), else at `uv`.
    pub fn site(&self, uv: Vec2) -> Vec2 {
        match self.exit {
            Some(exit) if self.touching => exit,
            _ => uv,
        }
    }
}

/// Probes the surface around barycentrics `uv` of `triangle` on the given side within
/// `reach` metres (module docs).
pub fn probe(scene: &TracedScene, triangle: u32, uv: Vec2, front: bool, reach: f32) -> Probe {
    let p = scene.surface_point(triangle, uv, front);
    let origin = scene.spawn_origin(&p);
    let mu = p.geometric_normal;
    let (e1, e2) = orthonormal_basis(mu);
    let same = SAME_SURFACE_DEGREES.to_radians().cos();
    let [a, b, c] = scene.positions()[triangle as usize];
    let off = scene.spawn_offset();
    let boundary_tolerance = boundary_tolerance(scene, triangle);
    let mut best: Option<(f32, CrossingLine)> = None;
    let mut exit: Option<(f32, Vec2)> = None;
    for k in 0..PROBE_DIRECTIONS {
        let angle = k as f32 * std::f32::consts::TAU / PROBE_DIRECTIONS as f32;
        let d = e1 * angle.cos() + e2 * angle.sin();
        let Some(hit) = scene.closest_hit(origin, d, reach) else {
            continue;
        };
        let n_hit = scene.geometric_normals()[hit.triangle as usize];
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
    let exit_distance = exit.map_or(f32::INFINITY, |(t, _)| t);
    let exit = exit.map(|(_, uv)| uv);
    Probe {
        crossing: best.map(|(_, line)| line),
        crossing_distance: best.map_or(f32::INFINITY, |(t, _)| t),
        exit,
        exit_distance,
        touching,
    }
}

/// Whether any cell of the order-`n` grid of `triangle` (on the given side) is crossed:
/// probes from every grid point as far as one grid spacing (the longest edge over `n`).
pub fn grid_crossed(scene: &TracedScene, triangle: u32, front: bool, n: u32) -> bool {
    let [a, b, c] = scene.positions()[triangle as usize];
    let longest = longest_edge(a, b, c);
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
